//! Linear scaling of the features into [−0.95, 0.95], as the authors do (utils.py:116-126): one
//! min/max over all rotation entries (channels 0–2) and one over all stretch entries (channels
//! 3–8), each widened by 1e-6, over every frame and vertex of the feature sets it is fitted on.
//!
//! y = 1.9 (x − min)/(max − min) − 0.95, and back x = (max − min)(y + 0.95)/1.9 + min, both in
//! f64 (results stored as f32).
//!
//! [`Normalization::fit_quantile`] fits each range between two quantiles instead, and clamps
//! what lies beyond: a few outlying vertices (0.01 % of horse-gallop's stretch entries reach
//! −9.8 and 18.8 while 99 % lie in [−0.2, 1.5]) otherwise squeeze every ordinary value into a
//! few percent of the target range.

use crate::error::FeatureError;
use crate::features::{CHANNELS, FeatureSet, ROTATION_CHANNELS};

/// Half-width of the target range.
pub const TARGET: f64 = 0.95;
/// The authors' padding of each range (keeps a constant group from dividing by zero).
pub const PADDING: f64 = 1e-6;

/// The two affine maps (rotation group, stretch group), serialisable as JSON.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Normalization {
    pub rotation_min: f64,
    pub rotation_max: f64,
    pub scale_min: f64,
    pub scale_max: f64,
    /// Normalised values are clamped to ±this (set by [`Self::fit_quantile`]; absent = none).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub clamp: Option<f64>,
}

