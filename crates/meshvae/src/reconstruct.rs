//! Using a trained model on meshes: reconstruct them through the network (encoder mean →
//! decoder → de-normalised features → positions by the ACAP Poisson solve) and measure the
//! error of unseen shapes.

use crate::data::denormalize;
use crate::error::{Result, VaeError};
use crate::eval::{ErrorReport, error_report, mean_shape};
use crate::folder::TrainedModel;
use crate::params::ParamCount;
use candle_core::{Device, Tensor};
use deform_features::{CHANNELS, FeatureExtractor, FeatureSet, Reconstructor, RestMesh};
use mesh_io::{MeshSet, Point};
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

    /// Normalised features of the meshes `ids` of `set` as `[B, V, 9]`.
    pub fn encode_input(
        &self,
        extractor: &FeatureExtractor,
        set: &MeshSet,
        ids: &[usize],
        device: &Device,
    ) -> Result<Tensor> {
        let subset = set.subset(ids)?;
        let raw = extractor.extract(&subset)?.features;
        let normalized = self.normalization.apply(&raw);
        Ok(Tensor::from_vec(
            normalized.into_vec(),
            (ids.len(), set.vertex_count(), CHANNELS),
            device,
        )?)
    }

    /// Positions from network outputs in normalised units `[B, V, 9]`.
    pub fn positions_from_output(
        &self,
        reconstructor: &Reconstructor,
        output: &Tensor,
    ) -> Result<Vec<Vec<[f64; 3]>>> {
        let raw: FeatureSet = denormalize(&self.normalization, output)?;
        Ok(reconstructor.reconstruct_all(&raw)?)
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
            let y = self
                .model
                .reconstruct_cond(&x, self.conditions(chunk)?.as_ref())?;
            out.extend(self.positions_from_output(&reconstructor, &y)?);
        }
        Ok(out)
    }

    /// Test and training errors, and the mean-shape baseline.
    pub fn evaluate(&self, set: &MeshSet, device: &Device) -> Result<EvalReport> {
        let frames =
            |ids: &[usize]| -> Vec<&[Point]> { ids.iter().map(|&i| set.frame(i)).collect() };
        let test = error_report(
            &frames(&self.split.test),
            &self.reconstruct(set, &self.split.test, device)?,
        )?;
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
        })
    }
}
