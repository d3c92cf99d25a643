//! `meshvae embed`: 2-D embeddings of every mesh of the set — the latent means by their two
//! most varying dimensions (as the paper), and PCA and t-SNE of the raw features — as a CSV and
//! three scatter plots side by side, points coloured by label (labelled sets) or by frame order,
//! joined in frame order where the set is a sequence (`--lines`).

use crate::CliError;
use crate::generate::{create_out, csv_field, model_and_set, write_png, write_text};
use meshvae::{EmbedOptions, loop_measure};
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct EmbedArgs {
    /// A model folder written by `meshvae train`.
    model: PathBuf,
    /// Folder for embedding.csv and embedding.png.
    #[arg(long)]
    out: PathBuf,
    /// The mesh set (default: the one recorded in the model's config).
    #[arg(long)]
    set: Option<PathBuf>,
    /// t-SNE perplexity (lowered to (N − 1) / 3 for small sets).
    #[arg(long, default_value_t = 30.0)]
    perplexity: f64,
    /// Seeds t-SNE when its PCA start is degenerate.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Join consecutive meshes by lines: `auto` where the set is a sequence (an animation:
    /// most consecutive meshes nearer to each other than the median pair in the features'
    /// PCA), `always`, or `never`.
    #[arg(long, value_enum, default_value_t = Lines::Auto)]
    lines: Lines,
}

#[derive(Clone, Copy, PartialEq, Eq, Debug, clap::ValueEnum)]
pub enum Lines {
    Auto,
    Always,
    Never,
}

/// Share of consecutive steps shorter than the median pair (LoopMeasure::nearer) from which
/// `--lines auto` joins the meshes: animations give 0.9–1, unordered sets about 0.5 (the
/// synthetic set 0.35).
const SEQUENCE_NEARER: f64 = 0.75;

/// Whether the set, in file order, is a sequence worth joining by lines.
fn is_sequence(pca: &[[f64; 2]]) -> bool {
    loop_measure(pca).is_ok_and(|m| m.nearer >= SEQUENCE_NEARER)
}

/// Pixels of each of the three plots.
const PLOT: (u32, u32) = (560, 520);

/// The CSV: one row per mesh with its latent, PCA and t-SNE coordinates (`points`). `label` is
/// last (so the earlier columns keep their positions) and always present, empty for a set
/// without labels, so that the schema is fixed.
fn csv(names: &[String], points: [&[[f64; 2]]; 3], labels: Option<&[String]>) -> String {
    let mut out = String::from("name,frame,latent_x,latent_y,pca_x,pca_y,tsne_x,tsne_y,label\n");
    for (i, name) in names.iter().enumerate() {
        out += &csv_field(name);
        out += &format!(",{i}");
        for p in points {
            let [x, y] = p.get(i).copied().unwrap_or([f64::NAN; 2]);
            out += &format!(",{x},{y}");
        }
        let label = labels
            .and_then(|l| l.get(i))
            .map_or(String::new(), |l| csv_field(l));
        out += &format!(",{label}\n");
    }
    out
}

/// One plot: a labelled set gets one colour per label (with a legend), each label's meshes
/// joined in frame order if `joined`; an unlabelled set one series coloured by frame order.
fn plot(
    title: &str,
    (x, y): (&str, &str),
    points: &[[f64; 2]],
    labels: Option<&[String]>,
    joined: bool,
) -> Result<mesh_render::Image, CliError> {
    let point = |i: usize| points[i].map(|v| v as f32);
    let series: Vec<mesh_render::Series> = match labels {
        Some(labels) if labels.len() == points.len() => {
            let mut distinct: Vec<&String> = Vec::new();
            for l in labels {
                if !distinct.contains(&l) {
                    distinct.push(l);
                }
            }
            distinct
                .iter()
                .map(|&name| mesh_render::Series {
                    name: name.clone(),
                    points: (0..points.len())
                        .filter(|&i| &labels[i] == name)
                        .map(point)
                        .collect(),
                    joined,
                    color_by_order: false,
                })
                .collect()
        }
        _ => vec![mesh_render::Series {
            name: String::new(),
            points: (0..points.len()).map(point).collect(),
            joined,
            color_by_order: true,
        }],
    };
    Ok(mesh_render::scatter(title, x, y, &series, PLOT.0, PLOT.1)?)
}

