//! [`ChebConv`]: Chebyshev graph convolution y = Σ_{k<K} T_k(L̃) x W_k + b (Defferrard et al.),
//! with T_0 x = x, T_1 x = L̃ x, T_k x = 2 L̃ T_{k−1} x − T_{k−2} x.
//!
//! Weights are `[C_in·K, C_out]` with row `fin·K + k`, as in the authors' code, so their
//! checkpoints map one to one. The bias is optional (the authors' convolution has none).
//!
//! On the CPU (backend [`Backend::Kernel`], f32/f64) the whole layer is one fused custom op (see
//! `cheb_kernel.rs`); elsewhere it is the same recurrence written with [`SparseOp`] products and
//! candle ops ([`ChebConv::forward_unfused`]), which runs on any device.

use crate::cheb_kernel::MAX_K;
use crate::cheb_op::ChebOp;
use crate::check;
use crate::error::{ConvError, Result};
use crate::layout::Io;
use crate::spmm::{SparseOp, use_kernel};
use candle_core::Tensor;
use candle_nn::{Init, VarBuilder};

/// Sizes and options of a [`ChebConv`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ChebConfig {
    pub c_in: usize,
    pub c_out: usize,
    /// Number of Chebyshev terms (orders 0 … K−1); the authors use 3.
    pub k: usize,
    /// Add a learned bias (zero-initialised); the authors' convolution has none.
    pub bias: bool,
    /// Standard deviation of the normal weight initialisation (the authors: 0.02).
    pub init_std: f64,
}

impl ChebConfig {
    /// K = 3, no bias, N(0, 0.02²) weights: the authors' settings.
    pub fn new(c_in: usize, c_out: usize) -> Self {
        Self {
            c_in,
            c_out,
            k: 3,
            bias: false,
            init_std: 0.02,
        }
    }
}

/// A Chebyshev graph convolution on a fixed rescaled Laplacian L̃.
#[derive(Debug, Clone)]
pub struct ChebConv {
    laplacian: SparseOp,
    weight: Tensor,
    bias: Option<Tensor>,
    k: usize,
}

impl ChebConv {
    /// A layer whose weights (`weight`, and `bias` if asked for) come from `vb`, e.g. a
    /// `VarMap` for training. The layer uses the Laplacian's backend.
    pub fn new(laplacian: SparseOp, config: ChebConfig, vb: VarBuilder) -> Result<Self> {
        const OP: &str = "ChebConv::new";
        if config.k == 0 {
            return Err(ConvError::argument(OP, "k", "needs at least one term"));
        }
        if config.c_in == 0 || config.c_out == 0 {
            return Err(ConvError::argument(
                OP,
                "c_in/c_out",
                "channel counts must be positive",
            ));
        }
        let init = Init::Randn {
            mean: 0.0,
            stdev: config.init_std,
        };
        let weight = vb.get_with_hints((config.c_in * config.k, config.c_out), "weight", init)?;
        let bias = if config.bias {
            Some(vb.get_with_hints(config.c_out, "bias", Init::Const(0.0))?)
        } else {
            None
        };
        Self::from_weights(laplacian, config.k, weight, bias)
    }

    /// A layer with given weights `[C_in·K, C_out]` (row `fin·K + k`) and optional bias `[C_out]`.
    pub fn from_weights(
        laplacian: SparseOp,
        k: usize,
        weight: Tensor,
        bias: Option<Tensor>,
    ) -> Result<Self> {
        const OP: &str = "ChebConv::from_weights";
        check::square(OP, "laplacian", laplacian.rows(), laplacian.cols())?;
        if k == 0 {
            return Err(ConvError::argument(OP, "k", "needs at least one term"));
        }
        let (rows, c_out) = weight
            .dims2()
            .map_err(|_| ConvError::argument(OP, "weight", format!("shape {:?}", weight.dims())))?;
        if rows == 0 || rows % k != 0 || c_out == 0 {
            return Err(ConvError::argument(
                OP,
                "weight",
                format!("shape {:?} is not [C_in·{k}, C_out]", weight.dims()),
            ));
        }
        check::bias(OP, bias.as_ref(), c_out)?;
        Ok(Self {
            laplacian,
            weight,
            bias,
            k,
        })
    }

    pub fn weight(&self) -> &Tensor {
        &self.weight
    }

    pub fn bias(&self) -> Option<&Tensor> {
        self.bias.as_ref()
    }

