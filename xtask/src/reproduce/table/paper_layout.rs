//! The "In the paper's layout" section: the paper's ablation table with our data sets added as
//! rows, our mean distances set beside the paper's printed values.

use super::{Aggregate, aggregate};
use crate::reproduce::Outcome;
use crate::reproduce::paper::{self, AblationColumn};
use crate::reproduce::plan::COLUMNS;
use crate::reproduce::stats::sig;
use std::fmt::Write;

/// The mean distance to set beside the paper's: after rigid alignment (the authors' measure)
/// where the runs recorded it, else after aligning centroids, marked "(c)".
fn paper_measure(a: &Aggregate) -> String {
    match a.mean_distance_rigid {
        Some(r) => sig(r.mean),
        None => format!("{} (c)", sig(a.mean_distance.mean)),
    }
}

pub(super) fn paper_layout(md: &mut String, o: &Outcome) {
    md.push_str(
        "## In the paper's layout\n\nThe paper's ablation table (`table:different_sim`) with \
         our data sets added as rows: our mean dist after rigid alignment (mean over seeds; \
         \"(c)\": runs that recorded only the centroid-aligned one), the paper's values as \
         printed. Columns we do not run yet say so.\n\n| data set |",
    );
    for c in AblationColumn::ALL {
        let _ = write!(md, " {} |", c.heading());
    }
    md.push_str(" max pooling (not in the paper) |\n|---|");
    md.push_str(&"---:|".repeat(AblationColumn::ALL.len() + 1));
    md.push('\n');
    for set in &o.sets {
        let name = set.dataset.name;
        let _ = write!(md, "| {name} (ours) |");
        for c in AblationColumn::ALL {
            let value =
                COLUMNS
                    .iter()
                    .find(|col| col.paper == Some(c))
                    .map_or("not run".into(), |col| {
                        aggregate(&o.results, name, col.id)
                            .map_or("not run".into(), |a| paper_measure(&a))
                    });
            let _ = write!(md, " {value} |");
        }
        let max =
            aggregate(&o.results, name, "max").map_or("not run".into(), |a| paper_measure(&a));
        let _ = writeln!(md, " {max} |");
    }
    for row in paper::ABLATION {
        let _ = write!(md, "| {} (paper) |", row.dataset);
        for c in AblationColumn::ALL {
            let _ = write!(md, " {} |", row.get(c));
        }
        md.push_str(" |\n");
    }
    md.push_str(
        "\nsamba is a sequence of the same subject and template as the paper's Swing; the \
         paper has no Horse row in this table (Horse is in the framework comparison below).\n\n",
    );
}
