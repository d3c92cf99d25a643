//! Buffer-level entry points: the same kernels as the candle ops, on caller-owned slices.
//!
//! Why: a training step built from candle ops allocates every activation and gradient afresh
//! (fresh pages, zeroed by the kernel on first touch) and keeps the graph alive; a hand-written
//! network (meshvae's training engine) instead owns its buffers and calls these.
//!
//! Layout: every array is vertex-major and channel-major, `[V, C, B]` (the kernels' internal
//! form): vertex i's block is C rows of B values. Pooling products treat a vertex's block as
//! n = C·B opaque values, so they work for any per-vertex layout.

use crate::cheb_kernel::{self, Bufs, ChebShape, MAX_K, Need};
use crate::error::{ConvError, Result};
use crate::kernel::{Csr, Real, spmm_axpby};
use crate::layout::{Blocks, Io};
use crate::max_kernel::{MaxMode, max_pool, max_unpool};
use crate::spmm::SparseOp;
use crate::workspace::Workspace;
use sparse_csr::CsrMatrix;
use std::sync::Arc;

/// The float types of the buffer-level kernels: f32 and f64 (sealed: the kernels' own trait).
pub trait Float: Real {}

impl Float for f32 {}
impl Float for f64 {}

/// Sizes of one convolution call: batch B, input and output channels.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ConvDims {
    pub batch: usize,
    pub c_in: usize,
    pub c_out: usize,
}

fn check_len(op: &'static str, what: &str, got: usize, want: usize) -> Result<()> {
    if got == want {
        return Ok(());
    }
    Err(ConvError::input(
        op,
        format!("{what} has {got} values; expected {want}"),
    ))
}

/// The kernels index vertices with u32.
fn check_u32(op: &'static str, matrix: &CsrMatrix) -> Result<()> {
    if matrix.rows() > u32::MAX as usize || matrix.cols() > u32::MAX as usize {
        return Err(ConvError::argument(
            op,
            "matrix",
            format!(
                "{}x{} is too large for u32 indices",
                matrix.rows(),
                matrix.cols()
            ),
        ));
    }
    Ok(())
}

/// A sparse operator A (and its stored Aᵀ) applied to caller-owned `[V, n]` slices.
#[derive(Debug, Clone)]
pub struct SparseKernel {
    a: Arc<Csr>,
    at: Arc<Csr>,
}

impl SparseKernel {
    /// The kernel of `op` (its matrices are shared, not copied).
    pub fn new(op: &SparseOp) -> Self {
        Self {
            a: op.csr().clone(),
            at: op.csr_t().clone(),
        }
    }

    /// The kernel of `matrix`, without a candle operator or device (the same A and Aᵀ as
    /// [`SparseOp::new`] prepares).
    pub fn from_matrix(matrix: &CsrMatrix) -> Result<Self> {
        check_u32("SparseKernel::from_matrix", matrix)?;
        Ok(Self {
            a: Arc::new(Csr::from_matrix(matrix)),
            at: Arc::new(Csr::from_matrix(&matrix.transpose())),
        })
    }

    /// The same operator on renumbered vertices: output row p is row `rows[p]` of A, and input
    /// vertex `cols[q]` moves to position q (`None`: numbering kept). Each order must be a
    /// permutation of its side's vertices.
    pub fn permuted(&self, rows: Option<&[u32]>, cols: Option<&[u32]>) -> Result<Self> {
        if rows.is_none() && cols.is_none() {
            // Shared, not copied: the same entries in the same order.
            return Ok(self.clone());
        }
        const OP: &str = "SparseKernel::permuted";
        let row_pos = rows
            .map(|o| crate::order::positions(o, self.a.rows(), (OP, "rows")))
            .transpose()?;
        let col_pos = cols
            .map(|o| crate::order::positions(o, self.a.cols(), (OP, "cols")))
            .transpose()?;
        Ok(Self {
            a: Arc::new(self.a.permuted(rows, col_pos.as_deref(), (OP, "rows"))?),
            at: Arc::new(self.at.permuted(cols, row_pos.as_deref(), (OP, "cols"))?),
        })
    }

    /// Rows of A (output vertices).
    pub fn rows(&self) -> usize {
        self.a.rows()
    }

    /// Columns of A (input vertices).
    pub fn cols(&self) -> usize {
        self.a.cols()
    }

