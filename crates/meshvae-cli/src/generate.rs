//! `meshvae generate`: random meshes from a trained model, each with its nearest training mesh;
//! plus the helpers the applications (`generate`, `interpolate`, `embed`) share.

use crate::{CliError, print_warnings};
use mesh_io::{MeshSet, TriMesh};
use mesh_render::{Bounds, Image, RenderOptions, Tile, View};
use meshvae::{GenerateOptions, TrainedModel};
use std::path::{Path, PathBuf};

#[derive(clap::Args)]
pub struct GenerateArgs {
    /// A model folder written by `meshvae train`.
    model: PathBuf,
    /// Number of meshes to generate.
    #[arg(short = 'n', long = "count", default_value_t = 20)]
    count: usize,
    /// Folder for the meshes (sample_000.obj, …) and report.json / report.csv.
    #[arg(long)]
    out: PathBuf,
    /// Seeds the latent draws (same seed, same meshes).
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// The label to generate for a conditional model (trained with --labels or --conditional);
    /// required for such a model, refused for another.
    #[arg(long)]
    label: Option<String>,
    /// The mesh set (default: the one recorded in the model's config); the nearest training
    /// meshes come from it.
    #[arg(long)]
    set: Option<PathBuf>,
    /// Also write sheet.png: each sample beside its nearest training mesh.
    #[arg(long)]
    sheet: bool,
    /// The side the pictures look from (auto, front, back, left, right, top, bottom).
    #[arg(long, default_value = "auto")]
    view: View,
}

/// The model in `model` and its mesh set (`set`, or the path its config records), checked to fit.
pub fn model_and_set(
    model: &Path,
    set: Option<&PathBuf>,
) -> Result<(TrainedModel, MeshSet), CliError> {
    model_and_set_selected(model, set, false)
}

/// As [`model_and_set`], with the weights selected on the test meshes if `select_on_test`.
pub fn model_and_set_selected(
    model: &Path,
    set: Option<&PathBuf>,
    select_on_test: bool,
) -> Result<(TrainedModel, MeshSet), CliError> {
    let trained = TrainedModel::load_selected(model, &meshvae::default_device(), select_on_test)?;
    let executor = trained.inference_executor();
    if executor.reason.is_some() {
        eprintln!("note: the network runs on {executor}");
    }
    let path = match set {
        Some(p) => p.clone(),
        None => trained.spec.source.clone().ok_or_else(|| {
            CliError::argument(
                "--set",
                "the model does not record its mesh set; pass --set",
            )
        })?,
    };
    let loaded = mesh_io::load_set(&path)?;
    print_warnings(&loaded.warnings);
    trained.check_set(&loaded.value)?;
    Ok((trained, loaded.value))
}

/// Prints why the model in `model` is not to be trusted, if it is not (test error not clearly
/// below the mean training shape's, training cut while still improving), and returns the
/// warnings as JSON for the command's report.
pub fn check_quality(
    trained: &TrainedModel,
    set: &MeshSet,
    model: &Path,
) -> Result<serde_json::Value, CliError> {
    let status = meshvae::read_status(&meshvae::ModelFolder::new(model))?;
    let warnings = trained.quality_warnings(set, status.as_ref(), &meshvae::default_device())?;
    Ok(print_quality(&warnings))
}

/// Prints each warning on stderr and returns them as `[{"kind", "message"}]`.
pub fn print_quality(warnings: &[meshvae::QualityWarning]) -> serde_json::Value {
    for w in warnings {
        eprintln!("warning: {w}");
    }
    warnings
        .iter()
        .map(|w| serde_json::json!({"kind": w.kind(), "message": w.to_string()}))
        .collect()
}

/// Creates the output folder (and its parents).
pub fn create_out(dir: &Path) -> Result<(), CliError> {
    std::fs::create_dir_all(dir).map_err(|e| CliError::Output {
        path: dir.into(),
        message: e.to_string(),
    })
}

/// A mesh of f32 positions on `faces` from f64 positions.
pub fn to_mesh(positions: &[[f64; 3]], faces: &[[u32; 3]]) -> Result<TriMesh, CliError> {
    Ok(TriMesh::new(
        positions.iter().map(|p| p.map(|x| x as f32)).collect(),
        faces.to_vec(),
    )?)
}

