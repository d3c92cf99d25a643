//! The plan's variables as candle [`Var`]s, created in name order from one [`Rng`] so that a
//! seed fixes every weight (the names, shapes and starting values are the plan's:
//! `net/vars.rs`).

use crate::error::Result;
use crate::net::vars::{Init, VarPlan};
use crate::numerics::rng::Rng;
use candle_core::{DType, Device, Tensor, Var};

/// Creates the variables of `plan` (sorted by name) in order, drawing every normal one from
/// `rng`.
pub(crate) fn create(
    plan: &[VarPlan],
    init_std: f64,
    dtype: DType,
    device: &Device,
    rng: &mut Rng,
) -> Result<Vec<Var>> {
    plan.iter()
        .map(|p| {
            let n = p.len();
            let values = match p.init {
                Init::Normal => rng.normals(n).into_iter().map(|x| x * init_std).collect(),
                Init::Zeros => vec![0.0; n],
                Init::Ones => vec![1.0; n],
                Init::Uniform(bound) => (0..n)
                    .map(|_| (2.0 * rng.uniform() - 1.0) * bound)
                    .collect(),
            };
            let t = Tensor::from_vec(values, p.shape.as_slice(), device)?.to_dtype(dtype)?;
            Ok(Var::from_tensor(&t)?)
        })
        .collect()
}
