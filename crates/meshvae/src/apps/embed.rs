//! 2-D embeddings of a mesh set (the paper's §4.6): the encoder means μ of all meshes shown by
//! the two latent dimensions of largest variance across the set, as the paper; beside it, for
//! comparison, PCA and t-SNE of the raw ACAP features (no network involved).
//!
//! [`loop_measure`] quantifies whether a sequence (e.g. one gait cycle) traces a closed loop.

use crate::error::{Result, VaeError};
use crate::numerics::pca::{centered_gram, distances_from_gram, pca_of_gram};
use crate::numerics::tsne::{TsneOptions, tsne};
use crate::trained::TrainedModel;
use mesh_io::MeshSet;

/// Settings of [`embed`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EmbedOptions {
    /// t-SNE perplexity; lowered to (N − 1) / 3 for small sets.
    pub perplexity: f64,
    /// t-SNE gradient steps.
    pub iterations: usize,
    /// Seeds t-SNE's initial layout when the PCA start is degenerate (all meshes equal).
    pub seed: u64,
}

impl Default for EmbedOptions {
    fn default() -> Self {
        Self {
            perplexity: 30.0,
            iterations: 1000,
            seed: 1,
        }
    }
}

/// The embeddings of every mesh of a set, in set order.
#[derive(Debug, Clone, PartialEq)]
pub struct Embedding {
    pub names: Vec<String>,
    /// μ of each mesh (the model's latent size).
    pub latent: Vec<Vec<f32>>,
    /// The two latent dimensions of largest variance of μ over the set, largest first.
    pub latent_dims: [usize; 2],
    /// Their variances.
    pub latent_variance: [f64; 2],
    /// μ restricted to `latent_dims`.
    pub latent_2d: Vec<[f64; 2]>,
    /// Scores on the first two principal components of the raw features.
    pub pca_2d: Vec<[f64; 2]>,
    /// Fractions of the raw features' variance the two components explain.
    pub pca_explained: [f64; 2],
    /// t-SNE of the raw features.
    pub tsne_2d: Vec<[f64; 2]>,
    /// The perplexity t-SNE used.
    pub perplexity: f64,
}

/// The smallest set [`embed`] accepts: t-SNE needs a perplexity above 1 with at least three
/// neighbours per unit of perplexity.
pub const MIN_EMBED_MESHES: usize = 5;

/// The latent, PCA and t-SNE embeddings of every mesh of `set` (the model's set).
///
/// Errors: a set that is not the model's, fewer than [`MIN_EMBED_MESHES`] meshes, bad t-SNE
/// settings.
pub fn embed(model: &TrainedModel, set: &MeshSet, options: &EmbedOptions) -> Result<Embedding> {
    model.check_set(set)?;
    let n = set.len();
    if n < MIN_EMBED_MESHES {
        return Err(VaeError::argument(
            "mesh set",
            format!("{n} meshes; an embedding needs at least {MIN_EMBED_MESHES}"),
        ));
    }
    if !(options.perplexity.is_finite() && options.perplexity > 1.0) {
        return Err(VaeError::argument(
            "perplexity",
            format!("{} is not above 1", options.perplexity),
        ));
    }
    let ids: Vec<usize> = (0..n).collect();
    let latent = model.latent_means(set, &ids)?;
    let (latent_dims, latent_variance) = largest_variance_dims(&latent);
    let latent_2d = latent
        .iter()
        .map(|z| latent_dims.map(|d| f64::from(z[d])))
        .collect();

    let raw = model.extractor()?.extract(set)?.features;
    let rows: Vec<&[f32]> = (0..n).map(|i| raw.frame(i)).collect();
    let gram = centered_gram(&rows)?;
    let pca = pca_of_gram(&gram, n, 2)?;
    let pca_2d: Vec<[f64; 2]> = pca.scores.iter().map(|s| [s[0], s[1]]).collect();

    // PCA scores as t-SNE's start (scaled to a small spread, as the usual "pca" init): the
    // global arrangement survives and the result needs no random draw.
    let spread = (pca.variances[0]).sqrt();
    let init: Option<Vec<[f64; 2]>> = (spread > 0.0).then(|| {
        pca_2d
            .iter()
            .map(|p| [1e-4 * p[0] / spread, 1e-4 * p[1] / spread])
            .collect()
    });
    let perplexity = options.perplexity.min((n - 1) as f64 / 3.0);
    let tsne_options = TsneOptions {
        perplexity,
        iterations: options.iterations,
        seed: options.seed,
        ..TsneOptions::default()
    };
    let tsne_2d = tsne(
        &distances_from_gram(&gram, n),
        n,
        &tsne_options,
        init.as_deref(),
    )?;
    Ok(Embedding {
        names: set.names().to_vec(),
        latent,
        latent_dims,
        latent_variance,
        latent_2d,
        pca_2d,
        pca_explained: [pca.explained(0), pca.explained(1)],
        tsne_2d,
        perplexity,
    })
}

