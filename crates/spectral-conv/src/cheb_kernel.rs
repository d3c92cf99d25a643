//! Fused Chebyshev-convolution kernels: y = Σ_{k<K} T_k(L̃) x W_k on flat `[B, V, C]` slices.
//!
//! Why fused: the op-by-op version writes and re-reads every T_k and its stacked copy (a dozen
//! passes over [B, V, C] arrays); here the forward pass stores only T_0 … T_{K−2} and computes the
//! last term and the channel mixing vertex by vertex, and the backward pass evaluates
//! dx = Σ_k T_k(L̃ᵀ) (g W_kᵀ) by Clenshaw's recurrence
//! (b_k = g W_kᵀ + 2 L̃ᵀ b_{k+1} − b_{k+2}, dx = g W_0ᵀ + L̃ᵀ b_1 − b_2: K − 1 sparse passes),
//! accumulating dW in the sweep that starts it.
//!
//! Internal layout: channel-major blocks `[V, C, B]` (see `kernel.rs`). The channel mixing
//! (per vertex a `[27] → [9]` map applied to B = 32 rows, the bulk of the arithmetic) keeps
//! 8 batch lanes × 9 outputs in registers while it walks the 27 inputs ([`mix`]).
//!
//! Weight layout as the authors': W is `[C_in·K, C_out]`, row `fin·K + k`.

use crate::kernel::{
    CHUNK_ROWS, ChunkOut, Csr, Madd, Real, Staging, chunk_outs, chunk_span, gather_row, load_chunk,
    multiversion, spmm_axpby, to_channel_major,
};
use crate::scratch;
use rayon::prelude::*;

/// The sizes of one fused convolution.
#[derive(Debug, Clone, Copy)]
pub(crate) struct ChebShape {
    pub batch: usize,
    pub v: usize,
    pub ci: usize,
    pub co: usize,
    pub k: usize,
}

/// Batch lanes processed together (one AVX register of f32).
const LANES: usize = 8;

/// W rearranged k-major: `wk[(k·ci + f)·co + o] = W[(f·K + k)·co + o]` (inputs × outputs).
fn weights_k_major<T: Real>(w: &[T], s: &ChebShape) -> Vec<T> {
    let mut wk = Vec::with_capacity(w.len());
    for k in 0..s.k {
        for f in 0..s.ci {
            wk.extend_from_slice(&w[(f * s.k + k) * s.co..][..s.co]);
        }
    }
    wk
}

/// W transposed per order: `wt[(k·co + o)·ci + f] = W[(f·K + k)·co + o]`, for g W_kᵀ.
fn weights_transposed<T: Real>(w: &[T], s: &ChebShape) -> Vec<T> {
    let mut wt = Vec::with_capacity(w.len());
    for k in 0..s.k {
        for o in 0..s.co {
            wt.extend((0..s.ci).map(|f| w[(f * s.k + k) * s.co + o]));
        }
    }
    wt
}

/// out[p, :] (+)= Σ_q m[q·P + p] · inp[q, :] on channel-major blocks (`inp` `[Q, B]`, `out`
/// `[P, B]`); with `accumulate` out is added to, else overwritten. `P` is the output count when
/// known at compile time (then 8 lanes × P outputs stay in registers), 0 when only `p_dyn` is.
#[inline(always)]
fn mix<T: Real, M: Madd, const P: usize>(
    inp: &[T],
    m: &[T],
    p_dyn: usize,
    batch: usize,
    out: &mut [T],
    accumulate: bool,
) {
    let p_n = if P == 0 { p_dyn } else { P };
    let q_n = inp.len() / batch;
    let mut done = 0;
    if P > 0 {
        done = batch - batch % LANES;
        for lb in (0..done).step_by(LANES) {
            let mut acc = [[T::ZERO; LANES]; P];
            if accumulate {
                for (p, a) in acc.iter_mut().enumerate() {
                    a.copy_from_slice(&out[p * batch + lb..][..LANES]);
                }
            }
            for q in 0..q_n {
                let x = &inp[q * batch + lb..][..LANES];
                let m_q = &m[q * P..][..P];
                for (a, &w) in acc.iter_mut().zip(m_q) {
                    for (z, &xv) in a.iter_mut().zip(x) {
                        *z = M::madd(xv, w, *z);
                    }
                }
            }
            for (p, a) in acc.iter().enumerate() {
                out[p * batch + lb..][..LANES].copy_from_slice(a);
            }
        }
    }
    if done < batch {
        // Remaining lanes (all of them when P is not fixed): axpy rows.
        for p in 0..p_n {
            let o = &mut out[p * batch + done..(p + 1) * batch];
            if !accumulate {
                o.fill(T::ZERO);
            }
            for q in 0..q_n {
                let w = m[q * p_n + p];
                for (z, &xv) in o.iter_mut().zip(&inp[q * batch + done..(q + 1) * batch]) {
                    *z = M::madd(xv, w, *z);
                }
            }
        }
    }
}

