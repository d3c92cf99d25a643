//! Fused Chebyshev-convolution kernels: y = Σ_{k<K} T_k(L̃) x W_k + b, with T_0 = x,
//! T_1 = L̃ x, T_k = 2 L̃ T_{k−1} − T_{k−2}, and their backward pass.
//!
//! Forward: T_1 … T_{K−2} are stored (channel-major, for the backward pass), then one sweep
//! computes T_{K−1} vertex by vertex from a gather of T_{K−2} and mixes all K terms (plus the
//! bias) into y. K = 3: one stored term, two sparse passes.
//!
//! Backward (A = L̃, g the output gradient; nothing assumes A symmetric, Aᵀ is stored): one sweep
//! gathers h = Aᵀ g and accumulates, per chunk of vertices, dW_k = T_kᵀ g (k ≤ K−2),
//! P = T_{K−2}ᵀ h (then dW_{K−1} = c·P − dW_{K−3}, since T_{K−1} = c A T_{K−2} − T_{K−3}) and
//! db = Σ g, and writes the Clenshaw term b_{K−2} = g W_{K−2}ᵀ + c h W_{K−1}ᵀ (c = 2, or 1 for
//! K = 2). Then b_k = g W_kᵀ + 2 Aᵀ b_{k+1} − b_{k+2} down to dx = b_0 (coefficient 1), one
//! sparse pass each: K = 3 takes two sweeps in all. Chunk partial sums are reduced in chunk
//! order, so gradients are bit-reproducible whatever the thread count.
//!
//! Arrays: x and g arrive as vertex-major [`Blocks`] (`[B, V, C]` data is converted first), y
//! and dx leave through [`ChunkOut`] in the caller's layout; the intermediates are `[V, C, B]`.
//! Weight layout as the authors': W is `[C_in·K, C_out]`, row `fin·K + k`.

use crate::kernel::{CHUNK_ROWS, Csr, Madd, Real, Staging, chunk_span, multiversion};
use crate::layout::{Blocks, ChunkOut, Io, chunk_outs};
use crate::mix::{LANES, MixDims, dot_chunk, mix};
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

/// The largest K the fused kernels take (a vertex's K term blocks are listed on the stack);
/// larger K runs unfused.
pub(crate) const MAX_K: usize = 8;

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

/// α · W_kᵀ + β · W_jᵀ as `[co, ci]` (rows: outputs of the forward map, the inputs of g W_kᵀ).
fn weights_t<T: Real>(
    w: &[T],
    s: &ChebShape,
    (alpha, k): (f64, usize),
    other: Option<(f64, usize)>,
) -> Vec<T> {
    let at = |k: usize, o: usize, f: usize| w[(f * s.k + k) * s.co + o].to_f64();
    let mut wt = Vec::with_capacity(s.co * s.ci);
    for o in 0..s.co {
        for f in 0..s.ci {
            let extra = other.map_or(0.0, |(beta, j)| beta * at(j, o, f));
            wt.push(T::from_f64(alpha * at(k, o, f) + extra));
        }
    }
    wt
}

/// T_1 … T_{K−2} (none for K ≤ 2), channel-major `[V, ci, B]`: what the later sweeps read.
pub(crate) fn stored_terms<T: Real>(a: &Csr, x: Blocks<'_, T>, s: &ChebShape) -> Vec<Vec<T>> {
    let n = s.batch * s.ci;
    let mut terms: Vec<Vec<T>> = (1..s.k.saturating_sub(1))
        .map(|_| scratch::take(s.v * n))
        .collect();
    let mut outs: Vec<&mut [T]> = terms.iter_mut().map(|t| t.as_mut_slice()).collect();
    stored_terms_into(a, x, s, &mut outs);
    terms
}

/// [`stored_terms`] into given buffers (`terms[k − 1]` = T_k, each `V·ci·B` long).
pub(crate) fn stored_terms_into<T: Real>(
    a: &Csr,
    x: Blocks<'_, T>,
    s: &ChebShape,
    terms: &mut [&mut [T]],
) {
    let n = s.batch * s.ci;
    for k in 1..s.k.saturating_sub(1) {
        let (done, rest) = terms.split_at_mut(k - 1);
        let out = &mut *rest[0];
        let term = |j: usize| match j {
            0 => x,
            _ => Blocks::channel_major(&*done[j - 1], s.batch, s.ci),
        };
        let (src, prev) = (term(k - 1), (k >= 2).then(|| term(k - 2)));
        if n > 0 {
            out.par_chunks_mut(CHUNK_ROWS * n)
                .enumerate()
                .for_each_init(Staging::new, |staging, (chunk, out)| {
                    term_chunk(a, src, prev, s, chunk, out, staging)
                });
        }
    }
}

