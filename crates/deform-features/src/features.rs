//! The 9-number features of a whole mesh set, and their extraction (parallel over frames).
//!
//! Channel order per vertex (network order, as the authors' Python: rotation first):
//! `[ωx, ωy, ωz, S11, S12, S13, S22, S23, S33]` where ω is the rotation vector of R_i (log R_i
//! as an axis-angle vector, the ACAP-consistent representative, |ω| may exceed π) and S_i the
//! symmetric stretch of the polar decomposition T_i = R_i S_i (raw: identity at rest, not S − I).
//! (The authors store the strict upper triangle of the skew matrix log R, (−ωz, ωy, −ωx); only the
//! encoding differs, the information is the same.)

use crate::consistency::make_consistent;
use crate::error::FeatureError;
use crate::fit::Fitter;
use crate::integrate::Integrator;
use crate::rest::RestMesh;
use crate::rotation::{Mat3, Vec3, exp_rotation, log_rotation, mul, polar};
use mesh_io::{MeshSet, Point};
use rayon::prelude::*;

/// Numbers per vertex.
pub const CHANNELS: usize = 9;
/// Channels 0..3 are the rotation vector; 3..9 the stretch.
pub const ROTATION_CHANNELS: usize = 3;
/// Names of the channels, in order.
pub const CHANNEL_NAMES: [&str; CHANNELS] =
    ["wx", "wy", "wz", "s11", "s12", "s13", "s22", "s23", "s33"];

/// Features of N frames of V vertices, f32, row-major [N, V, 9].
#[derive(Debug, Clone, PartialEq)]
pub struct FeatureSet {
    frames: usize,
    vertices: usize,
    data: Vec<f32>,
}

impl FeatureSet {
    /// Wraps a flat [N, V, 9] array, checking its length.
    pub fn new(frames: usize, vertices: usize, data: Vec<f32>) -> Result<Self, FeatureError> {
        let expected = frames * vertices * CHANNELS;
        if data.len() != expected {
            return Err(FeatureError::shape(
                "feature array",
                format!("{frames} × {vertices} × {CHANNELS} = {expected} values"),
                data.len(),
            ));
        }
        Ok(Self {
            frames,
            vertices,
            data,
        })
    }

    /// Number of frames N.
    pub fn frames(&self) -> usize {
        self.frames
    }

    /// Number of vertices V.
    pub fn vertices(&self) -> usize {
        self.vertices
    }

    /// The flat [N, V, 9] data.
    pub fn as_slice(&self) -> &[f32] {
        &self.data
    }

    pub fn as_mut_slice(&mut self) -> &mut [f32] {
        &mut self.data
    }

    pub fn into_vec(self) -> Vec<f32> {
        self.data
    }

    /// Frame `f` as a flat [V, 9] slice. Panics if `f >= frames()`, like slice indexing.
    pub fn frame(&self, f: usize) -> &[f32] {
        let len = self.vertices * CHANNELS;
        &self.data[f * len..(f + 1) * len]
    }

    /// The 9 numbers of vertex `v` in frame `f`.
    pub fn vertex(&self, f: usize, v: usize) -> [f32; CHANNELS] {
        let start = (f * self.vertices + v) * CHANNELS;
        let mut out = [0.0; CHANNELS];
        out.copy_from_slice(&self.data[start..start + CHANNELS]);
        out
    }

    /// The frames at `indices`, in that order (e.g. a training split).
    pub fn subset(&self, indices: &[usize]) -> Result<Self, FeatureError> {
        if let Some(&bad) = indices.iter().find(|&&i| i >= self.frames) {
            return Err(FeatureError::input(
                "frame indices",
                format!("frame {bad} is out of range (the set has {})", self.frames),
            ));
        }
        let data = indices
            .iter()
            .flat_map(|&i| self.frame(i).iter().copied())
            .collect();
        Self::new(indices.len(), self.vertices, data)
    }
}

/// The 9 numbers of one vertex from R's rotation vector and the stretch S.
pub fn encode(omega: Vec3, s: &Mat3) -> [f64; CHANNELS] {
    [
        omega[0], omega[1], omega[2], s[0][0], s[0][1], s[0][2], s[1][1], s[1][2], s[2][2],
    ]
}

/// T = exp(ω) S from the 9 numbers of one vertex.
pub fn decode(f: &[f64; CHANNELS]) -> Mat3 {
    let r = exp_rotation([f[0], f[1], f[2]]);
    let s = [[f[3], f[4], f[5]], [f[4], f[6], f[7]], [f[5], f[7], f[8]]];
    mul(&r, &s)
}

