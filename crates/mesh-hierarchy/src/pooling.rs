//! Pooling and de-pooling operators between two levels, and the names of the poolers compared
//! in the paper's ablation.

use crate::error::HierarchyError;
use serde::{Deserialize, Serialize};
use sparse_csr::CsrMatrix;
use std::fmt;
use std::str::FromStr;

/// Which pooling a hierarchy uses (the paper's ablation, Table 3): the one user-facing choice,
/// from the command line (`--pool`) through the model's configuration to the hierarchy's
/// operators, which carry how they are applied ([`PoolingOp::mode`]) so that no later stage
/// decides it again. Names: `mean` (or `ours`), `max`, `qem`, `sampling`, `none`, `graph`,
/// `remesh`.
///
/// The two poolers added last, for the table's "Graph Pooling" and "Uniform Simp." columns:
///
/// **Graph pooling** ([`Pooler::Graph`]; Shen et al. 2018, KCNet). The coarse vertex set and
/// coarse mesh are exactly those of [`Pooler::Mean`] (modified QEM, λ = 0.001: the simplifier's
/// `survivors` and `coarse`). Coarse vertex c, with survivor s_c, pools over its neighbourhood
/// N(c) = the closed one-ring of s_c on the fine graph ∪ the QEM cluster of c; the clusters
/// partition the fine vertices, so every fine vertex is in some N(c).
/// - Pool: `y[c, ch] = max over u ∈ N(c) of x[u, ch]` — the plain channel-wise max, as KCNet
///   (not the signed largest magnitude of [`Pooler::Max`]); ties go to the lowest fine index.
///   The gradient goes to the selected element, summed where one fine vertex is selected by
///   several coarse vertices (the neighbourhoods overlap).
/// - De-pool: `fine[v] = mean over {c : v ∈ N(c)} of coarse[c]`, a sparse n×m matrix whose
///   rows sum to 1 (the configured [`DepoolMode`] does not apply).
///
/// Why this is a fair reading of the column: KCNet pools a point cloud by taking, for each
/// point of a subsample, the max over its kNN neighbourhood on a graph of the points. Here the
/// graph is the mesh itself (its one-rings are the natural neighbourhoods) and the subsample is
/// our survivors, so the coarse level, the convolutions and everything else equal ours; the
/// only difference to our pooling is max over overlapping neighbourhoods instead of mean over a
/// partition. Adding the cluster to the one-ring only guarantees that no fine vertex is
/// ignored.
///
/// **Uniform remeshing** ([`Pooler::Remesh`]). The coarse level is
/// `qem_simplify::remesh` of the fine mesh to `ratio` of its vertices (a uniform, isotropic
/// remeshing, the paper's `\cite{remesh}`), which also returns each fine vertex's coarse
/// vertex; pooling is the mean over those clusters and de-pooling copies (or is Pᵀ, as the
/// configured [`DepoolMode`]), i.e. exactly [`Pooler::Mean`]'s operators on another coarse
/// level.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Pooler {
    /// The paper's: simplification with the edge-length term (λ = 0.001) and mean pooling.
    /// Parsed from `mean` or `ours` (the name hierarchy files written before the two choices
    /// were one still carry).
    #[default]
    #[serde(alias = "ours")]
    Mean,
    /// The paper's simplification with max pooling (signed largest magnitude per cluster).
    Max,
    /// Classical QEM (λ = 0), same mean pooling.
    Qem,
    /// Ranjan et al. 2018 (CoMA): keep the survivors of classical QEM, up-sample by barycentric
    /// coordinates in the nearest coarse triangle.
    Sampling,
    /// No pooling: identity operators, every level is the template.
    None,
    /// Graph max pooling (Shen et al. 2018) over overlapping neighbourhoods of our survivors;
    /// see the type's documentation.
    Graph,
    /// Uniform remeshing with mean pooling; see the type's documentation.
    Remesh,
}

impl Pooler {
    /// All poolers: the ablation's original five first, then graph pooling and remeshing.
    pub const ALL: [Pooler; 7] = [
        Self::Mean,
        Self::Max,
        Self::Qem,
        Self::Sampling,
        Self::None,
        Self::Graph,
        Self::Remesh,
    ];