/// The two coordinates of largest variance (largest first; ties to the lower index) and their
/// variances. With a one-dimensional input both are dimension 0.
pub fn largest_variance_dims(rows: &[Vec<f32>]) -> ([usize; 2], [f64; 2]) {
    let width = rows.first().map_or(0, Vec::len);
    let n = rows.len().max(1) as f64;
    let variance: Vec<f64> = (0..width)
        .map(|d| {
            let mean = rows.iter().map(|r| f64::from(r[d])).sum::<f64>() / n;
            rows.iter()
                .map(|r| (f64::from(r[d]) - mean).powi(2))
                .sum::<f64>()
                / n
        })
        .collect();
    let mut order: Vec<usize> = (0..width).collect();
    order.sort_by(|&a, &b| variance[b].total_cmp(&variance[a]).then(a.cmp(&b)));
    let first = order.first().copied().unwrap_or(0);
    let second = order.get(1).copied().unwrap_or(first);
    let var = |d: usize| variance.get(d).copied().unwrap_or(0.0);
    ([first, second], [var(first), var(second)])
}

/// How closely a sequence of 2-D points traces a closed loop, in its order.
///
/// The criterion made numeric: consecutive frames are nearer to each other than a
/// typical pair ([`Self::nearer`]), and the last frame is near the first ([`Self::closing`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LoopMeasure {
    /// Mean distance between consecutive points, last → first included, divided by the mean
    /// distance over all pairs. Points evenly spaced on a circle traversed k times give about
    /// k·π²/(2N) (0.10 for one turn of N = 48); the same points in random order give about 1.
    pub ratio: f64,
    /// Fraction of the N consecutive steps (last → first included) shorter than the median
    /// distance over all pairs: 1 along a loop (however many turns it makes), about 0.5 for
    /// points in random order.
    pub nearer: f64,
    /// Distance last → first divided by the median of the other consecutive steps: about 1 on
    /// a closed loop, about N on an open path.
    pub closing: f64,
}

impl LoopMeasure {
    /// The smallest [`Self::nearer`] accepted: at most one step in ten as long as a typical
    /// pair. In random order the fraction is Binomial(N, ½) / N, 0.50 ± 0.07 for N = 48, so 0.9
    /// lies more than five standard deviations above it.
    pub const MIN_NEARER: f64 = 0.9;
    /// The largest [`Self::closing`] accepted: the last step may be a few typical steps long.
    pub const MAX_CLOSING: f64 = 3.0;

    /// Whether both criteria hold.
    pub fn is_loop(&self) -> bool {
        self.nearer >= Self::MIN_NEARER && self.closing <= Self::MAX_CLOSING
    }
}

