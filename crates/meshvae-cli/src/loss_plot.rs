//! `loss.png` in a model folder: the training, validation and test losses of `log.jsonl`
//! against optimizer steps (log scale), with the chosen checkpoint and every learning-rate cut
//! marked.

use crate::CliError;
use mesh_render::{Curve, LinePlot, Marker, line_plot};
use meshvae::{EpochRecord, ModelFolder, read_log};
use std::path::PathBuf;

/// Draws `loss.png` from the folder's log and returns its path.
pub fn write_loss_plot(folder: &ModelFolder) -> Result<PathBuf, CliError> {
    let log = read_log(&folder.log())?;
    let status = meshvae::read_status(folder)?;
    // Older folders without run.json: the epoch of the lowest validation (or training) loss.
    let best_epoch = match &status {
        Some(s) => s.best_epoch,
        None => log
            .iter()
            .min_by(|a, b| {
                let score = |r: &EpochRecord| r.val_loss.unwrap_or(r.train_loss);
                score(a).total_cmp(&score(b))
            })
            .map_or(0, |r| r.epoch),
    };
    let image = draw(&log, best_epoch)?;
    let path = folder.loss_plot();
    image.save_png(&path)?;
    Ok(path)
}

/// [`write_loss_plot`] unless `loss.png` is already newer than the log.
pub fn refresh_loss_plot(folder: &ModelFolder) -> Result<PathBuf, CliError> {
    let path = folder.loss_plot();
    let modified = |p: &std::path::Path| std::fs::metadata(p).and_then(|m| m.modified()).ok();
    match (modified(&path), modified(&folder.log())) {
        (Some(png), Some(log)) if png >= log => Ok(path),
        _ => write_loss_plot(folder),
    }
}

/// The step of a record (older logs count epochs only: then one step per epoch is assumed).
fn step_of(r: &EpochRecord) -> f64 {
    if r.step > 0 {
        r.step as f64
    } else {
        r.epoch as f64
    }
}

fn draw(log: &[EpochRecord], best_epoch: usize) -> Result<mesh_render::Image, CliError> {
    let positive = |v: f64| v.is_finite() && v > 0.0;
    let curve = |name: &str, value: &dyn Fn(&EpochRecord) -> Option<f64>| Curve {
        name: name.into(),
        points: log
            .iter()
            .filter_map(|r| value(r).filter(|&v| positive(v)).map(|v| [step_of(r), v]))
            .collect(),
    };
    let curves: Vec<Curve> = [
        curve("train, total", &|r| Some(r.train_loss)),
        curve("train, reconstruction", &|r| Some(r.rec)),
        curve("validation (chooses the weights)", &|r| r.val_loss),
        curve("test (only watched)", &|r| r.test_loss),
    ]
    .into_iter()
    .filter(|c| !c.points.is_empty())
    .collect();
    let mut markers = Vec::new();
    if let Some(best) = log.iter().find(|r| r.epoch == best_epoch) {
        markers.push(Marker {
            x: step_of(best),
            label: format!("chosen: epoch {best_epoch}"),
            dashed: false,
        });
    }
    // Cuts and rollbacks halve the rate at once; a decay lowers it a little every epoch, which
    // is no event to mark (a cosine over 16 epochs or more never falls below 0.77 of the
    // previous epoch's rate in one).
    for pair in log.windows(2) {
        if let (Some(a), Some(b)) = (pair[0].lr, pair[1].lr)
            && b < a * 0.55
        {
            markers.push(Marker {
                x: step_of(&pair[1]),
                label: format!("lr {b:.1e}"),
                dashed: true,
            });
        }
    }
    let plot = LinePlot {
        title: "losses during training",
        x_label: "optimizer step",
        y_label: "loss (log scale)",
        log_y: true,
        width: 1000,
        height: 600,
    };
    Ok(line_plot(&plot, &curves, &markers)?)
}
