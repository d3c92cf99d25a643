//! Mean ± standard deviation over seeds.

/// Mean and sample standard deviation (n − 1 in the denominator; `None` for one value).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Stat {
    pub n: usize,
    pub mean: f64,
    pub std: Option<f64>,
}

impl Stat {
    /// `None` for no values.
    pub fn of(values: &[f64]) -> Option<Self> {
        let n = values.len();
        if n == 0 {
            return None;
        }
        let mean = values.iter().sum::<f64>() / n as f64;
        let std = (n > 1).then(|| {
            let ss: f64 = values.iter().map(|v| (v - mean) * (v - mean)).sum();
            (ss / (n - 1) as f64).sqrt()
        });
        Some(Self { n, mean, std })
    }

    /// `mean ± std` with four significant digits (just the mean for one value).
    pub fn show(&self) -> String {
        match self.std {
            Some(s) => format!("{} ± {}", sig(self.mean), sig(s)),
            None => sig(self.mean),
        }
    }
}

/// Four significant digits, fixed-point between 1e-3 and 1e5, scientific outside.
pub fn sig(x: f64) -> String {
    if !x.is_finite() {
        return format!("{x}");
    }
    if x == 0.0 {
        return "0".into();
    }
    // The magnitude after rounding to four digits (0.099999 is shown as 0.1000, not 0.10000).
    let first = x.abs().log10().floor() as i32;
    let scale = 10f64.powi(3 - first);
    let rounded = (x.abs() * scale).round() / scale;
    let magnitude = rounded.log10().floor() as i32;
    if (-3..5).contains(&magnitude) {
        let decimals = (3 - magnitude).max(0) as usize;
        format!("{x:.decimals$}")
    } else {
        format!("{x:.3e}")
    }
}

/// A count with thousands separators: 7941042 → "7,941,042".
pub fn thousands(n: usize) -> String {
    let digits = n.to_string();
    let mut out = String::with_capacity(digits.len() + digits.len() / 3);
    for (i, ch) in digits.chars().enumerate() {
        if i > 0 && (digits.len() - i).is_multiple_of(3) {
            out.push(',');
        }
        out.push(ch);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mean_and_sample_std_by_hand() {
        let s = Stat::of(&[1.0, 2.0, 4.0]).unwrap();
        assert!((s.mean - 7.0 / 3.0).abs() < 1e-15);
        // Deviations −4/3, −1/3, 5/3: Σ² = 42/9, over n − 1 = 2.
        assert!((s.std.unwrap() - (42.0f64 / 18.0).sqrt()).abs() < 1e-15);
        assert_eq!(Stat::of(&[0.5]).unwrap().std, None);
        assert!(Stat::of(&[]).is_none());
        assert_eq!(Stat::of(&[0.5]).unwrap().show(), "0.5000");
    }

    #[test]
    fn formatting() {
        assert_eq!(sig(0.030_334), "0.03033");
        assert_eq!(sig(1.5), "1.500");
        assert_eq!(sig(1234.4), "1234");
        assert_eq!(sig(-0.0012344), "-0.001234");
        assert_eq!(sig(0.000_123_4), "1.234e-4");
        assert_eq!(sig(0.0), "0");
        assert_eq!(sig(0.099_999_999), "0.1000");
        assert_eq!(sig(9.99996), "10.00");
        assert_eq!(thousands(7_941_042), "7,941,042");
        assert_eq!(thousands(999), "999");
        assert_eq!(thousands(1000), "1,000");
        assert_eq!(Stat::of(&[0.01, 0.03]).unwrap().show(), "0.02000 ± 0.01414");
    }
}
