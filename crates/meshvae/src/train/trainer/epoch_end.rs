//! The end of an epoch that did not diverge: the schedule's decision, the test pass, the log
//! line, the best weights, the files due, and what the run reports (`run.json`, the progress
//! bar, the summary, or the interruption).

use super::Trainer;
use crate::error::{Result, VaeError};
use crate::executor::Executor;
use crate::train::best::{BestState, keep_weights, write_current};
use crate::train::checkpoint::Checkpoint;
use crate::train::epoch_log::{EpochRecord, append_log};
use crate::train::request::TrainSummary;
use crate::train::schedule::{Decision, StopReason};
use crate::train::status::RunStatus;
use std::time::Instant;

/// What [`Trainer::end_epoch`] needs to know about the epoch's steps.
pub(super) struct EpochSteps {
    pub epoch: usize,
    pub started: Instant,
    pub steps_before: u64,
    /// Losses summed over the epoch's meshes (total, rec, KL, L2).
    pub sums: [f64; 4],
    pub val_loss: Option<f64>,
    pub looked_at: bool,
}

impl Trainer<'_> {
    /// After an epoch that did not diverge: the schedule's decision, the test loss when due,
    /// the log line, the best weights and the files due. Returns the epoch's record and
    /// whether the run ends with it.
    pub(super) fn end_epoch(
        &mut self,
        steps: EpochSteps,
        mut executor: Box<dyn Executor>,
    ) -> Result<(EpochRecord, bool)> {
        self.finished_steps = self.adam.step_count();
        let n = self.data.split.train.len().max(1) as f64;
        // The schedule sees the loss that chooses the weights (validation, or training), and
        // counts the steps since it last saw one.
        let score = steps.val_loss.unwrap_or(steps.sums[0] / n);
        let decision = if steps.looked_at {
            let since = (self.adam.step_count() - self.last_looked_at) as usize;
            self.last_looked_at = self.adam.step_count();
            let at = self.adam.step_count();
            (self.progress.schedule).update(&self.schedule, score, since, at)
        } else {
            Decision::Continue
        };
        if decision == Decision::Stop {
            self.stop = StopReason::Converged;
        }
        let finished = steps.epoch == self.epochs || decision == Decision::Stop;
        // Due when the step count passes a multiple of `test_every_steps` (the same epochs
        // whether or not the run was resumed in between), and at the end.
        let every = self.options.test_every_steps.max(1) as u64;
        let test_due = finished || self.adam.step_count() / every > steps.steps_before / every;
        let test_loss = if test_due {
            let t = Instant::now();
            let loss = self.loss_on(&self.data.split.test, executor.as_mut())?;
            self.phases.test += t.elapsed().as_secs_f64();
            loss
        } else {
            None
        };
        if self.keep_in_memory {
            self.kept = Some(executor);
        } else {
            drop(executor);
        }
        let record = self.record(&steps, n, test_loss);
        debug_assert!(!steps.looked_at || score == record.score(self.data.split.selection()));
        let book = Instant::now();
        self.keep_bests(&record, score, steps.looked_at)?;
        // Only after an epoch that looked at the loss: a resumed run then counts the steps
        // since the last look from its checkpoint.
        let write_due = steps.looked_at
            && self.last_write.elapsed().as_secs_f64() >= self.options.checkpoint_seconds;
        if finished || write_due {
            self.write_files(finished, book)?;
        } else {
            self.phases.bookkeeping += book.elapsed().as_secs_f64();
        }
        Ok((record, finished))
    }

    /// The epoch's line of `log.jsonl`.
    fn record(&self, steps: &EpochSteps, n: f64, test_loss: Option<f64>) -> EpochRecord {
        EpochRecord {
            epoch: steps.epoch,
            train_loss: steps.sums[0] / n,
            rec: steps.sums[1] / n,
            kl: steps.sums[2] / n,
            l2: steps.sums[3] / n,
            val_loss: steps.val_loss,
            test_loss,
            seconds: steps.started.elapsed().as_secs_f64(),
            step: self.adam.step_count(),
            lr: Some(self.adam.config().lr),
            since_best: (self.schedule)
                .stops_early()
                .then_some(self.progress.schedule.since_best as u64),
            executor: Some(self.choice.kind),
            executor_reason: self.choice.reason.clone(),
        }
    }

    /// Logs the epoch and keeps its weights where they are a new best (on the loss that
    /// chooses the weights, or on the test loss).
    fn keep_bests(&mut self, record: &EpochRecord, score: f64, looked_at: bool) -> Result<()> {
        let epoch = record.epoch;
        let improved = looked_at && score < self.progress.best_loss;
        if improved {
            self.progress.best_loss = score;
            self.progress.best_epoch = epoch;
        }
        let improved_on_test = record
            .test_loss
            .filter(|&t| t < self.progress.best_test_loss);
        if let Some(t) = improved_on_test {
            self.progress.best_test_loss = t;
            self.progress.best_test_epoch = epoch;
        }
        self.progress.epoch = epoch;
        self.progress.rng = self.rng.state();
        self.progress.seconds = self.prior_seconds + self.start.elapsed().as_secs_f64();
        // Before any checkpoint of this epoch: a resumed run truncates the log to its epoch.
        append_log(&self.folder.log(), record)?;
        // A kill before these reach the folder replays the epochs since the last write and
        // finds the same bests again, so writing them early is safe.
        if improved_on_test.is_some() && self.keep_selected_on_test {
            let path = self.folder.weights_selected_on_test();
            self.best_on_test = keep_weights(&self.model, self.keep_in_memory, &path, epoch)?;
        }
        if !improved {
            return Ok(());
        }
        let (model, adam, progress) = (&self.model, &self.adam, &self.progress);
        if !self.keep_in_memory {
            return write_current(model, adam, progress, &self.folder);
        }
        match self.best.as_mut() {
            Some(best) => best.recapture(model, adam, progress),
            None => {
                self.best = Some(BestState::capture(model, adam, progress)?);
                Ok(())
            }
        }
    }

    /// Writes the kept weights and `run.json` (the checkpoint goes with the best weights);
    /// `book` started this epoch's bookkeeping.
    fn write_files(&mut self, finished: bool, book: Instant) -> Result<()> {
        if let Some(weights) = self.best_on_test.take() {
            let path = self.folder.weights_selected_on_test();
            let at = self.progress.best_test_epoch;
            self.model.save_snapshot(&weights, &path, Some(at))?;
        }
        if let Some(best) = self.best.as_mut() {
            best.write(&self.model, &self.folder)?;
        }
        let reason = if finished {
            self.stop
        } else {
            StopReason::Interrupted
        };
        self.phases.bookkeeping += book.elapsed().as_secs_f64();
        let book = Instant::now();
        // Stamped again after the writes: `run.json`'s seconds then cover every phase it
        // reports (the checkpoint keeps the stamp of its epoch).
        self.progress.seconds = self.prior_seconds + self.start.elapsed().as_secs_f64();
        self.write_status(reason)?;
        self.last_write = Instant::now();
        self.phases.bookkeeping += book.elapsed().as_secs_f64();
        Ok(())
    }

    /// Ends a run asked to stop: the epoch under way is dropped, the best epoch's state and
    /// `run.json` (`interrupted`) are written, and the error says where a resumed run goes on.
    pub(super) fn interrupt(&mut self) -> Result<VaeError> {
        self.write_files(false, Instant::now())?;
        let checkpoint = self.folder.checkpoint();
        Ok(VaeError::Interrupted {
            dir: self.folder.dir.clone(),
            epoch: self.progress.epoch,
            checkpoint: match checkpoint.is_file() {
                true => Checkpoint::epoch(&checkpoint)?,
                false => None,
            },
        })
    }

    /// `run.json` as of now, saying `reason`.
    fn status(&self, reason: StopReason) -> RunStatus {
        let steps = self.finished_steps;
        let progress = &self.progress;
        RunStatus {
            stop_reason: reason,
            epochs: progress.epoch,
            epoch_budget: self.epochs,
            steps,
            steps_per_epoch: self.steps_per_epoch,
            best_epoch: progress.best_epoch,
            selected_on: self.data.split.selection(),
            still_improving: (progress.schedule).still_improving(&self.schedule, steps as usize),
            lr: self.adam.config().lr,
            lr_cuts: progress.schedule.cuts,
            rollbacks: progress.schedule.rollbacks,
            clipped_steps: (self.adam.grad_clip().is_on()).then(|| self.adam.grad_clip().clipped()),
            seconds: progress.seconds,
            path: self.choice.kind.to_string(),
            executor_reason: self.choice.reason.clone(),
            best_test_epoch: (progress.best_test_epoch > 0).then_some(progress.best_test_epoch),
            best_test_loss: (progress.best_test_loss.is_finite())
                .then_some(progress.best_test_loss),
            phases: Some(self.phases),
        }
    }

    pub(super) fn write_status(&self, reason: StopReason) -> Result<()> {
        (self.folder).write_json(&self.folder.status(), &self.status(reason))
    }

    /// The progress bar's message after `record`. The bar's length is the budget; a run
    /// usually stops earlier, when the count of steps without a new best reaches the patience.
    pub(super) fn bar_message(&self, record: &EpochRecord) -> String {
        let show = |l: Option<f64>| l.map_or("–".into(), |t| format!("{t:.3}"));
        let stall = record.since_best.map_or(String::new(), |n| {
            format!("  no new best for {n}/{} steps", self.schedule.patience)
        });
        format!(
            "epoch {}/{}  loss {:.3}  val {}  test {}  lr {:.1e}{stall}",
            record.epoch,
            self.epochs,
            record.train_loss,
            show(record.val_loss),
            show(record.test_loss),
            self.adam.config().lr,
        )
    }

    /// The run's summary once its loop has ended.
    pub(super) fn summary(self, epochs_run: usize, last: Option<EpochRecord>) -> TrainSummary {
        let steps = self.adam.step_count();
        let state = self.progress.schedule;
        TrainSummary {
            epochs_run,
            epochs_total: self.epochs,
            stop_reason: self.stop,
            steps,
            still_improving: state.still_improving(&self.schedule, steps as usize),
            lr: self.adam.config().lr,
            seconds_total: self.prior_seconds + self.start.elapsed().as_secs_f64(),
            last,
            best_epoch: self.progress.best_epoch,
            best_loss: self.progress.best_loss,
            selected_on: self.data.split.selection(),
            seconds: self.start.elapsed().as_secs_f64(),
            executor: Some(self.choice.clone()),
        }
    }
}
