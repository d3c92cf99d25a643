//! `meshvae train`, `eval`, `reconstruct` end to end on a small synthetic set.

mod common;

use common::{fails_with, meshvae, ok, s, synth_case, train_short};

#[test]
fn train_eval_reconstruct_on_a_synthetic_set() {
    let (dir, set, model) = synth_case("train", 4);
    let train = |extra: &[&str]| {
        let mut args = vec![
            "train",
            s(&set),
            "--out",
            s(&model),
            "--epochs",
            "2",
            "--batch",
            "4",
            "--latent",
            "16",
            "--quiet",
        ];
        args.extend_from_slice(extra);
        meshvae(&args)
    };
    // Keeps the weights chosen on the test loss too (`eval --select-on-test` below); resuming
    // goes on keeping them.
    let out = train(&["--keep-selected-on-test"]);
    assert!(out.status.success());
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stdout.contains("trained 2 epoch(s)"), "{stdout}");
    assert!(stdout.contains("loss curves: "), "{stdout}");
    // Two epochs are far from converged: the budget stopped a run that was still learning.
    assert!(
        stderr.contains("warning: stopped by the budget") && stderr.contains("--resume --steps"),
        "{stderr}"
    );

    // Another run into the same folder is refused; --resume continues, --force replaces.
    fails_with(&train(&[]), 1, "already holds a model");
    let resume = |extra: &[&str]| {
        let mut args = vec!["train", s(&set), "--out", s(&model), "--resume", "--quiet"];
        args.extend_from_slice(extra);
        meshvae(&args)
    };
    let out = ok(&resume(&["--epochs", "3"]));
    assert!(out.contains("trained 1 epoch(s)"), "{out}");
    // A budget below what the run has trained is refused, and config.json stays as it was.
    let config = std::fs::read(model.join("config.json")).unwrap();
    fails_with(
        &resume(&["--epochs", "2"]),
        1,
        "cannot resume with --epochs 2: the model has already trained 3 epochs",
    );
    fails_with(&resume(&["--steps", "1"]), 1, "already trained");
    assert_eq!(std::fs::read(model.join("config.json")).unwrap(), config);
    fails_with(&resume(&["--steps", "0"]), 1, "steps");
    fails_with(&resume(&["--epochs", "4", "--steps", "9"]), 2, "--steps");
    fails_with(&resume(&["--lr", "0.5"]), 1, "cannot resume");
    // The optimiser's settings too: a resumed run trains as it began or not at all.
    for flag in [
        ["--clip", "2"],
        ["--beta2", "0.999"],
        ["--head-lr-scale", "1"],
    ] {
        fails_with(&resume(&flag), 1, "cannot resume");
    }
    // The split is drawn by shape unless asked otherwise, and a model keeps its kind of split.
    let split = |dir: &std::path::Path| -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(dir.join("split.json")).unwrap()).unwrap()
    };
    assert_eq!(split(&model)["by_shape"], true);
    fails_with(&resume(&["--split-by-mesh"]), 1, "cannot resume");
    // One epoch into a new folder, with `extra` options.
    let one_epoch = |out: &std::path::Path, extra: &[&str]| {
        ok(&train_short(&set, out, 1, extra));
    };
    let by_mesh = dir.join("by-mesh");
    one_epoch(&by_mesh, &["--split-by-mesh"]);
    assert_eq!(split(&by_mesh)["by_shape"], false);
    // A run killed in its first epoch (run.json says interrupted, no checkpoint, nothing
    // logged): --resume says that it starts again instead of passing a restart off as a
    // continuation.
    std::fs::remove_file(by_mesh.join("checkpoint.safetensors")).unwrap();
    std::fs::write(by_mesh.join("log.jsonl"), "").unwrap();
    let status = std::fs::read_to_string(by_mesh.join("run.json")).unwrap();
    let killed = status.replace("\"budget\"", "\"interrupted\"");
    assert_ne!(killed, status);
    std::fs::write(by_mesh.join("run.json"), killed).unwrap();
    let out = meshvae(&[
        "train",
        s(&set),
        "--out",
        s(&by_mesh),
        "--resume",
        "--epochs",
        "1",
        "--split-by-mesh",
        "--batch",
        "4",
        "--latent",
        "16",
        "--quiet",
    ]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(ok(&out).contains("trained 1 epoch(s)"));
    assert!(
        stderr.contains("no checkpoint to continue from")
            && stderr.contains("restarts from epoch 1"),
        "{stderr}"
    );
    // The authors' choices where they differ from ours, for A/B runs, recorded in config.json.
    let authors = dir.join("authors");
    one_epoch(
        &authors,
        &[
            "--no-batch-norm",
            "--last-encoder-tanh",
            "--normalize-on-all",
        ],
    );
    let config: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(authors.join("config.json")).unwrap())
            .unwrap();
    assert_eq!(config["model"]["batch_norm"], false);
    assert_eq!(config["model"]["last_encoder_linear"], false);
    assert_eq!(config["train"]["normalize_on_all"], true);
    assert!(config["train"]["schedule"]["patience"].as_u64().unwrap() > 0);
    // The synthetic set has no repeated shape: both ways draw the same meshes.
    assert_eq!(split(&by_mesh)["test"], split(&model)["test"]);

    let json = ok(&meshvae(&["eval", s(&model), "--json"]));
    let v: serde_json::Value = serde_json::from_str(&json).unwrap();
    for key in [
        "test_rms",
        "test_rms_x1000",
        "test_rms_rel",
        "train_rms",
        "params",
        "epochs",
        "vertices",
        "selected_on",
        "val_meshes",
        "split_by_shape",
        "stop_reason",
        "steps",
        "test_mean_distance_rigid",
        "loss_plot",
    ] {
        assert!(v.get(key).is_some(), "eval --json lacks {key}: {json}");
    }
    assert_eq!(v["epochs"], 3);
    // Three epochs of a falling loss: cut by the budget, still improving.
    assert_eq!(v["stop_reason"], "budget");
    assert_eq!(v["still_improving"], true);
    assert!(
        v["test_mean_distance_rigid"].as_f64().unwrap()
            <= v["test_mean_distance"].as_f64().unwrap()
    );
    // loss.png: a picture of the three epochs' losses.
    let png = model.join("loss.png");
    assert_eq!(v["loss_plot"].as_str(), Some(s(&png)));
    let plot = mesh_render::Image::decode_png(&std::fs::read(&png).unwrap()).unwrap();
    assert_eq!((plot.width, plot.height), (1000, 600));
    let text = ok(&meshvae(&["eval", s(&model)]));
    assert!(
        text.contains("stopped      budget WHILE STILL IMPROVING"),
        "{text}"
    );
    assert!(text.contains("loss curves"), "{text}");
    // 8 meshes: 4 test, 4 training of which one validates and chooses the weights.
    assert_eq!(
        (v["selected_on"].as_str(), v["val_meshes"].as_u64()),
        (Some("validation"), Some(1))
    );
    assert_eq!(v["train_meshes"], 3);
    let text = ok(&meshvae(&["eval", s(&model)]));
    assert!(text.contains("split        random, by shape"), "{text}");
    assert!(
        text.contains("chosen on the validation loss; 1 validation meshes")
            && !text.contains("SELECTED ON TEST"),
        "{text}"
    );
    // The authors' protocol on request, labelled as such.
    let text = ok(&meshvae(&["eval", s(&model), "--select-on-test"]));
    assert!(text.contains("SELECTED ON TEST"), "{text}");
    let json = ok(&meshvae(&["eval", s(&model), "--select-on-test", "--json"]));
    let on_test: serde_json::Value = serde_json::from_str(&json).unwrap();
    assert_eq!(on_test["selected_on"], "test");
    assert_eq!(v["vertices"], 2498);
    // Weights written by another program (meshvae.torch's save copies these files and writes
    // the weights): no run.json, no log, and eval says their training is not recorded.
    let bare = dir.join("bare");
    std::fs::create_dir_all(&bare).unwrap();
    for entry in std::fs::read_dir(&model).unwrap() {
        let path = entry.unwrap().path();
        let name = path.file_name().unwrap().to_str().unwrap().to_string();
        let training = [
            "run.json",
            "log.jsonl",
            "loss.png",
            "checkpoint.safetensors",
        ];
        if path.is_file() && !training.contains(&name.as_str()) {
            std::fs::copy(&path, bare.join(&name)).unwrap();
        }
    }
    let out = meshvae(&["eval", s(&bare)]);
    let text = ok(&out);
    assert!(text.contains("stopped      unrecorded"), "{text}");
    assert!(text.contains("epochs       unrecorded"), "{text}");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!stderr.contains("loss.png"), "{stderr}");
    let bare_json: serde_json::Value =
        serde_json::from_str(&ok(&meshvae(&["eval", s(&bare), "--json"]))).unwrap();
    assert_eq!(bare_json["stop_reason"], "unrecorded");
    assert!(bare_json["epochs"].is_null() && bare_json["loss_plot"].is_null());
    assert_eq!(bare_json["test_rms"], v["test_rms"]);
    // --resume on such a folder continues from its weights (not from a fresh start).
    let out = meshvae(&[
        "train",
        s(&set),
        "--out",
        s(&bare),
        "--resume",
        "--epochs",
        "1",
        "--batch",
        "4",
        "--latent",
        "16",
        "--quiet",
    ]);
    ok(&out);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("training continues from them"), "{stderr}");
    let first_loss = |folder: &std::path::Path| -> f64 {
        let log = std::fs::read_to_string(folder.join("log.jsonl")).unwrap();
        let first: serde_json::Value = serde_json::from_str(log.lines().next().unwrap()).unwrap();
        first["train_loss"].as_f64().unwrap()
    };
    let (continued, fresh) = (first_loss(&bare), first_loss(&model));
    assert!(
        continued < fresh,
        "first epoch from the weights {continued}, fresh {fresh}"
    );
    assert!(v["test_rms"].as_f64().unwrap() > 0.0);

    let rec = dir.join("rec");
    let out = ok(&meshvae(&["reconstruct", s(&model), "--out", s(&rec)]));
    assert!(out.contains("wrote 4 reconstructed meshes"), "{out}");
    let objs: Vec<_> = std::fs::read_dir(&rec)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    assert_eq!(objs.len(), 4);
    // Written where `eval` measures them: each centroid on its original's.
    let centroid = |path: &std::path::Path| {
        let mesh = mesh_io::read_mesh(path).unwrap().value;
        let n = mesh.positions.len() as f64;
        let mut c = [0.0f64; 3];
        for p in &mesh.positions {
            for k in 0..3 {
                c[k] += f64::from(p[k]) / n;
            }
        }
        c
    };
    for obj in &objs {
        let (a, b) = (centroid(obj), centroid(&set.join(obj.file_name().unwrap())));
        let gap = (0..3).map(|k| (a[k] - b[k]).powi(2)).sum::<f64>().sqrt();
        assert!(gap < 1e-4, "{}: centroid {gap} away", obj.display());
    }
    // With --sheet: truth beside reconstruction for the 4 test meshes, 2 pairs per row, under
    // a colour bar.
    let rec_sheet = dir.join("rec-sheet");
    let out = ok(&meshvae(&[
        "reconstruct",
        s(&model),
        "--out",
        s(&rec_sheet),
        "--sheet",
        "--view",
        "left",
    ]));
    assert!(out.contains("and sheet.png"), "{out}");
    let bytes = std::fs::read(rec_sheet.join("sheet.png")).unwrap();
    let image = mesh_render::Image::decode_png(&bytes).unwrap();
    let caption = mesh_render::caption_height(256);
    assert!(
        image.width >= 4 * 256 && image.height > 2 * caption + 40,
        "{}x{}",
        image.width,
        image.height
    );
    // Seen from the left the capsules lie: tiles lower than square, without empty bands (two
    // rows of square tiles alone would be taller).
    assert!(image.height < 2 * (256 + caption), "{}", image.height);
    // The bar heads the sheet: its hottest colour (the last column but the frame) sits in the
    // top band.
    let hot = mesh_render::error_color(1.0);
    let near = |c: [u8; 3]| (0..3).all(|k| c[k].abs_diff(hot[k]) <= 6);
    assert!(
        (0..60).any(|y| (0..image.width).any(|x| image.pixel(x, y).is_some_and(near))),
        "no colour bar at the top"
    );
    fails_with(
        &meshvae(&[
            "reconstruct",
            s(&model),
            "--out",
            s(&rec_sheet),
            "--view",
            "diagonal",
        ]),
        2,
        "--view",
    );

    // Bad arguments and a foreign set.
    fails_with(&train(&["--structure", "CXC"]), 2, "--structure");
    let other = dir.join("other");
    std::fs::create_dir_all(&other).unwrap();
    for name in ["a.obj", "b.obj"] {
        std::fs::write(
            other.join(name),
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 3 4\nf 1 4 2\nf 2 4 3\n",
        )
        .unwrap();
    }
    fails_with(
        &meshvae(&["eval", s(&model), "--set", s(&other)]),
        1,
        "vertices",
    );
    fails_with(&meshvae(&["eval", s(&dir)]), 1, "not a model folder");
}

