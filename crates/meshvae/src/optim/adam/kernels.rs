//! [`Adam`](super::Adam)'s CPU update (f32/f64): one pass over θ, m, v and the gradient (whole,
//! or made row block by row block: [`GradSource`]), for the engine's step and for candle's
//! gradients alike.

use super::Slot;
use crate::error::{Result, VaeError};
use crate::numerics::real::{CHUNK, Real, span, span_mut};
use candle_core::{CpuStorage, InplaceOp1, Layout, Tensor, bail};
use rayon::prelude::*;
use std::cell::RefCell;

/// One variable's gradient for [`super::Adam::step_with_sources`].
pub(crate) enum GradSource<'a, T> {
    /// The whole gradient, in the variable's layout.
    Slice(&'a [T]),
    /// A row-major gradient with `row_len` columns, made as the update reaches it:
    /// `fill(first_row, out)` writes the rows from `first_row` on into `out` (a whole number
    /// of rows). Each block lives in a small buffer the update reads while it is still in
    /// cache, instead of a gradient as large as the weights being written out and read back.
    Rows {
        row_len: usize,
        fill: &'a (dyn Fn(usize, &mut [T]) + Sync),
    },
}

/// Adam's update with g ← g + l2·θ, in one pass over θ, m, v and g: the one CPU
/// implementation, run by both the engine's step and candle's (`Adam::step_with_l2`).
#[derive(Clone, Copy)]
pub(super) struct FusedUpdate {
    pub beta1: f64,
    pub beta2: f64,
    pub scale_m: f64,
    pub scale_v: f64,
    pub lr: f64,
    pub eps: f64,
    pub l2: f64,
    /// Every gradient is multiplied by this first (a clipped step's; 1 otherwise).
    pub grad_scale: f64,
}

impl FusedUpdate {
    /// The same update at `scale` times the rate.
    pub(super) fn scaled(self, scale: f64) -> Self {
        Self {
            lr: self.lr * scale,
            ..self
        }
    }

    /// Updates one slot's θ, m, v in place (CPU tensors of type `T`); returns ½Σθ² of θ
    /// before the update.
    pub(super) fn run_on<T: Real>(&self, s: &Slot, g: &GradSource<T>) -> Result<f64> {
        with_slice_mut::<T, _>(s.var.as_tensor(), |theta| {
            with_slice_mut::<T, _>(s.m.as_tensor(), |m| {
                with_slice_mut::<T, _>(s.v.as_tensor(), |v| Ok(self.run(theta, m, v, g)))
            })
        })
    }

    /// Updates θ, m, v in place; returns ½Σθ² of θ before the update.
    pub(super) fn run<T: Real>(
        &self,
        theta: &mut [T],
        m: &mut [T],
        v: &mut [T],
        g: &GradSource<T>,
    ) -> f64 {
        let k = Coefficients {
            b1: T::of(self.beta1),
            c1: T::of(1.0 - self.beta1),
            b2: T::of(self.beta2),
            c2: T::of(1.0 - self.beta2),
            sm: T::of(self.scale_m),
            sv: T::of(self.scale_v),
            lr: T::of(self.lr),
            eps: T::of(self.eps),
            l2: T::of(self.l2),
            gs: T::of(self.grad_scale),
        };
        let with_l2 = self.l2 != 0.0;
        let scaled = self.grad_scale != 1.0;
        let chunk = |t: &mut [T], m: &mut [T], v: &mut [T], g: &[T]| {
            // 8 floats per instruction instead of 4; the same operations, so the same bits
            // (vector division and square root are exact).
            crate::numerics::wide::wide(
                #[inline(always)]
                || {
                    let sq = square_sum(t);
                    match (with_l2, scaled) {
                        (true, false) => update_chunk::<T, true, false>(k, t, m, v, g),
                        (false, false) => update_chunk::<T, false, false>(k, t, m, v, g),
                        (true, true) => update_chunk::<T, true, true>(k, t, m, v, g),
                        (false, true) => update_chunk::<T, false, true>(k, t, m, v, g),
                    }
                    sq
                },
            )
        };
        let partial: Vec<f64> = match *g {
            GradSource::Slice(g) => theta
                .par_chunks_mut(CHUNK)
                .zip(m.par_chunks_mut(CHUNK))
                .zip(v.par_chunks_mut(CHUNK).zip(g.par_chunks(CHUNK)))
                .map(|((t, m), (v, g))| chunk(t, m, v, g))
                .collect(),
            GradSource::Rows { row_len, fill } => {
                // Whole rows per block (CHUNK itself for rows of 128: the same partial sums).
                let rows = (CHUNK / row_len).max(1);
                let len = rows * row_len;
                theta
                    .par_chunks_mut(len)
                    .zip(m.par_chunks_mut(len))
                    .zip(v.par_chunks_mut(len))
                    .enumerate()
                    .map_init(Vec::new, |g, (i, ((t, m), v))| {
                        g.resize(t.len(), T::of(0.0));
                        fill(i * rows, g);
                        chunk(t, m, v, g)
                    })
                    .collect()
            }
        };
        0.5 * partial.iter().sum::<f64>()
    }
}

