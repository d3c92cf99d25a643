//! Dense products on the engine's buffers with the `gemm` crate (the kernel candle's matmul
//! runs), writing into preallocated outputs instead of fresh tensors.
//!
//! One shape gets its own parallel split: a batch-by-latent product over the whole flattened
//! mesh (m = B, n = 128, k = V₂·9 ≈ 38,000 on horse-gallop: μ, σ and ∂L/∂z). `gemm` shares
//! out rows and columns, of which there are too few, so two threads ran it slower than one
//! (14.5 against 11.2 ms). Here the k axis is cut into fixed slices whose products are
//! summed in slice order (5.7–5.9 ms), the same sums whatever the thread count.

use super::Real;
use rayon::prelude::*;

/// The k slice of a split product (fixed, so that the result does not depend on the threads).
const K_SLICE: usize = 2048;

/// Products with at most this many output elements and k at least `SPLIT_K_MIN` are split
/// along k.
const SPLIT_MN_MAX: usize = 64 * 256;
const SPLIT_K_MIN: usize = 4 * K_SLICE;

/// A matrix view: element (r, c) at `data[r·rs + c·cs]`.
#[derive(Clone, Copy)]
pub(super) struct Mat<'a, T> {
    pub data: &'a [T],
    pub rs: usize,
    pub cs: usize,
}

impl<'a, T> Mat<'a, T> {
    /// A row-major matrix with `cols` columns.
    pub fn row_major(data: &'a [T], cols: usize) -> Self {
        Self {
            data,
            rs: cols,
            cs: 1,
        }
    }

    /// A column-major matrix with `rows` rows.
    pub fn col_major(data: &'a [T], rows: usize) -> Self {
        Self {
            data,
            rs: 1,
            cs: rows,
        }
    }
}

/// The last index a `rows × cols` view with strides (rs, cs) touches, plus one.
fn extent(rows: usize, cols: usize, rs: usize, cs: usize) -> usize {
    if rows == 0 || cols == 0 {
        0
    } else {
        (rows - 1) * rs + (cols - 1) * cs + 1
    }
}

/// dst (m × n, strides `dst_rs`, `dst_cs`) = [dst +] lhs (m × k) · rhs (k × n), on the rayon
/// pool.
///
/// Panics (an internal error, not an input one) if a view does not fit its slice: the engine
/// sizes every buffer from the model when it is built.
pub(super) fn matmul<T: Real>(
    dst: &mut [T],
    dst_strides: (usize, usize),
    lhs: Mat<'_, T>,
    rhs: Mat<'_, T>,
    dims: (usize, usize, usize),
    accumulate: bool,
) {
    if !check_or_finish(dst, dst_strides, lhs, rhs, dims, accumulate) {
        return;
    }
    let (m, n, k) = dims;
    if m * n <= SPLIT_MN_MAX && k >= SPLIT_K_MIN {
        split_k(dst, dst_strides, lhs, rhs, dims, accumulate);
        return;
    }
    // SAFETY: as `product` asks: every view fits its slice (checked above), `dst` aliases
    // neither input.
    unsafe { product(dst, dst_strides, lhs, rhs, dims, accumulate, true) }
}

/// [`matmul`] on the calling thread only: for blocks of a product that the caller already
/// runs in parallel. The same sums as [`matmul`] where that does not split k.
pub(super) fn matmul_serial<T: Real>(
    dst: &mut [T],
    dst_strides: (usize, usize),
    lhs: Mat<'_, T>,
    rhs: Mat<'_, T>,
    dims: (usize, usize, usize),
    accumulate: bool,
) {
    if check_or_finish(dst, dst_strides, lhs, rhs, dims, accumulate) {
        // SAFETY: as in `matmul`.
        unsafe { product(dst, dst_strides, lhs, rhs, dims, accumulate, false) }
    }
}