multiversion!(
    #[allow(clippy::too_many_arguments)]
    fn term_chunk<T>(
        a: &Csr,
        src: Blocks<'_, T>,
        prev: Option<Blocks<'_, T>>,
        s: &ChebShape,
        chunk: usize,
        out: &mut [T],
        staging: &mut Staging<T>,
    ) => term_chunk_body
);

/// out = A src (+ 2 A src − prev when `prev` is given) over one chunk.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn term_chunk_body<T: Real, M: Madd>(
    a: &Csr,
    src: Blocks<'_, T>,
    prev: Option<Blocks<'_, T>>,
    s: &ChebShape,
    chunk: usize,
    out: &mut [T],
    staging: &mut Staging<T>,
) {
    let n = s.batch * s.ci;
    let (i0, cnt) = chunk_span(chunk, s.v);
    let [tmp, pbuf] = staging.get([n, cnt * n]);
    let prev = prev.map(|p| p.chunk(i0, cnt, pbuf));
    for (li, o) in out.chunks_exact_mut(n).enumerate() {
        let (cols, vals) = a.row::<T>(i0 + li);
        src.gather::<M>(cols, vals, tmp, o);
        if let Some(prev) = prev {
            let two = T::from_f64(2.0);
            for (z, &p) in o.iter_mut().zip(&prev[li * n..][..n]) {
                *z = two * *z - p;
            }
        }
    }
}

/// Forward: y (layout `io`, a fresh vector for candle) and the stored terms T_1 … T_{K−2}.
pub(crate) fn forward<T: Real>(
    a: &Csr,
    x: Blocks<'_, T>,
    w: &[T],
    bias: Option<&[T]>,
    s: &ChebShape,
    io: Io,
) -> (Vec<T>, Vec<Vec<T>>) {
    let terms = stored_terms(a, x, s);
    let mut y = vec![T::ZERO; s.batch * s.v * s.co];
    let refs: Vec<&[T]> = terms.iter().map(|t| t.as_slice()).collect();
    mix_terms(a, x, &refs, w, bias, s, (io, &mut y));
    (y, terms)
}

/// The forward's last sweep: T_{K−1} from the stored terms, all K terms mixed into y (layout
/// `io`).
pub(crate) fn mix_terms<T: Real>(
    a: &Csr,
    x: Blocks<'_, T>,
    terms: &[&[T]],
    w: &[T],
    bias: Option<&[T]>,
    s: &ChebShape,
    (io, y): (Io, &mut [T]),
) {
    let wk = weights_k_major(w, s);
    let ctx = Ctx { a, x, terms, s };
    chunk_outs(y, io, (s.batch, s.v, s.co))
        .into_par_iter()
        .enumerate()
        .for_each_init(Staging::new, |staging, (chunk, dest)| {
            forward_chunk(&ctx, &wk, bias, chunk, dest, staging)
        });
}

/// What every sweep reads: the operator, x and the stored terms.
struct Ctx<'a, T> {
    a: &'a Csr,
    x: Blocks<'a, T>,
    terms: &'a [&'a [T]],
    s: &'a ChebShape,
}

impl<T: Real> Ctx<'_, T> {
    /// T_k (k ≤ K−2) of a chunk, `[cnt, ci, B]`; `xc` is x's chunk.
    #[inline(always)]
    fn term<'b>(&'b self, k: usize, xc: &'b [T], (i0, cnt): (usize, usize)) -> &'b [T] {
        let n = self.s.ci * self.s.batch;
        match k {
            0 => xc,
            _ => &self.terms[k - 1][i0 * n..][..cnt * n],
        }
    }
}

multiversion!(
    fn forward_chunk<T>(
        ctx: &Ctx<'_, T>,
        wk: &[T],
        bias: Option<&[T]>,
        chunk: usize,
        dest: ChunkOut<'_, T>,
        staging: &mut Staging<T>,
    ) => forward_chunk_body
);

