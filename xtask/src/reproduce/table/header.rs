//! The "How these numbers were made" section: command, data sets, split, training, protocol,
//! machine and time.

use crate::reproduce::Outcome;
use crate::reproduce::plan::Budget;
use crate::reproduce::record::RunResult;
use crate::reproduce::stats::{Stat, sig, thousands};
use meshvae::TrainConfig;
use std::fmt::Write;

pub(super) fn header(md: &mut String, o: &Outcome) {
    let opts = &o.options;
    let seeds: Vec<String> = (1..=opts.seeds).map(|s| s.to_string()).collect();
    // `+ 0.0`: an empty sum is -0.0, which would print as "-0.0 min".
    let compute: f64 = o
        .results
        .iter()
        .map(|r| r.train_seconds + r.other_seconds)
        .sum::<f64>()
        + 0.0;
    let training: f64 = o.results.iter().map(|r| r.train_seconds).sum::<f64>() + 0.0;
    let _ = writeln!(md, "## How these numbers were made\n");
    let _ = writeln!(md, "- Command: `{}`", opts.command);
    for set in &o.sets {
        let _ = writeln!(
            md,
            "- Data set {}: {} meshes of {} vertices and {} faces, bounding-box diagonal {} \
             (of its first mesh), from {}.",
            set.dataset.name,
            set.set.len(),
            thousands(set.set.vertex_count()),
            thousands(set.set.faces().len()),
            sig(set.diagonal),
            set.description
        );
    }
    // A set without repeated shapes splits alike either way, and its runs are shared
    // (`Run::with_split_of`).
    let unrepeated: Vec<&str> = o
        .sets
        .iter()
        .filter(|s| !s.repeated_shapes)
        .map(|s| s.dataset.name)
        .collect();
    let split = if opts.by_shape {
        "by shape: meshes with the same vertex positions (horse-gallop stores its 24-frame \
         cycle twice) are one shape and always land on the same side, so every test shape is \
         unseen; ⌊G/2⌋ of the G shapes train, always including mesh 0's, the rest pose every \
         mesh's features are computed against; a set without repeats splits as mesh by mesh, \
         so its runs are also those of the split by mesh"
            .to_string()
    } else {
        let mut split = "mesh by mesh, as the paper's random halves (⌊N/2⌋ training meshes, \
                         always including mesh 0, the rest pose every mesh's features are \
                         computed against): where a set holds a shape twice, a test mesh may \
                         have its copy in training"
            .to_string();
        if !unrepeated.is_empty() {
            let _ = write!(
                split,
                "; {} holds no shape twice, so this split is its split by shape, and its runs \
                 are those of the split by shape (its records are in that split's folder)",
                unrepeated.join(" and ")
            );
        }
        split
    };
    let _ = writeln!(
        md,
        "- Seeds {}: each seed draws one random split into halves, {split}; the split is used \
         by every network of that seed, and the seed also draws the initial weights and the \
         training's shuffles and noise.",
        seeds.join(", ")
    );
    match opts.budget {
        Budget::Epochs(epochs) => {
            let _ = writeln!(
                md,
                "- {epochs} epochs per run (the authors' code runs 8000), batch 50, Adam with a \
                 constant learning rate of 1e-3 and no early stop, the paper's network and loss \
                 as the authors' code runs them (`meshvae::ModelConfig::default()`), de-pooling \
                 by copy."
            );
        }
        Budget::Converged { max_steps } => {
            let _ = writeln!(
                md,
                "- Every run trained until the validation loss converged ({}), as `meshvae \
                 train` does by default (`TrainConfig::default()`), batch 50, Adam, the paper's \
                 network and loss as the authors' code runs them \
                 (`meshvae::ModelConfig::default()`), de-pooling by copy.",
                converged_training(max_steps)
            );
            stops(md, o);
        }
    }
    let _ = writeln!(md, "- Protocol: {}.", opts.protocol.description);
    let _ = writeln!(
        md,
        "- Machine of this invocation: {} cores (`nproc`), {}. Wall time of this invocation {:.1} min{}; the runs' own time \
         summed (earlier invocations included) {:.1} min, of which training {:.1} min{}.",
        o.machine.cores,
        o.machine.cpu,
        o.wall_seconds / 60.0,
        if o.reused == o.results.len() && !o.results.is_empty() {
            " (it trained nothing: every run was read from its result file)"
        } else {
            ""
        },
        compute / 60.0,
        training / 60.0,
        per_set_time(o)
    );
    let mut threads: Vec<usize> = o.results.iter().filter_map(|r| r.threads).collect();
    threads.sort_unstable();
    threads.dedup();
    if !threads.is_empty() {
        let list: Vec<String> = threads.iter().map(|t| t.to_string()).collect();
        let _ = writeln!(
            md,
            "- Threads per run: {} (`--jobs` trains several runs at once, each on its share of \
             the cores, so their summed time can exceed the wall time; the numbers do not \
             depend on it).",
            list.join(", ")
        );
    }
    machines(md, o);
    code(md, o);
    if let Some(records) = &opts.records {
        let folder = |set: &str, suffix: &str| {
            format!(
                "`{}/{set}/{}/{}{suffix}/seed<N>/<column>.result.json`",
                records.display(),
                opts.protocol.id,
                opts.budget.dir_name(),
            )
        };
        let _ = write!(md, "- Every run's numbers: ");
        if opts.by_shape {
            let _ = writeln!(md, "{}.", folder("<data set>", ""));
        } else {
            let _ = write!(md, "{}", folder("<data set>", "-by-mesh"));
            let shared: Vec<String> = unrepeated.iter().map(|s| folder(s, "")).collect();
            if shared.is_empty() {
                let _ = writeln!(md, ".");
            } else {
                let _ = writeln!(
                    md,
                    ", and {} for the runs shared with the split by shape.",
                    shared.join(" and ")
                );
            }
        }
    }
    for note in &o.notes {
        let _ = writeln!(md, "- {note}");
    }
    md.push_str(
        "\nMeasures, on the test meshes: **RMS** = sqrt(Σ‖v − v̂‖² / (3·N·V)) after aligning \
         centroids, in mesh units; **rel** = RMS / the bounding-box diagonal; **mean dist** = \
         mean per-vertex Euclidean distance after aligning centroids; **mean dist, rigid** = \
         the same after the best rotation and translation (Kabsch), the measure of the authors' \
         evaluation script `show_error.m`. The paper calls its numbers RMS errors, but the \
         authors' released evaluation computes rigidly aligned mean distances, so the paper's \
         figures stand beside our rigid mean dist. Every number is mean ± sample standard \
         deviation over the seeds. \"ours against it\" = (ours − it) / it on \
         the mean RMS over the seeds both have finished (named in brackets when either has a \
         seed the other lacks).\n\n",
    );
}

