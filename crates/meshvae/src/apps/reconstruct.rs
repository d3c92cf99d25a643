//! Using a trained model on meshes: reconstruct them through the network (encoder mean →
//! decoder → de-normalised features → positions by the ACAP Poisson solve) and measure the
//! error of unseen shapes.

use crate::apps::eval::{ErrorReport, error_report, mean_shape};
use crate::error::{Result, VaeError};
use crate::net::params::ParamCount;
use crate::train::data::denormalize;
use crate::train::scaling::InputScaling;
use crate::trained::TrainedModel;
use candle_core::{Device, Tensor};
use deform_features::{CHANNELS, FeatureExtractor, FeatureSet, Reconstructor, RestMesh};
use mesh_io::{MeshSet, Point, ShapeGroups};
use serde::{Deserialize, Serialize};

/// Meshes reconstructed per network call (bounds memory on large meshes).
const CHUNK: usize = 16;

/// Errors of a trained model on its set.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct EvalReport {
    pub test: ErrorReport,
    pub train: ErrorReport,
    /// The trivial predictor "mean training shape" on the test meshes.
    pub mean_shape: ErrorReport,
    pub params: ParamCount,
    pub epochs: usize,
    pub vertices: usize,
    /// The test error split by whether a copy of the test shape is among the training meshes
    /// (present only when some is: a split drawn mesh by mesh of a set that holds shapes twice,
    /// as horse-gallop under the authors' protocol).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub copies: Option<CopySplit>,
}

/// [`EvalReport::test`] over two parts of the test meshes: those whose shape a training mesh
/// repeats (within [`ShapeGroups::DEFAULT_TOLERANCE`]), which measure memory, and the others,
/// which measure generalisation.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CopySplit {
    pub copy_in_training: ErrorReport,
    /// `None` when every test shape has a copy in training.
    pub unseen: Option<ErrorReport>,
}

impl TrainedModel {
    /// The rest mesh the model's features are relative to.
    pub fn rest(&self) -> Result<RestMesh> {
        Ok(RestMesh::new(
            &self.template.positions,
            &self.template.faces,
        )?)
    }

    /// Checks that `set` is the model's set: same connectivity and mesh count.
    pub fn check_set(&self, set: &MeshSet) -> Result<()> {
        self.spec.check_set(set, &self.template, &self.folder.dir)?;
        if set.len() != self.spec.names.len() {
            return Err(VaeError::model(
                &self.folder.dir,
                format!(
                    "the model's split refers to {} meshes; this set has {}",
                    self.spec.names.len(),
                    set.len()
                ),
            ));
        }
        Ok(())
    }

    /// The feature extractor of this model (its rest mesh and feature options).
    pub fn extractor(&self) -> Result<FeatureExtractor> {
        Ok(FeatureExtractor::new(self.rest()?, self.spec.features)?)
    }

    /// The network's scaled inputs of the meshes `ids` of `set`: features `[B, V, 9]` (from
    /// `extractor`), or for a position network the standardised positions `[B, V, 3]`.
    pub fn encode_input(
        &self,
        extractor: &FeatureExtractor,
        set: &MeshSet,
        ids: &[usize],
        device: &Device,
    ) -> Result<Tensor> {
        let (values, channels) = match &self.normalization {
            InputScaling::Features(normalization) => {
                let raw = extractor.extract(&set.subset(ids)?)?.features;
                (normalization.apply(&raw).into_vec(), CHANNELS)
            }
            InputScaling::Positions(scaling) => {
                let mut values = Vec::with_capacity(ids.len() * set.vertex_count() * 3);
                for &i in ids {
                    if i >= set.len() {
                        return Err(VaeError::argument(
                            "mesh index",
                            format!("{i} is out of range ({} meshes)", set.len()),
                        ));
                    }
                    values.extend(scaling.apply(set.frame(i)));
                }
                (values, 3)
            }
        };
        Ok(Tensor::from_vec(
            values,
            (ids.len(), set.vertex_count(), channels),
            device,
        )?)
    }

