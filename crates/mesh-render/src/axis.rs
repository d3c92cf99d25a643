//! Axes of the line plots: round tick positions on a linear or logarithmic axis, short tick
//! labels, and [`Axis`], plotters' own mapping with these ticks.

use crate::plot::Range;
use plotters::coord::ranged1d::{DefaultFormatting, KeyPointHint};
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;

/// A tick label: up to 5 significant digits without trailing zeros; scientific ("1e-4",
/// "2.5e6") outside 0.001 ≤ |v| < 10⁶.
pub(crate) fn tick_label(v: f64) -> String {
    fn trim(s: &str) -> &str {
        if s.contains('.') {
            s.trim_end_matches('0').trim_end_matches('.')
        } else {
            s
        }
    }
    let a = v.abs();
    if a == 0.0 {
        "0".into()
    } else if (1e-3..1e6).contains(&a) {
        let decimals = (4 - a.log10().floor() as i32).max(0) as usize;
        trim(&format!("{v:.decimals$}")).into()
    } else {
        let s = format!("{v:.3e}");
        match s.split_once('e') {
            Some((mantissa, exponent)) => format!("{}e{exponent}", trim(mantissa)),
            None => s,
        }
    }
}

/// The smallest 1, 2 or 5 × 10ᵏ that is at least `min_step`.
fn nice_step(min_step: f64) -> f64 {
    if !(min_step.is_finite() && min_step > 0.0) {
        return 1.0;
    }
    let base = 10f64.powf(min_step.log10().floor());
    [1.0, 2.0, 5.0, 10.0]
        .into_iter()
        .map(|m| m * base)
        .find(|&s| s >= min_step * (1.0 - 1e-9))
        .unwrap_or(10.0 * base)
}

/// The multiples of `step` inside `range` (none when there would be absurdly many).
fn multiples(range: &Range, step: f64) -> Vec<f64> {
    let first = (range.start / step - 1e-9).ceil();
    let last = (range.end / step + 1e-9).floor();
    if !(first.is_finite() && last.is_finite() && last >= first && last - first <= 1000.0) {
        return Vec::new();
    }
    (first as i64..=last as i64)
        .map(|k| k as f64 * step)
        .collect()
}

/// Bold (labelled) and light grid positions of a linear axis: round steps at least `min_step`
/// apart, light lines halfway.
pub(crate) fn linear_ticks(range: &Range, min_step: f64) -> (Vec<f64>, Vec<f64>) {
    let step = nice_step(min_step);
    (multiples(range, step), multiples(range, step / 2.0))
}

/// Bold and light grid positions of a logarithmic axis over `range` (positive) whose labelled
/// neighbours are at least `min_decades` apart: 1…9, 1-2-3-4-5-7, 1-2-3-5, 1-2-5 or 1 × 10ᵏ, or every few
/// decades; light lines at 1…9 × 10ᵏ. Over less than 1.5 decades (or with fewer than three such
/// ticks), round linear steps instead when they give more labels.
pub(crate) fn log_ticks(range: &Range, min_decades: f64) -> (Vec<f64>, Vec<f64>) {
    let (lo, hi) = (range.start, range.end);
    let (first, last) = (lo.log10().floor() as i32, hi.log10().ceil() as i32);
    let inside = |v: &f64| *v >= lo * (1.0 - 1e-12) && *v <= hi * (1.0 + 1e-12);
    let decade_points = |mantissas: &[f64], every: i32| -> Vec<f64> {
        (first..=last)
            .filter(|e| e.rem_euclid(every) == 0)
            .flat_map(|e| mantissas.iter().map(move |m| m * 10f64.powi(e)))
            .filter(inside)
            .collect()
    };
    let spaced = |t: &[f64]| {
        t.windows(2)
            .all(|w| (w[1] / w[0]).log10() >= min_decades * (1.0 - 1e-9))
    };
    const ALL: [f64; 9] = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0];
    let mantissa_sets: [&[f64]; 5] = [
        &ALL,
        &[1.0, 2.0, 3.0, 4.0, 5.0, 7.0],
        &[1.0, 2.0, 3.0, 5.0],
        &[1.0, 2.0, 5.0],
        &[1.0],
    ];
    let bold = mantissa_sets
        .iter()
        .map(|m| decade_points(m, 1))
        .find(|t| spaced(t))
        .unwrap_or_else(|| {
            let every = [2, 3, 5, 10, 20, 50, 100]
                .into_iter()
                .find(|&k| f64::from(k) >= min_decades)
                .unwrap_or(100);
            decade_points(&[1.0], every)
        });
    if bold.len() < 3 || (hi / lo).log10() < 1.5 {
        // The narrowest gap of linear ticks is at the top: hi / (hi - step) >= 10^min_decades.
        let (linear, light) = linear_ticks(range, hi * (1.0 - 10f64.powf(-min_decades)));
        if linear.len() > bold.len() && linear.iter().all(|v| *v > 0.0) {
            return (linear, light);
        }
    }
    let light = if (hi / lo).log10() <= 8.0 {
        decade_points(&ALL, 1)
    } else {
        decade_points(&[1.0], 1)
    };
    (bold, light)
}