/// "learning rate 1e-2 after a 300-step warm-up, falling along a cosine to 1/32 of it over
/// 1,200 steps, stop after 200 steps without a new best once it has ended, …; budget 20,000
/// steps" (or, without a decay, "… halved on plateaus, stop after 1,500 steps …"):
/// `meshvae train`'s default training, from its settings.
pub(super) fn converged_training(max_steps: usize) -> String {
    let train = TrainConfig::default();
    let schedule = train.schedule;
    let warmup = match schedule.warmup_steps {
        0 => String::new(),
        w => format!(" after a {}-step warm-up", thousands(w)),
    };
    let rule = if schedule.decay_steps > 0 {
        format!(
            "{warmup}, falling along a cosine to 1/{} of it over {} steps, stop after {} steps \
             without a new best once it has ended",
            (1.0 / schedule.min_lr_ratio).round(),
            thousands(schedule.decay_steps),
            thousands(schedule.patience),
        )
    } else {
        let cut = if schedule.lr_factor == 0.5 {
            "halved".to_string()
        } else {
            format!("multiplied by {}", schedule.lr_factor)
        };
        format!(
            "{warmup} {cut} on plateaus, stop after {} steps without a new best",
            thousands(schedule.patience)
        )
    };
    // Said only where they are not the authors' (one rate, TF's β₂).
    let heads = if train.head_lr_scale == 1.0 {
        String::new()
    } else {
        format!(", the dense heads' at {} of it", train.head_lr_scale)
    };
    let beta2 = if train.adam_beta2 == 0.999 {
        String::new()
    } else {
        format!("; Adam's β₂ {}", train.adam_beta2)
    };
    let clip = if train.grad_clip == 0.0 {
        String::new()
    } else {
        format!(
            "; a step's gradient clipped to {}× the recent norm",
            train.grad_clip
        )
    };
    format!(
        "learning rate {:e}{rule}{heads}{beta2}{clip}; budget {} steps",
        train.lr,
        thousands(max_steps)
    )
}

