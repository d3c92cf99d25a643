//! The run table: data sets, columns (network variants) and protocols, and the runs they make.
//!
//! A column or a protocol is one entry of [`COLUMNS`] or [`PROTOCOLS`]: the tables, the folder
//! names and the markdown follow from the entries. A run is one (data set, protocol, budget,
//! seed, column); each seed draws its own random half/half split. The budget is the plan: a
//! fixed number of epochs at the authors' constant rate, or `meshvae train`'s default training
//! until the validation loss converges ([`Budget`]).

use meshvae::{DEFAULT_MAX_STEPS, TrainConfig};
use std::path::{Path, PathBuf};

mod columns;
pub use columns::{COLUMNS, Column, Group, OURS, column};

/// How the reported checkpoint is chosen and what the model may see.
#[derive(Debug, Clone, Copy)]
pub struct Protocol {
    /// Folder name.
    pub id: &'static str,
    /// What results.md says about it.
    pub description: &'static str,
    /// Adjusts the training settings for the protocol.
    pub configure: fn(&mut TrainConfig),
    /// Report the weights with the lowest test loss (`meshvae eval --select-on-test`).
    pub select_on_test: bool,
}

fn validation_protocol(train: &mut TrainConfig) {
    train.val_fraction = 0.1;
}

fn authors_protocol(train: &mut TrainConfig) {
    train.val_fraction = 0.0;
}

/// The protocols, the default first.
pub const PROTOCOLS: &[Protocol] = &[
    Protocol {
        id: "validation",
        description: "validation: 10 % of each seed's training half (at least one mesh, two from ten on, whole \
                      shapes, drawn from the seed) is held out as a validation set, and the reported weights \
                      are those of the epoch with the lowest validation loss; no test mesh \
                      influences training or the choice of checkpoint (`meshvae train`'s \
                      default). The weights the test loss would have chosen are evaluated too, \
                      in the columns marked \"selected on test\"",
        configure: validation_protocol,
        select_on_test: false,
    },
    Protocol {
        id: "select-on-test",
        description: "the authors' protocol: the whole training half trains and the reported \
                      weights are those of the epoch with the lowest loss on the test meshes \
                      (as its evaluation script picks it), so the test set takes part in \
                      choosing the checkpoint; the numbers are not errors on unseen data",
        configure: authors_protocol,
        select_on_test: true,
    },
];

/// Looks a protocol up by id.
pub fn protocol(id: &str) -> Option<&'static Protocol> {
    PROTOCOLS.iter().find(|p| p.id == id)
}

/// Where a data set's meshes come from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Source {
    /// `mesh_io::synth`: small in quick mode, `meshvae synth`'s default otherwise.
    Synthetic,
    /// One of `mesh_io::datasets::KNOWN`.
    Real,
}

/// A data set `reproduce` knows.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Dataset {
    pub name: &'static str,
    pub source: Source,
}

/// Every data set, in table order.
pub const DATASETS: &[Dataset] = &[
    Dataset {
        name: "horse-gallop",
        source: Source::Real,
    },
    Dataset {
        name: "samba",
        source: Source::Real,
    },
    Dataset {
        name: "elephant-gallop",
        source: Source::Real,
    },
    Dataset {
        name: "synthetic",
        source: Source::Synthetic,
    },
];

/// Looks a data set up by name.
pub fn dataset(name: &str) -> Option<&'static Dataset> {
    DATASETS.iter().find(|d| d.name == name)
}

/// How long every run of a plan trains, and how.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Budget {
    /// Exactly this many epochs at the authors' constant learning rate of 1e-3, without early
    /// stop (runs under `<set>/<protocol>/e<epochs>`): the first reproduction's plan, whose
    /// networks were still learning at 600 epochs.
    Epochs(usize),
    /// `meshvae train`'s default training (`TrainConfig::default()`'s learning rate and
    /// schedule): until the validation loss converges, or at most `max_steps` optimizer steps
    /// ([`DEFAULT_MAX_STEPS`], as `meshvae train` given no budget; `--quick` uses fewer).
    Converged { max_steps: usize },
}

