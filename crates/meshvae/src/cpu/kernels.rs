//! The engine's element-wise passes on `[V, C, B]` buffers (vertex i, channel c, batch b at
//! `(i·C + c)·B + b`): layout changes, batch norm fused with tanh, tanh, the squared error.
//! Reductions sum fixed chunks of vertices in f64 and add the partial sums in chunk order, so
//! results do not depend on the thread count.

use super::{Real, f64_of, of};
use crate::numerics::wide::wide;
use rayon::prelude::*;

/// Vertices per parallel chunk.
const CHUNK_V: usize = 256;

/// x `[B, V, C]` → out `[V, C, B]`.
pub(super) fn to_vcb<T: Real>(
    x: &[T],
    out: &mut [T],
    (batch, v, c): (usize, usize, usize),
    order: Option<&[u32]>,
) {
    let n = c * batch;
    out.par_chunks_mut(CHUNK_V * n)
        .enumerate()
        .for_each(|(chunk, o)| {
            // Mesh by mesh: each reads one run of x (contiguous unless renumbered), and the
            // chunk it scatters into stays in cache (vertex by vertex, the batch's B distant
            // rows were read at once).
            let i0 = chunk * CHUNK_V;
            for b in 0..batch {
                let mesh = &x[b * v * c..][..v * c];
                for (li, block) in o.chunks_exact_mut(n).enumerate() {
                    let i = order.map_or(i0 + li, |o| o[i0 + li] as usize);
                    for (ch, &val) in mesh[i * c..][..c].iter().enumerate() {
                        block[ch * batch + b] = val;
                    }
                }
            }
        });
}

/// x `[V, C, B]` → out `[B, V, C]`, undoing [`to_vcb`]'s vertex order (`order[p]`: the
/// template vertex at position p).
pub(super) fn from_vcb<T: Real>(
    x: &[T],
    out: &mut [T],
    (batch, v, c): (usize, usize, usize),
    order: Option<&[u32]>,
) {
    out.par_chunks_mut(v * c).enumerate().for_each(|(b, mesh)| {
        for p in 0..v {
            let i = order.map_or(p, |o| o[p] as usize);
            for ch in 0..c {
                mesh[i * c + ch] = x[(p * c + ch) * batch + b];
            }
        }
    });
}

/// Eight running f64 sums: value i of a run goes to lane i mod 8. One serial f64 sum is a chain
/// of dependent adds (four cycles each); eight independent ones vectorise.
type Lanes = [f64; 8];

/// Σ f(run[i]) in eight lanes, in a local array (so that the lanes stay in registers).
#[inline(always)]
fn run_lanes<T: Real>(run: &[T], f: impl Fn(f64) -> f64) -> Lanes {
    let mut acc = [0.0; 8];
    let blocks = run.chunks_exact(8);
    let tail = blocks.remainder();
    for block in blocks {
        for (l, &v) in acc.iter_mut().zip(block) {
            *l += f(f64_of(v));
        }
    }
    for (l, &v) in acc.iter_mut().zip(tail) {
        *l += f(f64_of(v));
    }
    acc
}

/// Per-channel sums over a `[V, C, B]` array of the values, or (`shift` given) of their
/// squared distances to the channel's shift; chunk partials added in order.
fn channel_sums<T: Real>(x: &[T], (c, batch): (usize, usize), shift: Option<&[f64]>) -> Vec<f64> {
    let n = c * batch;
    let partial: Vec<Vec<Lanes>> = x
        .par_chunks(CHUNK_V * n)
        .map(|rows| {
            wide(
                #[inline(always)]
                || {
                    let mut s = vec![[0.0; 8]; c];
                    for block in rows.chunks_exact(n) {
                        for (ch, (run, lanes)) in block.chunks_exact(batch).zip(&mut s).enumerate()
                        {
                            let acc = match shift {
                                None => run_lanes(run, |v| v),
                                Some(m) => {
                                    let m = m[ch];
                                    run_lanes(run, |v| (v - m) * (v - m))
                                }
                            };
                            lanes.iter_mut().zip(acc).for_each(|(l, a)| *l += a);
                        }
                    }
                    s
                },
            )
        })
        .collect();
    let mut s = vec![0.0; c];
    for p in partial {
        s.iter_mut()
            .zip(p)
            .for_each(|(a, lanes)| *a += lanes.iter().sum::<f64>());
    }
    s
}

