//! The fused Chebyshev convolution as one candle `CustomOp2` on (x `[B, V, C_in]`,
//! W `[C_in·K, C_out]`): forward and backward run the kernels of `cheb_kernel.rs` on the CPU
//! storage directly.

use crate::cheb_kernel::{self, ChebShape};
use crate::kernel::{Csr, Real};
use crate::scratch::Recycled;
use crate::spmm::contiguous_span;
use candle_core::backend::BackendStorage;
use candle_core::{CpuStorage, CustomOp2, Layout, Shape, Storage, Tensor, WithDType};
use std::any::Any;
use std::sync::{Arc, Mutex};

/// The fused op on (x `[B, V, C_in]`, W `[C_in·K, C_out]`). The forward's stored terms
/// T_0 … T_{K−2} (channel-major) are kept for the backward pass (recomputed if missing).
pub(crate) struct ChebOp {
    a: Arc<Csr>,
    at: Arc<Csr>,
    k: usize,
    saved: Mutex<Option<Arc<dyn Any + Send + Sync>>>,
}

impl ChebOp {
    pub(crate) fn new(a: Arc<Csr>, at: Arc<Csr>, k: usize) -> Self {
        Self {
            a,
            at,
            k,
            saved: Mutex::new(None),
        }
    }

    fn shape(&self, x_dims: &[usize], w_dims: &[usize]) -> candle_core::Result<ChebShape> {
        let (&[batch, v, ci], &[rows, co]) = (x_dims, w_dims) else {
            candle_core::bail!("cheb-conv: shapes {x_dims:?} and {w_dims:?}");
        };
        if v != self.a.rows || rows != ci * self.k {
            candle_core::bail!(
                "cheb-conv: input {x_dims:?} and weight {w_dims:?} do not fit {} vertices, K = {}",
                self.a.rows,
                self.k
            );
        }
        Ok(ChebShape {
            batch,
            v,
            ci,
            co,
            k: self.k,
        })
    }

    fn run<T: Real>(&self, x: &[T], w: &[T], s: &ChebShape) -> Vec<T> {
        let (y, stored) = cheb_kernel::forward(&self.a, x, w, s);
        if let Ok(mut saved) = self.saved.lock() {
            *saved = Some(Arc::new(Recycled(stored)));
        }
        y
    }

    /// The stored terms of the forward pass, or recomputed from x.
    fn stored<T: Real>(&self, x: &[T], s: &ChebShape) -> Arc<Recycled<T>> {
        let saved = self.saved.lock().ok().and_then(|s| s.clone());
        match saved.and_then(|s| s.downcast::<Recycled<T>>().ok()) {
            Some(stored) => stored,
            None => Arc::new(Recycled(cheb_kernel::stored_terms(&self.a, x, s))),
        }
    }

    fn backward<T: Real + WithDType>(
        &self,
        x: &Tensor,
        w: &Tensor,
        g: &Tensor,
        need: (bool, bool),
    ) -> candle_core::Result<(Option<Tensor>, Option<Tensor>)> {
        let (x_store, x_layout) = x.storage_and_layout();
        let (w_store, w_layout) = w.storage_and_layout();
        let (g_store, g_layout) = g.storage_and_layout();
        let s = self.shape(x_layout.dims(), w_layout.dims())?;
        let (xs, ws, gs) = (
            cpu_slice::<T>(&x_store, x_layout)?,
            cpu_slice::<T>(&w_store, w_layout)?,
            cpu_slice::<T>(&g_store, g_layout)?,
        );
        if gs.len() != s.batch * s.v * s.co {
            candle_core::bail!("cheb-conv: gradient of shape {:?}", g_layout.dims());
        }
        let stored = self.stored(xs, &s);
        let (dx, dw) = cheb_kernel::backward(&self.a, &self.at, &stored.0, ws, gs, &s, need);
        let dx = dx
            .map(|d| Tensor::from_vec(d, x_layout.dims(), x.device()))
            .transpose()?;
        let dw = dw
            .map(|d| Tensor::from_vec(d, w_layout.dims(), w.device()))
            .transpose()?;
        Ok((dx, dw))
    }
}

/// The contiguous data of a CPU tensor of dtype `T`.
fn cpu_slice<'a, T: WithDType>(
    storage: &'a Storage,
    layout: &Layout,
) -> candle_core::Result<&'a [T]> {
    let Storage::Cpu(cpu) = storage else {
        candle_core::bail!("cheb-conv: the backward pass expects CPU tensors");
    };
    let (lo, hi) = contiguous_span("cheb-conv", layout)?;
    Ok(&T::cpu_storage_as_slice(cpu)?[lo..hi])
}

impl CustomOp2 for ChebOp {
    fn name(&self) -> &'static str {
        "cheb-conv"
    }

    fn cpu_fwd(
        &self,
        xs: &CpuStorage,
        xl: &Layout,
        ws: &CpuStorage,
        wl: &Layout,
    ) -> candle_core::Result<(CpuStorage, Shape)> {
        let s = self.shape(xl.dims(), wl.dims())?;
        let (xa, xb) = contiguous_span("cheb-conv", xl)?;
        let (wa, wb) = contiguous_span("cheb-conv", wl)?;
        let out_shape = Shape::from((s.batch, s.v, s.co));
        match (xs, ws) {
            (CpuStorage::F32(x), CpuStorage::F32(w)) => Ok((
                CpuStorage::F32(self.run(&x[xa..xb], &w[wa..wb], &s)),
                out_shape,
            )),
            (CpuStorage::F64(x), CpuStorage::F64(w)) => Ok((
                CpuStorage::F64(self.run(&x[xa..xb], &w[wa..wb], &s)),
                out_shape,
            )),
            _ => candle_core::bail!(
                "cheb-conv: dtypes {:?} and {:?}; expected both f32 or both f64",
                xs.dtype(),
                ws.dtype()
            ),
        }
    }

    fn bwd(
        &self,
        x: &Tensor,
        w: &Tensor,
        _y: &Tensor,
        grad: &Tensor,
    ) -> candle_core::Result<(Option<Tensor>, Option<Tensor>)> {
        // Only what someone asked for: no dx for a network's input data.
        let need = (x.track_op(), w.track_op());
        let (x, w) = (x.contiguous()?, w.contiguous()?);
        // Gradients can arrive strided (zero strides from a broadcast): make them dense.
        let g = grad.contiguous()?;
        match x.dtype() {
            candle_core::DType::F32 => self.backward::<f32>(&x, &w, &g, need),
            candle_core::DType::F64 => self.backward::<f64>(&x, &w, &g, need),
            other => candle_core::bail!("cheb-conv: dtype {other:?} not supported"),
        }
    }
}
