//! Max pooling over member lists on flat slices: the kernels of [`crate::MaxPool`], for the
//! authors' signed-magnitude max pooling over clusters and for graph max pooling over
//! overlapping neighbourhoods (see [`MaxMode`]).

use crate::kernel::{CHUNK_ROWS, Csr, Madd, Real, multiversion};
use rayon::prelude::*;

/// What a [`crate::MaxPool`] selects among the members of a row.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum MaxMode {
    /// The member of largest magnitude, sign kept (the authors' max pooling). Ties in magnitude
    /// go to the negative value, then to the lowest vertex index.
    #[default]
    SignedMax,
    /// The largest value (KCNet's graph max pooling). Ties go to the lowest vertex index.
    PlainMax,
}

/// Max pooling over member lists: for every (b, p, ch), the member j of row p of `pattern`
/// (its columns, ascending; rows may overlap) selected by `mode` from x[b, j, ch]. Writes the
/// value to `out` `[B, P, c]` and j to `arg` (`u32::MAX` and 0 for an empty row).
pub(crate) fn max_pool<T: Real>(
    pattern: &Csr,
    x: &[T],
    out: &mut [T],
    arg: &mut [u32],
    c: usize,
    mode: MaxMode,
) {
    match mode {
        MaxMode::SignedMax => max_pool_with::<T, true>(pattern, x, out, arg, c),
        MaxMode::PlainMax => max_pool_with::<T, false>(pattern, x, out, arg, c),
    }
}

/// [`max_pool`] with the mode as a constant, so that the inner loop has no branch on it.
fn max_pool_with<T: Real, const SIGNED: bool>(
    pattern: &Csr,
    x: &[T],
    out: &mut [T],
    arg: &mut [u32],
    c: usize,
) {
    if c == 0 || pattern.rows() == 0 {
        return;
    }
    out.par_chunks_mut(CHUNK_ROWS * c)
        .zip(arg.par_chunks_mut(CHUNK_ROWS * c))
        .enumerate()
        .for_each(|(chunk, (out, arg))| {
            let rows = (pattern, chunk * CHUNK_ROWS);
            if SIGNED {
                max_chunk_signed(rows, x, out, arg, c);
            } else {
                max_chunk_plain(rows, x, out, arg, c);
            }
        });
}

multiversion!(
    fn max_chunk_plain<T>(
        rows: (&Csr, usize),
        x: &[T],
        out: &mut [T],
        arg: &mut [u32],
        c: usize,
    ) => max_chunk_plain_body
);

multiversion!(
    fn max_chunk_signed<T>(
        rows: (&Csr, usize),
        x: &[T],
        out: &mut [T],
        arg: &mut [u32],
        c: usize,
    ) => max_chunk_signed_body
);

#[inline(always)]
fn max_chunk_plain_body<T: Real, M: Madd>(
    rows: (&Csr, usize),
    x: &[T],
    out: &mut [T],
    arg: &mut [u32],
    c: usize,
) {
    max_chunk::<T, false>(rows, x, out, arg, c);
}

#[inline(always)]
fn max_chunk_signed_body<T: Real, M: Madd>(
    rows: (&Csr, usize),
    x: &[T],
    out: &mut [T],
    arg: &mut [u32],
    c: usize,
) {
    max_chunk::<T, true>(rows, x, out, arg, c);
}

