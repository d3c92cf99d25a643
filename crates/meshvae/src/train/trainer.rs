//! [`Trainer`]: one run's state, and the loop over its epochs. Each method is one part of an
//! epoch: the steps ([`Trainer::train_epoch`], [`Trainer::step`]), the look at the validation
//! loss ([`Trainer::look`]), a rollback after a divergence ([`Trainer::recover`]), and the
//! bookkeeping after a good epoch ([`Trainer::end_epoch`]: schedule, test pass, log, bests,
//! files).

use super::bar::progress_bar;
use super::best::BestState;
use super::checkpoint::{Checkpoint, Progress};
use super::epoch_log::{EpochRecord, read_log, truncate_log};
use super::folder::{ModelFolder, ModelSpec};
use super::lock::TrainLock;
use super::loss_pass::validation_loss;
use super::phases::PhaseSeconds;
use super::request::{TrainOptions, TrainRequest, TrainSummary, hierarchy_config};
use super::rollback::{self, Recovery};
use super::schedule::{Schedule, StopReason};
use super::setup::{fresh_setup, resume_setup, write_model_files};
use super::status::{RunStatus, read_status};
use super::stream_seed;
use crate::candle::model::MeshVae;
use crate::error::Result;
use crate::executor::{Batch, Executor, ExecutorChoice, TrainStep};
use crate::numerics::rng::Rng;
use crate::optim::adam::Adam;
use crate::train::data::MeshData;
use candle_core::Tensor;
use indicatif::ProgressBar;
use mesh_hierarchy::Hierarchy;
use std::collections::BTreeMap;
use std::time::Instant;

mod epoch_end;
use epoch_end::EpochSteps;

/// A step's losses (total, reconstruction, KL, L2), or why it diverged.
type StepOutcome = std::result::Result<[f64; 4], String>;

/// One run being trained: its files, model, optimiser and the loop's bookkeeping.
pub(super) struct Trainer<'a> {
    options: &'a TrainOptions,
    start: Instant,
    folder: ModelFolder,
    spec: ModelSpec,
    hierarchy: Hierarchy,
    data: MeshData,
    model: MeshVae,
    adam: Adam,
    progress: Progress,
    rng: Rng,
    /// How an earlier session ended the run, if it did.
    ended: Option<RunStatus>,
    schedule: Schedule,
    epochs: usize,
    steps_per_epoch: usize,
    base_lr: f64,
    /// Which path trains, and why candle where it is candle: said on every line of
    /// `log.jsonl`, in `run.json` and in the summary.
    choice: ExecutorChoice,
    phases: PhaseSeconds,
    prior_seconds: f64,
    /// The best weights (and state) kept in memory until the next write, for small models.
    best: Option<BestState>,
    best_on_test: Option<BTreeMap<String, Tensor>>,
    keep_in_memory: bool,
    keep_selected_on_test: bool,
    /// A small model's executor (the engine's buffers), kept from one epoch to the next.
    kept: Option<Box<dyn Executor>>,
    last_write: Instant,
    stop: StopReason,
    /// False between a rollback and the next epoch that finishes: a divergence then means the
    /// best weights themselves cannot train.
    trained_since_rollback: bool,
    last_looked_at: u64,
    /// Optimizer steps at the end of the last finished epoch: `run.json`'s count (the steps of
    /// an epoch a stop request cut short are dropped with it).
    finished_steps: u64,
    /// Held while the trainer lives: no other training writes the folder meanwhile.
    _lock: TrainLock,
}

