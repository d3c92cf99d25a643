//! `cargo xtask reproduce --check RECORD`: trains one recorded run again, from scratch, with
//! the settings its record names, and sets every number beside the stored one. Training is
//! deterministic (the engine's results do not depend on the thread count), so at the record's
//! commit they agree to the last digit; where they do not, the check says what differs between
//! the record's code and settings and this one's.

use super::commit::Commit;
use super::plan::{self, Run};
use super::record::{self, RunResult, RunSettings};
use super::run::{self, Place};
use super::{LoadedSet, ReproError};
use meshvae::Platform;
use std::fmt::Write;
use std::path::Path;

/// One number of the record, stored and now.
#[derive(Debug, Clone, PartialEq)]
pub struct Row {
    pub name: &'static str,
    pub stored: String,
    pub now: String,
}

impl Row {
    pub fn agrees(&self) -> bool {
        self.stored == self.now
    }
}

/// What [`check`] found.
#[derive(Debug, Clone)]
pub struct Checked {
    pub stored: RunResult,
    pub now: RunResult,
    pub rows: Vec<Row>,
    /// Why the numbers may differ: the code, the settings; empty where nothing explains it.
    pub reasons: Vec<String>,
}

impl Checked {
    /// Whether every number agrees to the digit.
    pub fn agrees(&self) -> bool {
        self.rows.iter().all(Row::agrees)
    }

    /// The comparison as a plain-text table, then the verdict.
    pub fn report(&self) -> String {
        let mut out = String::new();
        let width = self.rows.iter().map(|r| r.stored.len()).max().unwrap_or(0);
        let _ = writeln!(out, "{:<28} {:<width$}  now", "", "stored");
        for row in &self.rows {
            let mark = if row.agrees() { "" } else { "  ← differs" };
            let _ = writeln!(
                out,
                "{:<28} {:<width$}  {}{mark}",
                row.name, row.stored, row.now
            );
        }
        let differing = self.rows.iter().filter(|r| !r.agrees()).count();
        if differing == 0 {
            let _ = writeln!(
                out,
                "reproduced: all {} numbers agree to the digit.",
                self.rows.len()
            );
        } else {
            let _ = writeln!(
                out,
                "not reproduced: {differing} of {} numbers differ.",
                self.rows.len()
            );
            if self.reasons.is_empty() {
                let _ = writeln!(
                    out,
                    "The record names this very commit and settings, and training is \
                     deterministic: this is a bug (report it with the record)."
                );
            }
            for reason in &self.reasons {
                let _ = writeln!(out, "- {reason}");
            }
        }
        out
    }
}

/// Retrains the run of the record at `record_path` under `work` (its model folder replaced),
/// with the record's settings, and compares. `commit` is this code's.
pub fn check(
    record_path: &Path,
    work: &Path,
    commit: Option<&Commit>,
) -> Result<Checked, ReproError> {
    let stored = record::read_record(record_path)?;
    let run = run_of(&stored, record_path)?;
    let model = run.column.model().map_err(|e| ReproError::run(&run, e))?;
    let settings = stored
        .settings
        .clone()
        .unwrap_or_else(|| RunSettings::unrecorded(&run, &model));
    let loaded = set_of(&stored, &run, record_path)?;
    let folder = run.model_dir(work);
    if folder.exists() {
        std::fs::remove_dir_all(&folder).map_err(|e| ReproError::io(&folder, e))?;
    }
    let place = Place {
        work,
        records: work,
        checkpoint_seconds: 60.0,
        commit,
    };
    let now = run::execute(
        &run,
        &settings,
        &loaded.set,
        loaded.source.clone(),
        place,
        |_| {},
    )?;
    let rows = rows(&stored, &now);
    let mut reasons = Vec::new();
    match (&stored.commit, commit) {
        (None, _) => reasons.push(
            "The record does not name its commit (it was written before records kept it): \
             the code that made it may differ from this one."
                .into(),
        ),
        (Some(then), Some(now)) if then.hash() != now.hash() => reasons.push(format!(
            "The record was made at {then}; this check ran {now}: the code changed in between."
        )),
        (Some(then), None) => reasons.push(format!(
            "The record was made at {then}; this check ran outside a git work tree, so its \
             code is unknown."
        )),
        (Some(then), Some(now)) => {
            if then.dirty || now.dirty {
                reasons.push(format!(
                    "The record was made at {then}; this check ran {now}: uncommitted changes \
                     on either side can change the numbers."
                ));
            }
        }
    }
    if let Some(by) = &stored.trained_by {
        let names: Vec<String> = by.iter().map(|c| c.to_string()).collect();
        reasons.push(format!(
            "The record's run was trained by {} (resumed or evaluated again by other code): \
             one commit's training need not give its numbers.",
            match names.is_empty() {
                true => "code not recorded".to_string(),
                false => names.join(", then "),
            }
        ));
    }
    let here = Platform::this();
    match &stored.platform {
        None => reasons.push(format!(
            "The record does not name its machine (it was written before records kept it): \
             the numbers depend on the CPU's SIMD features and data caches (`gemm` blocks its \
             products by them), and this check ran on {here}."
        )),
        Some(then) if !then.same_numerics(&here) => reasons.push(format!(
            "The record was trained on {then}; this check ran on {here}: other SIMD features \
             or caches order the sums differently, and the difference grows over the steps."
        )),
        Some(_) => {}
    }
    if stored.settings.is_none() {
        reasons.push(
            "The record keeps no settings: it was retrained with the settings assumed for \
             records of its time, which may not be the ones it ran."
                .into(),
        );
    }
    if stored.model != model {
        reasons.push(format!(
            "The column {:?} defines another network today than the record's.",
            stored.column
        ));
    }
    Ok(Checked {
        stored,
        now,
        rows,
        reasons,
    })
}

