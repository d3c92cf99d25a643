//! `cargo xtask reproduce`: trains the paper's ablations on our data sets, several seeds each,
//! and writes `docs/results.md` (or the page of another plan) with our numbers beside the
//! paper's.
//!
//! - [`plan`]: the run table (data sets, columns, protocols) and each run's folder;
//! - [`run`]: one run — train with resumption, evaluate, record a result JSON;
//! - [`record`]: that JSON (`RunResult`), and whether a record is today's or stale;
//! - [`settings`], [`commit`] (and `meshvae::Platform`, the machine): what a record says made it,
//!   and what differs from today's;
//! - [`check`]: `--check RECORD`, one record retrained and compared digit by digit;
//! - [`stats`]: mean ± std over seeds;
//! - [`table`]: the markdown, and each page's summary for the README (`table::summary`);
//! - [`params`]: parameter counts (ours by the paper's formula, Tan et al.'s derived);
//! - [`paper`]: the paper's numbers.
//!
//! Every run is a model folder under the work folder,
//! `<data set>/<protocol>/<budget>/seed<N>/<column>` with the budget `converged` (the default:
//! until the validation loss converges, `-by-mesh` for the paper's split) or `e<epochs>`
//! (`--epochs N`: a fixed number of epochs at the authors' constant rate); a finished
//! run leaves `<column>.result.json` beside it (with the commit and settings that made it) and
//! is skipped next time while today's code would train it with the same settings, an unfinished
//! one is resumed from its checkpoint, so an interrupted `reproduce` continues where it stopped.
//! A set that holds no shape twice splits alike by shape and by mesh, so the paper's split
//! trains it in the by-shape folders and both pages share those runs ([`Run::with_split_of`]).

pub mod check;
pub mod commit;
pub mod paper;
pub mod params;
pub mod plan;
pub mod record;
pub mod run;
pub mod settings;
pub mod stats;
pub mod table;

use commit::Commit;
use indicatif::{MultiProgress, ProgressBar, ProgressDrawTarget, ProgressStyle};
use mesh_io::MeshSet;
use mesh_io::synth::SynthConfig;
use plan::{Budget, Column, Dataset, Protocol, Run, Source};
use record::{Recorded, RunResult};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// What can stop `reproduce`; each names the data set, run or file concerned.
#[derive(Debug, thiserror::Error)]
pub enum ReproError {
    #[error("invalid {arg}: {message}")]
    Argument { arg: &'static str, message: String },
    #[error("data set {name}: {message}")]
    Dataset { name: String, message: String },
    #[error("run {run}: {source}")]
    Run {
        run: String,
        // Boxed: the library's error is large, and this one travels through every call.
        source: Box<meshvae::VaeError>,
    },
    #[error("{}: {message}", path.display())]
    Results { path: PathBuf, message: String },
}

impl ReproError {
    pub(crate) fn run(run: &Run, source: meshvae::VaeError) -> Self {
        Self::Run {
            run: run.name(),
            source: Box::new(source),
        }
    }

    /// Whether Ctrl-C or SIGTERM stopped the runs (each wrote its state first, so the same
    /// command continues them).
    pub fn is_interrupted(&self) -> bool {
        matches!(self, Self::Run { source, .. }
            if matches!(**source, meshvae::VaeError::Interrupted { .. }))
    }

