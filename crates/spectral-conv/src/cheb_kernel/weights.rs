//! The weight layouts the kernels work in: W rearranged k-major for the forward mix, transposed
//! (and combined) for the backward products, and dW brought back from the k-major accumulation
//! (the recurrence for dW_{K−1} is derived in the `cheb_kernel` module comment).

use super::ChebShape;
use crate::kernel::Real;

/// W rearranged k-major: `wk[(k·ci + f)·co + o] = W[(f·K + k)·co + o]` (inputs × outputs).
pub(super) fn weights_k_major<T: Real>(w: &[T], s: &ChebShape) -> Vec<T> {
    let mut wk = Vec::with_capacity(w.len());
    for k in 0..s.k {
        for f in 0..s.ci {
            wk.extend_from_slice(&w[(f * s.k + k) * s.co..][..s.co]);
        }
    }
    wk
}

/// α · W_kᵀ + β · W_jᵀ as `[co, ci]` (rows: outputs of the forward map, the inputs of g W_kᵀ).
pub(super) fn weights_t<T: Real>(
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

/// dW from the k-major accumulation order back to the `[ci·K, co]` layout, with
/// dW_{K−1} = c·P − dW_{K−3} (see the module comment).
pub(super) fn weights_from_k_major<T: Real>(acc: &[f64], s: &ChebShape) -> Vec<T> {
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
