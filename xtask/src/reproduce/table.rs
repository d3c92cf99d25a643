//! The markdown of `docs/results.md`: our numbers (mean ± std over seeds) beside the paper's.

use super::Outcome;
use super::plan::{COLUMNS, Column, Group};
use super::record::RunResult;
use super::stats::Stat;
use std::fmt::Write;

mod ablation;
mod claims;
pub mod figure;
mod frameworks;
mod header;
mod improvements;
mod ordering;
mod paper_layout;
mod parameters;
mod seeds;
mod structures;
pub mod summary;

/// Opens the block of results.md that a regeneration keeps.
pub const BEGIN_HAND_WRITTEN: &str = "<!-- BEGIN hand-written: kept by cargo xtask reproduce -->";
/// Closes it.
pub const END_HAND_WRITTEN: &str = "<!-- END hand-written -->";

/// The hand-written block of an existing results.md (markers included), if it has one.
pub fn hand_written(text: &str) -> Option<&str> {
    let start = text.find(BEGIN_HAND_WRITTEN)?;
    let end = text[start..].find(END_HAND_WRITTEN)? + start + END_HAND_WRITTEN.len();
    Some(&text[start..end])
}

/// One (data set, column) over its seeds.
#[derive(Debug, Clone)]
pub struct Aggregate {
    pub rms: Stat,
    pub rel: Stat,
    pub mean_distance: Stat,
    /// Mean distance after rigid alignment (the authors' measure), where every run recorded it.
    pub mean_distance_rigid: Option<Stat>,
    /// Rigid mean distance of the test meshes whose copy trains, and of the unseen ones, where
    /// every run's split put copies of test shapes among its training meshes.
    pub copies: Option<(Stat, Stat)>,
    pub train_rms: Stat,
    pub mean_shape: Stat,
    /// Test RMS of the weights the test loss would have chosen (validation protocol only).
    pub rms_on_test: Option<Stat>,
    pub params: usize,
    pub params_without_biases: usize,
    pub levels: Vec<usize>,
}

/// The aggregate of `column` on `dataset`, if any run of it finished.
pub fn aggregate(results: &[RunResult], dataset: &str, column: &str) -> Option<Aggregate> {
    let runs: Vec<&RunResult> = results
        .iter()
        .filter(|r| r.dataset == dataset && r.column == column)
        .collect();
    let first = runs.first()?;
    let stat = |f: fn(&RunResult) -> f64| Stat::of(&runs.iter().map(|r| f(r)).collect::<Vec<_>>());
    Some(Aggregate {
        rms: stat(|r| r.test_rms)?,
        rel: stat(|r| r.test_rms_rel)?,
        mean_distance: stat(|r| r.test_mean_distance)?,
        mean_distance_rigid: all_of(&runs, |r| r.test_mean_distance_rigid),
        copies: all_of(&runs, |r| {
            r.copy_split.map(|c| c.copy_in_training_mean_distance_rigid)
        })
        .zip(all_of(&runs, |r| {
            r.copy_split.and_then(|c| c.unseen_mean_distance_rigid)
        })),
        train_rms: stat(|r| r.train_rms)?,
        mean_shape: stat(|r| r.mean_shape_rms)?,
        rms_on_test: Stat::of(
            &runs
                .iter()
                .filter_map(|r| r.test_rms_selected_on_test)
                .collect::<Vec<_>>(),
        ),
        params: first.params,
        params_without_biases: first.params_without_biases,
        levels: first.levels.clone(),
    })
}

/// Ours and another column on `dataset` over the seeds both have finished: comparing a mean
/// over three seeds with one seed's figure would set one split's luck against another's.
#[derive(Debug, Clone)]
pub struct Paired {
    /// Ours' test RMS over the shared seeds.
    pub ours: Stat,
    /// The other column's test RMS over the same seeds.
    pub it: Stat,
    pub seeds: Vec<u64>,
    /// Whether either column has finished seeds the other has not.
    pub partial: bool,
}

impl Paired {
    /// (ours − it) / it in percent, on the shared seeds' mean test RMS.
    pub fn change(&self) -> f64 {
        super::paper::relative_change(self.ours.mean, self.it.mean)
    }

