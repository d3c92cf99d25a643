//! [`SpatialConv`]: the paper's "Only Spatial Conv." layer, in the style of Gao et al. 2018:
//! y_i = W_selfᵀ x_i + W_nbᵀ · mean_{j ∈ N(i)} x_j + b, with weights `[C_in, C_out]`.
//!
//! The neighbour mean is a [`SparseOp`] of D⁻¹A (see [`neighbour_mean_matrix`]), so it shares the
//! kernel/fallback machinery (and gradients) of every other sparse product.

use crate::check;
use crate::error::{ConvError, Result};
use crate::spmm::SparseOp;
use candle_core::Tensor;
use candle_nn::{Init, VarBuilder};
use sparse_csr::CsrMatrix;

/// D⁻¹A: row i holds 1/|N(i)| at each neighbour j ≠ i of the adjacency pattern (its values are
/// ignored, so a weighted adjacency works too). A vertex without neighbours gets an empty row,
/// i.e. a neighbour mean of 0.
pub fn neighbour_mean_matrix(adjacency: &CsrMatrix) -> Result<CsrMatrix> {
    const OP: &str = "neighbour_mean_matrix";
    check::square(OP, "adjacency", adjacency.rows(), adjacency.cols())?;
    let mut triplets = Vec::with_capacity(adjacency.nnz());
    for r in 0..adjacency.rows() {
        let neighbours: Vec<u32> = adjacency
            .row(r)
            .0
            .iter()
            .copied()
            .filter(|&c| c as usize != r)
            .collect();
        let w = 1.0 / neighbours.len().max(1) as f64;
        triplets.extend(neighbours.into_iter().map(|c| (r as u32, c, w)));
    }
    CsrMatrix::from_triplets(adjacency.rows(), adjacency.cols(), &triplets)
        .map_err(|e| ConvError::argument(OP, "adjacency", e.to_string()))
}

/// Sizes and options of a [`SpatialConv`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SpatialConfig {
    pub c_in: usize,
    pub c_out: usize,
    /// Add a learned bias (zero-initialised).
    pub bias: bool,
    /// Standard deviation of the normal weight initialisation.
    pub init_std: f64,
}

impl SpatialConfig {
    /// With bias, N(0, 0.02²) weights (the initialisation the authors use for every layer).
    pub fn new(c_in: usize, c_out: usize) -> Self {
        Self {
            c_in,
            c_out,
            bias: true,
            init_std: 0.02,
        }
    }
}

/// A spatial graph convolution: self term plus mean of the neighbours.
#[derive(Debug, Clone)]
pub struct SpatialConv {
    neighbour_mean: SparseOp,
    w_self: Tensor,
    w_nb: Tensor,
    bias: Option<Tensor>,
}

impl SpatialConv {
    /// A layer with weights `w_self`, `w_nb` (and `bias`) from `vb`; `neighbour_mean` is a
    /// [`SparseOp`] of [`neighbour_mean_matrix`].
    pub fn new(neighbour_mean: SparseOp, config: SpatialConfig, vb: VarBuilder) -> Result<Self> {
        if config.c_in == 0 || config.c_out == 0 {
            return Err(ConvError::argument(
                "SpatialConv::new",
                "c_in/c_out",
                "channel counts must be positive",
            ));
        }
        let init = Init::Randn {
            mean: 0.0,
            stdev: config.init_std,
        };
        let shape = (config.c_in, config.c_out);
        let w_self = vb.get_with_hints(shape, "w_self", init)?;
        let w_nb = vb.get_with_hints(shape, "w_nb", init)?;
        let bias = if config.bias {
            Some(vb.get_with_hints(config.c_out, "bias", Init::Const(0.0))?)
        } else {
            None
        };
        Self::from_weights(neighbour_mean, w_self, w_nb, bias)
    }

    /// A layer with given weights `[C_in, C_out]` and optional bias `[C_out]`.
    pub fn from_weights(
        neighbour_mean: SparseOp,
        w_self: Tensor,
        w_nb: Tensor,
        bias: Option<Tensor>,
    ) -> Result<Self> {
        const OP: &str = "SpatialConv::from_weights";
        check::square(
            OP,
            "neighbour_mean",
            neighbour_mean.rows(),
            neighbour_mean.cols(),
        )?;
        if w_self.rank() != 2 || w_self.dims() != w_nb.dims() {
            return Err(ConvError::argument(
                OP,
                "w_self/w_nb",
                format!(
                    "shapes {:?} and {:?}; expected both [C_in, C_out]",
                    w_self.dims(),
                    w_nb.dims()
                ),
            ));
        }
        let c_out = w_self.dims()[1];
        check::bias(OP, bias.as_ref(), c_out)?;
        Ok(Self {
            neighbour_mean,
            w_self,
            w_nb,
            bias,
        })
    }

