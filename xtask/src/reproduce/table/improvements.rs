//! The "Relative improvements of ours" section: ours against every other ablation column on test
//! RMS, per data set and averaged, beside the paper's claims and its own table's average.

use super::{columns_of, paired, percent};
use crate::reproduce::Outcome;
use crate::reproduce::paper;
use crate::reproduce::plan::{Group, OURS};
use crate::reproduce::stats::Stat;
use std::fmt::Write;

pub(super) fn improvements(md: &mut String, o: &Outcome) {
    md.push_str(
        "## Relative improvements of ours\n\n(ours − other) / other on test RMS over the seeds \
         both have finished (named where one has more), per data set and averaged over data sets as the paper averages over its four. \"paper's table\" \
         recomputes that average from the paper's own ablation table.\n\n| against | paper's \
         claim | paper's table |",
    );
    for set in &o.sets {
        let _ = write!(md, " {} |", set.dataset.name);
    }
    md.push_str(" mean over ours |\n|---|---:|---:|");
    md.push_str(&"---:|".repeat(o.sets.len() + 1));
    md.push('\n');
    for column in columns_of(Group::Ablation).filter(|c| !c.is_ours()) {
        let claim = column
            .paper
            .and_then(|p| paper::CLAIMS.iter().find(|(c, _)| *c == p))
            .map_or("—".into(), |(_, v)| format!("{v:+.2} %"));
        let table = column
            .paper
            .map_or("—".into(), |p| percent(paper::table_mean_change(p)));
        let _ = write!(md, "| {} | {claim} | {table} |", column.label);
        let mut changes = Vec::new();
        for set in &o.sets {
            let name = set.dataset.name;
            match paired(&o.results, name, OURS, column.id) {
                Some(p) => {
                    changes.push(p.change());
                    let _ = write!(md, " {} |", p.show_change());
                }
                None => md.push_str(" — |"),
            }
        }
        let mean = Stat::of(&changes).map_or("—".into(), |s| percent(s.mean));
        let _ = writeln!(md, " {mean} |");
    }
    md.push('\n');
}
