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

mod backward;
mod clenshaw;
mod forward;
#[cfg(test)]
mod tests;
mod weights;

use crate::kernel::{Csr, Real};
use crate::layout::Blocks;

pub(crate) use backward::{Bufs, Inputs, Need, backward, backward_into};
pub(crate) use forward::{forward, mix_terms, stored_terms, stored_terms_into};

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
