//! [`SpiralConv`]: SpiralNet++'s convolution (Gong et al. 2019). Each vertex reads its spiral,
//! a fixed sequence of S vertices starting with itself, and one dense layer maps the S·C_in
//! values to C_out: y_v = W ᵀ [x_{s_v,0}, …, x_{s_v,S−1}] + b, with W `[S·C_in, C_out]` in
//! SpiralNet++'s order (row s·C_in + c reads channel c of the spiral's s-th vertex).
//!
//! On the CPU it is one custom op that never holds the gathered `[B·V, S·C_in]` matrix
//! (`spiral_kernel`); written with candle ops ([`Backend::Fallback`], any device) that matrix
//! is made, kept for the backward pass, and its gradient made again: S times the input, three
//! times over, each step.

use crate::custom_op::cpu_slice;
use crate::error::{ConvError, Result};
use crate::kernel::Real;
use crate::spiral_kernel::{self, SpiralDims};
use crate::spmm::{Backend, use_kernel};
use candle_core::{CpuStorage, CustomOp2, DType, Layout, Shape, Tensor};
use candle_nn::{Init, VarBuilder};
use std::sync::Arc;

/// The spirals of one mesh: vertex v's at `indices[v·S .. v·S + S]`.
#[derive(Debug)]
struct Spirals {
    indices: Arc<Vec<u32>>,
    /// The same indices as a `[V·S]` u32 tensor on the weights' device (the fallback's).
    tensor: Tensor,
    vertices: usize,
    length: usize,
}

/// A spiral convolution on one mesh (see the module documentation). Cheap to clone.
#[derive(Debug, Clone)]
pub struct SpiralConv {
    spirals: Arc<Spirals>,
    weight: Tensor,
    bias: Option<Tensor>,
    backend: Backend,
}

impl SpiralConv {
    /// A layer of `c_in → c_out` channels on `spirals` (S = `length` indices per vertex, as
    /// `mesh_hierarchy::spirals` makes them), with `weight` `[S·c_in, c_out]` Glorot-uniform
    /// (SpiralNet++'s initialisation) and a zero `bias` from `vb`.
    pub fn new(
        spirals: &[u32],
        length: usize,
        (c_in, c_out): (usize, usize),
        vb: VarBuilder,
    ) -> Result<Self> {
        if c_in == 0 || c_out == 0 || length == 0 {
            return Err(ConvError::argument(
                "SpiralConv::new",
                "c_in/c_out/length",
                format!("must be positive; got {c_in}, {c_out}, {length}"),
            ));
        }
        let fan_in = length * c_in;
        let bound = (6.0 / (fan_in + c_out) as f64).sqrt();
        let init = Init::Uniform {
            lo: -bound,
            up: bound,
        };
        let weight = vb.get_with_hints((fan_in, c_out), "weight", init)?;
        let bias = vb.get_with_hints(c_out, "bias", Init::Const(0.0))?;
        Self::from_weights(spirals, length, weight, Some(bias))
    }

    /// A layer with given `weight` `[S·C_in, C_out]` and optional `bias` `[C_out]` on
    /// `spirals` (`length` = S indices per vertex, every index a vertex of the mesh).
    pub fn from_weights(
        spirals: &[u32],
        length: usize,
        weight: Tensor,
        bias: Option<Tensor>,
    ) -> Result<Self> {
        const OP: &str = "SpiralConv::from_weights";
        if length == 0 || spirals.is_empty() || !spirals.len().is_multiple_of(length) {
            return Err(ConvError::argument(
                OP,
                "spirals",
                format!(
                    "{} indices do not make spirals of length {length}",
                    spirals.len()
                ),
            ));
        }
        let vertices = spirals.len() / length;
        if let Some(&bad) = spirals.iter().find(|&&u| u as usize >= vertices) {
            return Err(ConvError::argument(
                OP,
                "spirals",
                format!("index {bad} out of range for {vertices} vertices"),
            ));
        }
        let (rows, c_out) = weight.dims2().map_err(|_| {
            ConvError::argument(
                OP,
                "weight",
                format!("shape {:?}; expected [S·C_in, C_out]", weight.dims()),
            )
        })?;
        if !rows.is_multiple_of(length) {
            return Err(ConvError::argument(
                OP,
                "weight",
                format!("{rows} rows are not a multiple of the spiral length {length}"),
            ));
        }
        crate::check::bias(OP, bias.as_ref(), c_out)?;
        let tensor = Tensor::from_vec(spirals.to_vec(), spirals.len(), weight.device())?;
        Ok(Self {
            spirals: Arc::new(Spirals {
                indices: Arc::new(spirals.to_vec()),
                tensor,
                vertices,
                length,
            }),
            weight,
            bias,
            backend: Backend::Kernel,
        })
    }