impl Budget {
    /// The converged plan with `meshvae train`'s step budget.
    pub const CONVERGED: Self = Self::Converged {
        max_steps: DEFAULT_MAX_STEPS,
    };

    /// The folder of the plan's runs: `e<epochs>`, `converged`, or `converged-s<max steps>`
    /// for a step budget other than [`DEFAULT_MAX_STEPS`].
    pub fn dir_name(&self) -> String {
        match *self {
            Self::Epochs(epochs) => format!("e{epochs}"),
            Self::Converged { max_steps } if max_steps == DEFAULT_MAX_STEPS => "converged".into(),
            Self::Converged { max_steps } => format!("converged-s{max_steps}"),
        }
    }

    /// The fixed number of epochs, if the plan has one.
    pub fn epochs(&self) -> Option<usize> {
        match *self {
            Self::Epochs(epochs) => Some(epochs),
            Self::Converged { .. } => None,
        }
    }

    /// The step budget of the converged plan.
    pub fn max_steps(&self) -> Option<usize> {
        match *self {
            Self::Epochs(_) => None,
            Self::Converged { max_steps } => Some(max_steps),
        }
    }
}

/// One training run.
#[derive(Debug, Clone, Copy)]
pub struct Run {
    pub dataset: &'static Dataset,
    pub protocol: &'static Protocol,
    pub budget: Budget,
    pub seed: u64,
    pub column: &'static Column,
    /// Test and validation meshes drawn by shape (`TrainConfig::split_by_shape`), so copies
    /// of one shape stay on one side; otherwise mesh by mesh.
    pub by_shape: bool,
}

impl Run {
    /// `WORK/<data set>/<protocol>/<budget>/seed<seed>`, the budget `e<epochs>` or `converged`
    /// ([`Budget::dir_name`]): the runs sharing a split (`e<epochs>-by-mesh`,
    /// `converged-by-mesh` for splits drawn mesh by mesh).
    pub fn seed_dir(&self, work: &Path) -> PathBuf {
        let split = if self.by_shape { "" } else { "-by-mesh" };
        work.join(self.dataset.name)
            .join(self.protocol.id)
            .join(format!("{}{split}", self.budget.dir_name()))
            .join(format!("seed{}", self.seed))
    }

    /// The model folder.
    pub fn model_dir(&self, work: &Path) -> PathBuf {
        self.seed_dir(work).join(self.column.id)
    }

    /// The small JSON written when the run is finished and evaluated.
    pub fn result_path(&self, work: &Path) -> PathBuf {
        self.seed_dir(work)
            .join(format!("{}.result.json", self.column.id))
    }

    /// The training settings: the paper's defaults, this run's budget and seed, the protocol.
    /// A fixed number of epochs trains at a constant learning rate of 1e-3 with min–max feature
    /// ranges (the authors'), as every run recorded before the converged plan; the converged plan trains as `meshvae
    /// train` does given no budget (default rate and schedule, at most `max_steps` steps).
    pub fn train_config(&self) -> TrainConfig {
        let net = TrainConfig::for_network(self.column.net);
        let mut train = match self.budget {
            Budget::Epochs(epochs) => TrainConfig {
                epochs,
                schedule: meshvae::Schedule::constant(),
                lr: 1e-3,
                normalize_quantile: 0.0,
                adam_beta2: meshvae::AdamConfig::default().beta2,
                head_lr_scale: 1.0,
                grad_clip: 0.0,
                ..net
            },
            Budget::Converged { max_steps } => TrainConfig {
                steps: Some(max_steps),
                ..net
            },
        };
        train.seed = self.seed;
        train.split_by_shape = self.by_shape;
        (self.protocol.configure)(&mut train);
        train
    }

