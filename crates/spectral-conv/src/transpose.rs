//! Transposes between B runs of S values (one run per batch slice, as a chunk of vertices sits in
//! a `[B, V, C]` array) and S rows of B values (the channel-major staging blocks).
//!
//! Why a module of its own: done one value at a time, these copies cost as much as the sparse
//! products around them; with AVX 8×8 tile transposes (f32) they are about 7× faster.

/// dst[s·B + b] = runs[b][s] for s < S, with B = `runs.len()`.
pub(crate) fn gather_runs_scalar<T: Copy>(runs: &[&[T]], dst: &mut [T]) {
    let batch = runs.len();
    for (b, run) in runs.iter().enumerate() {
        for (s, &v) in run.iter().enumerate() {
            dst[s * batch + b] = v;
        }
    }
}

/// runs[b][s] = src[s·B + b] for s < S, with B = `runs.len()`.
pub(crate) fn scatter_runs_scalar<T: Copy>(src: &[T], runs: &mut [&mut [T]]) {
    let batch = runs.len();
    for (b, run) in runs.iter_mut().enumerate() {
        for (s, z) in run.iter_mut().enumerate() {
            *z = src[s * batch + b];
        }
    }
}

/// dst[c·R + r] = src[r·C + c]: an R × C row-major block into its C × R transpose (one vertex's
/// `[B, C]` block of a `[V, B, C]` array to the kernels' `[C, B]`, and back).
pub(crate) fn transpose_block_scalar<T: Copy>(src: &[T], rows: usize, cols: usize, dst: &mut [T]) {
    for (r, row) in src[..rows * cols].chunks_exact(cols).enumerate() {
        for (c, &v) in row.iter().enumerate() {
            dst[c * rows + r] = v;
        }
    }
}

/// [`transpose_block_scalar`] with AVX 8×8 tiles where the CPU has AVX2.
pub(crate) fn transpose_block_f32(src: &[f32], rows: usize, cols: usize, dst: &mut [f32]) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") && !crate::kernel::baseline_forced() {
        // SAFETY: the CPU supports AVX2 (checked just above).
        unsafe { avx::transpose_block(src, rows, cols, dst) };
        return;
    }
    transpose_block_scalar(src, rows, cols, dst);
}

/// The f32 versions: AVX 8×8 tiles where the CPU has AVX2, the scalar loops elsewhere and for
/// the edges.
pub(crate) fn gather_runs_f32(runs: &[&[f32]], dst: &mut [f32]) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") && !crate::kernel::baseline_forced() {
        // SAFETY: the CPU supports AVX2 (checked just above).
        unsafe { avx::gather_runs(runs, dst) };
        return;
    }
    gather_runs_scalar(runs, dst);
}

/// See [`gather_runs_f32`].
pub(crate) fn scatter_runs_f32(src: &[f32], runs: &mut [&mut [f32]]) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") && !crate::kernel::baseline_forced() {
        // SAFETY: the CPU supports AVX2 (checked just above).
        unsafe { avx::scatter_runs(src, runs) };
        return;
    }
    scatter_runs_scalar(src, runs);
}

#[cfg(target_arch = "x86_64")]
mod avx {
    use std::arch::x86_64::{
        __m256, _mm256_loadu_ps, _mm256_permute2f128_ps, _mm256_shuffle_ps, _mm256_storeu_ps,
        _mm256_unpackhi_ps, _mm256_unpacklo_ps,
    };

    /// Eight loaded rows → eight transposed rows.
    #[target_feature(enable = "avx2")]
    fn transpose8(r: [__m256; 8]) -> [__m256; 8] {
        let t0 = _mm256_unpacklo_ps(r[0], r[1]);
        let t1 = _mm256_unpackhi_ps(r[0], r[1]);
        let t2 = _mm256_unpacklo_ps(r[2], r[3]);
        let t3 = _mm256_unpackhi_ps(r[2], r[3]);
        let t4 = _mm256_unpacklo_ps(r[4], r[5]);
        let t5 = _mm256_unpackhi_ps(r[4], r[5]);
        let t6 = _mm256_unpacklo_ps(r[6], r[7]);
        let t7 = _mm256_unpackhi_ps(r[6], r[7]);
        let u0 = _mm256_shuffle_ps::<0x44>(t0, t2);
        let u1 = _mm256_shuffle_ps::<0xEE>(t0, t2);
        let u2 = _mm256_shuffle_ps::<0x44>(t1, t3);
        let u3 = _mm256_shuffle_ps::<0xEE>(t1, t3);
        let u4 = _mm256_shuffle_ps::<0x44>(t4, t6);
        let u5 = _mm256_shuffle_ps::<0xEE>(t4, t6);
        let u6 = _mm256_shuffle_ps::<0x44>(t5, t7);
        let u7 = _mm256_shuffle_ps::<0xEE>(t5, t7);
        [
            _mm256_permute2f128_ps::<0x20>(u0, u4),
            _mm256_permute2f128_ps::<0x20>(u1, u5),
            _mm256_permute2f128_ps::<0x20>(u2, u6),
            _mm256_permute2f128_ps::<0x20>(u3, u7),
            _mm256_permute2f128_ps::<0x31>(u0, u4),
            _mm256_permute2f128_ps::<0x31>(u1, u5),
            _mm256_permute2f128_ps::<0x31>(u2, u6),
            _mm256_permute2f128_ps::<0x31>(u3, u7),
        ]
    }