    /// The same layer on another implementation (the fallback is the reference the kernel is
    /// tested against, and what runs off the CPU anyway).
    pub fn with_backend(mut self, backend: Backend) -> Self {
        self.backend = backend;
        self
    }

    pub fn weight(&self) -> &Tensor {
        &self.weight
    }

    pub fn bias(&self) -> Option<&Tensor> {
        self.bias.as_ref()
    }

    /// S, the vertices per spiral.
    pub fn length(&self) -> usize {
        self.spirals.length
    }

    /// The mesh's vertex count V.
    pub fn vertices(&self) -> usize {
        self.spirals.vertices
    }

    pub fn c_in(&self) -> usize {
        self.weight.dims()[0] / self.spirals.length
    }

    pub fn c_out(&self) -> usize {
        self.weight.dims()[1]
    }

    /// y `[B, V, C_out]` from x `[B, V, C_in]` (or `[V, C_in]` → `[V, C_out]`).
    pub fn forward(&self, x: &Tensor) -> Result<Tensor> {
        const OP: &str = "SpiralConv::forward";
        let squeeze = x.rank() == 2;
        let x3 = if squeeze { x.unsqueeze(0)? } else { x.clone() };
        let (v, c_in) = (self.vertices(), self.c_in());
        let fits = x3.rank() == 3
            && x3.dim(1)? == v
            && x3.dim(2)? == c_in
            && x.dtype() == self.weight.dtype();
        if !fits {
            return Err(ConvError::input(
                OP,
                format!(
                    "input {:?} of {:?}; the layer expects [B, {v}, {c_in}] of {:?}",
                    x.dims(),
                    x.dtype(),
                    self.weight.dtype()
                ),
            ));
        }
        let y = if use_kernel(self.backend, &x3) && self.weight.device().is_cpu() {
            let op = SpiralOp {
                spirals: self.spirals.indices.clone(),
                length: self.length(),
            };
            x3.contiguous()?.apply_op2(&self.weight.contiguous()?, op)?
        } else {
            self.gathered_matmul(&x3)?
        };
        let y = match &self.bias {
            Some(b) => crate::bias::add_bias(&y, b, self.backend)?,
            None => y,
        };
        Ok(if squeeze { y.squeeze(0)? } else { y })
    }

    /// The fallback: x gathered to `[B, V·S, C]`, which is `[B·V, S·C]` in SpiralNet++'s
    /// order without a transpose, times W.
    fn gathered_matmul(&self, x: &Tensor) -> Result<Tensor> {
        let (b, v, c) = x.dims3()?;
        let gathered = x
            .contiguous()?
            .index_select(&self.spirals.tensor, 1)?
            .reshape((b * v, self.length() * c))?;
        Ok(gathered
            .matmul(&self.weight)?
            .reshape((b, v, self.c_out()))?)
    }
}

/// The custom op: `[B, V, C_in]`, `[S·C_in, C_out]` → `[B, V, C_out]`, without bias.
struct SpiralOp {
    spirals: Arc<Vec<u32>>,
    length: usize,
}

const NAME: &str = "spiral-conv";

