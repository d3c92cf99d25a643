//! Training on a small synthetic set: the model folder, resumption that reproduces an
//! uninterrupted run bit for bit, refusal to overwrite, evaluation and a foreign set.

use candle_core::Device;
use deform_features::FeatureOptions;
use mesh_hierarchy::HierarchyConfig;
use mesh_io::MeshSet;
use mesh_io::synth::{SynthConfig, generate};
use meshvae::{
    DEFAULT_MAX_STEPS, EpochRecord, ExecutorKind, ModelConfig, ModelFolder, RunStatus, Schedule,
    Selection, Split, SplitFile, StopReason, TrainConfig, TrainOptions, TrainRequest, TrainSummary,
    TrainedModel, VaeError, read_log, read_status, train,
};
use std::path::{Path, PathBuf};

fn small_set(seed: u64, rings: usize) -> MeshSet {
    generate(&SynthConfig {
        seed,
        meshes_per_label: 6,
        rings,
        segments: 10,
        cap_rings: 2,
        ..SynthConfig::default()
    })
    .expect("synthetic set")
    .set
}

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("meshvae-train-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

fn request<'a>(set: &'a MeshSet, out: &Path, epochs: usize) -> TrainRequest<'a> {
    TrainRequest {
        set,
        source: None,
        out: out.to_path_buf(),
        model: ModelConfig {
            latent: 16,
            ..ModelConfig::default()
        },
        train: TrainConfig {
            epochs,
            batch: 4,
            seed: 11,
            ..TrainConfig::default()
        },
        features: FeatureOptions::default(),
        hierarchy: HierarchyConfig::default(),
        split: None,
    }
}

fn options(resume: bool, force: bool) -> TrainOptions {
    TrainOptions {
        resume,
        force,
        ..TrainOptions::default()
    }
}

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
    let folder = ModelFolder::new(&early);
    std::fs::remove_file(folder.checkpoint()).unwrap();
    let text = std::fs::read_to_string(folder.log()).unwrap();
    let first: String = text.lines().take(1).map(|l| format!("{l}\n")).collect();
    std::fs::write(folder.log(), first).unwrap();
    // Such a run's run.json says it was interrupted.
    let status = std::fs::read_to_string(folder.status()).unwrap();
    let status = status.replace("\"budget\"", "\"interrupted\"");
    assert!(status.contains("interrupted"));
    std::fs::write(folder.status(), status).unwrap();
    let resumed = train(&request(&set, &early, 2), &options(true, false), |_| {}).unwrap();
    assert_eq!(resumed.epochs_run, 2);
    let _ = std::fs::remove_dir_all(&dir);
    let _ = std::fs::remove_dir_all(&early);
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

    let err = train(&request(&set, &out, 2), &options(false, false), |_| {}).unwrap_err();
    assert!(matches!(err, VaeError::Model { .. }), "{err}");
    assert!(err.to_string().contains("already holds a model"), "{err}");
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

#[test]
fn a_non_finite_loss_stops_training_with_a_message() {
    let set = small_set(3, 8);
    let out = scratch("nan");
    let mut req = request(&set, &out, 3);
    // The weighted reconstruction term overflows f32: the loss is infinite at the first step.
    req.train.loss.rec = 1e38;
    let err = train(&req, &options(false, false), |_| {}).unwrap_err();
    assert!(matches!(err, VaeError::Diverged(_)), "{err}");
    let text = err.to_string();
    assert!(text.contains("epoch 1") && text.contains("inf"), "{text}");
    assert!(!ModelFolder::new(&out).weights().exists());
    let _ = std::fs::remove_dir_all(&out);
}

/// Eight epochs on a small set at a constant rate whose step 9 diverges (and, with
/// `fail_after_rollback`, also the first step after that rollback): the summary, the log
/// (every epoch once, in order, all finite: a failed attempt is not logged), the status and
/// the base rate.
fn diverging_run(
    name: &str,
    fail_after_rollback: bool,
) -> (TrainSummary, Vec<EpochRecord>, RunStatus, f64) {
    let set = small_set(3, 8);
    let out = scratch(name);
    let mut req = request(&set, &out, 8);
    req.train.schedule = Schedule::constant();
    let options = TrainOptions {
        fail_step: Some(9),
        fail_after_rollback,
        ..options(false, false)
    };
    let summary = train(&req, &options, |_| {}).unwrap();
    assert_eq!(summary.epochs_total, 8);
    let folder = ModelFolder::new(&out);
    let log = read_log(&folder.log()).unwrap();
    let epochs: Vec<usize> = log.iter().map(|r| r.epoch).collect();
    assert_eq!(epochs, (1..=8).collect::<Vec<_>>());
    assert!(log.iter().all(|r| r.train_loss.is_finite()));
    let status = read_status(&folder).unwrap().unwrap();
    let _ = std::fs::remove_dir_all(&out);
    (summary, log, status, req.train.lr)
}