/// One chunk of [`max_pool`]: output rows `first ..` (global row g = b·P + p) into `out` and
/// `arg`, `c` values each.
#[inline(always)]
fn max_chunk<T: Real, const SIGNED: bool>(
    (pattern, first): (&Csr, usize),
    x: &[T],
    out: &mut [T],
    arg: &mut [u32],
    c: usize,
) {
    let (rows, cols) = (pattern.rows(), pattern.cols());
    for (local, (y, am)) in out
        .chunks_exact_mut(c)
        .zip(arg.chunks_exact_mut(c))
        .enumerate()
    {
        let g = first + local;
        let (b, p) = (g / rows, g % rows);
        let xb = &x[b * cols * c..][..cols * c];
        let members = pattern.row::<T>(p).0;
        let Some((&j0, rest)) = members.split_first() else {
            y.fill(T::ZERO);
            am.fill(u32::MAX);
            continue;
        };
        // Blocks of LANES values, the members innermost, so that the running selection stays
        // in registers and y and arg are written once (a select whose false case keeps the
        // stored value compiles to a masked store, which is slow on some CPUs).
        let mut k0 = 0;
        while k0 < c {
            let lanes = MAX_LANES.min(c - k0);
            if lanes == MAX_LANES {
                let (best, at) = select_block::<T, SIGNED, MAX_LANES>(xb, (j0, rest), c, k0);
                y[k0..k0 + MAX_LANES].copy_from_slice(&best);
                am[k0..k0 + MAX_LANES].copy_from_slice(&at);
            } else {
                for k in k0..c {
                    let (best, at) = select_block::<T, SIGNED, 1>(xb, (j0, rest), c, k);
                    (y[k], am[k]) = (best[0], at[0]);
                }
            }
            k0 += lanes;
        }
    }
}

/// Values per block of [`max_chunk`].
const MAX_LANES: usize = 16;

/// The selection over the members (`j0` first, then `rest`, ascending) of the `L` values from
/// `k0` of every member's row in `xb` (`[V, c]`): the first member initialises it, a later one
/// replaces it only when strictly better, so ties keep the lower index.
#[inline(always)]
fn select_block<T: Real, const SIGNED: bool, const L: usize>(
    xb: &[T],
    (j0, rest): (u32, &[u32]),
    c: usize,
    k0: usize,
) -> ([T; L], [u32; L]) {
    let mut best = [T::ZERO; L];
    best.copy_from_slice(&xb[j0 as usize * c + k0..][..L]);
    let mut at = [j0; L];
    for &j in rest {
        let xs = &xb[j as usize * c + k0..][..L];
        for l in 0..L {
            let (v, z) = (xs[l], best[l]);
            // `|` and `&`, not `||` and `&&`: no branches, so the loop vectorises.
            let better = if SIGNED {
                let (av, az) = (v.abs(), z.abs());
                (av > az) | ((av == az) & (v < z))
            } else {
                v > z
            };
            best[l] = if better { v } else { z };
            at[l] = if better { j } else { at[l] };
        }
    }
    (best, at)
}

/// The adjoint of [`max_pool`]: dx[b, j, ch] = Σ over (p with arg[b, p, ch] = j) of
/// g[b, p, ch], with `g` `[B, rows, c]`, `dx` `[B, cols, c]` (overwritten) and `members_t` the
/// transpose of the member pattern (row j: the rows p that hold j). Overlapping rows may select
/// one j several times: the contributions add up, in ascending p.
///
/// A gather rather than a scatter: each fine vertex's block of dx is summed from the blocks of
/// g whose selection it might be, so chunks of vertices run in parallel without sharing a
/// value, the sums do not depend on the thread count, and the compare-and-add vectorises.
pub(crate) fn max_unpool<T: Real>(members_t: &Csr, arg: &[u32], g: &[T], dx: &mut [T], c: usize) {
    let (cols, rows) = (members_t.rows(), members_t.cols());
    if c == 0 || cols == 0 {
        return;
    }
    dx.par_chunks_mut(CHUNK_ROWS * c)
        .enumerate()
        .for_each(|(chunk, dx)| {
            let first = chunk * CHUNK_ROWS;
            for (local, d) in dx.chunks_exact_mut(c).enumerate() {
                let gj = first + local;
                let (b, j) = (gj / cols, gj % cols);
                let (gb, ab) = (&g[b * rows * c..], &arg[b * rows * c..]);
                unpool_row(members_t.row::<T>(j).0, gb, ab, j as u32, d);
            }
        });
}

