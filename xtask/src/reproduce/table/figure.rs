//! The page's pictures: one dot plot per data set, every network's error on each seed beside
//! the paper's figure for ours, so that a reader sees at a glance how far apart the seeds are
//! compared with the gaps between networks. Written beside the page as
//! `<page>-<data set>.png`.

use crate::reproduce::plan::{COLUMNS, OURS};
use crate::reproduce::record::RunResult;
use crate::reproduce::{Outcome, ReproError, paper};
use mesh_render::{DotPlot, DotRow, Marker, dot_plot};
use std::path::{Path, PathBuf};

/// The picture of `dataset` beside `page`: `docs/results.md` → `docs/results-samba.png`.
pub fn path(page: &Path, dataset: &str) -> PathBuf {
    let stem = page
        .file_stem()
        .map_or_else(|| "results".into(), |s| s.to_string_lossy().into_owned());
    page.with_file_name(format!("{stem}-{dataset}.png"))
}

/// The file name of [`path`], as the page links it.
pub fn file_name(page: &Path, dataset: &str) -> String {
    path(page, dataset)
        .file_name()
        .map_or_else(String::new, |n| n.to_string_lossy().into_owned())
}

/// Whether the page has a picture of `dataset`: some run of it has finished.
pub fn has_figure(o: &Outcome, dataset: &str) -> bool {
    o.results.iter().any(|r| r.dataset == dataset)
}

/// Writes the picture of every data set with a finished run (atomically; a file whose bytes
/// would not change is left alone).
pub fn write_figures(o: &Outcome) -> Result<(), ReproError> {
    for set in &o.sets {
        let name = set.dataset.name;
        if !has_figure(o, name) {
            continue;
        }
        let file = path(&o.options.results, name);
        let png = figure(o, name)
            .and_then(|image| image.encode_png())
            .map_err(|e| ReproError::io(&file, e))?;
        if std::fs::read(&file).is_ok_and(|old| old == png) {
            continue;
        }
        mesh_io::atomic::write_bytes_atomic(&file, &png).map_err(|e| ReproError::io(&file, e))?;
    }
    Ok(())
}

/// Every column with a finished run on `dataset`, a row each in the tables' order, a dot per
/// seed: the rigidly aligned mean distance where every run of the set has it, else test RMS.
fn figure(o: &Outcome, dataset: &str) -> Result<mesh_render::Image, mesh_render::RenderError> {
    let runs: Vec<&RunResult> = (o.results.iter())
        .filter(|r| r.dataset == dataset)
        .collect();
    let rigid = runs.iter().all(|r| r.test_mean_distance_rigid.is_some());
    let value = |r: &RunResult| match rigid {
        true => r.test_mean_distance_rigid.unwrap_or(r.test_rms),
        false => r.test_rms,
    };
    let rows: Vec<DotRow> = COLUMNS
        .iter()
        .filter(|c| runs.iter().any(|r| r.column == c.id))
        .map(|c| DotRow {
            label: c.label.replace("**", "").replace('`', ""),
            values: (1..=o.options.seeds)
                .map(|s| {
                    (runs.iter())
                        .find(|r| r.column == c.id && r.seed == s)
                        .map(|r| value(r))
                })
                .collect(),
        })
        .collect();
    let mut markers = Vec::new();
    if rigid
        && let Some(row) = paper::matching_row(dataset)
            .and_then(|r| paper::FRAMEWORKS.iter().find(|f| f.dataset == r))
    {
        let scale = paper::copy_scale(dataset);
        markers.push(Marker {
            x: row.ours * scale.unwrap_or(1.0),
            label: format!(
                "paper, ours on {}{}",
                row.dataset,
                if scale.is_some() { " (our units)" } else { "" }
            ),
            dashed: true,
        });
    }
    let seeds: Vec<String> = (1..=o.options.seeds).map(|s| format!("seed {s}")).collect();
    let names: Vec<&str> = seeds.iter().map(String::as_str).collect();
    let title = format!("{dataset}: every run's error on the test meshes, seed by seed");
    let x_label = match rigid {
        true => "mean distance after rigid alignment (mesh units); bar: mean over seeds",
        false => "test RMS (mesh units); bar: mean over seeds",
    };
    let plot = DotPlot {
        title: &title,
        x_label,
        value_names: &names,
        width: 900,
        height: 150 + 28 * rows.len() as u32,
    };
    dot_plot(&plot, &rows, &markers)
}

/// The markdown line that shows the picture of `dataset`.
pub fn link(o: &Outcome, dataset: &str) -> String {
    format!(
        "![{dataset}: every network's error on each seed, {OURS} beside the others]({})\n\n",
        file_name(&o.options.results, dataset)
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_picture_sits_beside_its_page() {
        let page = Path::new("docs/results-split-by-mesh.md");
        assert_eq!(
            path(page, "samba"),
            Path::new("docs/results-split-by-mesh-samba.png")
        );
        assert_eq!(
            file_name(page, "horse-gallop"),
            "results-split-by-mesh-horse-gallop.png"
        );
    }
}
