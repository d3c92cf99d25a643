//! AVX2 + FMA versions of the f32 mixing and dot-product tiles of `mix.rs`.
//!
//! Why by hand: written generically, the 12-accumulator tiles were compiled to scalar FMAs on
//! stack slots (the optimiser did not promote the accumulator arrays to registers), 3–5× slower.
//! Arrays of `__m256` are promoted. Used wherever the CPU has AVX2 and FMA; a batch that is not a
//! multiple of 8 ends in one masked vector per row (a training set of 22 meshes is one batch of
//! 22, and the generic code made such an epoch ~1.6× slower). The generic code is the reference
//! in the tests.

#[cfg(target_arch = "x86_64")]
use std::arch::x86_64::{
    __m256, __m256i, _mm256_add_ps, _mm256_cmpgt_epi32, _mm256_fmadd_ps, _mm256_loadu_ps,
    _mm256_maskload_ps, _mm256_maskstore_ps, _mm256_set1_epi32, _mm256_set1_ps, _mm256_setr_epi32,
    _mm256_setzero_ps, _mm256_storeu_ps,
};

use crate::mix::{LANES, MixDims};

/// Whether the AVX2 + FMA tiles can run here (and the tests do not force the baseline).
fn usable(batch: usize) -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        batch > 0
            && std::arch::is_x86_feature_detected!("avx2")
            && std::arch::is_x86_feature_detected!("fma")
            && !crate::kernel::baseline_forced()
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        let _ = batch;
        false
    }
}

/// [`crate::mix::mix`] for f32; false (nothing done) where the tiles cannot run.
pub(crate) fn mix_f32(
    inps: &[&[f32]],
    m: &[f32],
    d: MixDims,
    bias: Option<&[f32]>,
    out: &mut [f32],
) -> bool {
    if !usable(d.batch) {
        return false;
    }
    #[cfg(target_arch = "x86_64")]
    // SAFETY: the CPU has AVX2 and FMA (checked by `usable`).
    unsafe {
        avx::mix(inps, m, d, bias, out)
    };
    true
}

/// [`crate::mix::dot_chunk`] for f32; false (nothing done) where the tiles cannot run.
pub(crate) fn dot_chunk_f32(
    t: &[f32],
    g: &[f32],
    dims: (usize, usize, usize),
    lanes: &mut [[f32; LANES]],
) -> bool {
    if !usable(dims.2) {
        return false;
    }
    #[cfg(target_arch = "x86_64")]
    // SAFETY: the CPU has AVX2 and FMA (checked by `usable`).
    unsafe {
        avx::dot_chunk(t, g, dims, lanes)
    };
    true
}

#[cfg(target_arch = "x86_64")]
mod avx {
    use super::*;

    #[inline]
    #[target_feature(enable = "avx2,fma")]
    fn load(src: &[f32]) -> __m256 {
        let src = &src[..LANES];
        // SAFETY: `src` holds 8 f32 (sliced just above); loadu has no alignment requirement.
        unsafe { _mm256_loadu_ps(src.as_ptr()) }
    }

    #[inline]
    #[target_feature(enable = "avx2,fma")]
    fn store(dst: &mut [f32], v: __m256) {
        let dst = &mut dst[..LANES];
        // SAFETY: `dst` holds 8 f32 (sliced just above); storeu has no alignment requirement.
        unsafe { _mm256_storeu_ps(dst.as_mut_ptr(), v) }
    }

