use super::*;
use crate::reproduce::plan::{self, Budget, OURS, PROTOCOLS};
use crate::reproduce::{LoadedSet, Machine, Options, synthetic_config};
use meshvae::ModelConfig;

pub(super) fn result(column: &str, seed: u64, rms: f64) -> RunResult {
    RunResult {
        dataset: "synthetic".into(),
        protocol: PROTOCOLS[0].id.into(),
        column: column.into(),
        seed,
        epochs: 5,
        step_budget: None,
        model: ModelConfig::default(),
        levels: vec![258, 129],
        test_meshes: 8,
        train_meshes: 8,
        test_rms: rms,
        test_rms_rel: rms / 5.0,
        test_mean_distance: 1.5 * rms,
        train_rms: rms,
        mean_shape_rms: 0.5,
        params: 1000,
        params_without_biases: 900,
        best_epoch: 5,
        val_meshes: 1,
        split_by_shape: true,
        selected_on: "validation".into(),
        test_rms_selected_on_test: Some(rms * 0.99),
        best_epoch_on_test: Some(4),
        train_seconds: 1.0,
        other_seconds: 1.0,
        threads: None,
        stop_reason: None,
        steps: None,
        test_mean_distance_rigid: None,
        rollbacks: None,
        copy_split: None,
        settings: None,
        commit: None,
        trained_by: None,
        platform: None,
    }
}

/// `md` from the first occurrence of `start` on.
fn from<'a>(md: &'a str, start: &str) -> &'a str {
    &md[md
        .find(start)
        .unwrap_or_else(|| panic!("no {start:?} in {md}"))..]
}

/// The first line of `text` that starts with `start`.
fn line<'a>(text: &'a str, start: &str) -> &'a str {
    text.lines()
        .find(|l| l.starts_with(start))
        .unwrap_or_else(|| panic!("no line starting {start:?} in {text}"))
}

pub(super) fn outcome(results: Vec<RunResult>) -> Outcome {
    let dataset = plan::dataset("synthetic").unwrap();
    let set = mesh_io::synth::generate(&synthetic_config(true))
        .unwrap()
        .set;
    Outcome {
        options: Options {
            datasets: vec![dataset],
            columns: plan::COLUMNS.iter().collect(),
            budget: Budget::Epochs(5),
            seeds: 2,
            quick: true,
            protocol: &PROTOCOLS[0],
            by_shape: true,
            work: "w".into(),
            records: None,
            jobs: 1,
            results: "r.md".into(),
            command: "cargo xtask reproduce --quick".into(),
            progress: false,
            report_only: false,
            commit: None,
        },
        sets: vec![LoadedSet {
            dataset,
            set,
            source: None,
            diagonal: 5.0,
            description: "test".into(),
            repeated_shapes: true,
        }],
        results,
        reused: 0,
        machine: Machine {
            cores: 2,
            cpu: "test CPU".into(),
        },
        wall_seconds: 60.0,
        notes: vec![],
    }
}