/// A divergence after the first epochs is not the end of the run: training goes back to the
/// best weights at half the rate, with fresh optimizer moments, and the run says so.
#[test]
fn a_divergence_rolls_back_to_the_best_weights_at_half_the_rate() {
    let (summary, log, status, lr) = diverging_run("rollback", false);
    let steps_per_epoch = log[0].step as usize;
    let failed_epoch = 8 / steps_per_epoch + 1;
    // After the rollback (8 steps taken) the halved rate warms up again over REWARM_STEPS.
    let rate = |step: u64| {
        let rewarm = ((step - 8) as f64 / meshvae::REWARM_STEPS as f64).min(1.0);
        (lr / 2.0) * rewarm
    };
    for r in &log {
        let expected = if r.epoch < failed_epoch {
            lr
        } else {
            rate(r.step)
        };
        let got = r.lr.unwrap();
        assert!(
            (got - expected).abs() <= 1e-12 * lr,
            "epoch {}: {got} vs {expected}",
            r.epoch
        );
    }
    // The steps of the abandoned attempt count: the optimizer took them.
    let failed_steps = 9 - (failed_epoch - 1) * steps_per_epoch;
    assert_eq!(
        summary.steps as usize,
        8 * steps_per_epoch + failed_steps - 1,
        "{log:?}"
    );
    assert_eq!((status.rollbacks, status.lr_cuts), (1, 1));
    assert!((status.lr - rate(summary.steps)).abs() <= 1e-12 * lr);
}

/// Best weights that diverge again before an epoch finishes cannot be gone back to: the run
/// starts over from its initial weights (at a quarter of the rate after two rollbacks) and
/// finishes.
#[test]
fn best_weights_that_cannot_take_a_step_give_way_to_the_initial_ones() {
    let (_, log, status, _) = diverging_run("rollback-initial", true);
    assert_eq!((status.rollbacks, status.lr_cuts), (2, 2));
    // Started over: the first epoch after the restart fits worse than the epoch before the
    // divergence did (the initial weights know nothing yet).
    let steps_per_epoch = log[0].step as usize;
    let failed_epoch = 8 / steps_per_epoch + 1;
    assert!(
        log[failed_epoch - 1].train_loss > log[failed_epoch - 2].train_loss,
        "{log:?}"
    );
}

