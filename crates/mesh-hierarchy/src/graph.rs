//! Graph pooling (Shen et al. 2018, KCNet) on a mesh: the neighbourhoods N(c) of the coarse
//! vertices and the operators built from them (see [`crate::Pooler::Graph`] for the definition
//! and why it is a fair reading of the paper's "Graph Pooling" column).
//!
//! N(c) = closed one-ring of the survivor s_c on the fine graph ∪ the cluster of c. The clusters
//! partition the fine vertices, so every fine vertex is in at least one N(c); one-rings overlap,
//! so most are in several.

use crate::error::HierarchyError;
use crate::laplacian::try_adjacency;
use crate::pooling::{Pooler, PoolingOp};
use mesh_io::Face;
use sparse_csr::CsrMatrix;

/// The m×n membership matrix of the neighbourhoods: M[c, u] = 1 for u ∈ N(c) (columns
/// ascending), for the fine mesh's `faces`, the simplifier's `survivors` (coarse → fine) and
/// `cluster_of` (fine → coarse; n = its length).
///
/// Errors: a face, survivor or cluster index out of range (naming it).
pub fn neighbourhoods(
    faces: &[Face],
    survivors: &[u32],
    cluster_of: &[u32],
) -> Result<CsrMatrix, HierarchyError> {
    let (n, m) = (cluster_of.len(), survivors.len());
    if let Some((c, &s)) = survivors
        .iter()
        .enumerate()
        .find(|(_, s)| **s as usize >= n)
    {
        return Err(HierarchyError::InvalidArgument {
            argument: "survivors",
            message: format!("coarse vertex {c} survives as fine vertex {s}, beyond {n}"),
        });
    }
    if let Some((v, &c)) = cluster_of
        .iter()
        .enumerate()
        .find(|(_, c)| **c as usize >= m)
    {
        return Err(HierarchyError::InvalidArgument {
            argument: "cluster_of",
            message: format!("fine vertex {v} maps to coarse vertex {c}, beyond {m}"),
        });
    }
    let adjacency = try_adjacency(n, faces)?;
    let mut triplets: Vec<(u32, u32, f64)> = Vec::with_capacity(8 * m + n);
    for (c, &s) in survivors.iter().enumerate() {
        triplets.push((c as u32, s, 1.0));
        triplets.extend(
            adjacency
                .row(s as usize)
                .0
                .iter()
                .map(|&u| (c as u32, u, 1.0)),
        );
    }
    triplets.extend(
        cluster_of
            .iter()
            .enumerate()
            .map(|(v, &c)| (c, v as u32, 1.0)),
    );
    // A member reached twice (the survivor is in its own cluster and one-ring) is one member.
    triplets.sort_unstable_by_key(|t| (t.0, t.1));
    triplets.dedup_by_key(|t| (t.0, t.1));
    Ok(CsrMatrix::from_triplets(m, n, &triplets)?)
}

