//! [`MeshData`]: a mesh set turned into what the network eats — ACAP features of every mesh,
//! normalised into ±0.95 by ranges fitted on the training split only (or, for the position
//! networks, the positions standardised per vertex on the training split), and batches of them
//! as `[B, V, C]` tensors (with, for a conditional model, each mesh's one-hot label).

use crate::candle::model::MeshVae;
use crate::error::{Result, VaeError};
use crate::train::scaling::{InputScaling, PositionScaling};
use crate::train::split::Split;
use candle_core::{Device, Tensor};
use deform_features::{CHANNELS, FeatureExtractor, FeatureOptions, FeatureSet, Normalization};
use mesh_io::MeshSet;

/// Every mesh's scaled network input, f32 `[N, V, C]`.
#[derive(Debug, Clone, PartialEq)]
pub struct Inputs {
    frames: usize,
    vertices: usize,
    channels: usize,
    data: Vec<f32>,
}

impl Inputs {
    fn new(frames: usize, vertices: usize, channels: usize, data: Vec<f32>) -> Self {
        debug_assert_eq!(data.len(), frames * vertices * channels);
        Self {
            frames,
            vertices,
            channels,
            data,
        }
    }

    pub fn frames(&self) -> usize {
        self.frames
    }

    pub fn vertices(&self) -> usize {
        self.vertices
    }

    /// Values per vertex: 9 features or 3 coordinates.
    pub fn channels(&self) -> usize {
        self.channels
    }

    /// Mesh `i`'s values `[V·C]`.
    pub fn frame(&self, i: usize) -> &[f32] {
        let n = self.vertices * self.channels;
        &self.data[i * n..(i + 1) * n]
    }

    /// Every value `[N·V·C]`.
    pub fn as_slice(&self) -> &[f32] {
        &self.data
    }
}

/// Inputs of a set, their scaling, and the split it was fitted on.
#[derive(Debug, Clone)]
pub struct MeshData {
    /// Every mesh's input (features relative to the set's first mesh, the rest pose, or
    /// positions), scaled with [`Self::normalization`]. The raw features are not kept: on large
    /// meshes they would double this, the largest thing in memory besides the model.
    pub normalized: Inputs,
    /// Fitted on the training meshes only, so the test meshes stay unseen.
    pub normalization: InputScaling,
    pub split: Split,
    /// Warnings of the feature extraction (degenerate faces and the like).
    pub warnings: Vec<String>,
    /// Each mesh's label, for a conditional model (see [`Self::with_labels`]).
    pub labels: Option<Vec<String>>,
}

/// How [`MeshData::prepare_fitted`] fits the normalisation.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct NormalizationFit {
    /// On every mesh, test meshes included (the authors' code), instead of the training ones.
    pub on_all: bool,
    /// Range between the quantiles q and 1 − q, outliers clamped (0: min and max).
    pub quantile: f64,
}

impl MeshData {
    /// Features of every mesh of `set` with a normalisation fitted on `split.train`.
    pub fn prepare(set: &MeshSet, split: Split, options: FeatureOptions) -> Result<Self> {
        Self::prepare_fitted(set, split, options, NormalizationFit::default())
    }

    /// As [`Self::prepare`], with the normalisation fitted as `fit` says: on every mesh (test
    /// meshes included, as the authors' code does; the test meshes then influence the model
    /// through the feature ranges) or the training meshes, between quantiles or not.
    pub fn prepare_fitted(
        set: &MeshSet,
        split: Split,
        options: FeatureOptions,
        fit: NormalizationFit,
    ) -> Result<Self> {
        let extractor = FeatureExtractor::for_set(set, options)?;
        let features = extractor.extract(set)?;
        split.check(features.features.frames())?;
        let normalization = if fit.on_all {
            Normalization::fit_quantile([&features.features], fit.quantile)?
        } else {
            let train = features.features.subset(&split.train)?;
            Normalization::fit_quantile([&train], fit.quantile)?
        };
        Ok(Self::with_normalization(
            features.features,
            split,
            normalization,
            features.warnings,
        ))
    }

