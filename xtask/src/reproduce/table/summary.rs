//! A page's summary for the repository's README: per data set, how many runs finished and how
//! they stopped, ours' error beside the paper's figure, ours' rank on each seed, and on how many
//! seeds each of the paper's claims holds. Generated from the same records as the page, so the
//! README's figures cannot drift from it; [`replace_block`] puts it between the README's markers
//! for the page.

use super::claims::{Verdict, rank, verdict, wins};
use super::frameworks::{ROWS, seeds_below};
use super::{aggregate, columns_of, seed_list};
use crate::reproduce::Outcome;
use crate::reproduce::paper;
use crate::reproduce::plan::{Budget, Group, OURS};
use crate::reproduce::stats::{Stat, sig};
use std::fmt::Write;

/// The line that opens the README's block for `page` (its path from the README's folder).
pub fn begin_marker(page: &str) -> String {
    format!("<!-- BEGIN generated from {page} by cargo xtask reproduce -->")
}

/// The line that closes it.
pub fn end_marker(page: &str) -> String {
    format!("<!-- END generated from {page} -->")
}

/// `readme` with the text between `page`'s markers replaced by `summary`, or `None` when it
/// has no such block (a README opts in by holding the two markers).
pub fn replace_block(readme: &str, page: &str, summary: &str) -> Option<String> {
    let (begin, end) = (begin_marker(page), end_marker(page));
    let start = readme.find(&begin)? + begin.len();
    let stop = readme[start..].find(&end)? + start;
    Some(format!(
        "{}\n{}{}",
        &readme[..start],
        summary.trim_end_matches('\n').to_string() + "\n",
        &readme[stop..]
    ))
}

/// The summary of `o`'s page, linked as `page`.
pub fn summary(o: &Outcome, page: &str) -> String {
    let opts = &o.options;
    let split = if opts.by_shape {
        "**Split by shape**, so that every test shape is unseen"
    } else {
        "**Under the paper's split**, random halves drawn mesh by mesh"
    };
    let training = match opts.budget {
        Budget::Converged { .. } => "each run trained until its validation loss converged".into(),
        Budget::Epochs(n) => format!("each run trained for {n} epochs"),
    };
    let measure = match o
        .results
        .iter()
        .all(|r| r.test_mean_distance_rigid.is_some())
    {
        true => "errors are rigidly aligned mean distances (the measure of the paper's figures)",
        false => {
            "errors are rigidly aligned mean distances (the measure of the paper's figures) \
                  where every record has them, else test RMS"
        }
    };
    let mut md = wrap(
        &format!(
            "{split} ([{page}]({page})): {training}; {measure}, mean ± standard deviation over \
             the seeds:"
        ),
        "",
    );
    md.push('\n');
    for set in &o.sets {
        let name = set.dataset.name;
        let mut item = format!(
            "- **{name}**: {}",
            runs_sentence(o, name, set.set.vertex_count())
        );
        if opts.by_shape && !set.repeated_shapes {
            // Its runs are the paper's split's too: that page's summary has the figures.
            item.push_str(
                " It holds no shape twice, so its split by shape is its split mesh by mesh: the \
                 runs and figures are those under the paper's split.",
            );
            md.push_str(&wrap(&item, "  "));
            continue;
        }
        let sentences = [
            ours_sentence(o, name),
            ranks_sentence(o, name),
            claims_sentence(o, name),
            frameworks_sentence(o, name),
        ];
        for text in sentences.into_iter().flatten() {
            item.push(' ');
            item.push_str(&text);
        }
        md.push_str(&wrap(&item, "  "));
    }
    md
}

/// `text` broken at spaces into lines of at most 100 characters (a longer word stands alone),
/// the lines after the first indented by `indent`, as the README's own paragraphs are.
fn wrap(text: &str, indent: &str) -> String {
    const WIDTH: usize = 100;
    let mut out = String::new();
    let mut line = String::new();
    for word in text.split(' ').filter(|w| !w.is_empty()) {
        if !line.trim().is_empty() && line.chars().count() + 1 + word.chars().count() > WIDTH {
            out.push_str(line.trim_end());
            out.push('\n');
            line = indent.to_string();
        } else if !line.trim().is_empty() {
            line.push(' ');
        }
        line.push_str(word);
    }
    out.push_str(line.trim_end());
    out.push('\n');
    out
}

