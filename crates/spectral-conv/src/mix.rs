//! The dense per-vertex arithmetic of the Chebyshev kernels, on channel-major `[C, B]` blocks:
//! channel mixing (out = Σ_k T_k W_k, the bulk of the multiply-adds) and the weight gradient's
//! batch dot products (dW_k = Σ T_kᵀ g).
//!
//! Register tiles: a mixing tile holds 4 × 8 batch lanes × 3 outputs (12 accumulators, 4 input
//! loads and 3 weight broadcasts per input row); a dot tile holds 3 inputs × 3 outputs × 8
//! lanes and walks a whole chunk of vertices before it is written back. Both keep the loads per
//! multiply-add low enough for the FMA units, not the load ports, to set the pace.

use crate::kernel::{Madd, Real};

/// Batch lanes per accumulator (one AVX register of f32).
pub(crate) const LANES: usize = 8;

/// Dimensions of one mixing call: `p` outputs, `batch` lanes per row.
#[derive(Clone, Copy)]
pub struct MixDims {
    pub p: usize,
    pub batch: usize,
}

/// out `[p, B]` = bias + Σ_inputs Σ_q m[q, :] ⊗ inp[q, :], where the rows q of `m` (`p` weights
/// each) run over the inputs' rows in order (`inps[0]`'s rows first). Every input is `[Q_i, B]`.
#[inline(always)]
pub(crate) fn mix<T: Real, M: Madd>(
    inps: &[&[T]],
    m: &[T],
    d: MixDims,
    bias: Option<&[T]>,
    out: &mut [T],
) {
    if T::mix_simd(inps, m, d, bias, out) {
        return;
    }
    let MixDims { p, batch } = d;
    let wide = std::mem::size_of::<T>() <= 4;
    let mut o0 = 0;
    while o0 < p {
        let o_n = if p - o0 >= 3 { 3 } else { 1 };
        let mut lb = 0;
        while lb < batch {
            let left = batch - lb;
            lb += match (o_n, left) {
                (3, 32..) if wide => mix_tile::<T, M, 4, 3>(inps, m, d, (o0, lb), bias, out),
                (3, 16..) => mix_tile::<T, M, 2, 3>(inps, m, d, (o0, lb), bias, out),
                (3, 8..) => mix_tile::<T, M, 1, 3>(inps, m, d, (o0, lb), bias, out),
                (_, 8..) => mix_tile::<T, M, 1, 1>(inps, m, d, (o0, lb), bias, out),
                _ => mix_tail::<T, M>(inps, m, d, (o0, o_n, lb), bias, out),
            };
        }
        o0 += o_n;
    }
}

/// G × 8 lanes from `lb` of outputs `o0 .. o0 + O`; returns the lanes done.
#[inline(always)]
fn mix_tile<T: Real, M: Madd, const G: usize, const O: usize>(
    inps: &[&[T]],
    m: &[T],
    MixDims { p, batch }: MixDims,
    (o0, lb): (usize, usize),
    bias: Option<&[T]>,
    out: &mut [T],
) -> usize {
    let mut acc = [[[T::ZERO; LANES]; G]; O];
    if let Some(b) = bias {
        for (a, &bo) in acc.iter_mut().zip(&b[o0..o0 + O]) {
            *a = [[bo; LANES]; G];
        }
    }
    let mut q_base = 0;
    for inp in inps {
        let q_n = inp.len() / batch;
        for q in 0..q_n {
            // Plain indexing on fixed-length slices keeps `acc` in registers.
            let row = &inp[q * batch + lb..][..G * LANES];
            let w = &m[(q_base + q) * p + o0..][..O];
            for o in 0..O {
                let wv = w[o];
                for gi in 0..G {
                    for l in 0..LANES {
                        acc[o][gi][l] = M::madd(row[gi * LANES + l], wv, acc[o][gi][l]);
                    }
                }
            }
        }
        q_base += q_n;
    }
    for (o, a) in acc.iter().enumerate() {
        let dst = &mut out[(o0 + o) * batch + lb..][..G * LANES];
        for (d, ag) in dst.chunks_exact_mut(LANES).zip(a) {
            d.copy_from_slice(ag);
        }
    }
    G * LANES
}

