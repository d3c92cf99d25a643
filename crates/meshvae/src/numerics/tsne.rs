//! Exact t-SNE (van der Maaten & Hinton 2008) for the few hundred meshes of a set: O(N²) per
//! iteration, no Barnes–Hut approximation.
//!
//! Each point's Gaussian bandwidth is found by bisection so that its conditional distribution has
//! the requested perplexity; the symmetrised affinities are matched by a Student-t distribution
//! in 2-D by gradient descent with momentum and per-coordinate gains, early exaggeration for the
//! first iterations. Everything runs sequentially from a seeded [`Rng`]: the same input and seed
//! give the same bits.

use crate::error::{Result, VaeError};
use crate::numerics::rng::Rng;

/// Settings of [`tsne`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TsneOptions {
    /// Effective number of neighbours; must lie in (1, N − 1).
    pub perplexity: f64,
    /// Gradient steps in all.
    pub iterations: usize,
    /// Factor on the affinities during the first `exaggeration_iterations` steps.
    pub exaggeration: f64,
    pub exaggeration_iterations: usize,
    /// Step size; `None`: max(N / exaggeration / 4, 50) (the common "auto" choice).
    pub learning_rate: Option<f64>,
    /// Seeds the random initial layout (used when no initial layout is given).
    pub seed: u64,
}

impl Default for TsneOptions {
    fn default() -> Self {
        Self {
            perplexity: 30.0,
            iterations: 1000,
            exaggeration: 12.0,
            exaggeration_iterations: 250,
            learning_rate: None,
            seed: 1,
        }
    }
}

/// The calibrated conditional distributions p_{j|i} (N × N row-major, zero diagonal) and the
/// precision β_i = 1 / (2σ_i²) of each row.
#[derive(Debug, Clone, PartialEq)]
pub struct Calibration {
    pub conditional: Vec<f64>,
    pub beta: Vec<f64>,
}

fn check_distances(dist2: &[f64], n: usize) -> Result<()> {
    if dist2.len() != n * n {
        return Err(VaeError::argument(
            "t-SNE distances",
            format!("{} values for {n} × {n} points", dist2.len()),
        ));
    }
    if let Some(k) = dist2.iter().position(|d| !d.is_finite() || *d < 0.0) {
        return Err(VaeError::argument(
            "t-SNE distances",
            format!(
                "entry ({}, {}) is {}, not a finite squared distance",
                k / n,
                k % n,
                dist2[k]
            ),
        ));
    }
    Ok(())
}

fn check_perplexity(perplexity: f64, n: usize) -> Result<()> {
    if !(perplexity > 1.0 && perplexity < n as f64 - 1.0) {
        return Err(VaeError::argument(
            "perplexity",
            format!(
                "{perplexity} is not in (1, N − 1) = (1, {}) for {n} points",
                n as f64 - 1.0
            ),
        ));
    }
    Ok(())
}

/// Entropy (nats) of row `i`'s distribution at precision `beta` over the shifted distances `d`
/// (self excluded), writing the probabilities into `p`.
fn row_entropy(d: &[f64], i: usize, beta: f64, p: &mut [f64]) -> f64 {
    let mut sum = 0.0;
    for (j, (pj, &dj)) in p.iter_mut().zip(d).enumerate() {
        *pj = if j == i { 0.0 } else { (-beta * dj).exp() };
        sum += *pj;
    }
    let mut weighted = 0.0;
    for (pj, &dj) in p.iter_mut().zip(d) {
        *pj /= sum;
        weighted += *pj * dj;
    }
    // H = ln Z + β Σ p_j d_j.
    sum.ln() + beta * weighted
}