/// acc[p][l] += Σ_j t[j·8 + l] · g[p, j·8 + l]: lane-parallel batch dot products of one input
/// row with every output row (dW = Σ Tᵀ g without reassociating float sums). With `P` fixed,
/// the P accumulators stay in registers and advance together (independent FMA chains).
#[inline(always)]
fn dot_lanes<T: Real, M: Madd, const P: usize>(
    t: &[T],
    g: &[T],
    batch: usize,
    acc: &mut [[T; LANES]],
) {
    let full = batch - batch % LANES;
    if P > 0 {
        let mut regs = [[T::ZERO; LANES]; P];
        regs.copy_from_slice(&acc[..P]);
        for lb in (0..full).step_by(LANES) {
            let tv = &t[lb..][..LANES];
            for (p, r) in regs.iter_mut().enumerate() {
                let gv = &g[p * batch + lb..][..LANES];
                for ((z, &a), &b) in r.iter_mut().zip(tv).zip(gv) {
                    *z = M::madd(a, b, *z);
                }
            }
        }
        acc[..P].copy_from_slice(&regs);
    } else {
        for (p, a) in acc.iter_mut().enumerate() {
            let g_p = &g[p * batch..][..batch];
            for (tc, gc) in t[..full]
                .chunks_exact(LANES)
                .zip(g_p[..full].chunks_exact(LANES))
            {
                for ((z, &tv), &gv) in a.iter_mut().zip(tc).zip(gc) {
                    *z = M::madd(tv, gv, *z);
                }
            }
        }
    }
    for (p, a) in acc.iter_mut().enumerate() {
        let g_p = &g[p * batch..][..batch];
        for ((z, &tv), &gv) in a.iter_mut().zip(&t[full..]).zip(&g_p[full..]) {
            *z = M::madd(tv, gv, *z);
        }
    }
}

/// T_0 … T_{K−2} (at least T_0), channel-major `[V, ci, B]`: what later terms gather from.
pub(crate) fn stored_terms<T: Real>(a: &Csr, x: &[T], s: &ChebShape) -> Vec<Vec<T>> {
    let n = s.batch * s.ci;
    let mut terms = vec![to_channel_major(x, s.batch, s.v, s.ci)];
    for k in 1..s.k.saturating_sub(1) {
        let mut out = scratch::take(s.v * n);
        if k == 1 {
            spmm_axpby(a, T::from_f64(1.0), &terms[0], T::ZERO, None, &mut out, n);
        } else {
            let (two, minus_one) = (T::from_f64(2.0), T::from_f64(-1.0));
            let (src, prev) = (&terms[k - 1], &terms[k - 2]);
            spmm_axpby(a, two, src, minus_one, Some(prev), &mut out, n);
        }
        terms.push(out);
    }
    terms
}