/// Per-channel mean and biased variance over vertices and batch (two passes, f64).
pub(super) fn moments<T: Real>(x: &[T], (c, batch): (usize, usize)) -> (Vec<f64>, Vec<f64>) {
    let count = (x.len() / c.max(1)).max(1) as f64;
    let mean: Vec<f64> = channel_sums(x, (c, batch), None)
        .iter()
        .map(|s| s / count)
        .collect();
    let var = channel_sums(x, (c, batch), Some(&mean))
        .iter()
        .map(|s| s / count)
        .collect();
    (mean, var)
}

/// out = [tanh]((x − m)·s·γ + β) per channel, with `inv_std` = s.
#[allow(clippy::too_many_arguments)]
pub(super) fn bn_forward<T: Real>(
    x: &[T],
    out: &mut [T],
    (mean, inv_std): (&[f64], &[f64]),
    (gamma, beta): (&[T], &[T]),
    (c, batch): (usize, usize),
    tanh: bool,
) {
    let n = c * batch;
    // y = x·a + d per channel, a = γ s, d = β − m γ s (f64, then the float type).
    let a: Vec<T> = (0..c).map(|j| of(f64_of(gamma[j]) * inv_std[j])).collect();
    let d: Vec<T> = (0..c)
        .map(|j| of(f64_of(beta[j]) - mean[j] * f64_of(gamma[j]) * inv_std[j]))
        .collect();
    out.par_chunks_mut(CHUNK_V * n)
        .zip(x.par_chunks(CHUNK_V * n))
        .for_each(|(o, x)| {
            wide(
                #[inline(always)]
                || {
                    for (ob, xb) in o.chunks_exact_mut(n).zip(x.chunks_exact(n)) {
                        for (ch, (orun, xrun)) in ob
                            .chunks_exact_mut(batch)
                            .zip(xb.chunks_exact(batch))
                            .enumerate()
                        {
                            let (a, d) = (a[ch], d[ch]);
                            // Two loops: with the test inside, tanh was computed for every
                            // value and then thrown away where it was not wanted.
                            let pairs = orun.iter_mut().zip(xrun);
                            if tanh {
                                pairs.for_each(|(o, &x)| {
                                    *o = crate::numerics::real::Real::tanh(x * a + d)
                                });
                            } else {
                                pairs.for_each(|(o, &x)| *o = x * a + d);
                            }
                        }
                    }
                },
            )
        });
}

