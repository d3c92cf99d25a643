//! Which implementation computes the training steps: the hand-written CPU engine
//! ([`crate::Engine`]) or candle's autograd, and why candle where it is. Chosen once per run
//! and written on every line of `log.jsonl`, in `run.json` and in the summary, so that a run
//! never changes path without a word.

use crate::candle::model::MeshVae;
use crate::cpu::Engine;
use candle_core::Device;
use serde::{Deserialize, Serialize};
use std::fmt;

/// The device every command trains and runs its models on: the one place that chooses it. The
/// CPU, where the engine runs; on another device the steps would fall to candle's autograd
/// ([`Executor::choose`] says so in every run's log).
pub fn default_device() -> Device {
    Device::Cpu
}

/// The implementation that computes the steps.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ExecutorKind {
    /// The hand-written forward, backward and Adam step over reused buffers (CPU).
    Engine,
    /// candle's autograd: the reference, and the path for models and devices the engine does
    /// not cover.
    Candle,
}

impl fmt::Display for ExecutorKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Engine => "engine",
            Self::Candle => "candle",
        })
    }
}

/// The executor of a run and, for candle, why.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Executor {
    pub kind: ExecutorKind,
    /// Why candle and not the engine (`None` for the engine).
    pub reason: Option<String>,
}

impl Executor {
    /// The engine where it supports `model` and is allowed, candle otherwise.
    pub fn choose(model: &MeshVae, engine_allowed: bool) -> Self {
        let reason = if engine_allowed {
            Engine::unsupported(model).map(|why| format!("the engine does not cover {why}"))
        } else {
            Some("the engine was switched off (--no-engine)".into())
        };
        Self {
            kind: match reason {
                None => ExecutorKind::Engine,
                Some(_) => ExecutorKind::Candle,
            },
            reason,
        }
    }
}

impl fmt::Display for Executor {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match &self.reason {
            Some(why) => write!(f, "{} ({why})", self.kind),
            None => write!(f, "{}", self.kind),
        }
    }
}