/// The default protocol: no test mesh influences training or the choice of checkpoint. Two
/// runs whose sets differ only in the test meshes (bent out of shape) end with bit-identical
/// weights, checkpoints and validation losses; only the logged test losses differ.
#[test]
fn test_meshes_influence_neither_training_nor_the_chosen_checkpoint() {
    let set = small_set(3, 8);
    let out_a = scratch("leak-a");
    let out_b = scratch("leak-b");
    // Every epoch's test loss, to see each one differ.
    let options = |resume, force| TrainOptions {
        test_every_steps: 1,
        ..options(resume, force)
    };
    // Run a keeps the weights chosen on the test loss, b only their epoch: nothing else
    // changes.
    let keep = TrainOptions {
        keep_selected_on_test: true,
        ..options(false, false)
    };
    let a = train(&request(&set, &out_a, 4), &keep, |_| {}).unwrap();
    assert_eq!(a.selected_on, Selection::Validation);
    let split = TrainedModel::load(&out_a, &Device::Cpu).unwrap().split;
    assert!(!split.val.is_empty() && !split.test.is_empty());
    assert!(split.train.contains(&0), "the rest pose trains");

    let mut positions = Vec::new();
    for (i, frame) in set.frames().enumerate() {
        let test = split.test.contains(&i);
        positions.extend(frame.iter().map(|p| match test {
            true => [
                p[0] * 1.3 + 0.2 * p[1] * p[1],
                p[1] * 0.8,
                p[2] + 0.1 * p[0],
            ],
            false => *p,
        }));
    }
    let perturbed = MeshSet::from_flat(
        set.faces().to_vec(),
        set.vertex_count(),
        positions,
        set.names().to_vec(),
    )
    .unwrap();
    train(
        &request(&perturbed, &out_b, 4),
        &options(false, false),
        |_| {},
    )
    .unwrap();

    let (fa, fb) = (ModelFolder::new(&out_a), ModelFolder::new(&out_b));
    let read = |path: PathBuf| std::fs::read(path).unwrap();
    assert!(
        read(fa.weights()) == read(fb.weights()),
        "best weights differ"
    );
    // The checkpoints' training state (weights, batch-norm statistics, Adam's moments) is
    // identical; only their record of the best test loss differs.
    let state = |f: &ModelFolder| {
        let map = candle_core::safetensors::load(f.checkpoint(), &Device::Cpu).unwrap();
        let mut state: Vec<(String, Vec<f64>)> = map
            .into_iter()
            .filter(|(k, _)| k.starts_with("model.") || k.starts_with("adam."))
            .map(|(k, t)| {
                let t = t.flatten_all().unwrap();
                (
                    k,
                    t.to_dtype(candle_core::DType::F64)
                        .unwrap()
                        .to_vec1()
                        .unwrap(),
                )
            })
            .collect();
        state.sort_by(|a, b| a.0.cmp(&b.0));
        state
    };
    let (sa, sb) = (state(&fa), state(&fb));
    assert!(sa.len() > 10, "{} tensors", sa.len());
    for ((ka, a), (kb, b)) in sa.iter().zip(&sb) {
        assert_eq!(ka, kb);
        let same = a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits());
        assert!(same, "checkpointed {ka} differs");
    }
    let (log_a, log_b) = (read_log(&fa.log()).unwrap(), read_log(&fb.log()).unwrap());
    for (x, y) in log_a.iter().zip(&log_b) {
        assert_eq!((x.train_loss, x.val_loss), (y.train_loss, y.val_loss));
        assert_ne!(
            x.test_loss, y.test_loss,
            "the perturbation reached the test meshes"
        );
    }
    // The authors' protocol is still available, labelled, from its own weights file.
    assert!(fa.weights_selected_on_test().is_file());
    let on_test = TrainedModel::load_selected(&out_a, &Device::Cpu, true).unwrap();
    assert_eq!(on_test.selected_on, Selection::Test);
    let best_test = log_a
        .iter()
        .min_by(|x, y| x.test_loss.unwrap().total_cmp(&y.test_loss.unwrap()))
        .unwrap()
        .epoch;
    assert_eq!(on_test.epochs_trained().unwrap().1, best_test);
    // Weights of another epoch than run.json's choice (a resumed run that stopped keeping
    // them, say) are refused as stale.
    let status_path = fa.status();
    let mut status: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&status_path).unwrap()).unwrap();
    status["best_test_epoch"] = serde_json::json!(best_test + 100);
    std::fs::write(&status_path, status.to_string()).unwrap();
    let err = TrainedModel::load_selected(&out_a, &Device::Cpu, true)
        .err()
        .unwrap()
        .to_string();
    assert!(
        err.contains("stale") && err.contains(&format!("epoch {best_test}")),
        "{err}"
    );
    // Without the option, run.json names the epoch and the error says how to keep them.
    assert!(!fb.weights_selected_on_test().is_file());
    let best_test_b = log_b
        .iter()
        .min_by(|x, y| x.test_loss.unwrap().total_cmp(&y.test_loss.unwrap()))
        .unwrap()
        .epoch;
    let status = meshvae::read_status(&fb).unwrap().unwrap();
    assert_eq!(status.best_test_epoch, Some(best_test_b));
    let err = TrainedModel::load_selected(&out_b, &Device::Cpu, true)
        .err()
        .unwrap()
        .to_string();
    let epoch = format!("epoch {best_test_b}");
    assert!(
        err.contains("--keep-selected-on-test") && err.contains(&epoch),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(&out_a);
    let _ = std::fs::remove_dir_all(&out_b);
}

