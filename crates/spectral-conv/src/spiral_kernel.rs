//! The spiral convolution's CPU passes on slices: y = gather(x) · W and its gradients, a block
//! of rows at a time. The gathered matrix `[B·V, S·C]` (S times the input: 213 MB for 32
//! channels of a batch of 32 horses) never exists whole; each block of it lives in a buffer
//! that stays in cache while `gemm` uses it, and the input's gradient is scattered from the
//! block of ∂L/∂(gathered) that was just made.
//!
//! Every sum is taken in an order that depends on the sizes only, never on the threads: the
//! input's gradient is accumulated per batch item in vertex order, and the weight gradient's
//! partial products over fixed spans of rows are added in span order.

use crate::kernel::Real;
use rayon::prelude::*;

/// Rows (vertex of one batch item) per gathered block: 256 × S·C values, 295 KB of f32 for
/// spirals of 9 over 32 channels, well inside the L2 cache.
const BLOCK: usize = 256;

/// Rows per partial weight gradient (a multiple of [`BLOCK`]); the partials are `S·C × C_out`
/// each (36 KB for 288 × 32 in f32).
const SPAN: usize = 16 * BLOCK;

/// Sizes of one spiral convolution.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct SpiralDims {
    pub batch: usize,
    pub vertices: usize,
    pub c_in: usize,
    /// Spiral length S (vertices per spiral, the vertex itself first).
    pub length: usize,
    pub c_out: usize,
}

impl SpiralDims {
    /// Width of a gathered row, S·C_in.
    fn width(&self) -> usize {
        self.length * self.c_in
    }
}

/// Gathers rows `first .. first + rows` of the flattened `[B·V]` rows: row (b, v) is x's
/// values at the spiral of v, `[S·C]` (index s·C + c).
fn gather<T: Real>(
    x: &[T],
    spirals: &[u32],
    d: SpiralDims,
    first: usize,
    rows: usize,
    out: &mut [T],
) {
    let (c, s_len) = (d.c_in, d.length);
    for (r, row) in out.chunks_exact_mut(d.width()).take(rows).enumerate() {
        let (b, v) = ((first + r) / d.vertices, (first + r) % d.vertices);
        let xb = &x[b * d.vertices * c..][..d.vertices * c];
        let spiral = &spirals[v * s_len..][..s_len];
        for (dst, &u) in row.chunks_exact_mut(c).zip(spiral) {
            dst.copy_from_slice(&xb[u as usize * c..][..c]);
        }
    }
}

/// y `[B·V, C_out]` = gather(x) · w for x `[B, V, C_in]`, w `[S·C_in, C_out]`.
pub(crate) fn forward<T: Real>(x: &[T], spirals: &[u32], w: &[T], d: SpiralDims) -> Vec<T> {
    let (width, c_out) = (d.width(), d.c_out);
    let mut y = vec![T::ZERO; d.batch * d.vertices * c_out];
    if c_out == 0 {
        return y;
    }
    y.par_chunks_mut(BLOCK * c_out)
        .enumerate()
        .for_each_init(Vec::new, |g, (block, yb)| {
            let rows = yb.len() / c_out;
            g.resize(rows * width, T::ZERO);
            gather(x, spirals, d, block * BLOCK, rows, g);
            let lhs = View::row_major(g, width);
            let rhs = View::row_major(w, c_out);
            product(yb, (c_out, 1), lhs, rhs, (rows, c_out, width), false);
        });
    y
}

/// The gradients the caller asked for.
pub(crate) struct SpiralGrads<T> {
    /// `[B, V, C_in]`.
    pub dx: Option<Vec<T>>,
    /// `[S·C_in, C_out]`.
    pub dw: Option<Vec<T>>,
}

/// ∂L/∂x and ∂L/∂w of [`forward`] from g = ∂L/∂y `[B·V, C_out]`.
pub(crate) fn backward<T: Real>(
    x: &[T],
    spirals: &[u32],
    w: &[T],
    g: &[T],
    d: SpiralDims,
    (need_x, need_w): (bool, bool),
) -> SpiralGrads<T> {
    SpiralGrads {
        dx: need_x.then(|| grad_x(spirals, w, g, d)),
        dw: need_w.then(|| grad_w(x, spirals, g, d)),
    }
}

