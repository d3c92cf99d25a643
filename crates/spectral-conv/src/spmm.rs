//! [`SparseOp`]: y = A x for a fixed sparse matrix A and a batch of per-vertex features x
//! `[B, V, C]` (or `[V, C]`), with gradients flowing to x.
//!
//! Two implementations, chosen by [`Backend`]:
//! - [`Backend::Kernel`]: a candle `CustomOp1` with a hand-written CPU kernel (rayon over output
//!   rows, see `kernel.rs`) whose backward applies the pre-computed Aᵀ with the same kernel.
//!   On a non-CPU device, or for a dtype other than f32/f64, it falls back automatically.
//! - [`Backend::Fallback`]: candle's own ops only (`index_select`, a broadcast multiply,
//!   `index_add`), so it runs on any device; candle's autodiff differentiates it. It is also the
//!   reference the kernel is tested against.

use crate::custom_op::{self, SliceOp};
use crate::error::{ConvError, Result};
use crate::kernel::{Csr, Real, spmm_batch_major};
use crate::workspace::Workspace;
use candle_core::{CpuStorage, CustomOp1, DType, Device, Layout, Shape, Tensor};
use sparse_csr::CsrMatrix;
use std::sync::Arc;

/// Which implementation a sparse product (and the layers built on it) uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Backend {
    /// The hand-written CPU kernels (custom ops); candle ops wherever they cannot run.
    #[default]
    Kernel,
    /// candle's own ops only: any device, any float dtype, several times slower on the CPU.
    Fallback,
}

/// A fixed sparse operator A (`rows × cols`), applied to `[B, cols, C]` features.
///
/// Cheap to clone (the matrices and the [`Workspace`] are shared), so one Laplacian can serve
/// several layers.
#[derive(Debug, Clone)]
pub struct SparseOp {
    inner: Arc<Inner>,
    backend: Backend,
    workspace: Arc<Workspace>,
}

#[derive(Debug)]
struct Inner {
    a: Arc<Csr>,
    at: Arc<Csr>,
    device: Device,
    /// The fallback's tensors on `device`: row and column of every non-zero (u32), and the values
    /// as `[1, nnz, 1]` in f32 and f64.
    rows_idx: Tensor,
    cols_idx: Tensor,
    values_f32: Tensor,
    values_f64: Tensor,
}

impl Inner {
    fn build(a: Arc<Csr>, at: Arc<Csr>, device: &Device) -> Result<Self> {
        let nnz = a.nnz();
        let row_of: Vec<u32> = (0..a.rows())
            .flat_map(|r| std::iter::repeat_n(r as u32, a.columns(r).len()))
            .collect();
        Ok(Self {
            rows_idx: Tensor::from_vec(row_of, nnz, device)?,
            cols_idx: Tensor::from_slice(a.indices(), nnz, device)?,
            values_f32: Tensor::from_slice(a.values_f32(), (1, nnz, 1), device)?,
            values_f64: Tensor::from_slice(a.values_f64(), (1, nnz, 1), device)?,
            a,
            at,
            device: device.clone(),
        })
    }
}

impl SparseOp {
    /// Prepares A for products on `device` (A, Aᵀ in both precisions, and the fallback's index
    /// tensors). The backend defaults to [`Backend::Kernel`]; the kernels' scratch goes to a
    /// new [`Workspace`] of its own ([`Self::with_workspace`] shares one).
    pub fn new(matrix: &CsrMatrix, device: &Device) -> Result<Self> {
        if matrix.rows() > u32::MAX as usize || matrix.cols() > u32::MAX as usize {
            return Err(ConvError::argument(
                "SparseOp::new",
                "matrix",
                format!(
                    "{}x{} is too large for u32 indices",
                    matrix.rows(),
                    matrix.cols()
                ),
            ));
        }
        let a = Arc::new(Csr::from_matrix(matrix));
        let at = Arc::new(Csr::from_matrix(&matrix.transpose()));
        Ok(Self {
            inner: Arc::new(Inner::build(a, at, device)?),
            backend: Backend::Kernel,
            workspace: Arc::default(),
        })
    }

    /// The same operator with another backend (the matrices stay shared).
    pub fn with_backend(&self, backend: Backend) -> Self {
        Self {
            backend,
            ..self.clone()
        }
    }

