//! Random generation (the paper's §4.4): latent vectors z ~ N(0, I) decoded into meshes, each
//! with its nearest training mesh by average per-vertex Euclidean distance — the paper's check
//! that the generated shapes are new rather than copies of the training set.
//!
//! A conditional model decodes z ~ N(0, I) with the one-hot label the user asks for
//! ([`TrainedModel::generate_labelled`]); each sample's nearest training mesh then tells, by its
//! label, whether the sample looks like the meshes of that label ([`Generated::label_share`]).

use crate::error::{Result, VaeError};
use crate::numerics::rng::Rng;
use crate::trained::TrainedModel;
use candle_core::Tensor;
use deform_features::Reconstructor;
use mesh_io::{MeshSet, Point};
use rayon::prelude::*;

/// Latent vectors decoded per network call (bounds memory on large meshes).
const CHUNK: usize = 16;

/// What to generate (a conditional model's label is an argument of
/// [`TrainedModel::generate_labelled`]).
#[derive(Debug, Clone, PartialEq)]
pub struct GenerateOptions {
    /// Number of samples (at least 1).
    pub count: usize,
    /// Seeds the latent draws: the same seed gives the same meshes, and sample i does not
    /// depend on `count`.
    pub seed: u64,
}

impl Default for GenerateOptions {
    fn default() -> Self {
        Self { count: 20, seed: 1 }
    }
}

/// A mesh of the set nearest to a given shape.
#[derive(Debug, Clone, PartialEq)]
pub struct Neighbour {
    /// Index in the set (and in the model's `spec.names`).
    pub index: usize,
    pub name: String,
    /// Mean per-vertex Euclidean distance after aligning centroids, in mesh units.
    pub distance: f64,
    /// `distance` divided by the bounding-box diagonal of the model's template.
    pub distance_rel: f64,
    /// Its label: a conditional model's label of that mesh, else the set's, if labelled.
    pub label: Option<String>,
}

/// Generated meshes with their latent vectors and nearest training meshes.
#[derive(Debug, Clone)]
pub struct Generated {
    /// `latents[i]`: the z of sample i (`latent` values).
    pub latents: Vec<Vec<f32>>,
    /// `positions[i]`: the decoded mesh i on the template's connectivity.
    pub positions: Vec<Vec<[f64; 3]>>,
    /// `nearest[i]`: the training mesh nearest to sample i.
    pub nearest: Vec<Neighbour>,
    /// The label every sample was decoded with (conditional models).
    pub label: Option<String>,
}

impl Generated {
    /// The share of samples whose nearest training mesh carries the requested label (`None`
    /// without a label).
    pub fn label_share(&self) -> Option<f64> {
        let label = self.label.as_ref()?;
        let hits = self
            .nearest
            .iter()
            .filter(|n| n.label.as_ref() == Some(label))
            .count();
        Some(hits as f64 / self.nearest.len().max(1) as f64)
    }
}

impl TrainedModel {
    /// Meshes decoded (inference mode) from latent vectors, each of the model's latent size,
    /// with, for a conditional model, one label vector per latent vector (`conditions[i]` has
    /// one weight per model label: a one-hot row as `MeshVae::one_hot` makes, or a blend of two
    /// for an interpolation).
    ///
    /// Errors: a vector of the wrong length or with non-finite values; conditions missing for a
    /// conditional model, given to an unconditional one, or not one row of the label count per
    /// latent vector.
    pub fn decode_latents(
        &self,
        latents: &[Vec<f32>],
        conditions: Option<&[Vec<f32>]>,
    ) -> Result<Vec<Vec<[f64; 3]>>> {
        let labels = self.model.labels().len();
        if let Some(c) = conditions
            && (c.len() != latents.len() || c.iter().any(|row| row.len() != labels))
        {
            return Err(VaeError::argument(
                "label vectors",
                format!(
                    "{} rows for {} latent vectors; each needs {labels} values (one per \
                         model label)",
                    c.len(),
                    latents.len()
                ),
            ));
        }
        let width = self.model.latent();
        for (i, z) in latents.iter().enumerate() {
            if z.len() != width {
                return Err(VaeError::argument(
                    "latent vector",
                    format!(
                        "vector {i} has {} values; the model's latent size is {width}",
                        z.len()
                    ),
                ));
            }
            if z.iter().any(|x| !x.is_finite()) {
                return Err(VaeError::argument(
                    "latent vector",
                    format!("vector {i} is not finite"),
                ));
            }
        }
        let reconstructor = Reconstructor::new(&self.rest()?)?;
        let mut out = Vec::with_capacity(latents.len());
        for (k, chunk) in latents.chunks(CHUNK).enumerate() {
            let matrix = |rows: &[Vec<f32>], width: usize| -> Result<Tensor> {
                let flat: Vec<f32> = rows.iter().flatten().copied().collect();
                Ok(
                    Tensor::from_vec(flat, (rows.len(), width), self.model.device())?
                        .to_dtype(self.model.dtype())?,
                )
            };
            let z = matrix(chunk, width)?;
            let c = conditions
                .map(|c| matrix(&c[k * CHUNK..k * CHUNK + chunk.len()], labels))
                .transpose()?;
            let y = self.decode_batch(&z, c.as_ref())?;
            out.extend(self.positions_from_output(&reconstructor, &y)?);
        }
        Ok(out)
    }

