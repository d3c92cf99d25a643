//! How a convolution's weight variables feed the fused Chebyshev kernel.

use super::super::{Scalar, of};
use crate::error::Result;

/// A convolution's weight variables (indices into the trainable list).
#[derive(Debug, Clone, Copy)]
pub(super) enum ConvWeight {
    /// Chebyshev: one `[C_in·K, C_out]` variable, row f·K + k holding W_k's row f.
    Stacked(usize),
    /// Spatial, x W_self + (D⁻¹A x) W_nb: the Chebyshev kernel with K = 2 on D⁻¹A (T_0 x = x,
    /// T_1 x = D⁻¹A x), its weight the two variables' rows interleaved.
    Pair { w_self: usize, w_nb: usize },
}

impl ConvWeight {
    /// The kernel's `[C_in·K, C_out]` weight (`co` columns).
    pub(super) fn stacked<'a, T: Scalar>(
        self,
        w: &[&'a [T]],
        co: usize,
    ) -> std::borrow::Cow<'a, [T]> {
        match self {
            Self::Stacked(i) => std::borrow::Cow::Borrowed(w[i]),
            Self::Pair { w_self, w_nb } => std::borrow::Cow::Owned(
                w[w_self]
                    .chunks_exact(co)
                    .zip(w[w_nb].chunks_exact(co))
                    .flat_map(|(s, n)| s.iter().chain(n).copied())
                    .collect(),
            ),
        }
    }

    /// Runs `f` on the kernel's weight gradient and stores it in the variables' gradients.
    pub(super) fn write_grad<T: Scalar>(
        self,
        grads: &mut [Vec<T>],
        co: usize,
        f: impl FnOnce(&mut [T]) -> Result<()>,
    ) -> Result<()> {
        match self {
            Self::Stacked(i) => f(&mut grads[i]),
            Self::Pair { w_self, w_nb } => {
                let mut dw = vec![of(0.0); grads[w_self].len() + grads[w_nb].len()];
                f(&mut dw)?;
                for (k, dst) in [w_self, w_nb].into_iter().enumerate() {
                    let rows = dw.chunks_exact(co).skip(k).step_by(2);
                    for (d, s) in grads[dst].chunks_exact_mut(co).zip(rows) {
                        d.copy_from_slice(s);
                    }
                }
                Ok(())
            }
        }
    }
}