#[test]
fn copies_of_one_shape_stay_on_one_side_of_the_split() {
    // Every shape twice, as horse-gallop stores its gallop cycle.
    let once = small_set(5, 8);
    let n = once.len();
    let mut positions = Vec::new();
    let mut names = Vec::new();
    for copy in 0..2 {
        for (i, frame) in once.frames().enumerate() {
            positions.extend_from_slice(frame);
            names.push(format!("copy{copy}_{i:02}"));
        }
    }
    let twice =
        MeshSet::from_flat(once.faces().to_vec(), once.vertex_count(), positions, names).unwrap();
    let out = scratch("twins");
    let mut req = request(&twice, &out, 1);
    req.train.val_fraction = 0.25;
    train(&req, &options(false, false), |_| {}).unwrap();
    let folder = ModelFolder::new(&out);
    let file: SplitFile = folder.read_json(&folder.split()).unwrap();
    assert!(file.by_shape);
    let expected: Vec<Vec<usize>> = (0..n).map(|i| vec![i, i + n]).collect();
    assert_eq!(file.repeated_shapes, expected);
    let side = |i: usize| {
        (
            file.test.contains(&i),
            file.val.contains(&i),
            file.train.contains(&i),
        )
    };
    for i in 0..n {
        assert_eq!(side(i), side(i + n), "mesh {i} and its copy are split");
    }
    assert!(!file.test.is_empty() && !file.val.is_empty());
    assert_eq!(file.test.len(), n, "half of the shapes test");
    let trained = TrainedModel::load(&out, &Device::Cpu).unwrap();
    let report = trained.evaluate(&twice, &Device::Cpu).unwrap();
    assert_eq!(report.copies, None, "no test shape is trained on");

    // Opting out draws the test meshes one by one, exactly the plain random split...
    req.train.split_by_shape = false;
    train(&req, &options(false, true), |_| {}).unwrap();
    let file: SplitFile = folder.read_json(&folder.split()).unwrap();
    let plain = Split::random(2 * n, 0.5, req.train.seed).unwrap();
    assert!(!file.by_shape && file.repeated_shapes.is_empty());
    assert_eq!(file.test, plain.test);
    let mut trained_or_val = [file.train.clone(), file.val.clone()].concat();
    trained_or_val.sort_unstable();
    assert_eq!(trained_or_val, plain.train);
    // ...but validation shapes stay whole: no validation mesh has its copy among the training
    // meshes, so the validation loss measures unseen poses.
    let twin = |i: usize| (i + n) % (2 * n);
    assert!(!file.val.is_empty());
    for &i in &file.val {
        assert!(
            !file.train.contains(&twin(i)),
            "{i}'s copy trains: {file:?}"
        );
    }
    // Evaluation tells the test meshes whose copy trained from the others.
    let with_copy = file
        .test
        .iter()
        .filter(|&&i| file.train.contains(&twin(i)))
        .count();
    assert!(with_copy > 0 && with_copy < file.test.len(), "{file:?}");
    let trained = TrainedModel::load(&out, &Device::Cpu).unwrap();
    let report = trained.evaluate(&twice, &Device::Cpu).unwrap();
    let copies = report.copies.expect("some test shapes are trained on");
    let unseen = copies.unseen.expect("some are not");
    assert_eq!(copies.copy_in_training.meshes, with_copy);
    assert_eq!(unseen.meshes, file.test.len() - with_copy);
    // The two parts average to the whole (every mesh has as many vertices).
    let parts = copies.copy_in_training.mean_distance_rigid * with_copy as f64
        + unseen.mean_distance_rigid * unseen.meshes as f64;
    let whole = report.test.mean_distance_rigid * file.test.len() as f64;
    assert!(
        (parts - whole).abs() <= 1e-9 * whole.max(1e-12),
        "{parts} vs {whole}"
    );
    // A model trained by shape is not resumed as one drawn by mesh.
    let same = train(&req, &options(true, false), |_| {});
    assert!(same.is_ok(), "same settings resume: {same:?}");
    req.train.split_by_shape = true;
    let err = train(&req, &options(true, false), |_| {}).unwrap_err();
    assert!(err.to_string().contains("training settings"), "{err}");
    let _ = std::fs::remove_dir_all(&out);
}

