//! How a convolution's weight variables feed the fused Chebyshev kernel.

use super::super::{Real, of};
use crate::error::Result;

/// A convolution's weight variables (indices into the trainable list).
#[derive(Debug, Clone, Copy)]
pub(super) enum ConvWeight {
    /// Chebyshev: one `[C_in·K, C_out]` variable, row f·K + k holding W_k's row f.
    Stacked(usize),
    /// Spatial, x W_self + (D⁻¹A x) W_nb: the Chebyshev kernel with K = 2 on D⁻¹A (T_0 x = x,
    /// T_1 x = D⁻¹A x), its weight the two variables' rows interleaved.
    Pair { w_self: usize, w_nb: usize },
    /// A tied decoder convolution: the adjoint of an encoder convolution's weights (run on the
    /// transposed operator). Chebyshev: Σ_k T_k(L̃ᵀ) Y W_kᵀ, the per-order blocks of W
    /// transposed; spatial: Y W_selfᵀ + (D⁻¹A)ᵀ Y W_nbᵀ.
    Adjoint(Adjoint),
}

/// The encoder weights a tied decoder convolution is the adjoint of.
#[derive(Debug, Clone, Copy)]
pub(super) enum Adjoint {
    Cheb { w: usize, k: usize },
    Spatial { w_self: usize, w_nb: usize },
}

impl ConvWeight {
    /// The kernel's `[C_in·K, C_out]` weight (`co` columns).
    pub(super) fn stacked<'a, T: Real>(
        self,
        w: &[&'a [T]],
        co: usize,
    ) -> std::borrow::Cow<'a, [T]> {
        use std::borrow::Cow;
        match self {
            Self::Stacked(i) => Cow::Borrowed(w[i]),
            Self::Pair { w_self, w_nb } => Cow::Owned(
                w[w_self]
                    .chunks_exact(co)
                    .zip(w[w_nb].chunks_exact(co))
                    .flat_map(|(s, n)| s.iter().chain(n).copied())
                    .collect(),
            ),
            Self::Adjoint(a) => {
                let mut out = vec![of(0.0); a.len(w)];
                a.each(w, co, |enc, dec, src| out[dec] = src[enc]);
                Cow::Owned(out)
            }
        }
    }

    /// Runs `f` on the kernel's weight gradient and stores it in the variables' gradients, or
    /// adds it there (`add`: an encoder convolution whose weights a tied decoder convolution
    /// shares; the decoder's backward pass runs first and writes its part).
    pub(super) fn write_grad<T: Real>(
        self,
        grads: &mut [Vec<T>],
        co: usize,
        add: bool,
        f: impl FnOnce(&mut [T]) -> Result<()>,
    ) -> Result<()> {
        let put = |d: &mut T, s: T| *d = if add { *d + s } else { s };
        match self {
            Self::Stacked(i) if !add => f(&mut grads[i]),
            Self::Stacked(i) => {
                let mut dw = vec![of(0.0); grads[i].len()];
                f(&mut dw)?;
                grads[i].iter_mut().zip(dw).for_each(|(d, s)| put(d, s));
                Ok(())
            }
            Self::Pair { w_self, w_nb } => {
                let mut dw = vec![of(0.0); grads[w_self].len() + grads[w_nb].len()];
                f(&mut dw)?;
                for (k, dst) in [w_self, w_nb].into_iter().enumerate() {
                    let rows = dw.chunks_exact(co).skip(k).step_by(2);
                    for (d, s) in grads[dst].chunks_exact_mut(co).zip(rows) {
                        d.iter_mut().zip(s).for_each(|(d, &s)| put(d, s));
                    }
                }
                Ok(())
            }
            Self::Adjoint(a) => {
                let lens: Vec<usize> = a.vars().iter().map(|&v| grads[v].len()).collect();
                let mut dw = vec![of(0.0); lens.iter().sum()];
                f(&mut dw)?;
                // The adjoint's gradient, transposed back onto the encoder's variables.
                let vars = a.vars();
                let mut split: Vec<Vec<T>> = lens.iter().map(|&n| vec![of(0.0); n]).collect();
                a.each_split(lens[0], co, |var, enc, dec| split[var][enc] = dw[dec]);
                for (&v, g) in vars.iter().zip(split) {
                    grads[v].iter_mut().zip(g).for_each(|(d, s)| put(d, s));
                }
                Ok(())
            }
        }
    }
}

impl Adjoint {
    fn vars(self) -> Vec<usize> {
        match self {
            Self::Cheb { w, .. } => vec![w],
            Self::Spatial { w_self, w_nb } => vec![w_self, w_nb],
        }
    }

    fn len<T>(self, w: &[&[T]]) -> usize {
        self.vars().iter().map(|&v| w[v].len()).sum()
    }

    /// Calls `f(encoder index, adjoint index, encoder variable's values)` for every weight.
    fn each<T: Copy>(self, w: &[&[T]], co: usize, mut f: impl FnMut(usize, usize, &[T])) {
        let vars = self.vars();
        self.each_split(w[vars[0]].len(), co, |var, enc, dec| {
            f(enc, dec, w[vars[var]])
        });
    }

    /// Calls `f(variable, its index, adjoint index)` for every weight; `var_len` is the length
    /// of one encoder variable, `co` the adjoint's output channels (the encoder's inputs).
    fn each_split(self, var_len: usize, co: usize, mut f: impl FnMut(usize, usize, usize)) {
        match self {
            // Encoder W[fin·K + k, o] (`[co·K, n_o]`) ↦ adjoint W'[o·K + k, fin].
            Self::Cheb { k, .. } => {
                let n_o = var_len / (co * k);
                for fin in 0..co {
                    for kk in 0..k {
                        for o in 0..n_o {
                            f(0, (fin * k + kk) * n_o + o, (o * k + kk) * co + fin);
                        }
                    }
                }
            }
            // Encoder W_self, W_nb `[co, n_o]` ↦ adjoint rows 2o (W_selfᵀ) and 2o + 1 (W_nbᵀ).
            Self::Spatial { .. } => {
                let n_o = var_len / co;
                for var in 0..2 {
                    for fin in 0..co {
                        for o in 0..n_o {
                            f(var, fin * n_o + o, (2 * o + var) * co + fin);
                        }
                    }
                }
            }
        }
    }
}