/// The [`LoopMeasure`] of `points` in order.
///
/// Errors: fewer than 3 points, non-finite coordinates, all points equal.
pub fn loop_measure(points: &[[f64; 2]]) -> Result<LoopMeasure> {
    let n = points.len();
    if n < 3 {
        return Err(VaeError::argument(
            "loop points",
            format!("{n}; a loop needs at least 3"),
        ));
    }
    if points.iter().flatten().any(|x| !x.is_finite()) {
        return Err(VaeError::argument("loop points", "not all finite"));
    }
    let dist = |a: [f64; 2], b: [f64; 2]| ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)).sqrt();
    let mut steps: Vec<f64> = points.windows(2).map(|w| dist(w[0], w[1])).collect();
    let closing_step = dist(points[n - 1], points[0]);
    let mut pairs = Vec::with_capacity(n * (n - 1) / 2);
    for i in 0..n {
        for j in i + 1..n {
            pairs.push(dist(points[i], points[j]));
        }
    }
    let mean_pair = pairs.iter().sum::<f64>() / pairs.len() as f64;
    if mean_pair == 0.0 {
        return Err(VaeError::argument("loop points", "all equal"));
    }
    pairs.sort_by(f64::total_cmp);
    let median_pair = pairs[pairs.len() / 2];
    let shorter = steps
        .iter()
        .chain([&closing_step])
        .filter(|&&s| s < median_pair)
        .count();
    let consecutive = (steps.iter().sum::<f64>() + closing_step) / n as f64;
    steps.sort_by(f64::total_cmp);
    let median_step = steps[steps.len() / 2];
    Ok(LoopMeasure {
        ratio: consecutive / mean_pair,
        nearer: shorter as f64 / n as f64,
        closing: if median_step > 0.0 {
            closing_step / median_step
        } else {
            f64::INFINITY
        },
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::apps::fixture;

    fn circle(n: usize) -> Vec<[f64; 2]> {
        (0..n)
            .map(|k| {
                let a = std::f64::consts::TAU * k as f64 / n as f64;
                [3.0 * a.cos(), 3.0 * a.sin()]
            })
            .collect()
    }

    #[test]
    fn loop_measure_tells_loops_from_open_paths_and_clouds() {
        let c = circle(48);
        let m = loop_measure(&c).unwrap();
        let want = std::f64::consts::PI.powi(2) / (2.0 * 48.0);
        assert!((m.ratio - want).abs() < 0.01, "{} vs {want}", m.ratio);
        assert!((m.closing - 1.0).abs() < 1e-9);
        assert_eq!(m.nearer, 1.0);
        assert!(m.is_loop());
        // Four turns of 12 frames each (as horse-gallop's two gait cycles look in 2-D).
        let turns: Vec<[f64; 2]> = (0..48).map(|k| circle(12)[k % 12]).collect();
        let m = loop_measure(&turns).unwrap();
        assert!(m.is_loop() && m.ratio > 0.3, "{m:?}");
        // A figure eight (the gait may cross itself) is still one closed loop.
        let eight: Vec<[f64; 2]> = (0..48)
            .map(|k| {
                let a = std::f64::consts::TAU * k as f64 / 48.0;
                [a.sin(), (2.0 * a).sin() * 0.5]
            })
            .collect();
        assert!(loop_measure(&eight).unwrap().is_loop());
        // Half a circle: consecutive steps small, but the last is far from the first.
        let arc: Vec<[f64; 2]> = circle(96)[..48].to_vec();
        let m = loop_measure(&arc).unwrap();
        assert!(m.closing > 10.0 && !m.is_loop(), "{m:?}");
        // The circle's points in a scrambled order.
        let mut scrambled = c.clone();
        crate::numerics::rng::Rng::new(3).shuffle(&mut scrambled);
        let m = loop_measure(&scrambled).unwrap();
        assert!(m.ratio > 0.7 && m.nearer < 0.75 && !m.is_loop(), "{m:?}");
        assert!(loop_measure(&c[..2]).is_err());
        assert!(loop_measure(&[[1.0, 1.0]; 4]).is_err());
        assert!(loop_measure(&[[1.0, f64::NAN], [0.0, 0.0], [1.0, 0.0]]).is_err());
    }

    #[test]
    fn largest_variance_dimensions() {
        let rows = vec![
            vec![0.0f32, 5.0, 1.0, 0.0],
            vec![0.0, -5.0, 2.0, 0.5],
            vec![0.0, 5.0, 3.0, 0.0],
        ];
        let (dims, var) = largest_variance_dims(&rows);
        assert_eq!(dims, [1, 2]);
        assert!((var[0] - 200.0 / 9.0).abs() < 1e-9);
        assert!((var[1] - 2.0 / 3.0).abs() < 1e-9);
        assert_eq!(largest_variance_dims(&[vec![1.0], vec![2.0]]).0, [0, 0]);
    }

    #[test]
    fn embeddings_of_the_synthetic_set() {
        let (model, set) = fixture::trained();
        let options = EmbedOptions {
            iterations: 300,
            ..EmbedOptions::default()
        };
        let e = embed(model, set, &options).unwrap();
        let n = set.len();
        assert_eq!(e.names, set.names());
        for pts in [&e.latent_2d, &e.pca_2d, &e.tsne_2d] {
            assert_eq!(pts.len(), n);
            assert!(pts.iter().flatten().all(|x| x.is_finite()));
        }
        assert_eq!(e.perplexity, (n - 1) as f64 / 3.0);
        // The latent coordinates are μ's two most varying dimensions.
        let means = model
            .latent_means(set, &(0..n).collect::<Vec<_>>())
            .unwrap();
        assert_eq!(e.latent, means);
        let (dims, _) = largest_variance_dims(&means);
        assert_eq!(e.latent_dims, dims);
        assert_ne!(dims[0], dims[1]);
        assert_eq!(
            e.latent_2d[3],
            [means[3][dims[0]], means[3][dims[1]]].map(f64::from)
        );
        // PCA agrees with the PCA of the raw features computed directly.
        let raw = model.extractor().unwrap().extract(set).unwrap().features;
        let rows: Vec<&[f32]> = (0..n).map(|i| raw.frame(i)).collect();
        let direct = crate::numerics::pca::pca(&rows, 2).unwrap();
        for (p, s) in e.pca_2d.iter().zip(&direct.scores) {
            assert!((p[0] - s[0]).abs() < 1e-9 && (p[1] - s[1]).abs() < 1e-9);
        }
        assert!(e.pca_explained[0] >= e.pca_explained[1] && e.pca_explained[0] <= 1.0);
        assert_eq!(embed(model, set, &options).unwrap(), e, "deterministic");

        let few = set.subset(&[0, 1, 2, 3]).unwrap();
        assert!(embed(model, &few, &options).is_err());
        let bad = EmbedOptions {
            perplexity: 0.5,
            ..options
        };
        assert!(
            embed(model, set, &bad)
                .unwrap_err()
                .to_string()
                .contains("perplexity")
        );
    }
}