    /// y = A x with `n` values per vertex: x `[cols, n]`, y `[rows, n]` (overwritten).
    pub fn apply<T: Float>(&self, x: &[T], y: &mut [T], n: usize) -> Result<()> {
        Self::product(&self.a, x, y, n, "SparseKernel::apply")
    }

    /// y = Aᵀ x with `n` values per vertex: x `[rows, n]`, y `[cols, n]` (overwritten).
    pub fn apply_t<T: Float>(&self, x: &[T], y: &mut [T], n: usize) -> Result<()> {
        Self::product(&self.at, x, y, n, "SparseKernel::apply_t")
    }

    fn product<T: Float>(a: &Csr, x: &[T], y: &mut [T], n: usize, op: &'static str) -> Result<()> {
        check_len(op, "x", x.len(), a.cols() * n)?;
        check_len(op, "y", y.len(), a.rows() * n)?;
        spmm_axpby(a, T::from_f64(1.0), x, T::ZERO, None, y, n);
        Ok(())
    }
}

/// The fused Chebyshev convolution y = Σ_{k<K} T_k(L̃) x W_k (no bias) on `[V, C, B]` slices,
/// W `[C_in·K, C_out]` as [`crate::ChebConv`]'s.
#[derive(Debug, Clone)]
pub struct ChebKernel {
    a: Arc<Csr>,
    at: Arc<Csr>,
    k: usize,
}

impl ChebKernel {
    /// The convolution of order `k` (1 ..= 8) on `laplacian` (its matrices are shared, not
    /// copied).
    pub fn new(laplacian: &SparseOp, k: usize) -> Result<Self> {
        Self::checked(
            laplacian.csr().clone(),
            laplacian.csr_t().clone(),
            k,
            "ChebKernel::new",
        )
    }

    /// The convolution of order `k` (1 ..= 8) on the rescaled Laplacian `laplacian`, without a
    /// candle operator or device (the same matrices as `ChebKernel::new(&SparseOp::new(..))`).
    pub fn from_matrix(laplacian: &CsrMatrix, k: usize) -> Result<Self> {
        const OP: &str = "ChebKernel::from_matrix";
        check_u32(OP, laplacian)?;
        let a = Arc::new(Csr::from_matrix(laplacian));
        let at = Arc::new(Csr::from_matrix(&laplacian.transpose()));
        Self::checked(a, at, k, OP)
    }

    fn checked(a: Arc<Csr>, at: Arc<Csr>, k: usize, op: &'static str) -> Result<Self> {
        if k == 0 || k > MAX_K {
            return Err(ConvError::argument(
                op,
                "k",
                format!("{k}; the fused kernels take 1 ..= {MAX_K}"),
            ));
        }
        if a.rows() != a.cols() {
            return Err(ConvError::argument(
                op,
                "laplacian",
                format!("{}x{} is not square", a.rows(), a.cols()),
            ));
        }
        Ok(Self { a, at, k })
    }

    pub fn k(&self) -> usize {
        self.k
    }

    /// The share of the operator's off-diagonal entries that join vertices more than `window`
    /// positions apart: how far its gathers jump in the current numbering.
    pub fn far_share(&self, window: usize) -> f64 {
        let a = &self.a;
        let (mut far, mut all) = (0usize, 0usize);
        for r in 0..a.rows() {
            for &c in a.columns(r) {
                if c as usize != r {
                    all += 1;
                    far += usize::from((c as usize).abs_diff(r) > window);
                }
            }
        }
        if all == 0 {
            0.0
        } else {
            far as f64 / all as f64
        }
    }

    /// A cache-friendly renumbering of the operator's vertices ([`crate::locality_order`] of
    /// its pattern): `order[p]` is the vertex placed at position p.
    pub fn locality_order(&self) -> Vec<u32> {
        let a = &self.a;
        crate::order::rcm(a.rows(), |r| a.columns(r))
    }

    /// The same convolution on renumbered vertices (P L̃ Pᵀ, with `order[p]` the vertex at
    /// position p): on data renumbered the same way it gives the renumbered output.
    pub fn permuted(&self, order: &[u32]) -> Result<Self> {
        let arg = ("ChebKernel::permuted", "order");
        let pos = crate::order::positions(order, self.a.rows(), arg)?;
        Ok(Self {
            a: Arc::new(self.a.permuted(Some(order), Some(&pos), arg)?),
            at: Arc::new(self.at.permuted(Some(order), Some(&pos), arg)?),
            k: self.k,
        })
    }