/// Batch norm's backward pass (batch statistics), through tanh first if `tanh`: `g` holds the
/// gradient at the output and receives the gradient at the input x; returns (dγ, dβ).
#[allow(clippy::too_many_arguments)]
pub(super) fn bn_backward<T: Real>(
    x: &[T],
    out: &[T],
    g: &mut [T],
    (mean, inv_std): (&[f64], &[f64]),
    gamma: &[T],
    (c, batch): (usize, usize),
    tanh: bool,
) -> (Vec<f64>, Vec<f64>) {
    let n = c * batch;
    let count = (x.len() / n.max(1) * batch).max(1) as f64;
    let ms: Vec<T> = mean.iter().map(|&m| of(m)).collect();
    let ss: Vec<T> = inv_std.iter().map(|&s| of(s)).collect();
    let one: T = of(1.0);
    // Pass 1: g ← g·(1 − out²) and Σ g, Σ g·x̂ per channel (eight local lanes each, as `run_lanes`).
    let partial: Vec<Vec<[Lanes; 2]>> = g
        .par_chunks_mut(CHUNK_V * n)
        .zip(x.par_chunks(CHUNK_V * n).zip(out.par_chunks(CHUNK_V * n)))
        .map(|(g, (x, o))| {
            wide(
                #[inline(always)]
                || {
                    let mut s = vec![[[0.0; 8]; 2]; c];
                    for ((gb, xb), ob) in g
                        .chunks_exact_mut(n)
                        .zip(x.chunks_exact(n))
                        .zip(o.chunks_exact(n))
                    {
                        for (ch, sums) in s.iter_mut().enumerate() {
                            let (mut sg, mut sgx) = ([0.0; 8], [0.0; 8]);
                            let r = ch * batch..(ch + 1) * batch;
                            let (m, inv) = (ms[ch], ss[ch]);
                            let step = |gv: &mut T, xv: T, ov: T, sg: &mut f64, sgx: &mut f64| {
                                if tanh {
                                    *gv *= one - ov * ov;
                                }
                                *sg += f64_of(*gv);
                                *sgx += f64_of(*gv * ((xv - m) * inv));
                            };
                            let mut gs = gb[r.clone()].chunks_exact_mut(8);
                            let (mut xs, mut os) =
                                (xb[r.clone()].chunks_exact(8), ob[r].chunks_exact(8));
                            for ((g8, x8), o8) in (&mut gs).zip(&mut xs).zip(&mut os) {
                                for l in 0..8 {
                                    step(&mut g8[l], x8[l], o8[l], &mut sg[l], &mut sgx[l]);
                                }
                            }
                            let tails = (gs.into_remainder(), xs.remainder(), os.remainder());
                            for (l, ((gv, &xv), &ov)) in
                                tails.0.iter_mut().zip(tails.1).zip(tails.2).enumerate()
                            {
                                step(gv, xv, ov, &mut sg[l], &mut sgx[l]);
                            }
                            for (acc, run) in sums.iter_mut().zip([sg, sgx]) {
                                acc.iter_mut().zip(run).for_each(|(a, r)| *a += r);
                            }
                        }
                    }
                    s
                },
            )
        })
        .collect();
    let mut s = vec![0.0; 2 * c];
    for p in partial {
        for (ch, [sg, sgx]) in p.iter().enumerate() {
            s[ch] += sg.iter().sum::<f64>();
            s[c + ch] += sgx.iter().sum::<f64>();
        }
    }
    let (dbeta, dgamma) = (s[..c].to_vec(), s[c..].to_vec());
    // Pass 2: dx = γ s (g − dβ/N − x̂ dγ/N).
    let scale: Vec<T> = (0..c).map(|j| of(f64_of(gamma[j]) * inv_std[j])).collect();
    let mb: Vec<T> = dbeta.iter().map(|&v| of(v / count)).collect();
    let mg: Vec<T> = dgamma.iter().map(|&v| of(v / count)).collect();
    g.par_chunks_mut(CHUNK_V * n)
        .zip(x.par_chunks(CHUNK_V * n))
        .for_each(|(g, x)| {
            wide(
                #[inline(always)]
                || {
                    for (gb, xb) in g.chunks_exact_mut(n).zip(x.chunks_exact(n)) {
                        for ch in 0..c {
                            let r = ch * batch..(ch + 1) * batch;
                            let (m, inv, sc, b, gm) = (ms[ch], ss[ch], scale[ch], mb[ch], mg[ch]);
                            for (gv, &xv) in gb[r.clone()].iter_mut().zip(&xb[r]) {
                                *gv = sc * (*gv - b - (xv - m) * inv * gm);
                            }
                        }
                    }
                },
            )
        });
    (dgamma, dbeta)
}

/// x ← tanh(x).
pub(super) fn tanh_inplace<T: Real>(x: &mut [T]) {
    x.par_chunks_mut(1 << 14).for_each(|c| {
        wide(|| {
            c.iter_mut()
                .for_each(|v| *v = crate::numerics::real::Real::tanh(*v))
        })
    });
}

/// g ← g·(1 − y²) for the saved tanh output y.
pub(super) fn tanh_backward<T: Real>(y: &[T], g: &mut [T]) {
    let one: T = of(1.0);
    g.par_chunks_mut(1 << 14)
        .zip(y.par_chunks(1 << 14))
        .for_each(|(g, y)| {
            wide(|| {
                for (g, &y) in g.iter_mut().zip(y) {
                    *g *= one - y * y;
                }
            })
        });
}

/// Σ (x̂ − x)² (f64), writing g = coeff·(x̂ − x).
pub(super) fn sse_grad<T: Real>(x_hat: &[T], x: &[T], g: &mut [T], coeff: f64) -> f64 {
    let k: T = of(coeff);
    let partial: Vec<f64> = g
        .par_chunks_mut(1 << 14)
        .zip(x_hat.par_chunks(1 << 14).zip(x.par_chunks(1 << 14)))
        .map(|(g, (h, x))| {
            let mut s = 0.0;
            for (g, (&h, &x)) in g.iter_mut().zip(h.iter().zip(x)) {
                let d = h - x;
                let dd = f64_of(d);
                s += dd * dd;
                *g = d * k;
            }
            s
        })
        .collect();
    partial.iter().sum()
}

/// Σ over the batch of a `[K, B]` array: out[k] = Σ_b x[k·B + b].
pub(super) fn row_sums<T: Real>(x: &[T], batch: usize, out: &mut [T]) {
    out.par_iter_mut()
        .zip(x.par_chunks(batch.max(1)))
        .for_each(|(o, row)| {
            *o = of(row.iter().map(|&v| f64_of(v)).sum::<f64>());
        });
}