    /// The simplifier's λ for this pooler (`None` for the poolers that do not run the
    /// simplifier: no pooling and remeshing).
    pub fn lambda(self) -> Option<f64> {
        match self {
            Self::Mean | Self::Max | Self::Graph => Some(qem_simplify::DEFAULT_LAMBDA),
            Self::Qem | Self::Sampling => Some(0.0),
            Self::None | Self::Remesh => Option::None,
        }
    }

    /// How this pooler's operators are applied to features: the one place that decides it.
    pub fn mode(self) -> PoolMode {
        match self {
            // Remeshing only changes the coarse level: its operators are mean pooling's.
            Self::Mean | Self::Qem | Self::Remesh => PoolMode::Mean,
            Self::Max => PoolMode::SignedMax,
            Self::Graph => PoolMode::PlainMax,
            Self::Sampling => PoolMode::Sampling,
            Self::None => PoolMode::Identity,
        }
    }
}

/// How a [`PoolingOp`] is applied to features, decided by its [`Pooler`] ([`Pooler::mode`]).
/// De-pooling is always `depool · coarse`, except for [`PoolMode::Identity`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum PoolMode {
    /// `coarse = pool · fine`, the mean over each cluster (ours, classical QEM, remeshing).
    Mean,
    /// Per row of `pool`, the member of largest magnitude with its sign (ties: the negative
    /// one, as the authors' code): max pooling.
    SignedMax,
    /// Per row of `pool` (a neighbourhood), the largest value (ties: the lowest fine index):
    /// graph pooling.
    PlainMax,
    /// `coarse = pool · fine` keeps the survivors; de-pooling up-samples barycentrically.
    Sampling,
    /// Both operators are the identity (no pooling): nothing to compute.
    Identity,
}

impl fmt::Display for Pooler {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Mean => "mean",
            Self::Max => "max",
            Self::Qem => "qem",
            Self::Sampling => "sampling",
            Self::None => "none",
            Self::Graph => "graph",
            Self::Remesh => "remesh",
        })
    }
}

/// Why a pooler name was not recognised.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown pooler {0:?} (expected mean, max, qem, sampling, none, graph or remesh)")]
pub struct UnknownPooler(pub String);

impl FromStr for Pooler {
    type Err = UnknownPooler;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.to_ascii_lowercase().as_str() {
            "mean" | "ours" => Ok(Self::Mean),
            "qem" => Ok(Self::Qem),
            "max" => Ok(Self::Max),
            "sampling" => Ok(Self::Sampling),
            "none" => Ok(Self::None),
            "graph" => Ok(Self::Graph),
            "remesh" => Ok(Self::Remesh),
            _ => Err(UnknownPooler(s.to_owned())),
        }
    }
}

/// How mean de-pooling spreads a coarse value over its cluster.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub enum DepoolMode {
    /// Copy the coarse value to every member: D[v, c] = 1, so P·D = I.
    #[default]
    Copy,
    /// The authors' code: D = Pᵀ, the coarse value divided by the cluster size (their
    /// de-pooling multiplies by the pooling matrix's transpose).
    Transpose,
}

/// Why a de-pooling mode name was not recognised.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown de-pooling mode {0:?} (expected copy or transpose)")]
pub struct UnknownDepoolMode(pub String);

impl FromStr for DepoolMode {
    type Err = UnknownDepoolMode;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.to_ascii_lowercase().as_str() {
            "copy" => Ok(Self::Copy),
            "transpose" => Ok(Self::Transpose),
            _ => Err(UnknownDepoolMode(s.to_owned())),
        }
    }
}

impl fmt::Display for DepoolMode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Copy => "copy",
            Self::Transpose => "transpose",
        })
    }
}

/// The operators from one level (fine, n vertices) to the next (coarse, m vertices).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PoolingOp {
    /// Which pooler built it.
    pub kind: Pooler,
    /// m×n: coarse = pool · fine (mean pooling, or selection for sampling). For `Max` this is
    /// the mean matrix too, and for `Graph` the mean over each neighbourhood N(c) (its pattern
    /// is the membership: row c's columns are N(c)); [`PoolingOp::pool`] applies the max over
    /// each row's columns instead.
    pub pool: CsrMatrix,
    /// n×m: fine = depool · coarse (copy, Pᵀ, barycentric up-sampling, or for `Graph` the mean
    /// over the neighbourhoods containing the fine vertex).
    pub depool: CsrMatrix,
    /// Members (fine indices, ascending) of each coarse vertex's cluster (for `Graph`, the
    /// simplifier's clusters that the neighbourhoods extend); `None` for sampling and no
    /// pooling.
    pub clusters: Option<Vec<Vec<u32>>>,
}