    /// The same operator keeping its kernels' scratch in `workspace` (one per network keeps
    /// the memory of all its layers in one place; see [`Workspace`]).
    pub fn with_workspace(&self, workspace: Arc<Workspace>) -> Self {
        Self {
            workspace,
            ..self.clone()
        }
    }

    /// Where the kernels of this operator, and of the layers built on it, keep their scratch.
    pub fn workspace(&self) -> &Arc<Workspace> {
        &self.workspace
    }

    pub fn backend(&self) -> Backend {
        self.backend
    }

    /// Rows of A: the vertex count of the output.
    pub fn rows(&self) -> usize {
        self.inner.a.rows()
    }

    /// Columns of A: the vertex count the input must have.
    pub fn cols(&self) -> usize {
        self.inner.a.cols()
    }

    pub fn nnz(&self) -> usize {
        self.inner.a.nnz()
    }

    pub fn device(&self) -> &Device {
        &self.inner.device
    }

    pub(crate) fn csr(&self) -> &Arc<Csr> {
        &self.inner.a
    }

    pub(crate) fn csr_t(&self) -> &Arc<Csr> {
        &self.inner.at
    }

    /// Aᵀ as an operator of its own (the CSR arrays are shared, not rebuilt).
    pub fn transpose(&self) -> Result<Self> {
        let inner = Inner::build(
            self.inner.at.clone(),
            self.inner.a.clone(),
            &self.inner.device,
        )?;
        Ok(Self {
            inner: Arc::new(inner),
            ..self.clone()
        })
    }

    /// y = A x for x `[B, cols, C]` (→ `[B, rows, C]`) or `[cols, C]` (→ `[rows, C]`), with the
    /// operator's backend.
    pub fn apply(&self, x: &Tensor) -> Result<Tensor> {
        self.apply_with(x, self.backend)
    }

    /// y = A x with an explicit backend (e.g. the fallback as a reference).
    pub fn apply_with(&self, x: &Tensor, backend: Backend) -> Result<Tensor> {
        let (x3, squeeze) = self.check_input("SparseOp::apply", x)?;
        let y = if use_kernel(backend, &x3) {
            x3.contiguous()?.apply_op1(SpmmOp {
                a: self.inner.a.clone(),
                at: self.inner.at.clone(),
                ws: self.workspace.clone(),
            })?
        } else {
            self.fallback(&x3)?
        };
        Ok(if squeeze { y.squeeze(0)? } else { y })
    }

    /// y = A x in the vertex-major layout: x `[cols, B, C]` (or `[cols, C]`) → `[rows, B, C]`
    /// (or `[rows, C]`). Each vertex's B·C values are one contiguous row, so the kernel gathers
    /// whole rows without any transpose.
    pub fn apply_vertex_major(&self, x: &Tensor) -> Result<Tensor> {
        self.apply_vertex_major_with(x, self.backend)
    }

    /// [`Self::apply_vertex_major`] with an explicit backend.
    pub fn apply_vertex_major_with(&self, x: &Tensor, backend: Backend) -> Result<Tensor> {
        let (rows, flat) = self.vertex_major_rows("SparseOp::apply_vertex_major", x)?;
        let y = self.apply_with(&flat, backend)?;
        let mut dims = x.dims().to_vec();
        dims[0] = rows;
        Ok(y.reshape(dims)?)
    }

    /// Checks a vertex-major x (`[cols, B, C]` or `[cols, C]`) and returns it as one batch of
    /// rows `[1, cols, B·C]`, with the output's vertex count.
    pub(crate) fn vertex_major_rows(
        &self,
        op: &'static str,
        x: &Tensor,
    ) -> Result<(usize, Tensor)> {
        if !matches!(x.rank(), 2 | 3) {
            return Err(ConvError::input(
                op,
                format!(
                    "input of shape {:?}; expected [V, B, C] or [V, C]",
                    x.dims()
                ),
            ));
        }
        let v = x.dim(0)?;
        let row = x.elem_count() / v.max(1);
        let (flat, _) = self.check_input(op, &x.reshape((1, v, row))?)?;
        Ok((self.rows(), flat))
    }

