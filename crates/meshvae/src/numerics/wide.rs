//! [`wide`]: element-wise loops compiled for AVX2 + FMA where the CPU has them.

/// Runs `f` compiled for AVX2 and FMA where the CPU has them (8 floats per instruction instead
/// of baseline x86-64's 4). Rust never fuses a multiply and an add on its own, so the results
/// are bit-identical either way; only the vector width changes.
#[inline(always)]
pub(crate) fn wide<R, F: FnOnce() -> R>(f: F) -> R {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma") {
        // SAFETY: the CPU has both features (checked just above).
        return unsafe { avx2(f) };
    }
    f()
}

/// `f` inlined into a function compiled with AVX2 and FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn avx2<R>(f: impl FnOnce() -> R) -> R {
    f()
}