/// [`FusedUpdate::run_on`] with a candle gradient (a contiguous CPU tensor of type `T`).
pub(super) fn update_slot<T: Real>(s: &Slot, g: &Tensor, update: &FusedUpdate) -> Result<()> {
    let (store, layout) = g.storage_and_layout();
    let candle_core::Storage::Cpu(cpu) = &*store else {
        return Err(VaeError::argument("adam gradients", "not on the CPU"));
    };
    let data = T::cpu(cpu)
        .ok_or_else(|| VaeError::argument("adam gradients", "of another dtype than θ"))?;
    let g = span("adam", data, layout)?;
    update.run_on(s, &GradSource::Slice(g))?;
    Ok(())
}

/// [`FusedUpdate`]'s numbers in the element type.
#[derive(Clone, Copy)]
struct Coefficients<T> {
    b1: T,
    c1: T,
    b2: T,
    c2: T,
    sm: T,
    sv: T,
    lr: T,
    eps: T,
    l2: T,
    gs: T,
}

/// One chunk of the fused update. The coefficients arrive by value and the L2 and scaling
/// switches as constants: read through the closure's references they were reloaded every
/// element (the slices might have aliased them), which kept the loop scalar (~13 % of a
/// horse-gallop step). An unscaled step does not multiply by 1, so it stays bit-identical.
#[inline(always)]
fn update_chunk<T: Real, const L2: bool, const SCALED: bool>(
    k: Coefficients<T>,
    t: &mut [T],
    m: &mut [T],
    v: &mut [T],
    g: &[T],
) {
    let Coefficients {
        b1,
        c1,
        b2,
        c2,
        sm,
        sv,
        lr,
        eps,
        l2,
        gs,
    } = k;
    for (((t, m), v), &g) in t.iter_mut().zip(m).zip(v).zip(g) {
        let g = if SCALED { g * gs } else { g };
        let g = if L2 { g + *t * l2 } else { g };
        *m = *m * b1 + g * c1;
        *v = *v * b2 + (g * g) * c2;
        *t -= (*m * sm) / ((*v * sv).sqrt() + eps) * lr;
    }
}

/// Σx² in f64, over eight interleaved partial sums (vectorisable; the order differs from a
/// serial sum only by rounding).
#[inline(always)]
fn square_sum<T: Real>(x: &[T]) -> f64 {
    let mut lanes = [0.0f64; 8];
    let blocks = x.chunks_exact(8);
    let tail: f64 = blocks
        .remainder()
        .iter()
        .map(|a| a.as_f64() * a.as_f64())
        .sum();
    for block in blocks {
        for (lane, a) in lanes.iter_mut().zip(block) {
            let a = a.as_f64();
            *lane += a * a;
        }
    }
    lanes.iter().sum::<f64>() + tail
}

/// Runs `f` on the mutable contiguous data of a CPU tensor of type `T` (in place, through an
/// [`InplaceOp1`], the one way candle lends its storage mutably).
pub(super) fn with_slice_mut<T: Real, R>(
    t: &Tensor,
    f: impl FnOnce(&mut [T]) -> Result<R>,
) -> Result<R> {
    type Job<'f, T, R> = Box<dyn FnOnce(&mut [T]) -> Result<R> + 'f>;
    struct Lend<'f, T, R> {
        f: RefCell<Option<Job<'f, T, R>>>,
        out: RefCell<Option<Result<R>>>,
    }
    impl<T: Real, R> InplaceOp1 for Lend<'_, T, R> {
        fn name(&self) -> &'static str {
            "lend-mut"
        }
        fn cpu_fwd(&self, s: &mut CpuStorage, l: &Layout) -> candle_core::Result<()> {
            let Some(data) = T::cpu_mut(s) else {
                bail!("lend-mut: storage of another dtype");
            };
            let data = span_mut("lend-mut", data, l)?;
            if let Some(f) = self.f.borrow_mut().take() {
                *self.out.borrow_mut() = Some(f(data));
            }
            Ok(())
        }
    }
    let lend = Lend {
        f: RefCell::new(Some(Box::new(f) as Job<'_, T, R>)),
        out: RefCell::new(None),
    };
    t.inplace_op1(&lend)?;
    lend.out.into_inner().unwrap_or_else(|| {
        Err(VaeError::argument(
            "adam",
            "the update did not run (not a CPU tensor?)",
        ))
    })
}