#[test]
fn tables_show_mean_std_and_the_relative_change() {
    // Ours 0.9 ± 0.1 over two seeds; every other column 1.0 ± 0.1: ours is 10 % lower.
    let mut results = Vec::new();
    for c in COLUMNS {
        let base = if c.is_ours() { 0.9 } else { 1.0 };
        results.push(result(c.id, 1, base - 0.1 / 2f64.sqrt()));
        results.push(result(c.id, 2, base + 0.1 / 2f64.sqrt()));
    }
    let md = markdown(&outcome(results.clone()), Some("KEPT"));
    assert!(
        md.contains("| **ours** (modified QEM, mean pooling) | 0.9000 ± 0.1000 |"),
        "{md}"
    );
    assert!(md.contains("| Only Spectral Conv. (no pooling) | -8.36 % | -6.92 % | -10.00 % |"));
    assert!(md.contains("On synthetic, ours has the lowest test RMS of the ablation columns.\n"));
    // With columns still to run, the sentence says of how many.
    let some: Vec<RunResult> = (results.iter())
        .filter(|r| ["ours", "no-pool", "spatial"].contains(&r.column.as_str()))
        .cloned()
        .collect();
    let md_some = markdown(&outcome(some), None);
    assert!(
        md_some.contains(
            "On synthetic, ours has the lowest test RMS of the 3 ablation columns finished so \
             far (of 8)."
        ),
        "{md_some}"
    );
    // Every column ties except ours: ours first, and the paper also puts ours first.
    let line = md
        .lines()
        .find(|l| l.starts_with("- synthetic: Our Method <"))
        .unwrap_or_else(|| panic!("{md}"));
    assert!(line.contains("of 21 pairs"), "{line}");
    assert!(md.contains("- Paper: Our Method < "), "{md}");
    assert!(md.contains("## Hand-written notes\n\nKEPT"));
    assert!(md.contains("Machine of this invocation: 2 cores (`nproc`), test CPU"));
    // No record names its machine: no line about the runs' machines.
    assert!(!md.contains("Runs' machines"), "{md}");

    // Max pooling below ours by less than the spread: named, "within one standard deviation".
    for r in results.iter_mut().filter(|r| r.column == "max") {
        r.test_rms -= 0.15;
    }
    let md = markdown(&outcome(results), None);
    assert!(md.contains("ours is **not** the lowest. Below it: modified QEM, max pooling (0.8500"));
    assert!(md.contains("within one standard deviation"));
    assert!(md.contains(BEGIN_HAND_WRITTEN) && md.contains(END_HAND_WRITTEN));
}

#[test]
fn the_runs_machines_are_counted_from_their_records() {
    let platform = |cpu: &str, caches: &str| meshvae::Platform {
        cpu: cpu.into(),
        simd: vec!["avx2".into(), "fma".into()],
        caches: caches.into(),
    };
    let mut results: Vec<RunResult> = ["ours", "no-pool", "spatial", "max"]
        .iter()
        .map(|c| result(c, 1, 1.0))
        .collect();
    results[0].platform = Some(platform("A", "L1d 48K"));
    results[1].platform = Some(platform("B", "L1d 32K"));
    results[2].platform = Some(platform("A", "L1d 48K"));
    let md = markdown(&outcome(results), None);
    let machines = line(&md, "- Runs' machines: ");
    assert!(
        machines.starts_with(
            "- Runs' machines: A (avx2, fma; L1d 48K): 2 runs; B (avx2, fma; L1d 32K): 1 run; \
             not named: 1 run (written before records kept the machine)."
        ),
        "{machines}"
    );
}

#[test]
fn the_hand_written_block_is_found_with_its_markers() {
    let text = format!("# R\n\ntables\n\n{BEGIN_HAND_WRITTEN}\nkeep me\n{END_HAND_WRITTEN}\n");
    let block = hand_written(&text).unwrap();
    assert!(block.starts_with(BEGIN_HAND_WRITTEN) && block.ends_with(END_HAND_WRITTEN));
    assert!(block.contains("keep me"));
    assert!(hand_written("no markers").is_none());
    assert!(hand_written(BEGIN_HAND_WRITTEN).is_none());
}