impl PoolingOp {
    /// Graph pooling's operators from the modified-QEM simplification of the fine mesh (its
    /// `faces`, `survivors` and `cluster_of`; see [`neighbourhoods`]):
    /// - `pool` (m×n): 1/|N(c)| at the members of N(c). Its pattern is the membership; its
    ///   values make it the neighbourhood mean for consumers that need a matrix, while
    ///   [`PoolingOp::pool`] (and the model) take the channel-wise max over N(c).
    /// - `depool` (n×m): `fine[v] = mean over {c : v ∈ N(c)} of coarse[c]` (rows sum to 1).
    /// - `clusters`: the simplifier's clusters (the partition N(c) extends).
    pub fn graph(
        faces: &[Face],
        survivors: &[u32],
        cluster_of: &[u32],
    ) -> Result<Self, HierarchyError> {
        let members = neighbourhoods(faces, survivors, cluster_of)?;
        let (n, m) = (members.cols(), members.rows());
        let mut pool = Vec::with_capacity(members.nnz());
        let mut covers = vec![0usize; n];
        for c in 0..m {
            let cols = members.row(c).0;
            let w = 1.0 / cols.len() as f64;
            for &u in cols {
                pool.push((c as u32, u, w));
                covers[u as usize] += 1;
            }
        }
        let depool: Vec<(u32, u32, f64)> = pool
            .iter()
            .map(|&(c, u, _)| (u, c, 1.0 / covers[u as usize] as f64))
            .collect();
        let mut clusters = vec![Vec::new(); m];
        for (v, &c) in cluster_of.iter().enumerate() {
            clusters[c as usize].push(v as u32);
        }
        Ok(Self {
            kind: Pooler::Graph,
            pool: CsrMatrix::from_triplets(m, n, &pool)?,
            depool: CsrMatrix::from_triplets(n, m, &depool)?,
            clusters: Some(clusters),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A strip of 6 triangles:
    /// ```text
    /// 0---1---2---3
    /// | \ | \ | \ |
    /// 4---5---6---7
    /// ```
    /// coarse 0 = survivor 2 with cluster {2, 3, 7}, coarse 1 = survivor 4 with {0, 1, 4},
    /// coarse 2 = survivor 5 with {5, 6}.
    fn strip() -> (Vec<Face>, Vec<u32>, Vec<u32>) {
        let faces = vec![
            [0, 4, 5],
            [0, 5, 1],
            [1, 5, 6],
            [1, 6, 2],
            [2, 6, 7],
            [2, 7, 3],
        ];
        (faces, vec![2, 4, 5], vec![1, 1, 0, 0, 1, 2, 2, 0])
    }

    #[test]
    fn neighbourhoods_of_a_strip_by_hand() {
        let (faces, survivors, cluster_of) = strip();
        let members = neighbourhoods(&faces, &survivors, &cluster_of).unwrap();
        // One-rings: 2 → {1, 3, 6, 7}, 4 → {0, 5}, 5 → {0, 1, 4, 6}; vertex 1 reaches N(1)
        // only through the cluster.
        assert_eq!(members.row(0).0, [1, 2, 3, 6, 7]);
        assert_eq!(members.row(1).0, [0, 1, 4, 5]);
        assert_eq!(members.row(2).0, [0, 1, 4, 5, 6]);
        assert!(members.values().iter().all(|&v| v == 1.0));

        let op = PoolingOp::graph(&faces, &survivors, &cluster_of).unwrap();
        assert_eq!(op.kind, Pooler::Graph);
        // Two channels: the first has a tie (3 at vertices 0 and 4) and vertex 6 is the max of
        // two neighbourhoods; the second is all negative (a plain max, not the largest
        // magnitude).
        let x = [
            3.0, -5.0, -1.0, -2.0, 0.5, -8.0, 2.0, -1.0, 3.0, -3.0, -4.0, -9.0, 7.0, -6.0, 1.0,
            -7.0,
        ];
        assert_eq!(op.pool(&x, 2).unwrap(), [7.0, -1.0, 3.0, -2.0, 7.0, -2.0]);
        // The gradient goes to the selected members and adds up at vertex 6 (picked twice);
        // the tie goes to the lowest index, vertex 0.
        let g = [1.0, 2.0, 10.0, 20.0, 100.0, 200.0];
        let dx = op.pool_gradient(&x, &g, 2).unwrap();
        let mut want = [0.0; 16];
        want[0] = 10.0; // vertex 0, channel 0
        want[12] = 101.0; // vertex 6, channel 0
        want[3] = 220.0; // vertex 1, channel 1
        want[7] = 2.0; // vertex 3, channel 1
        assert_eq!(dx, want);
        // De-pooling averages over the neighbourhoods containing each vertex.
        let (a, b, c) = (6.0, 12.0, 30.0);
        let want = [
            (b + c) / 2.0,
            (a + b + c) / 3.0,
            a,
            a,
            (b + c) / 2.0,
            (b + c) / 2.0,
            (a + c) / 2.0,
            a,
        ];
        let up = op.depool(&[a, b, c], 1).unwrap();
        assert!(
            up.iter().zip(&want).all(|(p, q)| (p - q).abs() < 1e-14),
            "{up:?}"
        );
        assert_eq!(op.clusters.as_ref().unwrap()[2], [5, 6]);
    }

    #[test]
    fn bad_indices_are_typed_errors() {
        let (faces, survivors, cluster_of) = strip();
        let err = neighbourhoods(&faces, &[2, 4, 8], &cluster_of).unwrap_err();
        assert!(err.to_string().contains("survivors"), "{err}");
        let err = neighbourhoods(&faces, &survivors, &[1, 1, 0, 0, 1, 2, 3, 0]).unwrap_err();
        assert!(err.to_string().contains("cluster_of"), "{err}");
        let err = neighbourhoods(&[[0, 1, 9]], &survivors, &cluster_of).unwrap_err();
        assert!(err.to_string().contains("faces"), "{err}");
    }
}
