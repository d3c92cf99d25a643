//! The "Seed by seed" section: every run's test RMS, its rank among the ablation columns of its
//! seed, and on how many seeds ours is below each column. Means over three seeds hide whether a
//! column wins everywhere by a little or on one seed by a lot; the paper's claims are about the
//! former.

use super::{columns_of, figure};
use crate::reproduce::Outcome;
use crate::reproduce::plan::{COLUMNS, Group, OURS};
use crate::reproduce::record::RunResult;
use crate::reproduce::stats::{sig, thousands};
use std::fmt::Write;

/// The section, for every data set with at least one finished run.
pub(super) fn seed_by_seed(md: &mut String, o: &Outcome) {
    let mut wrote_heading = false;
    for set in &o.sets {
        let name = set.dataset.name;
        let runs: Vec<&RunResult> = o.results.iter().filter(|r| r.dataset == name).collect();
        if runs.is_empty() {
            continue;
        }
        if !wrote_heading {
            md.push_str(
                "## Seed by seed\n\nTest RMS of every run; the rank is among the ablation \
                 columns of that seed (1 = lowest, in bold), and \"ours below it\" counts the \
                 seeds on which ours has the lower test RMS.\n\n",
            );
            wrote_heading = true;
        }
        table(md, name, &runs, &figure::link(o, name));
        if let Some(max_steps) = o.options.budget.max_steps() {
            stops(md, &runs, max_steps);
        }
        blowups(md, &runs);
    }
}

fn table(md: &mut String, dataset: &str, runs: &[&RunResult], picture: &str) {
    let mut seeds: Vec<u64> = runs.iter().map(|r| r.seed).collect();
    seeds.sort_unstable();
    seeds.dedup();
    let find = |column: &str, seed: u64| {
        runs.iter()
            .find(|r| r.column == column && r.seed == seed)
            .map(|r| r.test_rms)
    };
    // Rank of each ablation column on each seed (1 = lowest), among the columns that finished.
    let rank = |column: &str, seed: u64| -> Option<usize> {
        let mine = find(column, seed)?;
        let lower = columns_of(Group::Ablation)
            .filter_map(|c| find(c.id, seed))
            .filter(|&x| x < mine)
            .count();
        Some(lower + 1)
    };

    let _ = writeln!(md, "### {dataset}\n");
    md.push_str(picture);
    md.push_str("| network |");
    for s in &seeds {
        let _ = write!(md, " seed {s} |");
    }
    md.push_str(" ranks | ours below it |\n|---|");
    md.push_str(&"---:|".repeat(seeds.len()));
    md.push_str("---|---|\n");

    for column in COLUMNS {
        if !seeds.iter().any(|&s| find(column.id, s).is_some()) {
            continue;
        }
        let ablation = column.group == Group::Ablation;
        let _ = write!(md, "| {} |", column.label);
        for &s in &seeds {
            let cell = match find(column.id, s) {
                None => "—".to_string(),
                Some(x) if ablation && rank(column.id, s) == Some(1) => format!("**{}**", sig(x)),
                Some(x) => sig(x),
            };
            let _ = write!(md, " {cell} |");
        }
        let ranks = if ablation {
            seeds
                .iter()
                .map(|&s| rank(column.id, s).map_or("—".into(), |r| r.to_string()))
                .collect::<Vec<_>>()
                .join(" / ")
        } else {
            String::new()
        };
        let below = if column.is_ours() {
            "—".to_string()
        } else {
            let both: Vec<(f64, f64)> = seeds
                .iter()
                .filter_map(|&s| Some((find(OURS, s)?, find(column.id, s)?)))
                .collect();
            if both.is_empty() {
                String::new()
            } else {
                let wins = both.iter().filter(|(ours, it)| ours < it).count();
                format!("{wins} of {}", both.len())
            }
        };
        let _ = writeln!(md, " {ranks} | {below} |");
    }

    md.push_str("| mean training shape (trivial predictor) |");
    for &s in &seeds {
        let cell = runs
            .iter()
            .find(|r| r.seed == s)
            .map_or("—".into(), |r| sig(r.mean_shape_rms));
        let _ = write!(md, " {cell} |");
    }
    md.push_str(" | |\n\n");

    // Under the validation protocol: how often the two losses choose the same weights.
    let compared: Vec<&&RunResult> = runs
        .iter()
        .filter(|r| r.best_epoch_on_test.is_some())
        .collect();
    if !compared.is_empty() {
        let same = compared
            .iter()
            .filter(|r| r.best_epoch_on_test == Some(r.best_epoch))
            .count();
        let _ = writeln!(
            md,
            "The validation loss and the test loss chose the same epoch in {same} of {} runs.\n",
            compared.len()
        );
    }
}