/// Kills training ten times at pseudo-random moments while it writes a checkpoint after every
/// epoch; the next run cleans what the kills left, and every file of the folder stays readable.
#[test]
fn killed_runs_leave_no_temporary_files_and_readable_folders() {
    use std::process::{Command, Stdio};
    let (_dir, set, model) = synth_case("kill", 3);
    let args = |resume: bool, epochs: &str| -> Vec<String> {
        let mut a = vec![
            "train",
            s(&set),
            "--out",
            s(&model),
            "--epochs",
            epochs,
            "--batch",
            "4",
            "--latent",
            "16",
            "--checkpoint-seconds",
            "0",
            "--quiet",
        ];
        if resume {
            a.push("--resume");
        }
        a.into_iter().map(String::from).collect()
    };
    let run = |a: Vec<String>| meshvae(&a.iter().map(String::as_str).collect::<Vec<_>>());
    // xorshift: the same "random" moments on every run of the test.
    let mut state = 0x9e37_79b9_7f4a_7c15u64;
    let mut killed_with_temporary = 0;
    for round in 0..10 {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        let wait = std::time::Duration::from_millis(300 + state % 1200);
        // The first run starts the folder; the others continue it (or restart it, if it was
        // killed before its first checkpoint).
        let resume = model.join("config.json").is_file();
        let mut child = Command::new(env!("CARGO_BIN_EXE_meshvae"))
            .args(args(resume, "100000"))
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        std::thread::sleep(wait);
        let _ = child.kill();
        child.wait().unwrap();
        let temporaries = temporaries(&model);
        killed_with_temporary += usize::from(!temporaries.is_empty());
        let logged = std::fs::read_to_string(model.join("log.jsonl"))
            .map(|t| t.lines().count())
            .unwrap_or(0);
        eprintln!(
            "round {round}: killed after {wait:?}, {logged} epochs logged, temporaries {temporaries:?}"
        );
    }
    // One more left by hand, so that the cleaning is tested whatever the kills hit.
    std::fs::write(
        model.join(".checkpoint.safetensors.tmp"),
        b"half a checkpoint",
    )
    .unwrap();
    eprintln!("{killed_with_temporary} of 10 kills left a temporary file");
    let done: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(model.join("run.json")).unwrap()).unwrap();
    let epochs = (done["epochs"].as_u64().unwrap() + 2).to_string();
    ok(&run(args(true, &epochs)));
    assert_eq!(temporaries(&model), Vec::<String>::new());
    // Every file reads: the evaluation loads the settings, split, hierarchy, normalisation and
    // weights; the log and run.json parse; the checkpoint continues.
    ok(&meshvae(&["eval", s(&model), "--json"]));
    for line in std::fs::read_to_string(model.join("log.jsonl"))
        .unwrap()
        .lines()
    {
        serde_json::from_str::<serde_json::Value>(line).unwrap();
    }
    let more = (done["epochs"].as_u64().unwrap() + 3).to_string();
    ok(&run(args(true, &more)));
}