    /// The mask of the first `n` lanes (`n < 8`), for the ragged end of a batch.
    #[inline]
    #[target_feature(enable = "avx2,fma")]
    fn head_mask(n: usize) -> __m256i {
        _mm256_cmpgt_epi32(
            _mm256_set1_epi32(n as i32),
            _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7),
        )
    }

    /// The first `n` values of `src` (fewer than 8), zeros in the other lanes.
    #[inline]
    #[target_feature(enable = "avx2,fma")]
    fn load_head(src: &[f32], n: usize, mask: __m256i) -> __m256 {
        let src = &src[..n];
        // SAFETY: the mask enables exactly the lanes of `src`'s n values (sliced just above);
        // masked-off lanes are neither read nor faulted on.
        unsafe { _mm256_maskload_ps(src.as_ptr(), mask) }
    }

    /// Writes the first `n` lanes of `v` (fewer than 8) to `dst`.
    #[inline]
    #[target_feature(enable = "avx2,fma")]
    fn store_head(dst: &mut [f32], n: usize, mask: __m256i, v: __m256) {
        let dst = &mut dst[..n];
        // SAFETY: as in `load_head`: only the n lanes of `dst` are written.
        unsafe { _mm256_maskstore_ps(dst.as_mut_ptr(), mask, v) }
    }

    #[target_feature(enable = "avx2,fma")]
    pub(super) fn mix(
        inps: &[&[f32]],
        m: &[f32],
        d: MixDims,
        bias: Option<&[f32]>,
        out: &mut [f32],
    ) {
        let MixDims { p, batch } = d;
        let mut o0 = 0;
        while o0 < p {
            let o_n = if p - o0 >= 3 { 3 } else { 1 };
            let mut lb = 0;
            while lb < batch {
                lb += match (o_n, batch - lb) {
                    (3, 32..) => tile::<4, 3>(inps, m, d, (o0, lb), bias, out),
                    (3, LANES..) => tile::<1, 3>(inps, m, d, (o0, lb), bias, out),
                    (_, LANES..) => tile::<1, 1>(inps, m, d, (o0, lb), bias, out),
                    (3, _) => tail::<3>(inps, m, d, (o0, lb), bias, out),
                    _ => tail::<1>(inps, m, d, (o0, lb), bias, out),
                };
            }
            o0 += o_n;
        }
    }

    /// G × 8 lanes from `lb` of outputs `o0 .. o0 + O`; returns the lanes done.
    #[inline]
    #[target_feature(enable = "avx2,fma")]
    fn tile<const G: usize, const O: usize>(
        inps: &[&[f32]],
        m: &[f32],
        MixDims { p, batch }: MixDims,
        (o0, lb): (usize, usize),
        bias: Option<&[f32]>,
        out: &mut [f32],
    ) -> usize {
        let mut acc = [[_mm256_setzero_ps(); G]; O];
        if let Some(b) = bias {
            for (o, a) in acc.iter_mut().enumerate() {
                *a = [_mm256_set1_ps(b[o0 + o]); G];
            }
        }
        let mut q_base = 0;
        for inp in inps {
            let q_n = inp.len() / batch;
            for q in 0..q_n {
                let row = &inp[q * batch + lb..][..G * LANES];
                let w = &m[(q_base + q) * p + o0..][..O];
                let mut wv = [_mm256_setzero_ps(); O];
                for (v, &x) in wv.iter_mut().zip(w) {
                    *v = _mm256_set1_ps(x);
                }
                // One input vector at a time: the O broadcasts, one input and the O·G
                // accumulators fit the 16 registers. With all G inputs loaded first, a 4 × 3
                // tile needed 17 and kept two accumulators on the stack: a store-to-load chain
                // through memory on every input row (`perf annotate`): 0.97 against 1.25 vector
                // FMAs per cycle on one core, the same sums in the same order.
                for gi in 0..G {
                    let xv = load(&row[gi * LANES..]);
                    for (a, &v) in acc.iter_mut().zip(&wv) {
                        a[gi] = _mm256_fmadd_ps(xv, v, a[gi]);
                    }
                }
            }
            q_base += q_n;
        }
        for (o, a) in acc.iter().enumerate() {
            for (gi, &v) in a.iter().enumerate() {
                store(&mut out[(o0 + o) * batch + lb + gi * LANES..], v);
            }
        }
        G * LANES
    }

    /// [`tile`] for the last `batch − lb` (< 8) lanes; returns them.
    #[inline]
    #[target_feature(enable = "avx2,fma")]
    fn tail<const O: usize>(
        inps: &[&[f32]],
        m: &[f32],
        MixDims { p, batch }: MixDims,
        (o0, lb): (usize, usize),
        bias: Option<&[f32]>,
        out: &mut [f32],
    ) -> usize {
        let n = batch - lb;
        let mask = head_mask(n);
        let mut acc = [_mm256_setzero_ps(); O];
        if let Some(b) = bias {
            for (o, a) in acc.iter_mut().enumerate() {
                *a = _mm256_set1_ps(b[o0 + o]);
            }
        }
        let mut q_base = 0;
        for inp in inps {
            let q_n = inp.len() / batch;
            for q in 0..q_n {
                let x = load_head(&inp[q * batch + lb..], n, mask);
                let w = &m[(q_base + q) * p + o0..][..O];
                for (a, &wv) in acc.iter_mut().zip(w) {
                    *a = _mm256_fmadd_ps(x, _mm256_set1_ps(wv), *a);
                }
            }
            q_base += q_n;
        }
        for (o, &v) in acc.iter().enumerate() {
            store_head(&mut out[(o0 + o) * batch + lb..], n, mask, v);
        }
        n
    }

    #[target_feature(enable = "avx2,fma")]
    pub(super) fn dot_chunk(
        t: &[f32],
        g: &[f32],
        dims: (usize, usize, usize),
        lanes: &mut [[f32; LANES]],
    ) {
        let (ci, co, _) = dims;
        let mut f0 = 0;
        while f0 < ci {
            let f_n = if ci - f0 >= 3 { 3 } else { 1 };
            let mut o0 = 0;
            while o0 < co {
                let o_n = if co - o0 >= 3 { 3 } else { 1 };
                match (f_n, o_n) {
                    (3, 3) => dot_tile::<3, 3>(t, g, dims, (f0, o0), lanes),
                    (3, _) => dot_tile::<3, 1>(t, g, dims, (f0, o0), lanes),
                    (_, 3) => dot_tile::<1, 3>(t, g, dims, (f0, o0), lanes),
                    _ => dot_tile::<1, 1>(t, g, dims, (f0, o0), lanes),
                }
                o0 += o_n;
            }
            f0 += f_n;
        }
    }

    /// acc[f][o] += t[f] · g[o], lane by lane.
    #[inline]
    #[target_feature(enable = "avx2,fma")]
    fn outer_fma<const F: usize, const O: usize>(
        acc: &mut [[__m256; O]; F],
        tv: &[__m256; F],
        gv: &[__m256; O],
    ) {
        for (a, &x) in acc.iter_mut().zip(tv) {
            for (z, &y) in a.iter_mut().zip(gv) {
                *z = _mm256_fmadd_ps(x, y, *z);
            }
        }
    }

    #[inline]
    #[target_feature(enable = "avx2,fma")]
    fn dot_tile<const F: usize, const O: usize>(
        t: &[f32],
        g: &[f32],
        (ci, co, batch): (usize, usize, usize),
        (f0, o0): (usize, usize),
        lanes: &mut [[f32; LANES]],
    ) {
        let mut acc = [[_mm256_setzero_ps(); O]; F];
        let full = batch - batch % LANES;
        let (rest, mask) = (batch - full, head_mask(batch % LANES));
        let (tn, gn) = (ci * batch, co * batch);
        let verts = (t.len() / tn).min(g.len() / gn);
        // Checked once here instead of twice per load: the loop below then keeps its row
        // pointers in registers (slice bounds checks made it reload lengths from the stack;
        // a horse-gallop training step got 13 % faster).
        assert!(
            f0 + F <= ci && o0 + O <= co,
            "dot tile outside the channels"
        );
        let (tp, gp) = (t.as_ptr(), g.as_ptr());
        for v in 0..verts {
            // SAFETY: vertex v < verts has ci·batch values in `t` and co·batch in `g`; rows
            // f0 + f < ci and o0 + o < co start inside them, and lb + 8 ≤ full ≤ batch.
            unsafe {
                let tr = tp.add(v * tn + f0 * batch);
                let gr = gp.add(v * gn + o0 * batch);
                let mut lb = 0;
                while lb < full {
                    let mut tv = [_mm256_setzero_ps(); F];
                    let mut gv = [_mm256_setzero_ps(); O];
                    for (f, x) in tv.iter_mut().enumerate() {
                        *x = _mm256_loadu_ps(tr.add(f * batch + lb));
                    }
                    for (o, y) in gv.iter_mut().enumerate() {
                        *y = _mm256_loadu_ps(gr.add(o * batch + lb));
                    }
                    outer_fma(&mut acc, &tv, &gv);
                    lb += LANES;
                }
            }
            if rest > 0 {
                let (tb, gb) = (&t[v * tn..][..tn], &g[v * gn..][..gn]);
                let mut tv = [_mm256_setzero_ps(); F];
                let mut gv = [_mm256_setzero_ps(); O];
                for (f, x) in tv.iter_mut().enumerate() {
                    *x = load_head(&tb[(f0 + f) * batch + full..], rest, mask);
                }
                for (o, y) in gv.iter_mut().enumerate() {
                    *y = load_head(&gb[(o0 + o) * batch + full..], rest, mask);
                }
                outer_fma(&mut acc, &tv, &gv);
            }
        }
        for (f, a) in acc.iter().enumerate() {
            for (o, &v) in a.iter().enumerate() {
                let l = &mut lanes[(f0 + f) * co + o0 + o];
                let sum = _mm256_add_ps(load(l), v);
                store(l, sum);
            }
        }
    }
}
