//! Training on a small synthetic set: the model folder, resumption that reproduces an
//! uninterrupted run bit for bit, refusal to overwrite, evaluation and a foreign set.

mod common;

use candle_core::Device;
use common::{assert_same_run, looking_request, options, request, scratch, small_set};
use meshvae::{
    EpochRecord, ModelFolder, Schedule, StopReason, TrainOptions, TrainedModel, VaeError, read_log,
    read_status, train,
};
use std::path::{Path, PathBuf};

#[test]
fn resumed_training_ends_with_the_weights_of_an_uninterrupted_run() {
    resumption_is_exact(&TrainOptions::default().best_in_memory_params, "mem");
    // Best weights written as soon as they improve (what large models do).
    resumption_is_exact(&0, "disk");
}

/// The checkpoint holds the best epoch's state, not the last one's (the folder keeps one copy
/// of the weights): a run killed after its best epoch resumes from that epoch and trains the
/// later ones again, ending bit for bit as the uninterrupted run.
#[test]
fn a_run_killed_after_its_best_epoch_replays_the_later_epochs_to_the_same_end() {
    for (in_memory, tag) in [(16usize << 20, "mem"), (0, "disk")] {
        let options = |resume: bool, checkpoint_seconds: f64| TrainOptions {
            best_in_memory_params: in_memory,
            checkpoint_seconds,
            test_every_steps: 1,
            ..options(resume, false)
        };
        let set = small_set(3, 8);
        let epochs = 12;
        let req = |out: &Path| {
            let mut r = request(&set, out, epochs);
            // A rate large enough that the validation loss does not fall every epoch.
            r.train.lr = 0.03;
            r.train.schedule = Schedule::constant();
            r
        };
        let whole = scratch(&format!("replay-whole-{tag}"));
        let whole_run = train(&req(&whole), &options(false, 60.0), |_| {}).unwrap();
        let best = whole_run.best_epoch;
        assert!(
            best < epochs,
            "the best epoch is the last: nothing to replay"
        );

        // Every best written as it comes, then "killed" after the last epoch was logged but
        // before the run recorded its end.
        let parts = scratch(&format!("replay-parts-{tag}"));
        train(&req(&parts), &options(false, 0.0), |_| {}).unwrap();
        let folder = ModelFolder::new(&parts);
        let status = std::fs::read_to_string(folder.status()).unwrap();
        std::fs::write(
            folder.status(),
            status.replace("\"budget\"", "\"interrupted\""),
        )
        .unwrap();
        let meta = mesh_io::stamped::format_of(&std::fs::read(folder.weights()).unwrap());
        assert_eq!(meta.as_deref(), Some("meshvae-weights"));
        // Killed while writing the pair: after the checkpoint, the new weights are still
        // pending (settled on resumption); before it, a half-written pending file is dropped.
        let pending = folder.pending_weights();
        if tag == "mem" {
            std::fs::rename(folder.weights(), &pending).unwrap();
            std::fs::write(folder.weights(), b"the previous best, say").unwrap();
        } else {
            std::fs::write(&pending, b"half a file").unwrap();
        }
        let resumed = train(&req(&parts), &options(true, 60.0), |_| {}).unwrap();
        assert_eq!(resumed.epochs_run, epochs - best, "{tag}");
        assert!(!pending.exists());

        let fw = ModelFolder::new(&whole);
        let read = |p: PathBuf| std::fs::read(p).unwrap();
        assert!(
            read(fw.weights()) == read(folder.weights()),
            "{tag}: weights"
        );
        let tensors = |f: &ModelFolder| {
            let mut map: Vec<(String, Vec<u64>)> =
                candle_core::safetensors::load(f.checkpoint(), &Device::Cpu)
                    .unwrap()
                    .into_iter()
                    .filter(|(k, _)| k != "progress.seconds")
                    .map(|(k, t)| {
                        let t = t.flatten_all().unwrap();
                        let t = t.to_dtype(candle_core::DType::F64).unwrap();
                        let values = t.to_vec1::<f64>().unwrap();
                        (k, values.iter().map(|x| x.to_bits()).collect())
                    })
                    .collect();
            map.sort();
            map
        };
        let (a, b) = (tensors(&fw), tensors(&folder));
        // No weights in the checkpoint: they are weights.safetensors.
        assert!(a.iter().all(|(k, _)| !k.starts_with("model.")));
        assert!(a.iter().any(|(k, _)| k.starts_with("adam.m.")));
        assert!(a == b, "{tag}: checkpoints differ");
        let epochs_done = a.iter().find(|(k, _)| k == "progress.epochs_done").unwrap();
        assert_eq!(f64::from_bits(epochs_done.1[0]), best as f64);
        let (la, lb) = (
            read_log(&fw.log()).unwrap(),
            read_log(&folder.log()).unwrap(),
        );
        assert_eq!(la.len(), epochs);
        let losses = |l: &[EpochRecord]| {
            l.iter()
                .map(|r| (r.epoch, r.train_loss, r.val_loss, r.test_loss))
                .collect::<Vec<_>>()
        };
        assert_eq!(losses(&la), losses(&lb), "{tag}: logs differ");
        let (sa, sb) = (
            read_status(&fw).unwrap().unwrap(),
            read_status(&folder).unwrap(),
        );
        let sb = sb.unwrap();
        assert_eq!(
            (sa.epochs, sa.steps, sa.best_epoch),
            (sb.epochs, sb.steps, sb.best_epoch)
        );
        assert_eq!(sb.stop_reason, StopReason::Budget);
        let _ = std::fs::remove_dir_all(&whole);
        let _ = std::fs::remove_dir_all(&parts);
    }
}