/// out `[K, B]` += bias[k] on every row.
pub(super) fn add_row_bias<T: Real>(out: &mut [T], bias: &[T], batch: usize) {
    out.par_chunks_mut(batch.max(1))
        .zip(bias.par_iter())
        .for_each(|(row, &b)| row.iter_mut().for_each(|v| *v += b));
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn layout_round_trip_and_moments() {
        // 3: the 8-lane sums' tail alone; 13: a full block and a tail.
        for batch in [3, 13] {
            layout_round_trip_and_moments_at(batch);
        }
    }

    fn layout_round_trip_and_moments_at(batch: usize) {
        let (v, c) = (600, 4);
        let x: Vec<f64> = (0..batch * v * c)
            .map(|i| (i as f64 * 0.13).sin() + (i % c) as f64)
            .collect();
        let mut vcb = vec![0.0; x.len()];
        to_vcb(&x, &mut vcb, (batch, v, c), None);
        assert_eq!(vcb[(5 * c + 2) * batch + 1], x[(v + 5) * c + 2]);
        // Renumbered: block p holds vertex order[p].
        let order: Vec<u32> = (0..v as u32).rev().collect();
        let mut moved = vec![0.0; x.len()];
        to_vcb(&x, &mut moved, (batch, v, c), Some(&order));
        let n = c * batch;
        assert_eq!(moved[5 * n..][..n], vcb[(v - 6) * n..][..n]);
        // Back to `[B, V, C]`, the order undone.
        for (layout, order) in [(&vcb, None), (&moved, Some(order.as_slice()))] {
            let mut back = vec![f64::NAN; x.len()];
            from_vcb(layout, &mut back, (batch, v, c), order);
            assert_eq!(back, x);
        }
        let (mean, var) = moments(&vcb, (c, batch));
        for ch in 0..c {
            let vals: Vec<f64> = x.iter().skip(ch).step_by(c).copied().collect();
            let m = vals.iter().sum::<f64>() / vals.len() as f64;
            let s = vals.iter().map(|v| (v - m) * (v - m)).sum::<f64>() / vals.len() as f64;
            assert!((mean[ch] - m).abs() < 1e-12 && (var[ch] - s).abs() < 1e-12);
        }
    }

    #[test]
    fn wide_passes_equal_the_scalar_formulas_bit_for_bit() {
        // Mixed signs and sizes, both tanh branches, a NaN and infinities.
        let (batch, c, v) = (13, 3, 40);
        let mut x: Vec<f32> = (0..batch * c * v)
            .map(|i| ((i as f32) * 0.731).sin() * (1.0 + (i % 7) as f32 * 2.0))
            .collect();
        x[5] = f32::NAN;
        x[6] = f32::INFINITY;
        x[7] = f32::NEG_INFINITY;
        let tanh = |v: f32| crate::numerics::real::Real::tanh(v);
        let mut t = x.clone();
        tanh_inplace(&mut t);
        let same = |a: &[f32], b: &[f32]| a.iter().zip(b).all(|(p, q)| p.to_bits() == q.to_bits());
        let expected: Vec<f32> = x.iter().map(|&v| tanh(v)).collect();
        assert!(same(&t, &expected), "tanh");

        let (mean, inv_std) = (vec![0.1, -0.2, 0.3], vec![1.5, 0.7, 2.0]);
        let (gamma, beta) = ([0.9f32, 1.1, -0.5], [0.05f32, -0.1, 0.2]);
        let mut out = vec![0.0f32; x.len()];
        bn_forward(
            &x,
            &mut out,
            (&mean, &inv_std),
            (&gamma, &beta),
            (c, batch),
            true,
        );
        let expected: Vec<f32> = x
            .iter()
            .enumerate()
            .map(|(i, &v)| {
                let ch = i / batch % c;
                let a = (f64::from(gamma[ch]) * inv_std[ch]) as f32;
                let d =
                    (f64::from(beta[ch]) - mean[ch] * f64::from(gamma[ch]) * inv_std[ch]) as f32;
                tanh(v * a + d)
            })
            .collect();
        assert!(same(&out, &expected), "batch norm + tanh");

        let mut g = x.clone();
        tanh_backward(&t, &mut g);
        let expected: Vec<f32> = x.iter().zip(&t).map(|(&g, &y)| g * (1.0 - y * y)).collect();
        assert!(same(&g, &expected), "tanh backward");
    }
}
