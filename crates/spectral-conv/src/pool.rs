//! Pooling between mesh levels, all differentiable:
//! - [`MeanPool`]: coarse = P · fine, P (coarse × fine) with 1/|cluster| at the members.
//! - [`DePool`]: fine = D · coarse for whatever D (fine × coarse) it is given — the authors' Pᵀ
//!   (divide by cluster size) or a copy matrix.
//! - [`Sampling`]: CoMA down- or up-sampling matrices.
//! - [`MaxPool`]: per channel, the member of each cluster with the largest magnitude, sign kept
//!   (as the authors' max pooling), or ([`MaxMode::PlainMax`]) the largest value over overlapping
//!   neighbourhoods (graph max pooling, Shen et al. 2018); the gradient goes to the selected
//!   member only, summed where one member is selected several times.
//!
//! The first three are [`SparseOp`] products; `MaxPool` is a custom op that records the selected
//! members for its backward pass, with a candle-ops fallback for other devices.

use crate::buffers::MaxKernel;
use crate::custom_op::{self, SliceOp, cpu_slice};
use crate::error::{ConvError, Result};
use crate::kernel::{Csr, Real};
use crate::max_kernel::{MaxMode, max_pool, max_unpool};
use crate::spmm::{Backend, SparseOp, use_kernel};
use crate::workspace::Workspace;
use candle_core::{CpuStorage, CustomOp1, DType, Device, Layout, Shape, Tensor, WithDType};
use sparse_csr::CsrMatrix;
use std::sync::{Arc, Mutex};