/// The default training looks at the validation loss only every few steps, and `--clip` keeps
/// a running mean of the gradient norms: a run killed between two looks resumes from its
/// checkpoint (written only after a look) and ends bit for bit as the run that was never
/// stopped, the clip's running mean included.
#[test]
fn a_killed_run_resumes_between_looks() {
    let set = small_set(3, 8);
    let epochs = 14;
    let req = |out: &Path| looking_request(&set, out, epochs);
    let opts = |resume: bool| TrainOptions {
        checkpoint_seconds: 0.0,
        test_every_steps: 1,
        ..options(resume, false)
    };
    let whole = scratch("looks-whole");
    train(&req(&whole), &opts(false), |_| {}).unwrap();
    let log = read_log(&ModelFolder::new(&whole).log()).unwrap();
    let looked: Vec<bool> = log.iter().map(|r| r.val_loss.is_some()).collect();
    assert!(
        looked.contains(&false) && looked.iter().filter(|&&l| l).count() >= 3,
        "{looked:?}"
    );
    // Killed (a panic out of the epoch callback) after an epoch that was not looked at.
    let kill_after = 1 + looked[1..epochs - 1].iter().rposition(|&l| !l).unwrap();
    let parts = scratch("looks-parts");
    let killed = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        train(&req(&parts), &opts(false), |r| {
            assert!(r.epoch != kill_after, "killed");
        })
    }));
    assert!(killed.is_err());
    let resumed = train(&req(&parts), &opts(true), |_| {}).unwrap();
    assert!(resumed.epochs_run > 0 && resumed.epochs_run < epochs);
    assert_same_run(&whole, &parts, "killed between looks");
    let _ = std::fs::remove_dir_all(&whole);
    let _ = std::fs::remove_dir_all(&parts);
}

#[test]
fn resuming_a_finished_run_without_its_checkpoint_is_refused_and_keeps_the_weights() {
    let set = small_set(3, 8);
    let dir = scratch("no-checkpoint");
    train(&request(&set, &dir, 2), &options(false, false), |_| {}).unwrap();
    let folder = ModelFolder::new(&dir);
    std::fs::remove_file(folder.checkpoint()).unwrap();
    let weights = std::fs::read(folder.weights()).unwrap();
    let log = std::fs::read(folder.log()).unwrap();

    let err = train(&request(&set, &dir, 4), &options(true, false), |_| {}).unwrap_err();
    let msg = err.to_string();
    assert!(
        msg.contains("cannot resume") && msg.contains("checkpoint") && msg.contains("2 epochs"),
        "{msg}"
    );
    assert_eq!(std::fs::read(folder.weights()).unwrap(), weights);
    assert_eq!(std::fs::read(folder.log()).unwrap(), log);
    // The config still says 2 epochs: nothing was rewritten.
    assert!(
        std::fs::read_to_string(folder.config())
            .unwrap()
            .contains("\"epochs\": 2")
    );

    // A run killed before its first checkpoint (fewer epochs logged than it was asked for)
    // still restarts from scratch.
    let early = scratch("no-checkpoint-early");
    train(&request(&set, &early, 2), &options(false, false), |_| {}).unwrap();
    killed_before_its_first_checkpoint(&ModelFolder::new(&early), 1);
    let resumed = train(&request(&set, &early, 2), &options(true, false), |_| {}).unwrap();
    assert_eq!(resumed.epochs_run, 2);
    let _ = std::fs::remove_dir_all(&dir);
    let _ = std::fs::remove_dir_all(&early);
}

