//! How training stops: a non-finite loss, a divergence rolled back, convergence against a
//! budget, and the path (engine or candle) each run names.

mod common;

use candle_core::Device;
use common::{options, request, scratch, small_set};
use meshvae::{
    DEFAULT_MAX_STEPS, EpochRecord, ExecutorKind, ModelFolder, RunStatus, SPIKE_FACTOR,
    SPIKE_WINDOW, Schedule, StopReason, TrainOptions, TrainSummary, TrainedModel, VaeError,
    loss_spikes, read_log, read_status, train,
};

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
    // Where the time went: every phase of an epoch took some, and they add up to most of it.
    let phases = status.phases.unwrap();
    assert!(
        phases.forward_backward > 0.0 && phases.adam > 0.0,
        "{phases:?}"
    );
    assert!(phases.validation > 0.0 && phases.test > 0.0, "{phases:?}");
    assert!(
        phases.total() <= status.seconds,
        "{phases:?} {}",
        status.seconds
    );
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
    // Each epoch's record carries the count the rule reads: it restarts at a new best and
    // reached the patience at the last epoch.
    let stalls: Vec<u64> = log.iter().map(|r| r.since_best.unwrap()).collect();
    assert!(stalls.contains(&0), "{stalls:?}");
    assert!(
        *stalls.last().unwrap() >= schedule.patience as u64,
        "{stalls:?}"
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

/// `meshvae train`'s default training (a warm-up, the cosine decay, β₂ 0.95, the dense heads at
/// a third of the rate): the rate peaks, falls to its floor, the run stops converged
/// no earlier than the decay's end, `patience` steps after its last new best, and no epoch's
/// training loss rises above 3× the median of the 50 before it (a finite blow-up).
#[test]
fn the_default_training_converges_after_its_decay_without_a_loss_spike() {
    let set = small_set(7, 8);
    let dir = scratch("cosine");
    let mut req = request(&set, &dir, 1);
    req.train.steps = Some(DEFAULT_MAX_STEPS);
    let schedule = Schedule::default();
    assert_eq!(req.train.schedule, schedule);
    assert!(schedule.decay_steps > 0 && req.train.adam_beta2 < 0.999);
    let summary = train(&req, &options(false, false), |_| {}).unwrap();
    assert_eq!(summary.stop_reason, StopReason::Converged, "{summary:?}");
    let log = read_log(&ModelFolder::new(&dir).log()).unwrap();
    let last = log.last().unwrap();
    let floor = req.train.lr * schedule.min_lr_ratio;
    assert!(log.iter().any(|r| r.lr.unwrap() == req.train.lr), "no peak");
    assert!((last.lr.unwrap() - floor).abs() < 1e-9 * floor, "{last:?}");
    assert!(last.step >= schedule.annealed_at(), "{last:?}");
    assert!(
        last.since_best.unwrap() >= schedule.patience as u64,
        "{last:?}"
    );
    let spikes = loss_spikes(&log, SPIKE_WINDOW, SPIKE_FACTOR);
    assert!(spikes.is_empty(), "loss spikes at epochs {spikes:?}");
    // It learned: the validation loss ended far below where it started.
    let first = log.iter().find_map(|r| r.val_loss).unwrap();
    let best = log
        .iter()
        .filter_map(|r| r.val_loss)
        .fold(f64::INFINITY, f64::min);
    assert!(best < 0.5 * first, "{best} vs {first}");
    let _ = std::fs::remove_dir_all(&dir);
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

/// Validation every 10 steps: the steps are those of a run that validates every epoch (the
/// pass changes no weight, and gradient clipping does not depend on it), the validation loss is measured only on the epochs that cross a
/// multiple of 10 steps and on the last, and the chosen weights are those of one of them.
#[test]
fn validation_every_n_steps_measures_only_then_and_chooses_among_those_epochs() {
    let set = small_set(7, 8);
    let run = |name: &str, every: usize| {
        let dir = scratch(name);
        let mut req = request(&set, &dir, 1);
        req.train.steps = Some(400);
        req.train.schedule = Schedule {
            decay_steps: 200,
            patience: 60,
            validate_every_steps: every,
            ..Schedule::cosine()
        };
        // Clipping at the running mean itself: it acts on many steps, the same ones in both.
        req.train.grad_clip = 1.0;
        let summary = train(&req, &options(false, false), |_| {}).unwrap();
        let folder = ModelFolder::new(&dir);
        let log = read_log(&folder.log()).unwrap();
        (dir, summary, log)
    };
    let (dir_all, _, every_epoch) = run("validate-every-1", 0);
    let (dir, summary, log) = run("validate-every-10", 10);
    assert!(log.iter().all(|r| r.step > 0));
    let per_epoch = log[0].step;
    assert!(
        per_epoch < 10,
        "{per_epoch} steps an epoch: nothing to skip"
    );
    for (a, b) in log.iter().zip(&every_epoch) {
        assert_eq!(
            (a.step, a.train_loss),
            (b.step, b.train_loss),
            "epoch {}",
            a.epoch
        );
    }
    let mut before = 0;
    for (i, r) in log.iter().enumerate() {
        let due = r.step / 10 > before / 10 || i + 1 == log.len();
        assert_eq!(
            r.val_loss.is_some(),
            due,
            "epoch {} (step {})",
            r.epoch,
            r.step
        );
        before = r.step;
    }
    assert!(log.iter().filter(|r| r.val_loss.is_none()).count() > log.len() / 2);
    let best = log.iter().find(|r| r.epoch == summary.best_epoch).unwrap();
    assert!(best.val_loss.is_some(), "{best:?}");
    let model = TrainedModel::load(&dir, &Device::Cpu).unwrap();
    assert_eq!(model.epochs_trained().unwrap().1, summary.best_epoch);
    let status = read_status(&ModelFolder::new(&dir)).unwrap().unwrap();
    let clipped = status.clipped_steps.unwrap();
    assert!(
        clipped > 0 && clipped < summary.steps,
        "{clipped} of {}",
        summary.steps
    );
    let _ = std::fs::remove_dir_all(&dir);
    let _ = std::fs::remove_dir_all(&dir_all);
}
