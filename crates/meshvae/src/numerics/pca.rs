//! Principal component analysis of a few high-dimensional rows (N meshes × D features, N ≪ D):
//! the centred Gram matrix `(X − x̄)(X − x̄)ᵀ` (N × N) is decomposed instead of the D × D
//! covariance; both share their non-zero eigenvalues, and the scores of row i on component k are
//! √λ_k · u_ik. The eigen decomposition is cyclic Jacobi (exact to round-off, O(N³) per sweep),
//! fine for the hundreds of meshes of a set.

use crate::error::{Result, VaeError};
use rayon::prelude::*;

/// A principal component analysis of N rows.
#[derive(Debug, Clone, PartialEq)]
pub struct Pca {
    /// `scores[i][k]`: row i projected on component k (centred), for the leading components.
    pub scores: Vec<Vec<f64>>,
    /// Variance along each leading component (eigenvalue / N), descending.
    pub variances: Vec<f64>,
    /// Total variance of the rows (trace of the covariance, divisor N).
    pub total_variance: f64,
}

impl Pca {
    /// The fraction of the total variance component `k` explains (0 when all rows are equal).
    pub fn explained(&self, k: usize) -> f64 {
        match self.variances.get(k) {
            Some(v) if self.total_variance > 0.0 => v / self.total_variance,
            _ => 0.0,
        }
    }
}

fn check_rows(rows: &[&[f32]], what: &str) -> Result<usize> {
    let Some(first) = rows.first() else {
        return Err(VaeError::argument(what, "no rows"));
    };
    let d = first.len();
    if d == 0 {
        return Err(VaeError::argument(what, "rows of length 0"));
    }
    for (i, r) in rows.iter().enumerate() {
        if r.len() != d {
            return Err(VaeError::argument(
                what,
                format!("row {i} has {} values, row 0 has {d}", r.len()),
            ));
        }
        if let Some(j) = r.iter().position(|x| !x.is_finite()) {
            return Err(VaeError::argument(
                what,
                format!("row {i} has a non-finite value at {j}"),
            ));
        }
    }
    Ok(d)
}

/// The centred Gram matrix `G_ij = (x_i − x̄)·(x_j − x̄)` of the rows, N × N row-major, in f64.
///
/// Errors: no rows, rows of different lengths, non-finite values.
pub fn centered_gram(rows: &[&[f32]]) -> Result<Vec<f64>> {
    let d = check_rows(rows, "PCA input")?;
    let n = rows.len();
    let mut mean = vec![0.0f64; d];
    for r in rows {
        for (m, &x) in mean.iter_mut().zip(r.iter()) {
            *m += f64::from(x);
        }
    }
    mean.iter_mut().for_each(|m| *m /= n as f64);
    // Centred copies in f64: exact products, and the pairs below read them n times each.
    let centred: Vec<Vec<f64>> = rows
        .par_iter()
        .map(|r| {
            r.iter()
                .zip(&mean)
                .map(|(&x, m)| f64::from(x) - m)
                .collect()
        })
        .collect();
    let upper: Vec<Vec<f64>> = (0..n)
        .into_par_iter()
        .map(|i| {
            (i..n)
                .map(|j| centred[i].iter().zip(&centred[j]).map(|(a, b)| a * b).sum())
                .collect()
        })
        .collect();
    let mut g = vec![0.0; n * n];
    for (i, row) in upper.iter().enumerate() {
        for (k, &v) in row.iter().enumerate() {
            g[i * n + i + k] = v;
            g[(i + k) * n + i] = v;
        }
    }
    Ok(g)
}

/// Squared Euclidean distances between rows from their (centred) Gram matrix, N × N.
pub fn distances_from_gram(gram: &[f64], n: usize) -> Vec<f64> {
    let mut d = vec![0.0; n * n];
    for i in 0..n {
        for j in 0..n {
            if i != j {
                d[i * n + j] = (gram[i * n + i] + gram[j * n + j] - 2.0 * gram[i * n + j]).max(0.0);
            }
        }
    }
    d
}