multiversion!(
    fn unpool_row<T>(
        holders: &[u32],
        g: &[T],
        arg: &[u32],
        j: u32,
        d: &mut [T],
    ) => unpool_row_body
);

#[inline(always)]
/// d = Σ over the rows p in `holders` of g[p] where arg[p] = j (every row `d.len()` wide).
fn unpool_row_body<T: Real, M: Madd>(holders: &[u32], g: &[T], arg: &[u32], j: u32, d: &mut [T]) {
    let c = d.len();
    d.fill(T::ZERO);
    for &p in holders {
        let (gp, ap) = (&g[p as usize * c..][..c], &arg[p as usize * c..][..c]);
        for ((z, &gv), &a) in d.iter_mut().zip(gp).zip(ap) {
            *z += if a == j { gv } else { T::ZERO };
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use sparse_csr::CsrMatrix;

    #[test]
    fn max_pool_picks_signed_largest_magnitude_and_unpool_scatters() {
        // Clusters {0, 1}, {2, 3, 4}, {} over 5 vertices.
        let p = CsrMatrix::from_triplets(
            3,
            5,
            &[
                (0, 0, 0.5),
                (0, 1, 0.5),
                (1, 2, 1.0),
                (1, 3, 1.0),
                (1, 4, 1.0),
            ],
        )
        .unwrap();
        let pat = Csr::from_matrix(&p);
        let pat_t = Csr::from_matrix(&p.transpose());
        // One batch, two channels.
        let x = [1.0, -2.0, -3.0, 2.0, 0.5, 4.0, -0.5, -4.0, 0.25, 1.0f64];
        let mut out = [9.0; 6];
        let mut arg = [7u32; 6];
        max_pool(&pat, &x, &mut out, &mut arg, 2, MaxMode::SignedMax);
        // Ties in magnitude (-2 vs 2, 0.5 vs -0.5, 4 vs -4) go to the negative value.
        assert_eq!(out, [-3.0, -2.0, -0.5, -4.0, 0.0, 0.0]);
        assert_eq!(arg, [1, 0, 3, 3, u32::MAX, u32::MAX]);
        let g = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0];
        let mut dx = [0.0; 10];
        max_unpool(&pat_t, &arg, &g, &mut dx, 2);
        assert_eq!(dx, [0.0, 2.0, 1.0, 0.0, 0.0, 0.0, 3.0, 4.0, 0.0, 0.0]);
    }

    #[test]
    fn plain_max_over_overlapping_rows_and_unpool_sums() {
        // Rows {0, 1, 2} and {1, 2} over 3 vertices; one channel, two batches.
        let p = CsrMatrix::from_triplets(
            2,
            3,
            &[
                (0, 0, 1.0),
                (0, 1, 1.0),
                (0, 2, 1.0),
                (1, 1, 1.0),
                (1, 2, 1.0),
            ],
        )
        .unwrap();
        let (pat, pat_t) = (Csr::from_matrix(&p), Csr::from_matrix(&p.transpose()));
        // Batch 0: vertex 1 is the max of both rows; batch 1: -3 (not the magnitude 5) and a
        // tie between vertices 1 and 2 that goes to 1.
        let x = [1.0, 4.0, -2.0, -5.0, -3.0, -3.0f32];
        let (mut out, mut arg) = ([0.0f32; 4], [0u32; 4]);
        max_pool(&pat, &x, &mut out, &mut arg, 1, MaxMode::PlainMax);
        assert_eq!(out, [4.0, 4.0, -3.0, -3.0]);
        assert_eq!(arg, [1, 1, 1, 1]);
        let mut dx = [7.0f32; 6];
        max_unpool(&pat_t, &arg, &[1.0, 10.0, 2.0, 20.0], &mut dx, 1);
        assert_eq!(dx, [0.0, 11.0, 0.0, 0.0, 22.0, 0.0]);
    }
}