impl<'a> Trainer<'a> {
    /// Sets the run up: a fresh model folder, or the state of the one being resumed.
    pub(super) fn new(request: &TrainRequest, options: &'a TrainOptions) -> Result<Self> {
        let start = Instant::now();
        request.train.validate()?;
        let folder = ModelFolder::new(&request.out);
        let device = &options.device;
        let hierarchy_config = hierarchy_config(&request.model, request.hierarchy);
        // Checked before anything is written, so bad settings leave no half-made model folder.
        request.model.validate()?;
        // One training per folder, from before anything in it is read or changed.
        let lock = TrainLock::acquire(&folder)?;
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
            // A plain auto-encoder has no σ head.
            for name in crate::net::plan::HEAD_WEIGHTS {
                if adam.names().any(|n| n == name) {
                    adam.scale_lr(name, spec.train.head_lr_scale)?;
                }
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
            schedule: Default::default(),
            seconds: 0.0,
        };
        // How the run ended, if it did: a checkpoint holds the best epoch's state, not the
        // last's.
        let ended = match options.resume {
            true => read_status(&folder)?.filter(|s| s.stop_reason != StopReason::Interrupted),
            false => None,
        };
        if options.resume {
            super::best::settle_pending(&folder, &mut model)?;
        }
        if options.resume && folder.checkpoint().is_file() {
            let (checkpoint, weights) = (folder.checkpoint(), folder.weights());
            progress = Checkpoint::load(&checkpoint, &weights, &mut model, &mut adam)?;
        } else if options.resume && written_elsewhere(&folder) {
            // Weights without a training record (meshvae.torch's `save`, or a folder assembled
            // by hand): they are what the user wants continued; only the optimiser's moments
            // and the schedule start afresh.
            model.load(&folder.weights())?;
            eprintln!(
                "{}: no checkpoint or log, only weights: training continues from them \
                 (weights.safetensors) with a fresh optimiser and schedule, from epoch 1",
                folder.dir.display()
            );
        } else if options.resume {
            // Interrupted before its first checkpoint: said, so that a restart is not mistaken
            // for a continuation.
            eprintln!(
                "{}: no checkpoint to continue from (the run stopped before its first one); \
                 training restarts from epoch 1",
                folder.dir.display()
            );
        }
        let steps_per_epoch = data.split.train.len().div_ceil(spec.train.batch);
        let epochs = spec.train.epoch_budget(steps_per_epoch);
        let choice = ExecutorChoice::choose(&model, options.engine);
        let keep_in_memory = model.param_count().with_biases <= options.best_in_memory_params;
        // A resumed run goes on keeping them if it kept them before (or its file would go
        // stale).
        let keep_selected_on_test = options.keep_selected_on_test
            || (options.resume && folder.weights_selected_on_test().is_file());
        Ok(Self {
            options,
            start,
            rng: Rng::from_state(progress.rng)?,
            schedule: spec.train.schedule,
            base_lr: spec.train.lr,
            prior_seconds: progress.seconds,
            last_looked_at: adam.step_count(),
            finished_steps: adam.step_count(),
            _lock: lock,
            folder,
            spec,
            hierarchy,
            data,
            model,
            adam,
            progress,
            ended,
            epochs,
            steps_per_epoch,
            choice,
            phases: PhaseSeconds::default(),
            best: None,
            best_on_test: None,
            keep_in_memory,
            keep_selected_on_test,
            kept: None,
            last_write: Instant::now(),
            stop: StopReason::Budget,
            trained_since_rollback: true,
        })
    }

    /// The summary of a run an earlier session ended, where nothing is left to train (a
    /// converged run resumed with a larger budget has nothing left to learn either): its
    /// record stands as it is.
    pub(super) fn ended_before(&self) -> Result<Option<TrainSummary>> {
        let Some(ended) = &self.ended else {
            return Ok(None);
        };
        if ended.stop_reason != StopReason::Converged && ended.epochs < self.epochs {
            return Ok(None);
        }
        let log = read_log(&self.folder.log())?;
        Ok(Some(TrainSummary {
            epochs_run: 0,
            epochs_total: self.epochs,
            stop_reason: ended.stop_reason,
            steps: ended.steps,
            still_improving: ended.still_improving,
            lr: ended.lr,
            seconds_total: ended.seconds,
            last: log.last().cloned(),
            best_epoch: ended.best_epoch,
            best_loss: self.progress.best_loss,
            selected_on: self.data.split.selection(),
            seconds: self.start.elapsed().as_secs_f64(),
            executor: None,
        }))
    }

