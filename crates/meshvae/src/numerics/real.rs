//! [`Real`]: the float types (f32, f64) the CPU kernels run on (the engine's passes, Adam's
//! update), with the f32 tanh they use, and the slices of candle's CPU storages they read.

use super::host::{HostSlice, HostVec};
use candle_core::{CpuStorage, Layout};
use candle_core::{Result, Tensor, bail};

/// Rows (or elements) per parallel chunk.
pub(crate) const CHUNK: usize = 1 << 14;

/// f32 or f64: what meshvae's CPU kernels need of a float type, beyond spectral-conv's kernels'
/// ([`spectral_conv::Float`]) and candle's storage ([`candle_core::WithDType`]).
pub(crate) trait Real:
    spectral_conv::Float
    + candle_core::WithDType
    + Copy
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
    /// The value in f64 (`as_f64`: spectral-conv and candle each have a `to_f64`).
    fn as_f64(self) -> f64;
    fn of(x: f64) -> Self;
    fn tanh(self) -> Self;
    fn sqrt(self) -> Self;
    /// The values of a CPU storage of this type.
    fn cpu(s: &CpuStorage) -> Option<&[Self]>;
    fn cpu_mut(s: &mut CpuStorage) -> Option<&mut [Self]>;
    /// The values of a host slice of this type.
    fn host(s: HostSlice<'_>) -> Option<&[Self]>;
    /// Values of this type as a host vector.
    fn host_vec(v: Vec<Self>) -> HostVec;
}

/// The parts of [`Real`] that differ between f32 and f64 only by name.
macro_rules! real_storage {
    ($t:ty, $v:ident) => {
        const DTYPE_OF: candle_core::DType = candle_core::DType::$v;
        fn host(s: HostSlice<'_>) -> Option<&[Self]> {
            match s {
                HostSlice::$v(v) => Some(v),
                _ => None,
            }
        }
        fn host_vec(v: Vec<Self>) -> HostVec {
            HostVec::$v(v)
        }
        fn cpu(s: &CpuStorage) -> Option<&[Self]> {
            match s {
                CpuStorage::$v(v) => Some(v),
                _ => None,
            }
        }
        fn cpu_mut(s: &mut CpuStorage) -> Option<&mut [Self]> {
            match s {
                CpuStorage::$v(v) => Some(v),
                _ => None,
            }
        }
        fn as_f64(self) -> f64 {
            self as f64
        }
        fn of(x: f64) -> Self {
            x as $t
        }
        fn sqrt(self) -> Self {
            <$t>::sqrt(self)
        }
    };
}

impl Real for f32 {
    real_storage!(f32, F32);
    #[inline(always)]
    fn tanh(self) -> Self {
        fast_tanh(self)
    }
}

impl Real for f64 {
    real_storage!(f64, F64);
    fn tanh(self) -> Self {
        f64::tanh(self)
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

/// Whether the CPU kernels can run on `t` (CPU, f32 or f64).
pub(crate) fn fusable(t: &Tensor) -> bool {
    t.device().is_cpu() && matches!(t.dtype(), candle_core::DType::F32 | candle_core::DType::F64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fast_tanh_is_accurate_everywhere() {
        let mut worst = 0.0f64;
        let mut x = -12.0f32;
        while x <= 12.0 {
            let want = (x as f64).tanh();
            let got = fast_tanh(x) as f64;
            let err = (got - want).abs() / want.abs().max(1e-30);
            worst = worst.max(err);
            x += 1.3e-4;
        }
        assert!(worst < 5e-7, "{worst}");
        for x in [
            0.0f32,
            -0.0,
            1e-30,
            0.125,
            -0.125,
            9.0,
            -9.0,
            100.0,
            f32::MAX,
        ] {
            let want = (x as f64).tanh();
            assert!(
                (fast_tanh(x) as f64 - want).abs() <= 6e-8 * want.abs().max(1e-30),
                "{x}"
            );
        }
        assert!(fast_tanh(f32::NAN).is_nan());
    }
}