/// "All 39 runs (13 networks × 3 seeds) finished, every one converged." or "12 of 39 …".
fn runs_sentence(o: &Outcome, dataset: &str, vertices: usize) -> String {
    let networks = (o.options.columns.iter())
        .filter(|c| vertices >= c.net.min_vertices())
        .count();
    let planned = networks * o.options.seeds as usize;
    let runs: Vec<_> = (o.results.iter())
        .filter(|r| r.dataset == dataset)
        .collect();
    let finished = runs.len();
    let converged = runs.iter().filter(|r| r.converged()).count();
    let stops = match o.options.budget {
        Budget::Epochs(_) => String::new(),
        Budget::Converged { .. } if converged == finished => match finished {
            1 => "; it converged".into(),
            _ => ", every one converged".into(),
        },
        Budget::Converged { .. } => format!(
            ", {converged} converged and {} cut by the step budget",
            finished - converged
        ),
    };
    if finished == 0 {
        format!("none of the {planned} runs has finished yet.")
    } else if finished == planned {
        format!(
            "all {planned} runs ({networks} networks × {} seeds) finished{stops}.",
            o.options.seeds
        )
    } else {
        let verb = if finished == 1 { "has" } else { "have" };
        format!("{finished} of the {planned} runs {verb} finished so far{stops}.")
    }
}

/// Ours' error, the trivial predictor's, the paper's figure and, where test shapes have copies
/// among the training meshes, ours' error on those and on the unseen ones.
fn ours_sentence(o: &Outcome, dataset: &str) -> Option<String> {
    let agg = aggregate(&o.results, dataset, OURS)?;
    let over = seeds_phrase(&agg.rms, o.options.seeds);
    let mut text = match agg.mean_distance_rigid {
        Some(rigid) => format!(
            "Ours reaches {}{over} (test RMS {}, where the mean training shape scores {})",
            rigid.show(),
            agg.rms.show(),
            agg.mean_shape.show()
        ),
        None => format!(
            "Ours reaches a test RMS of {}{over} (the mean training shape scores {})",
            agg.rms.show(),
            agg.mean_shape.show()
        ),
    };
    let row = paper::matching_row(dataset)
        .and_then(|r| paper::FRAMEWORKS.iter().find(|f| f.dataset == r));
    if let Some(row) = row {
        let _ = write!(
            text,
            ", beside the paper's {} figure of {}",
            row.dataset, row.ours
        );
        match paper::copy_scale(dataset) {
            Some(k) => {
                let _ = write!(text, " ({} in our copy's units)", sig(row.ours * k));
            }
            None => {
                let _ = write!(text, " ({})", paper::matching_note(dataset));
            }
        }
    }
    if let Some((copy, unseen)) = agg.copies {
        let _ = write!(
            text,
            "; {} on test poses whose copy was trained on and {} on unseen ones",
            sig(copy.mean),
            sig(unseen.mean)
        );
    }
    text.push('.');
    Some(text)
}

/// " over seed 1" when fewer seeds than planned have finished; nothing otherwise.
fn seeds_phrase(stat: &Stat, planned: u64) -> String {
    match stat.n {
        n if n as u64 >= planned => String::new(),
        1 => " on one seed".into(),
        n => format!(" on {n} seeds"),
    }
}

/// "Ours ranks 4th, 8th and 1st of the 8 ablation networks on seeds 1, 2, 3."
fn ranks_sentence(o: &Outcome, dataset: &str) -> Option<String> {
    let mut seeds: Vec<u64> = (o.results.iter())
        .filter(|r| r.dataset == dataset && r.column == OURS)
        .map(|r| r.seed)
        .collect();
    seeds.sort_unstable();
    let ranks: Vec<(u64, usize, usize)> = (seeds.iter())
        .filter_map(|&s| rank(&o.results, dataset, s).map(|(r, n)| (s, r, n)))
        .filter(|&(_, _, n)| n > 1)
        .collect();
    let (_, _, n) = *ranks.first()?;
    let all = columns_of(Group::Ablation).count();
    let of = |n: usize| match n == all {
        true => format!("the {n} ablation networks"),
        false => format!("the {n} ablation networks finished"),
    };
    if ranks.iter().all(|&(_, _, m)| m == n) {
        let places: Vec<String> = ranks.iter().map(|&(_, r, _)| ordinal(r)).collect();
        let on: Vec<u64> = ranks.iter().map(|&(s, _, _)| s).collect();
        Some(format!(
            "Ours ranks {} of {} on {}.",
            and_list(&places),
            of(n),
            seed_list(&on)
        ))
    } else {
        let each: Vec<String> = (ranks.iter())
            .map(|&(s, r, n)| format!("{} of {} on seed {s}", ordinal(r), of(n)))
            .collect();
        Some(format!("Ours ranks {}.", and_list(&each)))
    }
}

