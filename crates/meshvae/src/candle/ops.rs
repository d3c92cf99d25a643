//! Fused CPU ops for the training step's element-wise work, which candle runs one
//! single-threaded pass (and one allocation) per elementary op: tanh, batch norm and the L2 term
//! (Adam's in-place update is in `train/adam/kernels.rs`, on the helpers here). Each is a rayon loop over f32/f64 storage; reductions are summed per
//! fixed chunk and then in chunk order, so results do not depend on thread scheduling (a resumed
//! run must repeat an uninterrupted one bit for bit). Off the CPU, or for other dtypes, callers
//! use the equivalent candle ops (`*_reference` in the tests are those).

use candle_core::{CpuStorage, CustomOp1, CustomOp3, Layout, Shape};
use candle_core::{Result, Tensor, bail};
use rayon::prelude::*;

/// Rows (or elements) per parallel chunk.
pub(crate) const CHUNK: usize = 1 << 14;

/// f32 or f64.
pub(crate) trait Real:
    Copy
    + Send
    + Sync
    + 'static
    + std::ops::Add<Output = Self>
    + std::ops::Sub<Output = Self>
    + std::ops::Mul<Output = Self>
    + std::ops::Div<Output = Self>
{
    /// candle's name for this type.
    const DTYPE_OF: candle_core::DType;
    fn to_f64(self) -> f64;
    fn of(x: f64) -> Self;
    fn tanh(self) -> Self;
    fn sqrt(self) -> Self;
    /// The values of a CPU storage of this type.
    fn cpu(s: &CpuStorage) -> Option<&[Self]>;
    fn cpu_mut(s: &mut CpuStorage) -> Option<&mut [Self]>;
}

impl Real for f32 {
    const DTYPE_OF: candle_core::DType = candle_core::DType::F32;
    fn cpu(s: &CpuStorage) -> Option<&[Self]> {
        match s {
            CpuStorage::F32(v) => Some(v),
            _ => None,
        }
    }
    fn cpu_mut(s: &mut CpuStorage) -> Option<&mut [Self]> {
        match s {
            CpuStorage::F32(v) => Some(v),
            _ => None,
        }
    }
    fn to_f64(self) -> f64 {
        self as f64
    }
    fn of(x: f64) -> Self {
        x as f32
    }
    #[inline(always)]
    fn tanh(self) -> Self {
        fast_tanh(self)
    }
    fn sqrt(self) -> Self {
        f32::sqrt(self)
    }
}

impl Real for f64 {
    const DTYPE_OF: candle_core::DType = candle_core::DType::F64;
    fn cpu(s: &CpuStorage) -> Option<&[Self]> {
        match s {
            CpuStorage::F64(v) => Some(v),
            _ => None,
        }
    }
    fn cpu_mut(s: &mut CpuStorage) -> Option<&mut [Self]> {
        match s {
            CpuStorage::F64(v) => Some(v),
            _ => None,
        }
    }
    fn to_f64(self) -> f64 {
        self
    }
    fn of(x: f64) -> Self {
        x
    }
    fn tanh(self) -> Self {
        f64::tanh(self)
    }
    fn sqrt(self) -> Self {
        f64::sqrt(self)
    }
}

/// tanh in f32 without libm (whose `tanhf` costs ~20 ns, more than a whole graph convolution
/// per element): tanh|x| = −m/(2 + m) with m = e^(−2|x|) − 1, and m from 2ⁿ·e^r, |r| ≤ ln2/2, as
/// (2ⁿ − 1) + 2ⁿ·(e^r − 1) with a degree-7 Taylor series of e^r − 1. Near 0 (n = 0) that is the
/// series alone, accurate to the last bits, so no separate small-argument formula is needed.
/// Relative error ≲ 5e-7 (tested against f64).
#[inline(always)]
fn fast_tanh(x: f32) -> f32 {
    // Branch-free, so the loop vectorises and mixed-sign, mixed-size inputs (batch norm's
    // output) cost no mispredictions. From 9 on, 1 − tanh = 3e-8 is below half an ulp of 1:
    // clamp (NaN becomes 9 here and is restored below).
    let a = x.abs().min(9.0);
    let y = -2.0 * a;
    // y ≤ 0, so truncating y/ln2 − ½ rounds to nearest; an integer conversion (SSE2) instead
    // of `round`, which is a libm call on baseline x86-64 and stops vectorisation. Unchecked:
    // `as i32` saturates and maps NaN to 0, which the compiler did lane by lane with scalar
    // compares (half of a tanh's time); the value is never NaN nor out of range.
    // SAFETY: a ∈ [0, 9] (NaN became 9), so y·log2(e) − ½ ∈ [−26.5, −0.5]: finite, and its
    // truncation fits an i32.
    let k: i32 = unsafe { (y * std::f32::consts::LOG2_E - 0.5).to_int_unchecked() };
    let n = k as f32;
    // r = y − n·ln2, with ln2 split for accuracy.
    let r = (y - n * 0.693_145_75) - n * 1.428_606_8e-6;
    let q = r
        * (1.0
            + r * (0.5
                + r * (1.0 / 6.0
                    + r * (1.0 / 24.0 + r * (1.0 / 120.0 + r * (1.0 / 720.0 + r / 5040.0))))));
    let s = f32::from_bits(((k + 127) as u32) << 23);
    // 2ⁿ − 1 is exact (n ≤ 0).
    let m = s * q + (s - 1.0);
    let out = (-m / (2.0 + m)).copysign(x);
    if x.is_nan() { x } else { out }
}