/// The default budget and schedule on a small set: the run stops on its own (converged) long
/// before the budget, after `patience` steps without a new best validation loss, and says so;
/// the same run cut short by a small budget says `budget` and that it was still improving.
#[test]
fn default_training_stops_converged_and_a_short_budget_says_budget() {
    let set = small_set(7, 8);
    let dir = scratch("converged");
    let mut req = request(&set, &dir, 1);
    req.train.steps = Some(DEFAULT_MAX_STEPS);
    let schedule = Schedule::default();
    assert_eq!(req.train.schedule, schedule);
    let mut statuses = Vec::new();
    let options = TrainOptions {
        checkpoint_seconds: 2.0,
        ..options(false, false)
    };
    let summary = train(&req, &options, |record| {
        if record.epoch % 500 == 0 {
            statuses.push(read_status(&ModelFolder::new(&dir)).unwrap().unwrap());
        }
    })
    .unwrap();
    assert_eq!(summary.stop_reason, StopReason::Converged, "{summary:?}");
    assert!(!summary.still_improving);
    assert!(summary.epochs_run < summary.epochs_total, "{summary:?}");
    // While it ran, run.json said what a kill would leave: interrupted.
    assert!(!statuses.is_empty());
    assert!(
        statuses
            .iter()
            .all(|s| s.stop_reason == StopReason::Interrupted)
    );
    let folder = ModelFolder::new(&dir);
    let status = read_status(&folder).unwrap().unwrap();
    assert_eq!(status.stop_reason, StopReason::Converged);
    assert_eq!(status.steps, summary.steps);
    assert_eq!(status.path, "engine");
    assert_eq!(status.executor_reason, None);
    let executor = summary.executor.clone().unwrap();
    assert_eq!(
        (executor.kind, executor.reason),
        (ExecutorKind::Engine, None)
    );
    let text = std::fs::read_to_string(folder.status()).unwrap();
    assert!(text.contains("\"stop_reason\": \"converged\""), "{text}");

    // The stopping rule, checked on the log: no validation loss of the last `patience` steps
    // beat the best before them by the schedule's margin, and the rate was cut on the way.
    let log = read_log(&folder.log()).unwrap();
    let last = log.last().unwrap();
    assert_eq!(last.step, summary.steps);
    assert!(
        log.iter()
            .all(|r| r.executor == Some(ExecutorKind::Engine) && r.executor_reason.is_none())
    );
    let cut = last.step - schedule.patience as u64;
    let before = log
        .iter()
        .filter(|r| r.step <= cut)
        .filter_map(|r| r.val_loss)
        .fold(f64::INFINITY, f64::min);
    let after = log
        .iter()
        .filter(|r| r.step > cut)
        .filter_map(|r| r.val_loss)
        .fold(f64::INFINITY, f64::min);
    assert!(
        after >= before * (1.0 - schedule.min_improvement),
        "{after} vs {before}"
    );
    assert!(log.iter().any(|r| r.lr.unwrap() < req.train.lr), "no cut");
    assert!(
        log.iter().any(|r| r.test_loss.is_none()),
        "test every epoch"
    );
    assert!(
        last.test_loss.is_some(),
        "the last epoch measures the test loss"
    );

    // Resumed with a larger budget, a converged run has nothing left to do.
    let mut more = req.clone();
    more.train.steps = Some(2 * DEFAULT_MAX_STEPS);
    let again = train(&more, &options_resume(), |_| {}).unwrap();
    assert_eq!(
        (again.epochs_run, again.stop_reason),
        (0, StopReason::Converged)
    );

    // Cut short: the budget ends the run while the loss still falls, and it says so.
    let short = scratch("budget");
    let mut req = request(&set, &short, 1);
    req.train.steps = Some(60);
    let summary = train(&req, &options, |_| {}).unwrap();
    assert_eq!(summary.stop_reason, StopReason::Budget);
    assert!(summary.still_improving);
    assert_eq!(summary.steps, 60);
    let status = read_status(&ModelFolder::new(&short)).unwrap().unwrap();
    assert_eq!(
        (status.stop_reason, status.still_improving),
        (StopReason::Budget, true)
    );
    let _ = std::fs::remove_dir_all(&dir);
    let _ = std::fs::remove_dir_all(&short);
}

/// A run the engine does not take says so, with the reason, in the summary, on every line of
/// the log and in `run.json`.
#[test]
fn candle_runs_say_why() {
    let set = small_set(7, 8);
    for (tag, k, engine, why) in [
        ("k9", 9, true, "K = 9"),
        ("no-engine", 3, false, "--no-engine"),
    ] {
        let dir = scratch(&format!("executor-{tag}"));
        let mut req = request(&set, &dir, 3);
        req.model.k = k;
        let options = TrainOptions {
            engine,
            ..options(false, false)
        };
        let summary = train(&req, &options, |_| {}).unwrap();
        let executor = summary.executor.unwrap();
        assert_eq!(executor.kind, ExecutorKind::Candle, "{tag}");
        let reason = executor.reason.clone().unwrap();
        assert!(reason.contains(why), "{tag}: {reason}");
        assert!(executor.to_string().starts_with("candle ("), "{tag}");
        let folder = ModelFolder::new(&dir);
        let log = read_log(&folder.log()).unwrap();
        assert_eq!(log.len(), 3);
        for r in &log {
            assert_eq!(r.executor, Some(ExecutorKind::Candle), "{tag}");
            assert_eq!(r.executor_reason.as_deref(), Some(reason.as_str()), "{tag}");
        }
        let text = std::fs::read_to_string(folder.log()).unwrap();
        assert!(text.contains("\"executor\":\"candle\""), "{text}");
        let status = read_status(&folder).unwrap().unwrap();
        assert_eq!(status.path, "candle");
        assert_eq!(status.executor_reason.as_deref(), Some(reason.as_str()));
        let _ = std::fs::remove_dir_all(&dir);
    }
}

fn options_resume() -> TrainOptions {
    options(true, false)
}
