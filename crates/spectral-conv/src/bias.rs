//! y = x + b, b along x's last dimension (a layer's bias), as one CPU op.
//!
//! Why not `broadcast_add`: its backward pass fills a zero tensor the size of x, adds the
//! gradient into it and sums that with candle's generic strided reduction (one division per
//! element and reduced dimension), about a tenth of a SpiralNet++ training step. This op's
//! backward sums the gradient's rows directly, in the same order (row after row, from zero), so
//! the bias gradient keeps every bit, and a network trained with it matches one trained with
//! `broadcast_add` exactly.

use crate::custom_op::{contiguous_span, cpu_slice};
use crate::spmm::{Backend, use_kernel};
use candle_core::{CpuStorage, CustomOp2, DType, Layout, Shape, Tensor, WithDType};

const NAME: &str = "bias-add";

/// x + b for b of shape `[C]` and x of shape `[…, C]`: the custom op under
/// [`Backend::Kernel`] on CPU f32/f64 tensors, `broadcast_add` for anything else (the fallback
/// backend, other devices, dtypes or bias shapes).
pub(crate) fn add_bias(x: &Tensor, b: &Tensor, backend: Backend) -> candle_core::Result<Tensor> {
    let c = x.dims().last().copied().unwrap_or(0);
    let fits = use_kernel(backend, x)
        && b.device().is_cpu()
        && b.dims() == [c]
        && c > 0
        && x.dtype() == b.dtype();
    if fits {
        x.contiguous()?.apply_op2(&b.contiguous()?, BiasAdd)
    } else {
        x.broadcast_add(b)
    }
}

struct BiasAdd;

/// Each row of `x` (rows of `b.len()`) plus `b`.
fn add_rows<T: WithDType>(x: &[T], b: &[T]) -> Vec<T> {
    let mut y = Vec::with_capacity(x.len());
    for row in x.chunks_exact(b.len()) {
        y.extend(row.iter().zip(b).map(|(&v, &c)| v + c));
    }
    y
}

/// The sum of `g`'s rows of `c`, each element accumulated from zero in row order: the order of
/// candle's reduction over the leading dimensions, hence its bits.
fn sum_rows<T: WithDType>(g: &[T], c: usize) -> Vec<T> {
    let mut s = vec![T::zero(); c];
    for row in g.chunks_exact(c) {
        for (acc, &v) in s.iter_mut().zip(row) {
            *acc += v;
        }
    }
    s
}

