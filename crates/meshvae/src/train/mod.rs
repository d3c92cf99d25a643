//! Training: a mesh set in, a model folder out (see [`folder`]; loaded for use by
//! [`crate::TrainedModel`]).
//!
//! Each epoch shuffles the training meshes, takes Adam steps on batches, measures the
//! validation and test losses (the authors' validation loss: w_rec · mean squared error with
//! z = μ and batch norm in inference mode, here a true mean over the meshes) and appends a line
//! to `log.jsonl`. The validation loss also drives the [`Schedule`]: the run stops, *converged*,
//! once the loss has not reached a new best for the schedule's patience after its decay (or,
//! without a decay, the rate is cut on plateaus); otherwise it ends with its budget ([`TrainConfig::steps`](crate::TrainConfig::steps) or
//! `epochs`). `run.json` says which ([`RunStatus`]; `interrupted` until the run ends). Every [`TrainOptions::checkpoint_seconds`] (and after the last epoch) it
//! writes the weights with the lowest validation loss so far (the training loss without
//! validation meshes) to `weights.safetensors`, and the whole state to
//! `checkpoint.safetensors`. The test loss is only logged, and chooses a second set of weights,
//! `weights-selected-on-test.safetensors`, kept for comparison with the authors' protocol (they
//! picked their checkpoint on the test half); measuring it changes nothing else, so no test
//! mesh influences the model or its checkpoint. Killing the process at any moment loses at most the epochs since
//! that write: `resume` restarts from the checkpoint, and because every random draw comes from
//! one seeded stream saved with it, the resumed run ends with the same weights as an
//! uninterrupted one.
//!
//! A conditional model (`model.labels` non-empty, e.g. from [`ModelConfig::conditional_on`](crate::ModelConfig::conditional_on))
//! trains on the set's labels: every mesh needs one of the model's labels and every label needs
//! a training mesh. The meshes' labels are saved in `config.json`; the split is drawn as for
//! any model.
//!
//! This folder: the epoch loop (here; request and summary in `request.rs`), the saved settings
//! (`config.rs`), Adam (`adam.rs`, `adam/`), losses, schedule, data, split, the files a run
//! writes (`folder.rs`, `checkpoint.rs`, `epoch_log.rs`, `status.rs`) and the loop's helpers.

use crate::candle::model::MeshVae;
use crate::error::Result;
use crate::numerics::rng::Rng;
use crate::train::adam::Adam;
use crate::train::checkpoint::{Checkpoint, Progress};
use crate::train::schedule::{Decision, Schedule, ScheduleState, StopReason};
use folder::ModelFolder;
use std::time::Instant;

pub(crate) mod adam;
mod bar;
mod best;
pub(crate) mod checkpoint;
pub(crate) mod config;
pub(crate) mod data;
mod epoch_log;
mod executor;
pub(crate) mod folder;
pub(crate) mod loss;
mod loss_pass;
mod phases;
mod request;
mod rollback;
pub(crate) mod schedule;
mod setup;
pub(crate) mod split;
mod status;

use bar::progress_bar;
use best::{BestState, keep_weights, write_current};
pub use epoch_log::{EpochRecord, SPIKE_FACTOR, SPIKE_WINDOW, loss_spikes, read_log};
use epoch_log::{append_log, truncate_log};
pub use executor::{Executor, ExecutorKind};
use loss_pass::epoch_loss;
pub use loss_pass::validation_loss;
pub use phases::PhaseSeconds;
pub use request::{TrainOptions, TrainRequest, TrainSummary, hierarchy_config};
use rollback::Recovery;
use setup::{fresh_setup, resume_setup, write_model_files};
pub use status::{RunStatus, read_status};

/// Derives the training stream's seed from the user's (the split and the initial weights use
/// the seed itself).
fn stream_seed(seed: u64) -> u64 {
    seed ^ 0x7261_696E_5F73_6565
}