    pub fn w_self(&self) -> &Tensor {
        &self.w_self
    }

    pub fn w_nb(&self) -> &Tensor {
        &self.w_nb
    }

    pub fn bias(&self) -> Option<&Tensor> {
        self.bias.as_ref()
    }

    /// The neighbour-mean operator.
    pub fn neighbour_mean(&self) -> &SparseOp {
        &self.neighbour_mean
    }

    /// The output channel count, once `x` (with `c_in` channels) is known to suit the weights.
    fn check_channels(&self, op: &'static str, x: &Tensor, c_in: usize) -> Result<usize> {
        let (w_in, c_out) = self.w_self.dims2()?;
        if c_in != w_in || x.dtype() != self.w_self.dtype() {
            return Err(ConvError::input(
                op,
                format!(
                    "input {:?} of {:?}; the layer expects {w_in} channels of {:?}",
                    x.dims(),
                    x.dtype(),
                    self.w_self.dtype()
                ),
            ));
        }
        Ok(c_out)
    }

    /// y `[V, B, C_out]` from x `[V, B, C_in]` (or `[V, C_in]` → `[V, C_out]`): the vertex-major
    /// layout; channel last, so both products are one matmul over the V·B rows.
    pub fn forward_vertex_major(&self, x: &Tensor) -> Result<Tensor> {
        const OP: &str = "SpatialConv::forward_vertex_major";
        let (_, flat) = self.neighbour_mean.vertex_major_rows(OP, x)?;
        let c_in = x.dims().last().copied().unwrap_or(0);
        let c_out = self.check_channels(OP, x, c_in)?;
        let rows = flat.elem_count() / c_in;
        let mean = self.neighbour_mean.apply(&flat)?;
        let flat2 = |t: &Tensor| t.reshape((rows, c_in));
        let y = (flat2(&flat)?.matmul(&self.w_self)? + flat2(&mean)?.matmul(&self.w_nb)?)?;
        let y = match &self.bias {
            Some(b) => crate::bias::add_bias(&y, b, self.neighbour_mean.backend())?,
            None => y,
        };
        let mut dims = x.dims().to_vec();
        if let Some(last) = dims.last_mut() {
            *last = c_out;
        }
        Ok(y.reshape(dims)?)
    }