macro_rules! sparse_layer {
    ($(#[$doc:meta])* $name:ident, $what:literal) => {
        $(#[$doc])*
        #[derive(Debug, Clone)]
        pub struct $name(SparseOp);

        impl $name {
            #[doc = concat!("Wraps the ", $what, " matrix for products on `device`.")]
            pub fn new(matrix: &CsrMatrix, device: &Device) -> Result<Self> {
                Ok(Self(SparseOp::new(matrix, device)?))
            }

            /// The same layer with another backend.
            pub fn with_backend(&self, backend: Backend) -> Self {
                Self(self.0.with_backend(backend))
            }

            /// The same layer keeping its kernels' scratch in `workspace` (see
            /// [`SparseOp::with_workspace`]).
            pub fn with_workspace(&self, workspace: Arc<Workspace>) -> Self {
                Self(self.0.with_workspace(workspace))
            }

            /// `[B, cols, C]` (or `[cols, C]`) → `[B, rows, C]` (or `[rows, C]`).
            pub fn forward(&self, x: &Tensor) -> Result<Tensor> {
                self.0.apply(x)
            }

            /// `[cols, B, C]` (or `[cols, C]`) → `[rows, B, C]` (or `[rows, C]`): the vertex-major
            /// layout (see [`SparseOp::apply_vertex_major`]).
            pub fn forward_vertex_major(&self, x: &Tensor) -> Result<Tensor> {
                self.0.apply_vertex_major(x)
            }

            /// The underlying sparse product.
            pub fn op(&self) -> &SparseOp {
                &self.0
            }
        }
    };
}

sparse_layer!(
    /// Mean pooling: coarse = P · fine, with P the coarse × fine pooling matrix.
    MeanPool,
    "pooling (coarse × fine)"
);
sparse_layer!(
    /// De-pooling: fine = D · coarse, with D the fine × coarse de-pooling matrix.
    DePool,
    "de-pooling (fine × coarse)"
);
sparse_layer!(
    /// CoMA sampling: y = M · x for a down- (coarse × fine) or up-sampling (fine × coarse) matrix.
    Sampling,
    "sampling"
);

/// Max pooling over the member lists given by a pooling matrix's rows (its sparsity pattern;
/// values are ignored; rows may overlap). An empty row yields 0.
///
/// [`MaxMode::SignedMax`] ([`MaxPool::new`]): the member of largest magnitude, sign
/// kept; ties go to the negative value, then the lowest vertex index. [`MaxMode::PlainMax`]
/// ([`MaxPool::with_mode`]; graph pooling): the largest value; ties go to the lowest vertex
/// index. On the fallback path, in signed-magnitude mode, an exact tie between equal values
/// may give the gradient to another of the tied members (the output is the same); in plain
/// mode it selects exactly as the kernel.
#[derive(Debug, Clone)]
pub struct MaxPool {
    /// The CPU kernel: the pattern, its transpose and the mode.
    kernel: MaxKernel,
    backend: Backend,
    device: Device,
    /// Fallback: the members of every cluster, padded to `width` (with the first member, or
    /// vertex 0 for an empty cluster), as one u32 index tensor `[rows · width]`.
    members: Tensor,
    width: usize,
    /// Fallback: `[1, rows, 1]` with 0 at empty clusters, if there are any.
    nonempty: Option<Tensor>,
}

impl MaxPool {
    /// Signed max-magnitude pooling over the rows of `pooling` (coarse × fine), for inputs on
    /// `device`.
    pub fn new(pooling: &CsrMatrix, device: &Device) -> Result<Self> {
        Self::with_mode(pooling, MaxMode::SignedMax, device)
    }

    /// Max pooling of the given mode over the rows of `pooling` (coarse × fine; for graph
    /// pooling its membership pattern), for inputs on `device`.
    pub fn with_mode(pooling: &CsrMatrix, mode: MaxMode, device: &Device) -> Result<Self> {
        let kernel = MaxKernel::from_matrix(pooling, mode)?;
        let pattern = kernel.pattern();
        let rows = pattern.rows();
        let width = (0..rows)
            .map(|r| pattern.columns(r).len())
            .max()
            .unwrap_or(0)
            .max(1);
        let mut members = Vec::with_capacity(rows * width);
        let mut nonempty = Vec::with_capacity(rows);
        for r in 0..rows {
            let cols = pattern.columns(r);
            let pad = cols.first().copied().unwrap_or(0);
            members.extend(
                cols.iter()
                    .copied()
                    .chain(std::iter::repeat(pad))
                    .take(width),
            );
            nonempty.push(if cols.is_empty() { 0.0 } else { 1.0 });
        }
        let members = Tensor::from_vec(members, rows * width, device)?;
        let nonempty = if nonempty.contains(&0.0) {
            Some(Tensor::from_vec(nonempty, (1, rows, 1), device)?)
        } else {
            None
        };
        Ok(Self {
            kernel,
            backend: Backend::Kernel,
            device: device.clone(),
            members,
            width,
            nonempty,
        })
    }

    /// What the layer selects.
    pub fn mode(&self) -> MaxMode {
        self.kernel.mode()
    }

    /// The CPU kernel, for caller-owned buffers.
    pub fn kernel(&self) -> &MaxKernel {
        &self.kernel
    }

    /// The same layer with another backend.
    pub fn with_backend(&self, backend: Backend) -> Self {
        Self {
            backend,
            ..self.clone()
        }
    }

    /// The clusters (the pooling matrix's pattern).
    pub(crate) fn pattern(&self) -> &Csr {
        self.kernel.pattern()
    }

    /// `[B, fine, C]` (or `[fine, C]`) → `[B, coarse, C]` (or `[coarse, C]`).
    pub fn forward(&self, x: &Tensor) -> Result<Tensor> {
        self.forward_with(x, self.backend)
    }

    /// As [`Self::forward`] with an explicit backend.
    pub fn forward_with(&self, x: &Tensor, backend: Backend) -> Result<Tensor> {
        const OP: &str = "MaxPool::forward";
        let (x3, squeeze) = match x.rank() {
            2 => (x.unsqueeze(0)?, true),
            3 => (x.clone(), false),
            _ => {
                return Err(ConvError::input(
                    OP,
                    format!(
                        "input of shape {:?}; expected [B, V, C] or [V, C]",
                        x.dims()
                    ),
                ));
            }
        };
        if x3.dim(1)? != self.pattern().cols() || !x.dtype().is_float() {
            return Err(ConvError::input(
                OP,
                format!(
                    "input {:?} of {:?}; expected {} vertices of a float dtype",
                    x.dims(),
                    x.dtype(),
                    self.pattern().cols()
                ),
            ));
        }
        if !x.device().same_device(&self.device) {
            return Err(ConvError::input(
                OP,
                "input and pooling on different devices",
            ));
        }
        let y = if use_kernel(backend, &x3) {
            x3.contiguous()?.apply_op1(MaxPoolOp {
                kernel: self.kernel.clone(),
                arg: Mutex::new(None),
            })?
        } else {
            self.fallback(&x3)?
        };
        Ok(if squeeze { y.squeeze(0)? } else { y })
    }

    /// `[fine, B, C]` (or `[fine, C]`) → `[coarse, B, C]` (or `[coarse, C]`): the vertex-major
    /// layout. Per vertex and per (batch, channel) entry, the same selection as [`Self::forward`].
    pub fn forward_vertex_major(&self, x: &Tensor) -> Result<Tensor> {
        const OP: &str = "MaxPool::forward_vertex_major";
        if !matches!(x.rank(), 2 | 3) || x.dim(0)? == 0 {
            return Err(ConvError::input(
                OP,
                format!(
                    "input of shape {:?}; expected [V, B, C] or [V, C]",
                    x.dims()
                ),
            ));
        }
        // One batch whose rows are whole vertices: the [B, V, C] op with B = 1, C = B·C.
        let v = x.dim(0)?;
        let y = self.forward_with(&x.reshape((1, v, x.elem_count() / v))?, self.backend)?;
        let mut dims = x.dims().to_vec();
        dims[0] = self.pattern().rows();
        Ok(y.reshape(dims)?)
    }

    /// candle ops only: gather the padded clusters `[B, P, width, C]`, take the arg-max (plain
    /// mode; candle's arg-max keeps the first of equal values, i.e. the lowest vertex) or the
    /// arg-max and the arg-min, keeping the one of larger magnitude (signed magnitude), and
    /// gather it (differentiable).
    fn fallback(&self, x: &Tensor) -> Result<Tensor> {
        let (batch, _, c) = x.dims3()?;
        let rows = self.pattern().rows();
        let grouped = x
            .index_select(&self.members, 1)?
            .reshape((batch, rows, self.width, c))?;
        let imax = grouped.argmax_keepdim(2)?;
        let pick = match self.mode() {
            MaxMode::PlainMax => imax,
            MaxMode::SignedMax => {
                let imin = grouped.argmin_keepdim(2)?;
                let (vmax, vmin) = (grouped.gather(&imax, 2)?, grouped.gather(&imin, 2)?);
                let take_min = vmin.abs()?.ge(&vmax.abs()?)?;
                take_min.where_cond(&imin, &imax)?
            }
        };
        let y = grouped.gather(&pick, 2)?.squeeze(2)?;
        Ok(match &self.nonempty {
            Some(mask) => y.broadcast_mul(&mask.to_dtype(x.dtype())?)?,
            None => y,
        })
    }
}

/// The custom op; keeps the selected members (`[B, P, C]` vertex indices) for `bwd`.
struct MaxPoolOp {
    kernel: MaxKernel,
    arg: Mutex<Option<Arc<Vec<u32>>>>,
}

impl MaxPoolOp {
    /// The pooled values and the selected members for input `x` of shape `dims`.
    fn select<T: Real>(
        &self,
        x: &[T],
        dims: &[usize],
    ) -> candle_core::Result<(Vec<T>, Vec<u32>, Shape)> {
        let &[batch, v, c] = dims else {
            candle_core::bail!("max-pool: expected a rank-3 input, got {dims:?}");
        };
        if v != self.kernel.pattern().cols() {
            candle_core::bail!(
                "max-pool: {v} vertices, the pooling has {}",
                self.kernel.pattern().cols()
            );
        }
        let n = batch * self.kernel.pattern().rows() * c;
        let (mut y, mut arg) = (vec![T::ZERO; n], vec![0u32; n]);
        max_pool(
            self.kernel.pattern(),
            x,
            &mut y,
            &mut arg,
            c,
            self.kernel.mode(),
        );
        Ok((
            y,
            arg,
            Shape::from((batch, self.kernel.pattern().rows(), c)),
        ))
    }

    fn unpool<T: Real + WithDType>(&self, x: &Tensor, g: &Tensor) -> candle_core::Result<Tensor> {
        let (batch, v, c) = x.dims3()?;
        let arg = match self.arg.lock().ok().and_then(|a| a.clone()) {
            Some(arg) => arg,
            None => {
                // Not recorded (should not happen): select again from x.
                let (store, layout) = x.storage_and_layout();
                let xs = cpu_slice::<T>(Self::NAME, &store, layout)?;
                Arc::new(self.select(xs, layout.dims())?.1)
            }
        };
        let (store, layout) = g.storage_and_layout();
        let gs = cpu_slice::<T>(Self::NAME, &store, layout)?;
        if gs.len() != arg.len() {
            candle_core::bail!("max-pool: gradient of shape {:?}", layout.dims());
        }
        let mut dx = vec![T::ZERO; batch * v * c];
        max_unpool(self.kernel.pattern_t(), &arg, gs, &mut dx, c);
        Tensor::from_vec(dx, (batch, v, c), x.device())
    }
}

impl SliceOp for MaxPoolOp {
    const NAME: &'static str = "max-pool";

    fn run<T: Real>(&self, x: &[T], dims: &[usize]) -> candle_core::Result<(Vec<T>, Shape)> {
        let (y, arg, shape) = self.select(x, dims)?;
        if let Ok(mut saved) = self.arg.lock() {
            *saved = Some(Arc::new(arg));
        }
        Ok((y, shape))
    }
}

impl CustomOp1 for MaxPoolOp {
    fn name(&self) -> &'static str {
        Self::NAME
    }

    fn cpu_fwd(&self, s: &CpuStorage, l: &Layout) -> candle_core::Result<(CpuStorage, Shape)> {
        custom_op::cpu_fwd(self, s, l)
    }

    fn bwd(&self, x: &Tensor, _y: &Tensor, grad: &Tensor) -> candle_core::Result<Option<Tensor>> {
        let g = grad.contiguous()?;
        let x = x.contiguous()?;
        Ok(Some(match x.dtype() {
            DType::F32 => self.unpool::<f32>(&x, &g)?,
            DType::F64 => self.unpool::<f64>(&x, &g)?,
            other => candle_core::bail!("max-pool: dtype {other:?} not supported"),
        }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_util::*;
    use candle_core::Var;

    /// 10 fine vertices in 4 clusters of sizes 3, 2, 4, 1; P has 1/|C| at the members.
    fn pooling() -> CsrMatrix {
        let clusters: [&[u32]; 4] = [&[0, 4, 7], &[1, 2], &[3, 5, 6, 9], &[8]];
        let mut t = Vec::new();
        for (c, members) in clusters.iter().enumerate() {
            for &m in *members {
                t.push((c as u32, m, 1.0 / members.len() as f64));
            }
        }
        CsrMatrix::from_triplets(4, 10, &t).unwrap()
    }

    #[test]
    fn mean_pool_de_pool_and_sampling_apply_their_matrices_with_gradients() {
        let p = pooling();
        let x = Var::from_tensor(&tensor(random_vec(2 * 10 * 3, 70), &[2, 10, 3])).unwrap();
        let coarse = Var::from_tensor(&tensor(random_vec(2 * 4 * 3, 71), &[2, 4, 3])).unwrap();
        let pool = MeanPool::new(&p, &Device::Cpu).unwrap();
        let depool = DePool::new(&p.transpose(), &Device::Cpu).unwrap();
        let up = Sampling::new(&random_matrix(10, 4, 0.4, 72), &Device::Cpu).unwrap();
        let pooled = to_vec(&pool.forward(x.as_tensor()).unwrap());
        let xv = to_vec(&x);
        // Cluster 2 = {3, 5, 6, 9}, batch 1, channel 1.
        let want = [3, 5, 6, 9]
            .iter()
            .map(|&m| xv[(10 + m) * 3 + 1])
            .sum::<f64>()
            / 4.0;
        assert!((pooled[(4 + 2) * 3 + 1] - want).abs() < 1e-15);
        for backend in [Backend::Kernel, Backend::Fallback] {
            let pool = pool.with_backend(backend);
            let (depool, up) = (depool.with_backend(backend), up.with_backend(backend));
            let loss = || {
                let y = pool
                    .forward(x.as_tensor())
                    .map_err(candle_core::Error::wrap)?;
                weighted_sum(&y.sqr()?, 73)
            };
            assert!(grad_check(&[&x], loss) < 1e-7, "{backend:?} mean pool");
            for layer in [&depool.0, &up.0] {
                let loss = || {
                    let y = layer
                        .apply(coarse.as_tensor())
                        .map_err(candle_core::Error::wrap)?;
                    weighted_sum(&y.sqr()?, 74)
                };
                assert!(
                    grad_check(&[&coarse], loss) < 1e-7,
                    "{backend:?} de-pool/sampling"
                );
            }
        }
    }

    #[test]
    fn max_pool_selects_signed_max_magnitude_and_routes_the_gradient() {
        let mut p = pooling();
        // Add an empty cluster: 5 coarse vertices, the last one without members.
        let mut t: Vec<(u32, u32, f64)> = Vec::new();
        for r in 0..p.rows() {
            let (cols, vals) = p.row(r);
            t.extend(cols.iter().zip(vals).map(|(&c, &v)| (r as u32, c, v)));
        }
        p = CsrMatrix::from_triplets(5, 10, &t).unwrap();
        let pool = MaxPool::new(&p, &Device::Cpu).unwrap();
        let x = Var::from_tensor(&tensor(random_vec(2 * 10 * 3, 80), &[2, 10, 3])).unwrap();
        let xv = to_vec(&x);
        let kernel = pool.forward(x.as_tensor()).unwrap();
        let fallback = pool.forward_with(x.as_tensor(), Backend::Fallback).unwrap();
        assert_eq!(kernel.dims(), &[2, 5, 3]);
        assert_eq!(to_vec(&kernel), to_vec(&fallback));
        let y = to_vec(&kernel);
        for b in 0..2 {
            for r in 0..5 {
                for ch in 0..3 {
                    let want = p
                        .row(r)
                        .0
                        .iter()
                        .map(|&m| xv[(b * 10 + m as usize) * 3 + ch])
                        .fold(
                            0.0f64,
                            |best, v| if v.abs() > best.abs() { v } else { best },
                        );
                    assert_eq!(y[(b * 5 + r) * 3 + ch], want);
                }
            }
        }
        for backend in [Backend::Kernel, Backend::Fallback] {
            let pool = pool.with_backend(backend);
            let loss = || {
                let y = pool
                    .forward(x.as_tensor())
                    .map_err(candle_core::Error::wrap)?;
                weighted_sum(&y, 81)
            };
            assert!(grad_check(&[&x], loss) < 1e-7, "{backend:?}");
        }
        // f32 and rank 2 work too, and agree with the fallback.
        let x32 = x.as_tensor().get(0).unwrap().to_dtype(DType::F32).unwrap();
        let k32 = pool.forward(&x32).unwrap();
        assert_eq!(k32.dims(), &[5, 3]);
        assert_eq!(
            to_vec(&k32),
            to_vec(&pool.forward_with(&x32, Backend::Fallback).unwrap())
        );
        let wrong = tensor(vec![0.0; 9 * 3], &[9, 3]);
        assert!(matches!(pool.forward(&wrong), Err(ConvError::Input { .. })));
    }

    /// Graph pooling's membership on a 6×6 grid: clusters are 2×2 blocks, each with its
    /// top-left vertex as survivor, so neighbourhoods (one-ring ∪ block) overlap.
    fn grid_membership() -> CsrMatrix {
        let faces = grid_faces(6, 6);
        let cluster_of: Vec<u32> = (0..36u32).map(|v| (v / 6 / 2) * 3 + (v % 6) / 2).collect();
        let survivors: Vec<u32> = (0..9u32).map(|c| (c / 3) * 12 + (c % 3) * 2).collect();
        neighbourhoods(&faces, &survivors, &cluster_of)
    }

    #[test]
    fn graph_max_pool_takes_the_plain_max_over_overlapping_rows_with_gradients() {
        let members = grid_membership();
        assert!(members.nnz() > 36, "the neighbourhoods overlap");
        let pool = MaxPool::with_mode(&members, MaxMode::PlainMax, &Device::Cpu).unwrap();
        assert_eq!(pool.mode(), MaxMode::PlainMax);
        let x = Var::from_tensor(&tensor(random_vec(2 * 36 * 3, 90), &[2, 36, 3])).unwrap();
        let xv = to_vec(&x);
        let kernel = pool.forward(x.as_tensor()).unwrap();
        let fallback = pool.forward_with(x.as_tensor(), Backend::Fallback).unwrap();
        assert_eq!(kernel.dims(), &[2, 9, 3]);
        assert_eq!(to_vec(&kernel), to_vec(&fallback));
        let y = to_vec(&kernel);
        for b in 0..2 {
            for r in 0..9 {
                for ch in 0..3 {
                    let want = members
                        .row(r)
                        .0
                        .iter()
                        .map(|&m| xv[(b * 36 + m as usize) * 3 + ch])
                        .fold(f64::NEG_INFINITY, f64::max);
                    assert_eq!(y[(b * 9 + r) * 3 + ch], want);
                }
            }
        }
        for backend in [Backend::Kernel, Backend::Fallback] {
            let pool = pool.with_backend(backend);
            let loss = || {
                let y = pool
                    .forward(x.as_tensor())
                    .map_err(candle_core::Error::wrap)?;
                weighted_sum(&y, 91)
            };
            assert!(grad_check(&[&x], loss) < 1e-7, "{backend:?}");
        }
        // A vertex that is the max of several neighbourhoods gets the sum of their gradients
        // (on both paths); a tie goes to the lowest vertex, also on the fallback.
        let mut big = vec![0.0; 36];
        // Vertex 13 is in the neighbourhoods of survivors 12 and 14 (coarse 3 and 4); 27 and
        // 32 tie in coarse 7's, and 27 is also the max of coarse 8's.
        big[13] = 5.0;
        big[27] = 2.0;
        big[32] = 2.0;
        let with_13 = (0..9).filter(|&r| members.row(r).0.contains(&13)).count();
        assert_eq!(with_13, 2);
        let xb = Var::from_tensor(&tensor(big, &[36, 1])).unwrap();
        for backend in [Backend::Kernel, Backend::Fallback] {
            let y = pool.forward_with(xb.as_tensor(), backend).unwrap();
            let g = y.sum_all().unwrap().backward().unwrap();
            let dx = to_vec(g.get(xb.as_tensor()).unwrap());
            assert_eq!(dx[13], 2.0, "{backend:?}");
            assert_eq!(dx[27], 2.0, "{backend:?}");
            assert_eq!(dx[32], 0.0, "{backend:?}: the tie goes to vertex 27");
            assert_eq!(dx.iter().sum::<f64>(), 9.0, "{backend:?}");
        }
        // The signed-magnitude layer on the same rows differs (all-negative inputs).
        let neg = tensor(
            random_vec(36, 92).iter().map(|v| -v.abs()).collect(),
            &[36, 1],
        );
        let signed = MaxPool::new(&members, &Device::Cpu).unwrap();
        let (a, b) = (
            to_vec(&pool.forward(&neg).unwrap()),
            to_vec(&signed.forward(&neg).unwrap()),
        );
        assert!(a.iter().zip(&b).all(|(p, q)| p > q));
    }
}