/// T_{K−1} at vertex i (a `[ci, B]` block) into `last`.
#[inline(always)]
fn last_term<T: Real, M: Madd>(
    a: &Csr,
    terms: &[Vec<T>],
    k_count: usize,
    i: usize,
    last: &mut [T],
) {
    let n = last.len();
    if k_count == 1 {
        last.copy_from_slice(&terms[0][i * n..][..n]);
        return;
    }
    let (cols, vals) = a.row::<T>(i);
    gather_row::<T, M>(cols, vals, &terms[k_count - 2], n, last);
    if k_count >= 3 {
        let two = T::from_f64(2.0);
        for (z, &p) in last.iter_mut().zip(&terms[k_count - 3][i * n..][..n]) {
            *z = two * *z - p;
        }
    }
}

/// The `[ci, B]` block of T_k at vertex i: stored, or `last` for k = K − 1.
#[inline(always)]
fn term_block<'a, T>(
    terms: &'a [Vec<T>],
    last: &'a [T],
    k: usize,
    k_count: usize,
    i: usize,
) -> &'a [T] {
    if k + 1 == k_count {
        last
    } else {
        &terms[k][i * last.len()..][..last.len()]
    }
}

/// out = inp · m with `P` fixed at 9 (the feature width) where it applies.
#[inline(always)]
fn mix_any<T: Real, M: Madd>(inp: &[T], m: &[T], p: usize, batch: usize, out: &mut [T], acc: bool) {
    match p {
        9 => mix::<T, M, 9>(inp, m, p, batch, out, acc),
        _ => mix::<T, M, 0>(inp, m, p, batch, out, acc),
    }
}

/// Forward: returns y `[B, V, co]` and the stored terms (for the backward pass).
pub(crate) fn forward<T: Real>(a: &Csr, x: &[T], w: &[T], s: &ChebShape) -> (Vec<T>, Vec<Vec<T>>) {
    let terms = stored_terms(a, x, s);
    let wk = weights_k_major(w, s);
    let mut y = vec![T::ZERO; s.batch * s.v * s.co];
    chunk_outs(&mut y, false, (s.batch, s.v, s.co))
        .into_par_iter()
        .enumerate()
        .for_each_init(Staging::new, |staging, (chunk, dest)| {
            forward_chunk(a, &terms, &wk, s, chunk, dest, staging)
        });
    (y, terms)
}

multiversion!(
    #[allow(clippy::too_many_arguments)]
    fn forward_chunk<T>(
        a: &Csr,
        terms: &[Vec<T>],
        wk: &[T],
        s: &ChebShape,
        chunk: usize,
        dest: ChunkOut<'_, T>,
        staging: &mut Staging<T>,
    ) => forward_chunk_body
);

#[inline(always)]
fn forward_chunk_body<T: Real, M: Madd>(
    a: &Csr,
    terms: &[Vec<T>],
    wk: &[T],
    s: &ChebShape,
    chunk: usize,
    mut dest: ChunkOut<'_, T>,
    staging: &mut Staging<T>,
) {
    let (batch, ci, co) = (s.batch, s.ci, s.co);
    let (i0, cnt) = chunk_span(chunk, s.v);
    let [last, out, _] = staging.get([ci * batch, cnt * co * batch, 0]);
    for (li, y) in out.chunks_exact_mut(co * batch).enumerate() {
        let i = i0 + li;
        last_term::<T, M>(a, terms, s.k, i, last);
        for k in 0..s.k {
            let block = term_block(terms, last, k, s.k, i);
            mix_any::<T, M>(block, &wk[k * ci * co..][..ci * co], co, batch, y, k > 0);
        }
    }
    dest.store(out);
}