impl Normalization {
    /// Fits the ranges over every frame of every set given (later: the training split only).
    pub fn fit<'a>(sets: impl IntoIterator<Item = &'a FeatureSet>) -> Result<Self, FeatureError> {
        let mut r = (f64::INFINITY, f64::NEG_INFINITY);
        let mut s = (f64::INFINITY, f64::NEG_INFINITY);
        for set in sets {
            for vertex in set.as_slice().chunks_exact(CHANNELS) {
                for (c, &x) in vertex.iter().enumerate() {
                    let x = x as f64;
                    if !x.is_finite() {
                        return Err(FeatureError::input("features", "non-finite value"));
                    }
                    let range = if c < ROTATION_CHANNELS {
                        &mut r
                    } else {
                        &mut s
                    };
                    range.0 = range.0.min(x);
                    range.1 = range.1.max(x);
                }
            }
        }
        if !r.0.is_finite() {
            return Err(FeatureError::input(
                "features",
                "no features to fit a normalisation on",
            ));
        }
        Ok(Self {
            rotation_min: r.0 - PADDING,
            rotation_max: r.1 + PADDING,
            scale_min: s.0 - PADDING,
            scale_max: s.1 + PADDING,
            clamp: None,
        })
    }

    /// Fits each group's range between its quantiles `q` and `1 − q` (0 ≤ q < 0.5; 0 is
    /// [`Self::fit`]) and clamps normalised values to ±1, so that outliers map to the edge of
    /// what a tanh output can reach instead of far beyond it.
    pub fn fit_quantile<'a>(
        sets: impl IntoIterator<Item = &'a FeatureSet>,
        q: f64,
    ) -> Result<Self, FeatureError> {
        if !(0.0..0.5).contains(&q) {
            return Err(FeatureError::input(
                "quantile",
                format!("{q} is not in [0, 0.5)"),
            ));
        }
        let sets: Vec<&FeatureSet> = sets.into_iter().collect();
        let full = Self::fit(sets.iter().copied())?;
        if q == 0.0 {
            return Ok(full);
        }
        let (mut r, mut s) = (Vec::new(), Vec::new());
        for set in &sets {
            for vertex in set.as_slice().chunks_exact(CHANNELS) {
                r.extend_from_slice(&vertex[..ROTATION_CHANNELS]);
                s.extend_from_slice(&vertex[ROTATION_CHANNELS..]);
            }
        }
        let bounds = |v: &mut Vec<f32>| {
            let pick = |v: &mut Vec<f32>, k: usize| *v.select_nth_unstable_by(k, f32::total_cmp).1;
            let n = v.len();
            let lo = ((q * n as f64).floor() as usize).min(n - 1);
            let hi = (((1.0 - q) * n as f64).ceil() as usize).clamp(1, n) - 1;
            (pick(v, lo) as f64 - PADDING, pick(v, hi) as f64 + PADDING)
        };
        let (rotation_min, rotation_max) = bounds(&mut r);
        let (scale_min, scale_max) = bounds(&mut s);
        Ok(Self {
            rotation_min,
            rotation_max,
            scale_min,
            scale_max,
            clamp: Some(1.0),
        })
    }

    /// Checks that both ranges are finite and non-empty (e.g. after deserialising).
    pub fn validate(&self) -> Result<(), FeatureError> {
        let ok = |lo: f64, hi: f64| lo.is_finite() && hi.is_finite() && hi > lo;
        if ok(self.rotation_min, self.rotation_max) && ok(self.scale_min, self.scale_max) {
            Ok(())
        } else {
            Err(FeatureError::input(
                "normalization",
                format!("ranges must be finite with max > min, got {self:?}"),
            ))
        }
    }

    fn range(&self, channel: usize) -> (f64, f64) {
        if channel < ROTATION_CHANNELS {
            (self.rotation_min, self.rotation_max)
        } else {
            (self.scale_min, self.scale_max)
        }
    }

    /// Raw features → [−0.95, 0.95] (values outside the fitted range map outside it).
    pub fn apply(&self, features: &FeatureSet) -> FeatureSet {
        let limit = self.clamp.unwrap_or(f64::INFINITY);
        self.map(features, |x, lo, hi| {
            (2.0 * TARGET * (x - lo) / (hi - lo) - TARGET).clamp(-limit, limit)
        })
    }

    /// Normalised values → raw features.
    pub fn invert(&self, normalized: &FeatureSet) -> FeatureSet {
        self.map(normalized, |y, lo, hi| {
            (hi - lo) * (y + TARGET) / (2.0 * TARGET) + lo
        })
    }

    fn map(&self, features: &FeatureSet, f: impl Fn(f64, f64, f64) -> f64) -> FeatureSet {
        let mut out = features.clone();
        for vertex in out.as_mut_slice().chunks_exact_mut(CHANNELS) {
            for (c, x) in vertex.iter_mut().enumerate() {
                let (lo, hi) = self.range(c);
                *x = f(*x as f64, lo, hi) as f32;
            }
        }
        out
    }

    /// JSON text (the form stored in a features file's metadata).
    pub fn to_json(&self) -> String {
        // Serialising four f64 fields cannot fail.
        serde_json::to_string(self).unwrap_or_default()
    }

    /// Parses and validates the JSON written by [`Normalization::to_json`].
    pub fn from_json(text: &str) -> Result<Self, FeatureError> {
        let n: Self = serde_json::from_str(text)
            .map_err(|e| FeatureError::input("normalization", e.to_string()))?;
        n.validate()?;
        Ok(n)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn set(values: Vec<f32>) -> FeatureSet {
        let v = values.len() / CHANNELS;
        FeatureSet::new(1, v, values).unwrap()
    }

    #[test]
    fn maps_each_group_onto_the_target_range_and_back() {
        let a = set(vec![
            0.5, -1.0, 2.0, 1.0, 0.1, 0.0, 1.2, -0.3, 0.9, //
            -3.0, 0.0, 1.0, 0.8, 0.0, 0.2, 1.0, 0.0, 1.1,
        ]);
        let n = Normalization::fit([&a]).unwrap();
        assert_eq!(n.rotation_min, -3.0 - PADDING);
        assert_eq!(n.rotation_max, 2.0 + PADDING);
        assert!((n.scale_min - (-0.3 - PADDING)).abs() < 1e-7);
        let y = n.apply(&a);
        let (lo, hi) = y
            .as_slice()
            .iter()
            .fold((1.0f32, -1.0f32), |(l, h), &x| (l.min(x), h.max(x)));
        assert!(lo >= -0.95 && hi <= 0.95 && lo < -0.949 && hi > 0.949);
        // Rotation −3.0 is the group minimum → −0.95 (up to the padding).
        assert!((y.as_slice()[9] + 0.95).abs() < 1e-6);
        let back = n.invert(&y);
        for (x, z) in a.as_slice().iter().zip(back.as_slice()) {
            assert!((x - z).abs() < 1e-6);
        }
    }

    #[test]
    fn quantile_ranges_ignore_outliers_and_clamp_them() {
        // 1,000 vertices: rotations uniform in [−1, 1], stretches in [0.5, 1.5], and one vertex
        // far out in both groups.
        let mut values = Vec::new();
        for i in 0..1000 {
            let t = i as f32 / 999.0;
            values.extend([2.0 * t - 1.0; 3]);
            values.extend([0.5 + t; 6]);
        }
        values[..3].copy_from_slice(&[-40.0; 3]);
        values[3..9].copy_from_slice(&[90.0; 6]);
        let a = set(values);
        let full = Normalization::fit([&a]).unwrap();
        assert_eq!(full, Normalization::fit_quantile([&a], 0.0).unwrap());
        assert!(full.scale_max > 89.0 && full.clamp.is_none());
        let n = Normalization::fit_quantile([&a], 0.01).unwrap();
        // The 1 % and 99 % quantiles of each group, by a sort.
        let mut rot: Vec<f32> = a
            .as_slice()
            .chunks(9)
            .flat_map(|v| v[..3].to_vec())
            .collect();
        rot.sort_by(f32::total_cmp);
        assert_eq!(n.rotation_min, rot[30] as f64 - PADDING);
        assert_eq!(n.rotation_max, rot[2969] as f64 + PADDING);
        assert!(n.scale_max < 1.5 && n.scale_min > 0.5, "{n:?}");
        let y = n.apply(&a);
        let s = y.as_slice();
        // The outliers sit at the clamp; ordinary values spread over the target range.
        assert_eq!((s[0], s[3]), (-1.0, 1.0));
        assert!(s.iter().all(|x| x.abs() <= 1.0));
        let middle = &s[9 * 500..9 * 500 + 9];
        assert!(middle.iter().all(|x| x.abs() < 0.05), "{middle:?}");
        assert!(Normalization::fit_quantile([&a], 0.5).is_err());
    }

    #[test]
    fn json_round_trip_and_validation() {
        let n = Normalization {
            rotation_min: -3.5,
            rotation_max: 4.25,
            scale_min: -0.5,
            scale_max: 1.75,
            clamp: None,
        };
        assert_eq!(Normalization::from_json(&n.to_json()).unwrap(), n);
        // Older JSON has no clamp.
        assert!(!n.to_json().contains("clamp"));
        let clamped = Normalization {
            clamp: Some(1.0),
            ..n
        };
        assert_eq!(
            Normalization::from_json(&clamped.to_json()).unwrap(),
            clamped
        );
        assert!(Normalization::from_json("{\"rotation_min\":1}").is_err());
        let bad = Normalization {
            rotation_max: -4.0,
            ..n
        };
        assert!(Normalization::from_json(&bad.to_json()).is_err());
        let nan = set(vec![f32::NAN; 9]);
        assert!(Normalization::fit([&nan]).is_err());
    }
}
