//! The fused kernels against dense references, in every array layout they take.

use super::{ChebShape, Inputs, Need, backward, forward};
use crate::kernel::Csr;
use crate::layout::{Blocks, Io, to_channel_major};
use crate::test_util::{dense_apply, random_matrix, random_vec};
use crate::workspace::Workspace;
use sparse_csr::CsrMatrix;

/// Σ_k T_k(A) x W_k + b by dense recurrences on `[B, V, C]`, W in the authors' layout.
fn reference(m: &CsrMatrix, x: &[f64], w: &[f64], b: &[f64], s: &ChebShape) -> Vec<f64> {
    let mut terms = vec![x.to_vec()];
    for k in 1..s.k {
        let ax = dense_apply(m, &terms[k - 1], s.batch, s.ci);
        let t = if k == 1 {
            ax
        } else {
            ax.iter()
                .zip(&terms[k - 2])
                .map(|(a, p)| 2.0 * a - p)
                .collect()
        };
        terms.push(t);
    }
    let mut y = vec![0.0; s.batch * s.v * s.co];
    for r in 0..s.batch * s.v {
        for o in 0..s.co {
            y[r * s.co + o] = b[o];
            for f in 0..s.ci {
                for (k, t) in terms.iter().enumerate() {
                    y[r * s.co + o] += t[r * s.ci + f] * w[(f * s.k + k) * s.co + o];
                }
            }
        }
    }
    y
}

/// `[B, V, c]` data in layout `io`.
fn permute(x: &[f64], io: Io, (batch, v, c): (usize, usize, usize)) -> Vec<f64> {
    let mut out = vec![0.0; x.len()];
    for b in 0..batch {
        for i in 0..v {
            for ch in 0..c {
                let at = match io {
                    Io::BatchMajor => (b * v + i) * c + ch,
                    Io::VertexBatch => (i * batch + b) * c + ch,
                    Io::VertexChannel => (i * c + ch) * batch + b,
                };
                out[at] = x[(b * v + i) * c + ch];
            }
        }
    }
    out
}

/// x as the kernels take it: vertex-major data as is, `[B, V, C]` through a channel-major copy.
fn blocks<'a>(
    data: &'a [f64],
    copy: &'a mut Vec<f64>,
    io: Io,
    dims: (usize, usize, usize),
) -> Blocks<'a, f64> {
    if io == Io::BatchMajor {
        *copy = to_channel_major(data, io, dims, &Workspace::new());
        Blocks::channel_major(copy, dims.0, dims.2)
    } else {
        Blocks::new(data, io, dims.0, dims.2)
    }
}

#[test]
fn fused_forward_and_adjoint_match_dense_reference_in_every_layout() {
    // The SIMD variant must not change between the calls compared bit for bit below.
    let _lock = crate::kernel::BASELINE_LOCK.lock();
    // 70 vertices: two chunks; non-symmetric, so Aᵀ ≠ A.
    let v = 70;
    let m = random_matrix(v, v, 0.06, 7);
    let (a, at) = (Csr::from_matrix(&m), Csr::from_matrix(&m.transpose()));
    for (k, ci, co, batch) in [
        (1, 2, 3, 3),
        (2, 3, 2, 9),
        (3, 9, 9, 2),
        (3, 4, 5, 3),
        (4, 2, 5, 3),
        (5, 3, 1, 2),
    ] {
        let s = ChebShape {
            batch,
            v,
            ci,
            co,
            k,
        };
        let x = random_vec(batch * v * ci, 11);
        let w = random_vec(ci * k * co, 12);
        let bias = random_vec(co, 13);
        let g = random_vec(batch * v * co, 14);
        let want = reference(&m, &x, &w, &bias, &s);
        let dot = |y: &[f64]| y.iter().zip(&g).map(|(p, q)| p * q).sum::<f64>();
        for io in [Io::BatchMajor, Io::VertexBatch, Io::VertexChannel] {
            let case = format!("K={k} ci={ci} co={co} B={batch} {io:?}");
            let xd = permute(&x, io, (batch, v, ci));
            let gd = permute(&g, io, (batch, v, co));
            let (mut xcopy, mut gcopy) = (Vec::new(), Vec::new());
            let xb = blocks(&xd, &mut xcopy, io, (batch, v, ci));
            let (y, stored) = forward(&a, xb, &w, Some(&bias), &s, io, &Workspace::new());
            let want_io = permute(&want, io, (batch, v, co));
            for (p, q) in y.iter().zip(&want_io) {
                assert!((p - q).abs() < 1e-12, "{case}: forward");
            }
            // Adjoint identity: <g, y(x)> is linear in x, W and b, so its gradients are exact.
            let gb = blocks(&gd, &mut gcopy, io, (batch, v, co));
            let all = Need {
                x: true,
                w: true,
                b: true,
            };
            let ws = Workspace::new();
            let terms = refs(&stored);
            let inputs = Inputs {
                a: &a,
                at: &at,
                x: xb,
                terms: &terms,
                w: &w,
                g: gb,
                s: &s,
            };
            let grads_of = |need| backward(inputs, io, need, &ws);
            let grads = grads_of(all);
            let (dx, dw, db) = (grads.dx.unwrap(), grads.dw.unwrap(), grads.db.unwrap());
            let dx = {
                // Back to [B, V, C] for the comparison.
                let mut back = vec![0.0; dx.len()];
                let probe = permute(
                    &(0..dx.len()).map(|i| i as f64).collect::<Vec<_>>(),
                    io,
                    (batch, v, ci),
                );
                for (pos, &orig) in probe.iter().enumerate() {
                    back[orig as usize] = dx[pos];
                }
                back
            };
            let zero_b = vec![0.0; co];
            for (idx, &d) in dx.iter().enumerate().step_by(7) {
                let mut xe = vec![0.0; x.len()];
                xe[idx] = 1.0;
                let want = dot(&reference(&m, &xe, &w, &zero_b, &s));
                assert!((d - want).abs() < 1e-10, "{case}: dx[{idx}] {d} vs {want}");
            }
            for (idx, &d) in dw.iter().enumerate() {
                let mut we = vec![0.0; w.len()];
                we[idx] = 1.0;
                let want = dot(&reference(&m, &x, &we, &zero_b, &s));
                assert!((d - want).abs() < 1e-10, "{case}: dW[{idx}] {d} vs {want}");
            }
            for (o, &d) in db.iter().enumerate() {
                let want: f64 = (0..batch * v).map(|r| g[r * co + o]).sum();
                assert!((d - want).abs() < 1e-10, "{case}: db[{o}]");
            }
            // Only dW: no dx, the same dW.
            let only_w = Need {
                x: false,
                w: true,
                b: false,
            };
            let part = grads_of(only_w);
            assert!(part.dx.is_none() && part.db.is_none(), "{case}");
            assert_eq!(part.dw.unwrap(), dw, "{case}");
        }
    }
}

fn refs(v: &[Vec<f64>]) -> Vec<&[f64]> {
    v.iter().map(|t| t.as_slice()).collect()
}