/// Checks that every view fits its slice (panics otherwise) and finishes the empty products;
/// returns whether a product is left to compute.
fn check_or_finish<T: Real>(
    dst: &mut [T],
    (dst_rs, dst_cs): (usize, usize),
    lhs: Mat<'_, T>,
    rhs: Mat<'_, T>,
    (m, n, k): (usize, usize, usize),
    accumulate: bool,
) -> bool {
    assert!(
        extent(m, n, dst_rs, dst_cs) <= dst.len(),
        "gemm: dst too short"
    );
    assert!(
        extent(m, k, lhs.rs, lhs.cs) <= lhs.data.len(),
        "gemm: lhs too short"
    );
    assert!(
        extent(k, n, rhs.rs, rhs.cs) <= rhs.data.len(),
        "gemm: rhs too short"
    );
    if m == 0 || n == 0 {
        return false;
    }
    if k == 0 {
        if !accumulate {
            for r in 0..m {
                for c in 0..n {
                    dst[r * dst_rs + c * dst_cs] = <T as crate::numerics::real::Real>::of(0.0);
                }
            }
        }
        return false;
    }
    true
}

/// [`matmul`] for few outputs and a long k: each slice of k into its own `m × n` partial
/// product, in parallel, then dst = [dst +] Σ partials in slice order.
fn split_k<T: Real>(
    dst: &mut [T],
    (dst_rs, dst_cs): (usize, usize),
    lhs: Mat<'_, T>,
    rhs: Mat<'_, T>,
    (m, n, k): (usize, usize, usize),
    accumulate: bool,
) {
    let zero = <T as crate::numerics::real::Real>::of(0.0);
    let mut partials = vec![zero; k.div_ceil(K_SLICE) * m * n];
    partials
        .par_chunks_mut(m * n)
        .enumerate()
        .for_each(|(s, part)| {
            let k0 = s * K_SLICE;
            let kn = K_SLICE.min(k - k0);
            let l = Mat {
                data: &lhs.data[k0 * lhs.cs..],
                ..lhs
            };
            let r = Mat {
                data: &rhs.data[k0 * rhs.rs..],
                ..rhs
            };
            // SAFETY: the slices start at column k0 of lhs and row k0 of rhs, which exist
            // (k0 < k); their m × kn and kn × n views fit as the whole views did; `part` is
            // m × n row-major and borrowed mutably.
            unsafe { product(part, (n, 1), l, r, (m, n, kn), false, false) }
        });
    for r in 0..m {
        for c in 0..n {
            let d = &mut dst[r * dst_rs + c * dst_cs];
            let mut sum = if accumulate { *d } else { zero };
            for part in partials.chunks_exact(m * n) {
                sum += part[r * n + c];
            }
            *d = sum;
        }
    }
}

