//! Raw CPU kernels on flat slices (no candle types), shared by the custom ops.
//!
//! Layout: the layers receive and return `[B, V, C]` (row-major). A sparse product gathers, for
//! each output vertex, the rows of its neighbours; in `[B, V, C]` each such row is only `C` values
//! (36 bytes for C = 9) at an address that, for a mesh whose vertex order has little locality
//! (elephant-gallop: median index gap 78, 90th percentile 21,000), is a cache miss. So the
//! kernels gather from a *channel-major* copy `[V, C, B]`, where one neighbour is `C·B`
//! contiguous values (1,152 bytes at B = 32), and per-vertex arithmetic runs its inner loops over
//! the batch (long, vectorisable) rather than over 9 channels.
//!
//! Work is split over chunks of [`CHUNK_ROWS`] vertices, one rayon task each. Batch-major inputs
//! and outputs are transposed chunk by chunk through a small staging buffer, batch slice by batch
//! slice, so memory is always read and written in long runs. The CSR arrays (a few MB even for
//! 42k vertices) stay in cache.
//!
//! SIMD: the hot per-chunk functions are compiled twice ([`multiversion`]): for AVX2 + FMA, used
//! when the CPU has them, and for the baseline target.

use crate::error::{ConvError, Result};
use crate::layout::{ChunkOut, Io, chunk_outs, to_channel_major};
pub(crate) use crate::workspace::Staging;
use crate::workspace::{Pools, Workspace};
use rayon::prelude::*;
use sparse_csr::CsrMatrix;
use std::ops::{Add, AddAssign, Mul, Sub};

/// Vertices per rayon task: a chunk's staging buffers (64 × 288 floats each at B = 32, C = 9)
/// stay in the core's L2 cache.
pub(crate) const CHUNK_ROWS: usize = 64;

/// The float types the kernels run on (f32 and f64).
pub trait Real:
    Copy
    + Send
    + Sync
    + 'static
    + PartialOrd
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + AddAssign
{
    const ZERO: Self;
    fn from_f64(v: f64) -> Self;
    fn to_f64(self) -> f64;
    fn abs(self) -> Self;
    /// self · a + b in one rounding (only fast where FMA instructions are enabled).
    fn mul_add(self, a: Self, b: Self) -> Self;
    /// The matrix values in this precision.
    fn values(csr: &Csr) -> &[Self];
    /// This type's buffers of a [`crate::Workspace`] (given both).
    fn pools<'a>(f32s: &'a Pools<f32>, f64s: &'a Pools<f64>) -> &'a Pools<Self>;
    /// dst[s·B + b] = runs[b][s] (see `transpose.rs`).
    fn gather_runs(runs: &[&[Self]], dst: &mut [Self]) {
        crate::transpose::gather_runs_scalar(runs, dst);
    }
    /// runs[b][s] = src[s·B + b] (see `transpose.rs`).
    fn scatter_runs(src: &[Self], runs: &mut [&mut [Self]]) {
        crate::transpose::scatter_runs_scalar(src, runs);
    }
    /// dst[c·R + r] = src[r·C + c] for an R × C block (see `transpose.rs`).
    fn transpose_block(src: &[Self], rows: usize, cols: usize, dst: &mut [Self]) {
        crate::transpose::transpose_block_scalar(src, rows, cols, dst);
    }
    /// A hand-vectorised [`crate::mix::mix`], if there is one for this type and CPU (false:
    /// nothing was done).
    fn mix_simd(
        _inps: &[&[Self]],
        _m: &[Self],
        _d: crate::mix::MixDims,
        _bias: Option<&[Self]>,
        _out: &mut [Self],
    ) -> bool {
        false
    }
    /// A hand-vectorised [`crate::mix::dot_chunk`], if there is one (false: nothing was done).
    fn dot_simd(
        _t: &[Self],
        _g: &[Self],
        _dims: (usize, usize, usize),
        _lanes: &mut [[Self; crate::mix::LANES]],
    ) -> bool {
        false
    }
}