/// Eigenvalues (descending) and eigenvectors (`vectors[k]` for `values[k]`, unit length) of the
/// symmetric n × n row-major matrix `a`, by cyclic Jacobi rotations.
///
/// Errors: `a` not n × n, not symmetric, or not finite.
pub fn symmetric_eigen(a: &[f64], n: usize) -> Result<(Vec<f64>, Vec<Vec<f64>>)> {
    if a.len() != n * n {
        return Err(VaeError::argument(
            "matrix",
            format!("{} values for {n} × {n}", a.len()),
        ));
    }
    if a.iter().any(|x| !x.is_finite()) {
        return Err(VaeError::argument("matrix", "has non-finite values"));
    }
    let scale = a.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    for i in 0..n {
        for j in 0..i {
            if (a[i * n + j] - a[j * n + i]).abs() > 1e-9 * scale.max(f64::MIN_POSITIVE) {
                return Err(VaeError::argument(
                    "matrix",
                    format!("not symmetric at ({i}, {j})"),
                ));
            }
        }
    }
    let mut m = a.to_vec();
    // v holds the eigenvectors as columns.
    let mut v = vec![0.0; n * n];
    (0..n).for_each(|i| v[i * n + i] = 1.0);
    for _sweep in 0..100 {
        let off: f64 = (0..n)
            .flat_map(|i| (0..n).filter(move |&j| j != i).map(move |j| (i, j)))
            .map(|(i, j)| m[i * n + j] * m[i * n + j])
            .sum();
        let diag: f64 = (0..n).map(|i| m[i * n + i] * m[i * n + i]).sum();
        if off <= 1e-30 * diag || off == 0.0 {
            break;
        }
        for p in 0..n {
            for q in p + 1..n {
                let apq = m[p * n + q];
                if apq == 0.0 {
                    continue;
                }
                // The rotation that zeroes m[p][q] (Golub & Van Loan's symmetric Schur step).
                let theta = (m[q * n + q] - m[p * n + p]) / (2.0 * apq);
                let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
                let t = if theta == 0.0 { 1.0 } else { t };
                let c = 1.0 / (t * t + 1.0).sqrt();
                let s = t * c;
                for k in 0..n {
                    let (mkp, mkq) = (m[k * n + p], m[k * n + q]);
                    m[k * n + p] = c * mkp - s * mkq;
                    m[k * n + q] = s * mkp + c * mkq;
                }
                for k in 0..n {
                    let (mpk, mqk) = (m[p * n + k], m[q * n + k]);
                    m[p * n + k] = c * mpk - s * mqk;
                    m[q * n + k] = s * mpk + c * mqk;
                }
                for k in 0..n {
                    let (vkp, vkq) = (v[k * n + p], v[k * n + q]);
                    v[k * n + p] = c * vkp - s * vkq;
                    v[k * n + q] = s * vkp + c * vkq;
                }
            }
        }
    }
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&i, &j| m[j * n + j].total_cmp(&m[i * n + i]));
    let values = order.iter().map(|&k| m[k * n + k]).collect();
    let vectors = order
        .iter()
        .map(|&k| {
            let mut col: Vec<f64> = (0..n).map(|i| v[i * n + k]).collect();
            // A fixed sign (largest entry positive) makes the output reproducible.
            let big = col
                .iter()
                .copied()
                .fold(0.0f64, |b, x| if x.abs() > b.abs() { x } else { b });
            if big < 0.0 {
                col.iter_mut().for_each(|x| *x = -*x);
            }
            col
        })
        .collect();
    Ok((values, vectors))
}

/// The leading `components` principal components of `rows` (each a sample of D values).
///
/// Components beyond the data's rank (at most N − 1) have variance 0 and scores 0.
/// Errors: as [`centered_gram`], and `components` = 0.
pub fn pca(rows: &[&[f32]], components: usize) -> Result<Pca> {
    if components == 0 {
        return Err(VaeError::argument("PCA components", "must be at least 1"));
    }
    let gram = centered_gram(rows)?;
    pca_of_gram(&gram, rows.len(), components)
}