/// Trains (or resumes) a model; `on_epoch` sees every finished epoch.
pub fn train(
    request: &TrainRequest,
    options: &TrainOptions,
    mut on_epoch: impl FnMut(&EpochRecord),
) -> Result<TrainSummary> {
    let start = Instant::now();
    request.train.validate()?;
    let folder = ModelFolder::new(&request.out);
    let device = &options.device;
    let hierarchy_config = hierarchy_config(&request.model, request.hierarchy);

    // Checked before anything is written, so bad settings leave no half-made model folder.
    request.model.validate()?;
    // Left by a run killed while writing a file (its complete predecessor is still there).
    if options.resume || options.force {
        folder.remove_stale_temporaries()?;
    }
    let (spec, hierarchy, data, files) = if options.resume {
        let (spec, hierarchy, data) = resume_setup(request, &folder, hierarchy_config)?;
        (spec, hierarchy, data, None)
    } else {
        let (spec, hierarchy, data, files) =
            fresh_setup(request, &folder, options.force, hierarchy_config)?;
        (spec, hierarchy, data, Some(files))
    };

    let mut model = MeshVae::new(&spec.model, &hierarchy, device, spec.train.seed)?;
    let mut adam = Adam::with_config(model.trainable_vars(), spec.train.adam())?;
    if spec.train.head_lr_scale != 1.0 {
        for name in crate::net::plan::HEAD_WEIGHTS {
            adam.scale_lr(name, spec.train.head_lr_scale)?;
        }
    }
    adam.set_grad_clip(spec.train.grad_clip)?;
    if let Some(files) = &files {
        write_model_files(&folder, &spec, &hierarchy, &data, files)?;
    }
    let mut progress = Progress {
        epoch: 0,
        rng: Rng::new(stream_seed(spec.train.seed)).state(),
        best_loss: f64::INFINITY,
        best_epoch: 0,
        best_test_loss: f64::INFINITY,
        best_test_epoch: 0,
        schedule: ScheduleState::default(),
        seconds: 0.0,
    };
    // How the run ended, if it did: a checkpoint holds the best epoch's state, not the last's.
    let ended = match options.resume {
        true => read_status(&folder)?.filter(|s| s.stop_reason != StopReason::Interrupted),
        false => None,
    };
    if options.resume {
        best::settle_pending(&folder, &mut model)?;
    }
    if options.resume && folder.checkpoint().is_file() {
        let (checkpoint, weights) = (folder.checkpoint(), folder.weights());
        progress = Checkpoint::load(&checkpoint, &weights, &mut model, &mut adam)?;
    } else if options.resume {
        // Interrupted before its first checkpoint: said, so that a restart is not mistaken for
        // a continuation.
        eprintln!(
            "{}: no checkpoint to continue from (the run stopped before its first one); training \
             restarts from epoch 1",
            folder.dir.display()
        );
    }
    let batch = spec.train.batch;
    let train_ids = &data.split.train;
    let steps_per_epoch = train_ids.len().div_ceil(batch);
    let epochs = spec.train.epoch_budget(steps_per_epoch);
    let schedule: Schedule = spec.train.schedule;
    let selection = data.split.selection();
    if let Some(ended) = ended
        && (ended.stop_reason == StopReason::Converged || ended.epochs >= epochs)
    {
        // Nothing left to train (a converged run resumed with a larger budget has nothing left
        // to learn either): its record stands as it is.
        let log = read_log(&folder.log())?;
        return Ok(TrainSummary {
            epochs_run: 0,
            epochs_total: epochs,
            stop_reason: ended.stop_reason,
            steps: ended.steps,
            still_improving: ended.still_improving,
            lr: ended.lr,
            seconds_total: ended.seconds,
            last: log.last().cloned(),
            best_epoch: ended.best_epoch,
            best_loss: progress.best_loss,
            selected_on: selection,
            seconds: start.elapsed().as_secs_f64(),
            executor: None,
        });
    }
    truncate_log(&folder.log(), progress.epoch)?;
    let mut rng = Rng::from_state(progress.rng)?;
    let base_lr = spec.train.lr;
    // Which path trains, and why candle where it is candle: said on every line of `log.jsonl`,
    // in `run.json` and in the summary.
    let executor = Executor::choose(&model, options.engine);
    let engine_used = executor.kind == ExecutorKind::Engine;
    adam.set_lr(
        progress
            .schedule
            .lr(&schedule, base_lr, adam.step_count().max(1)),
    )?;
    let prior_seconds = progress.seconds;
    let mut phases = PhaseSeconds::default();
    let status = |progress: &Progress, reason: StopReason, adam: &Adam, phases| RunStatus {
        stop_reason: reason,
        epochs: progress.epoch,
        epoch_budget: epochs,
        steps: adam.step_count(),
        steps_per_epoch,
        best_epoch: progress.best_epoch,
        selected_on: data.split.selection(),
        still_improving: progress
            .schedule
            .still_improving(&schedule, adam.step_count() as usize),
        lr: adam.config().lr,
        lr_cuts: progress.schedule.cuts,
        rollbacks: progress.schedule.rollbacks,
        clipped_steps: adam.grad_clip().is_on().then(|| adam.grad_clip().clipped()),
        seconds: progress.seconds,
        path: executor.kind.to_string(),
        executor_reason: executor.reason.clone(),
        best_test_epoch: (progress.best_test_epoch > 0).then_some(progress.best_test_epoch),
        best_test_loss: progress
            .best_test_loss
            .is_finite()
            .then_some(progress.best_test_loss),
        phases: Some(phases),
    };
    // A converged run resumed from a checkpoint of its last epoch (versions 1 and 2; newer ones
    // are told by `run.json` above) has nothing left to learn.
    let already_converged = schedule.stops_early()
        && progress.schedule.since_best >= schedule.patience
        && adam.step_count() >= schedule.annealed_at();
    if !already_converged && progress.epoch < epochs {
        folder.write_json(
            &folder.status(),
            &status(&progress, StopReason::Interrupted, &adam, phases),
        )?;
    }
    let bar = progress_bar(options.progress, epochs, progress.epoch, steps_per_epoch);
    let mut last = None;
    let mut epochs_run = 0;
    let mut best: Option<BestState> = None;
    let mut best_on_test = None;
    let keep_in_memory = model.param_count().with_biases <= options.best_in_memory_params;
    // A resumed run goes on keeping them if it kept them before (or its file would go stale).
    let keep_selected_on_test = options.keep_selected_on_test
        || (options.resume && folder.weights_selected_on_test().is_file());
    let mut kept_engine = None;
    let mut last_write = Instant::now();
    let mut stop = if already_converged {
        StopReason::Converged
    } else {
        StopReason::Budget
    };
    let first_epoch = if already_converged {
        epochs + 1
    } else {
        progress.epoch + 1
    };

    // False between a rollback and the next epoch that finishes: a divergence then means the
    // best weights themselves cannot train.
    let mut trained_since_rollback = true;
    let mut epoch = first_epoch;
    let mut last_looked_at = adam.step_count();
    while epoch <= epochs {
        let t0 = Instant::now();
        let steps_before = adam.step_count();
        let mut order = train_ids.clone();
        rng.shuffle(&mut order);
        let mut sums = [0.0f64; 4];
        // A large model's engine is built per epoch and dropped before validation and
        // checkpoints, so that its buffers (~0.6 GB on elephant-gallop at batch 16) never
        // coexist with a checkpoint's copies; a small one's is kept (building it and touching
        // fresh pages cost ~10 % of a horse-gallop epoch).
        let mut engine = match kept_engine.take() {
            Some(engine) => Some(engine),
            None if engine_used => Some(crate::cpu::Engine::new(&model, batch)?),
            None => None,
        };
        let mut divergence = None;
        for chunk in order.chunks(batch) {
            adam.set_lr(
                progress
                    .schedule
                    .lr(&schedule, base_lr, adam.step_count() + 1),
            )?;
            let (x, c, eps) = phases.time(
                |p| &mut p.batches,
                || -> Result<_> {
                    let x = data.batch(chunk, device)?;
                    let c = data.conditions(&model, chunk)?;
                    let eps = rng.normal_tensor((chunk.len(), spec.model.latent), device)?;
                    Ok((x, c, eps))
                },
            )?;
            let step = adam.step_count() + 1;
            let diverged = |total: f64, rec: f64, kl: f64, l2: f64| {
                format!(
                    "epoch {epoch} (step {step}): the loss is {total} (rec {rec}, kl {kl}, l2 {l2})"
                )
            };
            let injected = match progress.schedule.rollbacks {
                0 => options.fail_step == Some(step),
                1 => options.fail_after_rollback && !trained_since_rollback,
                _ => false,
            };
            if injected {
                divergence = Some(format!("epoch {epoch}: the loss is NaN (injected)"));
                break;
            }
            let w_l2 = spec.train.loss.l2;
            let (total, rec, kl, l2) = match (engine.as_mut(), &c) {
                (Some(engine), c) => {
                    let loss = &spec.train.loss;
                    let l = phases.time(
                        |p| &mut p.forward_backward,
                        || engine.forward_backward_cond(&model, &x, c.as_ref(), &eps, loss),
                    )?;
                    if !(l.rec + l.kl).is_finite() {
                        let l2 = model.l2_term()?.to_dtype(candle_core::DType::F64)?;
                        let l2 = l2.to_scalar::<f64>()? * w_l2;
                        divergence = Some(diverged(l.rec + l.kl + l2, l.rec, l.kl, l2));
                        break;
                    }
                    // Adam also returns the L2 term of the weights it started from.
                    let l2 = phases.time(|p| &mut p.adam, || engine.apply_adam(&mut adam, w_l2))?;
                    let total = l.rec + l.kl + l2;
                    if !total.is_finite() {
                        divergence = Some(diverged(total, l.rec, l.kl, l2));
                        break;
                    }
                    (total, l.rec, l.kl, l2)
                }
                _ => {
                    // The L2 term's gradient is applied by Adam (see `MeshVae::training_loss`).
                    let t = std::time::Instant::now();
                    let loss = model.training_loss_cond(&x, c.as_ref(), &eps, &spec.train.loss)?;
                    let total = loss
                        .total
                        .to_dtype(candle_core::DType::F64)?
                        .to_scalar::<f64>()?
                        + loss.l2;
                    if !total.is_finite() {
                        divergence = Some(diverged(total, loss.rec, loss.kl, loss.l2));
                        break;
                    }
                    let grads = model.backward(&loss.total)?;
                    phases.forward_backward += t.elapsed().as_secs_f64();
                    phases.time(|p| &mut p.adam, || adam.step_with_l2(&grads, w_l2))?;
                    (total, loss.rec, loss.kl, loss.l2)
                }
            };
            let w = chunk.len() as f64;
            for (s, v) in sums.iter_mut().zip([total, rec, kl, l2]) {
                *s += v * w;
            }
            bar.inc(1);
        }
        let n = train_ids.len().max(1) as f64;
        // Evaluated in inference mode: it reads the weights and changes nothing. The engine, where
        // there is one, computes the same error without candle's per-op allocations.
        let mut loss_on = |ids: &[usize]| {
            let engine = engine.as_mut();
            epoch_loss(&model, &data, ids, batch, &spec.train.loss, device, engine)
        };
        // Without validation meshes the score is the training loss, free to look at.
        let looked_at = epoch == epochs
            || data.split.val.is_empty()
            || schedule.validation_due(steps_before, adam.step_count());
        let mut val_loss = None;
        if divergence.is_none() && looked_at {
            val_loss = phases.time(|p| &mut p.validation, || loss_on(&data.split.val))?;
            // The last step can leave non-finite weights behind a finite training loss.
            if let Some(v) = val_loss.filter(|v| !v.is_finite()) {
                divergence = Some(format!("epoch {epoch}: the validation loss is {v}"));
            } else if let Some(name) = phases.time(
                |p| &mut p.bookkeeping,
                || rollback::non_finite_weight(&model),
            )? {
                // The validation loss reads only the mean path: a broken σ branch passes it.
                divergence = Some(format!("epoch {epoch}: weight {name} is not finite"));
            }
        }
        if let Some(what) = divergence {
            // Back to the best weights at half the rate; the epoch is trained again (with the
            // next shuffle).
            drop(engine);
            // Best weights that diverge again before an epoch finishes are no place to go back
            // to (seen on samba, seed 3, epoch 14: one training mesh's σ overflows with the
            // weights of epoch 13 at any rate, and the validation pass, which reads only the
            // mean, cannot see it): start again from the initial weights instead.
            let initial = if trained_since_rollback {
                None
            } else {
                let fresh = MeshVae::new(&spec.model, &hierarchy, device, spec.train.seed)?;
                Some(rollback::tensors_of(&fresh))
            };
            trained_since_rollback = false;
            let best = best.as_ref().map(|b| b.weights());
            let best = best.as_ref();
            let recovery = Recovery {
                what,
                best,
                initial: initial.as_ref(),
                weights: &folder.weights(),
                schedule: &schedule,
                base_lr,
            };
            if let Err(e) = recovery.apply(&mut model, &mut adam, &mut progress) {
                bar.abandon();
                return Err(e);
            }
            let message = recovery.message(&progress);
            // A hidden bar prints nothing, and a recovered divergence must not pass unseen;
            // without the bar's context, the folder says which of several runs it was.
            if bar.is_hidden() {
                eprintln!("{}: {message}", folder.dir.display());
            } else {
                bar.println(message);
            }
            continue;
        }
        trained_since_rollback = true;
        // The schedule sees the loss that chooses the weights (validation, or training), and
        // counts the steps since it last saw one.
        let score = val_loss.unwrap_or(sums[0] / n);
        let decision = if looked_at {
            let steps = (adam.step_count() - last_looked_at) as usize;
            last_looked_at = adam.step_count();
            progress
                .schedule
                .update(&schedule, score, steps, adam.step_count())
        } else {
            Decision::Continue
        };
        if decision == Decision::Stop {
            stop = StopReason::Converged;
        }
        let finished = epoch == epochs || decision == Decision::Stop;
        // Due when the step count passes a multiple of `test_every_steps` (the same epochs
        // whether or not the run was resumed in between), and at the end.
        let every = options.test_every_steps.max(1) as u64;
        let test_due = finished || adam.step_count() / every > steps_before / every;
        let test_loss = if test_due {
            phases.time(|p| &mut p.test, || loss_on(&data.split.test))?
        } else {
            None
        };
        if keep_in_memory {
            kept_engine = engine;
        } else {
            drop(engine);
        }
        let record = EpochRecord {
            epoch,
            train_loss: sums[0] / n,
            rec: sums[1] / n,
            kl: sums[2] / n,
            l2: sums[3] / n,
            val_loss,
            test_loss,
            seconds: t0.elapsed().as_secs_f64(),
            step: adam.step_count(),
            lr: Some(adam.config().lr),
            since_best: schedule
                .stops_early()
                .then_some(progress.schedule.since_best as u64),
            executor: Some(executor.kind),
            executor_reason: executor.reason.clone(),
        };
        debug_assert!(!looked_at || score == record.score(selection));
        let improved = looked_at && score < progress.best_loss;
        if improved {
            progress.best_loss = score;
            progress.best_epoch = epoch;
        }
        let improved_on_test = test_loss.filter(|&t| t < progress.best_test_loss);
        if let Some(t) = improved_on_test {
            progress.best_test_loss = t;
            progress.best_test_epoch = epoch;
        }
        progress.epoch = epoch;
        progress.rng = rng.state();
        progress.seconds = prior_seconds + start.elapsed().as_secs_f64();
        // Before any checkpoint of this epoch: a resumed run truncates the log to its epoch.
        let mut book = Instant::now();
        append_log(&folder.log(), &record)?;
        // A kill before these reach the folder replays the epochs since the last write and
        // finds the same bests again, so writing them early is safe.
        if improved_on_test.is_some() && keep_selected_on_test {
            let path = folder.weights_selected_on_test();
            best_on_test = keep_weights(&model, keep_in_memory, &path, epoch)?;
        }
        if improved {
            if keep_in_memory {
                match best.as_mut() {
                    Some(best) => best.recapture(&model, &adam, &progress)?,
                    None => best = Some(BestState::capture(&model, &adam, &progress)?),
                }
            } else {
                write_current(&model, &adam, &progress, &folder)?;
            }
        }
        // Only after an epoch that looked at the loss: a resumed run then counts the steps
        // since the last look from its checkpoint.
        let write_due =
            looked_at && last_write.elapsed().as_secs_f64() >= options.checkpoint_seconds;
        if finished || write_due {
            if let Some(weights) = best_on_test.take() {
                let (path, at) = (folder.weights_selected_on_test(), progress.best_test_epoch);
                model.save_snapshot(&weights, &path, Some(at))?;
            }
            if let Some(best) = best.as_mut() {
                best.write(&model, &folder)?;
            }
            let reason = if finished {
                stop
            } else {
                StopReason::Interrupted
            };
            phases.bookkeeping += book.elapsed().as_secs_f64();
            book = Instant::now();
            folder.write_json(&folder.status(), &status(&progress, reason, &adam, phases))?;
            last_write = Instant::now();
        }
        phases.bookkeeping += book.elapsed().as_secs_f64();
        let show = |l: Option<f64>| l.map_or("–".into(), |t| format!("{t:.3}"));
        // The bar's length is the budget; a run usually stops earlier, when the count of steps
        // without a new best reaches the patience.
        let stall = record.since_best.map_or(String::new(), |n| {
            format!("  no new best for {n}/{} steps", schedule.patience)
        });
        bar.set_message(format!(
            "epoch {epoch}/{epochs}  loss {:.3}  val {}  test {}  lr {:.1e}{stall}",
            record.train_loss,
            show(val_loss),
            show(test_loss),
            adam.config().lr,
        ));
        on_epoch(&record);
        last = Some(record);
        epochs_run += 1;
        if finished {
            break;
        }
        epoch += 1;
    }
    bar.finish();
    let state = progress.schedule;
    Ok(TrainSummary {
        epochs_run,
        epochs_total: epochs,
        stop_reason: stop,
        steps: adam.step_count(),
        still_improving: state.still_improving(&schedule, adam.step_count() as usize),
        lr: adam.config().lr,
        seconds_total: prior_seconds + start.elapsed().as_secs_f64(),
        last,
        best_epoch: progress.best_epoch,
        best_loss: progress.best_loss,
        selected_on: selection,
        seconds: start.elapsed().as_secs_f64(),
        executor: Some(executor),
    })
}