#[test]
fn seed_by_seed_ranks_each_seed_and_counts_where_ours_is_below() {
    // Seed 1: ours lowest of everything. Seed 2: every column but ours at 1.0, ours 1.1, and
    // max pooling lowest at 0.5. The test loss picks another epoch on seed 2 only.
    let mut results = Vec::new();
    for c in COLUMNS {
        let mut r = result(c.id, 1, if c.is_ours() { 0.5 } else { 1.0 });
        r.best_epoch_on_test = Some(r.best_epoch);
        results.push(r);
        let rms = match c.id {
            "ours" => 1.1,
            "max" => 0.5,
            _ => 1.0,
        };
        let mut r = result(c.id, 2, rms);
        r.best_epoch_on_test = Some(3);
        results.push(r);
    }
    let md = markdown(&outcome(results), None);
    assert!(md.contains("## Seed by seed"), "{md}");
    assert!(
        md.contains("| network | seed 1 | seed 2 | ranks | ours below it |"),
        "{md}"
    );
    let section = from(&md, "## Seed by seed");
    let row = |label: &str| line(section, &format!("| {label} |"));
    let ours = row("**ours** (modified QEM, mean pooling)");
    assert!(
        ours.contains("| **0.5000** | 1.100 | 1 / 8 | — |"),
        "{ours}"
    );
    let max = row("modified QEM, max pooling");
    assert!(
        max.contains("| 1.000 | **0.5000** | 2 / 1 | 1 of 2 |"),
        "{max}"
    );
    // Ties rank alike: on seed 1 the six other columns share rank 2.
    let qem = row("classical QEM, mean pooling");
    assert!(qem.contains("| 2 / 2 | 1 of 2 |"), "{qem}");
    // Structure rows carry no rank.
    assert!(row("`CPCPC` (ours, two poolings)").ends_with("| 1.000 | 1.000 |  | 1 of 2 |"));
    let runs = 2 * COLUMNS.len();
    let same = format!("chose the same epoch in {} of {runs} runs", COLUMNS.len());
    assert!(md.contains(&same), "{md}");
}

#[test]
fn ours_is_compared_with_a_partial_column_on_the_seeds_both_finished() {
    // Ours: 1.0 on seed 1, 2.0 on seed 2 (mean 1.5). Remeshing finished seed 1 only, at 1.2:
    // against ours' seed 1 it is above (ours −16.67 %), though below ours' two-seed mean.
    let results = vec![
        result("ours", 1, 1.0),
        result("ours", 2, 2.0),
        result("remesh", 1, 1.2),
        result("qem", 1, 0.8),
        result("qem", 2, 1.6),
    ];
    let p = paired(&results, "synthetic", OURS, "remesh").unwrap();
    assert_eq!((p.seeds.clone(), p.partial), (vec![1], true));
    assert!((p.change() - (1.0 - 1.2) / 1.2 * 100.0).abs() < 1e-12);
    assert_eq!(p.show_change(), "-16.67 % (seed 1)");
    let q = paired(&results, "synthetic", OURS, "qem").unwrap();
    assert_eq!((q.seeds.clone(), q.partial), (vec![1, 2], false));
    assert_eq!(q.show_change(), "+25.00 %");
    assert!(paired(&results, "synthetic", OURS, "graph").is_none());

    let md = markdown(&outcome(results), None);
    let row = |label: &str| line(&md, &format!("| {label} |"));
    assert!(row("uniform remeshing, mean pooling").contains("| -16.67 % (seed 1) |"));
    assert!(row("classical QEM, mean pooling").contains("| +25.00 % |"));
    // The verdict names classical QEM (below ours on both seeds), not remeshing.
    let verdict = md
        .lines()
        .find(|l| l.starts_with("On synthetic, ours is **not** the lowest"))
        .unwrap_or_else(|| panic!("{md}"));
    assert!(verdict.contains("classical QEM, mean pooling (1.200 ± 0.5657 against ours 1.500 ± 0.7071; within one standard deviation)"), "{verdict}");
    assert!(!verdict.contains("remeshing"), "{verdict}");
    // A column below ours on the shared seed says which seed that is.
    let results = vec![
        result("ours", 1, 1.0),
        result("ours", 2, 2.0),
        result("graph", 2, 1.5),
    ];
    let md = markdown(&outcome(results), None);
    assert!(md.contains("graph pooling (Shen et al. 2018) (1.500 against ours 2.000 on seed 2; one seed: no spread to compare with)"), "{md}");
}