    pub fn k(&self) -> usize {
        self.k
    }

    pub fn c_in(&self) -> usize {
        self.weight.dims()[0] / self.k
    }

    pub fn c_out(&self) -> usize {
        self.weight.dims()[1]
    }

    pub fn laplacian(&self) -> &SparseOp {
        &self.laplacian
    }

    /// y `[B, V, C_out]` from x `[B, V, C_in]` (or `[V, C_in]` → `[V, C_out]`): the fused CPU op
    /// where it can run, [`Self::forward_unfused`] otherwise.
    pub fn forward(&self, x: &Tensor) -> Result<Tensor> {
        let (x3, squeeze) = self.check("ChebConv::forward", x)?;
        let y = match self.fused(&x3, Io::BatchMajor)? {
            Some(y) => y,
            None => self.add_bias(self.unfused(&x3)?)?,
        };
        Ok(if squeeze { y.squeeze(0)? } else { y })
    }

    /// y `[V, B, C_out]` from x `[V, B, C_in]`: the vertex-major layout, in which a network
    /// keeps its activations so that no layer transposes (see [`crate::SparseOp`]'s
    /// `apply_vertex_major`). Same results as [`Self::forward`] on the permuted tensors.
    pub fn forward_vertex_major(&self, x: &Tensor) -> Result<Tensor> {
        const OP: &str = "ChebConv::forward_vertex_major";
        if x.rank() != 3 {
            return Err(ConvError::input(
                OP,
                format!("input of shape {:?}; expected [V, B, C]", x.dims()),
            ));
        }
        let (x3, _) = self.check(OP, &x.transpose(0, 1)?)?;
        if let Some(y) = self.fused(x, Io::VertexBatch)? {
            return Ok(y);
        }
        let y = self.add_bias(self.unfused(&x3.contiguous()?)?)?;
        Ok(y.transpose(0, 1)?.contiguous()?)
    }

    /// The fused op on x in layout `io`, if it can run (CPU, f32/f64, K ≤ 8).
    fn fused(&self, x: &Tensor, io: Io) -> Result<Option<Tensor>> {
        let usable = use_kernel(self.laplacian.backend(), x)
            && self.weight.device().is_cpu()
            && self.k <= MAX_K;
        if !usable {
            return Ok(None);
        }
        let op = ChebOp::new(
            self.laplacian.csr().clone(),
            self.laplacian.csr_t().clone(),
            self.k,
            io,
            self.laplacian.workspace().clone(),
        );
        let (x, w) = (x.contiguous()?, self.weight.contiguous()?);
        Ok(Some(match &self.bias {
            Some(b) => x.apply_op3(&w, &b.contiguous()?, op)?,
            None => x.apply_op2(&w, op)?,
        }))
    }

    /// The recurrence written with [`SparseOp`] products (kernel or fallback, per the Laplacian's
    /// backend) and candle ops: stack the terms to `[B, V, C_in, K]`, one matmul with W.
    pub fn forward_unfused(&self, x: &Tensor) -> Result<Tensor> {
        let (x3, squeeze) = self.check("ChebConv::forward_unfused", x)?;
        let y = self.add_bias(self.unfused(&x3)?)?;
        Ok(if squeeze { y.squeeze(0)? } else { y })
    }

    fn unfused(&self, x: &Tensor) -> Result<Tensor> {
        let (batch, v, c_in) = x.dims3()?;
        let mut terms = vec![x.clone()];
        for k in 1..self.k {
            let lx = self.laplacian.apply(&terms[k - 1])?;
            let t = if k == 1 {
                lx
            } else {
                ((lx * 2.0)? - &terms[k - 2])?
            };
            terms.push(t);
        }
        let stacked = Tensor::stack(&terms, 3)?.reshape((batch * v, c_in * self.k))?;
        Ok(stacked
            .matmul(&self.weight)?
            .reshape((batch, v, self.c_out()))?)
    }

    fn check(&self, op: &'static str, x: &Tensor) -> Result<(Tensor, bool)> {
        let (x3, squeeze) = self.laplacian.check_input(op, x)?;
        if x3.dim(2)? != self.c_in() {
            return Err(ConvError::input(
                op,
                format!(
                    "input of shape {:?}; the layer expects {} channels",
                    x.dims(),
                    self.c_in()
                ),
            ));
        }
        if x.dtype() != self.weight.dtype() {
            return Err(ConvError::input(
                op,
                format!(
                    "input dtype {:?} differs from the weights' {:?}",
                    x.dtype(),
                    self.weight.dtype()
                ),
            ));
        }
        Ok((x3, squeeze))
    }