/// [`pca`] from the centred Gram matrix (so that one Gram serves PCA and t-SNE distances).
pub fn pca_of_gram(gram: &[f64], n: usize, components: usize) -> Result<Pca> {
    let (values, vectors) = symmetric_eigen(gram, n)?;
    let total_variance = (0..n).map(|i| gram[i * n + i]).sum::<f64>() / n as f64;
    let mut scores = vec![vec![0.0; components]; n];
    let mut variances = vec![0.0; components];
    for k in 0..components.min(n) {
        // Round-off can leave null eigenvalues slightly negative.
        let lambda = values[k].max(0.0);
        variances[k] = lambda / n as f64;
        let root = lambda.sqrt();
        for (i, row) in scores.iter_mut().enumerate() {
            row[k] = root * vectors[k][i];
        }
    }
    Ok(Pca {
        scores,
        variances,
        total_variance,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::numerics::rng::Rng;

    fn random_rows(n: usize, d: usize, seed: u64) -> Vec<Vec<f32>> {
        let mut r = Rng::new(seed);
        // Anisotropic: column j scaled by (j + 1) so the components are well separated.
        (0..n)
            .map(|_| {
                (0..d)
                    .map(|j| (r.normal() * (j as f64 + 1.0) + 3.0) as f32)
                    .collect()
            })
            .collect()
    }

    /// Brute force: the D × D covariance, its eigenvectors by power iteration with deflation.
    fn brute_force_axes(rows: &[Vec<f32>], k: usize) -> (Vec<f64>, Vec<Vec<f64>>, Vec<f64>) {
        let (n, d) = (rows.len(), rows[0].len());
        let mean: Vec<f64> = (0..d)
            .map(|j| rows.iter().map(|r| f64::from(r[j])).sum::<f64>() / n as f64)
            .collect();
        let mut cov = vec![vec![0.0; d]; d];
        for r in rows {
            for a in 0..d {
                for b in 0..d {
                    cov[a][b] += (f64::from(r[a]) - mean[a]) * (f64::from(r[b]) - mean[b]);
                }
            }
        }
        cov.iter_mut().flatten().for_each(|x| *x /= n as f64);
        let (mut values, mut axes) = (Vec::new(), Vec::new());
        for c in 0..k {
            let mut x: Vec<f64> = (0..d).map(|j| 1.0 + j as f64 * 0.1 + c as f64).collect();
            let mut lambda = 0.0;
            for _ in 0..5000 {
                let mut y: Vec<f64> = (0..d)
                    .map(|a| (0..d).map(|b| cov[a][b] * x[b]).sum())
                    .collect();
                let norm = y.iter().map(|v| v * v).sum::<f64>().sqrt();
                y.iter_mut().for_each(|v| *v /= norm);
                lambda = norm;
                x = y;
            }
            for a in 0..d {
                for b in 0..d {
                    cov[a][b] -= lambda * x[a] * x[b];
                }
            }
            values.push(lambda);
            axes.push(x);
        }
        (values, axes, mean)
    }

    #[test]
    fn jacobi_satisfies_the_eigen_equations() {
        let n = 7;
        let mut r = Rng::new(2);
        let mut a = vec![0.0; n * n];
        for i in 0..n {
            for j in 0..=i {
                let x = r.normal();
                a[i * n + j] = x;
                a[j * n + i] = x;
            }
        }
        let (values, vectors) = symmetric_eigen(&a, n).unwrap();
        assert!(values.windows(2).all(|w| w[0] >= w[1]));
        for (k, vk) in vectors.iter().enumerate() {
            for i in 0..n {
                let av: f64 = (0..n).map(|j| a[i * n + j] * vk[j]).sum();
                assert!((av - values[k] * vk[i]).abs() < 1e-10, "A v ≠ λ v");
            }
            for (l, vl) in vectors.iter().enumerate() {
                let dot: f64 = vk.iter().zip(vl).map(|(x, y)| x * y).sum();
                let want = if k == l { 1.0 } else { 0.0 };
                assert!((dot - want).abs() < 1e-10, "not orthonormal");
            }
        }
        // Trace is the sum of the eigenvalues; a known 2 × 2 case.
        let trace: f64 = (0..n).map(|i| a[i * n + i]).sum();
        assert!((values.iter().sum::<f64>() - trace).abs() < 1e-10);
        let (v2, _) = symmetric_eigen(&[2.0, 1.0, 1.0, 2.0], 2).unwrap();
        assert!((v2[0] - 3.0).abs() < 1e-12 && (v2[1] - 1.0).abs() < 1e-12);
        assert!(symmetric_eigen(&[1.0, 2.0, 0.0, 1.0], 2).is_err());
        assert!(symmetric_eigen(&[1.0, 2.0, 3.0], 2).is_err());
    }

    #[test]
    fn pca_matches_the_brute_force_covariance_decomposition() {
        // Both regimes: fewer rows than columns (the Gram path's purpose) and more.
        for (n, d) in [(6, 12), (12, 4)] {
            let rows = random_rows(n, d, n as u64);
            let refs: Vec<&[f32]> = rows.iter().map(Vec::as_slice).collect();
            let p = pca(&refs, 3).unwrap();
            let (values, axes, mean) = brute_force_axes(&rows, 3);
            for k in 0..3 {
                assert!(
                    (p.variances[k] - values[k]).abs() < 1e-8 * values[0],
                    "variance {k}: {} vs {}",
                    p.variances[k],
                    values[k]
                );
                // Scores equal the projections on the axes, up to one sign per component.
                let proj: Vec<f64> = rows
                    .iter()
                    .map(|r| {
                        (0..d)
                            .map(|j| (f64::from(r[j]) - mean[j]) * axes[k][j])
                            .sum()
                    })
                    .collect();
                let sign = if proj[0] * p.scores[0][k] < 0.0 {
                    -1.0
                } else {
                    1.0
                };
                for (i, pi) in proj.iter().enumerate() {
                    assert!(
                        (p.scores[i][k] - sign * pi).abs() < 1e-6,
                        "score ({i}, {k})"
                    );
                }
            }
            let total: f64 = (0..d)
                .map(|j| {
                    rows.iter()
                        .map(|r| (f64::from(r[j]) - mean[j]).powi(2))
                        .sum::<f64>()
                })
                .sum::<f64>()
                / n as f64;
            assert!((p.total_variance - total).abs() < 1e-8 * total);
            assert!(p.explained(0) > p.explained(1) && p.explained(0) < 1.0);
        }
    }

    #[test]
    fn gram_distances_and_degenerate_inputs() {
        let rows = random_rows(5, 3, 9);
        let refs: Vec<&[f32]> = rows.iter().map(Vec::as_slice).collect();
        let g = centered_gram(&refs).unwrap();
        let d = distances_from_gram(&g, 5);
        for i in 0..5 {
            for j in 0..5 {
                let want: f64 = (0..3)
                    .map(|k| (f64::from(rows[i][k]) - f64::from(rows[j][k])).powi(2))
                    .sum();
                assert!((d[i * 5 + j] - want).abs() < 1e-9 * want.max(1.0));
            }
        }
        // Identical rows: zero variance, no NaN; rank-limited components are zero.
        let same = [[1.0f32, 2.0].as_slice(), [1.0, 2.0].as_slice()];
        let p = pca(&same, 3).unwrap();
        assert_eq!(p.variances, vec![0.0; 3]);
        assert_eq!(p.explained(0), 0.0);
        assert!(pca(&[], 2).is_err());
        assert!(pca(&refs, 0).is_err());
        let ragged = [[1.0f32, 2.0].as_slice(), [1.0].as_slice()];
        assert!(pca(&ragged, 1).unwrap_err().to_string().contains("row 1"));
        let nan = [[f32::NAN, 2.0].as_slice()];
        assert!(pca(&nan, 1).unwrap_err().to_string().contains("non-finite"));
    }
}