#[test]
fn the_header_says_a_report_only_page_trained_nothing_and_gives_each_sets_time() {
    let mut o = outcome(vec![result("ours", 1, 0.5)]);
    let md = markdown(&o, None);
    assert!(!md.contains("it trained nothing"), "{md}");
    // One data set: no per-set split of the time.
    assert!(!md.contains("; synthetic 0.0 min"), "{md}");

    let samba = plan::dataset("samba").unwrap();
    let set = LoadedSet {
        dataset: samba,
        set: o.sets[0].set.clone(),
        source: None,
        diagonal: 5.0,
        description: "test".into(),
        repeated_shapes: false,
    };
    o.sets.push(set);
    let mut r = result("ours", 1, 0.5);
    r.dataset = "samba".into();
    r.train_seconds = 120.0;
    o.results.push(r);
    o.reused = o.results.len();
    let md = markdown(&o, None);
    assert!(md.contains("(it trained nothing: every run was read from its result file)"));
    // synthetic: 1 s + 1 s; samba: 120 s + 1 s.
    assert!(md.contains("; synthetic 0.0 min, samba 2.0 min."), "{md}");
}

#[test]
fn the_header_describes_the_plan_and_how_converged_runs_stopped() {
    let mut o = outcome(vec![result("ours", 1, 0.5), result("max", 1, 0.6)]);
    o.options.records = Some("docs/runs".into());
    let md = markdown(&o, None);
    assert!(
        md.contains(
            "- 5 epochs per run (the authors' code runs 8000), batch 50, Adam with a constant \
             learning rate of 1e-3 and no early stop,"
        ),
        "{md}"
    );
    assert!(md.contains("`docs/runs/<data set>/validation/e5/seed<N>/<column>.result.json`"));
    assert!(
        !md.contains("converged") && !md.contains("How the runs stopped"),
        "{md}"
    );

    // The converged plan: three runs converged, one used its budget.
    let converged = |column: &str, seed: u64, stop: &str, steps: u64| {
        let mut r = result(column, seed, 0.5);
        r.step_budget = Some(meshvae::DEFAULT_MAX_STEPS);
        r.stop_reason = Some(stop.into());
        r.steps = Some(steps);
        r
    };
    o.options.budget = Budget::CONVERGED;
    o.results = vec![
        converged("ours", 1, "converged", 3000),
        converged("ours", 2, "budget", 20_000),
        converged("max", 1, "converged", 4000),
        converged("max", 2, "converged", 5000),
    ];
    let md = markdown(&o, None);
    assert!(!md.contains("Blow-ups"), "no record keeps the count: {md}");
    o.results[1].rollbacks = Some(0);
    o.results[2].rollbacks = Some(2);
    o.results[3].rollbacks = Some(1);
    let md = markdown(&o, None);
    assert!(
        md.contains(
            "Blow-ups (the loss went NaN; training went back to its best weights, or its initial \
             ones, at half the rate) in 2 of the 3 runs whose record keeps the count: `max` (seed 1 ×2, seed 2). \
             1 earlier record does not keep it."
        ),
        "{md}"
    );
    assert!(
        md.contains(
            "- Every run trained until the validation loss converged (learning rate 1e-2 after \
             a 300-step warm-up, falling along a cosine to 1/32 of it over 1,200 steps, stop \
             after 200 steps without a new best once it has ended, the dense heads' at 0.3 of \
             it; Adam's β₂ 0.95; a step's gradient clipped to 3× the recent norm; budget 20,000 steps), as `meshvae train` does by default"
        ),
        "{md}"
    );
    assert!(!md.contains("epochs per run"), "{md}");
    assert!(
        md.contains(
            "- How the runs stopped: synthetic 3 converged, 1 at the step budget, mean 8,000 \
             steps (3,000 to 20,000)."
        ),
        "{md}"
    );
    assert!(
        md.contains("`docs/runs/<data set>/validation/converged/seed<N>/<column>.result.json`")
    );
    assert!(
        md.contains(
            "Stopped by the 20,000-step budget before converging: `ours` (seed 2); 3 of 4 runs \
             converged."
        ),
        "{md}"
    );
}