#[inline(always)]
fn forward_chunk_body<T: Real, M: Madd>(
    ctx: &Ctx<'_, T>,
    wk: &[T],
    bias: Option<&[T]>,
    chunk: usize,
    mut dest: ChunkOut<'_, T>,
    staging: &mut Staging<T>,
) {
    let s = ctx.s;
    let (n, n_out) = (s.ci * s.batch, s.co * s.batch);
    let (i0, cnt) = chunk_span(chunk, s.v);
    let [xbuf, tmp, last, ybuf] = staging.get([cnt * n, n, n, cnt * n_out]);
    let xc = ctx.x.chunk(i0, cnt, xbuf);
    let chunks: [&[T]; MAX_K] = std::array::from_fn(|k| {
        if k + 1 < s.k {
            ctx.term(k, xc, (i0, cnt))
        } else {
            &[]
        }
    });
    let bufs = (tmp, last);
    // No closure here: closures are not compiled with the caller's target features.
    match dest.direct() {
        Some(out) => forward_rows::<T, M>(ctx, wk, bias, (i0, xc, &chunks), bufs, out),
        None => {
            forward_rows::<T, M>(ctx, wk, bias, (i0, xc, &chunks), bufs, ybuf);
            dest.store(ybuf);
        }
    }
}

/// The forward pass's output rows of one chunk (see [`forward_chunk_body`]).
#[inline(always)]
fn forward_rows<T: Real, M: Madd>(
    ctx: &Ctx<'_, T>,
    wk: &[T],
    bias: Option<&[T]>,
    (i0, xc, chunks): (usize, &[T], &[&[T]; MAX_K]),
    (tmp, last): (&mut [T], &mut [T]),
    out: &mut [T],
) {
    let s = ctx.s;
    let (n, n_out) = (s.ci * s.batch, s.co * s.batch);
    for (li, y) in out.chunks_exact_mut(n_out).enumerate() {
        let mut inps: [&[T]; MAX_K] = [&[]; MAX_K];
        for (inp, c) in inps.iter_mut().zip(&chunks[..s.k - 1]) {
            *inp = &c[li * n..][..n];
        }
        // T_{K−1}: x itself, A x, or 2 A T_{K−2} − T_{K−3}.
        if s.k == 1 {
            inps[0] = &xc[li * n..][..n];
        } else {
            let (cols, vals) = ctx.a.row::<T>(i0 + li);
            let src = match s.k {
                2 => ctx.x,
                _ => Blocks::channel_major(ctx.terms[s.k - 3], s.batch, s.ci),
            };
            src.gather::<M>(cols, vals, tmp, last);
            if s.k >= 3 {
                let two = T::from_f64(2.0);
                for (z, &p) in last.iter_mut().zip(inps[s.k - 3]) {
                    *z = two * *z - p;
                }
            }
            inps[s.k - 1] = last;
        }
        let d = MixDims {
            p: s.co,
            batch: s.batch,
        };
        mix::<T, M>(&inps[..s.k], wk, d, bias, y);
    }
}

/// The gradients asked for: dx (in the caller's layout), dW `[ci·K, co]`, db `[co]`.
pub(crate) struct Grads<T> {
    pub dx: Option<Vec<T>>,
    pub dw: Option<Vec<T>>,
    pub db: Option<Vec<T>>,
}

/// Which gradients to compute.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Need {
    pub x: bool,
    pub w: bool,
    pub b: bool,
}

/// Backward: given the output gradient `g`, x and the forward's stored terms.
#[allow(clippy::too_many_arguments)]
pub(crate) fn backward<T: Real>(
    a: &Csr,
    at: &Csr,
    x: Blocks<'_, T>,
    terms: &[&[T]],
    w: &[T],
    g: Blocks<'_, T>,
    s: &ChebShape,
    io: Io,
    need: Need,
) -> Grads<T> {
    let size = s.batch * s.v * s.ci;
    let mut dx = need.x.then(|| vec![T::ZERO; size]);
    // Sweep 1 writes b_{K−2} into a recycled buffer (K ≥ 3) or, for K ≤ 2, dx itself.
    let mut work = (need.x && s.k >= 3).then(|| scratch::take(size));
    let bufs = Bufs {
        dx: dx.as_deref_mut().map(|d| (io, d)),
        work: work.as_deref_mut(),
    };
    let (dw, db) = backward_into(a, at, x, terms, w, g, s, bufs, need);
    if let Some(work) = work {
        scratch::give(work);
    }
    Grads { dx, dw, db }
}

/// Where [`backward_into`] writes dx (and in which layout), and its work buffer for b_{K−2}
/// (channel-major, `V·ci·B` values; needed when dx is wanted and K ≥ 3).
pub(crate) struct Bufs<'a, T> {
    pub dx: Option<(Io, &'a mut [T])>,
    pub work: Option<&'a mut [T]>,
}

