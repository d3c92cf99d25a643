//! `meshvae demo [--out DIR] [--epochs N] [--seed S] [--force]`: the whole pipeline on the
//! built-in synthetic set, by running the README walk-through's own commands in order (each
//! parsed from its command line, so the demo does exactly what those commands do), then a
//! summary of what was written where and what opens it.

use crate::CliError;
use crate::{embed, generate, interpolate, render, train};
use clap::{Args, FromArgMatches};
use mesh_io::synth::{ShapeKind, SynthConfig};
use std::ffi::OsString;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Meshes the demo generates.
const GENERATED: usize = 12;
/// Meshes of the interpolation, both ends included.
const STEPS: usize = 8;

/// What the demo writes inside `--out`; `--force` replaces exactly these.
const OUTPUTS: [&str; 7] = [
    "set",
    "set.png",
    "model",
    "generated",
    "interpolation",
    "embedding",
    "reconstruction",
];

#[derive(clap::Args)]
pub struct DemoArgs {
    /// Folder for everything the demo writes (refused if it exists and is not empty, unless
    /// --force).
    #[arg(long, default_value = "meshvae-demo")]
    out: PathBuf,
    /// A cap on the training epochs (default: none; the model trains until it has converged;
    /// fewer: faster, blurrier shapes).
    #[arg(long)]
    epochs: Option<usize>,
    /// Seeds the synthetic set, the split, the training, the generations and t-SNE.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Write into a non-empty --out, replacing the demo's own files and folders there (set,
    /// set.png, model, generated, interpolation, embedding, reconstruction); nothing else in it
    /// is touched.
    #[arg(long)]
    force: bool,
    /// For tests: 146-vertex capsules, 4 meshes per label and a small latent, so that a run
    /// takes seconds in a debug build. The pictures are then coarse.
    #[arg(long, hide = true)]
    tiny: bool,
}

/// A training the user stopped ends the demo there: what to run is the demo again, not the
/// `meshvae train --resume` the train command suggests.
fn interrupted_demo(e: CliError, args: &DemoArgs) -> CliError {
    match e {
        CliError::Interrupted { source, .. } => {
            let mut again = format!(
                "the demo stopped there; run it again with: meshvae demo --out {} --seed {}",
                train::shell_word(&args.out),
                args.seed
            );
            if let Some(n) = args.epochs {
                again.push_str(&format!(" --epochs {n}"));
            }
            again.push_str(" --force");
            CliError::Interrupted {
                source,
                next: again,
            }
        }
        e => e,
    }
}

/// Runs one of meshvae's commands on `argv` (its arguments after the command's name), printing
/// the command line first so that the user can rerun or vary it.
fn run_as<A: Args + FromArgMatches>(
    name: &'static str,
    argv: &[OsString],
    run: impl FnOnce(&A) -> Result<(), CliError>,
) -> Result<(), CliError> {
    let shown: Vec<String> = argv
        .iter()
        .map(|a| {
            let a = a.to_string_lossy();
            if a.contains([' ', '\'', '"']) {
                format!("'{}'", a.replace('\'', r"'\''"))
            } else {
                a.into_owned()
            }
        })
        .collect();
    out!("\n$ meshvae {name} {}", shown.join(" "));
    let command = A::augment_args(clap::Command::new(name).no_binary_name(true));
    let parsed = command
        .try_get_matches_from(argv)
        .and_then(|m| A::from_arg_matches(&m))
        // Only a bug in the demo's own argument lists can get here.
        .map_err(|e| CliError::argument("demo", format!("meshvae {name}: {e}")))?;
    run(&parsed)
}

/// Command-line arguments from strings and paths.
macro_rules! argv {
    ($($a:expr),* $(,)?) => { [$(OsString::from($a)),*] };
}