/// The contiguous slice a layout covers, or an error naming the op.
pub(crate) fn span<'a, T>(op: &str, data: &'a [T], l: &Layout) -> Result<&'a [T]> {
    match l.contiguous_offsets() {
        Some((lo, hi)) => Ok(&data[lo..hi]),
        None => bail!("{op}: input is not contiguous"),
    }
}

pub(crate) fn span_mut<'a, T>(op: &str, data: &'a mut [T], l: &Layout) -> Result<&'a mut [T]> {
    match l.contiguous_offsets() {
        Some((lo, hi)) => Ok(&mut data[lo..hi]),
        None => bail!("{op}: input is not contiguous"),
    }
}

/// Whether the fused ops can run on `t` (CPU, f32 or f64).
pub(crate) fn fusable(t: &Tensor) -> bool {
    t.device().is_cpu() && matches!(t.dtype(), candle_core::DType::F32 | candle_core::DType::F64)
}

// ---------------------------------------------------------------------------------------------
// tanh

/// y = tanh(x), backward g·(1 − y²).
pub(crate) fn tanh(x: &Tensor) -> Result<Tensor> {
    if fusable(x) {
        x.contiguous()?.apply_op1(Tanh)
    } else {
        x.tanh()
    }
}

struct Tanh;

impl CustomOp1 for Tanh {
    fn name(&self) -> &'static str {
        "fused-tanh"
    }

    fn cpu_fwd(&self, s: &CpuStorage, l: &Layout) -> Result<(CpuStorage, Shape)> {
        fn run<T: Real>(x: &[T]) -> Vec<T> {
            let mut y = x.to_vec();
            y.par_chunks_mut(CHUNK)
                .for_each(|c| c.iter_mut().for_each(|v| *v = v.tanh()));
            y
        }
        let out = match s {
            CpuStorage::F32(x) => CpuStorage::F32(run(span("tanh", x, l)?)),
            CpuStorage::F64(x) => CpuStorage::F64(run(span("tanh", x, l)?)),
            _ => bail!("fused-tanh: f32 or f64 only"),
        };
        Ok((out, l.shape().clone()))
    }

    fn bwd(&self, _arg: &Tensor, res: &Tensor, grad: &Tensor) -> Result<Option<Tensor>> {
        Ok(Some(
            grad.contiguous()?
                .apply_op1_no_bwd(&TanhGrad { y: res.clone() })?,
        ))
    }
}

/// g ↦ g·(1 − y²) for a saved output y.
struct TanhGrad {
    y: Tensor,
}

impl CustomOp1 for TanhGrad {
    fn name(&self) -> &'static str {
        "fused-tanh-grad"
    }

    fn cpu_fwd(&self, s: &CpuStorage, l: &Layout) -> Result<(CpuStorage, Shape)> {
        fn run<T: Real>(g: &[T], y: &[T]) -> Vec<T> {
            let mut out = g.to_vec();
            out.par_chunks_mut(CHUNK)
                .zip(y.par_chunks(CHUNK))
                .for_each(|(o, y)| {
                    for (o, &y) in o.iter_mut().zip(y) {
                        let (gv, yv) = (o.to_f64(), y.to_f64());
                        *o = T::of(gv * (1.0 - yv * yv));
                    }
                });
            out
        }
        let (ys, yl) = self.y.storage_and_layout();
        let out = match (s, &*ys) {
            (CpuStorage::F32(g), candle_core::Storage::Cpu(CpuStorage::F32(y))) => {
                CpuStorage::F32(run(span("tanh-grad", g, l)?, span("tanh-grad", y, yl)?))
            }
            (CpuStorage::F64(g), candle_core::Storage::Cpu(CpuStorage::F64(y))) => {
                CpuStorage::F64(run(span("tanh-grad", g, l)?, span("tanh-grad", y, yl)?))
            }
            _ => bail!("fused-tanh-grad: dtype mismatch"),
        };
        if yl.shape() != l.shape() {
            bail!(
                "fused-tanh-grad: shapes {:?} and {:?}",
                yl.shape(),
                l.shape()
            );
        }
        Ok((out, l.shape().clone()))
    }
}

