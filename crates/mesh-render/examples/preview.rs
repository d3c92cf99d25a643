//! Renders a preview gallery into a folder: `cargo run -p mesh-render --release --example preview
//! -- OUT_DIR [SET_DIR]` (default set: the synthetic capsules). Writes views.png, errors.png,
//! sheet.png and scatter.png, and prints the time of one 512² render.

use mesh_render::*;
use std::path::PathBuf;
use std::time::Instant;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let out = PathBuf::from(args.next().ok_or("usage: preview OUT_DIR [SET_DIR]")?);
    std::fs::create_dir_all(&out)?;
    let set = match args.next() {
        Some(dir) => mesh_io::load_set(dir.as_ref())?.value,
        None => mesh_io::synth::generate(&mesh_io::synth::SynthConfig::default())?.set,
    };
    let faces = set.faces();
    let frames: Vec<&[[f32; 3]]> = set.frames().collect();
    let frame = Bounds::of(&frames);

    let options = RenderOptions::default();
    let mut best = f64::MAX;
    for _ in 0..5 {
        let start = Instant::now();
        render(frames[0], faces, None, &options)?;
        best = best.min(start.elapsed().as_secs_f64());
    }
    println!(
        "512x512 render of {} vertices: best of 5 {:.1} ms",
        frames[0].len(),
        1e3 * best
    );

    let views: Vec<Image> = View::ALL
        .iter()
        .map(|&view| {
            let o = RenderOptions {
                width: 256,
                height: 256,
                view,
                ..Default::default()
            };
            render(frames[0], faces, None, &o)
        })
        .collect::<Result<_, _>>()?;
    hstack(&views)?.save_png(&out.join("views.png"))?;

    let last = frames[frames.len() - 1];
    let errors: Vec<f32> = frames[0]
        .iter()
        .zip(last)
        .map(|(a, b)| (0..3).map(|k| (a[k] - b[k]).powi(2)).sum::<f32>().sqrt())
        .collect();
    let max = errors.iter().copied().fold(0.0, f32::max);
    let colors = error_colors(&errors, max);
    let image = render(frames[0], faces, Some(&colors), &options)?;
    with_colorbar(&image, max, "distance to the last frame")?.save_png(&out.join("errors.png"))?;

    let tiles: Vec<Tile> = frames
        .iter()
        .zip(set.names())
        .take(12)
        .map(|(f, name)| {
            let o = RenderOptions {
                width: 192,
                height: 192,
                frame,
                ..Default::default()
            };
            Ok(Tile {
                image: render(f, faces, None, &o)?,
                caption: name.clone(),
            })
        })
        .collect::<Result<_, RenderError>>()?;
    sheet(&tiles, 4)?.save_png(&out.join("sheet.png"))?;

    let path: Vec<[f32; 2]> = (0..40)
        .map(|i| {
            let t = i as f32 / 39.0 * 6.0;
            [t.cos() * (1.0 + t / 3.0), t.sin() * (1.0 + t / 3.0)]
        })
        .collect();
    let cloud: Vec<[f32; 2]> = (0..60)
        .map(|i| {
            let a = i as f32 * 2.4;
            [
                2.0 + 0.6 * a.cos() * (i as f32 / 60.0),
                -1.5 + 0.6 * a.sin(),
            ]
        })
        .collect();
    let series = [
        Series {
            name: "interpolation".into(),
            points: path,
            joined: true,
            color_by_order: true,
        },
        Series {
            name: "test set".into(),
            points: cloud,
            ..Default::default()
        },
    ];
    let plot = scatter("Latent space", "z1", "z2", &series, 480, 400)?;
    let plot2 = scatter("PCA", "PC 1", "PC 2", &series[1..], 480, 400)?;
    hstack(&[plot, plot2])?.save_png(&out.join("scatter.png"))?;
    Ok(())
}