/// The run a record belongs to.
fn run_of(r: &RunResult, path: &Path) -> Result<Run, ReproError> {
    let unknown = |what: &str, value: &str| ReproError::Results {
        path: path.to_path_buf(),
        message: format!("the record's {what} {value:?} is not one this code knows"),
    };
    Ok(Run {
        dataset: plan::dataset(&r.dataset).ok_or_else(|| unknown("data set", &r.dataset))?,
        protocol: plan::protocol(&r.protocol).ok_or_else(|| unknown("protocol", &r.protocol))?,
        budget: r.budget(),
        seed: r.seed,
        column: plan::column(&r.column).ok_or_else(|| unknown("column", &r.column))?,
        by_shape: r.split_by_shape,
    })
}

/// The record's data set: the synthetic set of a full or a `--quick` run, whichever has the
/// record's vertex count; a real set from the data sets folder.
fn set_of(r: &RunResult, run: &Run, path: &Path) -> Result<LoadedSet, ReproError> {
    let vertices = r.levels.first().copied().unwrap_or(0);
    let mut tried = Vec::new();
    for quick in [false, true] {
        let loaded = super::load(run.dataset, quick)?;
        if loaded.set.vertex_count() == vertices {
            return Ok(loaded);
        }
        tried.push(loaded.set.vertex_count().to_string());
        if !matches!(run.dataset.source, plan::Source::Synthetic) {
            break;
        }
    }
    Err(ReproError::Results {
        path: path.to_path_buf(),
        message: format!(
            "the record's meshes have {vertices} vertices, but {} has {}",
            run.dataset.name,
            tried.join(" or ")
        ),
    })
}

/// How one number of a record is written.
type Show = fn(&RunResult) -> String;

/// The numbers a record states, stored and now, as they are written (shortest round-trip
/// decimal, so equal text is equal bits).
fn rows(stored: &RunResult, now: &RunResult) -> Vec<Row> {
    fn opt<T: ToString>(x: &Option<T>) -> String {
        x.as_ref().map_or("none".into(), T::to_string)
    }
    let pick: [(&'static str, Show); 18] = [
        ("test RMS", |r| r.test_rms.to_string()),
        ("test RMS / diagonal", |r| r.test_rms_rel.to_string()),
        ("test mean distance", |r| r.test_mean_distance.to_string()),
        ("test mean distance, rigid", |r| {
            opt(&r.test_mean_distance_rigid)
        }),
        ("train RMS", |r| r.train_rms.to_string()),
        ("mean-shape RMS", |r| r.mean_shape_rms.to_string()),
        ("test RMS, chosen on test", |r| {
            opt(&r.test_rms_selected_on_test)
        }),
        ("stop reason", |r| opt(&r.stop_reason)),
        ("steps", |r| opt(&r.steps)),
        ("epochs", |r| r.epochs.to_string()),
        ("best epoch", |r| r.best_epoch.to_string()),
        ("best epoch on test", |r| opt(&r.best_epoch_on_test)),
        ("rollbacks", |r| opt(&r.rollbacks)),
        ("parameters", |r| r.params.to_string()),
        ("train / val / test meshes", |r| {
            format!("{} / {} / {}", r.train_meshes, r.val_meshes, r.test_meshes)
        }),
        ("levels", |r| format!("{:?}", r.levels)),
        ("selected on", |r| r.selected_on.clone()),
        ("copies: seen / unseen rigid", |r| {
            r.copy_split.map_or("none".into(), |c| {
                format!(
                    "{} / {}",
                    c.copy_in_training_mean_distance_rigid,
                    opt(&c.unseen_mean_distance_rigid)
                )
            })
        }),
    ];
    pick.iter()
        .map(|(name, f)| Row {
            name,
            stored: f(stored),
            now: f(now),
        })
        .collect()
}