/// The paper's ablation and structure claims (ours below each other column), counted by
/// verdict on test RMS, seed by seed.
fn claims_sentence(o: &Outcome, dataset: &str) -> Option<String> {
    let others: Vec<_> = (columns_of(Group::Ablation).chain(columns_of(Group::Structure)))
        .filter(|c| !c.is_ours())
        .collect();
    let (mut holds, mut fails, mut open, mut waiting) = (vec![], vec![], 0, 0);
    let mut partial = false;
    for c in &others {
        let (below, both) = wins(&o.results, dataset, c.id);
        partial |= both > 0 && (both as u64) < o.options.seeds;
        match Verdict::of(below, both) {
            Verdict::NoSharedSeed => waiting += 1,
            Verdict::Holds => holds.push(c.label),
            Verdict::DoesNotHold => fails.push(c.label),
            Verdict::NotSettled => open += 1,
        }
    }
    if waiting == others.len() {
        return None;
    }
    let named = |labels: &[&str], verb: &str| match labels.len() {
        0 => format!("0 {verb}"),
        n if n == others.len() => format!("all {n} {verb}"),
        n => format!("{n} {verb} ({})", labels.join("; ")),
    };
    let hold = |n: usize| if n == 1 { "holds" } else { "hold" };
    let mut clauses = vec![
        named(&holds, &format!("{} on every seed", hold(holds.len()))),
        named(&fails, &format!("{} on none", hold(fails.len()))),
        format!(
            "{open} {} not settled",
            if open == 1 { "is" } else { "are" }
        ),
    ];
    if waiting > 0 {
        clauses.push(format!("{waiting} wait for runs"));
    }
    // Said before the counts: every verdict, "hold on none" too, may change with a missing seed.
    let so_far = if partial {
        "so far (seeds are missing): "
    } else {
        ""
    };
    Some(format!(
        "Of the paper's {} claims that ours is below another ablation network or structure \
         (test RMS, seed by seed; the page goes claim by claim), {so_far}{}.",
        others.len(),
        and_list(&clauses)
    ))
}

/// The other auto-encoders: each one's rigid mean distance and on how many seeds ours is lower.
fn frameworks_sentence(o: &Outcome, dataset: &str) -> Option<String> {
    let mut parts = Vec::new();
    for (id, label, _) in ROWS.iter().filter(|(id, _, _)| *id != OURS) {
        let (below, not) = seeds_below(&o.results, dataset, id);
        let both = below.len() + not.len();
        let Some(rigid) = aggregate(&o.results, dataset, id).and_then(|a| a.mean_distance_rigid)
        else {
            continue;
        };
        if both == 0 {
            continue;
        }
        let word = verdict(below.len(), both, o.options.seeds).replace("**", "");
        parts.push(format!(
            "{} {}{}: ours lower on {} of {both} ({word})",
            label.trim_matches('*'),
            rigid.show(),
            seeds_phrase(&rigid, o.options.seeds),
            below.len()
        ));
    }
    if parts.is_empty() {
        return None;
    }
    Some(format!(
        "Against the other auto-encoders, each trained by `meshvae train --net` alike: {}.",
        parts.join("; ")
    ))
}

/// 1 → "1st", 2 → "2nd", 11 → "11th", 23 → "23rd".
fn ordinal(n: usize) -> String {
    let suffix = match (n % 10, n % 100) {
        (_, 11..=13) => "th",
        (1, _) => "st",
        (2, _) => "nd",
        (3, _) => "rd",
        _ => "th",
    };
    format!("{n}{suffix}")
}

