//! The "The paper's claims" section: for every other column, on each data set, on how many of
//! the seeds both finished ours has the lower test RMS, the change on their mean, and the
//! verdict that follows (holds on every seed, does not hold on any, not settled between), with
//! ours' rank among the ablation columns on each seed. Generated, so that no sentence of the
//! hand-written notes has to state a figure that a new record would change.

use super::{columns_of, paired, percent};
use crate::reproduce::Outcome;
use crate::reproduce::paper;
use crate::reproduce::plan::{Group, OURS};
use crate::reproduce::record::RunResult;
use std::fmt::Write;

/// Seeds on which ours is below `column` on `dataset`, and the seeds both have.
pub(super) fn wins(results: &[RunResult], dataset: &str, column: &str) -> (usize, usize) {
    let rms = |col: &str, seed: u64| {
        (results.iter())
            .find(|r| r.dataset == dataset && r.column == col && r.seed == seed)
            .map(|r| r.test_rms)
    };
    let (mut below, mut both) = (0, 0);
    for r in results
        .iter()
        .filter(|r| r.dataset == dataset && r.column == OURS)
    {
        if let Some(other) = rms(column, r.seed) {
            both += 1;
            below += usize::from(r.test_rms < other);
        }
    }
    (below, both)
}

/// Whether ours is below another network on the seeds both have finished.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Verdict {
    NoSharedSeed,
    /// Below on every shared seed.
    Holds,
    /// Below on none.
    DoesNotHold,
    /// Below on some: the seeds still to run cannot settle it either way.
    NotSettled,
}

impl Verdict {
    /// The verdict for ours below the other on `below` of `both` shared seeds.
    pub(super) fn of(below: usize, both: usize) -> Self {
        match (below, both) {
            (_, 0) => Self::NoSharedSeed,
            (b, n) if b == n => Self::Holds,
            (0, _) => Self::DoesNotHold,
            _ => Self::NotSettled,
        }
    }
}

/// "holds", "does not hold" or "not settled" for ours below the other on `below` of `both`
/// seeds, of the `planned` seeds: a verdict of fewer seeds than planned is one "so far" (the
/// seeds still to run may undo it; a mixed one is settled already).
pub(super) fn verdict(below: usize, both: usize, planned: u64) -> &'static str {
    let partial = (both as u64) < planned;
    match (Verdict::of(below, both), partial) {
        (Verdict::NoSharedSeed, _) => "no shared seed",
        (Verdict::Holds, true) => "**holds** so far",
        (Verdict::Holds, false) => "**holds**",
        (Verdict::DoesNotHold, true) => "**does not hold** so far",
        (Verdict::DoesNotHold, false) => "**does not hold**",
        (Verdict::NotSettled, _) => "not settled",
    }
}

/// Ours' rank (1 = lowest test RMS) among the ablation columns finished on `seed`.
pub(super) fn rank(results: &[RunResult], dataset: &str, seed: u64) -> Option<(usize, usize)> {
    let rms = |col: &str| {
        (results.iter())
            .find(|r| r.dataset == dataset && r.column == col && r.seed == seed)
            .map(|r| r.test_rms)
    };
    let ours = rms(OURS)?;
    let all: Vec<f64> = columns_of(Group::Ablation)
        .filter_map(|c| rms(c.id))
        .collect();
    Some((all.iter().filter(|&&x| x < ours).count() + 1, all.len()))
}

pub(super) fn claims(md: &mut String, o: &Outcome) {
    md.push_str(
        "## The paper's claims\n\nOurs against every other column: on how many of the seeds \
         both have finished ours has the lower test RMS, and (ours − other) / other on their \
         mean. A claim **holds** on a data set when ours is lower on every such seed, **does \
         not hold** when on none (\"so far\" while seeds are missing), and is not settled in \
         between: a column's spread over the \
         seeds is as large as the paper's margins between columns, so only a gap that keeps \
         its sign on every split settles anything.\n\n| ours against | paper |",
    );
    for set in &o.sets {
        let _ = write!(md, " {} |", set.dataset.name);
    }
    md.push_str("\n|---|---:|");
    md.push_str(&"---|".repeat(o.sets.len()));
    md.push('\n');
    let others = columns_of(Group::Ablation)
        .chain(columns_of(Group::Structure))
        .filter(|c| !c.is_ours());
    for column in others {
        let claim = (column.paper)
            .and_then(|p| paper::CLAIMS.iter().find(|(c, _)| *c == p))
            .map(|(_, v)| format!("{v:+.2} %"))
            .or_else(|| column.paper.map(|p| percent(paper::table_mean_change(p))))
            .unwrap_or_else(|| "—".into());
        let _ = write!(md, "| {} | {claim} |", column.label);
        for set in &o.sets {
            let name = set.dataset.name;
            let (below, both) = wins(&o.results, name, column.id);
            match paired(&o.results, name, OURS, column.id) {
                Some(p) if both > 0 => {
                    let _ = write!(
                        md,
                        " {}: {below} of {both}, {} |",
                        verdict(below, both, o.options.seeds),
                        percent(p.change())
                    );
                }
                _ => md.push_str(" — |"),
            }
        }
        md.push('\n');
    }
    md.push_str(
        "\n\"paper\": the paper's stated average improvement where it states one, else the \
         average its own table gives.\n\n",
    );
    for set in &o.sets {
        let name = set.dataset.name;
        let mut seeds: Vec<u64> = (o.results.iter())
            .filter(|r| r.dataset == name && r.column == OURS)
            .map(|r| r.seed)
            .collect();
        seeds.sort_unstable();
        let ranks: Vec<String> = seeds
            .iter()
            .filter_map(|&s| {
                rank(&o.results, name, s).map(|(r, n)| format!("{r} of {n} on seed {s}"))
            })
            .collect();
        if !ranks.is_empty() {
            let _ = writeln!(
                md,
                "- Ours' rank among the ablation columns on {name}: {}.",
                ranks.join(", ")
            );
        }
    }
    md.push('\n');
}

#[cfg(test)]
mod tests {
    use super::verdict;

    #[test]
    fn a_claim_holds_only_on_every_seed() {
        assert_eq!(verdict(3, 3, 3), "**holds**");
        assert_eq!(verdict(0, 3, 3), "**does not hold**");
        assert_eq!(verdict(2, 3, 3), "not settled");
        assert_eq!(verdict(0, 0, 3), "no shared seed");
        // Fewer seeds than planned: a one-sided count may still turn.
        assert_eq!(verdict(1, 1, 3), "**holds** so far");
        assert_eq!(verdict(0, 2, 3), "**does not hold** so far");
        assert_eq!(verdict(1, 2, 3), "not settled");
    }
}