/// The backward pass into given buffers: dx (if `bufs.dx`), and returns dW `[ci·K, co]` and db
/// as asked by `need` (`need.x` is ignored: dx is computed iff a buffer is given). The Clenshaw
/// terms b_1 … b_{K−3} (only for K ≥ 4) come from the recycled buffers of `scratch.rs`.
#[allow(clippy::too_many_arguments)]
pub(crate) fn backward_into<T: Real>(
    a: &Csr,
    at: &Csr,
    x: Blocks<'_, T>,
    terms: &[&[T]],
    w: &[T],
    g: Blocks<'_, T>,
    s: &ChebShape,
    bufs: Bufs<'_, T>,
    need: Need,
) -> (Option<Vec<T>>, Option<Vec<T>>) {
    let k = s.k;
    let n_w = k * s.ci * s.co;
    let internal = k >= 3;
    let w1 = match k {
        1 => weights_t(w, s, (1.0, 0), None),
        _ => {
            let c = if k >= 3 { 2.0 } else { 1.0 };
            let mut w1 = weights_t(w, s, (1.0, k - 2), None);
            w1.extend(weights_t::<T>(w, s, (c, k - 1), None));
            w1
        }
    };
    let Bufs { dx, work } = bufs;
    let (mut dx, mut work) = (dx, work);
    let first: Option<(Io, &mut [T])> = match (internal, dx.as_mut(), work.as_deref_mut()) {
        (false, Some((io, d)), _) => Some((*io, &mut **d)),
        (true, Some(_), Some(wb)) => Some((Io::VertexChannel, wb)),
        _ => None,
    };
    let dests = match first {
        Some((out_io, out)) => chunk_outs(out, out_io, (s.batch, s.v, s.ci)),
        None => (0..s.v.div_ceil(CHUNK_ROWS))
            .map(|_| ChunkOut::Discard)
            .collect(),
    };
    let ctx = Ctx { a, x, terms, s };
    let sums = (need.w || need.b).then_some(n_w + s.co);
    let partials: Vec<Vec<f64>> = dests
        .into_par_iter()
        .enumerate()
        .map_init(Staging::new, |staging, (chunk, dest)| {
            sweep_chunk(&ctx, at, g, &w1, (chunk, sums, need.w), dest, staging)
        })
        .collect();
    let mut total = vec![0.0f64; n_w + s.co];
    for p in &partials {
        total.iter_mut().zip(p).for_each(|(t, v)| *t += v);
    }
    let dw = need.w.then(|| weights_from_k_major::<T>(&total[..n_w], s));
    let db = need
        .b
        .then(|| total[n_w..].iter().map(|&v| T::from_f64(v)).collect());
    if let (true, Some((io, d)), Some(wb)) = (internal, dx, work) {
        clenshaw(at, w, g, wb, s, (io, d));
    }
    (dw, db)
}

/// Clenshaw's recurrence from b_{K−2} (K ≥ 3) down to dx = b_0, written to `dx` (layout `io`).
fn clenshaw<T: Real>(
    at: &Csr,
    w: &[T],
    g: Blocks<'_, T>,
    b_first: &[T],
    s: &ChebShape,
    (io, dx): (Io, &mut [T]),
) {
    let size = s.batch * s.v * s.ci;
    // chain[j] = b_{K−2−j}: b_{K−2} is the caller's, the later ones recycled buffers.
    let mut chain: Vec<Vec<T>> = Vec::new();
    let mut dx = Some(dx);
    for k in (0..=s.k - 3).rev() {
        let alpha = T::from_f64(if k == 0 { 1.0 } else { 2.0 });
        let b = |kk: usize| -> &[T] {
            if kk == s.k - 2 {
                b_first
            } else {
                &chain[s.k - 3 - kk]
            }
        };
        // b_{k+2} = b_{K−1} = g W_{K−1}ᵀ was never stored: subtract it through the weights.
        let (wt_k, after) = if k + 2 == s.k - 1 {
            (weights_t(w, s, (1.0, k), Some((-1.0, s.k - 1))), None)
        } else {
            (weights_t(w, s, (1.0, k), None), Some(b(k + 2)))
        };
        let next = Blocks::channel_major(b(k + 1), s.batch, s.ci);
        let mut own = (k > 0).then(|| scratch::take(size));
        let (out_io, out): (Io, &mut [T]) = match own.as_deref_mut() {
            Some(o) => (Io::VertexChannel, o),
            None => match dx.take() {
                Some(d) => (io, d),
                None => return,
            },
        };
        chunk_outs(out, out_io, (s.batch, s.v, s.ci))
            .into_par_iter()
            .enumerate()
            .for_each_init(Staging::new, |staging, (chunk, dest)| {
                let step = (alpha, after);
                clenshaw_chunk(at, g, &wt_k, step, next, s, chunk, dest, staging)
            });
        chain.extend(own);
    }
    for done in chain {
        scratch::give(done);
    }
}