// ---------------------------------------------------------------------------------------------
// batch norm

/// Per-channel sums of f(row value, channel) over x `[N, C]`, chunk partials added in order.
fn channel_sums<T: Real>(x: &[T], c: usize, f: impl Fn(f64, usize) -> f64 + Sync) -> Vec<f64> {
    let partial: Vec<Vec<f64>> = x
        .par_chunks(CHUNK * c)
        .map(|rows| {
            let mut s = vec![0.0; c];
            for row in rows.chunks_exact(c) {
                for (j, &v) in row.iter().enumerate() {
                    s[j] += f(v.to_f64(), j);
                }
            }
            s
        })
        .collect();
    let mut s = vec![0.0; c];
    for p in partial {
        s.iter_mut().zip(p).for_each(|(a, b)| *a += b);
    }
    s
}

/// Per-channel mean and biased variance of x `[N, C]` (CPU), in f64 and two passes (no
/// cancellation when the mean is large).
pub(crate) fn channel_moments(x: &Tensor) -> Result<(Vec<f64>, Vec<f64>)> {
    fn run<T: Real>(x: &[T], c: usize) -> (Vec<f64>, Vec<f64>) {
        let n = (x.len() / c).max(1) as f64;
        let mean: Vec<f64> = channel_sums(x, c, |v, _| v).iter().map(|s| s / n).collect();
        let var = channel_sums(x, c, |v, j| (v - mean[j]) * (v - mean[j]))
            .iter()
            .map(|s| s / n)
            .collect();
        (mean, var)
    }
    let (_, c) = x.dims2()?;
    let x = x.contiguous()?;
    let (st, l) = x.storage_and_layout();
    Ok(match &*st {
        candle_core::Storage::Cpu(CpuStorage::F32(v)) => run(span("moments", v, l)?, c),
        candle_core::Storage::Cpu(CpuStorage::F64(v)) => run(span("moments", v, l)?, c),
        _ => bail!("channel_moments: CPU f32/f64 only"),
    })
}

/// y = γ (x − m)·s + β for x `[N, C]`, with per-channel m and s = 1/√(v + ε) given, followed
/// by tanh when `tanh` is set (fused, so the normalised tensor is never stored: one tensor of
/// the activations' size less per block in the autograd graph).
/// `batch_stats`: m and v are x's own moments, so the backward pass differentiates through
/// them (train mode); otherwise they are constants (eval mode).
pub(crate) fn batch_norm(
    x: &Tensor,
    gamma: &Tensor,
    beta: &Tensor,
    stats: (Vec<f64>, Vec<f64>),
    batch_stats: bool,
    tanh: bool,
) -> Result<Tensor> {
    let (mean, inv_std) = stats;
    x.contiguous()?.apply_op3(
        &gamma.contiguous()?,
        &beta.contiguous()?,
        BatchNormOp {
            mean,
            inv_std,
            batch_stats,
            tanh,
        },
    )
}

struct BatchNormOp {
    mean: Vec<f64>,
    inv_std: Vec<f64>,
    batch_stats: bool,
    tanh: bool,
}

impl BatchNormOp {
    fn forward<T: Real>(&self, x: &[T], gamma: &[T], beta: &[T]) -> Vec<T> {
        let c = self.mean.len();
        let scale: Vec<f64> = (0..c)
            .map(|j| gamma[j].to_f64() * self.inv_std[j])
            .collect();
        let mut y = x.to_vec();
        y.par_chunks_mut(CHUNK * c).for_each(|rows| {
            for row in rows.chunks_exact_mut(c) {
                for (j, v) in row.iter_mut().enumerate() {
                    *v = T::of((v.to_f64() - self.mean[j]) * scale[j] + beta[j].to_f64());
                }
                if self.tanh {
                    row.iter_mut().for_each(|v| *v = v.tanh());
                }
            }
        });
        y
    }