impl Real for f32 {
    const ZERO: Self = 0.0;
    fn from_f64(v: f64) -> Self {
        v as f32
    }
    fn to_f64(self) -> f64 {
        f64::from(self)
    }
    fn abs(self) -> Self {
        f32::abs(self)
    }
    #[inline(always)]
    fn mul_add(self, a: Self, b: Self) -> Self {
        f32::mul_add(self, a, b)
    }
    #[inline(always)]
    fn values(csr: &Csr) -> &[Self] {
        &csr.values_f32
    }
    fn pools<'a>(f32s: &'a Pools<f32>, _: &'a Pools<f64>) -> &'a Pools<Self> {
        f32s
    }
    fn gather_runs(runs: &[&[Self]], dst: &mut [Self]) {
        crate::transpose::gather_runs_f32(runs, dst);
    }
    fn scatter_runs(src: &[Self], runs: &mut [&mut [Self]]) {
        crate::transpose::scatter_runs_f32(src, runs);
    }
    fn transpose_block(src: &[Self], rows: usize, cols: usize, dst: &mut [Self]) {
        crate::transpose::transpose_block_f32(src, rows, cols, dst);
    }
    fn mix_simd(
        inps: &[&[Self]],
        m: &[Self],
        d: crate::mix::MixDims,
        bias: Option<&[Self]>,
        out: &mut [Self],
    ) -> bool {
        crate::simd::mix_f32(inps, m, d, bias, out)
    }
    fn dot_simd(
        t: &[Self],
        g: &[Self],
        dims: (usize, usize, usize),
        lanes: &mut [[Self; crate::mix::LANES]],
    ) -> bool {
        crate::simd::dot_chunk_f32(t, g, dims, lanes)
    }
}

impl Real for f64 {
    const ZERO: Self = 0.0;
    fn from_f64(v: f64) -> Self {
        v
    }
    fn to_f64(self) -> f64 {
        self
    }
    fn abs(self) -> Self {
        f64::abs(self)
    }
    #[inline(always)]
    fn mul_add(self, a: Self, b: Self) -> Self {
        f64::mul_add(self, a, b)
    }
    #[inline(always)]
    fn values(csr: &Csr) -> &[Self] {
        csr.matrix.values()
    }
    fn pools<'a>(_: &'a Pools<f32>, f64s: &'a Pools<f64>) -> &'a Pools<Self> {
        f64s
    }
}

/// How a kernel spells a multiply-add: [`Plain`] (a·b + c, for any CPU) or [`Fused`] (one FMA
/// instruction; only used in code compiled with the `fma` target feature, where `mul_add` is an
/// instruction rather than a library call).
pub(crate) trait Madd {
    fn madd<T: Real>(a: T, b: T, c: T) -> T;
}

pub(crate) struct Plain;
pub(crate) struct Fused;

impl Madd for Plain {
    #[inline(always)]
    fn madd<T: Real>(a: T, b: T, c: T) -> T {
        a * b + c
    }
}

impl Madd for Fused {
    #[inline(always)]
    fn madd<T: Real>(a: T, b: T, c: T) -> T {
        a.mul_add(b, c)
    }
}

