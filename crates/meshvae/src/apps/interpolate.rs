//! Latent interpolation (the paper's §4.3, the authors' `interpola`): the encoder means of two
//! meshes, linearly interpolated at t = 0, 1/(steps−1), …, 1 (both ends included), decoded in
//! inference mode.

use crate::error::{Result, VaeError};
use crate::train::split::resolve_mesh;
use crate::trained::TrainedModel;
use mesh_io::MeshSet;

/// An interpolation sequence between two meshes of a set.
#[derive(Debug, Clone)]
pub struct Interpolation {
    /// Indices in the set of the two ends.
    pub from: usize,
    pub to: usize,
    /// The interpolation parameter of each step, 0 first and 1 last.
    pub t: Vec<f64>,
    /// The latent vector of each step.
    pub latents: Vec<Vec<f32>>,
    /// The decoded mesh of each step.
    pub positions: Vec<Vec<[f64; 3]>>,
}

impl TrainedModel {
    /// Encoder means μ (inference mode) of the meshes `ids` of `set`, one vector each.
    pub fn latent_means(&self, set: &MeshSet, ids: &[usize]) -> Result<Vec<Vec<f32>>> {
        self.check_set(set)?;
        let extractor = self.extractor()?;
        let mut out = Vec::with_capacity(ids.len());
        for chunk in ids.chunks(16) {
            let x = self
                .encode_input(&extractor, set, chunk, self.model.device())?
                .to_dtype(self.model.dtype())?;
            let c = self.conditions(chunk)?;
            let mu = self.encode_mu(&x, c.as_ref())?;
            out.extend(mu.to_dtype(candle_core::DType::F32)?.to_vec2::<f32>()?);
        }
        Ok(out)
    }
}

/// `steps` meshes from mesh `from` to mesh `to` of `set` (each given by name or index).
///
/// Errors: an unknown name or an index out of range (naming `from` / `to`), `steps` < 2, a set
/// that is not the model's.
pub fn interpolate(
    model: &TrainedModel,
    set: &MeshSet,
    from: &str,
    to: &str,
    steps: usize,
) -> Result<Interpolation> {
    if steps < 2 {
        return Err(VaeError::argument(
            "steps",
            format!("{steps}: at least 2 (both ends are included)"),
        ));
    }
    model.check_set(set)?;
    let a = resolve_mesh(set.names(), from, "from")?;
    let b = resolve_mesh(set.names(), to, "to")?;
    let means = model.latent_means(set, &[a, b])?;
    let (za, zb) = (&means[0], &means[1]);
    let t: Vec<f64> = (0..steps).map(|k| k as f64 / (steps - 1) as f64).collect();
    let latents: Vec<Vec<f32>> = t
        .iter()
        .map(|&t| {
            za.iter()
                .zip(zb)
                .map(|(&x, &y)| ((1.0 - t) * f64::from(x) + t * f64::from(y)) as f32)
                .collect()
        })
        .collect();
    // A conditional model's label blends from the first mesh's to the second's.
    let conditions = model.conditions_between(a, b, &t)?;
    let positions = model.decode_latents(&latents, conditions.as_deref())?;
    Ok(Interpolation {
        from: a,
        to: b,
        t,
        latents,
        positions,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::apps::fixture;

    #[test]
    fn endpoints_are_the_reconstructions_of_the_two_meshes() {
        let (model, set) = fixture::trained();
        let from = set.names()[1].clone();
        let seq = interpolate(model, set, &from, "6", 5).unwrap();
        assert_eq!((seq.from, seq.to), (1, 6));
        assert_eq!(seq.t, vec![0.0, 0.25, 0.5, 0.75, 1.0]);
        assert_eq!(seq.positions.len(), 5);
        let rec = model
            .reconstruct(set, &[1, 6], model.model.device())
            .unwrap();
        let diag = model.template.bbox_diagonal();
        for (got, want) in [(&seq.positions[0], &rec[0]), (&seq.positions[4], &rec[1])] {
            for (p, q) in got.iter().zip(want) {
                for k in 0..3 {
                    assert!((p[k] - q[k]).abs() < 1e-5 * diag, "{p:?} vs {q:?}");
                }
            }
        }
        // The latent path is the straight line between the two means.
        let means = model.latent_means(set, &[1, 6]).unwrap();
        assert_eq!(seq.latents[0], means[0]);
        assert_eq!(seq.latents[4], means[1]);
        assert_eq!(seq.latents[2].len(), 16);
        for ((&a, &b), &m) in means[0].iter().zip(&means[1]).zip(&seq.latents[2]) {
            let mid = 0.5 * (f64::from(a) + f64::from(b));
            assert!((f64::from(m) - mid).abs() < 1e-6);
        }
        // Intermediate shapes lie between the ends: nearer to each end than the ends are apart.
        let ends = crate::apps::generate::mean_distance(&seq.positions[0], &seq.positions[4]);
        let mid_a = crate::apps::generate::mean_distance(&seq.positions[2], &seq.positions[0]);
        assert!(ends > 0.0 && mid_a < ends, "{mid_a} vs {ends}");
    }

    #[test]
    fn unknown_meshes_and_too_few_steps_are_named_errors() {
        let (model, set) = fixture::trained();
        let err = interpolate(model, set, "nope", "0", 4).unwrap_err();
        assert!(
            err.to_string().contains("from") && err.to_string().contains("nope"),
            "{err}"
        );
        let err = interpolate(model, set, "0", "8", 4).unwrap_err();
        assert!(err.to_string().contains("to"), "{err}");
        let err = interpolate(model, set, "0", "1", 1).unwrap_err();
        assert!(err.to_string().contains("steps"), "{err}");
    }
}
