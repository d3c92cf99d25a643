//! ELU (SpiralNet++'s activation) as one CPU op each way. candle's own ELU makes nine tensors
//! the size of its input in the backward pass (masks, their conversions, sums): a quarter of a
//! SpiralNet++ step on horse-gallop. This computes candle's formulas element by element, so
//! the same bits: y = x for x ≥ +0, α(eˣ − 1) otherwise; ∂y/∂x = 1 for x > 0, y + α otherwise.

use crate::error::Result;
use candle_core::backend::BackendStorage;
use candle_core::{CpuStorage, CustomOp1, DType, Layout, Shape, Tensor};

/// elu(x) with parameter `alpha`, differentiable; candle's own op off the CPU.
pub(crate) fn elu(x: &Tensor, alpha: f64) -> Result<Tensor> {
    let fused = x.device().is_cpu() && matches!(x.dtype(), DType::F32 | DType::F64);
    Ok(match fused {
        true => x.contiguous()?.apply_op1(Elu { alpha })?,
        false => x.elu(alpha)?,
    })
}

struct Elu {
    alpha: f64,
}

/// `[lo, hi)` of a contiguous layout.
fn span(layout: &Layout) -> candle_core::Result<(usize, usize)> {
    layout
        .contiguous_offsets()
        .ok_or_else(|| candle_core::Error::Msg("elu: input is not contiguous".into()))
}

impl CustomOp1 for Elu {
    fn name(&self) -> &'static str {
        "elu"
    }

    fn cpu_fwd(&self, s: &CpuStorage, l: &Layout) -> candle_core::Result<(CpuStorage, Shape)> {
        let (lo, hi) = span(l)?;
        let out = match s {
            CpuStorage::F32(x) => {
                let a = self.alpha as f32;
                let f = |v: f32| {
                    if v.is_sign_positive() {
                        v
                    } else {
                        (v.exp() - 1.0) * a
                    }
                };
                CpuStorage::F32(x[lo..hi].iter().map(|&v| f(v)).collect())
            }
            CpuStorage::F64(x) => {
                let a = self.alpha;
                let f = |v: f64| {
                    if v.is_sign_positive() {
                        v
                    } else {
                        (v.exp() - 1.0) * a
                    }
                };
                CpuStorage::F64(x[lo..hi].iter().map(|&v| f(v)).collect())
            }
            other => candle_core::bail!("elu: dtype {:?} not supported", other.dtype()),
        };
        Ok((out, l.shape().clone()))
    }

    fn bwd(&self, x: &Tensor, y: &Tensor, grad: &Tensor) -> candle_core::Result<Option<Tensor>> {
        let (x, y, g) = (x.contiguous()?, y.contiguous()?, grad.contiguous()?);
        let (xs, xl) = x.storage_and_layout();
        let (ys, yl) = y.storage_and_layout();
        let (gs, gl) = g.storage_and_layout();
        let ((x0, x1), (y0, y1), (g0, g1)) = (span(xl)?, span(yl)?, span(gl)?);
        use candle_core::Storage::Cpu;
        let (dims, device) = (x.dims(), x.device());
        let dx = match (&*xs, &*ys, &*gs) {
            (Cpu(CpuStorage::F32(x)), Cpu(CpuStorage::F32(y)), Cpu(CpuStorage::F32(g))) => {
                let a = self.alpha as f32;
                let d: Vec<f32> = (x[x0..x1].iter().zip(&y[y0..y1]).zip(&g[g0..g1]))
                    .map(|((&x, &y), &g)| g * if x > 0.0 { 1.0 } else { y + a })
                    .collect();
                Tensor::from_vec(d, dims, device)?
            }
            (Cpu(CpuStorage::F64(x)), Cpu(CpuStorage::F64(y)), Cpu(CpuStorage::F64(g))) => {
                let a = self.alpha;
                let d: Vec<f64> = (x[x0..x1].iter().zip(&y[y0..y1]).zip(&g[g0..g1]))
                    .map(|((&x, &y), &g)| g * if x > 0.0 { 1.0 } else { y + a })
                    .collect();
                Tensor::from_vec(d, dims, device)?
            }
            _ => candle_core::bail!("elu: x, y and the gradient must be CPU tensors of one dtype"),
        };
        Ok(Some(dx))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::{Device, Var};

    /// Values and gradients have candle's bits, including at ±0, for large negatives, NaN.
    #[test]
    fn forward_and_gradient_have_candles_bits() {
        let mut values: Vec<f64> = (0..5000)
            .map(|i| ((i as f64) * 0.37).sin() * 10f64.powi(i % 7 - 3))
            .collect();
        values.extend([0.0, -0.0, -80.0, 80.0, 1e-30, -1e-30, f64::NAN]);
        let n = values.len();
        let r: Vec<f64> = (0..n).map(|i| ((i as f64) * 1.3).cos()).collect();
        for dtype in [DType::F32, DType::F64] {
            let x = Var::from_tensor(
                &Tensor::new(values.as_slice(), &Device::Cpu)
                    .unwrap()
                    .to_dtype(dtype)
                    .unwrap(),
            )
            .unwrap();
            let weights = Tensor::new(r.as_slice(), &Device::Cpu)
                .unwrap()
                .to_dtype(dtype)
                .unwrap();
            let run = |fused: bool| {
                let y = match fused {
                    true => elu(x.as_tensor(), 0.7).unwrap(),
                    false => x.as_tensor().elu(0.7).unwrap(),
                };
                let grads = (&y * &weights)
                    .unwrap()
                    .sum_all()
                    .unwrap()
                    .backward()
                    .unwrap();
                let bits = |t: &Tensor| -> Vec<u64> {
                    let v = t.to_dtype(DType::F64).unwrap().to_vec1::<f64>().unwrap();
                    v.iter().map(|a| a.to_bits()).collect()
                };
                (bits(&y), bits(grads.get(&x).unwrap()))
            };
            assert!(run(true) == run(false), "{dtype:?}: bits differ");
        }
    }
}