#[test]
fn rigid_distances_stand_beside_the_paper_and_copies_are_split_out() {
    let mut results = Vec::new();
    for seed in 1..=2 {
        let mut r = result(OURS, seed, 0.02);
        r.test_mean_distance_rigid = Some(0.01 * seed as f64);
        r.copy_split = Some(crate::reproduce::record::CopySplitRecord {
            copy_in_training_meshes: 3 + seed as usize,
            copy_in_training_mean_distance_rigid: 0.005,
            unseen_meshes: 5 - seed as usize,
            unseen_mean_distance_rigid: Some(0.02),
        });
        results.push(r);
        // A column whose runs predate the rigid measure: centroid-aligned, marked.
        results.push(result("max", seed, 0.04));
    }
    let md = markdown(&outcome(results), None);
    let ours = md
        .lines()
        .find(|l| l.starts_with("| **ours**"))
        .unwrap_or_else(|| panic!("{md}"));
    assert!(ours.contains("| 0.01500 ± 0.007071 |"), "{ours}");
    let max = md
        .lines()
        .find(|l| l.starts_with("| modified QEM, max pooling |"))
        .unwrap();
    assert_eq!(max.matches(" — ").count(), 1, "{max}");
    let row = md
        .lines()
        .find(|l| l.starts_with("| synthetic (ours) |"))
        .unwrap_or_else(|| panic!("{md}"));
    assert!(row.contains(" 0.01500 |"), "{row}");
    assert!(row.ends_with(" 0.06000 (c) |"), "{row}");
    assert!(
        md.contains("(seed 1 4 of 8, seed 2 5 of 8): ours reaches a rigid mean distance of 0.005000 ± 0 on them"),
        "{md}"
    );
    assert!(
        md.contains("and 0.02000 ± 0 on the other, unseen poses"),
        "{md}"
    );
    assert!(!md.contains("shared/notes"));
    // Ours alone is not "the lowest".
    let alone: Vec<RunResult> = (1..=2).map(|seed| result(OURS, seed, 0.02)).collect();
    let md = markdown(&outcome(alone), None);
    assert!(
        md.contains("no other ablation column has finished a run yet"),
        "{md}"
    );
    assert!(!md.contains("ours has the lowest"), "{md}");
}

#[test]
fn the_papers_horse_figure_is_shown_in_our_copys_units() {
    let mut o = outcome(vec![]);
    // Horse-gallop's row, whatever set stands in for it.
    o.sets[0].dataset = plan::dataset("horse-gallop").unwrap();
    let mut r = result(OURS, 1, 0.02);
    r.dataset = "horse-gallop".into();
    r.test_mean_distance_rigid = Some(0.0177);
    o.results = vec![r];
    let md = markdown(&o, None);
    let section = from(&md, "### horse-gallop (");
    let row = |start: &str| line(section, start);
    // 0.0119 × 1.6768815 = 0.019955.
    let ours = row("| **ours** |");
    assert!(
        ours.contains("| 0.01770 |") && ours.ends_with("| 0.0119 (= 0.01995 here) |"),
        "{ours}"
    );
    // Networks without a run say so; the mesh VAE ran out of memory in the paper.
    let tan = row("| Tan et al. 2018");
    assert!(
        tan.contains("not run") && tan.ends_with("| out of memory |"),
        "{tan}"
    );
    assert!(row("| Gong et al. 2019").ends_with("| – |"));
    // Each definition once, under its own name.
    assert!(
        section.contains("\n- Ranjan et al. 2018 (CoMA): Chebyshev K = 6"),
        "{section}"
    );
    assert!(section.contains("\n- Ours: Yuan et al. 2020"), "{section}");
    assert!(!section.contains("(CoMA): Ranjan"), "{section}");
    assert!(md.contains("scaled by 1.6768815 about the origin"), "{md}");
}