    /// (dx, dγ, dβ) from x, γ, the output y and its gradient g.
    fn backward<T: Real>(
        &self,
        x: &[T],
        gamma: &[T],
        y: &[T],
        g: &[T],
    ) -> (Vec<T>, Vec<T>, Vec<T>) {
        // Through tanh first: the gradient at the batch norm's output is g·(1 − y²). It is
        // written into the buffer that becomes dx.
        let mut dx = g.to_vec();
        if self.tanh {
            dx.par_chunks_mut(CHUNK)
                .zip(y.par_chunks(CHUNK))
                .for_each(|(d, y)| {
                    for (d, &y) in d.iter_mut().zip(y) {
                        *d = *d * (T::of(1.0) - y * y);
                    }
                });
        }
        let g = &dx;
        let c = self.mean.len();
        let n = x.len() / c;
        // Σ g and Σ g·x̂ per channel, in chunk order.
        let partial: Vec<Vec<f64>> = x
            .par_chunks(CHUNK * c)
            .zip(g.par_chunks(CHUNK * c))
            .map(|(xr, gr)| {
                let mut s = vec![0.0; 2 * c];
                for (xrow, grow) in xr.chunks_exact(c).zip(gr.chunks_exact(c)) {
                    for j in 0..c {
                        let gv = grow[j].to_f64();
                        let xh = (xrow[j].to_f64() - self.mean[j]) * self.inv_std[j];
                        s[j] += gv;
                        s[c + j] += gv * xh;
                    }
                }
                s
            })
            .collect();
        let mut s = vec![0.0; 2 * c];
        for p in partial {
            s.iter_mut().zip(p).for_each(|(a, b)| *a += b);
        }
        let (dbeta, dgamma) = (&s[..c], &s[c..]);
        let scale: Vec<f64> = (0..c)
            .map(|j| gamma[j].to_f64() * self.inv_std[j])
            .collect();
        dx.par_chunks_mut(CHUNK * c)
            .zip(x.par_chunks(CHUNK * c))
            .for_each(|(dr, xr)| {
                for (drow, xrow) in dr.chunks_exact_mut(c).zip(xr.chunks_exact(c)) {
                    for j in 0..c {
                        let gv = drow[j].to_f64();
                        drow[j] = T::of(if self.batch_stats {
                            let xh = (xrow[j].to_f64() - self.mean[j]) * self.inv_std[j];
                            scale[j] * (gv - dbeta[j] / n as f64 - xh * dgamma[j] / n as f64)
                        } else {
                            scale[j] * gv
                        });
                    }
                }
            });
        let to = |v: &[f64]| v.iter().map(|&x| T::of(x)).collect();
        (dx, to(dgamma), to(dbeta))
    }
}

/// The f32/f64 slices of three CPU storages of one dtype, or an error.
macro_rules! with_slices {
    ($op:literal, ($a:expr, $la:expr), ($b:expr, $lb:expr), ($c:expr, $lc:expr), |$x:ident, $y:ident, $z:ident| $body:expr) => {
        match ($a, $b, $c) {
            (CpuStorage::F32(a), CpuStorage::F32(b), CpuStorage::F32(c)) => {
                let ($x, $y, $z) = (span($op, a, $la)?, span($op, b, $lb)?, span($op, c, $lc)?);
                $body
            }
            (CpuStorage::F64(a), CpuStorage::F64(b), CpuStorage::F64(c)) => {
                let ($x, $y, $z) = (span($op, a, $la)?, span($op, b, $lb)?, span($op, c, $lc)?);
                $body
            }
            _ => bail!("{}: f32 or f64 inputs of one dtype only", $op),
        }
    };
}

/// Wraps a `Vec<f32|f64>` as the matching storage.
trait IntoStorage {
    fn storage(self) -> CpuStorage;
}

impl IntoStorage for Vec<f32> {
    fn storage(self) -> CpuStorage {
        CpuStorage::F32(self)
    }
}

impl IntoStorage for Vec<f64> {
    fn storage(self) -> CpuStorage {
        CpuStorage::F64(self)
    }
}