impl PoolingOp {
    /// Identity operators on n vertices (the no-pooling ablation).
    pub fn identity(n: usize) -> Self {
        Self {
            kind: Pooler::None,
            pool: CsrMatrix::identity(n),
            depool: CsrMatrix::identity(n),
            clusters: Option::None,
        }
    }

    /// Mean pooling (and max, for `kind == Max`) over the clusters given by `cluster_of`
    /// (fine → coarse, every coarse index in 0..coarse_count used): the operators of `ours`,
    /// `qem`, `max` and `remesh`.
    pub fn from_clusters(
        kind: Pooler,
        cluster_of: &[u32],
        coarse_count: usize,
        depool: DepoolMode,
    ) -> Result<Self, sparse_csr::CsrError> {
        let mut clusters = vec![Vec::new(); coarse_count];
        for (v, &c) in cluster_of.iter().enumerate() {
            let cluster = clusters.get_mut(c as usize).ok_or_else(|| {
                sparse_csr::CsrError(format!("cluster {c} beyond {coarse_count}"))
            })?;
            cluster.push(v as u32);
        }
        if let Some(c) = clusters.iter().position(Vec::is_empty) {
            return Err(sparse_csr::CsrError(format!("cluster {c} is empty")));
        }
        let mut pool_t = Vec::with_capacity(cluster_of.len());
        let mut depool_t = Vec::with_capacity(cluster_of.len());
        for (c, members) in clusters.iter().enumerate() {
            let w = 1.0 / members.len() as f64;
            for &v in members {
                pool_t.push((c as u32, v, w));
                let d = match depool {
                    DepoolMode::Copy => 1.0,
                    DepoolMode::Transpose => w,
                };
                depool_t.push((v, c as u32, d));
            }
        }
        let n = cluster_of.len();
        Ok(Self {
            kind,
            pool: CsrMatrix::from_triplets(coarse_count, n, &pool_t)?,
            depool: CsrMatrix::from_triplets(n, coarse_count, &depool_t)?,
            clusters: Some(clusters),
        })
    }

    /// How the operators are applied (from the pooler that built them).
    pub fn mode(&self) -> PoolMode {
        self.kind.mode()
    }

    /// Fine vertex count n.
    pub fn fine_count(&self) -> usize {
        self.pool.cols()
    }

    /// Coarse vertex count m.
    pub fn coarse_count(&self) -> usize {
        self.pool.rows()
    }

    /// Pools `channels` interleaved channels (`fine.len() == n · channels`, vertex-major):
    /// for `Max` the member of largest magnitude with its sign (ties: the negative one, as the
    /// authors' code), for `Graph` the largest value over the neighbourhood (ties: the lowest
    /// fine index), `pool · fine` otherwise. Errors when `fine` has not n · channels values.
    pub fn pool(&self, fine: &[f64], channels: usize) -> Result<Vec<f64>, HierarchyError> {
        check_len("fine", fine, self.fine_count(), channels)?;
        Ok(match self.mode() {
            PoolMode::SignedMax | PoolMode::PlainMax => self.select(fine, channels).0,
            _ => apply(&self.pool, fine, channels),
        })
    }

    /// The gradient of [`Self::pool`] at `fine`: ∂⟨upstream, pool(fine)⟩/∂fine, `[n, channels]`
    /// for `upstream` `[m, channels]`. For `Max` and `Graph` each upstream value goes to the
    /// selected fine value (summed where one is selected several times), otherwise it is
    /// poolᵀ · upstream. Errors when a slice has the wrong length.
    pub fn pool_gradient(
        &self,
        fine: &[f64],
        upstream: &[f64],
        channels: usize,
    ) -> Result<Vec<f64>, HierarchyError> {
        check_len("fine", fine, self.fine_count(), channels)?;
        check_len("upstream", upstream, self.coarse_count(), channels)?;
        Ok(match self.mode() {
            PoolMode::SignedMax | PoolMode::PlainMax => {
                let (_, picked) = self.select(fine, channels);
                let mut grad = vec![0.0; fine.len()];
                for (i, (&u, &g)) in picked.iter().zip(upstream).enumerate() {
                    if u != u32::MAX {
                        grad[u as usize * channels + i % channels] += g;
                    }
                }
                grad
            }
            _ => apply(&self.pool.transpose(), upstream, channels),
        })
    }

