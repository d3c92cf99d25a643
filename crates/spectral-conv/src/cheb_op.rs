//! The fused Chebyshev convolution as one candle custom op: `CustomOp2` on (x, W), or
//! `CustomOp3` on (x, W, b) with a bias. Forward and backward run the kernels of
//! `cheb_kernel.rs` on the CPU storage directly, for x in `[B, V, C_in]` or `[V, B, C_in]`.

use crate::cheb_kernel::{self, ChebShape, Need};
use crate::custom_op::{contiguous_span, cpu_slice};
use crate::kernel::{Csr, Real};
use crate::layout::{Blocks, Io, to_channel_major};
use crate::workspace::{Recycled, Workspace};
use candle_core::backend::BackendStorage;
use candle_core::{CpuStorage, CustomOp2, CustomOp3, Layout, Shape, Tensor, WithDType};
use std::any::Any;
use std::sync::{Arc, Mutex};

/// The op's name in candle and in error messages.
const NAME: &str = "cheb-conv";

/// The fused op. The forward pass keeps its stored terms (and, for `[B, V, C]` input, the
/// channel-major copy of x) for the backward pass; they are recomputed if missing.
pub(crate) struct ChebOp {
    a: Arc<Csr>,
    at: Arc<Csr>,
    k: usize,
    io: Io,
    workspace: Arc<Workspace>,
    saved: Mutex<Option<Arc<dyn Any + Send + Sync>>>,
}

/// What the forward pass leaves for the backward pass: buffers 0 … (x copy first, if any).
struct Saved<T: Real> {
    x_copy: bool,
    bufs: Recycled<T>,
}

impl<T: Real> Saved<T> {
    fn terms(&self) -> &[Vec<T>] {
        &self.bufs.bufs[usize::from(self.x_copy)..]
    }
}

/// Dense slices of the op's arguments.
struct Args<'a, T> {
    x: &'a [T],
    w: &'a [T],
    b: Option<&'a [T]>,
}

impl ChebOp {
    pub(crate) fn new(
        a: Arc<Csr>,
        at: Arc<Csr>,
        k: usize,
        io: Io,
        workspace: Arc<Workspace>,
    ) -> Self {
        Self {
            a,
            at,
            k,
            io,
            workspace,
            saved: Mutex::new(None),
        }
    }

    /// Buffers that return to this op's workspace when the last reference goes.
    fn recycled<T: Real>(&self, bufs: Vec<Vec<T>>) -> Recycled<T> {
        Recycled {
            bufs,
            home: self.workspace.clone(),
        }
    }