    pub(crate) fn io(path: &Path, e: impl std::fmt::Display) -> Self {
        Self::Results {
            path: path.to_path_buf(),
            message: e.to_string(),
        }
    }
}

/// Settings of one `reproduce` invocation.
#[derive(Debug, Clone)]
pub struct Options {
    pub datasets: Vec<&'static Dataset>,
    /// The columns to train (the page still shows every finished record): a reproduction too
    /// long for one sitting can train our method first and the ablations later.
    pub columns: Vec<&'static Column>,
    /// How long every run trains: a fixed number of epochs, or until converged.
    pub budget: Budget,
    /// Seeds 1..=seeds; each draws its own split.
    pub seeds: u64,
    /// Small synthetic set, one checkpoint per run.
    pub quick: bool,
    pub protocol: &'static Protocol,
    /// Draw each seed's split by shape (`meshvae::TrainConfig::split_by_shape`); false draws it
    /// mesh by mesh, as the paper's random halves, except on a set without repeated shapes,
    /// where the two are one split and the by-shape runs are used (`plan::Run::with_split_of`).
    pub by_shape: bool,
    /// Folder of the model folders (and, unless `records` says otherwise, the run results).
    pub work: PathBuf,
    /// Folder of the finished runs' result JSONs, laid out as under `work`: small enough to
    /// keep in version control, so a reproduction spread over several machines resumes from
    /// the runs another machine finished, and the tables can be regenerated from them.
    pub records: Option<PathBuf>,
    /// Runs trained at once, each on its own share of the cores (`--jobs`); one run on all
    /// cores is the default. The numbers do not depend on it (the engine's results are
    /// independent of the thread count).
    pub jobs: usize,
    /// The markdown file to write.
    pub results: PathBuf,
    /// The command line, quoted in the markdown.
    pub command: String,
    /// Draw progress bars (on a terminal).
    pub progress: bool,
    /// Train nothing: write the markdown from the runs already finished (a full reproduction
    /// spans several sessions; this shows where it stands).
    pub report_only: bool,
    /// The code this invocation runs, written into every record it makes.
    pub commit: Option<Commit>,
}

impl Options {
    /// Where finished runs' results are read and written.
    pub fn records(&self) -> &Path {
        self.records.as_deref().unwrap_or(&self.work)
    }

