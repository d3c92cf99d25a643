//! `meshvae reconstruct`: a trained model's reconstructions of its test meshes (or all) as OBJ
//! files, with an optional sheet of them beside their ground truth, coloured by the error.

use crate::CliError;
use crate::generate::model_and_set;
use mesh_io::TriMesh;
use std::path::{Path, PathBuf};

#[derive(clap::Args)]
pub struct ReconstructArgs {
    /// A model folder written by `meshvae train`.
    model: PathBuf,
    /// Folder for the reconstructed meshes (OBJ, named after the originals).
    #[arg(long)]
    out: PathBuf,
    /// The mesh set (default: the one recorded in the model's config).
    #[arg(long)]
    set: Option<PathBuf>,
    /// Reconstruct every mesh of the set, not only the test meshes.
    #[arg(long)]
    all: bool,
    /// Also write sheet.png: each ground truth beside its reconstruction coloured by the
    /// per-vertex error, with a colour bar.
    #[arg(long)]
    sheet: bool,
    /// The side the sheet's pictures look from.
    #[arg(long, default_value_t = mesh_render::View::Auto)]
    view: mesh_render::View,
}

pub fn run(args: &ReconstructArgs) -> Result<(), CliError> {
    let (trained, set) = model_and_set(&args.model, args.set.as_ref())?;
    crate::generate::check_quality(&trained, &set, &args.model)?;
    let ids: Vec<usize> = if args.all {
        (0..set.len()).collect()
    } else {
        trained.split.test.clone()
    };
    std::fs::create_dir_all(&args.out).map_err(|e| CliError::Output {
        path: args.out.clone(),
        message: e.to_string(),
    })?;
    let mut meshes = trained.reconstruct(&set, &ids, &meshvae::default_device())?;
    // Where `eval` measures them: the decoder fixes a shape up to a translation.
    for (&i, mesh) in ids.iter().zip(meshes.iter_mut()) {
        meshvae::align_centroids(set.frame(i), mesh);
    }
    // Drawn before anything is written, so a failure leaves no partial output.
    let sheet = if args.sheet {
        let view = args.view.for_set(set.frame(0));
        Some(error_sheet(&set, &ids, &meshes, view)?)
    } else {
        None
    };
    for (&i, positions) in ids.iter().zip(&meshes) {
        let mesh = TriMesh::new(
            positions.iter().map(|p| p.map(|x| x as f32)).collect(),
            set.faces().to_vec(),
        )?;
        let stem = Path::new(&set.names()[i])
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| format!("{i}"));
        mesh_io::write_mesh(&args.out.join(format!("{stem}.obj")), &mesh)?;
    }
    if let Some(sheet) = &sheet {
        sheet.save_png(&args.out.join("sheet.png"))?;
    }
    out!(
        "wrote {} reconstructed meshes{} to {}",
        meshes.len(),
        if sheet.is_some() {
            " and sheet.png"
        } else {
            ""
        },
        args.out.display()
    );
    Ok(())
}

/// Ground truth (grey) beside each reconstruction (centroid-aligned, as `eval` measures)
/// coloured by its per-vertex distance to the truth, all in one frame and on one colour scale
/// (0 … the largest error, the bar on top, in mesh units and % of the bounding-box diagonal of
/// the first mesh shown, as `eval`'s relative errors), as the paper's reconstruction figures.
fn error_sheet(
    set: &mesh_io::MeshSet,
    ids: &[usize],
    meshes: &[Vec<[f64; 3]>],
    view: mesh_render::View,
) -> Result<mesh_render::Image, CliError> {
    let recon: Vec<Vec<[f32; 3]>> = meshes
        .iter()
        .map(|m| m.iter().map(|p| p.map(|x| x as f32)).collect())
        .collect();
    let errors: Vec<Vec<f32>> = ids
        .iter()
        .zip(&recon)
        .map(|(&i, r)| {
            set.frame(i)
                .iter()
                .zip(r)
                .map(|(a, b)| {
                    let d: f32 = (0..3).map(|k| (a[k] - b[k]) * (a[k] - b[k])).sum();
                    d.sqrt()
                })
                .collect()
        })
        .collect();
    let max = errors
        .iter()
        .flatten()
        .fold(0f32, |m, &e| if e.is_finite() { m.max(e) } else { m });
    let diagonal = ids
        .first()
        .map_or(0.0, |&i| mesh_io::bbox_diagonal(set.frame(i)));
    let mut frames: Vec<&[[f32; 3]]> = ids.iter().map(|&i| set.frame(i)).collect();
    frames.extend(recon.iter().map(|r| r.as_slice()));
    let frame = mesh_render::Bounds::of(&frames);
    // No empty bands above and below long, low shapes; the full width, for the captions.
    let height = frame.map_or(256, |f| f.fit(view, 256).1);
    let options = mesh_render::RenderOptions {
        width: 256,
        height,
        view,
        frame,
        ..mesh_render::RenderOptions::default()
    };
    let mut tiles = Vec::with_capacity(2 * ids.len());
    for ((&i, r), e) in ids.iter().zip(&recon).zip(&errors) {
        let name = &set.names()[i];
        tiles.push(mesh_render::Tile {
            image: mesh_render::render(set.frame(i), set.faces(), None, &options)?,
            caption: name.clone(),
        });
        let colors = mesh_render::error_colors(e, max);
        let mean = e.iter().map(|&x| f64::from(x)).sum::<f64>() / e.len().max(1) as f64;
        tiles.push(mesh_render::Tile {
            image: mesh_render::render(r, set.faces(), Some(&colors), &options)?,
            caption: format!("{name} rec., mean {}", units(mean, diagonal)),
        });
    }
    let columns = if ids.len() > 1 { 4 } else { 2 };
    let sheet = mesh_render::sheet(&tiles, columns)?;
    let label = format!(
        "per-vertex error, mesh units (max {})",
        units(f64::from(max), diagonal)
    );
    Ok(mesh_render::with_colorbar_on_top(&sheet, max, &label)?)
}

/// A distance in mesh units and as a percentage of `diagonal`.
fn units(d: f64, diagonal: f64) -> String {
    if diagonal > 0.0 {
        format!("{d:.3} = {:.2} %", 100.0 * d / diagonal)
    } else {
        format!("{d:.3}")
    }
}