    /// The positions of every mesh of `set`, standardised per vertex and coordinate on
    /// `split.train` (the position networks' input).
    pub fn prepare_positions(set: &MeshSet, split: Split) -> Result<Self> {
        split.check(set.len())?;
        let scaling = PositionScaling::fit(set, &split.train)?;
        Ok(Self::with_position_scaling(set, split, scaling))
    }

    /// The positions of `set` with a given scaling (a saved model's).
    pub fn with_position_scaling(set: &MeshSet, split: Split, scaling: PositionScaling) -> Self {
        let data: Vec<f32> = set.frames().flat_map(|f| scaling.apply(f)).collect();
        Self {
            normalized: Inputs::new(set.len(), set.vertex_count(), 3, data),
            normalization: InputScaling::Positions(scaling),
            split,
            warnings: Vec::new(),
            labels: None,
        }
    }

    /// As [`Self::prepare`] from features already computed.
    pub fn from_features(raw: FeatureSet, split: Split, warnings: Vec<String>) -> Result<Self> {
        split.check(raw.frames())?;
        let normalization = Normalization::fit([&raw.subset(&split.train)?])?;
        Ok(Self::with_normalization(
            raw,
            split,
            normalization,
            warnings,
        ))
    }

    /// With a given normalisation (a saved model's).
    pub fn with_normalization(
        raw: FeatureSet,
        split: Split,
        normalization: Normalization,
        warnings: Vec<String>,
    ) -> Self {
        let normalized = normalization.apply(&raw);
        drop(raw);
        let (frames, vertices) = (normalized.frames(), normalized.vertices());
        Self {
            normalized: Inputs::new(frames, vertices, CHANNELS, normalized.into_vec()),
            normalization: InputScaling::Features(normalization),
            split,
            warnings,
            labels: None,
        }
    }

    /// Attaches one label per mesh (a conditional model's input).
    ///
    /// Errors: not one label per mesh.
    pub fn with_labels(mut self, labels: Vec<String>) -> Result<Self> {
        if labels.len() != self.len() {
            return Err(VaeError::argument(
                "labels",
                format!("{} labels for {} meshes", labels.len(), self.len()),
            ));
        }
        self.labels = Some(labels);
        Ok(self)
    }

    /// The one-hot labels `[B, L]` of the meshes `indices` if `model` is conditional, `None`
    /// otherwise (the batch that goes with [`Self::batch`]).
    ///
    /// Errors: a conditional model and meshes without labels, an index out of range, a label
    /// the model does not know.
    pub fn conditions(&self, model: &MeshVae, indices: &[usize]) -> Result<Option<Tensor>> {
        if !model.is_conditional() {
            return Ok(None);
        }
        let labels = self.labels.as_ref().ok_or_else(|| {
            VaeError::argument(
                "labels",
                "the model is conditional but the meshes have no labels",
            )
        })?;
        let picked = crate::candle::model::pick_labels(labels, indices)?;
        Ok(Some(model.one_hot(&picked)?))
    }

    pub fn len(&self) -> usize {
        self.normalized.frames()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    pub fn vertex_count(&self) -> usize {
        self.normalized.vertices()
    }

    /// Scaled inputs of the meshes `indices` as an f32 tensor `[B, V, C]`.
    pub fn batch(&self, indices: &[usize], device: &Device) -> Result<Tensor> {
        let channels = self.normalized.channels();
        let per_mesh = self.vertex_count() * channels;
        let mut data = Vec::with_capacity(indices.len() * per_mesh);
        for &i in indices {
            if i >= self.len() {
                return Err(VaeError::argument(
                    "mesh index",
                    format!("{i} is out of range ({} meshes)", self.len()),
                ));
            }
            data.extend_from_slice(self.normalized.frame(i));
        }
        Ok(Tensor::from_vec(
            data,
            (indices.len(), self.vertex_count(), channels),
            device,
        )?)
    }
}

/// Raw (de-normalised) features from a network output `[B, V, 9]` in normalised units.
pub fn denormalize(normalization: &Normalization, output: &Tensor) -> Result<FeatureSet> {
    let (b, v, c) = output.dims3()?;
    if c != CHANNELS {
        return Err(VaeError::shape(
            "denormalize",
            format!("output has {c} channels, expected {CHANNELS}"),
        ));
    }
    let flat: Vec<f32> = output.flatten_all()?.to_vec1()?;
    Ok(normalization.invert(&FeatureSet::new(b, v, flat)?))
}

#[cfg(test)]
mod tests {
    use super::*;
    use mesh_io::synth::{SynthConfig, generate};

