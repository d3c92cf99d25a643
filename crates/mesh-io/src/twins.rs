//! Meshes of a set that are one shape: [`MeshSet::shape_groups`].
//!
//! Why: a cyclic animation is sometimes stored twice (horse-gallop's 48 frames are one 24-frame
//! gallop cycle repeated, each copy translated forward; elephant-gallop's too, but for its last
//! frame). A random train/test split of such a set puts the twin of most test meshes in the
//! training half, so "unseen" errors are largely errors on seen shapes; splitting by group avoids
//! that.

use crate::error::{MeshIoError, Result};
use crate::mesh::{MeshSet, Point};

/// Which meshes of a set share one shape (up to translation): `group(i)` numbers the groups in
/// order of their first mesh.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ShapeGroups {
    of: Vec<usize>,
    count: usize,
}

impl ShapeGroups {
    /// The tolerance [`MeshSet::shape_groups`] is meant to be called with: an RMS difference of
    /// 1e-4 bounding-box diagonals. Twins in the gallop sets differ by < 5e-6 diagonals (float
    /// rounding of the translated copies), consecutive frames by > 5e-3.
    pub const DEFAULT_TOLERANCE: f64 = 1e-4;

    /// Every mesh its own group.
    pub fn singletons(n: usize) -> Self {
        Self {
            of: (0..n).collect(),
            count: n,
        }
    }

    /// The group of mesh `i`.
    pub fn group(&self, i: usize) -> usize {
        self.of[i]
    }

    /// Number of groups.
    pub fn len(&self) -> usize {
        self.count
    }

    /// Whether there are no meshes.
    pub fn is_empty(&self) -> bool {
        self.count == 0
    }

    /// Whether some shape occurs more than once.
    pub fn has_repeats(&self) -> bool {
        self.count < self.of.len()
    }

    /// The meshes of each group, in order.
    pub fn members(&self) -> Vec<Vec<usize>> {
        let mut out = vec![Vec::new(); self.count];
        for (i, &g) in self.of.iter().enumerate() {
            out[g].push(i);
        }
        out
    }
}

impl MeshSet {
    /// Groups the meshes whose shapes coincide once their centroids are aligned: the RMS of the
    /// per-vertex differences at most `rel_tol` times the first mesh's bounding-box diagonal
    /// (see [`ShapeGroups::DEFAULT_TOLERANCE`]). Each mesh joins the group of the first earlier
    /// mesh it matches.
    ///
    /// Errors: `rel_tol` negative or not finite (a NaN bound would merge every mesh).
    pub fn shape_groups(&self, rel_tol: f64) -> Result<ShapeGroups> {
        if !(rel_tol.is_finite() && rel_tol >= 0.0) {
            return Err(MeshIoError::InvalidArgument {
                argument: "shape tolerance",
                message: format!("{rel_tol} is not a finite number ≥ 0"),
            });
        }
        let centred: Vec<Vec<[f64; 3]>> = self.frames().map(centre).collect();
        let v = self.vertex_count().max(1) as f64;
        let tol = rel_tol * self.template().bbox_diagonal();
        // Compared as sums of squares, so a pair can stop as soon as it exceeds the bound.
        let bound = tol * tol * 3.0 * v;
        let mut of: Vec<Option<usize>> = vec![None; self.len()];
        let mut count = 0;
        for i in 0..self.len() {
            if of[i].is_some() {
                continue;
            }
            of[i] = Some(count);
            for j in i + 1..self.len() {
                if of[j].is_none() && within(&centred[i], &centred[j], bound) {
                    of[j] = Some(count);
                }
            }
            count += 1;
        }
        Ok(ShapeGroups {
            of: of.into_iter().map(|g| g.unwrap_or(0)).collect(),
            count,
        })
    }
}

fn centre(frame: &[Point]) -> Vec<[f64; 3]> {
    let n = frame.len().max(1) as f64;
    let mut c = [0.0f64; 3];
    for p in frame {
        for k in 0..3 {
            c[k] += f64::from(p[k]) / n;
        }
    }
    frame
        .iter()
        .map(|p| std::array::from_fn(|k| f64::from(p[k]) - c[k]))
        .collect()
}

/// Σ‖a − b‖² ≤ bound, stopping early once it is exceeded.
fn within(a: &[[f64; 3]], b: &[[f64; 3]], bound: f64) -> bool {
    let mut sum = 0.0;
    for (block_a, block_b) in a.chunks(256).zip(b.chunks(256)) {
        for (p, q) in block_a.iter().zip(block_b) {
            sum += (0..3).map(|k| (p[k] - q[k]).powi(2)).sum::<f64>();
        }
        if sum > bound {
            return false;
        }
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::TriMesh;

    fn set(frames: &[Vec<Point>]) -> MeshSet {
        let faces = vec![[0, 1, 2], [0, 2, 3]];
        let meshes = frames
            .iter()
            .map(|p| TriMesh::new(p.clone(), faces.clone()).unwrap())
            .collect();
        let names = (0..frames.len()).map(|i| format!("m{i}")).collect();
        MeshSet::from_meshes(meshes, names).unwrap()
    }

    #[test]
    fn translated_copies_group_and_small_deformations_do_not() {
        let base: Vec<Point> = vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, 0.0],
            [0.0, 1.0, 0.0],
        ];
        let moved = |d: [f32; 3]| {
            base.iter()
                .map(|p| [p[0] + d[0], p[1] + d[1], p[2] + d[2]])
                .collect::<Vec<_>>()
        };
        let mut bent = base.clone();
        // 1e-2 of a unit: far above 1e-4 diagonals (√2 · 1e-4).
        bent[2][2] = 0.01;
        let mut rounding = moved([5.0, 0.0, 0.0]);
        rounding[1][1] += 1e-6;
        let s = set(&[
            base.clone(),
            bent.clone(),
            moved([3.0, -2.0, 7.0]),
            rounding,
            moved([0.0, 0.0, 1.0]),
        ]);
        let g = s.shape_groups(ShapeGroups::DEFAULT_TOLERANCE).unwrap();
        assert_eq!(g.members(), vec![vec![0, 2, 3, 4], vec![1]]);
        assert!(g.has_repeats() && g.len() == 2 && g.group(3) == 0);
        // A looser tolerance merges the bent mesh too; a tighter one separates nothing new.
        assert_eq!(s.shape_groups(1e-1).unwrap().len(), 1);
        assert_eq!(s.shape_groups(1e-9).unwrap().len(), 3);
        let distinct = set(&[base, bent]);
        assert!(
            !distinct
                .shape_groups(ShapeGroups::DEFAULT_TOLERANCE)
                .unwrap()
                .has_repeats()
        );
        assert_eq!(
            ShapeGroups::singletons(3).members(),
            vec![vec![0], vec![1], vec![2]]
        );
        for bad in [f64::NAN, -1e-4, f64::INFINITY] {
            let err = s.shape_groups(bad).unwrap_err().to_string();
            assert!(err.contains("shape tolerance"), "{err}");
        }
    }
}