impl CustomOp3 for BatchNormOp {
    fn name(&self) -> &'static str {
        "fused-batch-norm"
    }

    fn cpu_fwd(
        &self,
        s1: &CpuStorage,
        l1: &Layout,
        s2: &CpuStorage,
        l2: &Layout,
        s3: &CpuStorage,
        l3: &Layout,
    ) -> Result<(CpuStorage, Shape)> {
        let c = self.mean.len();
        let ok = l1.dims().len() == 2 && l1.dims()[1] == c && l2.dims() == [c] && l3.dims() == [c];
        if !ok {
            bail!(
                "fused-batch-norm: x {:?}, γ {:?}, β {:?}",
                l1.dims(),
                l2.dims(),
                l3.dims()
            );
        }
        let out = with_slices!(
            "fused-batch-norm",
            (s1, l1),
            (s2, l2),
            (s3, l3),
            |x, g, b| self.forward(x, g, b).storage()
        );
        Ok((out, l1.shape().clone()))
    }

    fn bwd(
        &self,
        x: &Tensor,
        gamma: &Tensor,
        _beta: &Tensor,
        res: &Tensor,
        grad: &Tensor,
    ) -> Result<(Option<Tensor>, Option<Tensor>, Option<Tensor>)> {
        let grad = grad.contiguous()?;
        let res = res.contiguous()?;
        let (xs, xl) = x.storage_and_layout();
        let (gs, gl) = gamma.storage_and_layout();
        let (ys, yl) = res.storage_and_layout();
        let (ds, dl) = grad.storage_and_layout();
        let (
            candle_core::Storage::Cpu(xs),
            candle_core::Storage::Cpu(gs),
            candle_core::Storage::Cpu(ys),
            candle_core::Storage::Cpu(ds),
        ) = (&*xs, &*gs, &*ys, &*ds)
        else {
            bail!("fused-batch-norm: CPU only");
        };
        /// The backward on one dtype's slices, as tensors shaped like x, γ and β.
        fn typed<T: Real + candle_core::WithDType>(
            op: &BatchNormOp,
            x: &Tensor,
            data: [&[T]; 4],
            layouts: [&Layout; 4],
        ) -> Result<(Tensor, Tensor, Tensor)> {
            const OP: &str = "fused-batch-norm";
            let [xs, gs, ys, ds] = [0, 1, 2, 3].map(|i| span(OP, data[i], layouts[i]));
            let (dx, dgamma, dbeta) = op.backward(xs?, gs?, ys?, ds?);
            let (dev, c) = (x.device(), op.mean.len());
            Ok((
                Tensor::from_vec(dx, x.shape(), dev)?,
                Tensor::from_vec(dgamma, c, dev)?,
                Tensor::from_vec(dbeta, c, dev)?,
            ))
        }
        let layouts = [xl, gl, yl, dl];
        let (dx, dgamma, dbeta) = match (xs, gs, ys, ds) {
            (CpuStorage::F32(a), CpuStorage::F32(b), CpuStorage::F32(c), CpuStorage::F32(d)) => {
                typed(self, x, [a, b, c, d], layouts)?
            }
            (CpuStorage::F64(a), CpuStorage::F64(b), CpuStorage::F64(c), CpuStorage::F64(d)) => {
                typed(self, x, [a, b, c, d], layouts)?
            }
            _ => bail!("fused-batch-norm: f32 or f64 inputs of one dtype only"),
        };
        Ok((Some(dx), Some(dgamma), Some(dbeta)))
    }
}

// ---------------------------------------------------------------------------------------------
// L2 term

/// ½ Σ w² as a scalar tensor; backward g·w.
pub(crate) fn half_sum_sq(w: &Tensor) -> Result<Tensor> {
    if fusable(w) {
        w.contiguous()?.apply_op1(HalfSumSq)
    } else {
        w.sqr()?.sum_all()? * 0.5
    }
}

struct HalfSumSq;

impl CustomOp1 for HalfSumSq {
    fn name(&self) -> &'static str {
        "half-sum-sq"
    }

    fn cpu_fwd(&self, s: &CpuStorage, l: &Layout) -> Result<(CpuStorage, Shape)> {
        fn run<T: Real>(w: &[T]) -> f64 {
            let partial: Vec<f64> = w
                .par_chunks(CHUNK)
                .map(|c| c.iter().map(|&v| v.to_f64() * v.to_f64()).sum::<f64>())
                .collect();
            0.5 * partial.iter().sum::<f64>()
        }
        let out = match s {
            CpuStorage::F32(w) => CpuStorage::F32(vec![run(span("l2", w, l)?) as f32]),
            CpuStorage::F64(w) => CpuStorage::F64(vec![run(span("l2", w, l)?)]),
            _ => bail!("half-sum-sq: f32 or f64 only"),
        };
        Ok((out, Shape::from(())))
    }

    fn bwd(&self, arg: &Tensor, _res: &Tensor, grad: &Tensor) -> Result<Option<Tensor>> {
        Ok(Some(arg.broadcast_mul(grad)?))
    }
}

#[cfg(test)]
mod tests;