/// Finds each row's precision so that exp(entropy of p_{·|i}) equals `perplexity`.
///
/// Errors: a distance matrix of the wrong size or with negative/non-finite entries, a
/// perplexity outside (1, N − 1).
pub fn calibrate(dist2: &[f64], n: usize, perplexity: f64) -> Result<Calibration> {
    check_distances(dist2, n)?;
    check_perplexity(perplexity, n)?;
    let target = perplexity.ln();
    let mut conditional = vec![0.0; n * n];
    let mut beta = vec![0.0; n];
    let mut d = vec![0.0; n];
    for i in 0..n {
        let row = &dist2[i * n..(i + 1) * n];
        // Shift by the nearest distance (p is unchanged; exp no longer underflows) and scale by
        // the mean so the search starts near the answer whatever the units.
        let nearest = (0..n)
            .filter(|&j| j != i)
            .map(|j| row[j])
            .fold(f64::INFINITY, f64::min);
        let mean = (0..n)
            .filter(|&j| j != i)
            .map(|j| row[j] - nearest)
            .sum::<f64>()
            / (n - 1) as f64;
        let scale = if mean > 0.0 { mean } else { 1.0 };
        for j in 0..n {
            d[j] = (row[j] - nearest) / scale;
        }
        let p = &mut conditional[i * n..(i + 1) * n];
        let (mut lo, mut hi, mut b) = (0.0f64, f64::INFINITY, 1.0f64);
        for _ in 0..200 {
            let h = row_entropy(&d, i, b, p);
            if (h - target).abs() < 1e-10 {
                break;
            }
            // Entropy falls as β grows.
            if h > target {
                lo = b;
                b = if hi.is_finite() {
                    0.5 * (b + hi)
                } else {
                    2.0 * b
                };
            } else {
                hi = b;
                b = 0.5 * (b + lo);
            }
        }
        row_entropy(&d, i, b, p);
        beta[i] = b / scale;
    }
    Ok(Calibration { conditional, beta })
}

/// Symmetrised joint affinities p_ij = (p_{j|i} + p_{i|j}) / 2N.
fn joint(calibration: &Calibration, n: usize) -> Vec<f64> {
    let c = &calibration.conditional;
    let mut p = vec![0.0; n * n];
    for i in 0..n {
        for j in 0..n {
            if i != j {
                p[i * n + j] = ((c[i * n + j] + c[j * n + i]) / (2.0 * n as f64)).max(1e-12);
            }
        }
    }
    p
}

/// The Kullback–Leibler cost KL(P‖Q) of layout `y` and its gradient, with P scaled by
/// `exaggeration` in the gradient (the cost is always of the unscaled P).
fn cost_and_gradient(p: &[f64], y: &[[f64; 2]], exaggeration: f64) -> (f64, Vec<[f64; 2]>) {
    let n = y.len();
    let mut num = vec![0.0; n * n];
    let mut z = 0.0;
    for i in 0..n {
        for j in 0..n {
            if i != j {
                let dx = y[i][0] - y[j][0];
                let dy = y[i][1] - y[j][1];
                let w = 1.0 / (1.0 + dx * dx + dy * dy);
                num[i * n + j] = w;
                z += w;
            }
        }
    }
    let mut cost = 0.0;
    let mut grad = vec![[0.0; 2]; n];
    for i in 0..n {
        for j in 0..n {
            if i == j {
                continue;
            }
            let w = num[i * n + j];
            let q = (w / z).max(1e-300);
            let pij = p[i * n + j];
            cost += pij * (pij / q).ln();
            let f = 4.0 * (exaggeration * pij - q) * w;
            grad[i][0] += f * (y[i][0] - y[j][0]);
            grad[i][1] += f * (y[i][1] - y[j][1]);
        }
    }
    (cost, grad)
}