/// dW from the k-major accumulation order back to the `[ci·K, co]` layout, with
/// dW_{K−1} = c·P − dW_{K−3} (see the module comment).
fn weights_from_k_major<T: Real>(acc: &[f64], s: &ChebShape) -> Vec<T> {
    let block = s.ci * s.co;
    let mut dw = acc.to_vec();
    if s.k >= 3 {
        let (head, last) = dw.split_at_mut((s.k - 1) * block);
        let prev = &head[(s.k - 3) * block..][..block];
        for (z, &p) in last.iter_mut().zip(prev) {
            *z = 2.0 * *z - p;
        }
    }
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
        ctx: &Ctx<'_, T>,
        at: &Csr,
        g: Blocks<'_, T>,
        w1: &[T],
        job: (usize, Option<usize>, bool),
        dest: ChunkOut<'_, T>,
        staging: &mut Staging<T>,
    ) -> Vec<f64> => sweep_chunk_body
);

/// The first backward sweep over one chunk (`job`: chunk index, the length of the partial sums
/// if any are wanted, whether dW is): returns the chunk's dW (k-major) and db partial sums,
/// writes b_{K−2} (or dx) to `dest`.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn sweep_chunk_body<T: Real, M: Madd>(
    ctx: &Ctx<'_, T>,
    at: &Csr,
    g: Blocks<'_, T>,
    w1: &[T],
    (chunk, sums, need_w): (usize, Option<usize>, bool),
    mut dest: ChunkOut<'_, T>,
    staging: &mut Staging<T>,
) -> Vec<f64> {
    let s = ctx.s;
    let (k, ci, co, batch) = (s.k, s.ci, s.co, s.batch);
    let (n, n_out) = (ci * batch, co * batch);
    let (i0, cnt) = chunk_span(chunk, s.v);
    let h_len = if k >= 2 { cnt * n_out } else { 0 };
    let [gbuf, xbuf, hbuf, tmp, obuf] = staging.get([cnt * n_out, cnt * n, h_len, n_out, cnt * n]);
    let gc = g.chunk(i0, cnt, gbuf);
    // h = Aᵀ g at the chunk's vertices.
    for (li, h) in hbuf.chunks_exact_mut(n_out).enumerate() {
        let (cols, vals) = at.row::<T>(i0 + li);
        g.gather::<M>(cols, vals, tmp, h);
    }
    let hc = &*hbuf;
    let mut partial = Vec::new();
    if let Some(len) = sums {
        let mut lanes = vec![[T::ZERO; LANES]; len];
        let block = ci * co;
        if need_w {
            let xc = ctx.x.chunk(i0, cnt, xbuf);
            let dims = (ci, co, batch);
            for j in 0..(k - 1).max(1) {
                let t = ctx.term(j, xc, (i0, cnt));
                dot_chunk::<T, M>(t, gc, dims, &mut lanes[j * block..][..block]);
            }
            if k >= 2 {
                let t = ctx.term(k - 2, xc, (i0, cnt));
                dot_chunk::<T, M>(t, hc, dims, &mut lanes[(k - 1) * block..][..block]);
            }
        }
        let db = &mut lanes[k * block..];
        for gb in gc.chunks_exact(n_out) {
            for (acc, go) in db.iter_mut().zip(gb.chunks_exact(batch)) {
                // Lane b mod 8 takes g[b], in order of b, on a local copy: indexed as
                // `acc[b % 8]` in place, the sum ran one scalar load-add-store per value (half
                // of this sweep's time on horse-gallop).
                let mut a = *acc;
                let mut blocks = go.chunks_exact(LANES);
                for block in &mut blocks {
                    for (l, &v) in a.iter_mut().zip(block) {
                        *l += v;
                    }
                }
                for (l, &v) in a.iter_mut().zip(blocks.remainder()) {
                    *l += v;
                }
                *acc = a;
            }
        }
        partial = lanes
            .iter()
            .map(|l| l.iter().map(|v| v.to_f64()).sum())
            .collect();
    }
    if dest.is_discard() {
        return partial;
    }
    let hc = (k >= 2).then_some(hc);
    match dest.direct() {
        Some(out) => first_rows::<T, M>(gc, hc, w1, (ci, co, batch), out),
        None => {
            first_rows::<T, M>(gc, hc, w1, (ci, co, batch), obuf);
            dest.store(obuf);
        }
    }
    partial
}