/// The last (fewer than 8) lanes from `lb` of outputs `o0 .. o0 + o_n`, one at a time.
#[inline(always)]
fn mix_tail<T: Real, M: Madd>(
    inps: &[&[T]],
    m: &[T],
    MixDims { p, batch }: MixDims,
    (o0, o_n, lb): (usize, usize, usize),
    bias: Option<&[T]>,
    out: &mut [T],
) -> usize {
    for o in o0..o0 + o_n {
        for b in lb..batch {
            let mut z = bias.map_or(T::ZERO, |bias| bias[o]);
            let mut q_base = 0;
            for inp in inps {
                let q_n = inp.len() / batch;
                for q in 0..q_n {
                    z = M::madd(inp[q * batch + b], m[(q_base + q) * p + o], z);
                }
                q_base += q_n;
            }
            out[o * batch + b] = z;
        }
    }
    batch - lb
}

/// lanes[f·co + o][l] += Σ_v Σ_j t[v, f, j·8 + l] · g[v, o, j·8 + l] over a chunk of vertex
/// blocks (`t` `[cnt, ci, B]`, `g` `[cnt, co, B]`); the batch tail (B mod 8) goes to the first
/// lanes. Float sums are never reassociated across runs: the order is fixed by the loops.
#[inline(always)]
pub(crate) fn dot_chunk<T: Real, M: Madd>(
    t: &[T],
    g: &[T],
    (ci, co, batch): (usize, usize, usize),
    lanes: &mut [[T; LANES]],
) {
    if batch == 0 || T::dot_simd(t, g, (ci, co, batch), lanes) {
        return;
    }
    let three = std::mem::size_of::<T>() <= 4;
    let mut f0 = 0;
    while f0 < ci {
        let f_n = if three && ci - f0 >= 3 { 3 } else { 1 };
        let mut o0 = 0;
        while o0 < co {
            let o_n = if co - o0 >= 3 { 3 } else { 1 };
            let dims = (ci, co, batch);
            match (f_n, o_n) {
                (3, 3) => dot_tile::<T, M, 3, 3>(t, g, dims, (f0, o0), lanes),
                (3, _) => dot_tile::<T, M, 3, 1>(t, g, dims, (f0, o0), lanes),
                (_, 3) => dot_tile::<T, M, 1, 3>(t, g, dims, (f0, o0), lanes),
                _ => dot_tile::<T, M, 1, 1>(t, g, dims, (f0, o0), lanes),
            }
            o0 += o_n;
        }
        f0 += f_n;
    }
}

