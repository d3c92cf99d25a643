//! A cache-friendly vertex order (reverse Cuthill–McKee) for graphs whose vertex numbering has
//! little locality.
//!
//! Why: a sparse product gathers the feature rows of each vertex's neighbours. When neighbours
//! have distant indices (elephant-gallop: half of its edges join vertices more than 78 indices
//! apart, a tenth more than 21,000), every gather misses the cache and each row is fetched from
//! memory once per neighbour instead of once. Renumbering the template's vertices by
//! [`locality_order`] (once, before building the hierarchy and the features) keeps neighbours
//! within a narrow band of indices.

use crate::check;
use crate::error::{ConvError, Result};
use sparse_csr::CsrMatrix;
use std::collections::VecDeque;

/// The reverse Cuthill–McKee order of a square matrix's pattern (symmetrised): `order[p]` is the
/// old index of the vertex placed at position p. Each connected component is started from a
/// pseudo-peripheral vertex (the end of a breadth-first search from a vertex of least degree).
pub fn locality_order(pattern: &CsrMatrix) -> Result<Vec<u32>> {
    let n = pattern.rows();
    check::square("locality_order", "pattern", n, pattern.cols())?;
    Ok(rcm(n, |r| pattern.row(r).0))
}

/// [`locality_order`] of the pattern whose row `r` has the columns `row(r)` (n × n).
pub(crate) fn rcm<'a>(n: usize, row: impl Fn(usize) -> &'a [u32]) -> Vec<u32> {
    // Symmetrised neighbour lists without self-loops.
    let mut neighbours: Vec<Vec<u32>> = vec![Vec::new(); n];
    for r in 0..n {
        for &c in row(r) {
            if c as usize != r {
                neighbours[r].push(c);
                neighbours[c as usize].push(r as u32);
            }
        }
    }
    for list in &mut neighbours {
        list.sort_unstable();
        list.dedup();
    }
    let degree = |v: u32| neighbours[v as usize].len();
    let mut placed = vec![false; n];
    let mut order: Vec<u32> = Vec::with_capacity(n);
    let mut by_degree: Vec<u32> = (0..n as u32).collect();
    by_degree.sort_by_key(|&v| (degree(v), v));
    let mut scratch = vec![false; n];
    for &seed in &by_degree {
        if placed[seed as usize] {
            continue;
        }
        // Pseudo-peripheral start: the last vertex reached by a search from the seed.
        let far = bfs(seed, &neighbours, &placed, &mut scratch, |_| {});
        let start = far.unwrap_or(seed);
        let first = order.len();
        bfs(start, &neighbours, &placed, &mut scratch, |v| order.push(v));
        for &v in &order[first..] {
            placed[v as usize] = true;
        }
    }
    order.reverse();
    order
}

/// Breadth-first search from `start` over unplaced vertices, neighbours in increasing degree;
/// calls `visit` in visiting order and returns the last vertex visited. `seen` is scratch space
/// (all false on entry and on return).
fn bfs(
    start: u32,
    neighbours: &[Vec<u32>],
    placed: &[bool],
    seen: &mut [bool],
    mut visit: impl FnMut(u32),
) -> Option<u32> {
    let mut queue = VecDeque::from([start]);
    let mut visited = vec![start];
    seen[start as usize] = true;
    let mut next: Vec<u32> = Vec::new();
    while let Some(v) = queue.pop_front() {
        visit(v);
        next.clear();
        next.extend(
            neighbours[v as usize]
                .iter()
                .copied()
                .filter(|&u| !seen[u as usize] && !placed[u as usize]),
        );
        next.sort_by_key(|&u| (neighbours[u as usize].len(), u));
        for &u in &next {
            seen[u as usize] = true;
            visited.push(u);
            queue.push_back(u);
        }
    }
    let last = visited.last().copied();
    for v in visited {
        seen[v as usize] = false;
    }
    last
}