impl SpiralOp {
    fn dims(&self, x: &[usize], w: &[usize]) -> candle_core::Result<SpiralDims> {
        match (x, w) {
            (&[batch, vertices, c_in], &[rows, c_out]) if rows == self.length * c_in => {
                Ok(SpiralDims {
                    batch,
                    vertices,
                    c_in,
                    length: self.length,
                    c_out,
                })
            }
            _ => candle_core::bail!("{NAME}: shapes {x:?} and {w:?} do not fit"),
        }
    }

    fn run<T: Real + candle_core::WithDType>(
        &self,
        x: &[T],
        w: &[T],
        d: SpiralDims,
    ) -> (Vec<T>, Shape) {
        let y = spiral_kernel::forward(x, &self.spirals, w, d);
        (y, Shape::from((d.batch, d.vertices, d.c_out)))
    }

    fn backward<T: Real + candle_core::WithDType>(
        &self,
        (x, w, g): (&Tensor, &Tensor, &Tensor),
        d: SpiralDims,
    ) -> candle_core::Result<(Option<Tensor>, Option<Tensor>)> {
        let need = (x.track_op(), w.track_op());
        let (xs, _) = x.storage_and_layout();
        let (ws, _) = w.storage_and_layout();
        let (gs, _) = g.storage_and_layout();
        let grads = spiral_kernel::backward(
            cpu_slice::<T>(NAME, &xs, x.layout())?,
            &self.spirals,
            cpu_slice::<T>(NAME, &ws, w.layout())?,
            cpu_slice::<T>(NAME, &gs, g.layout())?,
            d,
            need,
        );
        let dx = grads.dx.map(|v| Tensor::from_vec(v, x.dims(), x.device()));
        let dw = grads.dw.map(|v| Tensor::from_vec(v, w.dims(), w.device()));
        Ok((dx.transpose()?, dw.transpose()?))
    }
}

