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
use crate::max_kernel::{max_pool, max_unpool};
use crate::pool::MaxPool;
use crate::spmm::SparseOp;
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

    /// Rows of A (output vertices).
    pub fn rows(&self) -> usize {
        self.a.rows
    }

    /// Columns of A (input vertices).
    pub fn cols(&self) -> usize {
        self.a.cols
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
        check_len(op, "x", x.len(), a.cols * n)?;
        check_len(op, "y", y.len(), a.rows * n)?;
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
    /// The convolution of order `k` (1 ..= 8) on `laplacian`.
    pub fn new(laplacian: &SparseOp, k: usize) -> Result<Self> {
        if k == 0 || k > MAX_K {
            return Err(ConvError::argument(
                "ChebKernel::new",
                "k",
                format!("{k}; the fused kernels take 1 ..= {MAX_K}"),
            ));
        }
        if laplacian.rows() != laplacian.cols() {
            return Err(ConvError::argument(
                "ChebKernel::new",
                "laplacian",
                format!("{}x{} is not square", laplacian.rows(), laplacian.cols()),
            ));
        }
        Ok(Self {
            a: laplacian.csr().clone(),
            at: laplacian.csr_t().clone(),
            k,
        })
    }

    pub fn k(&self) -> usize {
        self.k
    }

    pub fn vertices(&self) -> usize {
        self.a.rows
    }

    /// Values of the stored terms T_1 … T_{K−2} the forward pass leaves for the backward pass.
    pub fn terms_len(&self, batch: usize, c_in: usize) -> usize {
        self.k.saturating_sub(2) * self.a.rows * batch * c_in
    }

    fn shape(&self, d: ConvDims) -> ChebShape {
        ChebShape {
            batch: d.batch,
            v: self.a.rows,
            ci: d.c_in,
            co: d.c_out,
            k: self.k,
        }
    }

    fn check(&self, op: &'static str, d: ConvDims, x: usize, w: usize, terms: usize) -> Result<()> {
        let v = self.a.rows;
        check_len(op, "x", x, v * d.c_in * d.batch)?;
        check_len(op, "w", w, d.c_in * self.k * d.c_out)?;
        check_len(op, "terms", terms, self.terms_len(d.batch, d.c_in))
    }

    /// y = conv(x): x `[V, C_in, B]`, y `[V, C_out, B]` (overwritten); `terms`
    /// ([`Self::terms_len`] values) receives what [`Self::backward`] reads.
    pub fn forward<T: Float>(
        &self,
        x: &[T],
        w: &[T],
        d: ConvDims,
        terms: &mut [T],
        y: &mut [T],
    ) -> Result<()> {
        const OP: &str = "ChebKernel::forward";
        self.check(OP, d, x.len(), w.len(), terms.len())?;
        check_len(OP, "y", y.len(), self.a.rows * d.c_out * d.batch)?;
        let s = self.shape(d);
        let xb = Blocks::channel_major(x, d.batch, d.c_in);
        let mut outs: Vec<&mut [T]> = split_terms(terms, self.k, self.a.rows * d.batch * d.c_in);
        cheb_kernel::stored_terms_into(&self.a, xb, &s, &mut outs);
        let refs: Vec<&[T]> = outs.into_iter().map(|t| &*t).collect();
        cheb_kernel::mix_terms(&self.a, xb, &refs, w, None, &s, (Io::VertexChannel, y));
        Ok(())
    }

    /// The backward pass of [`Self::forward`] for the output gradient g `[V, C_out, B]`: writes
    /// dW (`[C_in·K, C_out]`, overwritten) and, if given, dx `[V, C_in, B]` (overwritten; `work`
    /// must then hold `V·C_in·B` values for K ≥ 3, its contents are scratch).
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
    ) -> Result<()> {
        const OP: &str = "ChebKernel::backward";
        self.check(OP, d, x.len(), w.len(), terms.len())?;
        let size = self.a.rows * d.c_in * d.batch;
        check_len(OP, "g", g.len(), self.a.rows * d.c_out * d.batch)?;
        check_len(OP, "dw", dw.len(), w.len())?;
        if let Some((dx, work)) = &dx {
            check_len(OP, "dx", dx.len(), size)?;
            if self.k >= 3 && work.len() < size {
                check_len(OP, "work", work.len(), size)?;
            }
        }
        let s = self.shape(d);
        let refs: Vec<&[T]> = if size == 0 {
            vec![&[]; self.k.saturating_sub(2)]
        } else {
            terms.chunks(size).collect()
        };
        let bufs = match dx {
            Some((dx, work)) => {
                let len = size.min(work.len());
                Bufs {
                    dx: Some((Io::VertexChannel, dx)),
                    work: Some(&mut work[..len]),
                }
            }
            None => Bufs {
                dx: None,
                work: None,
            },
        };
        let need = Need {
            x: true,
            w: true,
            b: false,
        };
        let (grad_w, _) = cheb_kernel::backward_into(
            &self.a,
            &self.at,
            Blocks::channel_major(x, d.batch, d.c_in),
            &refs,
            w,
            Blocks::channel_major(g, d.batch, d.c_out),
            &s,
            bufs,
            need,
        );
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

impl MaxPool {
    /// Max pooling (the layer's [`MaxPool::mode`]) of x `[fine, n]` into y `[coarse, n]`
    /// (every one of a vertex's n values pooled on its own, as
    /// [`MaxPool::forward_vertex_major`]); `arg` (`[coarse, n]`) receives the selected fine
    /// vertex (`u32::MAX` for an empty cluster).
    pub fn forward_into<T: Float>(
        &self,
        x: &[T],
        y: &mut [T],
        arg: &mut [u32],
        n: usize,
    ) -> Result<()> {
        const OP: &str = "MaxPool::forward_into";
        let p = self.pattern();
        check_len(OP, "x", x.len(), p.cols * n)?;
        check_len(OP, "y", y.len(), p.rows * n)?;
        check_len(OP, "arg", arg.len(), p.rows * n)?;
        max_pool(p, x, y, arg, n, self.mode());
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
        const OP: &str = "MaxPool::backward_into";
        let p = self.pattern();
        check_len(OP, "g", g.len(), p.rows * n)?;
        check_len(OP, "arg", arg.len(), p.rows * n)?;
        check_len(OP, "dx", dx.len(), p.cols * n)?;
        max_unpool(self.pattern_t(), arg, g, dx, n);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_util::{random_matrix, random_vec};
    use candle_core::{Device, Tensor};

    /// `[V, C, B]` → `[V, B, C]` (the candle ops' vertex-major layout).
    fn vcb_to_vbc(x: &[f64], (v, c, b): (usize, usize, usize)) -> Vec<f64> {
        let mut out = vec![0.0; x.len()];
        for i in 0..v {
            for ch in 0..c {
                for bb in 0..b {
                    out[(i * b + bb) * c + ch] = x[(i * c + ch) * b + bb];
                }
            }
        }
        out
    }

    fn vbc_to_vcb(x: &[f64], (v, c, b): (usize, usize, usize)) -> Vec<f64> {
        let mut out = vec![0.0; x.len()];
        for i in 0..v {
            for ch in 0..c {
                for bb in 0..b {
                    out[(i * c + ch) * b + bb] = x[(i * b + bb) * c + ch];
                }
            }
        }
        out
    }

    #[test]
    fn cheb_kernel_matches_the_candle_op_with_gradients() {
        let v = 90;
        let m = random_matrix(v, v, 0.05, 3);
        let op = SparseOp::new(&m, &Device::Cpu).unwrap();
        for (k, ci, co, batch) in [(1, 3, 2, 2), (2, 9, 4, 3), (3, 9, 9, 4), (4, 2, 3, 5)] {
            let kernel = ChebKernel::new(&op, k).unwrap();
            let d = ConvDims {
                batch,
                c_in: ci,
                c_out: co,
            };
            let x = random_vec(v * ci * batch, 1);
            let w = random_vec(ci * k * co, 2);
            let g = random_vec(v * co * batch, 4);
            let mut terms = vec![0.0; kernel.terms_len(batch, ci)];
            let mut y = vec![7.0; v * co * batch];
            kernel.forward(&x, &w, d, &mut terms, &mut y).unwrap();
            // The candle op on the same data, [V, B, C].
            let xt = candle_core::Var::from_vec(
                vcb_to_vbc(&x, (v, ci, batch)),
                (v, batch, ci),
                &Device::Cpu,
            )
            .unwrap();
            let wt = candle_core::Var::from_vec(w.clone(), (ci * k, co), &Device::Cpu).unwrap();
            let conv =
                crate::ChebConv::from_weights(op.clone(), k, wt.as_tensor().clone(), None).unwrap();
            let yt = conv.forward_vertex_major(xt.as_tensor()).unwrap();
            let want = vbc_to_vcb(
                &yt.flatten_all().unwrap().to_vec1().unwrap(),
                (v, co, batch),
            );
            for (p, q) in y.iter().zip(&want) {
                assert!((p - q).abs() < 1e-12, "K={k}: forward {p} vs {q}");
            }
            let gt = Tensor::from_vec(vcb_to_vbc(&g, (v, co, batch)), (v, batch, co), &Device::Cpu)
                .unwrap();
            let grads = (yt * gt).unwrap().sum_all().unwrap().backward().unwrap();
            let mut dw = vec![0.0; w.len()];
            let (mut dx, mut work) = (vec![5.0; x.len()], vec![3.0; x.len()]);
            kernel
                .backward(&x, &terms, &w, &g, d, &mut dw, Some((&mut dx, &mut work)))
                .unwrap();
            let want_dw: Vec<f64> = grads
                .get(&wt)
                .unwrap()
                .flatten_all()
                .unwrap()
                .to_vec1()
                .unwrap();
            let want_dx = vbc_to_vcb(
                &grads
                    .get(&xt)
                    .unwrap()
                    .flatten_all()
                    .unwrap()
                    .to_vec1()
                    .unwrap(),
                (v, ci, batch),
            );
            for (p, q) in dw.iter().zip(&want_dw).chain(dx.iter().zip(&want_dx)) {
                assert!(
                    (p - q).abs() < 1e-10 * q.abs().max(1.0),
                    "K={k}: {p} vs {q}"
                );
            }
            // Without dx, dW is the same.
            let mut dw2 = vec![0.0; w.len()];
            kernel
                .backward(&x, &terms, &w, &g, d, &mut dw2, None)
                .unwrap();
            assert_eq!(dw, dw2);
        }
        let kernel = ChebKernel::new(&op, 3).unwrap();
        let d = ConvDims {
            batch: 2,
            c_in: 3,
            c_out: 3,
        };
        let err = kernel
            .forward(&[0.0; 5], &[0.0; 27], d, &mut [], &mut [0.0; 540])
            .unwrap_err()
            .to_string();
        assert!(err.contains("x has 5 values"), "{err}");
        assert!(ChebKernel::new(&op, 0).is_err() && ChebKernel::new(&op, 9).is_err());
    }

    #[test]
    fn sparse_and_max_pool_kernels_match_dense_and_their_adjoints() {
        let m = random_matrix(30, 70, 0.1, 5);
        let op = SparseOp::new(&m, &Device::Cpu).unwrap();
        let kernel = SparseKernel::new(&op);
        let n = 6;
        let x = random_vec(70 * n, 6);
        let g = random_vec(30 * n, 7);
        let (mut y, mut back) = (vec![0.0; 30 * n], vec![0.0; 70 * n]);
        kernel.apply(&x, &mut y, n).unwrap();
        kernel.apply_t(&g, &mut back, n).unwrap();
        let want = crate::test_util::dense_apply(&m, &x, 1, n);
        assert!(y.iter().zip(&want).all(|(p, q)| (p - q).abs() < 1e-12));
        // <g, A x> = <Aᵀ g, x>.
        let lhs: f64 = g.iter().zip(&y).map(|(a, b)| a * b).sum();
        let rhs: f64 = back.iter().zip(&x).map(|(a, b)| a * b).sum();
        assert!((lhs - rhs).abs() < 1e-10 * lhs.abs().max(1.0));
        assert!(kernel.apply(&x[1..], &mut y, n).is_err());

        let pool = MaxPool::new(&m, &Device::Cpu).unwrap();
        let (mut py, mut arg) = (vec![0.0; 30 * n], vec![0u32; 30 * n]);
        pool.forward_into(&x, &mut py, &mut arg, n).unwrap();
        let xt = Tensor::from_vec(x.clone(), (70, 1, n), &Device::Cpu).unwrap();
        let want: Vec<f64> = pool
            .forward_vertex_major(&xt)
            .unwrap()
            .flatten_all()
            .unwrap()
            .to_vec1()
            .unwrap();
        assert_eq!(py, want);
        let mut dx = vec![9.0; 70 * n];
        pool.backward_into(&arg, &g, &mut dx, n).unwrap();
        let lhs: f64 = g.iter().zip(&py).map(|(a, b)| a * b).sum();
        let rhs: f64 = dx.iter().zip(&x).map(|(a, b)| a * b).sum();
        assert!((lhs - rhs).abs() < 1e-10 * lhs.abs().max(1.0));
    }

    #[test]
    fn graph_max_pool_buffers_match_the_candle_op_and_its_gradient() {
        // Overlapping member lists: each coarse vertex takes a random ~10% of 70 fine ones.
        let m = random_matrix(30, 70, 0.1, 11);
        let pool = MaxPool::with_mode(&m, crate::MaxMode::Plain, &Device::Cpu).unwrap();
        let n = 6;
        let x = random_vec(70 * n, 12);
        let g = random_vec(30 * n, 13);
        let (mut y, mut arg) = (vec![0.0; 30 * n], vec![0u32; 30 * n]);
        pool.forward_into(&x, &mut y, &mut arg, n).unwrap();
        let xt = candle_core::Var::from_vec(x.clone(), (70, 1, n), &Device::Cpu).unwrap();
        let yt = pool.forward_vertex_major(xt.as_tensor()).unwrap();
        let want: Vec<f64> = yt.flatten_all().unwrap().to_vec1().unwrap();
        assert_eq!(y, want);
        let gt = Tensor::from_vec(g.clone(), (30, 1, n), &Device::Cpu).unwrap();
        let grads = (yt * gt).unwrap().sum_all().unwrap().backward().unwrap();
        let want_dx: Vec<f64> = grads
            .get(xt.as_tensor())
            .unwrap()
            .flatten_all()
            .unwrap()
            .to_vec1()
            .unwrap();
        let mut dx = vec![9.0; 70 * n];
        pool.backward_into(&arg, &g, &mut dx, n).unwrap();
        for (p, q) in dx.iter().zip(&want_dx) {
            assert!((p - q).abs() < 1e-14, "{p} vs {q}");
        }
        // Some fine vertex was selected by more than one row and got the sum.
        let mut times = vec![0usize; 70 * n];
        for (i, &j) in arg.iter().enumerate() {
            if j != u32::MAX {
                times[j as usize * n + i % n] += 1;
            }
        }
        assert!(times.iter().any(|&t| t > 1));
        assert!(pool.backward_into(&arg, &g[1..], &mut dx, n).is_err());
    }

    #[test]
    fn max_pool_blocks_match_a_plain_loop_and_unpool_is_the_same_on_any_thread_count() {
        // 40 values per vertex: two blocks of 16 and a tail of 8 in the forward kernel.
        let m = random_matrix(50, 120, 0.08, 14);
        let n = 40;
        let x = random_vec(120 * n, 15);
        let g = random_vec(50 * n, 16);
        for mode in [crate::MaxMode::Plain, crate::MaxMode::SignedMagnitude] {
            let pool = MaxPool::with_mode(&m, mode, &Device::Cpu).unwrap();
            let (mut y, mut arg) = (vec![0.0; 50 * n], vec![0u32; 50 * n]);
            pool.forward_into(&x, &mut y, &mut arg, n).unwrap();
            for r in 0..50 {
                for k in 0..n {
                    let (mut best, mut at) = (0.0f64, u32::MAX);
                    for &j in m.row(r).0 {
                        let v = x[j as usize * n + k];
                        let better = match mode {
                            crate::MaxMode::Plain => v > best,
                            crate::MaxMode::SignedMagnitude => {
                                v.abs() > best.abs() || (v.abs() == best.abs() && v < best)
                            }
                        };
                        if at == u32::MAX || better {
                            (best, at) = (v, j);
                        }
                    }
                    assert_eq!((y[r * n + k], arg[r * n + k]), (best, at), "{mode:?}");
                }
            }
            let run = |threads: usize| {
                let mut dx = vec![0.0; 120 * n];
                rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .build()
                    .unwrap()
                    .install(|| pool.backward_into(&arg, &g, &mut dx, n).unwrap());
                dx
            };
            let one = run(1);
            assert_eq!(one, run(2));
            assert_eq!(one, run(5));
            // And it is the plain scatter-add.
            let mut want = vec![0.0; 120 * n];
            for (i, &j) in arg.iter().enumerate() {
                if j != u32::MAX {
                    want[j as usize * n + i % n] += g[i];
                }
            }
            assert_eq!(one, want);
        }
    }

    /// Timing probe (not a test of results): `cargo test --release -p spectral-conv --lib --
    /// --ignored --nocapture graph_pool_timing_probe`. Graph max pooling on a 205×205 grid
    /// (clusters of two vertices, so about half survive) at n = 288 values per vertex (B = 32,
    /// C = 9), against mean pooling over the same clusters.
    #[test]
    #[ignore]
    fn graph_pool_timing_probe() {
        let (rows, cols) = (205usize, 205usize);
        let v = rows * cols;
        let faces = crate::test_util::grid_faces(rows, cols);
        let half = cols.div_ceil(2);
        let cluster_of: Vec<u32> = (0..v)
            .map(|u| ((u / cols) * half + (u % cols) / 2) as u32)
            .collect();
        let survivors: Vec<u32> = (0..rows * half)
            .map(|c| ((c / half) * cols + (c % half) * 2) as u32)
            .collect();
        let members =
            mesh_hierarchy::graph::neighbourhoods(&faces, &survivors, &cluster_of).unwrap();
        let m = members.rows();
        let n = 288;
        let x: Vec<f32> = random_vec(v * n, 1).iter().map(|&a| a as f32).collect();
        let pool = MaxPool::with_mode(&members, crate::MaxMode::Plain, &Device::Cpu).unwrap();
        let signed = MaxPool::new(&members, &Device::Cpu).unwrap();
        let (mut y, mut arg, mut dx) = (vec![0f32; m * n], vec![0u32; m * n], vec![0f32; v * n]);
        // The fastest of 10 calls: the machine is shared.
        let time = |label: &str, f: &mut dyn FnMut()| {
            let mut best = f64::INFINITY;
            for _ in 0..10 {
                let t = std::time::Instant::now();
                f();
                best = best.min(t.elapsed().as_secs_f64() * 1e3);
            }
            println!("{label}: {best:.1} ms");
        };
        println!("{v} -> {m} vertices, {} memberships", members.nnz());
        time("graph pool forward_into", &mut || {
            pool.forward_into(&x, &mut y, &mut arg, n).unwrap()
        });
        time("signed max pool forward_into", &mut || {
            signed.forward_into(&x, &mut y, &mut arg, n).unwrap()
        });
        time("graph pool backward_into", &mut || {
            pool.backward_into(&arg, &y, &mut dx, n).unwrap()
        });
        let one = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap();
        time("graph pool backward_into, 1 thread", &mut || {
            one.install(|| pool.backward_into(&arg, &y, &mut dx, n).unwrap())
        });
        let mean = SparseKernel::new(&SparseOp::new(&members, &Device::Cpu).unwrap());
        time("sparse product, same pattern", &mut || {
            mean.apply(&x, &mut y, n).unwrap()
        });
    }
}