/// An axis for plotters: plotters' own linear or logarithmic (`log_scale`) mapping, with our
/// tick positions (bold ones labelled) instead of plotters' choice.
pub(crate) struct Axis {
    scale: Scale,
    range: Range,
    bold: Vec<f64>,
    light: Vec<f64>,
}

enum Scale {
    Linear(RangedCoordf64),
    Log(LogCoord<f64>),
}

impl Axis {
    pub fn new(range: &Range, log: bool, (bold, light): (Vec<f64>, Vec<f64>)) -> Axis {
        let scale = if log {
            Scale::Log(range.clone().log_scale().into())
        } else {
            Scale::Linear(range.clone().into())
        };
        Axis {
            scale,
            range: range.clone(),
            bold,
            light,
        }
    }
}

impl Ranged for Axis {
    type FormatOption = DefaultFormatting;
    type ValueType = f64;

    fn map(&self, value: &f64, limit: (i32, i32)) -> i32 {
        match &self.scale {
            Scale::Linear(s) => s.map(value, limit),
            Scale::Log(s) => s.map(value, limit),
        }
    }

    fn key_points<Hint: KeyPointHint>(&self, hint: Hint) -> Vec<f64> {
        if hint.weight().allow_light_points() {
            self.light.clone()
        } else {
            self.bold.clone()
        }
    }

    fn range(&self) -> Range {
        self.range.clone()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tick_labels_are_short() {
        let cases = [
            (0.0, "0"),
            (-0.0, "0"),
            (500.0, "500"),
            (0.30000000000000004, "0.3"),
            (1234.5, "1234.5"),
            (0.00125, "0.00125"),
            (2.5e6, "2.5e6"),
            (1e-4, "1e-4"),
            (-3e-7, "-3e-7"),
            (20000.0, "20000"),
        ];
        for (v, s) in cases {
            assert_eq!(tick_label(v), s, "{v}");
        }
    }

    #[test]
    fn log_ticks_are_round_and_spaced() {
        // Three decades with room: 1-2-3-5 × 10^k.
        let (bold, light) = log_ticks(&(1.0..1000.0), 0.15);
        assert_eq!(bold.first(), Some(&1.0));
        assert!(bold.contains(&30.0) && bold.contains(&1000.0), "{bold:?}");
        assert!(light.contains(&70.0));
        // Crowded: only powers of ten, then every other one.
        let (bold, _) = log_ticks(&(1.0..1000.0), 0.9);
        assert_eq!(bold, vec![1.0, 10.0, 100.0, 1000.0]);
        let (bold, _) = log_ticks(&(1e-8..1e8), 1.5);
        assert!(
            bold.iter().all(|v| v.log10().round() as i32 % 2 == 0),
            "{bold:?}"
        );
        // Within a decade: round linear steps.
        let (bold, _) = log_ticks(&(280.0..1400.0), 0.06);
        assert!(bold.len() >= 4, "{bold:?}");
        assert!(
            bold.iter()
                .all(|v| *v >= 280.0 && *v <= 1400.0 && v % 100.0 == 0.0)
        );
    }
}