/// One frame's f64 features and its warnings.
pub type FrameFeatures = (Vec<[f64; CHANNELS]>, Vec<String>);

/// How features are computed.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FeatureOptions {
    /// Weight of the vertex-normal pair in the fit, relative to an average ring edge (> 0).
    pub normal_weight: f64,
    /// Choose ACAP-consistent rotation vectors (otherwise the principal ones, |ω| ≤ π).
    pub consistent_rotations: bool,
    /// Apply the minimal correction that makes the gradients exactly integrable by the
    /// reconstruction (see [`crate::integrate`]): exact round trips (also of every affine map),
    /// rougher features. Off: the plain per-vertex fit, smoother features, a round-trip floor
    /// (see the crate documentation for figures).
    pub integrable: bool,
}

impl Default for FeatureOptions {
    fn default() -> Self {
        Self {
            normal_weight: 1.0,
            consistent_rotations: true,
            integrable: true,
        }
    }
}

/// Features with the warnings met computing them.
#[derive(Debug, Clone, PartialEq)]
pub struct Features {
    pub features: FeatureSet,
    /// Degenerate input and the like (never printed by the library).
    pub warnings: Vec<String>,
}

/// Everything precomputed from one rest mesh to turn frames into features.
#[derive(Debug)]
pub struct FeatureExtractor {
    rest: RestMesh,
    options: FeatureOptions,
    fitter: Fitter,
    integrator: Option<Integrator>,
    warnings: Vec<String>,
}

impl FeatureExtractor {
    /// Precomputes the fit (and, with `options.integrable`, factorises the correction system).
    pub fn new(rest: RestMesh, options: FeatureOptions) -> Result<Self, FeatureError> {
        if !(options.normal_weight > 0.0 && options.normal_weight.is_finite()) {
            return Err(FeatureError::InvalidOption {
                option: "normal_weight",
                message: format!("must be a positive number, got {}", options.normal_weight),
            });
        }
        let fitter = Fitter::new(&rest, options.normal_weight);
        let mut warnings = rest.warnings().to_vec();
        let reg = fitter.regularized();
        if !reg.is_empty() {
            let first: Vec<String> = reg.iter().take(5).map(|v| v.to_string()).collect();
            warnings.push(format!(
                "{} vertices have a degenerate one-ring (e.g. {}); their fit is regularised \
                 towards the identity",
                reg.len(),
                first.join(", ")
            ));
        }
        let integrator = if options.integrable {
            Some(Integrator::new(&rest)?)
        } else {
            None
        };
        Ok(Self {
            rest,
            options,
            fitter,
            integrator,
            warnings,
        })
    }

    /// Frame 0 of `set` as the rest mesh, default weight clamp.
    pub fn for_set(set: &MeshSet, options: FeatureOptions) -> Result<Self, FeatureError> {
        Self::new(RestMesh::new(set.frame(0), set.faces())?, options)
    }

    pub fn rest(&self) -> &RestMesh {
        &self.rest
    }

    pub fn options(&self) -> FeatureOptions {
        self.options
    }

    /// Warnings about the rest mesh (degenerate faces, regularised rings, …).
    pub fn warnings(&self) -> &[String] {
        &self.warnings
    }

    fn check_frame(&self, frame: &[Point]) -> Result<Vec<Vec3>, FeatureError> {
        if frame.len() != self.rest.vertex_count() {
            return Err(FeatureError::shape(
                "frame",
                format!("{} vertices (the rest mesh's)", self.rest.vertex_count()),
                format!("{} vertices", frame.len()),
            ));
        }
        if let Some(v) = frame.iter().position(|p| !p.iter().all(|c| c.is_finite())) {
            return Err(FeatureError::input(
                "frame",
                format!("vertex {v} is not finite"),
            ));
        }
        Ok(frame.iter().map(|p| p.map(f64::from)).collect())
    }

    /// The deformation gradients T_i of one frame (after the optional correction).
    pub fn gradients(&self, frame: &[Point]) -> Result<Vec<Mat3>, FeatureError> {
        let frame = self.check_frame(frame)?;
        Ok(self.gradients_f64(&frame).0)
    }

    fn gradients_f64(&self, frame: &[Vec3]) -> (Vec<Mat3>, Vec<f64>) {
        let (mut t, areas) = self.fitter.fit_with_areas(&self.rest, frame);
        if let Some(integrator) = &self.integrator {
            integrator.correct(&self.rest, frame, &mut t);
        }
        (t, areas)
    }