    /// For each shape, the mesh among `candidates` (indices into `set`) with the smallest mean
    /// per-vertex distance after centroid alignment.
    ///
    /// Errors: no candidates, an index out of range, a shape with the wrong vertex count.
    pub fn nearest_meshes(
        &self,
        set: &MeshSet,
        candidates: &[usize],
        shapes: &[Vec<[f64; 3]>],
    ) -> Result<Vec<Neighbour>> {
        if candidates.is_empty() {
            return Err(VaeError::argument(
                "candidate meshes",
                "none to compare with",
            ));
        }
        if let Some(&i) = candidates.iter().find(|&&i| i >= set.len()) {
            return Err(VaeError::argument(
                "candidate meshes",
                format!(
                    "index {i} is out of range (the set has {} meshes)",
                    set.len()
                ),
            ));
        }
        if let Some(i) = shapes.iter().position(|s| s.len() != set.vertex_count()) {
            return Err(VaeError::shape(
                "nearest_meshes",
                format!(
                    "shape {i} has {} vertices, the set {}",
                    shapes[i].len(),
                    set.vertex_count()
                ),
            ));
        }
        let diagonal = self.template.bbox_diagonal();
        let labels = self.mesh_labels().or(set.labels());
        let centred: Vec<Vec<[f64; 3]>> = candidates
            .par_iter()
            .map(|&i| centre(set.frame(i).iter().map(|p: &Point| p.map(f64::from))))
            .collect();
        Ok(shapes
            .par_iter()
            .map(|shape| {
                let s = centre(shape.iter().copied());
                let (best, distance) = centred
                    .iter()
                    .enumerate()
                    .map(|(k, c)| (k, mean_distance(&s, c)))
                    .min_by(|a, b| a.1.total_cmp(&b.1))
                    .unwrap_or((0, f64::INFINITY));
                let index = candidates[best];
                Neighbour {
                    index,
                    name: set.names()[index].clone(),
                    distance,
                    distance_rel: if diagonal > 0.0 {
                        distance / diagonal
                    } else {
                        0.0
                    },
                    label: labels.map(|l| l[index].clone()),
                }
            })
            .collect())
    }
}

/// The points moved so that their centroid is the origin.
pub(crate) fn centre(points: impl Iterator<Item = [f64; 3]>) -> Vec<[f64; 3]> {
    let pts: Vec<[f64; 3]> = points.collect();
    let n = pts.len().max(1) as f64;
    let c = pts
        .iter()
        .fold([0.0; 3], |c, p| [c[0] + p[0], c[1] + p[1], c[2] + p[2]])
        .map(|x| x / n);
    pts.into_iter()
        .map(|p| [p[0] - c[0], p[1] - c[1], p[2] - c[2]])
        .collect()
}

/// Mean Euclidean distance between corresponding points.
pub(crate) fn mean_distance(a: &[[f64; 3]], b: &[[f64; 3]]) -> f64 {
    let sum: f64 = a
        .iter()
        .zip(b)
        .map(|(p, q)| {
            ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt()
        })
        .sum();
    sum / a.len().max(1) as f64
}

/// `options.count` meshes from z ~ N(0, I) (drawn from [`Rng`] with `options.seed`, row by
/// row), each with its nearest mesh among the model's training meshes of `set`.
///
/// Errors: `count` = 0, a set that is not the model's (connectivity or mesh count), a
/// conditional model (it needs [`TrainedModel::generate_labelled`]).
pub fn generate(
    model: &TrainedModel,
    set: &MeshSet,
    options: &GenerateOptions,
) -> Result<Generated> {
    model.generate_labelled(set, options, None)
}

impl TrainedModel {
    /// For a conditional model, the label vectors from mesh `a`'s one-hot label to mesh `b`'s,
    /// (1 − t)·c_a + t·c_b for each t (what an interpolation decodes with); `None` for an
    /// unconditional model.
    ///
    /// Errors: an index out of range.
    pub fn conditions_between(
        &self,
        a: usize,
        b: usize,
        t: &[f64],
    ) -> Result<Option<Vec<Vec<f32>>>> {
        let Some(ends) = self.conditions(&[a, b])? else {
            return Ok(None);
        };
        let ends: Vec<Vec<f32>> = ends.to_dtype(candle_core::DType::F32)?.to_vec2()?;
        Ok(Some(
            t.iter()
                .map(|&t| {
                    ends[0]
                        .iter()
                        .zip(&ends[1])
                        .map(|(&x, &y)| ((1.0 - t) * f64::from(x) + t * f64::from(y)) as f32)
                        .collect()
                })
                .collect(),
        ))
    }

