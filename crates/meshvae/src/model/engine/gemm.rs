//! Dense products on the engine's buffers with the `gemm` crate (the kernel candle's matmul
//! runs), writing into preallocated outputs instead of fresh tensors.

use super::Scalar;

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

/// dst (m × n, strides `dst_rs`, `dst_cs`) = [dst +] lhs (m × k) · rhs (k × n).
///
/// Panics (an internal error, not an input one) if a view does not fit its slice: the engine
/// sizes every buffer from the model when it is built.
pub(super) fn matmul<T: Scalar>(
    dst: &mut [T],
    (dst_rs, dst_cs): (usize, usize),
    lhs: Mat<'_, T>,
    rhs: Mat<'_, T>,
    (m, n, k): (usize, usize, usize),
    accumulate: bool,
) {
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
        return;
    }
    if k == 0 {
        if !accumulate {
            for r in 0..m {
                for c in 0..n {
                    dst[r * dst_rs + c * dst_cs] = <T as crate::ops::Real>::of(0.0);
                }
            }
        }
        return;
    }
    let one = <T as crate::ops::Real>::of(1.0);
    let threads = rayon::current_num_threads();
    let parallelism = if threads > 1 {
        gemm::Parallelism::Rayon(threads)
    } else {
        gemm::Parallelism::None
    };
    // SAFETY: every element the product reads or writes lies inside its slice (checked above,
    // strides are non-negative), `dst` is borrowed mutably and so aliases neither input, and T
    // is f32 or f64, which `gemm` supports. Why not candle's matmul: it returns a fresh tensor,
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
}