    /// Checks the numbers.
    pub fn validate(&self) -> Result<(), ReproError> {
        if self.budget == Budget::Epochs(0) {
            return Err(ReproError::Argument {
                arg: "--epochs",
                message: "must be at least 1".into(),
            });
        }
        if self.budget == (Budget::Converged { max_steps: 0 }) {
            return Err(ReproError::Argument {
                arg: "--converged",
                message: "the step budget must be at least 1".into(),
            });
        }
        if self.seeds == 0 {
            return Err(ReproError::Argument {
                arg: "--seeds",
                message: "must be at least 1".into(),
            });
        }
        if self.jobs == 0 {
            return Err(ReproError::Argument {
                arg: "--jobs",
                message: "must be at least 1".into(),
            });
        }
        if self.datasets.is_empty() {
            return Err(ReproError::Argument {
                arg: "--dataset",
                message: "no data set to run".into(),
            });
        }
        Ok(())
    }
}

/// A loaded data set and what the tables say about it.
#[derive(Debug, Clone)]
pub struct LoadedSet {
    pub dataset: &'static Dataset,
    pub set: MeshSet,
    pub source: Option<PathBuf>,
    /// Bounding-box diagonal of the first mesh (the unit of the relative errors).
    pub diagonal: f64,
    /// How it was made, for the markdown.
    pub description: String,
    /// Whether some shape occurs twice (`MeshSet::shape_groups`): only then does a split by
    /// mesh differ from a split by shape.
    pub repeated_shapes: bool,
}

/// The synthetic set of a quick run (258 vertices, 16 meshes) or of a full one (`meshvae
/// synth`'s default: 2,498 vertices, 80 meshes).
pub fn synthetic_config(quick: bool) -> SynthConfig {
    if quick {
        SynthConfig {
            meshes_per_label: 8,
            rings: 12,
            segments: 16,
            cap_rings: 2,
            ..SynthConfig::default()
        }
    } else {
        SynthConfig::default()
    }
}

/// Loads (or generates) a data set.
pub fn load(dataset: &'static Dataset, quick: bool) -> Result<LoadedSet, ReproError> {
    let fail = |message: String| ReproError::Dataset {
        name: dataset.name.into(),
        message,
    };
    let (set, source, how) = match dataset.source {
        Source::Synthetic => {
            let config = synthetic_config(quick);
            let set = mesh_io::synth::generate(&config)
                .map_err(|e| fail(e.to_string()))?
                .set;
            let how = format!(
                "`mesh_io::synth` bend/twist capsule ({} per label, {} rings × {} segments, {} \
                 cap rings, seed {:#x})",
                config.meshes_per_label,
                config.rings,
                config.segments,
                config.cap_rings,
                config.seed
            );
            (set, None, how)
        }
        Source::Real => {
            let dir = mesh_io::datasets::find(dataset.name).ok_or_else(|| {
                fail("not found (run ../shared/datasets/unpack, or set MESHVAE_DATASETS)".into())
            })?;
            let set = mesh_io::load_set(&dir)
                .map_err(|e| fail(e.to_string()))?
                .value;
            // The folder's name only: the page must not carry this machine's paths.
            let how = format!(
                "`{}/` of the data sets folder",
                dir.file_name()
                    .map_or(dataset.name.into(), |n| n.to_string_lossy())
            );
            (set, std::fs::canonicalize(&dir).ok(), how)
        }
    };
    let diagonal = mesh_io::bbox_diagonal(set.frame(0));
    let repeated_shapes = set
        .shape_groups(mesh_io::ShapeGroups::DEFAULT_TOLERANCE)
        .map_err(|e| fail(e.to_string()))?
        .has_repeats();
    Ok(LoadedSet {
        dataset,
        description: how,
        repeated_shapes,
        set,
        source,
        diagonal,
    })
}

/// The machine, as results.md states it.
#[derive(Debug, Clone, PartialEq)]
pub struct Machine {
    pub cores: usize,
    pub cpu: String,
}

impl Machine {
    pub fn this() -> Self {
        let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
        let cpu = std::fs::read_to_string("/proc/cpuinfo")
            .ok()
            .and_then(|text| {
                text.lines()
                    .find(|l| l.starts_with("model name"))
                    .and_then(|l| l.split(':').nth(1))
                    .map(|s| s.trim().to_string())
            })
            .unwrap_or_else(|| "unknown CPU".into());
        Self { cores, cpu }
    }
}

/// Everything the markdown is made from.
#[derive(Debug, Clone)]
pub struct Outcome {
    pub options: Options,
    pub sets: Vec<LoadedSet>,
    pub results: Vec<RunResult>,
    /// Runs skipped because an earlier invocation finished them.
    pub reused: usize,
    pub machine: Machine,
    /// This invocation, seconds.
    pub wall_seconds: f64,
    /// Notes such as data sets skipped in quick mode.
    pub notes: Vec<String>,
}

/// Runs every run of `options` (skipping finished ones), then writes the markdown.
pub fn reproduce(options: Options, mut notes: Vec<String>) -> Result<Outcome, ReproError> {
    options.validate()?;
    let started = Instant::now();
    let seeds: Vec<u64> = (1..=options.seeds).collect();
    let runs = plan::runs(
        &options.datasets,
        &options.columns,
        options.protocol,
        options.budget,
        &seeds,
        options.by_shape,
    );
    let multi = MultiProgress::with_draw_target(if options.progress {
        ProgressDrawTarget::stderr()
    } else {
        ProgressDrawTarget::hidden()
    });
    let runs_bar = multi.add(ProgressBar::new(runs.len() as u64));
    if let Ok(style) =
        ProgressStyle::with_template("runs   {bar:30} {pos}/{len}  {msg}  [{elapsed_precise}]")
    {
        runs_bar.set_style(style);
    }

    let mut sets = Vec::new();
    let mut results = Vec::new();
    let mut reused = 0;
    let mut unfinished = 0;
    let mut stale = Vec::new();
    for &dataset in &options.datasets {
        let loaded = load(dataset, options.quick)?;
        let mut pending = Vec::new();
        let vertices = loaded.set.vertex_count();
        let mut too_small = Vec::new();
        let set_runs: Vec<Run> = runs
            .iter()
            .filter(|r| r.dataset.name == dataset.name)
            .map(|r| r.with_split_of(loaded.repeated_shapes))
            .collect();
        for run in &set_runs {
            let net = run.column.net;
            if vertices < net.min_vertices() {
                if !too_small.contains(&net) {
                    too_small.push(net);
                    notes.push(format!(
                        "{net} is not run on {} ({vertices} vertices): it samples the template \
                         down by 4 four times, which needs at least {}.",
                        dataset.name,
                        net.min_vertices()
                    ));
                }
                runs_bar.inc(1);
                continue;
            }
            let record = record::recorded(run, options.records())?;
            if let Recorded::Current(done) = record {
                reused += 1;
                results.push(*done);
                runs_bar.inc(1);
                continue;
            }
            if let Recorded::Stale { differences, .. } = record {
                stale.push((run.name(), differences));
            }
            if options.report_only {
                unfinished += 1;
                runs_bar.inc(1);
            } else {
                pending.push(run);
            }
        }
        let trainer = Trainer {
            options: &options,
            loaded: &loaded,
            multi: &multi,
            runs_bar: &runs_bar,
        };
        results.extend(trainer.train_all(&pending)?);
        sets.push(loaded);
    }
    runs_bar.finish_and_clear();
    if unfinished > 0 {
        notes.push(format!(
            "**Partial:** {unfinished} of the {} runs have not finished yet (\"not run\" below, \
             and means over fewer seeds where a seed is missing); this page was written with \
             `--report-only`, and the same command without it continues the runs.",
            runs.len()
        ));
    }
    if !stale.is_empty() {
        notes.push(stale_note(&stale, options.report_only));
    }
    if reused > 0 {
        notes.push(format!(
            "{reused} of {} runs were finished by an earlier invocation and read from their \
             result files.",
            runs.len()
        ));
    }
    let outcome = Outcome {
        options,
        sets,
        results,
        reused,
        machine: Machine::this(),
        wall_seconds: started.elapsed().as_secs_f64(),
        notes,
    };
    write_results(&outcome)?;
    Ok(outcome)
}

/// The page's note on records made with other settings than today's: how many, and what
/// changed, grouped by the same differences.
fn stale_note(stale: &[(String, Vec<String>)], report_only: bool) -> String {
    let mut groups: Vec<(&[String], Vec<&str>)> = Vec::new();
    for (name, differences) in stale {
        match groups
            .iter_mut()
            .find(|(d, _)| *d == differences.as_slice())
        {
            Some((_, names)) => names.push(name),
            None => groups.push((differences, vec![name])),
        }
    }
    let described: Vec<String> = groups
        .iter()
        .map(|(differences, names)| {
            let runs = match names.as_slice() {
                [one] => one.to_string(),
                [first, ..] => format!("{} runs ({first}, …)", names.len()),
                [] => String::new(),
            };
            format!("{runs}: {}", differences.join(", "))
        })
        .collect();
    format!(
        "**Stale:** {} of the records were made with other settings than today's code runs; \
         they are {}. {}.",
        stale.len(),
        if report_only {
            "not shown (the same command without `--report-only` trains them again)"
        } else {
            "not reused: this invocation trained them again"
        },
        described.join("; ")
    )
}

/// Trains one data set's unfinished runs, `options.jobs` at a time.
struct Trainer<'a> {
    options: &'a Options,
    loaded: &'a LoadedSet,
    multi: &'a MultiProgress,
    runs_bar: &'a ProgressBar,
}

