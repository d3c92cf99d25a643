//! `cargo xtask reproduce --quick` end to end, into a temporary folder (never docs/): every run
//! trains and is evaluated, the markdown has every table, column and data set with finite
//! numbers, and a second invocation reuses the finished runs and resumes an unfinished one;
//! the converged plan (the default without `--epochs`) keeps its runs apart and resumes by
//! their `run.json`.

use std::path::Path;
use std::process::{Command, Output};
use xtask::reproduce::plan::{COLUMNS, Column, PROTOCOLS};
use xtask::reproduce::record::RunResult;

/// The columns that run on `dataset`: the position networks need 1,024 vertices, more than the
/// quick synthetic set's.
fn columns_on(dataset: &str) -> Vec<&'static Column> {
    let vertices = match dataset {
        "synthetic" => mesh_io::synth::generate(&xtask::reproduce::synthetic_config(true))
            .unwrap()
            .set
            .vertex_count(),
        _ => usize::MAX,
    };
    (COLUMNS.iter())
        .filter(|c| c.net.min_vertices() <= vertices)
        .collect()
}

/// The fixed-epoch plan most of the test checks: two epochs a run.
const TWO_EPOCHS: [&str; 2] = ["--epochs", "2"];

fn reproduce(work: &Path, results: &Path) -> Output {
    reproduce_with(work, results, &TWO_EPOCHS)
}