    /// The training settings assumed for a record of this run written before records kept
    /// their settings: those of [`Self::train_config`] with the optimiser and schedule that
    /// `meshvae train` used by default then (a rate of 1e-2 halved on plateaus, TF's β₂, one
    /// rate for every weight, no gradient clipping, validation after every epoch). While the defaults are those, such a
    /// record is reused; once they change, it is trained again.
    pub fn unrecorded_train_config(&self) -> TrainConfig {
        let mut train = self.train_config();
        if let Budget::Converged { .. } = self.budget {
            train.lr = 1e-2;
            train.schedule = meshvae::Schedule::plateau();
            train.adam_beta2 = 0.999;
            train.head_lr_scale = 1.0;
            train.grad_clip = 0.0;
        }
        train
    }

    /// This run on a set with or without repeated shapes. Without repeats a split by mesh is
    /// the split by shape, mesh for mesh (`meshvae::Split::random_by_shape`), and nothing else
    /// in training depends on how it was drawn: the run is then the by-shape one, so that both
    /// results pages share its folder and record instead of training it twice.
    pub fn with_split_of(self, repeated_shapes: bool) -> Self {
        Self {
            by_shape: self.by_shape || !repeated_shapes,
            ..self
        }
    }

    /// A short name for progress lines.
    pub fn name(&self) -> String {
        format!(
            "{} seed {} {}",
            self.dataset.name, self.seed, self.column.id
        )
    }
}