/// ∂L/∂x: per batch item (each owns its slice of dx), blocks of ∂L/∂(gathered) = g · wᵀ
/// scattered back to the vertices they were gathered from, in vertex order.
fn grad_x<T: Real>(spirals: &[u32], w: &[T], g: &[T], d: SpiralDims) -> Vec<T> {
    let (width, c, c_out, v_n) = (d.width(), d.c_in, d.c_out, d.vertices);
    let mut dx = vec![T::ZERO; d.batch * v_n * c];
    if v_n == 0 || c == 0 {
        return dx;
    }
    dx.par_chunks_mut(v_n * c)
        .enumerate()
        .for_each_init(Vec::new, |dg, (b, dxb)| {
            for v0 in (0..v_n).step_by(BLOCK) {
                let rows = BLOCK.min(v_n - v0);
                dg.resize(rows * width, T::ZERO);
                let lhs = View::row_major(&g[(b * v_n + v0) * c_out..], c_out);
                let rhs = View::col_major(w, c_out);
                product(dg, (width, 1), lhs, rhs, (rows, width, c_out), false);
                for (r, row) in dg.chunks_exact(width).take(rows).enumerate() {
                    let spiral = &spirals[(v0 + r) * d.length..][..d.length];
                    for (part, &u) in row.chunks_exact(c).zip(spiral) {
                        let dst = &mut dxb[u as usize * c..][..c];
                        for (a, &p) in dst.iter_mut().zip(part) {
                            *a += p;
                        }
                    }
                }
            }
        });
    dx
}

/// ∂L/∂w = gather(x)ᵀ · g: one partial product per span of rows (blocks gathered again, in
/// cache), the partials added in span order.
fn grad_w<T: Real>(x: &[T], spirals: &[u32], g: &[T], d: SpiralDims) -> Vec<T> {
    let (width, c_out) = (d.width(), d.c_out);
    let rows = d.batch * d.vertices;
    let size = width * c_out;
    let partials: Vec<Vec<T>> = (0..rows.div_ceil(SPAN))
        .into_par_iter()
        .map_init(Vec::new, |gathered, span| {
            let mut part = vec![T::ZERO; size];
            let end = (span * SPAN + SPAN).min(rows);
            for first in (span * SPAN..end).step_by(BLOCK) {
                let n = BLOCK.min(end - first);
                gathered.resize(n * width, T::ZERO);
                gather(x, spirals, d, first, n, gathered);
                let lhs = View::col_major(gathered, width);
                let rhs = View::row_major(&g[first * c_out..], c_out);
                product(&mut part, (c_out, 1), lhs, rhs, (width, c_out, n), true);
            }
            part
        })
        .collect();
    let mut dw = vec![T::ZERO; size];
    for part in &partials {
        for (a, &p) in dw.iter_mut().zip(part) {
            *a += p;
        }
    }
    dw
}

/// A matrix view: element (r, c) at `data[r·rs + c·cs]`.
#[derive(Clone, Copy)]
struct View<'a, T> {
    data: &'a [T],
    rs: usize,
    cs: usize,
}

impl<'a, T> View<'a, T> {
    fn row_major(data: &'a [T], cols: usize) -> Self {
        Self {
            data,
            rs: cols,
            cs: 1,
        }
    }

    /// A column-major matrix with `rows` rows (the transpose of a row-major one with `rows`
    /// columns): element (r, c) at `data[c·rows + r]`.
    fn col_major(data: &'a [T], rows: usize) -> Self {
        Self {
            data,
            rs: 1,
            cs: rows,
        }
    }
}

/// The last index an `rows × cols` view with strides (rs, cs) touches, plus one.
fn extent(rows: usize, cols: usize, rs: usize, cs: usize) -> usize {
    match rows == 0 || cols == 0 {
        true => 0,
        false => (rows - 1) * rs + (cols - 1) * cs + 1,
    }
}