    /// Max-type pooling over the columns of each row of `pool` (signed magnitude for `Max`,
    /// plain for `Graph`): the values and the selected fine vertices (`u32::MAX`, value 0, for
    /// an empty row). Members are visited in ascending order and only a strictly better one
    /// replaces the best so far, so ties go to the lowest index.
    fn select(&self, fine: &[f64], channels: usize) -> (Vec<f64>, Vec<u32>) {
        let m = self.coarse_count();
        let mut out = vec![0.0; m * channels];
        let mut picked = vec![u32::MAX; m * channels];
        let signed = self.mode() == PoolMode::SignedMax;
        for c in 0..m {
            for k in 0..channels {
                let (best, at) = (&mut out[c * channels + k], &mut picked[c * channels + k]);
                for &v in self.pool.row(c).0 {
                    let (x, b): (f64, f64) = (fine[v as usize * channels + k], *best);
                    let better = *at == u32::MAX
                        || if signed {
                            x.abs() > b.abs() || (x.abs() == b.abs() && x < b)
                        } else {
                            x > b
                        };
                    if better {
                        *best = x;
                        *at = v;
                    }
                }
            }
        }
        (out, picked)
    }

    /// De-pools `channels` interleaved channels: `depool · coarse`. Errors when `coarse` has not
    /// m · channels values.
    pub fn depool(&self, coarse: &[f64], channels: usize) -> Result<Vec<f64>, HierarchyError> {
        check_len("coarse", coarse, self.coarse_count(), channels)?;
        Ok(apply(&self.depool, coarse, channels))
    }
}

fn check_len(
    argument: &'static str,
    x: &[f64],
    vertices: usize,
    channels: usize,
) -> Result<(), HierarchyError> {
    if Some(x.len()) == vertices.checked_mul(channels) {
        Ok(())
    } else {
        Err(HierarchyError::InvalidArgument {
            argument,
            message: format!(
                "{} values for {vertices} vertices × {channels} channels",
                x.len()
            ),
        })
    }
}

/// y = A x for `channels` interleaved columns (vertex-major).
fn apply(a: &CsrMatrix, x: &[f64], channels: usize) -> Vec<f64> {
    let mut y = vec![0.0; a.rows() * channels];
    for r in 0..a.rows() {
        let (cols, vals) = a.row(r);
        for (&c, &w) in cols.iter().zip(vals) {
            for k in 0..channels {
                y[r * channels + k] += w * x[c as usize * channels + k];
            }
        }
    }
    y
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip() {
        for p in Pooler::ALL {
            assert_eq!(p.to_string().parse::<Pooler>(), Ok(p));
            let json = serde_json::to_string(&p).unwrap();
            assert_eq!(json, format!("\"{p}\""));
        }
        assert_eq!("mean".parse::<Pooler>(), Ok(Pooler::Mean));
        assert!("avg".parse::<Pooler>().is_err());
    }

    #[test]
    fn max_pooling_takes_signed_largest_magnitude() {
        let op = PoolingOp::from_clusters(Pooler::Max, &[0, 1, 0, 1], 2, DepoolMode::Copy).unwrap();
        // two channels; cluster 0 = {0, 2}, cluster 1 = {1, 3}
        let fine = [1.0, -2.0, 5.0, 0.5, -3.0, 2.0, 4.0, -0.5];
        assert!(op.pool(&fine, 3).is_err());
        assert_eq!(op.pool(&fine, 2).unwrap(), vec![-3.0, -2.0, 5.0, -0.5]);
        assert!(PoolingOp::from_clusters(Pooler::Mean, &[0, 2], 2, DepoolMode::Copy).is_err());
        assert!(PoolingOp::from_clusters(Pooler::Mean, &[0, 0], 2, DepoolMode::Copy).is_err());
    }
}
