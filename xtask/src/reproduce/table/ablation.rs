//! The "Ablation on …" sections, one per data set: every ablation column's numbers beside ours,
//! ours' error on test shapes whose copies train, and whether ours has the lowest test RMS.

use super::{aggregate, columns_of, paired, percent};
use crate::reproduce::paper;
use crate::reproduce::plan::{Group, OURS};
use crate::reproduce::record::RunResult;
use crate::reproduce::stats::thousands;
use crate::reproduce::{LoadedSet, Outcome};
use std::fmt::Write;

pub(super) fn ablation(md: &mut String, o: &Outcome, set: &LoadedSet) {
    let name = set.dataset.name;
    let _ = writeln!(md, "## Ablation on {name}\n");
    md.push_str(
        "| network | test RMS | rel | mean dist | mean dist, rigid | train RMS | params (no \
         biases) | ours against it | test RMS, selected on test |\n\
         |---|---:|---:|---:|---:|---:|---:|---:|---:|\n",
    );
    let ours = aggregate(&o.results, name, OURS);
    let mut mean_shape = None;
    for column in columns_of(Group::Ablation) {
        let Some(a) = aggregate(&o.results, name, column.id) else {
            let _ = writeln!(md, "| {} | not run | | | | | | | |", column.label);
            continue;
        };
        let against = match paired(&o.results, name, OURS, column.id) {
            Some(p) if !column.is_ours() => p.show_change(),
            _ => "—".into(),
        };
        let _ = writeln!(
            md,
            "| {} | {} | {} | {} | {} | {} | {} | {} | {} |",
            column.label,
            a.rms.show(),
            a.rel.show(),
            a.mean_distance.show(),
            a.mean_distance_rigid.map_or("—".into(), |s| s.show()),
            a.train_rms.show(),
            thousands(a.params_without_biases),
            against,
            a.rms_on_test.map_or("—".into(), |s| s.show()),
        );
        mean_shape.get_or_insert(a.mean_shape);
    }
    if let Some(m) = mean_shape {
        let against = ours.as_ref().map_or("—".into(), |ours| {
            percent(paper::relative_change(ours.rms.mean, m.mean))
        });
        let _ = writeln!(
            md,
            "| mean training shape (trivial predictor) | {} | | | | | | {against} | |",
            m.show()
        );
    }
    md.push('\n');
    copies(md, o, name);
    verdict(md, o, name);
}

/// Where test shapes have copies among the training meshes (halves drawn mesh by mesh on
/// horse-gallop): ours' error on those (memory) and on the unseen poses (generalisation).
fn copies(md: &mut String, o: &Outcome, dataset: &str) {
    let runs: Vec<&RunResult> = o
        .results
        .iter()
        .filter(|r| r.dataset == dataset && r.column == OURS)
        .collect();
    let Some((copy, unseen)) = aggregate(&o.results, dataset, OURS).and_then(|a| a.copies) else {
        return;
    };
    let counts: Vec<String> = runs
        .iter()
        .filter_map(|r| {
            let c = r.copy_split?;
            Some(format!(
                "seed {} {} of {}",
                r.seed,
                c.copy_in_training_meshes,
                c.copy_in_training_meshes + c.unseen_meshes
            ))
        })
        .collect();
    let _ = writeln!(
        md,
        "Test meshes whose copy is among the training meshes ({}): ours reaches a rigid mean \
         distance of {} on them (memory) and {} on the other, unseen poses (generalisation); \
         a seed's figure depends on how many copies its split trains.\n",
        counts.join(", "),
        copy.show(),
        unseen.show()
    );
}

/// Whether ours has the lowest RMS of the ablation columns on `dataset`, and if not, which
/// column beats it and whether by more than the spread over seeds.
fn verdict(md: &mut String, o: &Outcome, dataset: &str) {
    if aggregate(&o.results, dataset, OURS).is_none() {
        return;
    }
    let mut below = Vec::new();
    for column in columns_of(Group::Ablation).filter(|c| !c.is_ours()) {
        if let Some(p) = paired(&o.results, dataset, OURS, column.id)
            && p.it.mean < p.ours.mean
        {
            let spread = match (p.it.std, p.ours.std) {
                (Some(x), Some(y)) => Some(x.max(y)),
                _ => None,
            };
            let how = match spread {
                None => "one seed: no spread to compare with".to_string(),
                Some(s) if p.ours.mean - p.it.mean <= s => {
                    "within one standard deviation".to_string()
                }
                Some(_) => "by more than one standard deviation".to_string(),
            };
            let on = if p.partial {
                format!(" on {}", p.seed_list())
            } else {
                String::new()
            };
            below.push(format!(
                "{} ({} against ours {}{on}; {how})",
                column.label,
                p.it.show(),
                p.ours.show(),
            ));
        }
    }
    let columns = columns_of(Group::Ablation).count();
    let finished = columns_of(Group::Ablation)
        .filter(|c| aggregate(&o.results, dataset, c.id).is_some())
        .count();
    if finished == 1 {
        let _ = writeln!(
            md,
            "On {dataset}, no other ablation column has finished a run yet: nothing to rank.\n"
        );
    } else if below.is_empty() && finished < columns {
        let _ = writeln!(
            md,
            "On {dataset}, ours has the lowest test RMS of the {finished} ablation columns \
             finished so far (of {columns}).\n"
        );
    } else if below.is_empty() {
        let _ = writeln!(
            md,
            "On {dataset}, ours has the lowest test RMS of the ablation columns.\n"
        );
    } else {
        let _ = writeln!(
            md,
            "On {dataset}, ours is **not** the lowest. Below it: {}. See the hand-written \
             notes for why.\n",
            below.join("; ")
        );
    }
}
