//! Cache prefetch hints. A contraction touches a few dozen records spread over the vertex and
//! edge arrays; asking for all of them before using any lets their cache misses overlap.

/// Hints the CPU to bring the cache line at `p` into its caches. No effect on the program's
/// behaviour (and none at all off x86_64).
#[inline(always)]
pub(crate) fn prefetch<T>(p: *const T) {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: a prefetch neither reads nor writes memory as far as the program can observe and
    // never faults, whatever the address; SSE (which it belongs to) is part of x86_64's baseline.
    unsafe {
        use std::arch::x86_64::{_MM_HINT_T0, _mm_prefetch};
        _mm_prefetch::<_MM_HINT_T0>(p.cast());
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = p;
}

/// [`prefetch`] for every cache line of `*x`.
#[inline(always)]
pub(crate) fn prefetch_all<T>(x: &T) {
    let p = (x as *const T).cast::<u8>();
    let mut offset = 0;
    while offset < size_of::<T>() {
        prefetch(p.wrapping_add(offset));
        offset += 64;
    }
    // The last byte, in case `x` straddles one more line.
    prefetch(p.wrapping_add(size_of::<T>().saturating_sub(1)));
}
