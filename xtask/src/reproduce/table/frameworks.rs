//! The "Against other auto-encoders" section: the paper's `table:ERMS` rows for the data sets we
//! have, beside our network on the matching set (the paper's Horse figure in our copy's units).

use super::aggregate;
use crate::reproduce::Outcome;
use crate::reproduce::paper;
use crate::reproduce::plan::OURS;
use crate::reproduce::stats::{sig, thousands};
use std::fmt::Write;

pub(super) fn frameworks(md: &mut String, o: &Outcome) {
    md.push_str(
        "## Against other auto-encoders\n\nThe paper's `table:ERMS` rows for the data sets we \
         have, beside our network on the matching set. Ranjan 2018 is CoMA's whole network; our \
         \"CoMA mesh sampling\" column above is only its pooling inside our network.\n\n| data \
         set | vertices | Tan 2018 | Gao 2018 | Ranjan 2018 | ours (paper) | ours here: mean \
         dist, rigid | ours here: RMS |\n|---|---:|---:|---:|---:|---:|---:|---:|\n",
    );
    for set in &o.sets {
        let name = set.dataset.name;
        let Some(row_name) = paper::matching_row(name) else {
            continue;
        };
        let Some(row) = paper::FRAMEWORKS.iter().find(|r| r.dataset == row_name) else {
            continue;
        };
        let ours = aggregate(&o.results, name, OURS);
        let _ = writeln!(
            md,
            "| {} (paper) / {name} | {} / {} | {} | {} | {} | {} | {} | {} |",
            row.dataset,
            thousands(row.vertices),
            thousands(set.set.vertex_count()),
            row.tan.map_or("out of memory".into(), |v| v.to_string()),
            row.gao,
            row.ranjan,
            paper::copy_scale(name).map_or_else(
                || row.ours.to_string(),
                |k| format!("{} (= {} here)", row.ours, sig(row.ours * k))
            ),
            ours.as_ref().map_or("not run".into(), |a| {
                a.mean_distance_rigid
                    .map_or_else(|| format!("{} (c)", a.mean_distance.show()), |r| r.show())
            }),
            ours.as_ref().map_or("not run".into(), |a| a.rms.show()),
        );
    }
    if o.sets
        .iter()
        .any(|s| paper::copy_scale(s.dataset.name).is_some())
    {
        let _ = writeln!(
            md,
            "\n\"= … here\": the paper's figure in our copy's units. Our horse-gallop is \
             Sumner and Popović's original files scaled by {} about the origin (every vertex of \
             the 48 frames, to 8e-8). Errors in mesh units scale with the set (the features do \
             not change, the reconstructions scale), and the authors' pipeline measures errors \
             on its reconstructions in the files' own units, so the paper's Horse figure is \
             comparable with ours once converted, assuming the authors used the files as \
             distributed.",
            paper::HORSE_COPY_SCALE
        );
    }
    md.push('\n');
}