    /// Checks x against A and returns it as rank 3 (and whether a batch axis was added).
    pub(crate) fn check_input(&self, op: &'static str, x: &Tensor) -> Result<(Tensor, bool)> {
        let (x3, squeeze) = match x.rank() {
            2 => (x.unsqueeze(0)?, true),
            3 => (x.clone(), false),
            _ => {
                return Err(ConvError::input(
                    op,
                    format!(
                        "input of shape {:?}; expected [B, V, C] or [V, C]",
                        x.dims()
                    ),
                ));
            }
        };
        if x3.dim(1)? != self.cols() {
            return Err(ConvError::input(
                op,
                format!(
                    "input of shape {:?} has {} vertices; the operator expects {}",
                    x.dims(),
                    x3.dim(1)?,
                    self.cols()
                ),
            ));
        }
        if !x.dtype().is_float() {
            return Err(ConvError::input(
                op,
                format!("input dtype {:?}; expected a float dtype", x.dtype()),
            ));
        }
        if !x.device().same_device(&self.inner.device) {
            return Err(ConvError::input(
                op,
                format!(
                    "input on {:?} but the operator lives on {:?}",
                    x.device().location(),
                    self.inner.device.location()
                ),
            ));
        }
        Ok((x3, squeeze))
    }

    /// candle ops only: gather the columns of every non-zero, scale, scatter-add into rows.
    fn fallback(&self, x: &Tensor) -> Result<Tensor> {
        let (batch, _, c) = x.dims3()?;
        let inner = &self.inner;
        let zeros = Tensor::zeros((batch, self.rows(), c), x.dtype(), x.device())?;
        if inner.a.nnz() == 0 {
            return Ok(zeros);
        }
        let values = match x.dtype() {
            DType::F64 => inner.values_f64.clone(),
            DType::F32 => inner.values_f32.clone(),
            other => inner.values_f64.to_dtype(other)?,
        };
        let gathered = x.index_select(&inner.cols_idx, 1)?.broadcast_mul(&values)?;
        Ok(zeros.index_add(&inner.rows_idx, &gathered, 1)?)
    }
}

/// Whether the CPU kernel can run: asked for, on the CPU, in f32 or f64.
pub(crate) fn use_kernel(backend: Backend, x: &Tensor) -> bool {
    backend == Backend::Kernel
        && x.device().is_cpu()
        && matches!(x.dtype(), DType::F32 | DType::F64)
}

/// The custom op: y = A x on `[B, cols, C]`; backward applies Aᵀ.
struct SpmmOp {
    a: Arc<Csr>,
    at: Arc<Csr>,
    ws: Arc<Workspace>,
}

impl SliceOp for SpmmOp {
    const NAME: &'static str = "csr-spmm";

    fn run<T: Real>(&self, x: &[T], dims: &[usize]) -> candle_core::Result<(Vec<T>, Shape)> {
        let &[batch, v, c] = dims else {
            candle_core::bail!("csr-spmm: expected a rank-3 input, got {dims:?}");
        };
        if v != self.a.cols() {
            candle_core::bail!(
                "csr-spmm: {v} vertices, the matrix has {} columns",
                self.a.cols()
            );
        }
        let y = spmm_batch_major(&self.a, x, (batch, c), &self.ws);
        Ok((y, Shape::from((batch, self.a.rows(), c))))
    }
}