impl CustomOp2 for BiasAdd {
    fn name(&self) -> &'static str {
        NAME
    }

    fn cpu_fwd(
        &self,
        xs: &CpuStorage,
        xl: &Layout,
        bs: &CpuStorage,
        bl: &Layout,
    ) -> candle_core::Result<(CpuStorage, Shape)> {
        let (x0, x1) = contiguous_span(NAME, xl)?;
        let (b0, b1) = contiguous_span(NAME, bl)?;
        let y = match (xs, bs) {
            (CpuStorage::F32(x), CpuStorage::F32(b)) => {
                CpuStorage::F32(add_rows(&x[x0..x1], &b[b0..b1]))
            }
            (CpuStorage::F64(x), CpuStorage::F64(b)) => {
                CpuStorage::F64(add_rows(&x[x0..x1], &b[b0..b1]))
            }
            _ => candle_core::bail!("{NAME}: x and b must both be f32 or both f64"),
        };
        Ok((y, xl.shape().clone()))
    }

    fn bwd(
        &self,
        _x: &Tensor,
        b: &Tensor,
        _y: &Tensor,
        grad: &Tensor,
    ) -> candle_core::Result<(Option<Tensor>, Option<Tensor>)> {
        // A strided gradient is copied in its logical order, the order candle's reduction
        // reads it in.
        let g = grad.contiguous()?;
        let c = b.elem_count();
        let (storage, layout) = g.storage_and_layout();
        let db = match g.dtype() {
            DType::F32 => {
                let sums = sum_rows(cpu_slice::<f32>(NAME, &storage, layout)?, c);
                Tensor::from_vec(sums, c, b.device())?
            }
            DType::F64 => {
                let sums = sum_rows(cpu_slice::<f64>(NAME, &storage, layout)?, c);
                Tensor::from_vec(sums, c, b.device())?
            }
            other => candle_core::bail!("{NAME}: dtype {other:?} not supported"),
        };
        Ok((Some(grad.clone()), Some(db)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_util::random_vec;
    use candle_core::{Device, Var};

    fn bits(t: &Tensor) -> Vec<u64> {
        let t = t.flatten_all().unwrap();
        match t.dtype() {
            DType::F32 => (t.to_vec1::<f32>().unwrap().iter())
                .map(|v| u64::from(v.to_bits()))
                .collect(),
            _ => (t.to_vec1::<f64>().unwrap().iter())
                .map(|v| v.to_bits())
                .collect(),
        }
    }

    /// Values, and the gradients of x and b under a weighted sum, through `add`.
    fn run(
        dtype: DType,
        dims: &[usize],
        transposed_grad: bool,
        add: impl Fn(&Tensor, &Tensor) -> candle_core::Result<Tensor>,
    ) -> [Vec<u64>; 3] {
        let n: usize = dims.iter().product();
        let c = dims[dims.len() - 1];
        let t = |v: Vec<f64>, d: &[usize]| {
            Tensor::from_vec(v, d, &Device::Cpu)
                .unwrap()
                .to_dtype(dtype)
                .unwrap()
        };
        // Values of mixed magnitude, so that the order of the sums shows in the last bits.
        let spread = |v: Vec<f64>| -> Vec<f64> {
            (v.iter().enumerate())
                .map(|(i, x)| x * 10f64.powi((i % 7) as i32 - 3))
                .collect()
        };
        let x = Var::from_tensor(&t(spread(random_vec(n, 1)), dims)).unwrap();
        let b = Var::from_tensor(&t(random_vec(c, 2), &[c])).unwrap();
        let w = t(spread(random_vec(n, 3)), dims);
        let y = add(x.as_tensor(), b.as_tensor()).unwrap();
        // Through a transpose, the gradient arrives strided.
        let loss = if transposed_grad && dims.len() == 3 {
            let wt = w.transpose(0, 1).unwrap().contiguous().unwrap();
            (y.transpose(0, 1).unwrap() * wt)
                .unwrap()
                .sum_all()
                .unwrap()
        } else {
            (&y * &w).unwrap().sum_all().unwrap()
        };
        let grads = loss.backward().unwrap();
        [
            bits(&y),
            bits(grads.get(x.as_tensor()).unwrap()),
            bits(grads.get(b.as_tensor()).unwrap()),
        ]
    }

    #[test]
    fn values_and_gradients_have_the_bits_of_broadcast_add() {
        for dtype in [DType::F32, DType::F64] {
            for dims in [vec![4, 37, 16], vec![50, 3], vec![7]] {
                for transposed in [false, true] {
                    let ours = run(dtype, &dims, transposed, |x, b| {
                        add_bias(x, b, Backend::Kernel)
                    });
                    let theirs = run(dtype, &dims, transposed, |x, b| x.broadcast_add(b));
                    let case = format!("{dtype:?} {dims:?} transposed {transposed}");
                    assert_eq!(ours[0], theirs[0], "{case}: values");
                    assert_eq!(ours[1], theirs[1], "{case}: dx");
                    assert_eq!(ours[2], theirs[2], "{case}: db");
                }
            }
        }
    }

    #[test]
    fn the_bias_gradient_is_the_sum_over_rows() {
        let g: Vec<f64> = (0..12).map(f64::from).collect();
        assert_eq!(sum_rows(&g, 4), vec![12.0, 15.0, 18.0, 21.0]);
        assert_eq!(
            add_rows(&[1.0, 2.0, 3.0, 4.0], &[10.0, 20.0]),
            vec![11.0, 22.0, 13.0, 24.0]
        );
    }

    #[test]
    fn other_shapes_fall_back_to_broadcast_add() {
        let x = Tensor::ones((2, 3), DType::F32, &Device::Cpu).unwrap();
        let b = Tensor::new(&[[1f32, 2.0, 3.0]], &Device::Cpu).unwrap();
        let y = add_bias(&x, &b, Backend::Kernel).unwrap();
        assert_eq!(y.to_vec2::<f32>().unwrap(), vec![vec![2.0, 3.0, 4.0]; 2]);
        // A bias that fits no dimension is candle's shape error, not a panic.
        let wrong = Tensor::new(&[1f32, 2.0], &Device::Cpu).unwrap();
        assert!(add_bias(&x, &wrong, Backend::Kernel).is_err());
    }
}