/// Refuses a non-empty `out` without `force`; with it, removes the demo's earlier outputs.
fn prepare_out(out: &Path, force: bool) -> Result<(), CliError> {
    if out.exists() && !out.is_dir() {
        return Err(CliError::argument(
            "--out",
            format!("{} is a file, not a folder", out.display()),
        ));
    }
    let io_error = |path: &Path, e: std::io::Error| CliError::Output {
        path: path.into(),
        message: e.to_string(),
    };
    if out.is_dir() {
        let non_empty = std::fs::read_dir(out)
            .map_err(|e| io_error(out, e))?
            .next()
            .is_some();
        if non_empty && !force {
            return Err(CliError::argument(
                "--out",
                format!(
                    "{} exists and is not empty; pass --force to replace the demo's files in \
                     it, or choose another folder",
                    out.display()
                ),
            ));
        }
        for name in OUTPUTS {
            let path = out.join(name);
            let removed = if path.is_dir() {
                std::fs::remove_dir_all(&path)
            } else if path.exists() {
                std::fs::remove_file(&path)
            } else {
                Ok(())
            };
            removed.map_err(|e| io_error(&path, e))?;
        }
    }
    std::fs::create_dir_all(out).map_err(|e| io_error(out, e))
}

/// The synthetic set of the demo and the names of its most bent and most twisted meshes.
fn write_set(dir: &Path, seed: u64, tiny: bool) -> Result<(usize, String, String), CliError> {
    let config = if tiny {
        SynthConfig {
            seed,
            meshes_per_label: 4,
            rings: 8,
            segments: 12,
            cap_rings: 2,
            ..SynthConfig::default()
        }
    } else {
        // 530-vertex capsules: the bends and twists read as clearly as at the default 2,498
        // vertices, and a training step costs a fifth as much, so that the model converges
        // within the demo (80 meshes: with 40, 18 training meshes overfit, test RMS 4× higher).
        SynthConfig {
            seed,
            rings: 16,
            segments: 24,
            cap_rings: 3,
            ..SynthConfig::default()
        }
    };
    let synth = mesh_io::synth::generate(&config)?;
    mesh_io::write_folder(dir, &synth.set)?;
    let strongest = |kind: ShapeKind, amount: fn(&mesh_io::synth::ShapeParams) -> f32| {
        (0..synth.params.len())
            .filter(|&i| synth.params[i].label == kind)
            .max_by(|&a, &b| {
                amount(&synth.params[a])
                    .abs()
                    .total_cmp(&amount(&synth.params[b]).abs())
            })
            .map(|i| synth.set.names()[i].clone())
            .ok_or_else(|| {
                CliError::argument("demo", format!("the synthetic set has no {kind:?} mesh"))
            })
    };
    let bent = strongest(ShapeKind::Bend, |p| p.bend)?;
    let twisted = strongest(ShapeKind::Twist, |p| p.twist)?;
    out!(
        "wrote {} synthetic capsules of {} vertices (labels bend / twist) to {}",
        synth.set.len(),
        synth.set.vertex_count(),
        dir.display()
    );
    Ok((synth.set.len(), bent, twisted))
}