impl Trainer<'_> {
    /// Results in the order of `pending`; the first error stops every job after its current
    /// run (whose checkpoint lets the next invocation resume it).
    fn train_all(&self, pending: &[&Run]) -> Result<Vec<RunResult>, ReproError> {
        let jobs = self.options.jobs.min(pending.len()).max(1);
        if jobs == 1 {
            return pending.iter().map(|run| self.train(run)).collect();
        }
        let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
        let threads = (cores / jobs).max(1);
        let next = std::sync::atomic::AtomicUsize::new(0);
        let stop = std::sync::atomic::AtomicBool::new(false);
        let done = std::sync::Mutex::new(Vec::new());
        let failed = std::sync::Mutex::new(None);
        std::thread::scope(|scope| {
            for _ in 0..jobs {
                scope.spawn(|| {
                    let pool = match rayon::ThreadPoolBuilder::new().num_threads(threads).build() {
                        Ok(pool) => pool,
                        Err(e) => {
                            stop.store(true, std::sync::atomic::Ordering::SeqCst);
                            *failed.lock().unwrap_or_else(|p| p.into_inner()) =
                                Some(ReproError::Argument {
                                    arg: "--jobs",
                                    message: format!("cannot start a thread pool: {e}"),
                                });
                            return;
                        }
                    };
                    while !stop.load(std::sync::atomic::Ordering::SeqCst) {
                        let i = next.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
                        let Some(run) = pending.get(i) else { break };
                        match pool.install(|| self.train(run)) {
                            Ok(result) => done
                                .lock()
                                .unwrap_or_else(|p| p.into_inner())
                                .push((i, result)),
                            Err(e) => {
                                stop.store(true, std::sync::atomic::Ordering::SeqCst);
                                failed
                                    .lock()
                                    .unwrap_or_else(|p| p.into_inner())
                                    .get_or_insert(e);
                            }
                        }
                    }
                });
            }
        });
        if let Some(e) = failed.into_inner().unwrap_or_else(|p| p.into_inner()) {
            return Err(e);
        }
        let mut done = done.into_inner().unwrap_or_else(|p| p.into_inner());
        done.sort_by_key(|(i, _)| *i);
        Ok(done.into_iter().map(|(_, result)| result).collect())
    }

    /// One run, with its own epoch bar. A converged-plan run's bar is as long as its budget in
    /// epochs once its first epoch tells how many steps an epoch takes (the step budget, an
    /// upper bound, until then); the run usually stops before its end, when its message's count
    /// of steps without a new best reaches the patience.
    fn train(&self, run: &Run) -> Result<RunResult, ReproError> {
        let length = match run.budget {
            Budget::Epochs(epochs) => epochs,
            Budget::Converged { max_steps } => max_steps,
        };
        let bar = self.multi.add(ProgressBar::new(length as u64));
        if let Ok(style) =
            ProgressStyle::with_template("epochs {bar:30} {pos}/{len}  {msg}  [{eta_precise} left]")
        {
            bar.set_style(style);
        }
        let name = run.name();
        bar.set_message(name.clone());
        let patience = run.train_config().schedule.patience;
        let checkpoint_seconds = if self.options.quick { 1e9 } else { 60.0 };
        let model = run.column.model().map_err(|e| ReproError::run(run, e))?;
        let place = run::Place {
            work: &self.options.work,
            records: self.options.records(),
            checkpoint_seconds,
            commit: self.options.commit.as_ref(),
        };
        let result = run::execute(
            run,
            &record::RunSettings::of(run, &model),
            &self.loaded.set,
            self.loaded.source.clone(),
            place,
            |record| {
                if let Some(max_steps) = run.budget.max_steps()
                    && record.epoch > 0
                    && record.step > 0
                {
                    let steps_per_epoch = (record.step as usize).div_ceil(record.epoch);
                    bar.set_length(max_steps.div_ceil(steps_per_epoch) as u64);
                }
                bar.set_position(record.epoch as u64);
                if let Some(n) = record.since_best {
                    bar.set_message(format!("{name}  no new best for {n}/{patience} steps"));
                }
            },
        );
        bar.finish_and_clear();
        self.multi.remove(&bar);
        let result = result?;
        self.multi.suspend(|| {
            println!(
                "{}: test RMS {:.5} ({:.3e} of the diagonal), {:.1} s",
                run.name(),
                result.test_rms,
                result.test_rms_rel,
                result.train_seconds + result.other_seconds
            )
        });
        self.runs_bar.inc(1);
        Ok(result)
    }
}