/// "a", "a and b", "a, b and c".
fn and_list(items: &[String]) -> String {
    match items {
        [] => String::new(),
        [one] => one.clone(),
        [rest @ .., last] => format!("{} and {last}", rest.join(", ")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::reproduce::table::COLUMNS;
    use crate::reproduce::table::tests::{outcome, result};

    #[test]
    fn ordinals_and_seed_lists_read_as_english() {
        let got: Vec<String> = [1, 2, 3, 4, 11, 12, 13, 21, 22, 23, 101]
            .map(ordinal)
            .into();
        assert_eq!(
            got,
            [
                "1st", "2nd", "3rd", "4th", "11th", "12th", "13th", "21st", "22nd", "23rd", "101st"
            ]
        );
        assert_eq!(seed_list(&[1, 2, 3]), "seeds 1, 2, 3");
        assert_eq!(seed_list(&[2]), "seed 2");
    }

    #[test]
    fn the_block_between_the_markers_is_replaced_and_the_rest_kept() {
        let page = "docs/results.md";
        let readme = format!(
            "intro\n{}\nold figure 0.5\n{}\noutro\n",
            begin_marker(page),
            end_marker(page)
        );
        let new = replace_block(&readme, page, "new figure 0.4\n").unwrap();
        assert_eq!(
            new,
            format!(
                "intro\n{}\nnew figure 0.4\n{}\noutro\n",
                begin_marker(page),
                end_marker(page)
            )
        );
        // Idempotent, and another page's block is not this page's.
        assert_eq!(replace_block(&new, page, "new figure 0.4").unwrap(), new);
        assert_eq!(replace_block(&new, "docs/other.md", "x"), None);
        assert_eq!(replace_block("no markers", page, "x"), None);
    }

    #[test]
    fn the_summary_counts_runs_ranks_and_claims_from_the_records() {
        // Two seeds planned. Ours 0.9 on seed 1 (lowest), 1.05 on seed 2 (above every other
        // column at 1.0): so no claim holds on every seed, none fails on every seed.
        let vertices = outcome(vec![]).sets[0].set.vertex_count();
        let columns: Vec<_> = (COLUMNS.iter())
            .filter(|c| vertices >= c.net.min_vertices())
            .collect();
        let mut results = Vec::new();
        for c in &columns {
            let (one, two) = if c.is_ours() { (0.9, 1.05) } else { (1.0, 1.0) };
            results.push(result(c.id, 1, one));
            results.push(result(c.id, 2, two));
        }
        let o = outcome(results.clone());
        let text = flat(&summary(&o, "docs/results.md"));
        assert!(text.starts_with("**Split by shape**"), "{text}");
        // A set without repeated shapes shares its runs with the paper's split, whose summary
        // gives the figures.
        let mut shared = outcome(results.clone());
        shared.sets[0].repeated_shapes = false;
        let short = flat(&summary(&shared, "docs/results.md"));
        assert!(short.contains("those under the paper's split."), "{short}");
        assert!(!short.contains("Ours reaches"), "{short}");
        shared.options.by_shape = false;
        let full = flat(&summary(&shared, "docs/results-split-by-mesh.md"));
        assert!(full.starts_with("**Under the paper's split**"), "{full}");
        assert!(full.contains("Ours reaches"), "{full}");
        assert!(
            text.contains("([docs/results.md](docs/results.md))"),
            "{text}"
        );
        let networks = columns.len();
        assert!(
            text.contains(&format!(
                "all {} runs ({networks} networks × 2 seeds) finished.",
                2 * networks
            )),
            "{text}"
        );
        assert!(
            text.contains("Ours reaches a test RMS of 0.9750 ± 0.1061"),
            "{text}"
        );
        assert!(
            text.contains("Ours ranks 1st and 8th of the 8 ablation networks on seeds 1, 2."),
            "{text}"
        );
        assert!(
            text.contains("claims that ours is below another ablation network or structure"),
            "{text}"
        );
        assert!(
            text.contains("0 hold on every seed, 0 hold on none and 9 are not settled."),
            "{text}"
        );

        // Seed 2 of ours missing: on seed 1 ours is lowest everywhere, so every claim holds so
        // far, and the run count says so.
        results.retain(|r| !(r.column == OURS && r.seed == 2));
        let text = flat(&summary(&outcome(results.clone()), "docs/results.md"));
        assert!(
            text.contains(&format!(
                "{} of the {} runs have finished so far.",
                2 * networks - 1,
                2 * networks
            )),
            "{text}"
        );
        assert!(
            text.contains("Ours reaches a test RMS of 0.9000 on one seed"),
            "{text}"
        );
        assert!(
            text.contains("Ours ranks 1st of the 8 ablation networks on seed 1."),
            "{text}"
        );
        assert!(
            text.contains("claim by claim), so far (seeds are missing): all 9 hold on every seed, 0 hold on none"),
            "{text}"
        );

        // With rigid distances, ours' figure and the other auto-encoders' are those.
        for r in &mut results {
            r.test_mean_distance_rigid = Some(r.test_rms);
        }
        let text = flat(&summary(&outcome(results), "docs/results.md"));
        assert!(
            text.contains("errors are rigidly aligned mean distances (the measure"),
            "{text}"
        );
        assert!(
            text.contains("Ours reaches 0.9000 on one seed (test RMS 0.9000,"),
            "{text}"
        );
        assert!(
            text.contains("Gao et al. 2018 (= Only Spatial Conv.) 1.000 ± 0: ours lower on 1 of 1 (holds so far)"),
            "{text}"
        );
    }

    /// The text with its line breaks and indents as single spaces.
    fn flat(text: &str) -> String {
        text.split_whitespace().collect::<Vec<_>>().join(" ")
    }

    #[test]
    fn long_items_wrap_at_a_hundred_characters_and_keep_their_words() {
        let words: Vec<String> = (0..80).map(|i| format!("w{i}")).collect();
        let text = format!("- **set**: {} {}", words.join(" "), "x".repeat(120));
        let wrapped = wrap(&text, "  ");
        assert!(wrapped.lines().count() > 3, "{wrapped}");
        for (i, line) in wrapped.lines().enumerate() {
            assert!(
                line.chars().count() <= 100 || !line.trim().contains(' '),
                "{line}"
            );
            assert_eq!(line.starts_with("  "), i > 0, "{line}");
        }
        assert_eq!(flat(&wrapped), text);
    }
}