    /// y `[B, V, C_out]` from x `[B, V, C_in]` (or `[V, C_in]` → `[V, C_out]`).
    pub fn forward(&self, x: &Tensor) -> Result<Tensor> {
        const OP: &str = "SpatialConv::forward";
        let (x3, squeeze) = self.neighbour_mean.check_input(OP, x)?;
        let (batch, v, c_in) = x3.dims3()?;
        let c_out = self.check_channels(OP, x, c_in)?;
        let mean = self.neighbour_mean.apply(&x3)?;
        let flat = |t: &Tensor| t.reshape((batch * v, c_in));
        let y = (flat(&x3)?.matmul(&self.w_self)? + flat(&mean)?.matmul(&self.w_nb)?)?
            .reshape((batch, v, c_out))?;
        let y = match &self.bias {
            Some(b) => crate::bias::add_bias(&y, b, self.neighbour_mean.backend())?,
            None => y,
        };
        Ok(if squeeze { y.squeeze(0)? } else { y })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::spmm::Backend;
    use crate::test_util::*;
    use candle_core::{DType, Device, Var};

    #[test]
    fn neighbour_mean_averages_the_one_ring() {
        // Two triangles 0-1-2, 0-2-3, plus an isolated vertex 4.
        let adj = adjacency(5, &[[0, 1, 2], [0, 2, 3]]);
        let m = neighbour_mean_matrix(&adj).unwrap().to_dense();
        assert_eq!(m[0], vec![0.0, 1.0 / 3.0, 1.0 / 3.0, 1.0 / 3.0, 0.0]);
        assert_eq!(m[1], vec![0.5, 0.0, 0.5, 0.0, 0.0]);
        assert_eq!(m[4], vec![0.0; 5]);
        assert!(neighbour_mean_matrix(&random_matrix(2, 3, 0.5, 1)).is_err());
    }

    #[test]
    fn forward_matches_definition_and_gradients_match_finite_differences() {
        let faces = grid_faces(4, 4);
        let mean = neighbour_mean_matrix(&adjacency(16, &faces)).unwrap();
        let op = SparseOp::new(&mean, &Device::Cpu).unwrap();
        let (ci, co) = (3, 2);
        let ws = Var::from_tensor(&tensor(random_vec(ci * co, 60), &[ci, co])).unwrap();
        let wn = Var::from_tensor(&tensor(random_vec(ci * co, 61), &[ci, co])).unwrap();
        let b = Var::from_tensor(&tensor(random_vec(co, 62), &[co])).unwrap();
        let x = Var::from_tensor(&tensor(random_vec(2 * 16 * ci, 63), &[2, 16, ci])).unwrap();
        let dense = mean.to_dense();
        let (xv, wsv, wnv, bv) = (to_vec(&x), to_vec(&ws), to_vec(&wn), to_vec(&b));
        for backend in [Backend::Kernel, Backend::Fallback] {
            let conv = SpatialConv::from_weights(
                op.with_backend(backend),
                ws.as_tensor().clone(),
                wn.as_tensor().clone(),
                Some(b.as_tensor().clone()),
            )
            .unwrap();
            let y = to_vec(&conv.forward(x.as_tensor()).unwrap());
            for bt in 0..2 {
                for i in 0..16 {
                    for o in 0..co {
                        let mut want = bv[o];
                        for f in 0..ci {
                            let xi = xv[(bt * 16 + i) * ci + f];
                            let nb: f64 = (0..16)
                                .map(|j| dense[i][j] * xv[(bt * 16 + j) * ci + f])
                                .sum();
                            want += xi * wsv[f * co + o] + nb * wnv[f * co + o];
                        }
                        assert!((y[(bt * 16 + i) * co + o] - want).abs() < 1e-12);
                    }
                }
            }
            let loss = || {
                let y = conv
                    .forward(x.as_tensor())
                    .map_err(candle_core::Error::wrap)?;
                weighted_sum(&y.tanh()?, 64)
            };
            let err = grad_check(&[&x, &ws, &wn, &b], loss);
            assert!(err < 1e-7, "{backend:?}: relative error {err}");
        }
    }

    #[test]
    fn var_builder_construction_and_bad_input() {
        let mean = neighbour_mean_matrix(&adjacency(9, &grid_faces(3, 3))).unwrap();
        let op = SparseOp::new(&mean, &Device::Cpu).unwrap();
        let vm = candle_nn::VarMap::new();
        let vb = VarBuilder::from_varmap(&vm, DType::F32, &Device::Cpu);
        let conv = SpatialConv::new(op, SpatialConfig::new(9, 5), vb).unwrap();
        assert_eq!(vm.all_vars().len(), 3);
        let y = conv
            .forward(&Tensor::ones((2, 9, 9), DType::F32, &Device::Cpu).unwrap())
            .unwrap();
        assert_eq!(y.dims(), &[2, 9, 5]);
        let wrong = Tensor::ones((2, 9, 4), DType::F32, &Device::Cpu).unwrap();
        assert!(matches!(conv.forward(&wrong), Err(ConvError::Input { .. })));
        let wrong_vm = Tensor::ones((9, 2, 4), DType::F32, &Device::Cpu).unwrap();
        let err = conv
            .forward_vertex_major(&wrong_vm)
            .unwrap_err()
            .to_string();
        assert!(err.contains("expects 9 channels of F32"), "{err}");
        let rect = CsrMatrix::from_triplets(2, 3, &[(0, 1, 1.0)]).unwrap();
        let err = neighbour_mean_matrix(&rect).unwrap_err();
        assert!(
            err.to_string()
                .contains("`adjacency`: must be square, is 2x3"),
            "{err}"
        );
        let w = conv.w_self().clone();
        let wrong_bias = Tensor::zeros(4, DType::F32, &Device::Cpu).unwrap();
        let err = SpatialConv::from_weights(
            conv.neighbour_mean().clone(),
            w.clone(),
            w,
            Some(wrong_bias),
        );
        assert!(err.unwrap_err().to_string().contains("expected [5]"));
    }
}
