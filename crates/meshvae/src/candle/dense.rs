//! The dense layers between the flattened coarse features and the latent space, with weight
//! gradients that bypass candle's gradient store.
//!
//! Why: on a 42k-vertex mesh each dense weight is ~100 MB, and W_μ is used twice (the μ head and
//! the tied decoder layer). candle's backward accumulates a variable's gradient as
//! `zeros + g₁`, then `+ g₂`, each a fresh tensor, which put ~5 copies of W_μ's size in memory at
//! once. Here the op's backward returns no gradient for the weight and adds its contribution in
//! place into a [`GradSink`] instead; [`crate::MeshVae::backward`] moves the sums into the
//! gradient store, where Adam and the tests find them as usual.
//!
//! Off the CPU (or for other dtypes) the layers are plain candle matmuls and the gradients flow
//! through the store; the sinks then stay empty.

use crate::candle::ops::{Real, fusable, span, span_mut};
use candle_core::backend::BackendStorage;
use candle_core::{CpuStorage, CustomOp2, InplaceOp2, Layout, Shape, Tensor, bail};
use rayon::prelude::*;
use std::sync::{Arc, Mutex};

/// Where the backward pass leaves a weight's gradient (the sum of all its uses).
#[derive(Debug, Default)]
pub(crate) struct GradSink(Mutex<Option<Tensor>>);

impl GradSink {
    fn lock(&self) -> std::sync::MutexGuard<'_, Option<Tensor>> {
        // A panic while holding the lock cannot leave a half-added sum that matters: the step
        // that panicked is abandoned anyway.
        self.0.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Adds `g` to the sum (the first contribution is kept as is, without a copy).
    fn deposit(&self, g: Tensor) -> candle_core::Result<()> {
        let g = g.detach().contiguous()?;
        let mut slot = self.lock();
        match slot.as_mut() {
            None => *slot = Some(g),
            Some(sum) => sum.inplace_op2(&g, &AddAssign)?,
        }
        Ok(())
    }

    /// The sum so far, emptying the sink.
    pub(crate) fn take(&self) -> Option<Tensor> {
        self.lock().take()
    }
}

/// The weight operand's orientation: `x · W` (W `[in, out]`) or `x · Wᵀ` (W `[out, in]`).
#[derive(Debug, Clone, Copy)]
pub(crate) enum Orientation {
    Plain,
    Transposed,
}

/// y = x·W or x·Wᵀ for x `[B, in]`; W's gradient goes to `sink`.
pub(crate) fn dense(
    x: &Tensor,
    w: &Tensor,
    orientation: Orientation,
    sink: &Arc<GradSink>,
) -> crate::error::Result<Tensor> {
    if fusable(x) && x.dtype() == w.dtype() && w.device().is_cpu() {
        let op = DenseOp {
            orientation,
            sink: sink.clone(),
        };
        return Ok(x.contiguous()?.apply_op2(w, op)?);
    }
    Ok(match orientation {
        Orientation::Plain => x.matmul(w)?,
        Orientation::Transposed => x.matmul(&w.t()?)?,
    })
}

struct DenseOp {
    orientation: Orientation,
    sink: Arc<GradSink>,
}

impl CustomOp2 for DenseOp {
    fn name(&self) -> &'static str {
        "dense"
    }

    fn cpu_fwd(
        &self,
        s1: &CpuStorage,
        l1: &Layout,
        s2: &CpuStorage,
        l2: &Layout,
    ) -> candle_core::Result<(CpuStorage, Shape)> {
        let (&[b, k], &[r, c]) = (l1.dims(), l2.dims()) else {
            bail!(
                "dense: x {:?} and W {:?} must be matrices",
                l1.dims(),
                l2.dims()
            );
        };
        if !l2.is_contiguous() {
            bail!("dense: the weight must be contiguous");
        }
        let (n, rhs) = match self.orientation {
            Orientation::Plain => (c, l2.clone()),
            Orientation::Transposed => (r, l2.transpose(0, 1)?),
        };
        if rhs.dims()[0] != k {
            bail!("dense: x {:?} does not fit W {:?}", l1.dims(), l2.dims());
        }
        let y = s1.matmul(s2, (1, b, n, k), l1, &rhs)?;
        Ok((y, Shape::from((b, n))))
    }

    fn bwd(
        &self,
        x: &Tensor,
        w: &Tensor,
        _y: &Tensor,
        g: &Tensor,
    ) -> candle_core::Result<(Option<Tensor>, Option<Tensor>)> {
        let (x, w, g) = (x.detach(), w.detach(), g.detach().contiguous()?);
        let (dx, dw) = match self.orientation {
            // y = xW: dx = gWᵀ, dW = xᵀg.
            Orientation::Plain => (g.matmul(&w.t()?)?, x.t()?.matmul(&g)?),
            // y = xWᵀ: dx = gW, dW = gᵀx.
            Orientation::Transposed => (g.matmul(&w)?, g.t()?.matmul(&x)?),
        };
        self.sink.deposit(dw)?;
        Ok((Some(dx), None))
    }
}

/// In place: a ← a + b.
struct AddAssign;

impl InplaceOp2 for AddAssign {
    fn name(&self) -> &'static str {
        "add-assign"
    }

    fn cpu_fwd(
        &self,
        s1: &mut CpuStorage,
        l1: &Layout,
        s2: &CpuStorage,
        l2: &Layout,
    ) -> candle_core::Result<()> {
        fn run<T: Real>(a: &mut [T], b: &[T]) {
            a.par_chunks_mut(1 << 16)
                .zip(b.par_chunks(1 << 16))
                .for_each(|(a, b)| {
                    for (a, &b) in a.iter_mut().zip(b) {
                        *a = *a + b;
                    }
                });
        }
        if l1.shape() != l2.shape() {
            bail!("add-assign: shapes {:?} and {:?}", l1.shape(), l2.shape());
        }
        match (s1, s2) {
            (CpuStorage::F32(a), CpuStorage::F32(b)) => {
                run(span_mut("add-assign", a, l1)?, span("add-assign", b, l2)?)
            }
            (CpuStorage::F64(a), CpuStorage::F64(b)) => {
                run(span_mut("add-assign", a, l1)?, span("add-assign", b, l2)?)
            }
            _ => bail!("add-assign: f32 or f64 of one dtype only"),
        }
        Ok(())
    }
}