/// Makes a finished folder look like a run killed after `epochs` epochs and before its first
/// checkpoint: no checkpoint, that much log, and a run.json that still says `interrupted`.
fn killed_before_its_first_checkpoint(folder: &ModelFolder, epochs: usize) {
    std::fs::remove_file(folder.checkpoint()).unwrap();
    let text = std::fs::read_to_string(folder.log()).unwrap();
    let kept: String = text
        .lines()
        .take(epochs)
        .map(|l| format!("{l}\n"))
        .collect();
    std::fs::write(folder.log(), kept).unwrap();
    let status = std::fs::read_to_string(folder.status()).unwrap();
    assert!(status.contains("\"budget\""), "{status}");
    let status = status.replace("\"budget\"", "\"interrupted\"");
    std::fs::write(folder.status(), status).unwrap();
}

#[test]
fn a_step_budget_run_killed_before_its_first_checkpoint_restarts() {
    // Its config's `epochs` (here 1) is not its length: more epochs logged than that, no
    // checkpoint and a run.json that never left `interrupted` is a run cut short, not a
    // finished one.
    let set = small_set(3, 8);
    let dir = scratch("no-checkpoint-steps");
    let mut req = request(&set, &dir, 1);
    req.train.steps = Some(12);
    let whole = train(&req, &options(false, false), |_| {}).unwrap();
    assert!(whole.epochs_run >= 3, "{} epochs", whole.epochs_run);
    let folder = ModelFolder::new(&dir);
    killed_before_its_first_checkpoint(&folder, 2);

    let resumed = train(&req, &options(true, false), |_| {}).unwrap();
    assert_eq!(
        resumed.epochs_run, whole.epochs_run,
        "trained again from scratch"
    );
    assert_eq!(
        read_status(&folder).unwrap().unwrap().stop_reason,
        meshvae::StopReason::Budget
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// Rewrites a model folder's checkpoint in the layout of version 1: no metadata, the weights
/// inside as `model.*`, Adam's names prefixed twice, the counters packed into `meta.*` tensors.
fn to_version_1(folder: &ModelFolder) {
    use candle_core::Tensor;
    let path = folder.checkpoint();
    let mut map = candle_core::safetensors::load(&path, &Device::Cpu).unwrap();
    let weights = candle_core::safetensors::load(folder.weights(), &Device::Cpu).unwrap();
    let held = map.len();
    map.extend(weights.into_iter().map(|(k, t)| (format!("model.{k}"), t)));
    assert!(map.len() > held + 10);
    let get = |k: &str| map[k].flatten_all().unwrap();
    let cat =
        |keys: &[&str]| Tensor::cat(&keys.iter().map(|k| get(k)).collect::<Vec<_>>(), 0).unwrap();
    let mut old: std::collections::HashMap<String, Tensor> = map
        .iter()
        .filter_map(|(k, t)| {
            if k.starts_with("model.") {
                Some((k.clone(), t.clone()))
            } else {
                k.starts_with("adam.")
                    .then(|| (format!("adam.{k}"), t.clone()))
            }
        })
        .collect();
    old.insert("meta.rng".into(), get("progress.rng"));
    old.insert(
        "meta.epoch".into(),
        cat(&[
            "progress.epochs_done",
            "progress.best_epoch",
            "progress.best_test_epoch",
        ]),
    );
    old.insert(
        "meta.best_loss".into(),
        cat(&["progress.best_loss", "progress.best_test_loss"]),
    );
    old.insert("meta.schedule".into(), get("progress.schedule"));
    old.insert("meta.seconds".into(), get("progress.seconds"));
    // Eight progress tensors became five.
    assert_eq!(old.len(), map.len() - 3);
    candle_core::safetensors::save(&old, &path).unwrap();
}

fn resumption_is_exact(best_in_memory_params: &usize, tag: &str) {
    let options = |resume: bool, force: bool| TrainOptions {
        best_in_memory_params: *best_in_memory_params,
        // Every epoch's test loss, to compare the two logs line by line.
        test_every_steps: 1,
        ..options(resume, force)
    };
    let set = small_set(3, 8);
    let whole = scratch(&format!("whole-{tag}"));
    let parts = scratch(&format!("parts-{tag}"));
    // Validation after every epoch: the "interrupted" run below is a run whose budget ended,
    // and a run always looks at its last epoch, so with a look every N steps it would look at
    // one epoch more than the uninterrupted run. (A killed run resumes from its last
    // checkpoint, written only after a look: `a_killed_run_resumes_between_looks`.)
    let request = |set, out, epochs| {
        let mut r = request(set, out, epochs);
        r.train.schedule.validate_every_steps = 0;
        r
    };

    let summary = train(&request(&set, &whole, 4), &options(false, false), |_| {}).unwrap();
    assert_eq!(summary.epochs_run, 4);

    // "Interrupted" after two epochs, then resumed to four. A killed run may have logged an
    // epoch after its last checkpoint: resumption replays it.
    train(&request(&set, &parts, 2), &options(false, false), |_| {}).unwrap();
    let log = ModelFolder::new(&parts).log();
    let mut text = std::fs::read_to_string(&log).unwrap();
    text.push_str(
        &text
            .lines()
            .last()
            .unwrap()
            .replace("\"epoch\":2", "\"epoch\":3"),
    );
    text.push('\n');
    std::fs::write(&log, text).unwrap();
    if tag == "disk" {
        // Checkpoints written before the metadata convention resume exactly too.
        to_version_1(&ModelFolder::new(&parts));
    }
    let resumed = train(&request(&set, &parts, 4), &options(true, false), |_| {}).unwrap();
    assert_eq!(resumed.epochs_run, 2);

    // Every tensor of the checkpoint but the wall time spent.
    let checkpoint = |dir: &Path| {
        let mut map =
            candle_core::safetensors::load(ModelFolder::new(dir).checkpoint(), &Device::Cpu)
                .unwrap()
                .into_iter()
                .filter(|(k, _)| k != "progress.seconds")
                .map(|(k, t)| {
                    let t = t
                        .flatten_all()
                        .unwrap()
                        .to_dtype(candle_core::DType::F64)
                        .unwrap();
                    let bits: Vec<u64> = t
                        .to_vec1::<f64>()
                        .unwrap()
                        .iter()
                        .map(|x| x.to_bits())
                        .collect();
                    (k, bits)
                })
                .collect::<Vec<_>>();
        map.sort();
        map
    };
    let (a, b) = (checkpoint(&whole), checkpoint(&parts));
    assert!(a.len() > 10 && a.iter().any(|(k, _)| k == "progress.schedule"));
    assert!(a == b, "checkpoints differ after resumption");
    let a = std::fs::read(ModelFolder::new(&whole).weights()).unwrap();
    let b = std::fs::read(ModelFolder::new(&parts).weights()).unwrap();
    assert!(a == b, "best weights differ after resumption");
    let log_a = read_log(&ModelFolder::new(&whole).log()).unwrap();
    let log_b = read_log(&ModelFolder::new(&parts).log()).unwrap();
    assert_eq!(log_a.len(), 4);
    for (x, y) in log_a.iter().zip(&log_b) {
        assert_eq!(
            (x.epoch, x.train_loss, x.test_loss),
            (y.epoch, y.train_loss, y.test_loss)
        );
    }
    // Loss goes down on this easy set.
    assert!(log_a[3].train_loss < log_a[0].train_loss, "{log_a:?}");

    // A resumed run that is already complete does nothing.
    let again = train(&request(&set, &parts, 4), &options(true, false), |_| {}).unwrap();
    assert_eq!(again.epochs_run, 0);

    // Resuming with other settings is refused, naming what differs.
    let mut other = request(&set, &parts, 5);
    other.train.lr = 0.05;
    let err = train(&other, &options(true, false), |_| {}).unwrap_err();
    assert!(err.to_string().contains("training settings"), "{err}");

    let _ = std::fs::remove_dir_all(&whole);
    let _ = std::fs::remove_dir_all(&parts);
}

#[test]
fn model_folder_is_complete_refuses_overwrite_and_evaluates() {
    let set = small_set(5, 8);
    let out = scratch("folder");
    train(&request(&set, &out, 2), &options(false, false), |_| {}).unwrap();
    let folder = ModelFolder::new(&out);
    for path in [
        folder.config(),
        folder.hierarchy(),
        folder.normalization(),
        folder.split(),
        folder.template(),
        folder.weights(),
        folder.checkpoint(),
        folder.log(),
    ] {
        assert!(path.is_file(), "missing {}", path.display());
    }

    // The training's lock is gone once it ended.
    assert!(!out.join("training.lock").exists());

    let err = train(&request(&set, &out, 2), &options(false, false), |_| {}).unwrap_err();
    assert!(matches!(err, VaeError::Model { .. }), "{err}");
    assert!(err.to_string().contains("already holds a model"), "{err}");
    // A folder another training holds (here: a live process, this one) is refused, resumed or
    // replaced alike, and left as it was.
    std::fs::write(out.join("training.lock"), std::process::id().to_string()).unwrap();
    let log = std::fs::read_to_string(folder.log()).unwrap();
    for (resume, force) in [(true, false), (false, true)] {
        let err = train(&request(&set, &out, 3), &options(resume, force), |_| {}).unwrap_err();
        assert!(
            err.to_string().contains("is being trained by process"),
            "{err}"
        );
    }
    assert_eq!(std::fs::read_to_string(folder.log()).unwrap(), log);
    std::fs::remove_file(out.join("training.lock")).unwrap();
    train(&request(&set, &out, 1), &options(false, true), |_| {}).unwrap();

    let trained = TrainedModel::load(&out, &Device::Cpu).unwrap();
    let report = trained.evaluate(&set, &Device::Cpu).unwrap();
    let val = trained.split.val.len();
    assert!(val >= 1, "the default carves a validation set");
    assert_eq!(report.test.meshes + val + report.train.meshes, set.len());
    assert!(report.test.rms.is_finite() && report.test.rms > 0.0);
    assert!((report.test.rms_x1000 - 1000.0 * report.test.rms).abs() < 1e-9);
    assert_eq!(report.params, trained.model.param_count());

    // Another connectivity is a clear error.
    let foreign = small_set(5, 9);
    let err = trained.evaluate(&foreign, &Device::Cpu).unwrap_err();
    assert!(err.to_string().contains("vertices"), "{err}");
    let _ = std::fs::remove_dir_all(&out);
}

#[test]
fn not_a_model_folder_and_bad_settings_are_typed_errors() {
    let missing = scratch("missing");
    let err = TrainedModel::load(&missing, &Device::Cpu).unwrap_err();
    assert!(err.to_string().contains("not a model folder"), "{err}");

    let set = small_set(3, 8);
    let out = scratch("bad");
    let mut bad = request(&set, &out, 1);
    bad.train.batch = 0;
    assert!(train(&bad, &options(false, false), |_| {}).is_err());
    let mut bad = request(&set, &out, 1);
    bad.train.lr = f64::NAN;
    let err = train(&bad, &options(false, false), |_| {}).unwrap_err();
    assert!(err.to_string().contains("lr"), "{err}");
    let err = train(&request(&set, &out, 0), &options(false, false), |_| {}).unwrap_err();
    assert!(err.to_string().contains("epochs"), "{err}");
    // A bad model setting is refused before anything is written.
    let mut bad = request(&set, &out, 1);
    bad.model.latent = 0;
    let err = train(&bad, &options(false, false), |_| {}).unwrap_err();
    assert!(err.to_string().contains("latent"), "{err}");
    assert!(
        !ModelFolder::new(&out).has_model(),
        "a refused run left a config.json"
    );
    let _ = std::fs::remove_dir_all(&out);
}
