//! Recycled buffers for the kernels' large intermediates (channel-major copies, stored
//! Chebyshev terms, Clenshaw terms).
//!
//! Why: a `[32, 42321, 9]` f32 buffer is 49 MB. Freed, the allocator hands such blocks back to
//! the operating system, so the next one arrives as fresh pages that the kernel zeroes on first
//! touch (measured here: a fifth of the CPU time of a ChebConv forward + backward); reused from
//! the allocator, it is zeroed by `calloc` instead. The kernels overwrite every element of these
//! buffers, so a recycled one needs neither. At most [`KEEP`] buffers per float type are kept;
//! [`release_scratch`] frees them.

use crate::kernel::Real;
use std::sync::Mutex;

/// Buffers kept per float type.
const KEEP: usize = 8;

/// Buffers below this many values are left to the allocator.
const MIN_LEN: usize = 1 << 16;

pub(crate) static POOL_F32: Mutex<Vec<Vec<f32>>> = Mutex::new(Vec::new());
pub(crate) static POOL_F64: Mutex<Vec<Vec<f64>>> = Mutex::new(Vec::new());

/// Recycled [`crate::kernel::Staging`] buffer sets.
pub(crate) static STAGING_F32: Mutex<Vec<Vec<Vec<f32>>>> = Mutex::new(Vec::new());
pub(crate) static STAGING_F64: Mutex<Vec<Vec<Vec<f64>>>> = Mutex::new(Vec::new());

/// A vector of `len` values with unspecified contents (zeros, or a previous use's values): only
/// for buffers the caller overwrites entirely.
pub(crate) fn take<T: Real>(len: usize) -> Vec<T> {
    if len >= MIN_LEN
        && let Ok(mut pool) = T::scratch_pool().lock()
    {
        let best = pool
            .iter()
            .enumerate()
            .filter(|(_, v)| v.capacity() >= len)
            .min_by_key(|(_, v)| v.capacity())
            .map(|(i, _)| i);
        if let Some(i) = best {
            let mut v = pool.swap_remove(i);
            if v.len() >= len {
                v.truncate(len);
            } else {
                v.resize(len, T::ZERO);
            }
            return v;
        }
    }
    vec![T::ZERO; len]
}

/// Returns a buffer for later [`take`]s (the smallest kept one is dropped beyond [`KEEP`]).
pub(crate) fn give<T: Real>(v: Vec<T>) {
    if v.capacity() < MIN_LEN {
        return;
    }
    if let Ok(mut pool) = T::scratch_pool().lock() {
        pool.push(v);
        if pool.len() > KEEP
            && let Some(i) = (0..pool.len()).min_by_key(|&i| pool[i].capacity())
        {
            pool.swap_remove(i);
        }
    }
}

/// Frees the buffers this crate keeps for reuse (up to 8 per float type, each as large as one
/// `[B, V, C]` activation). They are refilled by the next layer calls.
pub fn release_scratch() {
    if let Ok(mut pool) = POOL_F32.lock() {
        pool.clear();
    }
    if let Ok(mut pool) = POOL_F64.lock() {
        pool.clear();
    }
    if let Ok(mut pool) = STAGING_F32.lock() {
        pool.clear();
    }
    if let Ok(mut pool) = STAGING_F64.lock() {
        pool.clear();
    }
}

/// Buffers that go back to the pool when dropped (the terms a forward pass keeps for its
/// backward pass live as long as candle's graph does).
pub(crate) struct Recycled<T: Real>(pub Vec<Vec<T>>);

impl<T: Real> Drop for Recycled<T> {
    fn drop(&mut self) {
        for v in self.0.drain(..) {
            give(v);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn buffers_are_reused_by_capacity_and_sized_on_the_way_out() {
        let big = MIN_LEN * 3;
        let mut a: Vec<f64> = take(big);
        assert_eq!(a.len(), big);
        a.iter_mut().for_each(|v| *v = 7.0);
        let ptr = a.as_ptr();
        give(a);
        // Another test may take it first; either way the length is right.
        let b: Vec<f64> = take(big - 5);
        assert_eq!(b.len(), big - 5);
        if b.as_ptr() == ptr {
            assert_eq!(b[0], 7.0, "recycled, not re-zeroed");
        }
        let c: Vec<f64> = take(10);
        assert_eq!(c, vec![0.0; 10]);
        give(b);
        release_scratch();
    }
}