/// dst (m × n) = [dst +] lhs (m × k) · rhs (k × n) with `gemm` on the calling thread (the
/// callers run blocks in parallel). Panics if a view does not fit its slice: the callers size
/// every buffer from the same dimensions, so that is an internal error.
fn product<T: Real>(
    dst: &mut [T],
    (dst_rs, dst_cs): (usize, usize),
    lhs: View<'_, T>,
    rhs: View<'_, T>,
    (m, n, k): (usize, usize, usize),
    accumulate: bool,
) {
    assert!(extent(m, n, dst_rs, dst_cs) <= dst.len(), "spiral: dst");
    assert!(
        extent(m, k, lhs.rs, lhs.cs) <= lhs.data.len(),
        "spiral: lhs"
    );
    assert!(
        extent(k, n, rhs.rs, rhs.cs) <= rhs.data.len(),
        "spiral: rhs"
    );
    if m == 0 || n == 0 {
        return;
    }
    if k == 0 {
        if !accumulate {
            dst.iter_mut().for_each(|a| *a = T::ZERO);
        }
        return;
    }
    // SAFETY: every view lies inside its slice (asserted above; strides are non-negative),
    // `dst` is borrowed mutably and so aliases neither input, and `Real` is f32 or f64, both
    // of which `gemm` supports.
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
            T::from_f64(1.0),
            T::from_f64(1.0),
            false,
            false,
            false,
            gemm::Parallelism::None,
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_util::random_vec;

    /// Dense reference in f64: the gathered matrix whole.
    fn reference(x: &[f64], spirals: &[u32], w: &[f64], d: SpiralDims) -> Vec<f64> {
        let (v_n, c, s_len, c_out) = (d.vertices, d.c_in, d.length, d.c_out);
        let mut y = vec![0.0; d.batch * v_n * c_out];
        for b in 0..d.batch {
            for v in 0..v_n {
                for o in 0..c_out {
                    let mut sum = 0.0;
                    for s in 0..s_len {
                        let u = spirals[v * s_len + s] as usize;
                        for ci in 0..c {
                            sum += x[(b * v_n + u) * c + ci] * w[(s * c + ci) * c_out + o];
                        }
                    }
                    y[(b * v_n + v) * c_out + o] = sum;
                }
            }
        }
        y
    }

    #[test]
    fn blocks_spans_and_scatter_match_the_whole_gathered_matrix() {
        // More rows than a span, a partial last block, repeated vertices in a spiral.
        let d = SpiralDims {
            batch: 3,
            vertices: 1500,
            c_in: 2,
            length: 4,
            c_out: 3,
        };
        let spirals: Vec<u32> = (0..d.vertices * d.length)
            .map(|i| {
                let (v, s) = (i / d.length, i % d.length);
                ((v * 7 + s * s * 13) % d.vertices) as u32
            })
            .collect();
        let x = random_vec(d.batch * d.vertices * d.c_in, 1);
        let w = random_vec(d.length * d.c_in * d.c_out, 2);
        let g = random_vec(d.batch * d.vertices * d.c_out, 3);
        let y = forward(&x, &spirals, &w, d);
        let want = reference(&x, &spirals, &w, d);
        let worst = y
            .iter()
            .zip(&want)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        assert!(worst < 1e-12, "forward off by {worst}");
        // The gradients as the transposes of the dense map y = M x and y = N w.
        let grads = backward(&x, &spirals, &w, &g, d, (true, true));
        let (dx, dw) = (grads.dx.unwrap(), grads.dw.unwrap());
        let mut want_dx = vec![0.0; x.len()];
        let mut want_dw = vec![0.0; w.len()];
        let (v_n, c, s_len, c_out) = (d.vertices, d.c_in, d.length, d.c_out);
        for b in 0..d.batch {
            for v in 0..v_n {
                for s in 0..s_len {
                    let u = spirals[v * s_len + s] as usize;
                    for ci in 0..c {
                        for o in 0..c_out {
                            let gy = g[(b * v_n + v) * c_out + o];
                            want_dx[(b * v_n + u) * c + ci] += gy * w[(s * c + ci) * c_out + o];
                            want_dw[(s * c + ci) * c_out + o] += gy * x[(b * v_n + u) * c + ci];
                        }
                    }
                }
            }
        }
        for (got, want, what) in [(&dx, &want_dx, "dx"), (&dw, &want_dw, "dw")] {
            let scale = want.iter().fold(1.0f64, |m, a| m.max(a.abs()));
            let worst = got
                .iter()
                .zip(want)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max);
            assert!(worst < 1e-12 * scale, "{what} off by {worst}");
        }
        // Only what was asked for.
        let none = backward(&x, &spirals, &w, &g, d, (false, true));
        assert!(none.dx.is_none() && none.dw.is_some());
    }

    #[test]
    fn results_do_not_depend_on_the_thread_count() {
        let d = SpiralDims {
            batch: 4,
            vertices: 2000,
            c_in: 3,
            length: 5,
            c_out: 4,
        };
        let spirals: Vec<u32> = (0..d.vertices * d.length)
            .map(|i| ((i * 31 + 7) % d.vertices) as u32)
            .collect();
        let x: Vec<f32> = random_vec(d.batch * d.vertices * d.c_in, 4)
            .iter()
            .map(|&a| a as f32)
            .collect();
        let w: Vec<f32> = random_vec(d.length * d.c_in * d.c_out, 5)
            .iter()
            .map(|&a| a as f32)
            .collect();
        let g: Vec<f32> = random_vec(d.batch * d.vertices * d.c_out, 6)
            .iter()
            .map(|&a| a as f32)
            .collect();
        let run = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            pool.install(|| {
                let y = forward(&x, &spirals, &w, d);
                let gr = backward(&x, &spirals, &w, &g, d, (true, true));
                (y, gr.dx.unwrap(), gr.dw.unwrap())
            })
        };
        assert!(run(1) == run(3), "the bits changed with the thread count");
    }
}