/// Backward: given the output gradient `g` `[B, V, co]`, returns dx `[B, V, ci]` (if `need_x`)
/// and dW `[ci·K, co]` (if `need_w`). `at` is L̃ᵀ; `terms` are the forward's stored terms.
#[allow(clippy::too_many_arguments)]
pub(crate) fn backward<T: Real>(
    a: &Csr,
    at: &Csr,
    terms: &[Vec<T>],
    w: &[T],
    g: &[T],
    s: &ChebShape,
    (need_x, need_w): (bool, bool),
) -> (Option<Vec<T>>, Option<Vec<T>>) {
    if !need_x && !need_w {
        return (None, None);
    }
    let wt = weights_transposed(w, s);
    let size = s.batch * s.v * s.ci;
    let n_w = s.k * s.ci * s.co;
    // b_{K−1} = g W_{K−1}ᵀ (channel-major); for K = 1 it is dx itself (batch-major).
    // (dx itself is handed to candle: a fresh buffer; the rest is recycled.)
    let fresh_or_recycled = |internal: bool| {
        if internal {
            scratch::take(size)
        } else {
            vec![T::ZERO; size]
        }
    };
    let mut b_next = need_x.then(|| fresh_or_recycled(s.k > 1));
    let dests = match b_next.as_deref_mut() {
        Some(h) => chunk_outs(h, s.k > 1, (s.batch, s.v, s.ci)),
        None => (0..s.v.div_ceil(CHUNK_ROWS))
            .map(|_| ChunkOut::Discard)
            .collect(),
    };
    let dw = dests
        .into_par_iter()
        .enumerate()
        .fold(
            || (vec![0.0f64; n_w], Staging::new()),
            |(mut acc, mut staging), (chunk, dest)| {
                let mut lanes = vec![[T::ZERO; LANES]; if need_w { n_w } else { 0 }];
                sweep_chunk(a, terms, g, &wt, s, chunk, dest, &mut lanes, &mut staging);
                for (z, l) in acc.iter_mut().zip(&lanes) {
                    *z += l.iter().map(|v| v.to_f64()).sum::<f64>();
                }
                (acc, staging)
            },
        )
        .map(|(acc, _)| acc)
        .reduce(
            || vec![0.0f64; n_w],
            |mut p, q| {
                p.iter_mut().zip(q).for_each(|(x, y)| *x += y);
                p
            },
        );
    let dw = need_w.then(|| weights_from_k_major(&dw, s));
    let Some(mut b_next) = b_next else {
        return (None, dw);
    };
    if s.k == 1 {
        return (Some(b_next), dw);
    }
    let mut b_after: Option<Vec<T>> = None;
    let block = s.co * s.ci;
    for k in (0..s.k - 1).rev() {
        let alpha = T::from_f64(if k == 0 { 1.0 } else { 2.0 });
        let mut out = fresh_or_recycled(k > 0);
        // b_{k+2} = b_{K−1} is g W_{K−1}ᵀ itself: subtract it through the weights
        // (g (W_kᵀ − W_{K−1}ᵀ)) rather than re-read it.
        let combined: Vec<T>;
        let (wt_k, after) = if k + 2 == s.k - 1 {
            let last = &wt[(s.k - 1) * block..][..block];
            combined = (wt[k * block..][..block].iter().zip(last))
                .map(|(&p, &q)| p - q)
                .collect();
            (&combined[..], None)
        } else {
            (&wt[k * block..][..block], b_after.as_deref())
        };
        // The intermediate b_k are gathered from later: channel-major; dx goes out batch-major.
        chunk_outs(&mut out, k > 0, (s.batch, s.v, s.ci))
            .into_par_iter()
            .enumerate()
            .for_each_init(Staging::new, |staging, (chunk, dest)| {
                let step = (alpha, after);
                clenshaw_chunk(at, g, wt_k, step, &b_next, s, chunk, dest, staging)
            });
        if let Some(done) = b_after.replace(std::mem::replace(&mut b_next, out)) {
            scratch::give(done);
        }
    }
    if let Some(done) = b_after {
        scratch::give(done);
    }
    (Some(b_next), dw)
}

/// dW from the k-major accumulation order back to the `[ci·K, co]` layout.
fn weights_from_k_major<T: Real>(dw: &[f64], s: &ChebShape) -> Vec<T> {
    let mut out = vec![T::ZERO; dw.len()];
    for k in 0..s.k {
        for f in 0..s.ci {
            for o in 0..s.co {
                out[(f * s.k + k) * s.co + o] = T::from_f64(dw[(k * s.ci + f) * s.co + o]);
            }
        }
    }
    out
}