/// A 2-D t-SNE layout of N points given their squared distances (N × N row-major).
///
/// `init`: a starting layout (e.g. scaled PCA scores); `None` draws one from N(0, 10⁻⁴ I) with
/// `options.seed`. Errors: as [`calibrate`], an `init` of the wrong length or not finite, zero
/// iterations, a non-positive exaggeration or learning rate.
pub fn tsne(
    dist2: &[f64],
    n: usize,
    options: &TsneOptions,
    init: Option<&[[f64; 2]]>,
) -> Result<Vec<[f64; 2]>> {
    if options.iterations == 0 {
        return Err(VaeError::argument("t-SNE iterations", "must be at least 1"));
    }
    if !(options.exaggeration.is_finite() && options.exaggeration > 0.0) {
        return Err(VaeError::argument(
            "t-SNE exaggeration",
            format!("{} is not positive", options.exaggeration),
        ));
    }
    let learning_rate = options
        .learning_rate
        .unwrap_or((n as f64 / options.exaggeration / 4.0).max(50.0));
    if !(learning_rate.is_finite() && learning_rate > 0.0) {
        return Err(VaeError::argument(
            "t-SNE learning rate",
            format!("{learning_rate} is not positive"),
        ));
    }
    let calibration = calibrate(dist2, n, options.perplexity)?;
    let p = joint(&calibration, n);
    let mut y: Vec<[f64; 2]> = match init {
        Some(start) => {
            if start.len() != n || start.iter().flatten().any(|v| !v.is_finite()) {
                return Err(VaeError::argument(
                    "t-SNE initial layout",
                    format!("needs {n} finite points, got {}", start.len()),
                ));
            }
            start.to_vec()
        }
        None => {
            let mut rng = Rng::new(options.seed);
            (0..n)
                .map(|_| [1e-2 * rng.normal(), 1e-2 * rng.normal()])
                .collect()
        }
    };
    let mut update = vec![[0.0f64; 2]; n];
    let mut gains = vec![[1.0f64; 2]; n];
    for it in 0..options.iterations {
        let early = it < options.exaggeration_iterations;
        let exaggeration = if early { options.exaggeration } else { 1.0 };
        let momentum = if early { 0.5 } else { 0.8 };
        let (_, grad) = cost_and_gradient(&p, &y, exaggeration);
        for i in 0..n {
            for k in 0..2 {
                // Gains grow while the gradient keeps pointing against the last step.
                let g = &mut gains[i][k];
                *g = if (grad[i][k] > 0.0) != (update[i][k] > 0.0) {
                    *g + 0.2
                } else {
                    (*g * 0.8).max(0.01)
                };
                update[i][k] = momentum * update[i][k] - learning_rate * *g * grad[i][k];
                y[i][k] += update[i][k];
            }
        }
        let mean = y
            .iter()
            .fold([0.0, 0.0], |m, p| [m[0] + p[0], m[1] + p[1]])
            .map(|s| s / n as f64);
        y.iter_mut().for_each(|p| {
            p[0] -= mean[0];
            p[1] -= mean[1];
        });
    }
    if y.iter().flatten().any(|v| !v.is_finite()) {
        return Err(VaeError::Diverged("t-SNE layout became non-finite".into()));
    }
    Ok(y)
}