    fn shape(&self, x_dims: &[usize], w_dims: &[usize]) -> candle_core::Result<ChebShape> {
        let (&[d0, d1, d2], &[rows, co]) = (x_dims, w_dims) else {
            candle_core::bail!("cheb-conv: shapes {x_dims:?} and {w_dims:?}");
        };
        let (batch, v, ci) = match self.io {
            Io::BatchMajor => (d0, d1, d2),
            Io::VertexBatch => (d1, d0, d2),
            Io::VertexChannel => (d2, d0, d1),
        };
        if v != self.a.rows() || rows != ci * self.k {
            candle_core::bail!(
                "cheb-conv: input {x_dims:?} and weight {w_dims:?} do not fit {} vertices, K = {}",
                self.a.rows(),
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

    fn out_shape(&self, s: &ChebShape) -> Shape {
        match self.io {
            Io::BatchMajor => Shape::from((s.batch, s.v, s.co)),
            Io::VertexBatch => Shape::from((s.v, s.batch, s.co)),
            Io::VertexChannel => Shape::from((s.v, s.co, s.batch)),
        }
    }

    /// x as blocks: the caller's array, or (`[B, V, C]`) a channel-major copy made here.
    fn x_blocks<'a, T: Real>(
        &self,
        x: &'a [T],
        copy: Option<&'a Vec<T>>,
        s: &ChebShape,
    ) -> Blocks<'a, T> {
        match copy {
            Some(c) => Blocks::channel_major(c, s.batch, s.ci),
            None => Blocks::new(x, self.io, s.batch, s.ci),
        }
    }

    fn saved_state<T: Real>(&self, x: &[T], s: &ChebShape) -> Saved<T> {
        let mut bufs = Vec::new();
        let x_copy = self.io == Io::BatchMajor;
        if x_copy {
            bufs.push(to_channel_major(
                x,
                self.io,
                (s.batch, s.v, s.ci),
                &self.workspace,
            ));
        }
        let xb = self.x_blocks(x, bufs.first(), s);
        let terms = cheb_kernel::stored_terms(&self.a, xb, s, &self.workspace);
        bufs.extend(terms);
        Saved {
            x_copy,
            bufs: self.recycled(bufs),
        }
    }

    fn run<T: Real>(&self, args: Args<'_, T>, s: &ChebShape) -> Vec<T> {
        let x_copy = (self.io == Io::BatchMajor)
            .then(|| to_channel_major(args.x, self.io, (s.batch, s.v, s.ci), &self.workspace));
        let xb = self.x_blocks(args.x, x_copy.as_ref(), s);
        let (y, terms) =
            cheb_kernel::forward(&self.a, xb, args.w, args.b, s, self.io, &self.workspace);
        let mut bufs: Vec<Vec<T>> = x_copy.into_iter().collect();
        let x_copy = !bufs.is_empty();
        bufs.extend(terms);
        let saved = Saved {
            x_copy,
            bufs: self.recycled(bufs),
        };
        if let Ok(mut slot) = self.saved.lock() {
            *slot = Some(Arc::new(saved));
        }
        y
    }

    fn fwd(
        &self,
        (xs, xl): (&CpuStorage, &Layout),
        (ws, wl): (&CpuStorage, &Layout),
        bias: Option<(&CpuStorage, &Layout)>,
    ) -> candle_core::Result<(CpuStorage, Shape)> {
        let s = self.shape(xl.dims(), wl.dims())?;
        let (xa, xb) = contiguous_span(NAME, xl)?;
        let (wa, wb) = contiguous_span(NAME, wl)?;
        let b_span = match bias {
            Some((_, bl)) if bl.dims() == [s.co] => Some(contiguous_span(NAME, bl)?),
            Some((_, bl)) => candle_core::bail!("cheb-conv: bias of shape {:?}", bl.dims()),
            None => None,
        };
        let out = self.out_shape(&s);
        macro_rules! run {
            ($variant:ident, $x:expr, $w:expr) => {{
                let b = match (bias, b_span) {
                    (Some((CpuStorage::$variant(b), _)), Some((lo, hi))) => Some(&b[lo..hi]),
                    (None, _) => None,
                    _ => candle_core::bail!("cheb-conv: the bias has another dtype"),
                };
                let args = Args {
                    x: &$x[xa..xb],
                    w: &$w[wa..wb],
                    b,
                };
                Ok((CpuStorage::$variant(self.run(args, &s)), out))
            }};
        }
        match (xs, ws) {
            (CpuStorage::F32(x), CpuStorage::F32(w)) => run!(F32, x, w),
            (CpuStorage::F64(x), CpuStorage::F64(w)) => run!(F64, x, w),
            _ => candle_core::bail!(
                "cheb-conv: dtypes {:?} and {:?}; expected both f32 or both f64",
                xs.dtype(),
                ws.dtype()
            ),
        }
    }

    /// The stored state of the forward pass, or recomputed from x.
    fn stored<T: Real>(&self, x: &[T], s: &ChebShape) -> Arc<Saved<T>> {
        let saved = self.saved.lock().ok().and_then(|s| s.clone());
        match saved.and_then(|s| s.downcast::<Saved<T>>().ok()) {
            Some(stored) => stored,
            None => Arc::new(self.saved_state(x, s)),
        }
    }

    fn backward<T: Real + WithDType>(
        &self,
        (x, w, g): (&Tensor, &Tensor, &Tensor),
        bias: Option<&Tensor>,
        need: Need,
    ) -> candle_core::Result<[Option<Tensor>; 3]> {
        let (x_store, x_layout) = x.storage_and_layout();
        let (w_store, w_layout) = w.storage_and_layout();
        let (g_store, g_layout) = g.storage_and_layout();
        let s = self.shape(x_layout.dims(), w_layout.dims())?;
        let (xs, ws, gs) = (
            cpu_slice::<T>(NAME, &x_store, x_layout)?,
            cpu_slice::<T>(NAME, &w_store, w_layout)?,
            cpu_slice::<T>(NAME, &g_store, g_layout)?,
        );
        if g_layout.shape() != &self.out_shape(&s) {
            candle_core::bail!("cheb-conv: gradient of shape {:?}", g_layout.dims());
        }
        let saved = self.stored(xs, &s);
        let xb = self.x_blocks(xs, saved.x_copy.then(|| &saved.bufs.bufs[0]), &s);
        let g_copy = (self.io == Io::BatchMajor)
            .then(|| to_channel_major(gs, self.io, (s.batch, s.v, s.co), &self.workspace));
        let gb = match &g_copy {
            Some(c) => Blocks::channel_major(c, s.batch, s.co),
            None => Blocks::new(gs, self.io, s.batch, s.co),
        };
        let terms: Vec<&[T]> = saved.terms().iter().map(|t| t.as_slice()).collect();
        let inputs = cheb_kernel::Inputs {
            a: &self.a,
            at: &self.at,
            x: xb,
            terms: &terms,
            w: ws,
            g: gb,
            s: &s,
        };
        let grads = cheb_kernel::backward(inputs, self.io, need, &self.workspace);
        if let Some(c) = g_copy {
            self.workspace.give(c);
        }
        let dx = grads
            .dx
            .map(|d| Tensor::from_vec(d, x_layout.dims(), x.device()))
            .transpose()?;
        let dw = grads
            .dw
            .map(|d| Tensor::from_vec(d, w_layout.dims(), w.device()))
            .transpose()?;
        let db = match (grads.db, bias) {
            (Some(d), Some(b)) => Some(Tensor::from_vec(d, b.dims(), b.device())?),
            _ => None,
        };
        Ok([dx, dw, db])
    }

    fn bwd_any(
        &self,
        x: &Tensor,
        w: &Tensor,
        bias: Option<&Tensor>,
        grad: &Tensor,
    ) -> candle_core::Result<[Option<Tensor>; 3]> {
        // Only what someone asked for: no dx for a network's input data.
        let need = Need {
            x: x.track_op(),
            w: w.track_op(),
            b: bias.is_some_and(|b| b.track_op()),
        };
        let (x, w) = (x.contiguous()?, w.contiguous()?);
        // Gradients can arrive strided (zero strides from a broadcast): make them dense.
        let g = grad.contiguous()?;
        match x.dtype() {
            candle_core::DType::F32 => self.backward::<f32>((&x, &w, &g), bias, need),
            candle_core::DType::F64 => self.backward::<f64>((&x, &w, &g), bias, need),
            other => candle_core::bail!("cheb-conv: dtype {other:?} not supported"),
        }
    }
}

impl CustomOp2 for ChebOp {
    fn name(&self) -> &'static str {
        NAME
    }