fn reproduce_with(work: &Path, results: &Path, extra: &[&str]) -> Output {
    let out = Command::new(env!("CARGO_BIN_EXE_xtask"))
        .args(["reproduce", "--quick", "--quiet", "--work"])
        .arg(work)
        .arg("--results")
        .arg(results)
        .args(extra)
        .output()
        .expect("the xtask binary runs");
    assert!(
        out.status.success(),
        "reproduce failed:\n{}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

fn result(work: &Path, dataset: &str, column: &str) -> RunResult {
    result_in(work, dataset, "e2", column)
}

/// The record of `column`, seed 1, in the plan folder `budget` (`e2`, `converged-s4`).
fn result_in(work: &Path, dataset: &str, budget: &str, column: &str) -> RunResult {
    let path = work
        .join(dataset)
        .join(PROTOCOLS[0].id)
        .join(budget)
        .join("seed1")
        .join(format!("{column}.result.json"));
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{path:?}: {e}"));
    serde_json::from_str(&text).unwrap()
}

/// Every decimal number in the markdown's table rows parses to a finite value, and no cell
/// is NaN or infinite.
fn assert_finite_tables(md: &str) {
    for line in md.lines().filter(|l| l.starts_with('|')) {
        assert!(
            !line.contains("NaN") && !line.contains("inf"),
            "non-finite cell: {line}"
        );
        for cell in line.split('|').map(str::trim) {
            let first = cell.split_whitespace().next().unwrap_or("");
            if first.starts_with(|c: char| c.is_ascii_digit()) && first.contains('.') {
                let value: f64 = first
                    .trim_end_matches('%')
                    .parse()
                    .unwrap_or_else(|_| panic!("{first:?} in {line}"));
                assert!(value.is_finite());
            }
        }
    }
}

/// Removes the run folders even when an assertion fails: they hold a few hundred MB of weights.
struct RemoveOnDrop(std::path::PathBuf);

impl Drop for RemoveOnDrop {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

#[test]
fn quick_reproduce_writes_every_table_and_resumes() {
    let dir = std::env::temp_dir().join(format!("xtask-reproduce-quick-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let _cleanup = RemoveOnDrop(dir.clone());
    let (work, results) = (dir.join("work"), dir.join("results.md"));
    // Before any run: --report-only trains nothing and writes a page that says so.
    reproduce_with(&work, &results, &["--report-only", "--epochs", "2"]);
    let md = std::fs::read_to_string(&results).unwrap();
    assert!(
        md.contains("**Partial:**") && md.contains("| not run |"),
        "{md}"
    );
    assert!(
        !work.join("synthetic").exists(),
        "--report-only trained something"
    );
    let first = reproduce(&work, &results);
    let stdout = String::from_utf8_lossy(&first.stdout).to_string();

    let horse = mesh_io::datasets::find("horse-gallop").is_some();
    let datasets: &[&str] = if horse {
        &["synthetic", "horse-gallop"]
    } else {
        &["synthetic"]
    };
    let md = std::fs::read_to_string(&results).unwrap();
    for heading in [
        "## How these numbers were made",
        "## In the paper's layout",
        "## Ordering of the columns",
        "## Seed by seed",
        "## Relative improvements of ours",
        "## The paper's claims",
        "## Against other auto-encoders",
        "## Network structures",
        "## Parameters",
        "## Hand-written notes",
    ] {
        assert!(md.contains(heading), "missing {heading}");
    }
    for dataset in datasets {
        assert!(
            md.contains(&format!("## Ablation on {dataset}")),
            "{dataset}"
        );
        assert!(md.contains(&format!("| {dataset} (ours) |")), "{dataset}");
        // Beside the page, a picture of every run's error, linked from it.
        let picture = format!("results-{dataset}.png");
        assert!(
            md.contains(&format!("]({picture})")),
            "{dataset}: no link to {picture}"
        );
        let png = std::fs::read(dir.join(&picture)).unwrap();
        let image = mesh_render::Image::decode_png(&png).unwrap();
        assert!(image.width >= 600 && image.height > 150, "{dataset}");
        for column in columns_on(dataset) {
            assert!(md.contains(column.label), "column {}", column.id);
            let r = result(&work, dataset, column.id);
            assert!(r.is_finite() && r.test_rms > 0.0, "{dataset} {}", column.id);
            assert_eq!((r.epochs, r.seed), (2, 1));
            // The default protocol: chosen on validation meshes, test-selected ones beside.
            assert_eq!(r.selected_on, "validation");
            assert!(r.val_meshes >= 1 && r.test_rms_selected_on_test.is_some());
            assert!(r.split_by_shape);
        }
    }
    if horse {
        // horse-gallop holds each pose twice: the default split keeps both copies on one side.
        let path = work
            .join("horse-gallop")
            .join(PROTOCOLS[0].id)
            .join("e2/seed1/ours/split.json");
        let text = std::fs::read_to_string(&path).unwrap();
        let split: meshvae::SplitFile = serde_json::from_str(&text).unwrap();
        assert!(split.by_shape);
        assert_eq!(split.repeated_shapes.len(), 24);
        let side = |i: &usize| {
            if split.test.contains(i) {
                "test"
            } else {
                "train or validation"
            }
        };
        for group in &split.repeated_shapes {
            assert!(
                group.iter().all(|i| side(i) == side(&group[0])),
                "copies of one shape on both sides: {group:?}"
            );
        }
    }
    assert!(!md.contains("| not run |"), "a run is missing:\n{md}");
    assert!(md.contains("7,941,042") && md.contains("4,118,706"));
    assert!(md.contains("129,745,920") && md.contains("68,610,048"));
    if horse {
        assert!(md.contains("### horse-gallop (8,431 vertices; the paper's Horse"));
    }
    assert_finite_tables(&md);
    assert!(stdout.contains("(0 reused)"), "{stdout}");

    // An unfinished run (model folder without its result) is resumed and re-evaluated to the
    // same numbers; every other run is read back.
    let ours = result(&work, "synthetic", "ours");
    let seed_dir = work
        .join("synthetic")
        .join(PROTOCOLS[0].id)
        .join("e2/seed1");
    // A finished run drops its training state but keeps what `meshvae` needs to load it.
    assert!(!seed_dir.join("ours/checkpoint.safetensors").exists());
    assert!(seed_dir.join("ours/weights.safetensors").is_file());
    std::fs::remove_file(seed_dir.join("ours.result.json")).unwrap();
    let second = reproduce(&work, &results);
    let stdout = String::from_utf8_lossy(&second.stdout);
    let runs: usize = datasets.iter().map(|d| columns_on(d).len()).sum();
    assert!(
        stdout.contains(&format!("{runs} runs ({} reused)", runs - 1)),
        "{stdout}"
    );
    let again = result(&work, "synthetic", "ours");
    assert_eq!(again.test_rms, ours.test_rms);
    assert_eq!(again.best_epoch, ours.best_epoch);

    // Two runs at a time, their results kept in a records folder apart from the model folders:
    // the same numbers as one run at a time on all cores.
    let records = dir.join("records");
    let records_arg = records.to_str().unwrap();
    let parallel_work = dir.join("parallel");
    let synthetic = [
        "--dataset",
        "synthetic",
        "--records",
        records_arg,
        "--epochs",
        "2",
    ];
    reproduce_with(
        &parallel_work,
        &dir.join("parallel.md"),
        &[&synthetic[..], &["--jobs", "2"]].concat(),
    );
    let untimed = |mut r: RunResult| {
        (r.train_seconds, r.other_seconds, r.threads) = (0.0, 0.0, None);
        r
    };
    for column in columns_on("synthetic") {
        assert_eq!(
            untimed(result(&records, "synthetic", column.id)),
            untimed(result(&work, "synthetic", column.id)),
            "{}",
            column.id
        );
    }
    assert!(
        !parallel_work
            .join("synthetic/validation/e2/seed1/ours.result.json")
            .exists()
    );
    // Another machine with only the records trains nothing and writes the same tables.
    let elsewhere = dir.join("elsewhere");
    let report = reproduce_with(
        &elsewhere,
        &dir.join("elsewhere.md"),
        &[&synthetic[..], &["--report-only"]].concat(),
    );
    let stdout = String::from_utf8_lossy(&report.stdout);
    let runs = columns_on("synthetic").len();
    assert!(
        stdout.contains(&format!("{runs} runs ({runs} reused)")),
        "{stdout}"
    );
    assert!(!elsewhere.exists());
    let md = std::fs::read_to_string(dir.join("elsewhere.md")).unwrap();
    assert!(!md.contains("| not run |"), "{md}");

    // The converged plan, the default without --epochs (`--quick`: a 4-step budget, far from
    // converging), in the same work folder: its own runs under converged-s4/, none of the
    // 2-epoch runs reused.
    let converged = ["--dataset", "synthetic"];
    let out = reproduce_with(&work, &dir.join("converged.md"), &converged);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        stdout.contains(&format!("{runs} runs (0 reused)")),
        "{stdout}"
    );
    for column in columns_on("synthetic") {
        let r = result_in(&work, "synthetic", "converged-s4", column.id);
        assert!(r.is_finite(), "{}", column.id);
        assert_eq!(r.step_budget, Some(4));
        assert_eq!(r.stop_reason.as_deref(), Some("budget"));
        // 7 training meshes: one step per epoch.
        assert_eq!((r.steps, r.epochs), (Some(4), 4), "{}", column.id);
        assert_eq!(r.rollbacks, Some(0), "{}", column.id);
    }
    let md = std::fs::read_to_string(dir.join("converged.md")).unwrap();
    assert!(
        md.contains("- Every run trained until the validation loss converged (learning rate"),
        "{md}"
    );
    assert!(md.contains("budget 4 steps)"), "{md}");
    assert!(
        md.contains(&format!(
            "No blow-ups (a NaN loss) in the {runs} runs whose record keeps the count."
        )),
        "{md}"
    );
    assert!(
        md.contains(&format!(
            "- How the runs stopped: synthetic 0 converged, {runs} at the step budget, mean 4 \
             steps (4 to 4)."
        )),
        "{md}"
    );
    assert!(!md.contains("| not run |"), "{md}");
    // A converged-plan run whose result is lost is only evaluated again: run.json says it
    // ended (on its budget), so it is not trained further.
    let seed_dir = work.join("synthetic/validation/converged-s4/seed1");
    let log = std::fs::read_to_string(seed_dir.join("ours/log.jsonl")).unwrap();
    let ours = result_in(&work, "synthetic", "converged-s4", "ours");
    std::fs::remove_file(seed_dir.join("ours.result.json")).unwrap();
    let again = reproduce_with(&work, &dir.join("converged.md"), &converged);
    let stdout = String::from_utf8_lossy(&again.stdout);
    assert!(
        stdout.contains(&format!("{runs} runs ({} reused)", runs - 1)),
        "{stdout}"
    );
    let again = result_in(&work, "synthetic", "converged-s4", "ours");
    assert_eq!((again.test_rms, again.epochs), (ours.test_rms, ours.epochs));
    assert_eq!(
        std::fs::read_to_string(seed_dir.join("ours/log.jsonl")).unwrap(),
        log
    );
    // Every record names the code that made it, as the page does; the same code trained and
    // evaluated it, so the record names no other.
    let commit = xtask::reproduce::commit::Commit::of(Path::new(env!("CARGO_MANIFEST_DIR")));
    assert_eq!(ours.commit, commit);
    assert_eq!((&ours.trained_by, &again.trained_by), (&None, &None));
    if commit.is_some() {
        // A finished folder whose training left no list of commits (trained before they were
        // kept, or the list lost) is evaluated again, and its record says so.
        std::fs::remove_file(seed_dir.join("ours.result.json")).unwrap();
        std::fs::remove_file(seed_dir.join("ours.commits.json")).unwrap();
        reproduce_with(&work, &dir.join("unknown.md"), &converged);
        let unknown = result_in(&work, "synthetic", "converged-s4", "ours");
        assert_eq!(unknown.trained_by, Some(vec![]));
        assert_eq!(unknown.test_rms, ours.test_rms);
        let md = std::fs::read_to_string(dir.join("unknown.md")).unwrap();
        assert!(
            md.contains("of which 1 was trained in part by other code"),
            "{md}"
        );
        // A run stopped before its first checkpoint, begun by other code, restarts from step 1:
        // this code alone trains it, and the record names no other.
        for file in [
            "ours.result.json",
            "ours/weights.safetensors",
            "ours/run.json",
        ] {
            std::fs::remove_file(seed_dir.join(file)).unwrap();
        }
        assert!(!seed_dir.join("ours/checkpoint.safetensors").exists());
        let other = r#"[{"describe": "0123456789ab", "dirty": false}]"#;
        std::fs::write(seed_dir.join("ours.commits.json"), other).unwrap();
        reproduce_with(&work, &dir.join("restarted.md"), &converged);
        let restarted = result_in(&work, "synthetic", "converged-s4", "ours");
        assert_eq!(restarted.trained_by, None);
        assert_eq!(restarted.test_rms, ours.test_rms);
    }
    if let Some(commit) = &commit {
        assert!(
            md.contains(&format!("- Code: `{commit}` ({runs} runs).")),
            "{md}"
        );
    }

    // The synthetic set holds no shape twice, so its split by mesh is its split by shape: the
    // paper's split reuses every run above instead of training it again, and says so.
    let by_mesh = reproduce_with(
        &work,
        &dir.join("by-mesh.md"),
        &["--dataset", "synthetic", "--split-by-mesh"],
    );
    let stdout = String::from_utf8_lossy(&by_mesh.stdout);
    assert!(
        stdout.contains(&format!("{runs} runs ({runs} reused)")),
        "{stdout}"
    );
    assert!(
        !work
            .join("synthetic/validation/converged-s4-by-mesh")
            .exists()
    );
    let md = std::fs::read_to_string(dir.join("by-mesh.md")).unwrap();
    assert!(
        md.contains("synthetic holds no shape twice, so this split is its split by shape"),
        "{md}"
    );
    assert!(!md.contains("| not run |"), "{md}");

    // A record made with another setting (here the rate, as when a default changes) is
    // flagged by --report-only and trained again, from scratch, by the next invocation.
    let record_path = seed_dir.join("ours.result.json");
    let edit_lr = |path: &Path, pointer: &str| {
        let mut value: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
        *value.pointer_mut(pointer).unwrap() = serde_json::json!(0.005);
        std::fs::write(path, serde_json::to_string_pretty(&value).unwrap()).unwrap();
    };
    edit_lr(&record_path, "/settings/train/lr");
    edit_lr(&seed_dir.join("ours/config.json"), "/train/lr");
    let report = reproduce_with(
        &work,
        &dir.join("stale.md"),
        &["--dataset", "synthetic", "--report-only"],
    );
    let stdout = String::from_utf8_lossy(&report.stdout);
    assert!(
        stdout.contains(&format!("{} runs ({} reused)", runs - 1, runs - 1)),
        "{stdout}"
    );
    let md = std::fs::read_to_string(dir.join("stale.md")).unwrap();
    assert!(
        md.contains("**Stale:** 1 of the records were made with other settings")
            && md.contains("synthetic seed 1 ours: train.lr 0.005 → 0.01"),
        "{md}"
    );
    let retrained = reproduce_with(&work, &dir.join("converged.md"), &converged);
    let stdout = String::from_utf8_lossy(&retrained.stdout);
    assert!(
        stdout.contains(&format!("{runs} runs ({} reused)", runs - 1)),
        "{stdout}"
    );
    let again = result_in(&work, "synthetic", "converged-s4", "ours");
    assert_eq!(again.settings, ours.settings);
    assert_eq!((again.test_rms, again.steps), (ours.test_rms, ours.steps));
    // Trained again (not resumed, not only evaluated): the same epochs, in their own time.
    let untimed = |log: &str| -> Vec<serde_json::Value> {
        log.lines()
            .map(|line| {
                let mut v: serde_json::Value = serde_json::from_str(line).unwrap();
                v["seconds"] = serde_json::Value::Null;
                v
            })
            .collect()
    };
    let relog = std::fs::read_to_string(seed_dir.join("ours/log.jsonl")).unwrap();
    assert_eq!(untimed(&relog), untimed(&log));
    assert_ne!(relog, log, "the log was not written again");

    // --check trains the record's run again and agrees to the digit; a record whose number
    // was changed does not, and the command says which number and fails.
    let record = record_path.to_str().unwrap();
    let checked = reproduce_with(&work, &dir.join("unused.md"), &["--check", record]);
    let stdout = String::from_utf8_lossy(&checked.stdout);
    assert!(
        stdout.contains("reproduced: all 18 numbers agree to the digit."),
        "{stdout}"
    );
    assert!(
        work.join("check/synthetic/validation/converged-s4/seed1/ours")
            .is_dir()
    );
    let tampered = dir.join("tampered.result.json");
    let mut value: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&record_path).unwrap()).unwrap();
    value["test_rms"] = serde_json::json!(ours.test_rms * 1.5);
    std::fs::write(&tampered, value.to_string()).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_xtask"))
        .args(["reproduce", "--quiet", "--work"])
        .arg(&work)
        .arg("--check")
        .arg(&tampered)
        .output()
        .expect("the xtask binary runs");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{stdout}");
    assert!(
        stdout.contains("← differs") && stdout.contains("not reproduced: 1 of 18 numbers differ"),
        "{stdout}"
    );
    assert!(stderr.contains("tampered.result.json"), "{stderr}");
}

#[test]
fn bad_arguments_are_errors_that_name_the_argument() {
    for (args, named) in [
        (&["--jobs", "0"][..], "--jobs"),
        (&["--epochs", "0"][..], "--epochs"),
        (&["--epochs", "5", "--converged"][..], "--converged"),
        (&["--seeds", "0"][..], "--seeds"),
        (&["--dataset", "swing"][..], "--dataset"),
        (&["--protocol", "nope"][..], "--protocol"),
        (&["--columns", "ours,mine"][..], "--columns"),
    ] {
        let out = Command::new(env!("CARGO_BIN_EXE_xtask"))
            .args(["reproduce", "--quiet", "--report-only", "--work"])
            .arg(std::env::temp_dir().join("xtask-bad-arguments-never-written"))
            .args(args)
            .output()
            .expect("the xtask binary runs");
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{args:?} was accepted");
        assert!(stderr.contains(named), "{args:?}: {stderr}");
        // An unknown name is quoted beside the known ones.
        if named == "--columns" {
            assert!(
                stderr.contains("\"mine\"") && stderr.contains("no-pool"),
                "{stderr}"
            );
        }
    }
}