/// Writes the markdown atomically, keeping the hand-written block of the file it replaces.
pub fn write_results(outcome: &Outcome) -> Result<(), ReproError> {
    let path = &outcome.options.results;
    let kept = match std::fs::read_to_string(path) {
        Ok(text) => table::hand_written(&text).map(str::to_string),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => None,
        Err(e) => return Err(ReproError::io(path, e)),
    };
    let markdown = table::markdown(outcome, kept.as_deref());
    if let Some(parent) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(parent).map_err(|e| ReproError::io(parent, e))?;
    }
    table::figure::write_figures(outcome)?;
    mesh_io::atomic::write_bytes_atomic(path, markdown.as_bytes())
        .map_err(|e| ReproError::io(path, e))?;
    write_summary(outcome)
}

/// Rewrites the page's summary in the README of the folder above the page's (`docs/x.md` →
/// `README.md`), where that README holds the page's markers (`table::summary::begin_marker`):
/// the README's figures then come from the same records as the page.
fn write_summary(outcome: &Outcome) -> Result<(), ReproError> {
    let page = &outcome.options.results;
    let Some(root) = page.parent().and_then(Path::parent) else {
        return Ok(());
    };
    let readme = root.join("README.md");
    let text = match std::fs::read_to_string(&readme) {
        Ok(text) => text,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(()),
        Err(e) => return Err(ReproError::io(&readme, e)),
    };
    let Ok(link) = page.strip_prefix(root) else {
        return Ok(());
    };
    let link: Vec<String> = (link.components())
        .map(|c| c.as_os_str().to_string_lossy().into_owned())
        .collect();
    let link = link.join("/");
    let summary = table::summary::summary(outcome, &link);
    match table::summary::replace_block(&text, &link, &summary) {
        Some(new) if new != text => mesh_io::atomic::write_bytes_atomic(&readme, new.as_bytes())
            .map_err(|e| ReproError::io(&readme, e)),
        _ => Ok(()),
    }
}