/// "- Code: the records name commit `…` (12 runs) …": which code made the numbers, from the
/// records themselves (an invocation may reuse records made by earlier commits).
/// "- Runs' machines: Intel(R) Xeon(R) Processor (avx2, fma, avx512f; L1d 48K …) 50 runs, …":
/// the machines the records name, since the bits of a run depend on the machine's SIMD
/// features and data caches (`meshvae::Platform`).
fn machines(md: &mut String, o: &Outcome) {
    let mut seen: Vec<(String, usize)> = Vec::new();
    let mut unnamed = 0;
    for r in &o.results {
        let Some(platform) = &r.platform else {
            unnamed += 1;
            continue;
        };
        let name = platform.to_string();
        match seen.iter_mut().find(|(n, _)| *n == name) {
            Some((_, count)) => *count += 1,
            None => seen.push((name, 1)),
        }
    }
    if seen.is_empty() {
        return;
    }
    let runs = |n: usize| if n == 1 { "run" } else { "runs" };
    let mut parts: Vec<String> = seen
        .iter()
        .map(|(name, n)| format!("{name}: {n} {}", runs(*n)))
        .collect();
    if unnamed > 0 {
        parts.push(format!(
            "not named: {unnamed} {} (written before records kept the machine)",
            runs(unnamed)
        ));
    }
    let _ = writeln!(
        md,
        "- Runs' machines: {}. Machines that differ in SIMD features or data caches train the \
         same run to other numbers (the matrix products block their sums by the caches' sizes; \
         a last-bit difference grows over the steps), as another seed would; `--check` expects \
         the same digits only on a machine like the record's.",
        parts.join("; ")
    );
}

fn code(md: &mut String, o: &Outcome) {
    if o.results.is_empty() {
        return;
    }
    let mut commits: Vec<(String, usize)> = Vec::new();
    let mut unnamed = 0;
    for r in &o.results {
        match &r.commit {
            Some(c) => {
                let name = format!("`{c}`");
                match commits.iter_mut().find(|(n, _)| *n == name) {
                    Some((_, count)) => *count += 1,
                    None => commits.push((name, 1)),
                }
            }
            None => unnamed += 1,
        }
    }
    let mut parts: Vec<String> = commits
        .iter()
        .map(|(name, n)| format!("{name} ({n} {})", if *n == 1 { "run" } else { "runs" }))
        .collect();
    if unnamed > 0 {
        parts.push(format!(
            "no commit named ({unnamed} {} written before records kept it)",
            if unnamed == 1 { "record" } else { "records" }
        ));
    }
    let mixed = o.results.iter().filter(|r| r.trained_by.is_some()).count();
    if mixed > 0 {
        parts.push(format!(
            "of which {mixed} {} trained in part by other code (the record's `trained_by` \
             names it)",
            if mixed == 1 { "was" } else { "were" }
        ));
    }
    let _ = writeln!(
        md,
        "- Code: {}. `cargo xtask reproduce --check <record>` trains one run again with its \
         record's settings and compares every number digit by digit.",
        parts.join(", ")
    );
}

/// "- How the runs stopped: horse-gallop 28 converged, 2 at the step budget, mean 6,340 steps
/// (2,100 to 20,000); samba …" (the converged plan's runs stop at different points).
fn stops(md: &mut String, o: &Outcome) {
    let parts: Vec<String> = o
        .sets
        .iter()
        .filter_map(|set| {
            let name = set.dataset.name;
            let runs: Vec<&RunResult> = o.results.iter().filter(|r| r.dataset == name).collect();
            if runs.is_empty() {
                return None;
            }
            let converged = runs.iter().filter(|r| r.converged()).count();
            let budget = runs
                .iter()
                .filter(|r| r.stop_reason.as_deref() == Some("budget"))
                .count();
            let mut part = format!("{name} {converged} converged, {budget} at the step budget");
            let unknown = runs.len() - converged - budget;
            if unknown > 0 {
                let _ = write!(part, ", {unknown} unrecorded");
            }
            let steps: Vec<f64> = runs
                .iter()
                .filter_map(|r| r.steps)
                .map(|s| s as f64)
                .collect();
            if let Some(stat) = Stat::of(&steps) {
                let (lo, hi) = steps.iter().fold((f64::INFINITY, 0.0f64), |(lo, hi), &s| {
                    (lo.min(s), hi.max(s))
                });
                let _ = write!(
                    part,
                    ", mean {} steps ({} to {})",
                    thousands(stat.mean.round() as usize),
                    thousands(lo as usize),
                    thousands(hi as usize)
                );
            }
            Some(part)
        })
        .collect();
    if !parts.is_empty() {
        let _ = writeln!(md, "- How the runs stopped: {}.", parts.join("; "));
    }
}

/// "; horse-gallop 139.3 min, samba 643.1 min" where more than one data set ran.
fn per_set_time(o: &Outcome) -> String {
    if o.sets.len() < 2 {
        return String::new();
    }
    let parts: Vec<String> = o
        .sets
        .iter()
        .map(|set| {
            let name = set.dataset.name;
            let seconds: f64 = o
                .results
                .iter()
                .filter(|r| r.dataset == name)
                .map(|r| r.train_seconds + r.other_seconds)
                .sum::<f64>()
                + 0.0;
            format!("{name} {:.1} min", seconds / 60.0)
        })
        .collect();
    format!("; {}", parts.join(", "))
}
