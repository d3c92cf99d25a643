//! [`Workspace`]: the scratch memory of the CPU kernels, owned by whoever runs them.
//!
//! Two kinds of buffers are reused from call to call:
//! - large intermediates (channel-major copies, stored Chebyshev terms, Clenshaw terms): a
//!   `[32, 42321, 9]` f32 buffer is 49 MB. Freed, the allocator hands such blocks back to the
//!   operating system, so the next one arrives as fresh pages that the kernel zeroes on first
//!   touch (measured: a fifth of the CPU time of a ChebConv forward + backward). The kernels
//!   overwrite every element of these buffers, so a reused one needs no zeroing either;
//! - staging sets: one per rayon task of a parallel sweep (a few per call), sized for a chunk of
//!   vertices.
//!
//! Nothing is global: a network on the buffer-level kernels owns one `Workspace` and passes it to
//! every call; a [`crate::SparseOp`] (and every layer built on it) holds one behind an `Arc`,
//! shared with the layers it is cloned into, or set with [`crate::SparseOp::with_workspace`].
//! Dropping the last owner frees the memory; [`Workspace::clear`] frees it earlier.

use crate::kernel::Real;
use std::sync::Mutex;

/// Large buffers kept per float type.
const KEEP: usize = 8;

/// Buffers below this many values are left to the allocator.
const MIN_LEN: usize = 1 << 16;

/// Staging sets kept per float type (a few per thread).
const STAGING_KEEP: usize = 16;

/// Scratch memory for the CPU kernels, reused between calls: up to 8 large intermediates per
/// float type (channel-major copies, stored Chebyshev terms, Clenshaw terms; a fresh 49 MB
/// buffer would otherwise be page-faulted and zeroed on every call) and the per-task staging
/// buffers of the parallel sweeps. Safe to share between threads; contents are never read
/// before being overwritten, so one workspace may serve any number of layers and calls.
/// Dropping it, or [`Workspace::clear`], frees the memory.
#[derive(Debug, Default)]
pub struct Workspace {
    f32: Pools<f32>,
    f64: Pools<f64>,
}

/// One float type's kept buffers.
#[derive(Debug, Default)]
pub struct Pools<T> {
    large: Mutex<Vec<Vec<T>>>,
    staging: Mutex<Vec<Vec<Vec<T>>>>,
}

impl Workspace {
    /// An empty workspace (buffers are added as calls need them).
    pub fn new() -> Self {
        Self::default()
    }

    /// Frees every kept buffer; later calls refill the workspace.
    pub fn clear(&self) {
        self.f32.clear();
        self.f64.clear();
    }

    /// Bytes held in kept buffers (their capacities).
    pub fn kept_bytes(&self) -> usize {
        self.f32.kept_bytes() + self.f64.kept_bytes()
    }

    /// Large buffers kept, both float types (staging sets not counted: how many rayon starts
    /// varies from call to call).
    #[cfg(test)]
    pub(crate) fn large_count(&self) -> usize {
        self.f32.large_count() + self.f64.large_count()
    }

    pub(crate) fn pools<T: Real>(&self) -> &Pools<T> {
        T::pools(&self.f32, &self.f64)
    }

    /// A vector of `len` values with unspecified contents (zeros, or an earlier use's values):
    /// only for buffers the caller overwrites entirely.
    pub(crate) fn take<T: Real>(&self, len: usize) -> Vec<T> {
        if len >= MIN_LEN
            && let Ok(mut pool) = self.pools::<T>().large.lock()
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

    /// Keeps a buffer for later [`Self::take`]s (the smallest kept one goes beyond [`KEEP`]).
    pub(crate) fn give<T: Real>(&self, v: Vec<T>) {
        if v.capacity() < MIN_LEN {
            return;
        }
        if let Ok(mut pool) = self.pools::<T>().large.lock() {
            pool.push(v);
            if pool.len() > KEEP
                && let Some(i) = (0..pool.len()).min_by_key(|&i| pool[i].capacity())
            {
                pool.swap_remove(i);
            }
        }
    }
}

impl<T> Pools<T> {
    #[cfg(test)]
    fn large_count(&self) -> usize {
        self.large.lock().map(|p| p.len()).unwrap_or(0)
    }

    fn clear(&self) {
        if let Ok(mut pool) = self.large.lock() {
            pool.clear();
        }
        if let Ok(mut pool) = self.staging.lock() {
            pool.clear();
        }
    }