    #[test]
    fn normalisation_sees_only_the_training_meshes() {
        let set = generate(&SynthConfig {
            meshes_per_label: 4,
            ..SynthConfig::default()
        })
        .unwrap()
        .set;
        let split = Split::random(set.len(), 0.5, 3).unwrap();
        let raw = FeatureExtractor::for_set(&set, FeatureOptions::default())
            .unwrap()
            .extract(&set)
            .unwrap()
            .features;
        let data = MeshData::prepare(&set, split.clone(), FeatureOptions::default()).unwrap();
        let extreme = (split.train.iter())
            .flat_map(|&i| data.normalized.frame(i))
            .fold(0f32, |m, x| m.max(x.abs()));
        assert!(
            (extreme - 0.95).abs() < 1e-3,
            "train range reaches ±0.95: {extreme}"
        );
        let on_train = Normalization::fit([&raw.subset(&split.train).unwrap()]).unwrap();
        let on_test = Normalization::fit([&raw.subset(&split.test).unwrap()]).unwrap();
        let fitted = |d: &MeshData| match &d.normalization {
            InputScaling::Features(n) => *n,
            InputScaling::Positions(_) => panic!("features expected"),
        };
        assert_eq!(fitted(&data), on_train);
        assert_ne!(fitted(&data), on_test);

        let x = data.batch(&[1, 0], &Device::Cpu).unwrap();
        assert_eq!(x.dims(), &[2, set.vertex_count(), CHANNELS]);
        let back = denormalize(&on_train, &x).unwrap();
        for (a, b) in back.frame(0).iter().zip(raw.frame(1)) {
            assert!((a - b).abs() < 1e-4, "{a} vs {b}");
        }
        assert!(data.batch(&[99], &Device::Cpu).is_err());

        // The authors' choice, on request: fitted on every mesh, so the whole set reaches ±0.95.
        let on_all = NormalizationFit {
            on_all: true,
            quantile: 0.0,
        };
        let all = MeshData::prepare_fitted(&set, split.clone(), FeatureOptions::default(), on_all)
            .unwrap();
        assert_eq!(fitted(&all), Normalization::fit([&raw]).unwrap());
        assert_ne!(fitted(&all), on_train);
        let extreme = all
            .normalized
            .as_slice()
            .iter()
            .fold(0f32, |m, x| m.max(x.abs()));
        assert!((extreme - 0.95).abs() < 1e-3, "{extreme}");
        // Between quantiles, on the training meshes: outliers clamped to ±1.
        let robust = NormalizationFit {
            on_all: false,
            quantile: 0.01,
        };
        let q = MeshData::prepare_fitted(&set, split.clone(), FeatureOptions::default(), robust)
            .unwrap();
        let train_raw = raw.subset(&split.train).unwrap();
        assert_eq!(
            fitted(&q),
            Normalization::fit_quantile([&train_raw], 0.01).unwrap()
        );
        let extreme = q
            .normalized
            .as_slice()
            .iter()
            .fold(0f32, |m, x| m.max(x.abs()));
        assert_eq!(extreme, 1.0);

        // The position networks' input: 3 standardised coordinates per vertex.
        let pos = MeshData::prepare_positions(&set, split.clone()).unwrap();
        let x = pos.batch(&[2], &Device::Cpu).unwrap();
        assert_eq!(x.dims(), &[1, set.vertex_count(), 3]);
        let InputScaling::Positions(scaling) = &pos.normalization else {
            panic!("positions expected");
        };
        let back = scaling.invert(pos.normalized.frame(2));
        assert!((back[7][1] - f64::from(set.frame(2)[7][1])).abs() < 1e-5);
    }
}
