//! The "Ordering of the columns" section: the paper's ablation columns from lowest to highest
//! error, in the paper's order and in ours on each data set, with the pairs that disagree.

use super::aggregate;
use crate::reproduce::Outcome;
use crate::reproduce::paper::{self, AblationColumn};
use crate::reproduce::plan::COLUMNS;
use std::fmt::Write;

/// The paper's ablation columns ordered by error: the paper's order from its own table (mean
/// over its rows of each column's error relative to ours, so that rows of different scales
/// weigh alike) against ours on each data set, and the pairs on which they disagree.
pub(super) fn ordering(md: &mut String, o: &Outcome) {
    let paper_score = |c: AblationColumn| {
        let sum: f64 = paper::ABLATION
            .iter()
            .map(|row| row.get(c) / row.get(AblationColumn::Ours))
            .sum();
        sum / paper::ABLATION.len() as f64
    };
    let mut paper_order: Vec<AblationColumn> = AblationColumn::ALL.to_vec();
    paper_order.sort_by(|a, b| paper_score(*a).total_cmp(&paper_score(*b)));
    let names = |order: &[AblationColumn]| -> String {
        order
            .iter()
            .map(|c| c.heading())
            .collect::<Vec<_>>()
            .join(" < ")
    };
    md.push_str(
        "## Ordering of the columns

The paper's seven ablation columns from lowest to \
         highest error. The paper's order averages, over its four rows, each column's error \
         divided by ours on that row.

",
    );
    let _ = writeln!(md, "- Paper: {}.", names(&paper_order));
    for set in &o.sets {
        let name = set.dataset.name;
        let mut ours: Vec<(AblationColumn, f64)> = AblationColumn::ALL
            .iter()
            .filter_map(|&c| {
                let col = COLUMNS.iter().find(|col| col.paper == Some(c))?;
                Some((c, aggregate(&o.results, name, col.id)?.rms.mean))
            })
            .collect();
        if ours.len() < 2 {
            continue;
        }
        ours.sort_by(|a, b| a.1.total_cmp(&b.1));
        let order: Vec<AblationColumn> = ours.iter().map(|(c, _)| *c).collect();
        let rank = |list: &[AblationColumn], c: AblationColumn| list.iter().position(|&x| x == c);
        let (mut agree, mut disagree) = (0, Vec::new());
        for (i, &a) in order.iter().enumerate() {
            for &b in &order[i + 1..] {
                // Ours puts a below b; does the paper?
                match (rank(&paper_order, a), rank(&paper_order, b)) {
                    (Some(x), Some(y)) if x < y => agree += 1,
                    _ => disagree.push(format!("{} below {}", a.heading(), b.heading())),
                }
            }
        }
        let _ = writeln!(
            md,
            "- {name}: {} — agrees with the paper on {agree} of {} pairs{}.",
            names(&order),
            agree + disagree.len(),
            if disagree.is_empty() {
                String::new()
            } else {
                format!("; here, unlike the paper: {}", disagree.join("; "))
            }
        );
    }
    md.push('\n');
}