#[inline(always)]
fn dot_tile<T: Real, M: Madd, const F: usize, const O: usize>(
    t: &[T],
    g: &[T],
    (ci, co, batch): (usize, usize, usize),
    (f0, o0): (usize, usize),
    lanes: &mut [[T; LANES]],
) {
    let full = batch - batch % LANES;
    let mut acc = [[[T::ZERO; LANES]; O]; F];
    for (f, a) in acc.iter_mut().enumerate() {
        a.copy_from_slice(&lanes[(f0 + f) * co + o0..][..O]);
    }
    for (tb, gb) in t.chunks_exact(ci * batch).zip(g.chunks_exact(co * batch)) {
        for lb in (0..full).step_by(LANES) {
            // Plain indexing on fixed-length slices: the optimiser then keeps `acc` in registers
            // (array-building closures here were left un-inlined, and `acc` on the stack).
            for (f, a) in acc.iter_mut().enumerate() {
                let tf = &tb[(f0 + f) * batch + lb..][..LANES];
                for (o, ao) in a.iter_mut().enumerate() {
                    let go = &gb[(o0 + o) * batch + lb..][..LANES];
                    for l in 0..LANES {
                        ao[l] = M::madd(tf[l], go[l], ao[l]);
                    }
                }
            }
        }
        for (f, a) in acc.iter_mut().enumerate() {
            let tf = &tb[(f0 + f) * batch + full..(f0 + f + 1) * batch];
            for (o, ao) in a.iter_mut().enumerate() {
                let go = &gb[(o0 + o) * batch + full..(o0 + o + 1) * batch];
                for ((z, &x), &y) in ao.iter_mut().zip(tf).zip(go) {
                    *z = M::madd(x, y, *z);
                }
            }
        }
    }
    for (f, a) in acc.iter().enumerate() {
        lanes[(f0 + f) * co + o0..][..O].copy_from_slice(a);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kernel::Plain;
    use crate::test_util::random_vec;

    #[test]
    fn mixing_and_dot_products_match_plain_loops_for_ragged_sizes() {
        for (batch, p, q) in [
            (32usize, 9usize, 9usize),
            (45, 9, 4),
            (13, 7, 5),
            (3, 2, 1),
            (8, 1, 3),
            (22, 9, 9),
            (7, 9, 3),
        ] {
            let a = random_vec(q * batch, 1);
            let b = random_vec(2 * q * batch, 2);
            let m = random_vec(3 * q * p, 3);
            let bias = random_vec(p, 4);
            let mut out = vec![0.0; p * batch];
            let d = MixDims { p, batch };
            mix::<f64, Plain>(&[&a, &b], &m, d, Some(&bias), &mut out);
            // f32 runs the AVX2 tiles where the CPU has them, ragged batches ending masked.
            let f32s = |v: &[f64]| v.iter().map(|&x| x as f32).collect::<Vec<f32>>();
            let mut out32 = vec![0.0f32; p * batch];
            let (a32, b32) = (f32s(&a), f32s(&b));
            mix::<f32, Plain>(&[&a32, &b32], &f32s(&m), d, Some(&f32s(&bias)), &mut out32);
            for o in 0..p {
                for l in 0..batch {
                    let mut want = bias[o];
                    for r in 0..3 * q {
                        let x = if r < q {
                            a[r * batch + l]
                        } else {
                            b[(r - q) * batch + l]
                        };
                        want += x * m[r * p + o];
                    }
                    assert!((out[o * batch + l] - want).abs() < 1e-12, "B={batch} p={p}");
                    let got32 = f64::from(out32[o * batch + l]);
                    assert!((got32 - want).abs() < 1e-4, "f32 B={batch} p={p}");
                }
            }
            // dot_chunk over 3 vertices: t [3, q, B], g [3, p, B].
            let t = random_vec(3 * q * batch, 5);
            let g = random_vec(3 * p * batch, 6);
            let mut lanes = vec![[0.0; LANES]; q * p];
            dot_chunk::<f64, Plain>(&t, &g, (q, p, batch), &mut lanes);
            let mut lanes32 = vec![[0.0f32; LANES]; q * p];
            let (t32, g32): (Vec<f32>, Vec<f32>) = (
                t.iter().map(|&v| v as f32).collect(),
                g.iter().map(|&v| v as f32).collect(),
            );
            dot_chunk::<f32, Plain>(&t32, &g32, (q, p, batch), &mut lanes32);
            for f in 0..q {
                for o in 0..p {
                    let mut want = 0.0;
                    for v in 0..3 {
                        for l in 0..batch {
                            want += t[(v * q + f) * batch + l] * g[(v * p + o) * batch + l];
                        }
                    }
                    let got: f64 = lanes[f * p + o].iter().sum();
                    assert!((got - want).abs() < 1e-12, "B={batch} f={f} o={o}");
                    let got32: f32 = lanes32[f * p + o].iter().sum();
                    assert!(
                        (f64::from(got32) - want).abs() < 1e-4,
                        "f32 B={batch} f={f}"
                    );
                }
            }
        }
    }
}