/// Every run of `datasets` × `seeds` × `columns`, data set by data set, seed by seed.
pub fn runs(
    datasets: &[&'static Dataset],
    columns: &[&'static Column],
    protocol: &'static Protocol,
    budget: Budget,
    seeds: &[u64],
    by_shape: bool,
) -> Vec<Run> {
    let mut out = Vec::new();
    for &dataset in datasets {
        for &seed in seeds {
            for &column in columns {
                out.push(Run {
                    dataset,
                    protocol,
                    budget,
                    seed,
                    column,
                    by_shape,
                });
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::reproduce::paper::AblationColumn;

    #[test]
    fn a_split_by_mesh_of_a_set_without_repeats_is_its_split_by_shape() {
        let run = |by_shape| Run {
            dataset: dataset("samba").unwrap(),
            protocol: &PROTOCOLS[0],
            budget: Budget::CONVERGED,
            seed: 2,
            column: COLUMNS.iter().find(|c| c.is_ours()).unwrap(),
            by_shape,
        };
        let work = Path::new("/w");
        let shared = run(false).with_split_of(false);
        assert!(shared.by_shape && shared.train_config().split_by_shape);
        assert_eq!(shared.model_dir(work), run(true).model_dir(work));
        // With repeats the two splits differ, and so do the runs.
        let apart = run(false).with_split_of(true);
        assert!(!apart.by_shape);
        assert_ne!(apart.model_dir(work), run(true).model_dir(work));
        assert!(run(true).with_split_of(true).by_shape);
    }

    #[test]
    fn columns_are_unique_and_build_valid_models() {
        let mut ids: Vec<&str> = COLUMNS.iter().map(|c| c.id).collect();
        ids.sort_unstable();
        ids.dedup();
        assert_eq!(ids.len(), COLUMNS.len());
        assert_eq!(COLUMNS.iter().filter(|c| c.is_ours()).count(), 1);
        for c in COLUMNS {
            let model = c.model().unwrap();
            model.validate().unwrap();
            assert_eq!(model.net, c.net);
            if c.net.is_ours() {
                assert_eq!(model.structure.to_string(), c.structure);
            }
        }
        // The other networks train at their authors' rate with their loss.
        let coma = runs(
            &[dataset("horse-gallop").unwrap()],
            &[column("coma").unwrap()],
            &PROTOCOLS[0],
            Budget::CONVERGED,
            &[1],
            false,
        )[0];
        let train = coma.train_config();
        assert_eq!((train.lr, train.loss.kl), (1e-3, 0.0));
        assert_eq!(coma.column.model().unwrap().latent, 8);
        // Every column of the paper's ablation is run, in the paper's order.
        let covered: Vec<AblationColumn> = COLUMNS.iter().filter_map(|c| c.paper).collect();
        assert_eq!(covered, AblationColumn::ALL);
    }

    #[test]
    fn runs_and_their_folders() {
        let horse = dataset("horse-gallop").unwrap();
        let synth = dataset("synthetic").unwrap();
        let protocol = &PROTOCOLS[0];
        let all: Vec<&Column> = COLUMNS.iter().collect();
        let runs = runs(
            &[synth, horse],
            &all,
            protocol,
            Budget::Epochs(20),
            &[1, 2],
            true,
        );
        assert_eq!(runs.len(), 2 * 2 * COLUMNS.len());
        assert_eq!(runs[0].dataset.name, "synthetic");
        assert_eq!(runs.last().unwrap().seed, 2);
        let r = runs[COLUMNS.len()];
        assert_eq!(r.seed, 2);
        let work = Path::new("/w");
        assert_eq!(
            r.model_dir(work),
            Path::new("/w/synthetic/validation/e20/seed2/spatial")
        );
        assert_eq!(
            r.result_path(work),
            Path::new("/w/synthetic/validation/e20/seed2/spatial.result.json")
        );
        let train = r.train_config();
        assert_eq!((train.epochs, train.seed, train.val_fraction), (20, 2, 0.1));
        assert!(train.split_by_shape);
        let by_mesh = Run {
            by_shape: false,
            ..r
        };
        assert!(!by_mesh.train_config().split_by_shape);
        assert_eq!(
            by_mesh.model_dir(work),
            Path::new("/w/synthetic/validation/e20-by-mesh/seed2/spatial")
        );
        assert!(dataset("swing").is_none() && super::protocol("nope").is_none());
        let authors = super::protocol("select-on-test").unwrap();
        let mut t = TrainConfig::default();
        (authors.configure)(&mut t);
        assert_eq!(t.val_fraction, 0.0);
    }

    #[test]
    fn the_epoch_plan_trains_at_a_constant_rate_and_the_converged_plan_as_meshvae_train() {
        let synth = dataset("synthetic").unwrap();
        let work = Path::new("/w");
        let spatial = [column("spatial").unwrap()];
        let fixed = runs(
            &[synth],
            &spatial,
            &PROTOCOLS[0],
            Budget::Epochs(600),
            &[3],
            true,
        )[0];
        let train = fixed.train_config();
        assert_eq!((train.epochs, train.steps, train.lr), (600, None, 1e-3));
        assert_eq!(train.schedule, meshvae::Schedule::constant());
        assert_eq!(train.normalize_quantile, 0.0);
        assert_eq!(fixed.budget.epochs(), Some(600));

        let converged = Run {
            budget: Budget::CONVERGED,
            ..fixed
        };
        assert_eq!(converged.budget.dir_name(), "converged");
        assert_eq!(
            converged.model_dir(work),
            Path::new("/w/synthetic/validation/converged/seed3/spatial")
        );
        assert_eq!(
            converged.result_path(work),
            Path::new("/w/synthetic/validation/converged/seed3/spatial.result.json")
        );
        let by_mesh = Run {
            by_shape: false,
            ..converged
        };
        assert_eq!(
            by_mesh.model_dir(work),
            Path::new("/w/synthetic/validation/converged-by-mesh/seed3/spatial")
        );
        // `meshvae train`'s default training: its rate and schedule, its step budget; the
        // seed, split and protocol as in the epoch plan.
        let train = converged.train_config();
        let default = TrainConfig::default();
        assert_eq!(train.steps, Some(DEFAULT_MAX_STEPS));
        assert_eq!(train.schedule, meshvae::Schedule::default());
        assert!(train.schedule.stops_early());
        assert_eq!(train.lr, default.lr);
        assert_eq!((train.seed, train.val_fraction), (3, 0.1));
        assert!(train.split_by_shape && !by_mesh.train_config().split_by_shape);
        train.validate().unwrap();
        assert_eq!(converged.budget.epochs(), None);
        assert_eq!(converged.budget.max_steps(), Some(DEFAULT_MAX_STEPS));
        // Another step budget (`--quick`) has a folder of its own.
        let short = Budget::Converged { max_steps: 4 };
        assert_eq!(short.dir_name(), "converged-s4");
        let quick = Run {
            budget: short,
            ..converged
        };
        assert_eq!(quick.train_config().steps, Some(4));
    }
}
