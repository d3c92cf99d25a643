//! [`EngineModel`]: what the engine needs of a model, whoever stores its variables.

use crate::error::Result;
use crate::net::config::ModelConfig;
use crate::net::plan::NetPlan;
use crate::numerics::host::{HostSlice, Precision};

/// A model as the engine sees it: the network's plan and configuration, and its variables in
/// the plan's order, which stay where the model keeps them (candle's `MeshVae` implements
/// this beside its own executor). The engine reads the trainable variables in place, writes
/// the batch norms' running statistics back, and leaves the weights' update to `Adam`.
pub(crate) trait EngineModel {
    fn config(&self) -> &ModelConfig;
    /// The layer list and variable ids; `None` for networks the engine does not run.
    fn plan(&self) -> Option<&NetPlan>;
    /// The variables' float type, or why the engine cannot read them in place.
    fn precision(&self) -> std::result::Result<Precision, String>;
    /// Vertices of the template.
    fn vertex_count(&self) -> usize;
    /// Names and element counts of the trainable variables, in the plan's order.
    fn trainable(&self) -> Vec<(String, usize)>;
    /// An identity per trainable variable, so that the engine refuses a model it was not
    /// built for (it reads the variables in place).
    fn var_ids(&self) -> Vec<u64>;
    /// Runs `f` on the trainable variables' values (unchanged meanwhile).
    fn with_weights(&self, f: &mut dyn FnMut(&[HostSlice<'_>]) -> Result<()>) -> Result<()>;
    /// State variable `id` (a running mean or variance) in f64.
    fn state(&self, id: usize) -> Result<Vec<f64>>;
    /// Sets state variable `id` (rounded to the model's precision).
    fn set_state(&self, id: usize, values: &[f64]) -> Result<()>;
}