    fn cpu_fwd(
        &self,
        xs: &CpuStorage,
        xl: &Layout,
        ws: &CpuStorage,
        wl: &Layout,
    ) -> candle_core::Result<(CpuStorage, Shape)> {
        self.fwd((xs, xl), (ws, wl), None)
    }

    fn bwd(
        &self,
        x: &Tensor,
        w: &Tensor,
        _y: &Tensor,
        grad: &Tensor,
    ) -> candle_core::Result<(Option<Tensor>, Option<Tensor>)> {
        let [dx, dw, _] = self.bwd_any(x, w, None, grad)?;
        Ok((dx, dw))
    }
}

impl CustomOp3 for ChebOp {
    fn name(&self) -> &'static str {
        "cheb-conv-bias"
    }

    fn cpu_fwd(
        &self,
        xs: &CpuStorage,
        xl: &Layout,
        ws: &CpuStorage,
        wl: &Layout,
        bs: &CpuStorage,
        bl: &Layout,
    ) -> candle_core::Result<(CpuStorage, Shape)> {
        self.fwd((xs, xl), (ws, wl), Some((bs, bl)))
    }

    fn bwd(
        &self,
        x: &Tensor,
        w: &Tensor,
        b: &Tensor,
        _y: &Tensor,
        grad: &Tensor,
    ) -> candle_core::Result<(Option<Tensor>, Option<Tensor>, Option<Tensor>)> {
        let b = b.contiguous()?;
        let [dx, dw, db] = self.bwd_any(x, w, Some(&b), grad)?;
        Ok((dx, dw, db))
    }
}