    #[target_feature(enable = "avx2")]
    fn load(src: &[f32]) -> __m256 {
        let src = &src[..8];
        // SAFETY: `src` holds 8 f32 (sliced just above); loadu has no alignment requirement.
        unsafe { _mm256_loadu_ps(src.as_ptr()) }
    }

    #[target_feature(enable = "avx2")]
    fn store(dst: &mut [f32], v: __m256) {
        let dst = &mut dst[..8];
        // SAFETY: `dst` holds 8 f32 (sliced just above); storeu has no alignment requirement.
        unsafe { _mm256_storeu_ps(dst.as_mut_ptr(), v) }
    }

    #[target_feature(enable = "avx2")]
    pub(super) fn gather_runs(runs: &[&[f32]], dst: &mut [f32]) {
        let batch = runs.len();
        let s_n = runs.first().map_or(0, |r| r.len());
        let (b_full, s_full) = (batch - batch % 8, s_n - s_n % 8);
        for b0 in (0..b_full).step_by(8) {
            for s0 in (0..s_full).step_by(8) {
                let rows = std::array::from_fn(|l| load(&runs[b0 + l][s0..]));
                for (s, v) in transpose8(rows).into_iter().enumerate() {
                    store(&mut dst[(s0 + s) * batch + b0..], v);
                }
            }
        }
        // Edges: the last batch lanes for every s, and the last values of every run.
        for (b, run) in runs.iter().enumerate() {
            let from = if b < b_full { s_full } else { 0 };
            for (s, &v) in run.iter().enumerate().skip(from) {
                dst[s * batch + b] = v;
            }
        }
    }

    #[target_feature(enable = "avx2")]
    pub(super) fn transpose_block(src: &[f32], rows: usize, cols: usize, dst: &mut [f32]) {
        let (r_full, c_full) = (rows - rows % 8, cols - cols % 8);
        let (src, dst) = (&src[..rows * cols], &mut dst[..rows * cols]);
        for r0 in (0..r_full).step_by(8) {
            for c0 in (0..c_full).step_by(8) {
                let tile = std::array::from_fn(|l| load(&src[(r0 + l) * cols + c0..]));
                for (c, v) in transpose8(tile).into_iter().enumerate() {
                    store(&mut dst[(c0 + c) * rows + r0..], v);
                }
            }
        }
        // Edges: the last columns of the tiled rows, then every column of the last rows.
        for r in 0..rows {
            let from = if r < r_full { c_full } else { 0 };
            for c in from..cols {
                dst[c * rows + r] = src[r * cols + c];
            }
        }
    }

    #[target_feature(enable = "avx2")]
    pub(super) fn scatter_runs(src: &[f32], runs: &mut [&mut [f32]]) {
        let batch = runs.len();
        let s_n = runs.first().map_or(0, |r| r.len());
        let (b_full, s_full) = (batch - batch % 8, s_n - s_n % 8);
        for b0 in (0..b_full).step_by(8) {
            for s0 in (0..s_full).step_by(8) {
                let rows = std::array::from_fn(|s| load(&src[(s0 + s) * batch + b0..]));
                for (l, v) in transpose8(rows).into_iter().enumerate() {
                    store(&mut runs[b0 + l][s0..], v);
                }
            }
        }
        for (b, run) in runs.iter_mut().enumerate() {
            let from = if b < b_full { s_full } else { 0 };
            for (s, z) in run.iter_mut().enumerate().skip(from) {
                *z = src[s * batch + b];
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn simd_and_scalar_transposes_agree_on_ragged_sizes() {
        for (batch, s_n) in [(32usize, 576usize), (13, 21), (8, 8), (3, 5), (16, 7)] {
            let data: Vec<f32> = (0..batch * s_n).map(|i| i as f32).collect();
            let runs: Vec<&[f32]> = data.chunks(s_n).collect();
            let (mut a, mut b) = (vec![0.0; batch * s_n], vec![0.0; batch * s_n]);
            gather_runs_f32(&runs, &mut a);
            gather_runs_scalar(&runs, &mut b);
            assert_eq!(a, b, "gather B={batch} S={s_n}");
            assert_eq!(
                a[(s_n - 1) * batch + batch - 1],
                data[(batch - 1) * s_n + s_n - 1]
            );
            let (mut c, mut d) = (vec![0.0; batch * s_n], vec![0.0; batch * s_n]);
            let mut runs_c: Vec<&mut [f32]> = c.chunks_mut(s_n).collect();
            scatter_runs_f32(&a, &mut runs_c);
            let mut runs_d: Vec<&mut [f32]> = d.chunks_mut(s_n).collect();
            scatter_runs_scalar(&a, &mut runs_d);
            assert_eq!(c, d, "scatter B={batch} S={s_n}");
            assert_eq!(c, data);
        }
    }

    #[test]
    fn block_transposes_agree_and_round_trip() {
        for (rows, cols) in [
            (32usize, 9usize),
            (9, 32),
            (13, 21),
            (8, 8),
            (3, 5),
            (17, 1),
        ] {
            let data: Vec<f32> = (0..rows * cols).map(|i| i as f32).collect();
            let (mut a, mut b) = (vec![0.0; rows * cols], vec![0.0; rows * cols]);
            transpose_block_f32(&data, rows, cols, &mut a);
            transpose_block_scalar(&data, rows, cols, &mut b);
            assert_eq!(a, b, "{rows}x{cols}");
            assert_eq!(a[(cols - 1) * rows], data[cols - 1]);
            let mut back = vec![0.0; rows * cols];
            transpose_block_f32(&a, cols, rows, &mut back);
            assert_eq!(back, data);
        }
    }
}