impl CustomOp1 for SpmmOp {
    fn name(&self) -> &'static str {
        Self::NAME
    }

    fn cpu_fwd(&self, s: &CpuStorage, l: &Layout) -> candle_core::Result<(CpuStorage, Shape)> {
        custom_op::cpu_fwd(self, s, l)
    }

    fn bwd(&self, _x: &Tensor, _y: &Tensor, grad: &Tensor) -> candle_core::Result<Option<Tensor>> {
        // Gradients can arrive strided (even with zero strides from a broadcast): make them dense.
        let transposed = SpmmOp {
            a: self.at.clone(),
            at: self.a.clone(),
            ws: self.ws.clone(),
        };
        Ok(Some(grad.contiguous()?.apply_op1(transposed)?))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_util::*;
    use candle_core::Var;

    #[test]
    fn both_backends_match_dense_in_f32_and_f64_and_rank_2() {
        let m = random_matrix(9, 14, 0.3, 3);
        let op = SparseOp::new(&m, &Device::Cpu).unwrap();
        let data = random_vec(2 * 14 * 4, 4);
        let want = dense_apply(&m, &data, 2, 4);
        let x = tensor(data.clone(), &[2, 14, 4]);
        for backend in [Backend::Kernel, Backend::Fallback] {
            let y = op.apply_with(&x, backend).unwrap();
            assert_eq!(y.dims(), &[2, 9, 4]);
            let err = to_vec(&y)
                .iter()
                .zip(&want)
                .map(|(p, q)| (p - q).abs())
                .fold(0.0, f64::max);
            assert!(err < 1e-12, "{backend:?}: {err}");
            let y32 = op
                .apply_with(&x.to_dtype(DType::F32).unwrap(), backend)
                .unwrap();
            assert_eq!(y32.dtype(), DType::F32);
            assert!(max_abs_diff(&y32, &y) < 1e-5);
        }
        let x2 = tensor(data[..14 * 4].to_vec(), &[14, 4]);
        let y2 = op.apply(&x2).unwrap();
        assert_eq!(y2.dims(), &[9, 4]);
        assert!(
            to_vec(&y2)
                .iter()
                .zip(&want)
                .all(|(p, q)| (p - q).abs() < 1e-12)
        );
        // A strided (transposed) input gives the same result as its contiguous copy.
        let xt = tensor(data, &[2, 4, 14]).transpose(1, 2).unwrap();
        let yt = op.apply(&xt).unwrap();
        let yc = op.apply(&xt.contiguous().unwrap()).unwrap();
        assert_eq!(to_vec(&yt), to_vec(&yc));
    }

    #[test]
    fn bad_inputs_are_typed_errors() {
        let op = SparseOp::new(&random_matrix(4, 5, 0.5, 1), &Device::Cpu).unwrap();
        let wrong_v = tensor(vec![0.0; 2 * 4 * 3], &[2, 4, 3]);
        assert!(matches!(op.apply(&wrong_v), Err(ConvError::Input { .. })));
        let rank1 = tensor(vec![0.0; 5], &[5]);
        assert!(matches!(op.apply(&rank1), Err(ConvError::Input { .. })));
        let ints = Tensor::zeros((5, 2), DType::U32, &Device::Cpu).unwrap();
        assert!(matches!(op.apply(&ints), Err(ConvError::Input { .. })));
        let msg = op.apply(&wrong_v).unwrap_err().to_string();
        assert!(
            msg.contains("SparseOp::apply") && msg.contains("expects 5"),
            "{msg}"
        );
    }

    #[test]
    fn kernel_gradients_match_finite_differences_and_the_fallback() {
        let m = random_matrix(7, 10, 0.35, 5);
        let op = SparseOp::new(&m, &Device::Cpu).unwrap();
        let x = Var::from_tensor(&tensor(random_vec(2 * 10 * 3, 6), &[2, 10, 3])).unwrap();
        for backend in [Backend::Kernel, Backend::Fallback] {
            let op = op.with_backend(backend);
            let loss = || {
                weighted_sum(
                    &op.apply(x.as_tensor()).map_err(candle_core::Error::wrap)?,
                    9,
                )
            };
            let err = grad_check(&[&x], loss);
            assert!(err < 1e-7, "{backend:?}: relative error {err}");
        }
        // Kernel vs fallback gradients through a nonlinear loss (a strided gradient arrives).
        let grad = |backend| {
            let y = op.apply_with(x.as_tensor(), backend).unwrap();
            let loss = y
                .sqr()
                .unwrap()
                .broadcast_mul(&Tensor::new(0.5f64, &Device::Cpu).unwrap());
            let grads = loss.unwrap().sum_all().unwrap().backward().unwrap();
            grads.get(&x).unwrap().clone()
        };
        assert!(max_abs_diff(&grad(Backend::Kernel), &grad(Backend::Fallback)) < 1e-12);
        // Aᵀ as an operator equals the transposed matrix.
        let xt = tensor(random_vec(7 * 2, 8), &[7, 2]);
        let yt = op.transpose().unwrap().apply(&xt).unwrap();
        let want = dense_apply(&m.transpose(), &to_vec(&xt), 1, 2);
        assert!(
            to_vec(&yt)
                .iter()
                .zip(&want)
                .all(|(p, q)| (p - q).abs() < 1e-12)
        );
    }
}