pub fn run(args: &EmbedArgs) -> Result<(), CliError> {
    if !(args.perplexity.is_finite() && args.perplexity > 1.0) {
        return Err(CliError::argument(
            "--perplexity",
            format!("{} is not above 1", args.perplexity),
        ));
    }
    let (trained, set) = model_and_set(&args.model, args.set.as_ref())?;
    let options = EmbedOptions {
        perplexity: args.perplexity,
        seed: args.seed,
        ..EmbedOptions::default()
    };
    let e = meshvae::embed(&trained, &set, &options)?;
    let [d0, d1] = e.latent_dims;
    let joined = match args.lines {
        Lines::Auto => is_sequence(&e.pca_2d),
        Lines::Always => true,
        Lines::Never => false,
    };
    let images = [
        plot(
            "latent means (largest-variance dimensions)",
            (&format!("z[{d0}]"), &format!("z[{d1}]")),
            &e.latent_2d,
            set.labels(),
            joined,
        )?,
        plot(
            "PCA of the raw features",
            (
                &format!("PC 1 ({:.0} %)", 100.0 * e.pca_explained[0]),
                &format!("PC 2 ({:.0} %)", 100.0 * e.pca_explained[1]),
            ),
            &e.pca_2d,
            set.labels(),
            joined,
        )?,
        plot(
            &format!("t-SNE of the raw features (perplexity {:.1})", e.perplexity),
            ("t-SNE 1", "t-SNE 2"),
            &e.tsne_2d,
            set.labels(),
            joined,
        )?,
    ];
    let picture = mesh_render::hstack(&images)?;

    create_out(&args.out)?;
    write_text(
        &args.out.join("embedding.csv"),
        &csv(
            &e.names,
            [&e.latent_2d, &e.pca_2d, &e.tsne_2d],
            set.labels(),
        ),
    )?;
    write_png(&args.out.join("embedding.png"), &picture)?;
    out!(
        "wrote embedding.csv and embedding.png ({} meshes{}) to {}",
        e.names.len(),
        if joined {
            ", joined in file order"
        } else {
            ", not joined: file order is not a sequence (--lines always joins them)"
        },
        args.out.display()
    );
    // How loop-like each embedding is in frame order (see meshvae::LoopMeasure).
    for (label, points) in [
        ("latent", &e.latent_2d),
        ("PCA", &e.pca_2d),
        ("t-SNE", &e.tsne_2d),
    ] {
        if let Ok(m) = loop_measure(points) {
            out!(
                "  {label:<6} loop measure: {:.0} % of consecutive steps shorter than the median \
                 pair, closing step {:.2} × the median step{}",
                100.0 * m.nearer,
                m.closing,
                if m.is_loop() { " (a closed loop)" } else { "" }
            );
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_loop_is_a_sequence_and_a_shuffled_one_is_not() {
        let circle: Vec<[f64; 2]> = (0..48)
            .map(|i| {
                let a = i as f64 * std::f64::consts::TAU / 48.0;
                [a.cos(), a.sin()]
            })
            .collect();
        assert!(is_sequence(&circle));
        // The same points visited by a stride of 17 (coprime with 48): every step long.
        let shuffled: Vec<[f64; 2]> = (0..48).map(|i| circle[(i * 17) % 48]).collect();
        assert!(!is_sequence(&shuffled));
    }

    #[test]
    fn the_csv_has_a_label_column_filled_only_for_a_labelled_set() {
        let names = ["a".to_string(), "b,c".to_string()];
        let points: [&[[f64; 2]]; 3] = [
            &[[0.5, -1.0], [2.0, 3.0]],
            &[[1.0, 2.0], [3.0, 4.0]],
            &[[-1.0, 1.0], [0.25, 0.0]],
        ];
        let header = "name,frame,latent_x,latent_y,pca_x,pca_y,tsne_x,tsne_y,label";
        let labels = ["bend".to_string(), "a \"b\", c".to_string()];
        assert_eq!(
            csv(&names, points, Some(&labels)),
            format!(
                "{header}\na,0,0.5,-1,1,2,-1,1,bend\n\"b,c\",1,2,3,3,4,0.25,0,\"a \"\"b\"\", c\"\n"
            )
        );
        assert_eq!(
            csv(&names, points, None),
            format!("{header}\na,0,0.5,-1,1,2,-1,1,\n\"b,c\",1,2,3,3,4,0.25,0,\n")
        );
    }
}