fn temporaries(dir: &std::path::Path) -> Vec<String> {
    std::fs::read_dir(dir)
        .map(|entries| {
            entries
                .filter_map(|e| e.ok())
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .filter(|n| n.starts_with('.') && n.ends_with(".tmp"))
                .collect()
        })
        .unwrap_or_default()
}

#[test]
fn a_model_the_engine_does_not_cover_says_so_in_training_and_in_eval() {
    let (dir, set, model) = synth_case("train-k9", 3);
    let train = |out: &std::path::Path, extra: &[&str]| ok(&train_short(&set, out, 1, extra));
    let trained = train(&model, &["--k", "9"]);
    let why = "candle (the engine does not cover K = 9 (at most 8))";
    assert!(
        trained.contains(&format!("steps computed by: {why}")),
        "{trained}"
    );
    let eval = meshvae(&["eval", s(&model)]);
    assert!(eval.status.success());
    let stderr = String::from_utf8_lossy(&eval.stderr);
    assert!(
        stderr.contains(&format!("note: the network runs on {why}")),
        "{stderr}"
    );
    // A model the engine covers prints no such note.
    let covered = dir.join("covered");
    train(&covered, &[]);
    let eval = meshvae(&["eval", s(&covered)]);
    assert!(!String::from_utf8_lossy(&eval.stderr).contains("runs on"));
}

