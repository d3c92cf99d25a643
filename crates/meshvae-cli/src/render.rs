//! `meshvae render MESH|DIR|SET --out FILE.png [--view front] [--size N] [--columns N]
//! [--errors-against GT] [--max-error E]`

use crate::{CliError, print_warnings};
use mesh_io::{MeshIoError, MeshSet, TriMesh};
use mesh_render::{Bounds, Image, RenderOptions, Tile, View};
use std::path::{Path, PathBuf};

/// Tile size of sheets when `--size` is not given.
const DEFAULT_TILE: u32 = 256;
/// Picture size of one mesh when `--size` is not given.
const DEFAULT_SINGLE: u32 = 512;

#[derive(clap::Args)]
pub struct RenderArgs {
    /// One mesh file (OBJ, OFF, PLY, GLB) → one picture; a folder of meshes, a multi-frame
    /// .glb/.gltf or a .mvset cache → a captioned grid of all meshes at one shared scale.
    input: PathBuf,
    /// The PNG to write (atomically: nothing is written on error).
    #[arg(long)]
    out: PathBuf,
    /// The side the camera looks from: auto (along the framed box's thinnest axis, y up unless
    /// the shape is flat in y), front (along -z, y up), back, left, right, top or bottom.
    #[arg(long, default_value = "auto", value_parser = parse_view)]
    view: View,
    /// Width and height in pixels of the picture (one mesh; default 512) or of each tile of a
    /// grid (default 256).
    #[arg(long)]
    size: Option<u32>,
    /// Tiles per row of a grid (default: about the square root of the count).
    #[arg(long)]
    columns: Option<usize>,
    /// Ground truth: colour each vertex by its distance to the same vertex of this mesh (or of
    /// the mesh of the same name, or else at the same position, in this folder/set), with a
    /// colour bar. Connectivity must match.
    #[arg(long)]
    errors_against: Option<PathBuf>,
    /// The distance at the top of the colour scale (default: the largest error).
    #[arg(long, requires = "errors_against")]
    max_error: Option<f32>,
}

fn parse_view(s: &str) -> Result<View, String> {
    s.parse::<View>().map_err(|e| e.to_string())
}

/// Meshes read from one input: shared faces, one frame per mesh, names, and the file or folder
/// that each came from (for error messages).
struct Input {
    set: MeshSet,
    path: PathBuf,
    /// One mesh file, rather than a set.
    single: bool,
}

fn read_input(path: &Path) -> Result<Input, CliError> {
    let single_file = |path: &Path| -> Result<Input, CliError> {
        let loaded = mesh_io::read_mesh(path)?;
        print_warnings(&loaded.warnings);
        let name = path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| path.display().to_string());
        Ok(Input {
            set: MeshSet::from_meshes(vec![loaded.value], vec![name])?,
            path: path.into(),
            single: true,
        })
    };
    let is_set_file = path
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| ["glb", "gltf", "mvset"].contains(&e.to_ascii_lowercase().as_str()));
    if !path.is_dir() && !is_set_file {
        return single_file(path);
    }
    match mesh_io::load_set(path) {
        Ok(loaded) => {
            print_warnings(&loaded.warnings);
            Ok(Input {
                set: loaded.value,
                path: path.into(),
                single: false,
            })
        }
        // One mesh: a .glb without morph targets, or a folder holding a single file.
        Err(MeshIoError::TooFewMeshes { .. }) if path.is_dir() => {
            let files = mesh_io::set::list_mesh_files(path)?;
            let first = files
                .first()
                .ok_or_else(|| MeshIoError::EmptySet { path: path.into() })?;
            let mut input = single_file(first)?;
            input.single = false;
            Ok(input)
        }
        Err(MeshIoError::TooFewMeshes { .. }) => single_file(path),
        Err(e) => Err(e.into()),
    }
}

/// Per-vertex Euclidean distances from each frame of `input` to its ground truth.
fn errors_against(input: &Input, gt_path: &Path) -> Result<Vec<Vec<f32>>, CliError> {
    let gt = read_input(gt_path)?;
    let template = |i: &Input| TriMesh {
        positions: i.set.frame(0).to_vec(),
        faces: i.set.faces().to_vec(),
    };
    mesh_io::check_same_connectivity(&template(input), &input.path, &template(&gt), &gt.path)
        .map_err(|e| {
            CliError::argument(
                "--errors-against",
                format!("the ground truth must have the input's connectivity: {e}"),
            )
        })?;
    let n = input.set.len();
    let by_name: Option<Vec<usize>> = input
        .set
        .names()
        .iter()
        .map(|name| gt.set.names().iter().position(|g| g == name))
        .collect();
    let pairs: Vec<usize> = if gt.set.len() == 1 {
        vec![0; n]
    } else if let Some(indices) = by_name {
        indices
    } else if gt.set.len() == n {
        (0..n).collect()
    } else {
        return Err(CliError::argument(
            "--errors-against",
            format!(
                "{} holds {} meshes and {} holds {}, and their names do not match: give one \
                 ground-truth mesh, or one per input mesh",
                gt_path.display(),
                gt.set.len(),
                input.path.display(),
                n
            ),
        ));
    };
    Ok(pairs
        .iter()
        .enumerate()
        .map(|(i, &g)| {
            input
                .set
                .frame(i)
                .iter()
                .zip(gt.set.frame(g))
                .map(|(a, b)| {
                    let d: f64 = (0..3)
                        .map(|k| (f64::from(a[k]) - f64::from(b[k])).powi(2))
                        .sum();
                    d.sqrt() as f32
                })
                .collect()
        })
        .collect())
}

