//! `meshvae embed`: 2-D embeddings of every mesh of the set — the latent means by their two
//! most varying dimensions (as the paper), and PCA and t-SNE of the raw features — as a CSV and
//! three scatter plots side by side, points coloured by label (labelled sets) or by frame order,
//! joined in frame order.

use crate::CliError;
use crate::generate::{create_out, csv_field, model_and_set, write_png, write_text};
use meshvae::{EmbedOptions, Embedding, loop_measure};
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
}

/// Pixels of each of the three plots.
const PLOT: (u32, u32) = (560, 520);

fn csv(e: &Embedding) -> String {
    let mut out = String::from("name,frame,latent_x,latent_y,pca_x,pca_y,tsne_x,tsne_y\n");
    for (i, name) in e.names.iter().enumerate() {
        let [lx, ly] = e.latent_2d[i];
        let [px, py] = e.pca_2d[i];
        let [tx, ty] = e.tsne_2d[i];
        out += &format!("{},{i},{lx},{ly},{px},{py},{tx},{ty}\n", csv_field(name));
    }
    out
}

/// One plot: a labelled set gets one colour per label (with a legend), each label's meshes
/// joined in frame order; an unlabelled set one series coloured and joined in frame order.
fn plot(
    title: &str,
    x: &str,
    y: &str,
    points: &[[f64; 2]],
    labels: Option<&[String]>,
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
                    joined: true,
                    color_by_order: false,
                })
                .collect()
        }
        _ => vec![mesh_render::Series {
            name: String::new(),
            points: (0..points.len()).map(point).collect(),
            joined: true,
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
    let images = [
        plot(
            "latent means (largest-variance dimensions)",
            &format!("z[{d0}]"),
            &format!("z[{d1}]"),
            &e.latent_2d,
            set.labels(),
        )?,
        plot(
            "PCA of the raw features",
            &format!("PC 1 ({:.0} %)", 100.0 * e.pca_explained[0]),
            &format!("PC 2 ({:.0} %)", 100.0 * e.pca_explained[1]),
            &e.pca_2d,
            set.labels(),
        )?,
        plot(
            &format!("t-SNE of the raw features (perplexity {:.1})", e.perplexity),
            "t-SNE 1",
            "t-SNE 2",
            &e.tsne_2d,
            set.labels(),
        )?,
    ];
    let picture = mesh_render::hstack(&images)?;

    create_out(&args.out)?;
    write_text(&args.out.join("embedding.csv"), &csv(&e))?;
    write_png(&args.out.join("embedding.png"), &picture)?;
    println!(
        "wrote embedding.csv and embedding.png ({} meshes) to {}",
        e.names.len(),
        args.out.display()
    );
    // How loop-like each embedding is in frame order (see meshvae::LoopMeasure).
    for (label, points) in [
        ("latent", &e.latent_2d),
        ("PCA", &e.pca_2d),
        ("t-SNE", &e.tsne_2d),
    ] {
        if let Ok(m) = loop_measure(points) {
            println!(
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