/// b_{K−2} (or dx) rows of one chunk: g W_{K−2}ᵀ + c h W_{K−1}ᵀ (`w1` stacks both), or g W_0ᵀ.
#[inline(always)]
fn first_rows<T: Real, M: Madd>(
    gc: &[T],
    hc: Option<&[T]>,
    w1: &[T],
    (ci, co, batch): (usize, usize, usize),
    out: &mut [T],
) {
    let (n, n_out) = (ci * batch, co * batch);
    let d = MixDims { p: ci, batch };
    for (li, o) in out.chunks_exact_mut(n).enumerate() {
        let g_i = &gc[li * n_out..][..n_out];
        match hc {
            Some(hc) => mix::<T, M>(&[g_i, &hc[li * n_out..][..n_out]], w1, d, None, o),
            None => mix::<T, M>(&[g_i], w1, d, None, o),
        }
    }
}

multiversion!(
    #[allow(clippy::too_many_arguments)]
    fn clenshaw_chunk<T>(
        at: &Csr,
        g: Blocks<'_, T>,
        wt_k: &[T],
        step: (T, Option<&[T]>),
        next: Blocks<'_, T>,
        s: &ChebShape,
        chunk: usize,
        dest: ChunkOut<'_, T>,
        staging: &mut Staging<T>,
    ) => clenshaw_chunk_body
);

/// One Clenshaw step over one chunk: out = g W_kᵀ + alpha · Aᵀ next − after (`after` absent:
/// 0); `next` and `after` channel-major.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn clenshaw_chunk_body<T: Real, M: Madd>(
    at: &Csr,
    g: Blocks<'_, T>,
    wt_k: &[T],
    (alpha, after): (T, Option<&[T]>),
    next: Blocks<'_, T>,
    s: &ChebShape,
    chunk: usize,
    mut dest: ChunkOut<'_, T>,
    staging: &mut Staging<T>,
) {
    let (batch, ci, co) = (s.batch, s.ci, s.co);
    let (n, n_out) = (ci * batch, co * batch);
    let (i0, cnt) = chunk_span(chunk, s.v);
    let [gbuf, tmp, acc, obuf] = staging.get([cnt * n_out, n, n, cnt * n]);
    let gc = g.chunk(i0, cnt, gbuf);
    let step = (alpha, after, next);
    match dest.direct() {
        Some(out) => clenshaw_rows::<T, M>(at, gc, wt_k, step, s, (i0, tmp, acc), out),
        None => {
            clenshaw_rows::<T, M>(at, gc, wt_k, step, s, (i0, tmp, acc), obuf);
            dest.store(obuf);
        }
    }
}

/// The Clenshaw step's rows of one chunk (see [`clenshaw_chunk_body`]).
#[inline(always)]
fn clenshaw_rows<T: Real, M: Madd>(
    at: &Csr,
    gc: &[T],
    wt_k: &[T],
    (alpha, after, next): (T, Option<&[T]>, Blocks<'_, T>),
    s: &ChebShape,
    (i0, tmp, acc): (usize, &mut [T], &mut [T]),
    out: &mut [T],
) {
    let (n, n_out) = (s.ci * s.batch, s.co * s.batch);
    let d = MixDims {
        p: s.ci,
        batch: s.batch,
    };
    for (li, o) in out.chunks_exact_mut(n).enumerate() {
        let i = i0 + li;
        let (cols, vals) = at.row::<T>(i);
        next.gather::<M>(cols, vals, tmp, acc);
        mix::<T, M>(&[&gc[li * n_out..][..n_out]], wt_k, d, None, o);
        for (z, &m) in o.iter_mut().zip(acc.iter()) {
            *z = M::madd(alpha, m, *z);
        }
        if let Some(after) = after {
            for (z, &p) in o.iter_mut().zip(&after[i * n..][..n]) {
                *z = *z - p;
            }
        }
    }
}
