//! Clenshaw's recurrence, the backward sweeps after the first: b_k = g W_kᵀ + 2 Aᵀ b_{k+1} −
//! b_{k+2} from b_{K−2} down to dx = b_0, one sparse pass each.

use super::ChebShape;
use super::weights::weights_t;
use crate::kernel::{Csr, Madd, Real, Staging, chunk_span, multiversion};
use crate::layout::{Blocks, ChunkOut, Io, chunk_outs};
use crate::mix::{MixDims, mix};
use crate::workspace::Workspace;
use rayon::prelude::*;

/// Clenshaw's recurrence from b_{K−2} (K ≥ 3) down to dx = b_0, written to `dx` (layout `io`).
/// `work` holds (K − 2) channel-major `V·ci·B` blocks: block j is b_{K−2−j}, block 0 written by
/// the caller, the others here (the caller's scratch: nothing is allocated).
pub(super) fn clenshaw<T: Real>(
    at: &Csr,
    w: &[T],
    g: Blocks<'_, T>,
    work: &mut [T],
    s: &ChebShape,
    (io, dx): (Io, &mut [T]),
    ws: &Workspace,
) {
    let size = s.batch * s.v * s.ci;
    let mut dx = Some(dx);
    for k in (0..=s.k - 3).rev() {
        let alpha = T::from_f64(if k == 0 { 1.0 } else { 2.0 });
        // b_k goes to block K − 2 − k; the b it reads are in the blocks before.
        let (done, rest) = work.split_at_mut((s.k - 2 - k) * size);
        let done = &*done;
        let b = |kk: usize| -> &[T] { &done[(s.k - 2 - kk) * size..][..size] };
        // b_{k+2} = b_{K−1} = g W_{K−1}ᵀ was never stored: subtract it through the weights.
        let (wt_k, after) = if k + 2 == s.k - 1 {
            (weights_t(w, s, (1.0, k), Some((-1.0, s.k - 1))), None)
        } else {
            (weights_t(w, s, (1.0, k), None), Some(b(k + 2)))
        };
        let next = Blocks::channel_major(b(k + 1), s.batch, s.ci);
        let (out_io, out): (Io, &mut [T]) = if k > 0 {
            (Io::VertexChannel, &mut rest[..size])
        } else {
            match dx.take() {
                Some(d) => (io, d),
                None => return,
            }
        };
        chunk_outs(out, out_io, (s.batch, s.v, s.ci))
            .into_par_iter()
            .enumerate()
            .for_each_init(
                || Staging::new(ws),
                |staging, (chunk, dest)| {
                    let step = (alpha, after);
                    clenshaw_chunk(at, g, &wt_k, step, next, s, chunk, dest, staging)
                },
            );
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
        staging: &mut Staging<'_, T>,
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
    staging: &mut Staging<'_, T>,
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