impl CustomOp2 for SpiralOp {
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
        let d = self.dims(xl.dims(), wl.dims())?;
        let (x0, x1) = crate::custom_op::contiguous_span(NAME, xl)?;
        let (w0, w1) = crate::custom_op::contiguous_span(NAME, wl)?;
        Ok(match (xs, ws) {
            (CpuStorage::F32(x), CpuStorage::F32(w)) => {
                let (y, s) = self.run(&x[x0..x1], &w[w0..w1], d);
                (CpuStorage::F32(y), s)
            }
            (CpuStorage::F64(x), CpuStorage::F64(w)) => {
                let (y, s) = self.run(&x[x0..x1], &w[w0..w1], d);
                (CpuStorage::F64(y), s)
            }
            _ => candle_core::bail!("{NAME}: x and w must both be f32 or both f64"),
        })
    }

    fn bwd(
        &self,
        x: &Tensor,
        w: &Tensor,
        _y: &Tensor,
        grad: &Tensor,
    ) -> candle_core::Result<(Option<Tensor>, Option<Tensor>)> {
        let d = self.dims(x.dims(), w.dims())?;
        // Gradients can arrive strided (zero strides from a broadcast): make them dense.
        let (x, w, g) = (x.contiguous()?, w.contiguous()?, grad.contiguous()?);
        match x.dtype() {
            DType::F32 => self.backward::<f32>((&x, &w, &g), d),
            DType::F64 => self.backward::<f64>((&x, &w, &g), d),
            other => candle_core::bail!("{NAME}: dtype {other:?} not supported"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_util::*;
    use candle_core::{Device, Var};

    /// Spirals on a 5 × 6 grid: each vertex, then neighbours by index distance (any fixed
    /// sequence of vertices is a valid spiral for the op).
    fn grid_spirals(v: usize, length: usize) -> Vec<u32> {
        (0..v * length)
            .map(|i| {
                let (vertex, s) = (i / length, i % length);
                ((vertex + s * 5 + s / 2) % v) as u32
            })
            .collect()
    }

    #[test]
    fn kernel_and_fallback_agree_and_gradients_match_finite_differences() {
        let (v, length, c_in, c_out) = (30, 4, 3, 2);
        let spirals = grid_spirals(v, length);
        let w = Var::from_tensor(&tensor(random_vec(length * c_in * c_out, 70), &[12, 2])).unwrap();
        let b = Var::from_tensor(&tensor(random_vec(c_out, 71), &[c_out])).unwrap();
        let x = Var::from_tensor(&tensor(random_vec(2 * v * c_in, 72), &[2, v, c_in])).unwrap();
        let conv = SpiralConv::from_weights(
            &spirals,
            length,
            w.as_tensor().clone(),
            Some(b.as_tensor().clone()),
        )
        .unwrap();
        let fallback = conv.clone().with_backend(Backend::Fallback);
        // The definition, in f64.
        let (xv, wv, bv) = (to_vec(&x), to_vec(&w), to_vec(&b));
        let y = to_vec(&conv.forward(x.as_tensor()).unwrap());
        for bt in 0..2 {
            for i in 0..v {
                for o in 0..c_out {
                    let mut want = bv[o];
                    for s in 0..length {
                        let u = spirals[i * length + s] as usize;
                        for c in 0..c_in {
                            want += xv[(bt * v + u) * c_in + c] * wv[(s * c_in + c) * c_out + o];
                        }
                    }
                    assert!((y[(bt * v + i) * c_out + o] - want).abs() < 1e-12);
                }
            }
        }
        let yf = fallback.forward(x.as_tensor()).unwrap();
        assert!(max_abs_diff(&conv.forward(x.as_tensor()).unwrap(), &yf) < 1e-12);
        for layer in [&conv, &fallback] {
            let loss = || {
                let y = layer
                    .forward(x.as_tensor())
                    .map_err(candle_core::Error::wrap)?;
                weighted_sum(&y.tanh()?, 73)
            };
            let err = grad_check(&[&x, &w, &b], loss);
            assert!(err < 1e-7, "{:?}: relative error {err}", layer.backend);
        }
        // An unbatched input, f32 kernel against f32 fallback.
        let x32 = x.as_tensor().get(0).unwrap().to_dtype(DType::F32).unwrap();
        let w32 = w.as_tensor().to_dtype(DType::F32).unwrap();
        let conv32 = SpiralConv::from_weights(&spirals, length, w32, None).unwrap();
        let y32 = conv32.forward(&x32).unwrap();
        assert_eq!(y32.dims(), &[v, c_out]);
        let y32f = conv32
            .with_backend(Backend::Fallback)
            .forward(&x32)
            .unwrap();
        assert!(max_abs_diff(&y32, &y32f) < 1e-5);
    }

    #[test]
    fn var_builder_construction_and_bad_input() {
        let spirals = grid_spirals(30, 4);
        let vm = candle_nn::VarMap::new();
        let vb = VarBuilder::from_varmap(&vm, DType::F32, &Device::Cpu);
        let conv = SpiralConv::new(&spirals, 4, (3, 5), vb).unwrap();
        assert_eq!(vm.all_vars().len(), 2);
        assert_eq!((conv.c_in(), conv.c_out(), conv.vertices()), (3, 5, 30));
        let wrong = Tensor::ones((2, 30, 4), DType::F32, &Device::Cpu).unwrap();
        let err = conv.forward(&wrong).unwrap_err().to_string();
        assert!(err.contains("expects [B, 30, 3] of F32"), "{err}");
        let w = conv.weight().clone();
        let err = SpiralConv::from_weights(&[0, 1, 1, 40], 2, w.clone(), None).unwrap_err();
        assert!(
            err.to_string()
                .contains("index 40 out of range for 2 vertices")
        );
        let err = SpiralConv::from_weights(&[0, 1, 2], 2, w.clone(), None).unwrap_err();
        assert!(err.to_string().contains("3 indices"), "{err}");
        let err = SpiralConv::from_weights(&[0, 1, 1, 0, 0, 1, 1, 0, 0, 1], 5, w, None);
        let err = err.unwrap_err();
        assert!(err.to_string().contains("not a multiple"), "{err}");
    }
}