#[test]
fn the_claims_are_counted_seed_by_seed_and_ours_is_ranked() {
    // Ours below max pooling on seeds 1 and 2, above it on seed 3; below qem on every seed.
    let mut results = Vec::new();
    for (seed, ours, max) in [(1, 0.5, 0.6), (2, 0.5, 0.7), (3, 0.9, 0.8)] {
        results.push(result(OURS, seed, ours));
        results.push(result("max", seed, max));
        results.push(result("qem", seed, 1.0));
    }
    let md = markdown(&outcome(results), None);
    let section = from(&md, "## The paper's claims");
    let row = |label: &str| line(section, &format!("| {label} |"));
    // (0.6333 − 0.7) / 0.7 = −9.52 %.
    let max = row("modified QEM, max pooling");
    assert!(
        max.ends_with("| — | not settled: 2 of 3, -9.52 % |"),
        "{max}"
    );
    let qem = row("classical QEM, mean pooling");
    assert!(qem.contains("| -9.17 % | **holds**: 3 of 3, "), "{qem}");
    assert!(
        section.contains("rank among the ablation columns on synthetic: 1 of 3 on seed 1, 1 of 3 on seed 2, 2 of 3 on seed 3."),
        "{section}"
    );
}

#[test]
fn the_framework_claims_name_the_seeds_on_which_ours_is_lower() {
    // Rigid distances: ours below Tan on seed 1 only, below CoMA on both, above SpiralNet++ on
    // both; Gao (spatial) has no seed.
    let mut results = Vec::new();
    for (seed, ours, tan, coma, spiral) in [(1, 0.5, 0.6, 0.9, 0.4), (2, 0.5, 0.45, 0.8, 0.3)] {
        for (column, rigid) in [
            (OURS, ours),
            ("tan2018", tan),
            ("coma", coma),
            ("spiralnet", spiral),
        ] {
            let mut r = result(column, seed, 1.0);
            r.test_mean_distance_rigid = Some(rigid);
            results.push(r);
        }
    }
    let md = markdown(&outcome(results), None);
    let section = from(&md, "The paper's `table:ERMS` puts ours below");
    let row = |label: &str| line(section, &format!("| {label}"));
    assert!(
        row("Tan et al. 2018")
            .ends_with("| not settled: ours lower on seed 1, not lower on seed 2 |"),
        "{section}"
    );
    assert!(
        row("Ranjan et al. 2018").ends_with("| **holds**: ours lower on seeds 1, 2 |"),
        "{section}"
    );
    assert!(
        row("Gong et al. 2019 (SpiralNet++), not in the paper")
            .ends_with("| **does not hold**: ours not lower on seeds 1, 2 |"),
        "{section}"
    );
    assert!(row("Gao et al. 2018").ends_with("| — |"), "{section}");
}

#[test]
fn a_page_split_by_mesh_names_the_sets_whose_runs_it_shares_with_the_split_by_shape() {
    let mut o = outcome(vec![result("ours", 1, 0.5)]);
    o.options.by_shape = false;
    o.options.records = Some("docs/runs".into());
    let md = markdown(&o, None);
    assert!(!md.contains("holds no shape twice"), "{md}");
    assert!(
        md.contains(
            "- Every run's numbers: \
             `docs/runs/<data set>/validation/e5-by-mesh/seed<N>/<column>.result.json`.\n"
        ),
        "{md}"
    );
    let mut samba = o.sets[0].clone();
    samba.dataset = plan::dataset("samba").unwrap();
    samba.repeated_shapes = false;
    o.sets.push(samba);
    let md = markdown(&o, None);
    assert!(
        md.contains(
            "; samba holds no shape twice, so this split is its split by shape, and its runs \
             are those of the split by shape (its records are in that split's folder);"
        ),
        "{md}"
    );
    assert!(
        md.contains(
            "`docs/runs/<data set>/validation/e5-by-mesh/seed<N>/<column>.result.json`, and \
             `docs/runs/samba/validation/e5/seed<N>/<column>.result.json` for the runs shared \
             with the split by shape."
        ),
        "{md}"
    );
}