    /// [`Self::change`] as a percentage, naming the seeds when not every finished seed is shared.
    pub fn show_change(&self) -> String {
        let change = percent(self.change());
        if self.partial {
            format!("{change} ({})", self.seed_list())
        } else {
            change
        }
    }

    /// "seed 1" or "seeds 1, 3".
    pub fn seed_list(&self) -> String {
        seed_list(&self.seeds)
    }
}

/// [`Paired`] figures of ours and `column` on `dataset`, if they share a finished seed.
pub fn paired(results: &[RunResult], dataset: &str, ours: &str, column: &str) -> Option<Paired> {
    let rms = |col: &str, seed: u64| {
        results
            .iter()
            .find(|r| r.dataset == dataset && r.column == col && r.seed == seed)
            .map(|r| r.test_rms)
    };
    let mut all: Vec<u64> = results
        .iter()
        .filter(|r| r.dataset == dataset && (r.column == ours || r.column == column))
        .map(|r| r.seed)
        .collect();
    all.sort_unstable();
    all.dedup();
    let (mut seeds, mut a, mut b) = (Vec::new(), Vec::new(), Vec::new());
    let mut partial = false;
    for &seed in &all {
        match (rms(ours, seed), rms(column, seed)) {
            (Some(x), Some(y)) => {
                seeds.push(seed);
                a.push(x);
                b.push(y);
            }
            _ => partial = true,
        }
    }
    Some(Paired {
        ours: Stat::of(&a)?,
        it: Stat::of(&b)?,
        seeds,
        partial,
    })
}

/// The statistic of `f` over `runs` if every run has a value.
fn all_of(runs: &[&RunResult], f: impl Fn(&RunResult) -> Option<f64>) -> Option<Stat> {
    let values: Option<Vec<f64>> = runs.iter().map(|r| f(r)).collect();
    Stat::of(&values?)
}

/// "seed 1" or "seeds 1, 3": how every sentence of the page and the README names seeds.
pub(super) fn seed_list(seeds: &[u64]) -> String {
    let names: Vec<String> = seeds.iter().map(u64::to_string).collect();
    match names.len() {
        1 => format!("seed {}", names[0]),
        _ => format!("seeds {}", names.join(", ")),
    }
}

fn percent(x: f64) -> String {
    format!("{x:+.2} %")
}

/// The whole page.
pub fn markdown(outcome: &Outcome, kept: Option<&str>) -> String {
    let mut md = String::new();
    md.push_str("# Results\n\n");
    md.push_str(
        "<!-- Generated by `cargo xtask reproduce`. Edit only the hand-written block at the end: \
         a regeneration keeps it and replaces everything else. -->\n\n",
    );
    md.push_str(
        "The tables of Yuan et al. 2020 (*Mesh Variational Autoencoders with Edge Contraction \
         Pooling*) reproduced on our data sets, with the paper's numbers beside ours.\n\n",
    );
    header::header(&mut md, outcome);
    for set in &outcome.sets {
        ablation::ablation(&mut md, outcome, set);
    }
    paper_layout::paper_layout(&mut md, outcome);
    ordering::ordering(&mut md, outcome);
    seeds::seed_by_seed(&mut md, outcome);
    improvements::improvements(&mut md, outcome);
    claims::claims(&mut md, outcome);
    structures::structures(&mut md, outcome);
    frameworks::frameworks(&mut md, outcome);
    parameters::parameters(&mut md, outcome);
    md.push_str("## Hand-written notes\n\n");
    match kept {
        Some(block) => {
            md.push_str(block);
            md.push('\n');
        }
        None => {
            let _ = writeln!(md, "{BEGIN_HAND_WRITTEN}\n(none yet)\n{END_HAND_WRITTEN}");
        }
    }
    md
}

fn columns_of(group: Group) -> impl Iterator<Item = &'static Column> {
    COLUMNS
        .iter()
        .filter(move |c| c.group == group || (c.is_ours() && group == Group::Structure))
}

#[cfg(test)]
mod tests;