    /// As [`generate`], every sample decoded with the one-hot `label` for a conditional model
    /// (the same seed draws the same z whatever the label).
    ///
    /// Errors: as [`generate`]; no label for a conditional model, a label for an unconditional
    /// one, a label the model does not know (the error lists the known ones).
    pub fn generate_labelled(
        &self,
        set: &MeshSet,
        options: &GenerateOptions,
        label: Option<&str>,
    ) -> Result<Generated> {
        generate_impl(self, set, options, label)
    }
}

fn generate_impl(
    model: &TrainedModel,
    set: &MeshSet,
    options: &GenerateOptions,
    label: Option<&str>,
) -> Result<Generated> {
    let condition = match label {
        Some(label) => {
            let classes = model.model.labels();
            let k = classes
                .iter()
                .position(|c| c == label)
                .ok_or_else(|| crate::candle::model::unknown_label(classes, label))?;
            let mut row = vec![0f32; classes.len()];
            row[k] = crate::candle::model::LABEL_SCALE;
            Some(row)
        }
        None if model.model.is_conditional() => {
            return Err(VaeError::argument(
                "label",
                format!(
                    "the model is conditional: give one of its labels ({})",
                    model.model.labels().join(", ")
                ),
            ));
        }
        None => None,
    };
    if options.count == 0 {
        return Err(VaeError::argument(
            "number of samples",
            "must be at least 1",
        ));
    }
    model.check_set(set)?;
    let mut rng = Rng::new(options.seed);
    let latents: Vec<Vec<f32>> = (0..options.count)
        .map(|_| {
            (0..model.model.latent())
                .map(|_| rng.normal() as f32)
                .collect()
        })
        .collect();
    let conditions = condition.map(|row| vec![row; latents.len()]);
    let positions = model.decode_latents(&latents, conditions.as_deref())?;
    let nearest = model.nearest_meshes(set, &model.split.train, &positions)?;
    Ok(Generated {
        latents,
        positions,
        nearest,
        label: label.map(String::from),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::apps::fixture;

    #[test]
    fn samples_have_the_template_connectivity_and_valid_neighbours() {
        let (model, set) = fixture::trained();
        let options = GenerateOptions { count: 5, seed: 3 };
        let g = generate(model, set, &options).unwrap();
        assert_eq!(g.positions.len(), 5);
        assert_eq!(g.latents.len(), 5);
        for (p, z) in g.positions.iter().zip(&g.latents) {
            assert_eq!(p.len(), set.vertex_count());
            assert!(p.iter().flatten().all(|x| x.is_finite()));
            assert_eq!(z.len(), 16);
        }
        // The samples differ from each other (distinct z decode to distinct shapes).
        assert!(mean_distance(&g.positions[0], &g.positions[1]) > 0.0);
        for (shape, nb) in g.positions.iter().zip(&g.nearest) {
            assert!(model.split.train.contains(&nb.index), "{nb:?}");
            assert_eq!(nb.name, set.names()[nb.index]);
            // Brute force over the training meshes.
            let s = centre(shape.iter().copied());
            let dists: Vec<f64> = model
                .split
                .train
                .iter()
                .map(|&i| mean_distance(&s, &centre(set.frame(i).iter().map(|p| p.map(f64::from)))))
                .collect();
            let best = dists.iter().copied().fold(f64::INFINITY, f64::min);
            assert!((nb.distance - best).abs() < 1e-12 * (1.0 + best));
            let diag = model.template.bbox_diagonal();
            assert!((nb.distance_rel - best / diag).abs() < 1e-12);
        }
        // Deterministic; a longer run starts with the same samples; another seed differs.
        let again = generate(model, set, &options).unwrap();
        assert_eq!(g.positions, again.positions);
        let more = generate(model, set, &GenerateOptions { count: 7, seed: 3 }).unwrap();
        assert_eq!(more.latents[..5], g.latents[..]);
        let other = generate(model, set, &GenerateOptions { count: 5, seed: 4 }).unwrap();
        assert_ne!(other.latents, g.latents);
    }

    #[test]
    fn bad_requests_are_named_errors() {
        let (model, set) = fixture::trained();
        let err = generate(model, set, &GenerateOptions { count: 0, seed: 1 }).unwrap_err();
        assert!(err.to_string().contains("number of samples"), "{err}");
        let fewer = set.subset(&[0, 1, 2]).unwrap();
        let err = generate(model, &fewer, &GenerateOptions::default()).unwrap_err();
        assert!(err.to_string().contains("this set has 3"), "{err}");
        let err = model.decode_latents(&[vec![0.0; 3]], None).unwrap_err();
        assert!(err.to_string().contains("latent size is 16"), "{err}");
        let err = model
            .decode_latents(&[vec![f32::NAN; 16]], None)
            .unwrap_err();
        assert!(err.to_string().contains("not finite"), "{err}");
        assert!(model.nearest_meshes(set, &[], &[]).is_err());
        assert!(model.nearest_meshes(set, &[99], &[]).is_err());
        assert!(
            model
                .nearest_meshes(set, &[0], &[vec![[0.0; 3]; 2]])
                .is_err()
        );
    }
}