/// P A Pᵀ for the order of [`locality_order`]: entry (p, q) is `A[order[p], order[q]]`.
pub fn permute_symmetric(matrix: &CsrMatrix, order: &[u32]) -> Result<CsrMatrix> {
    let n = matrix.rows();
    let position = inverse_order(order, n)?;
    check::square("permute_symmetric", "matrix", n, matrix.cols())?;
    let mut triplets = Vec::with_capacity(matrix.nnz());
    for r in 0..n {
        let (cols, vals) = matrix.row(r);
        for (&c, &v) in cols.iter().zip(vals) {
            triplets.push((position[r], position[c as usize], v));
        }
    }
    CsrMatrix::from_triplets(n, n, &triplets)
        .map_err(|e| ConvError::argument("permute_symmetric", "matrix", e.to_string()))
}

/// `position[old] = new` for an order `order[new] = old`, checking it is a permutation of 0..n.
pub fn inverse_order(order: &[u32], n: usize) -> Result<Vec<u32>> {
    positions(order, n, ("inverse_order", "order"))
}

/// [`inverse_order`], its error naming the calling method and argument (`op`, `arg`).
pub(crate) fn positions(
    order: &[u32],
    n: usize,
    (op, arg): (&'static str, &'static str),
) -> Result<Vec<u32>> {
    let bad = || {
        ConvError::argument(
            op,
            arg,
            format!("is not a permutation of 0..{n} ({} entries)", order.len()),
        )
    };
    if order.len() != n {
        return Err(bad());
    }
    let mut position = vec![u32::MAX; n];
    for (p, &v) in order.iter().enumerate() {
        let slot = position.get_mut(v as usize).ok_or_else(bad)?;
        if *slot != u32::MAX {
            return Err(bad());
        }
        *slot = p as u32;
    }
    Ok(position)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_util::{Rng, adjacency, grid_faces};

    /// The largest |position(i) − position(j)| over the edges.
    fn bandwidth(adj: &CsrMatrix, position: &[u32]) -> u32 {
        (0..adj.rows())
            .flat_map(|r| adj.row(r).0.iter().map(move |&c| (r, c)))
            .map(|(r, c)| position[r].abs_diff(position[c as usize]))
            .max()
            .unwrap_or(0)
    }

    #[test]
    fn reordering_a_shuffled_grid_restores_a_narrow_band() {
        let (rows, cols) = (12, 9);
        let n = rows * cols;
        // Shuffle the vertex numbering of a grid mesh.
        let mut shuffle: Vec<u32> = (0..n as u32).collect();
        let mut rng = Rng::new(3);
        for i in (1..n).rev() {
            let j = ((rng.next() + 1.0) / 2.0 * (i + 1) as f64) as usize % (i + 1);
            shuffle.swap(i, j);
        }
        let faces: Vec<[u32; 3]> = grid_faces(rows, cols)
            .iter()
            .map(|f| f.map(|v| shuffle[v as usize]))
            .collect();
        let adj = adjacency(n, &faces);
        let identity: Vec<u32> = (0..n as u32).collect();
        let order = locality_order(&adj).unwrap();
        let position = inverse_order(&order, n).unwrap();
        assert!(bandwidth(&adj, &identity) > 50);
        // A grid's natural band is about one row of vertices.
        assert!(
            bandwidth(&adj, &position) <= 2 * cols as u32,
            "{}",
            bandwidth(&adj, &position)
        );
        let permuted = permute_symmetric(&adj, &order).unwrap();
        let (dense, pdense) = (adj.to_dense(), permuted.to_dense());
        for p in 0..n {
            for q in 0..n {
                assert_eq!(pdense[p][q], dense[order[p] as usize][order[q] as usize]);
            }
        }
        assert!(inverse_order(&[0, 0, 1], 3).is_err());
        assert!(inverse_order(&[0, 3, 1], 3).is_err());
    }

    #[test]
    fn every_component_and_isolated_vertex_is_placed_once() {
        // Two triangles apart plus isolated vertices 6 and 7.
        let adj = adjacency(8, &[[0, 1, 2], [3, 4, 5]]);
        let mut order = locality_order(&adj).unwrap();
        order.sort_unstable();
        assert_eq!(order, (0..8).collect::<Vec<u32>>());
    }
}