    /// Trains epoch after epoch until the run converges or its budget ends; `on_epoch` sees
    /// every finished epoch.
    pub(super) fn run(mut self, mut on_epoch: impl FnMut(&EpochRecord)) -> Result<TrainSummary> {
        truncate_log(&self.folder.log(), self.progress.epoch)?;
        let first_step = self.adam.step_count().max(1);
        self.adam.set_lr(self.lr_at(first_step))?;
        // A converged run resumed from a checkpoint of its last epoch (versions 1 and 2; newer
        // ones are told by `run.json`) has nothing left to learn.
        let already_converged = self.schedule.stops_early()
            && self.progress.schedule.since_best >= self.schedule.patience
            && self.adam.step_count() >= self.schedule.annealed_at();
        if !already_converged && self.progress.epoch < self.epochs {
            self.write_status(StopReason::Interrupted)?;
        }
        let bar = progress_bar(
            self.options.progress,
            self.epochs,
            self.progress.epoch,
            self.steps_per_epoch,
        );
        let mut last = None;
        let mut epochs_run = 0;
        let mut epoch = if already_converged {
            self.stop = StopReason::Converged;
            self.epochs + 1
        } else {
            self.progress.epoch + 1
        };
        while epoch <= self.epochs {
            let started = Instant::now();
            let steps_before = self.adam.step_count();
            let mut executor = self.take_executor()?;
            let (sums, mut divergence) = self.train_epoch(epoch, executor.as_mut(), &bar)?;
            if self.stop_requested() {
                drop(executor);
                bar.abandon();
                return Err(self.interrupt()?);
            }
            // Without validation meshes the score is the training loss, free to look at.
            let looked_at = epoch == self.epochs
                || self.data.split.val.is_empty()
                || (self.schedule).validation_due(steps_before, self.adam.step_count());
            let mut val_loss = None;
            if divergence.is_none() && looked_at {
                (val_loss, divergence) = self.look(epoch, executor.as_mut())?;
            }
            if let Some(what) = divergence {
                drop(executor);
                if let Err(e) = self.recover(what, &bar) {
                    bar.abandon();
                    return Err(e);
                }
                continue;
            }
            self.trained_since_rollback = true;
            let steps = EpochSteps {
                epoch,
                started,
                steps_before,
                sums,
                val_loss,
                looked_at,
            };
            let (record, finished) = self.end_epoch(steps, executor)?;
            bar.set_message(self.bar_message(&record));
            on_epoch(&record);
            last = Some(record);
            epochs_run += 1;
            if finished {
                break;
            }
            epoch += 1;
        }
        bar.finish();
        Ok(self.summary(epochs_run, last))
    }

    fn stop_requested(&self) -> bool {
        (self.options.stop.as_ref()).is_some_and(|stop| stop.is_requested())
    }

    /// The learning rate of optimizer step `step`.
    fn lr_at(&self, step: u64) -> f64 {
        (self.progress.schedule).lr(&self.schedule, self.base_lr, step)
    }

    /// This epoch's executor. A large model's engine is built per epoch and dropped before
    /// validation and checkpoints, so that its buffers (~0.6 GB on elephant-gallop at batch
    /// 16) never coexist with a checkpoint's copies; a small one's is kept (building it and
    /// touching fresh pages cost ~10 % of a horse-gallop epoch).
    fn take_executor(&mut self) -> Result<Box<dyn Executor>> {
        match self.kept.take() {
            Some(executor) => Ok(executor),
            None => self.choice.build(&self.model, self.spec.train.batch),
        }
    }

    /// One pass over the shuffled training meshes: the losses summed over its meshes, and the
    /// divergence that cut it short, if one did.
    fn train_epoch(
        &mut self,
        epoch: usize,
        executor: &mut dyn Executor,
        bar: &ProgressBar,
    ) -> Result<([f64; 4], Option<String>)> {
        let mut order = self.data.split.train.clone();
        self.rng.shuffle(&mut order);
        let mut sums = [0.0f64; 4];
        for chunk in order.chunks(self.spec.train.batch) {
            self.adam.set_lr(self.lr_at(self.adam.step_count() + 1))?;
            match self.step(epoch, chunk, executor)? {
                Ok(losses) => {
                    let w = chunk.len() as f64;
                    for (s, v) in sums.iter_mut().zip(losses) {
                        *s += v * w;
                    }
                    bar.inc(1);
                    if self.stop_requested() {
                        break;
                    }
                }
                Err(divergence) => return Ok((sums, Some(divergence))),
            }
        }
        Ok((sums, None))
    }

