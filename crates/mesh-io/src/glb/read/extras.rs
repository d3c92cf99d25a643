//! The first mesh's `extras`: frame names, labels, and the writer's correction table of exact
//! values (its format is in the `glb` module documentation).

use super::Source;
use super::accessors::{f32_at, u32_at};
use crate::error::{Result, Warning};
use crate::glb::keys;
use crate::mesh::Point;
use serde_json::Value;

impl Source<'_> {
    /// Value of `key` in the first mesh's `extras`.
    fn extra(&self, key: &str) -> Option<&Value> {
        self.json.pointer("/meshes/0/extras")?.get(key)
    }

    fn warn(&self, warnings: &mut Vec<Warning>, message: String) {
        warnings.push(Warning {
            path: self.path.into(),
            message,
        });
    }

    pub(super) fn frame_names(&self, n: usize, warnings: &mut Vec<Warning>) -> Vec<String> {
        if let Some(value) = self.extra(keys::FRAME_NAMES) {
            match string_array(value, n) {
                Some(names) => return names,
                None => self.warn(
                    warnings,
                    format!("extras.{} is not {n} strings; ignored", keys::FRAME_NAMES),
                ),
            }
        }
        if let Some(value) = self.extra(keys::TARGET_NAMES) {
            match string_array(value, n - 1) {
                Some(names) => {
                    let base = self.json.pointer("/meshes/0/name").and_then(Value::as_str);
                    let mut all = vec![base.unwrap_or("base").to_string()];
                    all.extend(names);
                    return all;
                }
                None => self.warn(
                    warnings,
                    format!(
                        "extras.{} is not {} strings; ignored",
                        keys::TARGET_NAMES,
                        n - 1
                    ),
                ),
            }
        }
        (0..n).map(|k| format!("frame_{k:04}")).collect()
    }

    pub(super) fn labels(&self, n: usize, warnings: &mut Vec<Warning>) -> Option<Vec<String>> {
        let value = self.extra(keys::LABELS)?;
        let labels = string_array(value, n);
        if labels.is_none() {
            self.warn(
                warnings,
                format!("extras.{} is not {n} strings; ignored", keys::LABELS),
            );
        }
        labels
    }

    /// Applies the writer's table of exact values (see the module documentation).
    pub(super) fn apply_corrections(
        &self,
        positions: &mut [Point],
        n: usize,
        v: usize,
    ) -> Result<()> {
        let Some(table) = self.extra(keys::CORRECTIONS) else {
            return Ok(());
        };
        let what = format!("extras.{}", keys::CORRECTIONS);
        let field = |name: &str| {
            table
                .get(name)
                .and_then(Value::as_u64)
                .and_then(|x| usize::try_from(x).ok())
        };
        let (Some(view), Some(count)) = (field("bufferView"), field("count")) else {
            return Err(self.error(format!("{what} needs an integer bufferView and count")));
        };
        let size = keys::CORRECTION_SIZE;
        let records = self.elements(view, 0, count, size, Some(size), &what)?;
        for (i, record) in records.iter().enumerate() {
            let (frame, component) = (u32_at(record, 0) as usize, u32_at(record, 4) as usize);
            let slot = (frame < n && component < 3 * v)
                .then(|| positions.get_mut(frame * v + component / 3))
                .flatten()
                .ok_or_else(|| {
                    self.error(format!(
                        "{what}: record {i} names frame {frame}, component {component}, \
                         outside {n} frames of {v} vertices"
                    ))
                })?;
            slot[component % 3] = f32_at(record, 8);
        }
        Ok(())
    }
}

/// `value` as exactly `len` strings.
fn string_array(value: &Value, len: usize) -> Option<Vec<String>> {
    let array = value.as_array().filter(|a| a.len() == len)?;
    array.iter().map(|s| s.as_str().map(String::from)).collect()
}