    pub fn vertices(&self) -> usize {
        self.a.rows()
    }

    /// Values of the stored terms T_1 … T_{K−2} the forward pass leaves for the backward pass.
    pub fn terms_len(&self, batch: usize, c_in: usize) -> usize {
        self.k.saturating_sub(2) * self.a.rows() * batch * c_in
    }

    /// Values of the `work` buffer [`Self::backward`] needs with dx: Clenshaw's b_{K−2} … b_1,
    /// (K − 2) blocks of `V·C_in·B` (none for K ≤ 2).
    pub fn work_len(&self, batch: usize, c_in: usize) -> usize {
        self.k.saturating_sub(2) * self.a.rows() * c_in * batch
    }

    fn shape(&self, d: ConvDims) -> ChebShape {
        ChebShape {
            batch: d.batch,
            v: self.a.rows(),
            ci: d.c_in,
            co: d.c_out,
            k: self.k,
        }
    }

    fn check(&self, op: &'static str, d: ConvDims, x: usize, w: usize, terms: usize) -> Result<()> {
        let v = self.a.rows();
        check_len(op, "x", x, v * d.c_in * d.batch)?;
        check_len(op, "w", w, d.c_in * self.k * d.c_out)?;
        check_len(op, "terms", terms, self.terms_len(d.batch, d.c_in))
    }

    /// y = conv(x): x `[V, C_in, B]`, y `[V, C_out, B]` (overwritten); `terms`
    /// ([`Self::terms_len`] values) receives what [`Self::backward`] reads. The sweeps stage
    /// chunks of vertices in buffers of `ws`.
    pub fn forward<T: Float>(
        &self,
        x: &[T],
        w: &[T],
        d: ConvDims,
        terms: &mut [T],
        y: &mut [T],
        ws: &Workspace,
    ) -> Result<()> {
        const OP: &str = "ChebKernel::forward";
        self.check(OP, d, x.len(), w.len(), terms.len())?;
        check_len(OP, "y", y.len(), self.a.rows() * d.c_out * d.batch)?;
        let s = self.shape(d);
        let xb = Blocks::channel_major(x, d.batch, d.c_in);
        let mut outs: Vec<&mut [T]> = split_terms(terms, self.k, self.a.rows() * d.batch * d.c_in);
        cheb_kernel::stored_terms_into(&self.a, xb, &s, &mut outs, ws);
        let refs: Vec<&[T]> = outs.into_iter().map(|t| &*t).collect();
        cheb_kernel::mix_terms(&self.a, xb, &refs, w, None, &s, (Io::VertexChannel, y), ws);
        Ok(())
    }

    /// The backward pass of [`Self::forward`] for the output gradient g `[V, C_out, B]`: writes
    /// dW (`[C_in·K, C_out]`, overwritten) and, if given, dx `[V, C_in, B]` (overwritten; `work`
    /// must then hold [`Self::work_len`] values, its contents are scratch). Nothing is
    /// allocated but dW's sums; the sweeps stage chunks in buffers of `ws`.
    #[allow(clippy::too_many_arguments)]
    pub fn backward<T: Float>(
        &self,
        x: &[T],
        terms: &[T],
        w: &[T],
        g: &[T],
        d: ConvDims,
        dw: &mut [T],
        dx: Option<(&mut [T], &mut [T])>,
        ws: &Workspace,
    ) -> Result<()> {
        const OP: &str = "ChebKernel::backward";
        self.check(OP, d, x.len(), w.len(), terms.len())?;
        let size = self.a.rows() * d.c_in * d.batch;
        check_len(OP, "g", g.len(), self.a.rows() * d.c_out * d.batch)?;
        check_len(OP, "dw", dw.len(), w.len())?;
        let work_len = self.work_len(d.batch, d.c_in);
        if let Some((dx, work)) = &dx {
            check_len(OP, "dx", dx.len(), size)?;
            if work.len() < work_len {
                check_len(OP, "work", work.len(), work_len)?;
            }
        }
        let s = self.shape(d);
        let refs: Vec<&[T]> = if size == 0 {
            vec![&[]; self.k.saturating_sub(2)]
        } else {
            terms.chunks(size).collect()
        };
        let bufs = match dx {
            Some((dx, work)) => Bufs {
                dx: Some((Io::VertexChannel, dx)),
                work: Some(&mut work[..work_len]),
                ws,
            },
            None => Bufs {
                dx: None,
                work: None,
                ws,
            },
        };
        let need = Need {
            x: true,
            w: true,
            b: false,
        };
        let inputs = cheb_kernel::Inputs {
            a: &self.a,
            at: &self.at,
            x: Blocks::channel_major(x, d.batch, d.c_in),
            terms: &refs,
            w,
            g: Blocks::channel_major(g, d.batch, d.c_out),
            s: &s,
        };
        let (grad_w, _) = cheb_kernel::backward_into(inputs, bufs, need);
        if let Some(grad_w) = grad_w {
            dw.copy_from_slice(&grad_w);
        }
        Ok(())
    }
}

