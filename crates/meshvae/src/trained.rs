//! [`TrainedModel`]: a model folder loaded for use, the network with its best weights and
//! everything around it (hierarchy, normalisation, split, template). The applications (`apps/`)
//! work on it. The folder's layout and the files a run writes are in `train/folder.rs`.

use crate::candle::model::MeshVae;
use crate::error::{Result, VaeError};
use crate::executor::{
    Batch, CandleExecutor, EngineExecutor, Executor, ExecutorChoice, ExecutorKind,
};
use crate::net::network::Input;
use crate::train::folder::{ModelFolder, ModelSpec, SplitFile};
use crate::train::scaling::InputScaling;
use crate::train::split::{Selection, Split};
use candle_core::Device;
use candle_core::Tensor;
use mesh_hierarchy::Hierarchy;
use mesh_io::TriMesh;
use std::path::Path;
use std::sync::Mutex;

/// A model folder loaded for use: the network with its best weights and everything around it.
#[derive(Debug)]
pub struct TrainedModel {
    pub folder: ModelFolder,
    pub spec: ModelSpec,
    pub model: MeshVae,
    pub hierarchy: Hierarchy,
    /// How the network's inputs are scaled (features into ±0.95, or positions standardised).
    pub normalization: InputScaling,
    pub split: Split,
    pub template: TriMesh,
    /// Which loss chose the loaded weights.
    pub selected_on: Selection,
    /// The CPU engine that encodes and decodes for the applications, built on first use where
    /// it covers the model (see [`TrainedModel::reconstruct_batch`]).
    engine: Mutex<Option<EngineExecutor>>,
}

impl TrainedModel {
    /// Loads `dir` with its best weights (chosen on the validation meshes, or as recorded in
    /// its split file), or the last checkpoint's if no best was saved yet.
    pub fn load(dir: &Path, device: &Device) -> Result<Self> {
        Self::load_selected(dir, device, false)
    }

    /// As [`Self::load`]; with `select_on_test`, the weights with the lowest test loss instead
    /// (the authors' protocol, for comparison only: those errors are not on unseen data).
    ///
    /// Errors: `select_on_test` and a model without such weights (no test meshes, or trained
    /// before they were kept).
    pub fn load_selected(dir: &Path, device: &Device, select_on_test: bool) -> Result<Self> {
        let folder = ModelFolder::new(dir);
        let spec = folder.read_spec()?;
        spec.check_labels(dir)?;
        let hierarchy = Hierarchy::load(&folder.hierarchy())?;
        let normalization: InputScaling = folder.read_json(&folder.normalization())?;
        let positions = spec.model.net.input() == Input::Positions;
        normalization
            .validate(spec.vertices, positions)
            .map_err(|e| VaeError::model(folder.normalization(), e.to_string()))?;
        let split_file: SplitFile = folder.read_json(&folder.split())?;
        let split = split_file.split();
        split
            .check(spec.names.len())
            .map_err(|e| VaeError::model(folder.split(), e.to_string()))?;
        let template = mesh_io::read_mesh(&folder.template())?.value;
        if template.vertex_count() != spec.vertices
            || hierarchy.levels[0].vertex_count != spec.vertices
        {
            return Err(VaeError::model(
                dir,
                "template, hierarchy and config disagree on the vertex count",
            ));
        }
        let mut model = MeshVae::new(&spec.model, &hierarchy, device, spec.train.seed)?;
        let weights = folder.weights();
        let mut selected_on = split_file.selected_on;
        if select_on_test && selected_on != Selection::Test {
            let on_test = folder.weights_selected_on_test();
            let status = crate::train::read_status(&folder)?;
            let chosen_epoch = status.as_ref().and_then(|s| s.best_test_epoch);
            if !on_test.is_file() {
                let chosen = (status.as_ref())
                    .and_then(|s| s.best_test_epoch.zip(s.best_test_loss))
                    .map_or(String::new(), |(epoch, loss)| {
                        format!(" (the test loss chose epoch {epoch}, loss {loss:.4})")
                    });
                return Err(VaeError::model(
                    dir,
                    format!(
                        "no weights selected on the test meshes{chosen}: they are kept only when \
                         training is asked to (meshvae train --keep-selected-on-test), and \
                         exist only for a model with test meshes"
                    ),
                ));
            }
            let epoch = model.load_epoch(&on_test)?;
            if let (Some(held), Some(chosen)) = (epoch, chosen_epoch)
                && held != chosen
            {
                return Err(VaeError::model(
                    &on_test,
                    format!(
                        "holds the weights of epoch {held}, but the test loss chose epoch \
                         {chosen} (run.json): stale"
                    ),
                ));
            }
            selected_on = Selection::Test;
        } else if weights.is_file() {
            model.load(&weights)?;
        } else {
            crate::train::checkpoint::Checkpoint::load_model_only(
                &folder.checkpoint(),
                &mut model,
            )?;
        }
        Ok(Self {
            folder,
            spec,
            model,
            hierarchy,
            normalization,
            split,
            template,
            selected_on,
            engine: Mutex::new(None),
        })
    }
}