    /// One Adam step on the meshes `chunk`.
    fn step(
        &mut self,
        epoch: usize,
        chunk: &[usize],
        executor: &mut dyn Executor,
    ) -> Result<StepOutcome> {
        let device = &self.options.device;
        let (x, c, eps) = self.phases.time(
            |p| &mut p.batches,
            || -> Result<_> {
                let x = self.data.batch(chunk, device)?;
                let c = self.data.conditions(&self.model, chunk)?;
                let eps =
                    (self.rng).normal_tensor((chunk.len(), self.spec.model.latent), device)?;
                Ok((x, c, eps))
            },
        )?;
        let step = self.adam.step_count() + 1;
        let injected = match self.progress.schedule.rollbacks {
            0 => self.options.fail_step == Some(step),
            1 => self.options.fail_after_rollback && !self.trained_since_rollback,
            _ => false,
        };
        if injected {
            return Ok(Err(format!("epoch {epoch}: the loss is NaN (injected)")));
        }
        let step_inputs = TrainStep {
            batch: Batch {
                x: &x,
                c: c.as_ref(),
            },
            eps: &eps,
            adam: &mut self.adam,
            loss: &self.spec.train.loss,
        };
        let r = executor.step(&self.model, step_inputs)?;
        self.phases.forward_backward += r.forward_backward_seconds;
        self.phases.adam += r.update_seconds;
        if !r.finite {
            let (total, rec, kl, l2) = (r.total, r.rec, r.kl, r.l2);
            return Ok(Err(format!(
                "epoch {epoch} (step {step}): the loss is {total} (rec {rec}, kl {kl}, l2 {l2})"
            )));
        }
        Ok(Ok(r.terms()))
    }

    /// The loss on `ids` in inference mode: it reads the weights and changes nothing.
    fn loss_on(&self, ids: &[usize], executor: &mut dyn Executor) -> Result<Option<f64>> {
        let (batch, loss) = (self.spec.train.batch, &self.spec.train.loss);
        let device = &self.options.device;
        validation_loss(&self.model, &self.data, ids, batch, loss, device, executor)
    }

    /// The look at the validation loss after an epoch: the loss, and the divergence it shows,
    /// if any.
    fn look(
        &mut self,
        epoch: usize,
        executor: &mut dyn Executor,
    ) -> Result<(Option<f64>, Option<String>)> {
        let t = Instant::now();
        let val_loss = self.loss_on(&self.data.split.val, executor)?;
        self.phases.validation += t.elapsed().as_secs_f64();
        // The last step can leave non-finite weights behind a finite training loss.
        if let Some(v) = val_loss.filter(|v| !v.is_finite()) {
            let what = format!("epoch {epoch}: the validation loss is {v}");
            return Ok((val_loss, Some(what)));
        }
        let model = &self.model;
        let broken = (self.phases).time(
            |p| &mut p.bookkeeping,
            || rollback::non_finite_weight(model),
        )?;
        // The validation loss reads only the mean path: a broken σ branch passes it.
        let what = broken.map(|name| format!("epoch {epoch}: weight {name} is not finite"));
        Ok((val_loss, what))
    }

    /// Back to the best weights at half the rate after a divergence; the epoch is trained
    /// again (with the next shuffle).
    fn recover(&mut self, what: String, bar: &ProgressBar) -> Result<()> {
        // Best weights that diverge again before an epoch finishes are no place to go back to
        // (seen on samba, seed 3, epoch 14: one training mesh's σ overflows with the weights of
        // epoch 13 at any rate, and the validation pass, which reads only the mean, cannot see
        // it): start again from the initial weights instead.
        let initial = if self.trained_since_rollback {
            None
        } else {
            let (model, seed) = (&self.spec.model, self.spec.train.seed);
            let fresh = MeshVae::new(model, &self.hierarchy, &self.options.device, seed)?;
            Some(rollback::tensors_of(&fresh))
        };
        self.trained_since_rollback = false;
        let best = self.best.as_ref().map(|b| b.weights());
        let weights = self.folder.weights();
        let recovery = Recovery {
            what,
            best: best.as_ref(),
            initial: initial.as_ref(),
            weights: &weights,
            schedule: &self.schedule,
            base_lr: self.base_lr,
        };
        recovery.apply(&mut self.model, &mut self.adam, &mut self.progress)?;
        let message = recovery.message(&self.progress);
        // A hidden bar prints nothing, and a recovered divergence must not pass unseen;
        // without the bar's context, the folder says which of several runs it was.
        if bar.is_hidden() {
            eprintln!("{}: {message}", self.folder.dir.display());
        } else {
            bar.println(message);
        }
        Ok(())
    }
}

/// A model folder whose weights no `meshvae train` run recorded (no log, no status): written
/// by another program, such as meshvae.torch's `save`.
fn written_elsewhere(folder: &ModelFolder) -> bool {
    folder.weights().is_file() && !folder.log().is_file() && !folder.status().is_file()
}
