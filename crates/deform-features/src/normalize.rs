//! Linear scaling of the features into [−0.95, 0.95], as the authors do (utils.py:116-126): one
//! min/max over all rotation entries (channels 0–2) and one over all stretch entries (channels
//! 3–8), each widened by 1e-6, over every frame and vertex of the feature sets it is fitted on.
//!
//! y = 1.9 (x − min)/(max − min) − 0.95, and back x = (max − min)(y + 0.95)/1.9 + min, both in
//! f64 (results stored as f32).

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
        self.map(features, |x, lo, hi| {
            2.0 * TARGET * (x - lo) / (hi - lo) - TARGET
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
    fn json_round_trip_and_validation() {
        let n = Normalization {
            rotation_min: -3.5,
            rotation_max: 4.25,
            scale_min: -0.5,
            scale_max: 1.75,
        };
        assert_eq!(Normalization::from_json(&n.to_json()).unwrap(), n);
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