/// Three significant digits, compactly.
fn short(v: f32) -> String {
    if v == 0.0 {
        "0".into()
    } else if (1e-3..1e4).contains(&v.abs()) {
        let decimals = (2 - v.abs().log10().floor() as i32).max(0) as usize;
        format!("{v:.decimals$}")
    } else {
        format!("{v:.2e}")
    }
}

pub fn run(args: &RenderArgs) -> Result<(), CliError> {
    let is_png = args
        .out
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("png"));
    if !is_png {
        return Err(CliError::argument(
            "--out",
            format!("{}: the picture must be a .png file", args.out.display()),
        ));
    }
    if args.size == Some(0) {
        return Err(CliError::argument("--size", "must be at least 1 pixel"));
    }
    if args.columns == Some(0) {
        return Err(CliError::argument("--columns", "must be at least 1"));
    }
    if let Some(max) = args.max_error
        && !(max.is_finite() && max > 0.0)
    {
        return Err(CliError::argument(
            "--max-error",
            format!("must be a positive number, got {max}"),
        ));
    }
    let input = read_input(&args.input)?;
    let set = &input.set;
    let errors = match &args.errors_against {
        Some(gt) => Some(errors_against(&input, gt)?),
        None => None,
    };
    let max_error = errors.as_ref().map(|errors| {
        args.max_error
            .unwrap_or_else(|| errors.iter().flatten().copied().fold(0.0f32, f32::max))
    });
    let size = args.size.unwrap_or(if input.single {
        DEFAULT_SINGLE
    } else {
        DEFAULT_TILE
    });
    let frames: Vec<&[[f32; 3]]> = set.frames().collect();
    // The view of the set's other pictures (its rest mesh decides).
    let view = args.view.for_set(set.frame(0));
    // One frame for all meshes, so that sizes and motions compare.
    let frame = Bounds::of(&frames);
    // A single picture keeps the size asked for; tiles take the frame's shape.
    let (width, height) = match frame {
        Some(f) if !input.single => f.fit(view, size),
        _ => (size, size),
    };
    let options = RenderOptions {
        width,
        height,
        view,
        frame,
        ..RenderOptions::default()
    };
    let render_one = |i: usize| -> Result<Image, CliError> {
        let colors = match (&errors, max_error) {
            (Some(errors), Some(max)) => Some(mesh_render::error_colors(&errors[i], max)),
            _ => None,
        };
        Ok(mesh_render::render(
            frames[i],
            set.faces(),
            colors.as_deref(),
            &options,
        )?)
    };
    let mut image = if input.single {
        render_one(0)?
    } else {
        let tiles = (0..set.len())
            .map(|i| {
                let mut caption = set.names()[i].clone();
                if let Some(errors) = &errors {
                    let mean = errors[i].iter().map(|&e| f64::from(e)).sum::<f64>()
                        / errors[i].len().max(1) as f64;
                    caption = format!("{caption}  (mean {})", short(mean as f32));
                }
                Ok(Tile {
                    image: render_one(i)?,
                    caption,
                })
            })
            .collect::<Result<Vec<_>, CliError>>()?;
        let columns = args
            .columns
            .unwrap_or_else(|| (set.len() as f64).sqrt().ceil() as usize);
        mesh_render::sheet(&tiles, columns)?
    };
    if let Some(max) = max_error {
        image =
            mesh_render::with_colorbar_on_top(&image, max, "distance to ground truth, mesh units")?;
    }
    image.save_png(&args.out)?;
    out!(
        "{} -> {} ({}x{}, {} mesh{})",
        args.input.display(),
        args.out.display(),
        image.width,
        image.height,
        set.len(),
        if set.len() == 1 { "" } else { "es" }
    );
    if let (Some(max), Some(errors)) = (max_error, &errors) {
        let largest = errors.iter().flatten().copied().fold(0.0f32, f32::max);
        out!(
            "  largest error {} (colour scale 0..{})",
            short(largest),
            short(max)
        );
    }
    Ok(())
}