/// dst = [dst +] lhs · rhs with `gemm`, on the rayon pool if `parallel`.
///
/// # Safety
/// The m × k, k × n and m × n views must lie inside `lhs.data`, `rhs.data` and `dst`.
unsafe fn product<T: Real>(
    dst: &mut [T],
    (dst_rs, dst_cs): (usize, usize),
    lhs: Mat<'_, T>,
    rhs: Mat<'_, T>,
    (m, n, k): (usize, usize, usize),
    accumulate: bool,
    parallel: bool,
) {
    let one = <T as crate::numerics::real::Real>::of(1.0);
    let threads = if parallel {
        rayon::current_num_threads()
    } else {
        1
    };
    let parallelism = if threads > 1 {
        gemm::Parallelism::Rayon(threads)
    } else {
        gemm::Parallelism::None
    };
    // SAFETY: every element the product reads or writes lies inside its slice (the caller's
    // promise; strides are non-negative), `dst` is borrowed mutably and so aliases neither
    // input, and T is f32 or f64, which `gemm` supports. Why not candle's matmul: it returns a fresh tensor,
    // and the dense weight gradients are ~100 MB each on a 42k-vertex mesh (fresh pages every
    // step); this writes into the engine's buffers.
    unsafe {
        gemm::gemm(
            m,
            n,
            k,
            dst.as_mut_ptr(),
            dst_cs as isize,
            dst_rs as isize,
            accumulate,
            lhs.data.as_ptr(),
            lhs.cs as isize,
            lhs.rs as isize,
            rhs.data.as_ptr(),
            rhs.cs as isize,
            rhs.rs as isize,
            one,
            one,
            false,
            false,
            false,
            parallelism,
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn strided_products_match_a_naive_loop() {
        let (m, n, k) = (5usize, 7usize, 4usize);
        let a: Vec<f64> = (0..m * k).map(|i| (i as f64 * 0.37).sin()).collect();
        let b: Vec<f64> = (0..k * n).map(|i| (i as f64 * 0.91).cos()).collect();
        // a stored column-major, b row-major, the product written column-major and accumulated.
        let lhs = Mat {
            data: &a,
            rs: 1,
            cs: m,
        };
        let rhs = Mat {
            data: &b,
            rs: n,
            cs: 1,
        };
        let mut dst = vec![1.0; m * n];
        matmul(&mut dst, (1, m), lhs, rhs, (m, n, k), true);
        for r in 0..m {
            for c in 0..n {
                let want = 1.0 + (0..k).map(|j| a[r + j * m] * b[j * n + c]).sum::<f64>();
                assert!((dst[r + c * m] - want).abs() < 1e-12);
            }
        }
        matmul(&mut dst, (1, m), lhs, rhs, (m, n, k), false);
        assert!((dst[0] - (0..k).map(|j| a[j * m] * b[j * n]).sum::<f64>()).abs() < 1e-12);
    }

    /// The μ / σ shape: few outputs, k long enough to be cut into slices.
    #[test]
    fn long_k_products_are_split_match_a_naive_loop_and_ignore_the_thread_count() {
        let (m, n, k) = (3usize, 5usize, 2 * SPLIT_K_MIN + 17);
        let a: Vec<f64> = (0..m * k).map(|i| (i as f64 * 0.37).sin()).collect();
        let b: Vec<f64> = (0..k * n).map(|i| (i as f64 * 0.91).cos()).collect();
        // As the engine stores them: lhs `[k, m]` (a column-major m × k view), rhs row-major.
        let (lhs, rhs) = (Mat::col_major(&a, m), Mat::row_major(&b, n));
        let run = |threads: usize, accumulate: bool| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .expect("a thread pool");
            let mut dst = vec![1.0; m * n];
            pool.install(|| matmul(&mut dst, (n, 1), lhs, rhs, (m, n, k), accumulate));
            dst
        };
        let (one, three) = (run(1, true), run(3, true));
        assert_eq!(one, three, "the thread count changed the sums");
        for r in 0..m {
            for c in 0..n {
                let want = 1.0 + (0..k).map(|j| a[r + j * m] * b[j * n + c]).sum::<f64>();
                assert!((one[r * n + c] - want).abs() < 1e-9, "({r}, {c})");
            }
        }
        let fresh = run(2, false);
        assert!((fresh[0] - (one[0] - 1.0)).abs() < 1e-12);
    }

    /// The dense weights' gradient shape (rows = the flattened mesh, k = the batch), made
    /// block by block on one thread as Adam's fused pass does: the same bits as in one call.
    #[test]
    fn serial_row_blocks_equal_the_whole_product() {
        let (m, n, k) = (1000usize, 24usize, 32usize);
        let a: Vec<f32> = (0..m * k).map(|i| (i as f32 * 0.37).sin()).collect();
        let b: Vec<f32> = (0..k * n).map(|i| (i as f32 * 0.91).cos()).collect();
        let c: Vec<f32> = (0..m * n).map(|i| (i as f32 * 0.13).cos()).collect();
        let rhs = Mat::row_major(&b, n);
        let mut whole = c.clone();
        matmul(
            &mut whole,
            (n, 1),
            Mat::row_major(&a, k),
            rhs,
            (m, n, k),
            true,
        );
        let mut blocks = c.clone();
        for r0 in (0..m).step_by(128) {
            let rows = 128.min(m - r0);
            let lhs = Mat::row_major(&a[r0 * k..], k);
            let dst = &mut blocks[r0 * n..(r0 + rows) * n];
            matmul_serial(dst, (n, 1), lhs, rhs, (rows, n, k), true);
        }
        assert_eq!(whole, blocks);
        let naive: f32 = c[n + 1] + (0..k).map(|j| a[k + j] * b[j * n + 1]).sum::<f32>();
        assert!((blocks[n + 1] - naive).abs() < 1e-4);
    }
}