    fn kept_bytes(&self) -> usize {
        let size = std::mem::size_of::<T>();
        let large = self
            .large
            .lock()
            .map(|p| p.iter().map(Vec::capacity).sum::<usize>())
            .unwrap_or(0);
        let staging = self
            .staging
            .lock()
            .map(|p| p.iter().flatten().map(Vec::capacity).sum::<usize>())
            .unwrap_or(0);
        (large + staging) * size
    }
}

/// Per-task staging buffers: one set per rayon job (`for_each_init`, `map_init`) rather than
/// per chunk, taken from and returned to a [`Workspace`]: rayon starts a few jobs per parallel
/// loop, and fresh sets cost page faults and zeroing in every sweep of every layer. Contents
/// are left from earlier chunks; every kernel overwrites what it uses.
pub(crate) struct Staging<'w, T: Real> {
    bufs: Vec<Vec<T>>,
    home: &'w Pools<T>,
}

impl<T: Real> Drop for Staging<'_, T> {
    fn drop(&mut self) {
        if let Ok(mut pool) = self.home.staging.lock()
            && pool.len() < STAGING_KEEP
        {
            pool.push(std::mem::take(&mut self.bufs));
        }
    }
}

impl<'w, T: Real> Staging<'w, T> {
    pub fn new(ws: &'w Workspace) -> Self {
        let home = ws.pools::<T>();
        let bufs = home
            .staging
            .lock()
            .ok()
            .and_then(|mut pool| pool.pop())
            .unwrap_or_default();
        Self { bufs, home }
    }

    /// `N` buffers of the given lengths.
    pub fn get<const N: usize>(&mut self, lens: [usize; N]) -> [&mut [T]; N] {
        if self.bufs.len() < N {
            self.bufs.resize_with(N, Vec::new);
        }
        let mut bufs = self.bufs.iter_mut();
        std::array::from_fn(|k| match bufs.next() {
            Some(v) => {
                if v.len() < lens[k] {
                    v.resize(lens[k], T::ZERO);
                }
                &mut v[..lens[k]]
            }
            // Unreachable: `bufs` was just given at least N buffers.
            None => &mut [],
        })
    }
}

/// Buffers that go back to their workspace when dropped (the terms a forward pass keeps for
/// its backward pass live as long as candle's graph does).
pub(crate) struct Recycled<T: Real> {
    pub bufs: Vec<Vec<T>>,
    pub home: std::sync::Arc<Workspace>,
}

impl<T: Real> Drop for Recycled<T> {
    fn drop(&mut self) {
        for v in self.bufs.drain(..) {
            self.home.give(v);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn buffers_are_reused_by_capacity_and_sized_on_the_way_out() {
        let ws = Workspace::new();
        let big = MIN_LEN * 3;
        let mut a: Vec<f64> = ws.take(big);
        assert_eq!(a.len(), big);
        a.iter_mut().for_each(|v| *v = 7.0);
        let ptr = a.as_ptr();
        ws.give(a);
        assert_eq!(ws.kept_bytes(), big * 8);
        // Nothing else uses this workspace: the same buffer comes back, not re-zeroed.
        let b: Vec<f64> = ws.take(big - 5);
        assert_eq!(b.len(), big - 5);
        assert_eq!(b.as_ptr(), ptr);
        assert_eq!(b[0], 7.0);
        // Small requests and the other float type are separate.
        let c: Vec<f64> = ws.take(10);
        assert_eq!(c, vec![0.0; 10]);
        let d: Vec<f32> = ws.take(big);
        assert_ne!(d.as_ptr() as usize, ptr as usize);
        ws.give(b);
        ws.give(d);
        assert_eq!(ws.kept_bytes(), big * 8 + big * 4);
        ws.clear();
        assert_eq!(ws.kept_bytes(), 0);
    }

    #[test]
    fn at_most_keep_large_buffers_are_kept_the_smallest_go() {
        let ws = Workspace::new();
        for i in 0..KEEP + 3 {
            ws.give(vec![0f32; MIN_LEN + i]);
        }
        let kept = ws.pools::<f32>().large.lock().unwrap();
        assert_eq!(kept.len(), KEEP);
        assert!(kept.iter().all(|v| v.capacity() >= MIN_LEN + 3));
    }

    #[test]
    fn staging_sets_return_to_their_workspace() {
        let ws = Workspace::new();
        {
            let mut s: Staging<'_, f64> = Staging::new(&ws);
            let [a, b] = s.get([100, 7]);
            assert_eq!((a.len(), b.len()), (100, 7));
        }
        assert!(ws.kept_bytes() >= 107 * 8);
        let mut s: Staging<'_, f64> = Staging::new(&ws);
        assert_eq!(ws.kept_bytes(), 0, "taken out again");
        let [a] = s.get([50]);
        assert_eq!(a.len(), 50);
    }
}