    fn add_bias(&self, y: Tensor) -> Result<Tensor> {
        Ok(match &self.bias {
            Some(b) => y.broadcast_add(b)?,
            None => y,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::spmm::Backend;
    use crate::test_util::*;
    use candle_core::{DType, Device, Var};

    fn grid_laplacian(n: usize, m: usize) -> sparse_csr::CsrMatrix {
        mesh_laplacian(n * m, &grid_faces(n, m))
    }

    #[test]
    fn layers_keep_their_scratch_in_their_operators_workspace() {
        // 300 vertices × 9 channels × B = 32: the channel-major copies and stored terms are
        // large enough to be kept for reuse.
        let m = random_matrix(300, 300, 0.015, 90);
        let shared = std::sync::Arc::new(crate::Workspace::new());
        let op = SparseOp::new(&m, &Device::Cpu)
            .unwrap()
            .with_workspace(shared.clone());
        let other = SparseOp::new(&m, &Device::Cpu).unwrap();
        assert!(!std::sync::Arc::ptr_eq(other.workspace(), &shared));
        let conv = layer(&op, 3, 9, 9, false, 1);
        let x = Var::from_tensor(&tensor(random_vec(32 * 300 * 9, 2), &[32, 300, 9])).unwrap();
        assert_eq!(shared.kept_bytes(), 0);
        let y = conv.forward(x.as_tensor()).unwrap();
        weighted_sum(&y, 3).unwrap().backward().unwrap();
        drop(y);
        let kept = shared.kept_bytes();
        assert!(kept >= 300 * 9 * 32 * 8, "{kept} bytes kept");
        let large = shared.large_count();
        assert!(large >= 1);
        assert_eq!(other.workspace().kept_bytes(), 0, "nothing in another op's");
        // A second pass reuses the large buffers rather than adding more.
        let y = conv.forward(x.as_tensor()).unwrap();
        weighted_sum(&y, 3).unwrap().backward().unwrap();
        drop(y);
        assert_eq!(shared.large_count(), large);
        shared.clear();
        assert_eq!(shared.kept_bytes(), 0);
    }

    fn layer(op: &SparseOp, k: usize, ci: usize, co: usize, bias: bool, seed: u64) -> ChebConv {
        let w = tensor(random_vec(ci * k * co, seed), &[ci * k, co]);
        let b = bias.then(|| tensor(random_vec(co, seed + 1), &[co]));
        ChebConv::from_weights(op.clone(), k, w, b).unwrap()
    }

    #[test]
    fn fused_unfused_and_fallback_agree_and_match_the_definition() {
        // A non-symmetric operator, so a missing transpose in a backward pass would show.
        let m = random_matrix(12, 12, 0.3, 21);
        let op = SparseOp::new(&m, &Device::Cpu).unwrap();
        for (k, ci, co, bias) in [
            (1, 2, 3, true),
            (2, 3, 2, false),
            (3, 9, 9, true),
            (4, 2, 3, true),
        ] {
            let conv = layer(&op, k, ci, co, bias, 30);
            let x = tensor(random_vec(2 * 12 * ci, 31), &[2, 12, ci]);
            let fused = conv.forward(&x).unwrap();
            let unfused = conv.forward_unfused(&x).unwrap();
            let fallback_conv = ChebConv::from_weights(
                op.with_backend(Backend::Fallback),
                k,
                conv.weight().clone(),
                conv.bias().cloned(),
            )
            .unwrap();
            let fallback = fallback_conv.forward(&x).unwrap();
            assert!(max_abs_diff(&fused, &unfused) < 1e-12, "K={k}");
            assert!(max_abs_diff(&fused, &fallback) < 1e-12, "K={k}");
            // y[b, v, o] by the definition, one term at a time with dense products.
            let w = to_vec(conv.weight());
            let mut terms = vec![to_vec(&x)];
            for j in 1..k {
                let ax = dense_apply(&m, &terms[j - 1], 2, ci);
                terms.push(if j == 1 {
                    ax
                } else {
                    ax.iter()
                        .zip(&terms[j - 2])
                        .map(|(a, p)| 2.0 * a - p)
                        .collect()
                });
            }
            let y = to_vec(&fused);
            let b = conv.bias().map(to_vec).unwrap_or(vec![0.0; co]);
            for r in 0..24 {
                for o in 0..co {
                    let mut want = b[o];
                    for f in 0..ci {
                        for (j, t) in terms.iter().enumerate() {
                            want += t[r * ci + f] * w[(f * k + j) * co + o];
                        }
                    }
                    assert!((y[r * co + o] - want).abs() < 1e-12);
                }
            }
        }
    }

    #[test]
    fn gradients_match_finite_differences_on_every_path() {
        let op = SparseOp::new(&grid_laplacian(4, 5), &Device::Cpu).unwrap();
        let conv = layer(&op, 3, 3, 2, true, 40);
        let x = Var::from_tensor(&tensor(random_vec(2 * 20 * 3, 41), &[2, 20, 3])).unwrap();
        let w = Var::from_tensor(conv.weight()).unwrap();
        let b = Var::from_tensor(conv.bias().unwrap()).unwrap();
        for backend in [Backend::Kernel, Backend::Fallback] {
            let conv = ChebConv::from_weights(
                op.with_backend(backend),
                3,
                w.as_tensor().clone(),
                Some(b.as_tensor().clone()),
            )
            .unwrap();
            for fused in [true, false] {
                let loss = || {
                    let y = if fused {
                        conv.forward(x.as_tensor())
                    } else {
                        conv.forward_unfused(x.as_tensor())
                    };
                    weighted_sum(&y.map_err(candle_core::Error::wrap)?.tanh()?, 42)
                };
                let err = grad_check(&[&x, &w, &b], loss);
                assert!(
                    err < 1e-7,
                    "{backend:?} fused={fused}: relative error {err}"
                );
            }
        }
    }

    #[test]
    fn fused_gradients_match_the_fallback_in_f32_and_skip_untracked_inputs() {
        let op = SparseOp::new(&grid_laplacian(5, 6), &Device::Cpu).unwrap();
        let conv = layer(&op, 3, 9, 9, false, 50);
        let w = Var::from_tensor(&conv.weight().to_dtype(DType::F32).unwrap()).unwrap();
        let x = Var::from_tensor(
            &tensor(random_vec(3 * 30 * 9, 51), &[3, 30, 9])
                .to_dtype(DType::F32)
                .unwrap(),
        )
        .unwrap();
        let grads = |backend| {
            let conv =
                ChebConv::from_weights(op.with_backend(backend), 3, w.as_tensor().clone(), None)
                    .unwrap();
            let y = conv.forward(x.as_tensor()).unwrap();
            let g = weighted_sum(&y.sqr().unwrap(), 52)
                .unwrap()
                .backward()
                .unwrap();
            (g.get(&x).unwrap().clone(), g.get(&w).unwrap().clone())
        };
        let (dx_k, dw_k) = grads(Backend::Kernel);
        let (dx_f, dw_f) = grads(Backend::Fallback);
        assert!(max_abs_diff(&dx_k, &dx_f) < 1e-5);
        assert!(max_abs_diff(&dw_k, &dw_f) < 1e-4);
        // Plain input data (not a Var): the op returns no dx, the weights still get theirs.
        let data = x.as_tensor().detach();
        let conv = ChebConv::from_weights(op.clone(), 3, w.as_tensor().clone(), None).unwrap();
        let g = conv
            .forward(&data)
            .unwrap()
            .sum_all()
            .unwrap()
            .backward()
            .unwrap();
        assert!(g.get(&data).is_none());
        assert!(g.get(&w).is_some());
    }

    /// Puts the kernels back on their SIMD variants even if the test fails.
    struct BaselineGuard;

    impl Drop for BaselineGuard {
        fn drop(&mut self) {
            crate::kernel::FORCE_BASELINE.store(false, std::sync::atomic::Ordering::Relaxed);
        }
    }

    #[test]
    fn fused_matches_fallback_across_chunks_lanes_and_instruction_sets() {
        // 300 vertices span several kernel chunks; non-symmetric, so L̃ᵀ ≠ L̃. B = 11 covers the
        // 8-lane blocks and their tail; the baseline round runs the non-AVX code; B = 32 makes
        // buffers large enough to be reused (the operator's workspace) between the rounds.
        let m = random_matrix(300, 300, 0.015, 90);
        let op = SparseOp::new(&m, &Device::Cpu).unwrap();
        let _lock = crate::kernel::BASELINE_LOCK.lock();
        let _guard = BaselineGuard;
        for baseline in [false, true] {
            crate::kernel::FORCE_BASELINE.store(baseline, std::sync::atomic::Ordering::Relaxed);
            for (k, ci, co, batch) in [(3, 9, 9, 11), (4, 2, 3, 3), (2, 3, 1, 8), (3, 9, 9, 32)] {
                let w = tensor(random_vec(ci * k * co, 91), &[ci * k, co]);
                let x = tensor(random_vec(batch * 300 * ci, 92), &[batch, 300, ci]);
                for dtype in [DType::F64, DType::F32] {
                    let w = Var::from_tensor(&w.to_dtype(dtype).unwrap()).unwrap();
                    let x = Var::from_tensor(&x.to_dtype(dtype).unwrap()).unwrap();
                    let run = |backend| {
                        let op = op.with_backend(backend);
                        let conv =
                            ChebConv::from_weights(op, k, w.as_tensor().clone(), None).unwrap();
                        let y = conv.forward(x.as_tensor()).unwrap();
                        let g = weighted_sum(&y, 93).unwrap().backward().unwrap();
                        (y, g.get(&x).unwrap().clone(), g.get(&w).unwrap().clone())
                    };
                    let (y_k, dx_k, dw_k) = run(Backend::Kernel);
                    let (y_f, dx_f, dw_f) = run(Backend::Fallback);
                    let tol = if dtype == DType::F64 { 1e-10 } else { 1e-4 };
                    let case = format!("K={k} B={batch} {dtype:?} baseline={baseline}");
                    assert!(max_abs_diff(&y_k, &y_f) < tol, "{case}");
                    assert!(max_abs_diff(&dx_k, &dx_f) < tol, "{case}");
                    assert!(max_abs_diff(&dw_k, &dw_f) < 10.0 * tol, "{case}");
                }
            }
        }
    }

    #[test]
    fn construction_and_input_errors_are_typed() {
        let op = SparseOp::new(&grid_laplacian(3, 3), &Device::Cpu).unwrap();
        let vm = candle_nn::VarMap::new();
        let vb = VarBuilder::from_varmap(&vm, DType::F32, &Device::Cpu);
        let conv = ChebConv::new(op.clone(), ChebConfig::new(9, 4), vb.pp("c")).unwrap();
        assert_eq!(conv.weight().dims(), &[27, 4]);
        assert!(conv.bias().is_none());
        assert_eq!(vm.all_vars().len(), 1);
        let bad_k = ChebConfig {
            k: 0,
            ..ChebConfig::new(9, 4)
        };
        assert!(matches!(
            ChebConv::new(op.clone(), bad_k, vb.pp("d")),
            Err(ConvError::Argument { .. })
        ));
        let bad_w = tensor(vec![0.0; 10], &[5, 2]);
        assert!(matches!(
            ChebConv::from_weights(op.clone(), 3, bad_w, None),
            Err(ConvError::Argument { .. })
        ));
        let rect = SparseOp::new(&random_matrix(3, 4, 0.5, 1), &Device::Cpu).unwrap();
        let w = tensor(vec![0.0; 6], &[3, 2]);
        let err = ChebConv::from_weights(rect, 3, w.clone(), None).unwrap_err();
        assert!(matches!(
            err,
            ConvError::Argument {
                arg: "laplacian",
                ..
            }
        ));
        assert!(err.to_string().contains("must be square, is 3x4"), "{err}");
        let b3 = tensor(vec![0.0; 3], &[3]);
        let err = ChebConv::from_weights(op.clone(), 3, w, Some(b3)).unwrap_err();
        assert!(
            err.to_string().contains("`bias`: shape [3], expected [2]"),
            "{err}"
        );
        let x = Tensor::zeros((2, 9, 8), DType::F32, &Device::Cpu).unwrap();
        let err = conv.forward(&x).unwrap_err().to_string();
        assert!(err.contains("expects 9 channels"), "{err}");
        let x64 = Tensor::zeros((9, 9), DType::F64, &Device::Cpu).unwrap();
        assert!(matches!(conv.forward(&x64), Err(ConvError::Input { .. })));
        let y = conv.forward(&x64.to_dtype(DType::F32).unwrap()).unwrap();
        assert_eq!(y.dims(), &[9, 4]);
    }
}