/// Under the converged plan: which runs did not converge but used up their step budget, so
/// that with the header's counts every run's end is known.
fn stops(md: &mut String, runs: &[&RunResult], max_steps: usize) {
    let mut cut = Vec::new();
    for column in COLUMNS {
        let mut seeds: Vec<u64> = runs
            .iter()
            .filter(|r| r.column == column.id && r.stop_reason.as_deref() == Some("budget"))
            .map(|r| r.seed)
            .collect();
        seeds.sort_unstable();
        if !seeds.is_empty() {
            let seeds: Vec<String> = seeds.iter().map(u64::to_string).collect();
            cut.push(format!("`{}` (seed {})", column.id, seeds.join(", ")));
        }
    }
    let converged = runs.iter().filter(|r| r.converged()).count();
    if cut.is_empty() {
        let _ = writeln!(md, "{converged} of {} runs converged.\n", runs.len());
    } else {
        let _ = writeln!(
            md,
            "Stopped by the {}-step budget before converging: {}; {converged} of {} runs \
             converged.\n",
            thousands(max_steps),
            cut.join(", "),
            runs.len()
        );
    }
}

/// Which runs blew up (a NaN loss, after which training goes on from the best weights at half
/// the rate): such a run may stop higher than it would have, which matters where columns are
/// close. Silent where no record keeps the count.
fn blowups(md: &mut String, runs: &[&RunResult]) {
    let recorded = runs.iter().filter(|r| r.rollbacks.is_some()).count();
    if recorded == 0 {
        return;
    }
    let mut hit = Vec::new();
    let mut runs_hit = 0;
    for column in COLUMNS {
        let mut seeds: Vec<(u64, usize)> = runs
            .iter()
            .filter(|r| r.column == column.id)
            .filter_map(|r| r.rollbacks.filter(|&n| n > 0).map(|n| (r.seed, n)))
            .collect();
        if seeds.is_empty() {
            continue;
        }
        seeds.sort_unstable();
        runs_hit += seeds.len();
        let seeds: Vec<String> = seeds
            .iter()
            .map(|&(seed, n)| match n {
                1 => format!("seed {seed}"),
                n => format!("seed {seed} ×{n}"),
            })
            .collect();
        hit.push(format!("`{}` ({})", column.id, seeds.join(", ")));
    }
    if hit.is_empty() {
        let _ = write!(
            md,
            "No blow-ups (a NaN loss) in the {recorded} runs whose record keeps the count."
        );
    } else {
        let _ = write!(
            md,
            "Blow-ups (the loss went NaN; training went back to its best weights, or its initial \
             ones, at half the rate) in {runs_hit} of the {recorded} runs whose record keeps the count: {}.",
            hit.join(", ")
        );
    }
    let unrecorded = runs.len() - recorded;
    if unrecorded > 0 {
        let _ = write!(
            md,
            " {unrecorded} earlier {} not keep it.",
            if unrecorded == 1 {
                "record does"
            } else {
                "records do"
            }
        );
    }
    md.push_str("\n\n");
}