/// Defines `fn $name<T: Real>(args)` running `$body::<T, Fused>` compiled for AVX2 + FMA when
/// the CPU has both (std caches the check), else `$body::<T, Plain>` for the baseline target.
/// `$body` must be `#[inline(always)]` so that it is compiled inside each variant.
macro_rules! multiversion {
    ($(#[$meta:meta])* fn $name:ident<T>($($arg:ident: $ty:ty),* $(,)?) => $body:ident) => {
        $crate::kernel::multiversion!(
            $(#[$meta])* fn $name<T>($($arg: $ty),*) -> () => $body
        );
    };
    ($(#[$meta:meta])* fn $name:ident<T>($($arg:ident: $ty:ty),* $(,)?) -> $ret:ty => $body:ident) => {
        $(#[$meta])*
        fn $name<T: $crate::kernel::Real>($($arg: $ty),*) -> $ret {
            #[cfg(target_arch = "x86_64")]
            {
                $(#[$meta])*
                #[target_feature(enable = "avx2,fma")]
                fn fast<T: $crate::kernel::Real>($($arg: $ty),*) -> $ret {
                    $body::<T, $crate::kernel::Fused>($($arg),*)
                }
                if std::arch::is_x86_feature_detected!("avx2")
                    && std::arch::is_x86_feature_detected!("fma")
                    && !$crate::kernel::baseline_forced()
                {
                    // SAFETY: `fast` needs AVX2 and FMA, which this CPU was just found to have.
                    return unsafe { fast::<T>($($arg),*) };
                }
            }
            $body::<T, $crate::kernel::Plain>($($arg),*)
        }
    };
}
pub(crate) use multiversion;

/// Held by tests that set [`FORCE_BASELINE`] or need every call to take the same variant.
#[cfg(test)]
pub(crate) static BASELINE_LOCK: std::sync::Mutex<()> = std::sync::Mutex::new(());

/// Tests set this to run the baseline variants on a CPU that has AVX2 + FMA.
#[cfg(test)]
pub(crate) static FORCE_BASELINE: std::sync::atomic::AtomicBool =
    std::sync::atomic::AtomicBool::new(false);

#[inline(always)]
pub(crate) fn baseline_forced() -> bool {
    #[cfg(test)]
    {
        FORCE_BASELINE.load(std::sync::atomic::Ordering::Relaxed)
    }
    #[cfg(not(test))]
    {
        false
    }
}

/// A sparse matrix as the kernels read it: the [`CsrMatrix`] (pattern and f64 values) and its
/// values in f32, converted once at construction, never per call (`values_f32[e]` is always
/// `values()[e] as f32`).
#[derive(Debug)]
pub struct Csr {
    matrix: CsrMatrix,
    values_f32: Vec<f32>,
}

impl Csr {
    pub fn from_matrix(m: &CsrMatrix) -> Self {
        Self::new(m.clone())
    }

    fn new(matrix: CsrMatrix) -> Self {
        Self {
            values_f32: matrix.values().iter().map(|&v| v as f32).collect(),
            matrix,
        }
    }

    #[inline(always)]
    pub fn rows(&self) -> usize {
        self.matrix.rows()
    }

    #[inline(always)]
    pub fn cols(&self) -> usize {
        self.matrix.cols()
    }

    pub fn nnz(&self) -> usize {
        self.matrix.nnz()
    }

    /// The column indices of row `r` (the pattern alone).
    pub fn columns(&self, r: usize) -> &[u32] {
        self.matrix.row(r).0
    }

    /// The column of every non-zero, row after row.
    pub fn indices(&self) -> &[u32] {
        self.matrix.indices()
    }

    pub fn values_f32(&self) -> &[f32] {
        &self.values_f32
    }

    pub fn values_f64(&self) -> &[f64] {
        self.matrix.values()
    }

    /// Row `r` as (columns, values).
    #[inline(always)]
    pub fn row<T: Real>(&self, r: usize) -> (&[u32], &[T]) {
        let indptr = self.matrix.indptr();
        let span = indptr[r]..indptr[r + 1];
        (&self.matrix.indices()[span.clone()], &T::values(self)[span])
    }

    /// The matrix with renumbered rows and columns ([`CsrMatrix::permuted`]): row p of the result
    /// is row `rows[p]` of this one, and column `c` becomes the position of `c` in the column
    /// order (`col_pos`, the inverse of that order). `None` keeps the numbering. Each row's
    /// entries are sorted by their new column. Errors: orders that are not permutations.
    pub fn permuted(
        &self,
        rows: Option<&[u32]>,
        col_pos: Option<&[u32]>,
        (op, arg): (&'static str, &'static str),
    ) -> Result<Self> {
        let matrix = self
            .matrix
            .permuted(rows, col_pos)
            .map_err(|e| ConvError::argument(op, arg, e.to_string()))?;
        Ok(Self::new(matrix))
    }
}

/// The first vertex of chunk `chunk` and its vertex count, for `v` vertices.
#[inline(always)]
pub(crate) fn chunk_span(chunk: usize, v: usize) -> (usize, usize) {
    let i0 = chunk * CHUNK_ROWS;
    (i0, CHUNK_ROWS.min(v.saturating_sub(i0)))
}

/// acc = Σ_j a[row, j] · src[j, :] over one row's non-zeros; `src` is `[V, n]`.
#[inline(always)]
pub(crate) fn gather_row<T: Real, M: Madd>(
    cols: &[u32],
    vals: &[T],
    src: &[T],
    n: usize,
    acc: &mut [T],
) {
    let mut nonzeros = cols.iter().zip(vals);
    // The first product initialises acc (no separate zeroing pass over it).
    match nonzeros.next() {
        None => acc.fill(T::ZERO),
        Some((&j, &v)) => {
            for (z, &s) in acc.iter_mut().zip(&src[j as usize * n..][..n]) {
                *z = v * s;
            }
        }
    }
    for (&j, &v) in nonzeros {
        for (z, &s) in acc.iter_mut().zip(&src[j as usize * n..][..n]) {
            *z = M::madd(v, s, *z);
        }
    }
}

/// out[i, :] = alpha · Σ_j a[i, j] · src[j, :] + beta · prev[i, :] (no `prev`: 0), every row `n`
/// values wide: `src` is `[a.cols, n]`, `out` and `prev` `[a.rows, n]`.
pub(crate) fn spmm_axpby<T: Real>(
    a: &Csr,
    alpha: T,
    src: &[T],
    beta: T,
    prev: Option<&[T]>,
    out: &mut [T],
    n: usize,
) {
    if n == 0 || a.rows() == 0 {
        return;
    }
    out.par_chunks_mut(CHUNK_ROWS * n)
        .enumerate()
        .for_each(|(chunk, out)| spmm_chunk(a, (alpha, beta), src, prev, out, n, chunk));
}

multiversion!(
    #[allow(clippy::too_many_arguments)]
    fn spmm_chunk<T>(
        a: &Csr,
        coefficients: (T, T),
        src: &[T],
        prev: Option<&[T]>,
        out: &mut [T],
        n: usize,
        chunk: usize,
    ) => spmm_chunk_body
);

#[inline(always)]
fn spmm_chunk_body<T: Real, M: Madd>(
    a: &Csr,
    (alpha, beta): (T, T),
    src: &[T],
    prev: Option<&[T]>,
    out: &mut [T],
    n: usize,
    chunk: usize,
) {
    let unit = alpha.to_f64() == 1.0;
    let i0 = chunk * CHUNK_ROWS;
    for (li, y) in out.chunks_exact_mut(n).enumerate() {
        let i = i0 + li;
        let (cols, vals) = a.row::<T>(i);
        gather_row::<T, M>(cols, vals, src, n, y);
        if !unit {
            y.iter_mut().for_each(|z| *z = alpha * *z);
        }
        if let Some(prev) = prev {
            for (z, &p) in y.iter_mut().zip(&prev[i * n..][..n]) {
                *z = M::madd(beta, p, *z);
            }
        }
    }
}

/// The chunk of vertices `i0 .. i0 + cnt` of a `[B, V, c]` array as channel-major blocks:
/// `buf[(li·c + o)·B + b] = x[b, i0 + li, o]` (each batch slice's part is one long run).
#[inline(always)]
pub(crate) fn load_chunk<T: Real>(
    x: &[T],
    (batch, v, c): (usize, usize, usize),
    (i0, cnt): (usize, usize),
    buf: &mut [T],
) {
    let runs: Vec<&[T]> = (0..batch)
        .map(|b| &x[(b * v + i0) * c..][..cnt * c])
        .collect();
    T::gather_runs(&runs, &mut buf[..cnt * c * batch]);
}

/// y = A x for x `[B, A.cols, c]`, returning `[B, A.rows, c]` (through a channel-major copy of
/// x when B > 1; for B = 1 the layouts coincide and the rows are gathered directly).
pub(crate) fn spmm_batch_major<T: Real>(
    a: &Csr,
    x: &[T],
    (batch, c): (usize, usize),
    ws: &Workspace,
) -> Vec<T> {
    let mut y = vec![T::ZERO; batch * a.rows() * c];
    if batch <= 1 {
        spmm_axpby(a, T::from_f64(1.0), x, T::ZERO, None, &mut y, c);
        return y;
    }
    let xcm = to_channel_major(x, Io::BatchMajor, (batch, a.cols(), c), ws);
    chunk_outs(&mut y, Io::BatchMajor, (batch, a.rows(), c))
        .into_par_iter()
        .enumerate()
        .for_each_init(
            || Staging::new(ws),
            |staging, (chunk, dest)| gather_chunk(a, &xcm, batch * c, chunk, dest, staging),
        );
    ws.give(xcm);
    y
}

multiversion!(
    fn gather_chunk<T>(
        a: &Csr,
        src: &[T],
        n: usize,
        chunk: usize,
        dest: ChunkOut<'_, T>,
        staging: &mut Staging<'_, T>,
    ) => gather_chunk_body
);

#[inline(always)]
fn gather_chunk_body<T: Real, M: Madd>(
    a: &Csr,
    src: &[T],
    n: usize,
    chunk: usize,
    mut dest: ChunkOut<'_, T>,
    staging: &mut Staging<'_, T>,
) {
    let (i0, cnt) = chunk_span(chunk, a.rows());
    let [blocks, _, _] = staging.get([cnt * n, 0, 0]);
    for (li, acc) in blocks.chunks_exact_mut(n).enumerate() {
        let (cols, vals) = a.row::<T>(i0 + li);
        gather_row::<T, M>(cols, vals, src, n, acc);
    }
    dest.store(blocks);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_util::{dense_apply, random_matrix, random_vec};

    #[test]
    fn spmm_axpby_matches_dense_for_several_row_widths() {
        let m = random_matrix(130, 170, 0.05, 1);
        let a = Csr::from_matrix(&m);
        for n in [1usize, 3, 9, 4] {
            let src = random_vec(170 * n, 2);
            let prev = random_vec(130 * n, 3);
            let mut out = vec![0.0f64; 130 * n];
            spmm_axpby(&a, 2.0, &src, -0.5, Some(&prev), &mut out, n);
            let want = dense_apply(&m, &src, 1, n);
            for (k, (&o, &w)) in out.iter().zip(&want).enumerate() {
                assert!((o - (2.0 * w - 0.5 * prev[k])).abs() < 1e-12, "n={n} k={k}");
            }
            let src32: Vec<f32> = src.iter().map(|&v| v as f32).collect();
            let mut out32 = vec![0.0f32; 130 * n];
            spmm_axpby(&a, 1.0, &src32, 0.0, None, &mut out32, n);
            for (&o, &w) in out32.iter().zip(&want) {
                assert!((f64::from(o) - w).abs() < 1e-5);
            }
        }
    }

    #[test]
    fn batch_major_product_and_channel_major_copy_match_dense() {
        let m = random_matrix(300, 270, 0.02, 4);
        let a = Csr::from_matrix(&m);
        for (batch, c) in [(1usize, 3usize), (3, 9), (2, 5)] {
            let x = random_vec(batch * 270 * c, 5);
            let want = dense_apply(&m, &x, batch, c);
            let ws = Workspace::new();
            let y = spmm_batch_major(&a, &x, (batch, c), &ws);
            assert!(
                y.iter().zip(&want).all(|(p, q)| (p - q).abs() < 1e-12),
                "B={batch}"
            );
            // x[b, i, o] sits at cm[i, o, b].
            let cm = to_channel_major(&x, Io::BatchMajor, (batch, 270, c), &ws);
            for (b, i, o) in [(0, 0, 0), (batch - 1, 7, c - 1), (batch / 2, 269, c / 2)] {
                assert_eq!(cm[(i * c + o) * batch + b], x[(b * 270 + i) * c + o]);
            }
        }
    }
}