/// A CSV field, quoted when it holds a comma, quote or line break.
pub fn csv_field(s: &str) -> String {
    if s.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

/// Writes a text file atomically.
pub fn write_text(path: &Path, text: &str) -> Result<(), CliError> {
    mesh_io::atomic::write_bytes_atomic(path, text.as_bytes())?;
    Ok(())
}

/// Writes pretty JSON atomically.
pub fn write_json(path: &Path, value: &serde_json::Value) -> Result<(), CliError> {
    let text = serde_json::to_string_pretty(value).map_err(|e| CliError::Output {
        path: path.into(),
        message: e.to_string(),
    })?;
    write_text(path, &(text + "\n"))
}

/// Writes a PNG atomically.
pub fn write_png(path: &Path, image: &Image) -> Result<(), CliError> {
    mesh_io::atomic::write_bytes_atomic(path, &image.encode_png()?)?;
    Ok(())
}

/// Pixels of one mesh picture in the sheets and strips.
pub const TILE: u32 = 256;

/// Renders each mesh (positions on `faces`) at one common scale, with its caption.
pub fn tiles(
    meshes: &[(&[[f32; 3]], String)],
    faces: &[[u32; 3]],
    view: View,
) -> Result<Vec<Tile>, CliError> {
    let frames: Vec<&[[f32; 3]]> = meshes.iter().map(|(p, _)| *p).collect();
    let frame = Bounds::of(&frames);
    // No empty bands above and below long, low shapes; the full width, for the captions.
    let height = frame.map_or(TILE, |f| f.fit(view, TILE).1);
    let options = RenderOptions {
        width: TILE,
        height,
        view,
        frame,
        ..RenderOptions::default()
    };
    meshes
        .iter()
        .map(|(p, caption)| {
            Ok(Tile {
                image: mesh_render::render(p, faces, None, &options)?,
                caption: caption.clone(),
            })
        })
        .collect()
}

pub fn run(args: &GenerateArgs) -> Result<(), CliError> {
    if args.count == 0 {
        return Err(CliError::argument("--count", "must be at least 1"));
    }
    let (trained, set) = model_and_set(&args.model, args.set.as_ref())?;
    let options = GenerateOptions {
        count: args.count,
        seed: args.seed,
    };
    let warnings = check_quality(&trained, &set, &args.model)?;
    let generated = trained.generate_labelled(&set, &options, args.label.as_deref())?;
    let meshes: Vec<TriMesh> = generated
        .positions
        .iter()
        .map(|p| to_mesh(p, set.faces()))
        .collect::<Result<_, _>>()?;
    let digits = (args.count - 1).to_string().len().max(3);
    let files: Vec<String> = (0..args.count)
        .map(|i| format!("sample_{i:0digits$}.obj"))
        .collect();

    // Everything that can fail on content is computed before the first file is written.
    let sheet = if args.sheet {
        let mut pairs: Vec<(&[[f32; 3]], String)> = Vec::with_capacity(2 * args.count);
        for (i, (mesh, nb)) in meshes.iter().zip(&generated.nearest).enumerate() {
            let caption = match &args.label {
                Some(label) => format!("sample {i} ({label})"),
                None => format!("sample {i}"),
            };
            pairs.push((&mesh.positions, caption));
            pairs.push((
                set.frame(nb.index),
                // The terminal's unit: a fraction of the template's diagonal.
                format!("{} (d {:.2e} of diag.)", nb.name, nb.distance_rel),
            ));
        }
        let tiles = tiles(&pairs, set.faces(), args.view.for_set(set.frame(0)))?;
        // Two pairs per row (four columns), or one when there is a single sample.
        Some(mesh_render::sheet(
            &tiles,
            if args.count > 1 { 4 } else { 2 },
        )?)
    } else {
        None
    };

    create_out(&args.out)?;
    for (mesh, file) in meshes.iter().zip(&files) {
        mesh_io::write_mesh(&args.out.join(file), mesh)?;
    }
    let mut csv = String::from(
        "sample,file,label,nearest,nearest_index,nearest_label,distance,distance_rel\n",
    );
    let mut rows = Vec::with_capacity(args.count);
    let label = generated.label.as_deref();
    for (i, (file, nb)) in files.iter().zip(&generated.nearest).enumerate() {
        csv += &format!(
            "{i},{file},{},{},{},{},{},{}\n",
            csv_field(label.unwrap_or("")),
            csv_field(&nb.name),
            nb.index,
            csv_field(nb.label.as_deref().unwrap_or("")),
            nb.distance,
            nb.distance_rel
        );
        rows.push(serde_json::json!({
            "sample": i,
            "file": file,
            "label": label,
            "nearest": nb.name,
            "nearest_index": nb.index,
            "nearest_label": nb.label,
            "distance": nb.distance,
            "distance_rel": nb.distance_rel,
            "latent": generated.latents[i],
        }));
    }
    write_text(&args.out.join("report.csv"), &csv)?;
    let share = generated.label_share();
    let report = serde_json::json!({
        "model": args.model,
        "seed": args.seed,
        "count": args.count,
        "label": label,
        "label_share": share,
        "distance": "mean per-vertex Euclidean distance to the nearest training mesh, centroids aligned",
        "samples": rows,
        "warnings": warnings,
    });
    write_json(&args.out.join("report.json"), &report)?;
    if let Some(image) = &sheet {
        write_png(&args.out.join("sheet.png"), image)?;
    }
    let mean = generated
        .nearest
        .iter()
        .map(|n| n.distance_rel)
        .sum::<f64>()
        / args.count as f64;
    out!(
        "wrote {} generated meshes, report.json and report.csv{} to {}",
        args.count,
        if sheet.is_some() { ", sheet.png" } else { "" },
        args.out.display()
    );
    out!("mean distance to the nearest training mesh: {mean:.3e} of the template's diagonal");
    if let (Some(label), Some(share)) = (label, share) {
        let hits = generated
            .nearest
            .iter()
            .filter(|n| n.label.as_deref() == Some(label))
            .count();
        out!(
            "label {label}: {hits} of {} samples ({:.0} %) have their nearest training mesh \
             labelled {label}",
            args.count,
            100.0 * share
        );
    }
    Ok(())
}