impl TrainedModel {
    /// A conditional model's label of each mesh of its set (`spec.names` order).
    pub fn mesh_labels(&self) -> Option<&[String]> {
        self.spec.labels.as_deref()
    }

    /// What encodes and decodes for the applications ([`Self::reconstruct_batch`],
    /// [`Self::encode_mu`], [`Self::decode_batch`]): the CPU engine where it covers the model,
    /// else candle's model, with the reason (the CLI prints it).
    pub fn inference_executor(&self) -> ExecutorChoice {
        ExecutorChoice::choose(&self.model, true)
    }

    /// The one-hot labels `[B, L]` of the meshes `ids` of the model's set for a conditional
    /// model, `None` for an unconditional one: what `MeshVae::encode` and friends take.
    ///
    /// Errors: an index out of range.
    pub fn conditions(&self, ids: &[usize]) -> Result<Option<candle_core::Tensor>> {
        let Some(labels) = self.mesh_labels() else {
            return Ok(None);
        };
        let picked = crate::candle::model::pick_labels(labels, ids)?;
        Ok(Some(self.model.one_hot(&picked)?))
    }

    /// Epochs trained so far and the epoch whose weights are loaded, from `log.jsonl`.
    pub fn epochs_trained(&self) -> Result<(usize, usize)> {
        let path = self.folder.log();
        if !path.is_file() {
            return Ok((0, 0));
        }
        let log = crate::train::read_log(&path)?;
        let last = log.last().map_or(0, |r| r.epoch);
        let best = log
            .iter()
            .min_by(|a, b| {
                a.score(self.selected_on)
                    .total_cmp(&b.score(self.selected_on))
            })
            .map_or(0, |r| r.epoch);
        Ok((last, best))
    }
}

/// Inference for the applications: on the CPU engine where it covers the model (the same
/// results as candle's eval mode to rounding, without candle's per-op allocations), else
/// through candle's model.
impl TrainedModel {
    /// decode(μ(x, c), c) for features x `[B, V, 9]` (labels c `[B, L]` for a conditional
    /// model).
    pub fn reconstruct_batch(&self, x: &Tensor, c: Option<&Tensor>) -> Result<Tensor> {
        self.with_executor(x.dim(0)?, |e, m| e.reconstruct(m, Batch { x, c }))
    }

    /// The encoder means μ `[B, latent]` of features x `[B, V, 9]`.
    pub fn encode_mu(&self, x: &Tensor, c: Option<&Tensor>) -> Result<Tensor> {
        self.with_executor(x.dim(0)?, |e, m| e.encode(m, Batch { x, c }))
            .map(|(mu, _)| mu)
    }

    /// x̂ `[B, V, 9]` from latent vectors z `[B, latent]`.
    pub fn decode_batch(&self, z: &Tensor, c: Option<&Tensor>) -> Result<Tensor> {
        self.with_executor(z.dim(0)?, |e, m| e.decode(m, Batch { x: z, c }))
    }

    /// Runs `f` on the inference executor: the engine (built on first use, rebuilt for a
    /// larger batch) where it covers the model, candle's model otherwise.
    fn with_executor<R>(
        &self,
        batch: usize,
        f: impl FnOnce(&mut dyn Executor, &MeshVae) -> Result<R>,
    ) -> Result<R> {
        if self.inference_executor().kind != ExecutorKind::Engine {
            return f(&mut CandleExecutor, &self.model);
        }
        let mut slot = self.engine.lock().unwrap_or_else(|p| p.into_inner());
        if slot.as_ref().is_none_or(|e| e.max_batch() < batch) {
            *slot = Some(EngineExecutor::new(&self.model, batch.max(1))?);
        }
        match slot.as_mut() {
            Some(engine) => f(engine, &self.model),
            None => f(&mut CandleExecutor, &self.model),
        }
    }
}