pub fn run(args: &DemoArgs) -> Result<(), CliError> {
    if args.epochs == Some(0) {
        return Err(CliError::argument("--epochs", "must be at least 1"));
    }
    let start = Instant::now();
    let out = &args.out;
    prepare_out(out, args.force)?;
    let path = |name: &str| out.join(name);
    let seed = args.seed.to_string();

    out!("1. A synthetic mesh set: capsules that bend or twist, one connectivity.");
    let (meshes, bent, twisted) = write_set(&path("set"), args.seed, args.tiny)?;

    let until = match args.epochs {
        Some(n) => format!("for at most {n} epochs"),
        None => "until it has converged".to_string(),
    };
    out!(
        "\n2. Training the mesh VAE: ACAP deformation features of every mesh, the pooling \
         hierarchy (edge contraction), then training on half of the meshes {until}."
    );
    let mut train_argv = argv![
        path("set"),
        "--out",
        path("model"),
        "--seed",
        &seed,
        "--force"
    ]
    .to_vec();
    if let Some(n) = args.epochs {
        train_argv.extend(argv!["--epochs", n.to_string()]);
    }
    if args.tiny {
        train_argv.extend(argv!["--latent", "16", "--batch", "4", "--quiet"]);
    }
    run_as("train", &train_argv, train::run_train).map_err(|e| interrupted_demo(e, args))?;

    out!("\n3. Evaluation on the meshes training never saw, beside the mean training shape.");
    run_as("eval", &argv![path("model")], crate::eval::run_eval)?;

    out!("\n4. New shapes: z ~ N(0, I), decoded, each beside its nearest training mesh.");
    run_as(
        "generate",
        &argv![
            path("model"),
            "-n",
            GENERATED.to_string(),
            "--out",
            path("generated"),
            "--seed",
            &seed,
            "--sheet",
        ],
        generate::run,
    )?;

    out!("\n5. Interpolation in latent space from the most bent to the most twisted capsule.");
    run_as(
        "interpolate",
        &argv![
            path("model"),
            "--from",
            &bent,
            "--to",
            &twisted,
            "--steps",
            STEPS.to_string(),
            "--out",
            path("interpolation"),
        ],
        interpolate::run,
    )?;

    out!("\n6. The set embedded in 2-D: latent means beside PCA and t-SNE of the features.");
    run_as(
        "embed",
        &argv![path("model"), "--out", path("embedding"), "--seed", &seed],
        embed::run,
    )?;

    out!("\n7. Reconstructions of the test meshes, coloured by their error.");
    run_as(
        "reconstruct",
        &argv![path("model"), "--out", path("reconstruction"), "--sheet"],
        crate::reconstruct::run,
    )?;

    out!("\n8. A picture of the whole set.");
    run_as(
        "render",
        &argv![path("set"), "--out", path("set.png"), "--size", "160"],
        render::run,
    )?;

    let seconds = start.elapsed().as_secs_f64();
    let d = out.display();
    out!(
        "\nDone in {:.0} min {:02.0} s. Everything is in {d}/:",
        (seconds / 60.0).floor(),
        seconds % 60.0
    );
    out!(
        "  pictures (PNG; any image viewer or web browser): set.png (all {meshes} \
         meshes), generated/sheet.png, interpolation/strip.png, embedding/embedding.png, \
         reconstruction/sheet.png"
    );
    out!(
        "  meshes (OBJ; MeshLab, Blender: File > Import > Wavefront, or any 3-D viewer): set/, \
         generated/, interpolation/, reconstruction/"
    );
    out!(
        "  animation (GLB; Blender: File > Import > glTF, or a web glTF viewer): \
         interpolation/interpolation.glb plays the interpolation"
    );
    out!(
        "  reports (CSV / JSON; a spreadsheet or text editor): generated/report.csv, \
         embedding/embedding.csv, interpolation/interpolation.json"
    );
    out!(
        "  the model (a folder for the meshvae commands): model/, e.g. `meshvae generate \
         {d}/model -n 20 --out more --sheet`"
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_interrupted_demo_says_to_run_the_demo_again() {
        let args = DemoArgs {
            out: PathBuf::from("my demo"),
            epochs: Some(5),
            seed: 3,
            force: false,
            tiny: false,
        };
        let stopped = CliError::Interrupted {
            source: meshvae::VaeError::Interrupted {
                dir: PathBuf::from("my demo/model"),
                epoch: 7,
                checkpoint: Some(6),
            },
            next: "continue it with: meshvae train 'my demo/set' --out 'my demo/model' --resume"
                .into(),
        };
        let text = interrupted_demo(stopped, &args).to_string();
        assert!(
            text.contains("training interrupted after epoch 7"),
            "{text}"
        );
        assert!(
            text.ends_with(
                "run it again with: meshvae demo --out 'my demo' --seed 3 --epochs 5 --force"
            ),
            "{text}"
        );
        assert!(!text.contains("--resume"), "{text}");
        let other = interrupted_demo(CliError::argument("--out", "bad"), &args);
        assert_eq!(other.to_string(), "--out: bad");
    }
}