multiversion!(
    #[allow(clippy::too_many_arguments)]
    fn sweep_chunk<T>(
        a: &Csr,
        terms: &[Vec<T>],
        g: &[T],
        wt: &[T],
        s: &ChebShape,
        chunk: usize,
        dest: ChunkOut<'_, T>,
        lanes: &mut [[T; LANES]],
        staging: &mut Staging<T>,
    ) => sweep_chunk_body
);

/// The first backward sweep over one chunk: dW partial sums into `lanes` (k-major, if it is not
/// empty) and g W_{K−1}ᵀ into `dest` (unless discarded).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn sweep_chunk_body<T: Real, M: Madd>(
    a: &Csr,
    terms: &[Vec<T>],
    g: &[T],
    wt: &[T],
    s: &ChebShape,
    chunk: usize,
    mut dest: ChunkOut<'_, T>,
    lanes: &mut [[T; LANES]],
    staging: &mut Staging<T>,
) {
    let (batch, ci, co) = (s.batch, s.ci, s.co);
    let (i0, cnt) = chunk_span(chunk, s.v);
    let [g_blocks, last, h] = staging.get([cnt * co * batch, ci * batch, cnt * ci * batch]);
    load_chunk(g, (batch, s.v, co), (i0, cnt), g_blocks);
    let need_w = !lanes.is_empty();
    if need_w {
        for (li, g_block) in g_blocks.chunks_exact(co * batch).enumerate() {
            let i = i0 + li;
            last_term::<T, M>(a, terms, s.k, i, last);
            for k in 0..s.k {
                let block = term_block(terms, last, k, s.k, i);
                for (f, t_f) in block.chunks_exact(batch).enumerate() {
                    let lanes_kf = &mut lanes[(k * ci + f) * co..][..co];
                    match co {
                        9 => dot_lanes::<T, M, 9>(t_f, g_block, batch, lanes_kf),
                        _ => dot_lanes::<T, M, 0>(t_f, g_block, batch, lanes_kf),
                    }
                }
            }
        }
    }
    if !dest.is_discard() {
        let wt_last = &wt[(s.k - 1) * co * ci..][..co * ci];
        for (g_block, h_block) in g_blocks
            .chunks_exact(co * batch)
            .zip(h.chunks_exact_mut(ci * batch))
        {
            mix_any::<T, M>(g_block, wt_last, ci, batch, h_block, false);
        }
        dest.store(h);
    }
}

multiversion!(
    #[allow(clippy::too_many_arguments)]
    fn clenshaw_chunk<T>(
        at: &Csr,
        g: &[T],
        wt_k: &[T],
        step: (T, Option<&[T]>),
        next: &[T],
        s: &ChebShape,
        chunk: usize,
        dest: ChunkOut<'_, T>,
        staging: &mut Staging<T>,
    ) => clenshaw_chunk_body
);

