//! One node's forward and backward pass on the engine's buffers: a Chebyshev convolution with
//! its batch norm and tanh, or a pooling / de-pooling operator.

use super::{Acts, Node, PoolOp};
use crate::cpu::kernels as k;
use crate::cpu::{Real, of};
use crate::error::Result;
use crate::net::batch_norm as bn;
use spectral_conv::ConvDims;

/// 1 / √(v + ε), batch norm's factor (`net/batch_norm.rs`).
fn inv_std(v: &f64) -> f64 {
    let Ok(f) = bn::inv_std(v);
    f
}

/// Which statistics a batch norm normalises with: the batch's own (training; they are kept for
/// the backward pass and the running averages) or the running ones (inference, as `Mode::Eval`).
#[derive(Clone, Copy, PartialEq)]
pub(super) enum BnStats {
    Batch,
    Running,
}

pub(super) fn forward_node<T: Real>(
    node: &mut Node,
    acts: &mut Acts<T>,
    w: &[&[T]],
    batch: usize,
    stats: BnStats,
) -> Result<()> {
    match node {
        Node::Conv(c) => {
            let (nx, ny) = (c.v * c.ci * batch, c.v * c.co * batch);
            let d = ConvDims {
                batch,
                c_in: c.ci,
                c_out: c.co,
            };
            let tl = c.kernel.terms_len(batch, c.ci);
            let (mut pre, mut terms) = (acts.take(c.pre), acts.take(c.terms));
            let weight = c.weight.stacked(w, c.co);
            let done = c.kernel.forward(
                &acts.0[c.input][..nx],
                &weight,
                d,
                &mut terms[..tl],
                &mut pre[..ny],
                &c.ws,
            );
            acts.put(c.terms, terms);
            if let (Some(bn), BnStats::Running) = (&c.bn, stats) {
                let (mean, var) = &bn.running;
                let inv_std: Vec<f64> = var.iter().map(inv_std).collect();
                let out = &mut acts.0[c.out][..ny];
                let params = (w[bn.gamma], w[bn.beta]);
                k::bn_forward(
                    &pre[..ny],
                    out,
                    (mean, &inv_std),
                    params,
                    (c.co, batch),
                    c.tanh,
                );
            } else if let Some(bn) = &mut c.bn {
                let (mean, var) = k::moments(&pre[..ny], (c.co, batch));
                bn.inv_std = var.iter().map(inv_std).collect();
                bn.mean = mean;
                bn.var = var;
                let out = &mut acts.0[c.out][..ny];
                let stats = (bn.mean.as_slice(), bn.inv_std.as_slice());
                let params = (w[bn.gamma], w[bn.beta]);
                k::bn_forward(&pre[..ny], out, stats, params, (c.co, batch), c.tanh);
            } else if c.tanh {
                k::tanh_inplace(&mut pre[..ny]);
            }
            acts.put(c.pre, pre);
            done?;
        }
        Node::Pool(p) => {
            let n = p.c * batch;
            let out_len = p.v_out * n;
            match &mut p.op {
                PoolOp::Identity => {}
                PoolOp::Sparse(kernel) => {
                    let mut out = acts.take(p.out);
                    let done = kernel.apply(&acts.0[p.input][..p.v_in * n], &mut out[..out_len], n);
                    acts.put(p.out, out);
                    done?;
                }
                PoolOp::Max(pool, arg) => {
                    let mut out = acts.take(p.out);
                    let done = pool.forward_into(
                        &acts.0[p.input][..p.v_in * n],
                        &mut out[..out_len],
                        &mut arg[..out_len],
                        n,
                    );
                    acts.put(p.out, out);
                    done?;
                }
            }
        }
    }
    Ok(())
}

/// Backward through one node: `g[0]` holds the gradient at its output; the gradient at its
/// input ends in `g[1]` (returns true: swap them) or, for in-place steps, in `g[0]` (false).
pub(super) fn backward_node<T: Real>(
    node: &mut Node,
    acts: &Acts<T>,
    w: &[&[T]],
    batch: usize,
    grads: &mut [Vec<T>],
    g: [&mut Vec<T>; 3],
) -> Result<bool> {
    let [ga, gb, work] = g;
    match node {
        Node::Conv(c) => {
            let (nx, ny) = (c.v * c.ci * batch, c.v * c.co * batch);
            let out = &acts.0[c.out][..ny];
            if let Some(bn) = &c.bn {
                let stats = (bn.mean.as_slice(), bn.inv_std.as_slice());
                let pre = &acts.0[c.pre][..ny];
                let (dgamma, dbeta) = k::bn_backward(
                    pre,
                    out,
                    &mut ga[..ny],
                    stats,
                    w[bn.gamma],
                    (c.co, batch),
                    c.tanh,
                );
                for (dst, src) in [(bn.gamma, dgamma), (bn.beta, dbeta)] {
                    grads[dst].iter_mut().zip(src).for_each(|(d, s)| *d = of(s));
                }
            } else if c.tanh {
                k::tanh_backward(out, &mut ga[..ny]);
            }
            let d = ConvDims {
                batch,
                c_in: c.ci,
                c_out: c.co,
            };
            let tl = c.kernel.terms_len(batch, c.ci);
            let dx = if c.need_dx {
                Some((&mut gb[..nx], &mut work[..c.kernel.work_len(batch, c.ci)]))
            } else {
                None
            };
            let weight = c.weight.stacked(w, c.co);
            c.weight.write_grad(grads, c.co, c.add_grad, |dw| {
                c.kernel.backward(
                    &acts.0[c.input][..nx],
                    &acts.0[c.terms][..tl],
                    &weight,
                    &ga[..ny],
                    d,
                    dw,
                    dx,
                    &c.ws,
                )?;
                Ok(())
            })?;
            Ok(c.need_dx)
        }
        Node::Pool(p) => {
            let n = p.c * batch;
            let (gin, gout) = (&mut gb[..p.v_in * n], &ga[..p.v_out * n]);
            match &p.op {
                PoolOp::Identity => return Ok(false),
                PoolOp::Sparse(kernel) => kernel.apply_t(gout, gin, n)?,
                PoolOp::Max(pool, arg) => pool.backward_into(&arg[..p.v_out * n], gout, gin, n)?,
            }
            Ok(true)
        }
    }
}
