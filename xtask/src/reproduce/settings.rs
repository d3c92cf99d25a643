//! The settings a run trains with, as its record keeps them, and what differs between two of
//! them: a record whose settings are not today's is trained again, and the page says why.

use super::plan::Run;
use deform_features::FeatureOptions;
use mesh_hierarchy::HierarchyConfig;
use meshvae::{ModelConfig, ModelSpec, TrainConfig};
use serde::{Deserialize, Serialize};
use serde_json::Value;

/// The settings of [`RunResult::settings`](super::record::RunResult::settings), as `config.json`
/// of the model folder holds them.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunSettings {
    pub train: TrainConfig,
    pub features: FeatureOptions,
    pub hierarchy: HierarchyConfig,
}

impl RunSettings {
    /// What `run` trains with today.
    pub fn of(run: &Run, model: &ModelConfig) -> Self {
        Self {
            train: run.train_config(),
            features: FeatureOptions::default(),
            hierarchy: meshvae::hierarchy_config(model, HierarchyConfig::default()),
        }
    }

    /// What a record of `run` without settings is taken to have trained with
    /// ([`Run::unrecorded_train_config`]).
    pub fn unrecorded(run: &Run, model: &ModelConfig) -> Self {
        Self {
            train: run.unrecorded_train_config(),
            ..Self::of(run, model)
        }
    }

    /// The settings a model folder's `config.json` holds.
    pub fn of_spec(spec: &ModelSpec) -> Self {
        Self {
            train: spec.train.clone(),
            features: spec.features,
            hierarchy: spec.hierarchy,
        }
    }

    /// Whether a model folder trained with `self` can be resumed with `other`: every setting
    /// equal but the budget (epochs, steps), which a resumed run may raise.
    pub fn resumable_with(&self, other: &Self) -> bool {
        let mut other = other.clone();
        other.train.epochs = self.train.epochs;
        other.train.steps = self.train.steps;
        *self == other
    }
}

/// Every setting whose value differs between `recorded` and `current`, as `path old → new`
/// (`train.schedule.warmup_steps 0 → 300`), in the order of the settings' fields.
pub fn setting_differences(recorded: &RunSettings, current: &RunSettings) -> Vec<String> {
    let (Ok(a), Ok(b)) = (
        serde_json::to_value(recorded),
        serde_json::to_value(current),
    ) else {
        return vec!["settings (unserialisable)".into()];
    };
    let mut out = Vec::new();
    diff(&a, &b, String::new(), &mut out);
    out
}

fn diff(a: &Value, b: &Value, path: String, out: &mut Vec<String>) {
    match (a, b) {
        (Value::Object(x), Value::Object(y)) => {
            let join = |key: &str| {
                if path.is_empty() {
                    key.to_string()
                } else {
                    format!("{path}.{key}")
                }
            };
            for (key, value) in x {
                diff(value, y.get(key).unwrap_or(&Value::Null), join(key), out);
            }
            for (key, value) in y.iter().filter(|(key, _)| !x.contains_key(*key)) {
                diff(&Value::Null, value, join(key), out);
            }
        }
        _ if a != b => out.push(format!("{path} {} → {}", show(a, b), show(b, a))),
        _ => {}
    }
}

/// `value` as the page writes it; an absent value (null) is the zero its field's kind leaves
/// out of the JSON (`other` tells the kind).
fn show(value: &Value, other: &Value) -> String {
    match (value, other) {
        (Value::Null, Value::Number(_)) => "0".into(),
        (Value::Null, Value::Bool(_)) => "false".into(),
        (Value::Null, _) => "none".into(),
        (Value::String(s), _) => s.clone(),
        (value, _) => value.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::reproduce::plan::{self, Budget, COLUMNS, PROTOCOLS};

    fn settings() -> RunSettings {
        let run = Run {
            dataset: plan::dataset("horse-gallop").unwrap(),
            protocol: &PROTOCOLS[0],
            budget: Budget::CONVERGED,
            seed: 1,
            column: COLUMNS.iter().find(|c| c.is_ours()).unwrap(),
            by_shape: true,
        };
        RunSettings::of(&run, &run.column.model().unwrap())
    }

    #[test]
    fn differences_name_each_changed_setting_with_both_values() {
        let now = settings();
        assert!(setting_differences(&now, &now).is_empty());
        let mut then = now.clone();
        then.train.lr = 1e-3;
        then.train.schedule.warmup_steps = 0;
        then.train.grad_clip = 0.0;
        then.hierarchy.ratio = 0.25;
        let differences = setting_differences(&then, &now);
        assert_eq!(differences.len(), 4, "{differences:?}");
        assert!(differences.contains(&"train.lr 0.001 → 0.01".to_string()));
        assert!(differences.contains(&"train.schedule.warmup_steps 0 → 300".to_string()));
        assert!(
            differences.contains(&"train.grad_clip 0 → 3.0".to_string()),
            "{differences:?}"
        );
        assert!(
            differences
                .iter()
                .any(|d| d.starts_with("hierarchy.ratio 0.25 → ")),
            "{differences:?}"
        );
    }

    #[test]
    fn a_folder_resumes_with_a_larger_budget_only() {
        let now = settings();
        let mut longer = now.clone();
        longer.train.steps = Some(40_000);
        longer.train.epochs += 1;
        assert!(now.resumable_with(&longer));
        let mut other = now.clone();
        other.train.adam_beta2 = 0.999;
        assert!(!now.resumable_with(&other));
    }
}