/// The test loss is only watched: measured every 50 steps by default (and after the last
/// epoch), every epoch with `--test-every 1`, and the weights do not depend on it.
#[test]
fn the_test_loss_is_measured_every_50_steps_and_changes_no_weight() {
    let (dir, set, _) = synth_case("test-every", 4);
    let test_losses = |out: &std::path::Path, extra: &[&str]| -> Vec<bool> {
        ok(&train_short(&set, out, 4, extra));
        std::fs::read_to_string(out.join("log.jsonl"))
            .unwrap()
            .lines()
            .map(|line| {
                let record: serde_json::Value = serde_json::from_str(line).unwrap();
                record["test_loss"].is_number()
            })
            .collect()
    };
    let (sparse, every) = (dir.join("sparse"), dir.join("every"));
    assert_eq!(test_losses(&sparse, &[]), [false, false, false, true]);
    assert_eq!(test_losses(&every, &["--test-every", "1"]), [true; 4]);
    let weights = |out: &std::path::Path| std::fs::read(out.join("weights.safetensors")).unwrap();
    assert_eq!(weights(&sparse), weights(&every));
}

/// Ctrl-C (SIGINT) stops a training cleanly: its best state written, status 130, and the
/// command that continues it on stderr, which then does.
#[cfg(unix)]
#[test]
fn ctrl_c_writes_the_run_and_says_how_to_continue_it() {
    use std::process::{Command, Stdio};
    let (_dir, set, model) = synth_case("ctrl-c", 3);
    // No timed checkpoint: what the folder holds after the signal, the signal wrote.
    let child = Command::new(env!("CARGO_BIN_EXE_meshvae"))
        .args(["train", s(&set), "--out", s(&model), "--epochs", "100000"])
        .args([
            "--batch",
            "4",
            "--latent",
            "16",
            "--checkpoint-seconds",
            "1e9",
        ])
        .arg("--quiet")
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Until the validation loss has been looked at twice (a best epoch exists).
    let looked = || {
        std::fs::read_to_string(model.join("log.jsonl")).map_or(0, |t| {
            (t.lines().filter(|l| !l.contains("\"val_loss\":null"))).count()
        })
    };
    let started = std::time::Instant::now();
    while looked() < 2 && started.elapsed().as_secs() < 300 {
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    assert!(looked() >= 2, "no validation loss logged in 300 s");
    let pid = child.id().to_string();
    let sent = Command::new("kill").args(["-INT", &pid]).status().unwrap();
    assert!(sent.success());
    let out = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(130), "{stderr}");
    assert!(
        stderr.contains("training interrupted after epoch"),
        "{stderr}"
    );
    let resume = format!(
        "continue it with: meshvae train {} --out {} --resume",
        s(&set),
        s(&model)
    );
    assert!(stderr.contains(&resume), "{stderr}");
    let status: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(model.join("run.json")).unwrap()).unwrap();
    assert_eq!(status["stop_reason"], "interrupted");
    assert!(model.join("checkpoint.safetensors").is_file());
    assert!(!model.join("training.lock").exists());
    // The printed command continues it (here with a budget two epochs past the stop).
    let epochs = (status["epochs"].as_u64().unwrap() + 2).to_string();
    let args = ["train", s(&set), "--out", s(&model), "--resume", "--quiet"];
    let out = ok(&meshvae(&[&args[..], &["--epochs", &epochs]].concat()));
    assert!(
        out.contains(&format!("of at most {epochs} epochs")),
        "{out}"
    );
}