/// One Clenshaw step over one chunk: out = g W_kᵀ + alpha · L̃ᵀ next − after (`after` absent:
/// 0); `next` and `after` channel-major.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn clenshaw_chunk_body<T: Real, M: Madd>(
    at: &Csr,
    g: &[T],
    wt_k: &[T],
    (alpha, after): (T, Option<&[T]>),
    next: &[T],
    s: &ChebShape,
    chunk: usize,
    mut dest: ChunkOut<'_, T>,
    staging: &mut Staging<T>,
) {
    let (batch, ci, co) = (s.batch, s.ci, s.co);
    let n = ci * batch;
    let (i0, cnt) = chunk_span(chunk, s.v);
    let [g_blocks, acc, out] = staging.get([cnt * co * batch, n, cnt * n]);
    load_chunk(g, (batch, s.v, co), (i0, cnt), g_blocks);
    for (li, (g_block, o)) in g_blocks
        .chunks_exact(co * batch)
        .zip(out.chunks_exact_mut(n))
        .enumerate()
    {
        let i = i0 + li;
        let (cols, vals) = at.row::<T>(i);
        gather_row::<T, M>(cols, vals, next, n, acc);
        mix_any::<T, M>(g_block, wt_k, ci, batch, o, false);
        for (z, &m) in o.iter_mut().zip(acc.iter()) {
            *z = M::madd(alpha, m, *z);
        }
        if let Some(after) = after {
            for (z, &p) in o.iter_mut().zip(&after[i * n..][..n]) {
                *z = *z - p;
            }
        }
    }
    dest.store(out);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_util::{dense_apply, random_matrix, random_vec};

    /// Σ_k T_k(A) x W_k by dense recurrences, W in the authors' layout.
    fn reference(m: &mesh_hierarchy::CsrMatrix, x: &[f64], w: &[f64], s: &ChebShape) -> Vec<f64> {
        let mut terms = vec![x.to_vec()];
        for k in 1..s.k {
            let ax = dense_apply(m, &terms[k - 1], s.batch, s.ci);
            let t = if k == 1 {
                ax
            } else {
                ax.iter()
                    .zip(&terms[k - 2])
                    .map(|(a, p)| 2.0 * a - p)
                    .collect()
            };
            terms.push(t);
        }
        let mut y = vec![0.0; s.batch * s.v * s.co];
        for r in 0..s.batch * s.v {
            for o in 0..s.co {
                for f in 0..s.ci {
                    for (k, t) in terms.iter().enumerate() {
                        y[r * s.co + o] += t[r * s.ci + f] * w[(f * s.k + k) * s.co + o];
                    }
                }
            }
        }
        y
    }

    #[test]
    fn fused_forward_and_adjoint_match_dense_reference() {
        let v = 11;
        let m = random_matrix(v, v, 0.35, 7);
        let (a, at) = (Csr::from_matrix(&m), Csr::from_matrix(&m.transpose()));
        for (k, ci, co) in [(1, 2, 3), (2, 3, 2), (3, 9, 9), (4, 2, 5), (5, 3, 1)] {
            let s = ChebShape {
                batch: 2,
                v,
                ci,
                co,
                k,
            };
            let x = random_vec(2 * v * ci, 11);
            let w = random_vec(ci * k * co, 12);
            let (y, stored) = forward(&a, &x, &w, &s);
            let want = reference(&m, &x, &w, &s);
            for (p, q) in y.iter().zip(&want) {
                assert!((p - q).abs() < 1e-12, "K={k} forward");
            }
            // Adjoint identity: <g, y(x)> is linear in x and in W, so its gradients are exact.
            let g = random_vec(2 * v * co, 13);
            let (dx, dw) = backward(&a, &at, &stored, &w, &g, &s, (true, true));
            let (dx, dw) = (dx.unwrap(), dw.unwrap());
            let dot = |y: &[f64]| y.iter().zip(&g).map(|(p, q)| p * q).sum::<f64>();
            for (idx, &d) in dx.iter().enumerate().step_by(5) {
                let mut xe = vec![0.0; x.len()];
                xe[idx] = 1.0;
                let want = dot(&reference(&m, &xe, &w, &s));
                assert!((d - want).abs() < 1e-10, "K={k} dx[{idx}] {d} vs {want}");
            }
            for (idx, &d) in dw.iter().enumerate() {
                let mut we = vec![0.0; w.len()];
                we[idx] = 1.0;
                let want = dot(&reference(&m, &x, &we, &s));
                assert!((d - want).abs() < 1e-10, "K={k} dW[{idx}] {d} vs {want}");
            }
            let (none_x, only_w) = backward(&a, &at, &stored, &w, &g, &s, (false, true));
            assert!(none_x.is_none());
            let only_w = only_w.unwrap();
            assert!(only_w.iter().zip(&dw).all(|(p, q)| (p - q).abs() < 1e-12));
        }
    }
}