    /// The f64 features of one frame, and warnings about it.
    pub fn frame_features(&self, frame: &[Point]) -> Result<FrameFeatures, FeatureError> {
        let frame = self.check_frame(frame)?;
        let mut warnings = Vec::new();
        let (t, areas) = self.gradients_f64(&frame);
        let collapsed = areas
            .iter()
            .zip(self.rest.ring_areas())
            .filter(|&(&a, &a0)| a0 > 0.0 && a <= 1e-12 * a0)
            .count();
        if collapsed > 0 {
            warnings.push(format!(
                "{collapsed} vertices have a zero-area one-ring in this frame (collapsed \
                 triangles); their stretch is singular there"
            ));
        }
        let mut stretch = Vec::with_capacity(t.len());
        let mut omega = Vec::with_capacity(t.len());
        let mut bad = 0;
        for ti in &t {
            let (r, s) = if ti.iter().flatten().all(|x| x.is_finite()) {
                polar(ti)
            } else {
                bad += 1;
                (crate::rotation::IDENTITY, crate::rotation::IDENTITY)
            };
            omega.push(log_rotation(&r));
            stretch.push(s);
        }
        if bad > 0 {
            warnings.push(format!(
                "{bad} vertices had a non-finite deformation gradient; set to the identity"
            ));
        }
        if self.options.consistent_rotations {
            make_consistent(&self.rest, &mut omega);
        }
        let features = omega
            .iter()
            .zip(&stretch)
            .map(|(w, s)| encode(*w, s))
            .collect();
        Ok((features, warnings))
    }

    /// The features of every frame of `set` (rayon over frames), as f32 [N, V, 9].
    pub fn extract(&self, set: &MeshSet) -> Result<Features, FeatureError> {
        if set.vertex_count() != self.rest.vertex_count() {
            return Err(FeatureError::shape(
                "mesh set",
                format!("{} vertices (the rest mesh's)", self.rest.vertex_count()),
                format!("{} vertices", set.vertex_count()),
            ));
        }
        // Each frame writes its f32 features straight into the output, so that no frame's f64
        // features outlive it (for 48 elephant frames they would hold 146 MB).
        let mut data = vec![0f32; set.len() * set.vertex_count() * CHANNELS];
        let per_frame: Vec<Result<Vec<String>, FeatureError>> = data
            .par_chunks_mut(set.vertex_count() * CHANNELS)
            .enumerate()
            .map(|(f, out)| {
                let (features, frame_warnings) = self.frame_features(set.frame(f))?;
                for (o, x) in out.iter_mut().zip(features.iter().flatten()) {
                    *o = *x as f32;
                }
                Ok(frame_warnings)
            })
            .collect();
        let mut warnings = self.warnings.clone();
        for (f, result) in per_frame.into_iter().enumerate() {
            let name = &set.names()[f];
            warnings.extend(result?.into_iter().map(|w| format!("frame {name}: {w}")));
        }
        Ok(Features {
            features: FeatureSet::new(set.len(), set.vertex_count(), data)?,
            warnings,
        })
    }
}

/// Features of every frame of `set` relative to its frame 0.
pub fn extract_features(set: &MeshSet, options: FeatureOptions) -> Result<Features, FeatureError> {
    FeatureExtractor::for_set(set, options)?.extract(set)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rotation::frobenius;

    #[test]
    fn encode_decode_round_trip() {
        let w = [0.3, -2.5, 1.0];
        let s = [[1.2, 0.1, -0.2], [0.1, 0.9, 0.05], [-0.2, 0.05, 1.1]];
        let f = encode(w, &s);
        let t = decode(&f);
        let expected = mul(&exp_rotation(w), &s);
        let mut d = t;
        for r in 0..3 {
            for c in 0..3 {
                d[r][c] -= expected[r][c];
            }
        }
        assert!(frobenius(&d) < 1e-15);
        assert_eq!(f[4], s[0][1]);
    }

    #[test]
    fn feature_set_checks_its_shape() {
        assert!(FeatureSet::new(2, 3, vec![0.0; 54]).is_ok());
        assert!(FeatureSet::new(2, 3, vec![0.0; 53]).is_err());
        let fs = FeatureSet::new(2, 1, (0..18).map(|x| x as f32).collect()).unwrap();
        assert_eq!(fs.vertex(1, 0)[0], 9.0);
        assert_eq!(fs.subset(&[1]).unwrap().as_slice()[0], 9.0);
        assert!(fs.subset(&[2]).is_err());
    }
}
