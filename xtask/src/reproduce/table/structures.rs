//! The "Network structures" section: our pooling with more poolings (the paper's
//! `table:structure_compare`), beside the paper's SCAPE numbers.

use super::{aggregate, columns_of};
use crate::reproduce::Outcome;
use crate::reproduce::paper;
use crate::reproduce::plan::{Column, Group};
use crate::reproduce::stats::sig;
use std::fmt::Write;

pub(super) fn structures(md: &mut String, o: &Outcome) {
    md.push_str(
        "## Network structures\n\nOur pooling with more poolings (`table:structure_compare`): \
         test RMS, mean dist in brackets; the paper's numbers are for SCAPE only.\n\n| data \
         set |",
    );
    // The paper's order: the alternatives first, ours last.
    let mut columns: Vec<&Column> = columns_of(Group::Structure).collect();
    columns.sort_by_key(|c| c.is_ours());
    for c in &columns {
        let _ = write!(md, " {} |", c.structure);
    }
    md.push_str("\n|---|");
    md.push_str(&"---:|".repeat(columns.len()));
    md.push('\n');
    for set in &o.sets {
        let name = set.dataset.name;
        let _ = write!(md, "| {name} (ours) |");
        for c in &columns {
            let cell = aggregate(&o.results, name, c.id).map_or("not run".into(), |a| {
                format!("{} ({})", a.rms.show(), sig(a.mean_distance.mean))
            });
            let _ = write!(md, " {cell} |");
        }
        md.push('\n');
    }
    let (dataset, values) = paper::STRUCTURES;
    let _ = write!(md, "| {dataset} (paper) |");
    for c in &columns {
        let v = values.iter().find(|(s, _)| *s == c.structure);
        let _ = write!(md, " {} |", v.map_or("—".into(), |(_, v)| v.to_string()));
    }
    md.push_str("\n\n");
}
