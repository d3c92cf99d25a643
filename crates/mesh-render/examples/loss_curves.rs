//! Writes an example line plot of training curves: `cargo run -p mesh-render --release --example
//! loss_curves -- OUT.png [WIDTH HEIGHT]`. Train/validation/test losses over 3000 epochs (decaying
//! like 1000·exp(-x/500) + 300, with noise), log y axis, markers "best" and "lr ×0.5". Prints
//! the time of one plot, and of one with 20,000 points per curve.

use mesh_render::{Curve, LinePlot, Marker, line_plot};
use std::time::Instant;

/// A small deterministic generator (xorshift64*) for the noise.
struct Noise(u64);

impl Noise {
    fn uniform(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        (self.0.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Standard normal (Box–Muller).
    fn normal(&mut self) -> f64 {
        let (u, v) = (self.uniform().max(1e-300), self.uniform());
        (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
    }
}

fn curves(n: usize) -> Vec<Curve> {
    let mut noise = Noise(0x9e37_79b9_7f4a_7c15);
    let scale = 3000.0 / n as f64;
    [
        ("train", 300.0, 0.06),
        ("validation", 340.0, 0.03),
        ("test", 355.0, 0.03),
    ]
    .into_iter()
    .map(|(name, floor, sigma)| Curve {
        name: name.into(),
        points: (0..n)
            .map(|i| {
                let x = i as f64 * scale;
                let clean = 1000.0 * (-x / 500.0).exp() + floor;
                [x, clean * (1.0 + sigma * noise.normal()).max(0.05)]
            })
            .collect(),
    })
    .collect()
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let out = args
        .next()
        .ok_or("usage: loss_curves OUT.png [WIDTH HEIGHT]")?;
    let width = args.next().map(|s| s.parse()).transpose()?.unwrap_or(900);
    let height = args.next().map(|s| s.parse()).transpose()?.unwrap_or(540);
    let plot = LinePlot {
        title: "meshvae training: reconstruction loss",
        x_label: "epoch",
        y_label: "loss (MSE × 10⁴)",
        log_y: true,
        width,
        height,
    };
    let markers = [
        Marker {
            x: 1800.0,
            label: "lr ×0.5".into(),
            dashed: true,
        },
        Marker {
            x: 2640.0,
            label: "best".into(),
            dashed: false,
        },
    ];
    let data = curves(3000);
    let start = Instant::now();
    let image = line_plot(&plot, &data, &markers)?;
    println!(
        "3 × 3000 points: {:.1} ms",
        start.elapsed().as_secs_f64() * 1e3
    );
    image.save_png(out.as_ref())?;

    let dense = curves(20_000);
    let start = Instant::now();
    line_plot(&plot, &dense, &markers)?;
    println!(
        "3 × 20000 points: {:.1} ms",
        start.elapsed().as_secs_f64() * 1e3
    );
    println!("wrote {out}");
    Ok(())
}