/// KL(P‖Q) of a layout, for reporting how well it fits the affinities.
pub fn tsne_cost(dist2: &[f64], n: usize, perplexity: f64, y: &[[f64; 2]]) -> Result<f64> {
    let calibration = calibrate(dist2, n, perplexity)?;
    if y.len() != n {
        return Err(VaeError::argument(
            "t-SNE layout",
            format!("{} points for {n} distances", y.len()),
        ));
    }
    Ok(cost_and_gradient(&joint(&calibration, n), y, 1.0).0)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn squared_distances(points: &[Vec<f64>]) -> Vec<f64> {
        let n = points.len();
        let mut d = vec![0.0; n * n];
        for i in 0..n {
            for j in 0..n {
                d[i * n + j] = points[i]
                    .iter()
                    .zip(&points[j])
                    .map(|(a, b)| (a - b) * (a - b))
                    .sum();
            }
        }
        d
    }

    fn blobs(per: usize, dim: usize, separation: f64, seed: u64) -> Vec<Vec<f64>> {
        let mut r = Rng::new(seed);
        (0..2 * per)
            .map(|i| {
                let shift = if i < per { 0.0 } else { separation };
                (0..dim).map(|_| r.normal() + shift).collect()
            })
            .collect()
    }

    #[test]
    fn calibration_hits_the_perplexity() {
        let points = blobs(20, 5, 3.0, 4);
        let n = points.len();
        // Large units must not matter (the shift and scale inside).
        let d: Vec<f64> = squared_distances(&points).iter().map(|x| x * 1e6).collect();
        for perplexity in [2.0, 5.0, 12.5, 30.0] {
            let c = calibrate(&d, n, perplexity).unwrap();
            for i in 0..n {
                let row = &c.conditional[i * n..(i + 1) * n];
                assert_eq!(row[i], 0.0);
                assert!((row.iter().sum::<f64>() - 1.0).abs() < 1e-12);
                let h: f64 = row.iter().filter(|&&p| p > 0.0).map(|p| -p * p.ln()).sum();
                assert!(
                    (h.exp() - perplexity).abs() < 1e-3,
                    "row {i}: perplexity {} for {perplexity}",
                    h.exp()
                );
                // p_{j|i} ∝ exp(-β_i d_ij): ratios to the largest entry check β_i.
                let m = (0..n).max_by(|&x, &y| row[x].total_cmp(&row[y])).unwrap();
                for j in (0..n).filter(|&j| row[j] > 1e-30) {
                    let want = (-c.beta[i] * (d[i * n + j] - d[i * n + m])).exp();
                    assert!((row[j] / row[m] / want - 1.0).abs() < 1e-6, "row {i}, {j}");
                }
            }
        }
        assert!(calibrate(&d, n, 1.0).is_err());
        assert!(
            calibrate(&d, n, n as f64)
                .unwrap_err()
                .to_string()
                .contains("perplexity")
        );
        assert!(calibrate(&d[1..], n, 5.0).is_err());
        let mut bad = d.clone();
        bad[3] = f64::NAN;
        assert!(
            calibrate(&bad, n, 5.0)
                .unwrap_err()
                .to_string()
                .contains("(0, 3)")
        );
    }

    #[test]
    fn gradient_matches_finite_differences_of_the_cost() {
        let points = blobs(4, 3, 2.0, 5);
        let n = points.len();
        let c = calibrate(&squared_distances(&points), n, 3.0).unwrap();
        let p = joint(&c, n);
        let mut r = Rng::new(6);
        let y: Vec<[f64; 2]> = (0..n).map(|_| [r.normal(), r.normal()]).collect();
        let (_, grad) = cost_and_gradient(&p, &y, 1.0);
        let h = 1e-6;
        for i in 0..n {
            for k in 0..2 {
                let mut plus = y.clone();
                let mut minus = y.clone();
                plus[i][k] += h;
                minus[i][k] -= h;
                let fd = (cost_and_gradient(&p, &plus, 1.0).0
                    - cost_and_gradient(&p, &minus, 1.0).0)
                    / (2.0 * h);
                assert!(
                    (fd - grad[i][k]).abs() < 1e-6 * (1.0 + fd.abs()),
                    "({i}, {k}): {fd} vs {}",
                    grad[i][k]
                );
            }
        }
    }

    #[test]
    fn separated_clusters_stay_separated_and_runs_are_deterministic() {
        let points = blobs(15, 10, 20.0, 7);
        let n = points.len();
        let d = squared_distances(&points);
        let options = TsneOptions {
            perplexity: 8.0,
            iterations: 500,
            ..TsneOptions::default()
        };
        let y = tsne(&d, n, &options, None).unwrap();
        let dist =
            |a: [f64; 2], b: [f64; 2]| ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)).sqrt();
        let (mut intra, mut inter) = (0.0f64, f64::INFINITY);
        for i in 0..n {
            for j in i + 1..n {
                if (i < 15) == (j < 15) {
                    intra = intra.max(dist(y[i], y[j]));
                } else {
                    inter = inter.min(dist(y[i], y[j]));
                }
            }
        }
        // Every cross-cluster pair is farther apart than half the widest cluster.
        assert!(
            inter > 0.5 * intra,
            "inter {inter} vs intra diameter {intra}"
        );
        let cost = tsne_cost(&d, n, 8.0, &y).unwrap();
        let start: Vec<[f64; 2]> = {
            let mut r = Rng::new(1);
            (0..n)
                .map(|_| [1e-2 * r.normal(), 1e-2 * r.normal()])
                .collect()
        };
        assert!(
            cost < tsne_cost(&d, n, 8.0, &start).unwrap(),
            "the fit lowered KL"
        );

        let again = tsne(&d, n, &options, None).unwrap();
        assert_eq!(y, again);
        let other = tsne(&d, n, &TsneOptions { seed: 2, ..options }, None).unwrap();
        assert_ne!(y, other);
        let bad = TsneOptions {
            iterations: 0,
            ..options
        };
        assert!(tsne(&d, n, &bad, None).is_err());
        assert!(tsne(&d, n, &options, Some(&[[0.0, 0.0]])).is_err());
    }
}