/// The K − 2 stored-term slices of a `terms` buffer.
fn split_terms<T>(terms: &mut [T], k: usize, size: usize) -> Vec<&mut [T]> {
    let count = k.saturating_sub(2);
    if size == 0 {
        return (0..count).map(|_| <&mut [T]>::default()).collect();
    }
    terms.chunks_mut(size).take(count).collect()
}

/// Max pooling over the rows of a pooling matrix's pattern (each row's columns are one
/// cluster or neighbourhood), on caller-owned `[V, n]` slices; what [`crate::MaxPool`] runs on the CPU.
#[derive(Debug, Clone)]
pub struct MaxKernel {
    pattern: Arc<Csr>,
    /// The transposed pattern (fine vertex → the rows holding it), for the backward pass.
    pattern_t: Arc<Csr>,
    mode: MaxMode,
}

impl MaxKernel {
    /// The kernel selecting as `mode` says over the rows of `pooling` (coarse × fine).
    ///
    /// Errors: a matrix without fine vertices or too large for u32 indices.
    pub fn from_matrix(pooling: &CsrMatrix, mode: MaxMode) -> Result<Self> {
        if pooling.cols() == 0 {
            return Err(ConvError::argument(
                "MaxKernel::from_matrix",
                "pooling",
                "0 fine vertices is not a usable pooling matrix",
            ));
        }
        check_u32("MaxKernel::from_matrix", pooling)?;
        Ok(Self {
            pattern: Arc::new(Csr::from_matrix(pooling)),
            pattern_t: Arc::new(Csr::from_matrix(&pooling.transpose())),
            mode,
        })
    }

    /// What the kernel selects.
    pub fn mode(&self) -> MaxMode {
        self.mode
    }

    /// The clusters (the pooling matrix's pattern).
    pub(crate) fn pattern(&self) -> &Csr {
        &self.pattern
    }

    /// The transposed pattern: row j lists the clusters holding fine vertex j.
    pub(crate) fn pattern_t(&self) -> &Csr {
        &self.pattern_t
    }

    /// Max pooling of x `[fine, n]` into y `[coarse, n]` (every one of a vertex's n values
    /// pooled on its own, as [`crate::MaxPool::forward_vertex_major`]); `arg` (`[coarse, n]`)
    /// receives the selected fine vertex (`u32::MAX` for an empty cluster).
    pub fn forward_into<T: Float>(
        &self,
        x: &[T],
        y: &mut [T],
        arg: &mut [u32],
        n: usize,
    ) -> Result<()> {
        const OP: &str = "MaxKernel::forward_into";
        let p = &self.pattern;
        check_len(OP, "x", x.len(), p.cols() * n)?;
        check_len(OP, "y", y.len(), p.rows() * n)?;
        check_len(OP, "arg", arg.len(), p.rows() * n)?;
        max_pool(p, x, y, arg, n, self.mode);
        Ok(())
    }

    /// The adjoint of [`Self::forward_into`]: dx `[fine, n]` (overwritten) gets g `[coarse, n]`
    /// at the selected members, summed where a member was selected several times
    /// (overlapping member lists).
    pub fn backward_into<T: Float>(
        &self,
        arg: &[u32],
        g: &[T],
        dx: &mut [T],
        n: usize,
    ) -> Result<()> {
        const OP: &str = "MaxKernel::backward_into";
        let p = &self.pattern;
        check_len(OP, "g", g.len(), p.rows() * n)?;
        check_len(OP, "arg", arg.len(), p.rows() * n)?;
        check_len(OP, "dx", dx.len(), p.cols() * n)?;
        max_unpool(&self.pattern_t, arg, g, dx, n);
        Ok(())
    }
}

#[cfg(test)]
mod tests;
