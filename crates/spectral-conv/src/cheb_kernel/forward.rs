//! The forward pass: the stored terms T_1 … T_{K−2}, then the last sweep that computes T_{K−1}
//! vertex by vertex and mixes all K terms (plus the bias) into y.

use super::weights::weights_k_major;
use super::{ChebShape, Ctx, MAX_K};
use crate::kernel::{CHUNK_ROWS, Csr, Madd, Real, Staging, chunk_span, multiversion};
use crate::layout::{Blocks, ChunkOut, Io, chunk_outs};
use crate::mix::{MixDims, mix};
use crate::workspace::Workspace;
use rayon::prelude::*;

/// T_1 … T_{K−2} (none for K ≤ 2), channel-major `[V, ci, B]`: what the later sweeps read.
pub(crate) fn stored_terms<T: Real>(
    a: &Csr,
    x: Blocks<'_, T>,
    s: &ChebShape,
    ws: &Workspace,
) -> Vec<Vec<T>> {
    let n = s.batch * s.ci;
    let mut terms: Vec<Vec<T>> = (1..s.k.saturating_sub(1))
        .map(|_| ws.take(s.v * n))
        .collect();
    let mut outs: Vec<&mut [T]> = terms.iter_mut().map(|t| t.as_mut_slice()).collect();
    stored_terms_into(a, x, s, &mut outs, ws);
    terms
}

/// [`stored_terms`] into given buffers (`terms[k − 1]` = T_k, each `V·ci·B` long).
pub(crate) fn stored_terms_into<T: Real>(
    a: &Csr,
    x: Blocks<'_, T>,
    s: &ChebShape,
    terms: &mut [&mut [T]],
    ws: &Workspace,
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
                .for_each_init(
                    || Staging::new(ws),
                    |staging, (chunk, out)| term_chunk(a, src, prev, s, chunk, out, staging),
                );
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
        staging: &mut Staging<'_, T>,
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
    staging: &mut Staging<'_, T>,
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
    ws: &Workspace,
) -> (Vec<T>, Vec<Vec<T>>) {
    let terms = stored_terms(a, x, s, ws);
    let mut y = vec![T::ZERO; s.batch * s.v * s.co];
    let refs: Vec<&[T]> = terms.iter().map(|t| t.as_slice()).collect();
    mix_terms(a, x, &refs, w, bias, s, (io, &mut y), ws);
    (y, terms)
}

/// The forward's last sweep: T_{K−1} from the stored terms, all K terms mixed into y (layout
/// `io`).
#[allow(clippy::too_many_arguments)]
pub(crate) fn mix_terms<T: Real>(
    a: &Csr,
    x: Blocks<'_, T>,
    terms: &[&[T]],
    w: &[T],
    bias: Option<&[T]>,
    s: &ChebShape,
    (io, y): (Io, &mut [T]),
    ws: &Workspace,
) {
    let wk = weights_k_major(w, s);
    let ctx = Ctx { a, x, terms, s };
    chunk_outs(y, io, (s.batch, s.v, s.co))
        .into_par_iter()
        .enumerate()
        .for_each_init(
            || Staging::new(ws),
            |staging, (chunk, dest)| forward_chunk(&ctx, &wk, bias, chunk, dest, staging),
        );
}

multiversion!(
    fn forward_chunk<T>(
        ctx: &Ctx<'_, T>,
        wk: &[T],
        bias: Option<&[T]>,
        chunk: usize,
        dest: ChunkOut<'_, T>,
        staging: &mut Staging<'_, T>,
    ) => forward_chunk_body
);

#[inline(always)]
fn forward_chunk_body<T: Real, M: Madd>(
    ctx: &Ctx<'_, T>,
    wk: &[T],
    bias: Option<&[T]>,
    chunk: usize,
    mut dest: ChunkOut<'_, T>,
    staging: &mut Staging<'_, T>,
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
