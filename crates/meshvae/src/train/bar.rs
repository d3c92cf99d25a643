//! The training progress bar (steps, with the epoch and losses as its message).

use indicatif::{ProgressBar, ProgressStyle};

pub(super) fn progress_bar(show: bool, epochs: usize, done: usize, steps: usize) -> ProgressBar {
    if !show {
        return ProgressBar::hidden();
    }
    let bar = ProgressBar::new((epochs * steps) as u64);
    bar.set_position((done * steps) as u64);
    if let Ok(style) = ProgressStyle::with_template(
        "{bar:30} {pos}/{len} steps  {msg}  [{elapsed_precise} < {eta_precise}]",
    ) {
        bar.set_style(style);
    }
    bar.set_message(format!("epoch {done}/{epochs}"));
    bar
}