    /// Positions from network outputs in scaled units `[B, V, C]`: features through
    /// `reconstructor`'s Poisson solve, or a position network's output un-standardised.
    pub fn positions_from_output(
        &self,
        reconstructor: &Reconstructor,
        output: &Tensor,
    ) -> Result<Vec<Vec<[f64; 3]>>> {
        match &self.normalization {
            InputScaling::Features(normalization) => {
                let raw: FeatureSet = denormalize(normalization, output)?;
                Ok(reconstructor.reconstruct_all(&raw)?)
            }
            InputScaling::Positions(scaling) => {
                let (b, v, c) = output.dims3()?;
                if c != 3 || v * 3 != scaling.position_mean.len() {
                    return Err(VaeError::shape(
                        "positions_from_output",
                        format!("output of shape [{b}, {v}, {c}] for a position network"),
                    ));
                }
                let flat: Vec<f32> = output.flatten_all()?.to_vec1()?;
                Ok(flat
                    .chunks_exact(v * 3)
                    .map(|m| scaling.invert(m))
                    .collect())
            }
        }
    }

    /// Reconstructions (z = μ) of the meshes `ids` of `set`.
    pub fn reconstruct(
        &self,
        set: &MeshSet,
        ids: &[usize],
        device: &Device,
    ) -> Result<Vec<Vec<[f64; 3]>>> {
        self.check_set(set)?;
        let reconstructor = Reconstructor::new(&self.rest()?)?;
        let extractor = self.extractor()?;
        let mut out = Vec::with_capacity(ids.len());
        for chunk in ids.chunks(CHUNK) {
            let x = self.encode_input(&extractor, set, chunk, device)?;
            let y = self.reconstruct_batch(&x, self.conditions(chunk)?.as_ref())?;
            out.extend(self.positions_from_output(&reconstructor, &y)?);
        }
        Ok(out)
    }

    /// Test and training errors, and the mean-shape baseline.
    pub fn evaluate(&self, set: &MeshSet, device: &Device) -> Result<EvalReport> {
        let frames =
            |ids: &[usize]| -> Vec<&[Point]> { ids.iter().map(|&i| set.frame(i)).collect() };
        let test_out = self.reconstruct(set, &self.split.test, device)?;
        let test = error_report(&frames(&self.split.test), &test_out)?;
        let copies = self.copy_split(set, &test_out)?;
        let train = error_report(
            &frames(&self.split.train),
            &self.reconstruct(set, &self.split.train, device)?,
        )?;
        let mean = mean_shape(&frames(&self.split.train));
        let mean_shape = error_report(
            &frames(&self.split.test),
            &vec![mean; self.split.test.len()],
        )?;
        Ok(EvalReport {
            test,
            train,
            mean_shape,
            params: self.model.param_count(),
            epochs: self.spec.train.epochs,
            vertices: self.spec.vertices,
            copies,
        })
    }

    /// The test error of the test meshes with and without a copy among the training meshes
    /// (`None` when no test mesh has one); `test_out` are the test meshes' reconstructions.
    fn copy_split(&self, set: &MeshSet, test_out: &[Vec<[f64; 3]>]) -> Result<Option<CopySplit>> {
        let groups = set.shape_groups(ShapeGroups::DEFAULT_TOLERANCE)?;
        let trained: std::collections::HashSet<usize> =
            self.split.train.iter().map(|&i| groups.group(i)).collect();
        let (mut seen, mut unseen) = ((vec![], vec![]), (vec![], vec![]));
        for (&i, out) in self.split.test.iter().zip(test_out) {
            let part = if trained.contains(&groups.group(i)) {
                &mut seen
            } else {
                &mut unseen
            };
            part.0.push(set.frame(i));
            part.1.push(out.clone());
        }
        if seen.0.is_empty() {
            return Ok(None);
        }
        Ok(Some(CopySplit {
            copy_in_training: error_report(&seen.0, &seen.1)?,
            unseen: if unseen.0.is_empty() {
                None
            } else {
                Some(error_report(&unseen.0, &unseen.1)?)
            },
        }))
    }
}
