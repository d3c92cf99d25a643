//! Colour maps: per-vertex error → colour, and a perceptual map for ordering points in plots.

/// Stops of the error map, low → high: a pale cool grey (small errors look like the neutral
/// mesh), through pale yellow and orange, to a dark red. Luminance falls monotonically, so the
/// map reads in grey-scale prints too.
pub const ERROR_STOPS: [[u8; 3]; 5] = [
    [226, 232, 240],
    [254, 224, 144],
    [253, 174, 97],
    [215, 48, 39],
    [140, 0, 30],
];

/// Viridis (dark violet → blue → green → yellow), sampled at eleven evenly spaced stops; used
/// to colour scatter points by their order.
pub const VIRIDIS_STOPS: [[u8; 3]; 11] = [
    [68, 1, 84],
    [72, 36, 117],
    [65, 68, 135],
    [53, 95, 141],
    [42, 120, 142],
    [33, 145, 140],
    [34, 168, 132],
    [68, 191, 112],
    [122, 209, 81],
    [189, 223, 38],
    [253, 231, 37],
];

/// Piecewise-linear interpolation of `stops` at `t` in `[0, 1]` (clamped; NaN gives the last
/// stop).
pub fn sample(stops: &[[u8; 3]], t: f32) -> [u8; 3] {
    let Some(&last) = stops.last() else {
        return [0; 3];
    };
    if stops.len() == 1 || t.is_nan() {
        return last;
    }
    let x = t.clamp(0.0, 1.0) * (stops.len() - 1) as f32;
    let i = (x.floor() as usize).min(stops.len() - 2);
    let f = x - i as f32;
    let (a, b) = (stops[i], stops[i + 1]);
    std::array::from_fn(|k| {
        (f32::from(a[k]) + f * (f32::from(b[k]) - f32::from(a[k]))).round() as u8
    })
}

/// The error map at `t` in `[0, 1]` (see [`ERROR_STOPS`]).
pub fn error_color(t: f32) -> [u8; 3] {
    sample(&ERROR_STOPS, t)
}

/// Per-vertex error → colour on [`ERROR_STOPS`], `0 ..= max`: 0 gives the first stop, `max` (and
/// anything above, or NaN) the last. With `max ≤ 0` or NaN, positive errors get the last colour
/// and the others the first; with an infinite `max`, every finite error gets the first.
pub fn error_colors(errors: &[f32], max: f32) -> Vec<[u8; 3]> {
    let usable = max > 0.0;
    errors
        .iter()
        .map(|&e| {
            let t = if usable {
                e / max
            } else if e > 0.0 || e.is_nan() {
                1.0
            } else {
                0.0
            };
            error_color(t)
        })
        .collect()
}

/// Relative luminance (Rec. 709 weights on the 8-bit values), 0..=255.
pub fn luminance(c: [u8; 3]) -> f32 {
    0.2126 * f32::from(c[0]) + 0.7152 * f32::from(c[1]) + 0.0722 * f32::from(c[2])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn error_colors_run_from_the_first_to_the_last_stop_with_falling_luminance() {
        let max = 0.25;
        let errors: Vec<f32> = (0..=100).map(|i| i as f32 / 100.0 * max).collect();
        let colors = error_colors(&errors, max);
        assert_eq!(colors[0], ERROR_STOPS[0]);
        assert_eq!(colors[100], ERROR_STOPS[4]);
        for pair in colors.windows(2) {
            assert!(luminance(pair[1]) <= luminance(pair[0]) + 0.5, "{pair:?}");
        }
        assert!(luminance(colors[0]) - luminance(colors[100]) > 150.0);
        // Clamped above max and below 0; NaN counts as the worst.
        let extra = error_colors(&[2.0 * max, -1.0, f32::NAN], max);
        assert_eq!(extra, vec![ERROR_STOPS[4], ERROR_STOPS[0], ERROR_STOPS[4]]);
        // Degenerate maxima do not divide by zero.
        assert_eq!(
            error_colors(&[0.0, 1.0], 0.0),
            vec![ERROR_STOPS[0], ERROR_STOPS[4]]
        );
        assert_eq!(error_colors(&[0.5], f32::INFINITY), vec![ERROR_STOPS[0]]);
    }

    #[test]
    fn viridis_luminance_rises() {
        for pair in VIRIDIS_STOPS.windows(2) {
            assert!(luminance(pair[1]) > luminance(pair[0]), "{pair:?}");
        }
        assert_eq!(sample(&VIRIDIS_STOPS, 0.5), VIRIDIS_STOPS[5]);
        assert_eq!(sample(&VIRIDIS_STOPS, 0.05), [70, 19, 101]);
    }
}
