//! The backward pass and its first sweep: h = Aᵀ g, the dW and db partial sums per chunk, and
//! b_{K−2} (or dx directly for K ≤ 2); the rest of dx is [`clenshaw`]'s.

use super::clenshaw::clenshaw;
use super::weights::{weights_from_k_major, weights_t};
use super::{ChebShape, Ctx};
use crate::kernel::{CHUNK_ROWS, Csr, Madd, Real, Staging, chunk_span, multiversion};
use crate::layout::{Blocks, ChunkOut, Io, chunk_outs};
use crate::mix::{LANES, MixDims, dot_chunk, mix};
use crate::workspace::Workspace;
use rayon::prelude::*;

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

/// What the backward pass reads: A and its stored transpose, x, the forward's stored terms
/// T_1 … T_{K−2}, W, the output gradient g and the sizes.
#[derive(Clone, Copy)]
pub(crate) struct Inputs<'a, T> {
    pub a: &'a Csr,
    pub at: &'a Csr,
    pub x: Blocks<'a, T>,
    pub terms: &'a [&'a [T]],
    pub w: &'a [T],
    pub g: Blocks<'a, T>,
    pub s: &'a ChebShape,
}

/// Backward into fresh vectors (dx in layout `io`).
pub(crate) fn backward<T: Real>(
    inp: Inputs<'_, T>,
    io: Io,
    need: Need,
    ws: &Workspace,
) -> Grads<T> {
    let s = inp.s;
    let size = s.batch * s.v * s.ci;
    let mut dx = need.x.then(|| vec![T::ZERO; size]);
    // Sweep 1 writes b_{K−2} into a buffer of the workspace (K ≥ 3) or, for K ≤ 2, dx itself.
    let mut work = (need.x && s.k >= 3).then(|| ws.take((s.k - 2) * size));
    let bufs = Bufs {
        dx: dx.as_deref_mut().map(|d| (io, d)),
        work: work.as_deref_mut(),
        ws,
    };
    let (dw, db) = backward_into(inp, bufs, need);
    if let Some(work) = work {
        ws.give(work);
    }
    Grads { dx, dw, db }
}

/// Where [`backward_into`] writes dx (and in which layout), and its work buffer for Clenshaw's
/// b_{K−2} … b_1 ((K − 2) channel-major blocks of `V·ci·B` values; needed when dx is wanted and
/// K ≥ 3), and the workspace its sweeps stage chunks in.
pub(crate) struct Bufs<'a, T> {
    pub dx: Option<(Io, &'a mut [T])>,
    pub work: Option<&'a mut [T]>,
    pub ws: &'a Workspace,
}

/// The backward pass into given buffers: dx (if `bufs.dx`), and returns dW `[ci·K, co]` and db
/// as asked by `need` (`need.x` is ignored: dx is computed iff a buffer is given). Clenshaw's
/// b_{K−2} … b_1 go to `bufs.work`; the sweeps' staging comes from `bufs.ws`.
pub(crate) fn backward_into<T: Real>(
    inp: Inputs<'_, T>,
    bufs: Bufs<'_, T>,
    need: Need,
) -> (Option<Vec<T>>, Option<Vec<T>>) {
    let Inputs {
        a,
        at,
        x,
        terms,
        w,
        g,
        s,
    } = inp;
    let k = s.k;
    let size = s.batch * s.v * s.ci;
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
    let Bufs { dx, work, ws } = bufs;
    let (mut dx, mut work) = (dx, work);
    let first: Option<(Io, &mut [T])> = match (internal, dx.as_mut(), work.as_deref_mut()) {
        (false, Some((io, d)), _) => Some((*io, &mut **d)),
        (true, Some(_), Some(wb)) => Some((Io::VertexChannel, &mut wb[..size])),
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
        .map_init(
            || Staging::new(ws),
            |staging, (chunk, dest)| {
                sweep_chunk(&ctx, at, g, &w1, (chunk, sums, need.w), dest, staging)
            },
        )
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
        clenshaw(at, w, g, wb, s, (io, d), ws);
    }
    (dw, db)
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
        staging: &mut Staging<'_, T>,
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
    staging: &mut Staging<'_, T>,
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
