use super::*;

fn decay(name: &str, n: usize, offset: f64) -> Curve {
    Curve {
        name: name.into(),
        points: (0..n)
            .map(|i| {
                let x = i as f64;
                [x, 1000.0 * (-x / (n as f64 / 6.0)).exp() + offset]
            })
            .collect(),
    }
}

fn log_plot() -> LinePlot<'static> {
    LinePlot {
        title: "loss",
        x_label: "step",
        y_label: "MSE",
        log_y: true,
        width: 480,
        height: 320,
    }
}

fn near(p: [u8; 3], c: [u8; 3], tolerance: i32) -> bool {
    p.iter()
        .zip(c)
        .all(|(a, b)| (i32::from(*a) - i32::from(b)).abs() <= tolerance)
}

/// Pixels of the image within `tolerance` of `c` in every channel.
fn count(image: &Image, c: [u8; 3], tolerance: i32) -> usize {
    image
        .rgb
        .chunks_exact(3)
        .filter(|p| near([p[0], p[1], p[2]], c, tolerance))
        .count()
}

#[test]
fn two_curve_log_plot_shows_both_colours() {
    // Unnamed curves: no legend, so the colours can only come from the curves themselves.
    let curves = [decay("", 60, 300.0), decay("", 60, 30.0)];
    let image = line_plot(&log_plot(), &curves, &[]).unwrap();
    assert_eq!((image.width, image.height), (480, 320));
    assert_eq!(image.rgb.len(), 480 * 320 * 3);
    assert!(image.rgb.iter().any(|&v| v < 200), "all white");
    for color in &SERIES_COLORS[..2] {
        let n = count(&image, *color, 12);
        assert!(n > 100, "{n} pixels of curve colour {color:?}");
    }
    assert_eq!(
        count(&image, SERIES_COLORS[2], 12),
        0,
        "a third colour appeared"
    );
    // Named: a legend appears in the (empty) upper right corner and adds the colours there.
    let named = [decay("train", 60, 300.0), decay("validation", 60, 30.0)];
    let with_legend = line_plot(&log_plot(), &named, &[]).unwrap();
    assert_ne!(with_legend, image);
    let in_upper_right = |image: &Image| {
        let mut n = 0;
        for y in 0..image.height / 2 {
            for x in image.width / 2..image.width {
                n += usize::from(near(image.pixel(x, y).unwrap(), SERIES_COLORS[1], 12));
            }
        }
        n
    };
    assert!(in_upper_right(&with_legend) > in_upper_right(&image));
}

#[test]
fn log_axis_spans_decades_and_linear_axis_does_not() {
    // Same data, 300 .. 1300 on a log axis vs a linear one: on the log axis the curve's
    // start (high) lies proportionally lower in the frame.
    let curves = [decay("", 100, 1.0)];
    let log = render(&log_plot(), &curves, &[]).unwrap();
    let linear_plot = LinePlot {
        log_y: false,
        ..log_plot()
    };
    let linear = render(&linear_plot, &curves, &[]).unwrap();
    // Height (from the bottom of the frame) of the curve at 1/3 of the x range.
    let curve_height = |(image, frame): &(Image, Frame)| {
        let x = (frame.x.start + (frame.x.end - frame.x.start) / 3) as u32;
        let y = (frame.y.start..frame.y.end)
            .find(|&y| near(image.pixel(x, y as u32).unwrap(), SERIES_COLORS[0], 40))
            .expect("curve pixel in the column");
        f64::from(frame.y.end - y) / f64::from(frame.y.end - frame.y.start)
    };
    // y at x = 33 is 1000·e^-2 + 1 ≈ 136 of 1..1001: linear ≈ 0.14, log ≈ 0.71.
    let (hl, hg) = (curve_height(&linear), curve_height(&log));
    assert!((0.08..0.25).contains(&hl), "linear {hl}");
    assert!((0.6..0.8).contains(&hg), "log {hg}");
}

#[test]
fn solid_marker_is_a_column_at_its_x() {
    let curves = [decay("train", 200, 300.0)];
    let marker = Marker {
        x: 150.0,
        label: "best".into(),
        dashed: false,
    };
    let (image, frame) = render(&log_plot(), &curves, &[marker]).unwrap();
    // Expected column: linear map of x over the data range 0..199 onto the frame.
    let t = 150.0 / 199.0;
    let expected = frame.x.start + (t * f64::from(frame.x.end - frame.x.start)).floor() as i32;
    let column_share = |x: i32| {
        let on = (frame.y.start..frame.y.end)
            .filter(|&y| image.pixel(x as u32, y as u32) == Some(MARKER_SOLID))
            .count();
        on as f64 / f64::from(frame.y.end - frame.y.start)
    };
    let best = (expected - 1..=expected + 1)
        .map(column_share)
        .fold(0.0, f64::max);
    assert!(best > 0.8, "marker column covers only {best}");
    // And nowhere else: columns well away from it have no marker pixels.
    assert!(column_share(expected - 20) < 0.05);
    assert!(column_share(expected + 20) < 0.05);
}

#[test]
fn dashed_marker_is_a_broken_column() {
    let curves = [decay("train", 200, 300.0)];
    let marker = Marker {
        x: 50.0,
        label: "lr ×0.5".into(),
        dashed: true,
    };
    let (image, frame) = render(&log_plot(), &curves, &[marker]).unwrap();
    // plotters maps the x range onto the frame's first to last pixel (end - 1, not end).
    let x =
        frame.x.start + (50.0 / 199.0 * f64::from(frame.x.end - 1 - frame.x.start)).floor() as i32;
    let (on, gaps) = (frame.y.start..frame.y.end).fold((0, 0), |(on, gaps), y| {
        match image.pixel(x as u32, y as u32) == Some(MARKER_DASHED) {
            true => (on + 1, gaps),
            false => (on, gaps + 1),
        }
    });
    let share = f64::from(on) / f64::from(on + gaps);
    assert!((0.4..0.8).contains(&share), "dashed share {share}");
}

#[test]
fn log_y_rejects_zero_and_negative_naming_the_curve() {
    let mut bad = decay("validation", 10, 300.0);
    bad.points[7][1] = 0.0;
    let err = line_plot(&log_plot(), &[decay("train", 10, 300.0), bad.clone()], &[])
        .unwrap_err()
        .to_string();
    assert!(err.starts_with("curves: "), "{err}");
    assert!(err.contains("curve \"validation\": point 7"), "{err}");
    bad.points[7][1] = -2.0;
    let err = line_plot(&log_plot(), &[bad.clone()], &[]).unwrap_err();
    assert!(err.to_string().contains("point 7 (7, -2)"), "{err}");
    // A linear y axis shows them.
    let linear = LinePlot {
        log_y: false,
        ..log_plot()
    };
    line_plot(&linear, &[bad], &[]).unwrap();
}

#[test]
fn non_finite_values_are_errors() {
    let mut nan = decay("test", 10, 300.0);
    nan.points[3][0] = f64::NAN;
    let linear = LinePlot {
        log_y: false,
        ..log_plot()
    };
    for plot in [log_plot(), linear] {
        let err = line_plot(&plot, &[nan.clone()], &[])
            .unwrap_err()
            .to_string();
        assert!(err.contains("curve \"test\": point 3 (NaN, "), "{err}");
        assert!(err.contains("not finite"), "{err}");
    }
    let marker = Marker {
        x: f64::INFINITY,
        label: "best".into(),
        dashed: false,
    };
    let err = line_plot(&log_plot(), &[decay("a", 10, 1.0)], &[marker]).unwrap_err();
    assert!(
        matches!(
            err,
            RenderError::InvalidArgument {
                argument: "markers",
                ..
            }
        ),
        "{err}"
    );
    assert!(err.to_string().contains("\"best\""), "{err}");
}

#[test]
fn empty_and_too_small_are_errors() {
    let empty = Curve::default();
    for curves in [&[][..], &[empty.clone(), empty][..]] {
        let err = line_plot(&log_plot(), curves, &[]).unwrap_err();
        assert!(
            matches!(err, RenderError::Empty { argument: "curves" }),
            "{err}"
        );
    }
    let small = LinePlot {
        width: crate::MIN_PLOT_SIZE - 1,
        ..log_plot()
    };
    let err = line_plot(&small, &[decay("a", 10, 1.0)], &[]).unwrap_err();
    assert!(matches!(err, RenderError::Size { .. }), "{err}");
    // The smallest allowed size works, with texts and markers.
    let smallest = LinePlot {
        width: crate::MIN_PLOT_SIZE,
        height: crate::MIN_PLOT_SIZE,
        ..log_plot()
    };
    let marker = Marker {
        x: 3.0,
        label: "best".into(),
        dashed: false,
    };
    line_plot(&smallest, &[decay("a", 10, 1.0)], &[marker]).unwrap();
}

#[test]
fn single_point_curve_is_a_dot() {
    let curve = Curve {
        name: "only".into(),
        points: vec![[5.0, 42.0]],
    };
    for log_y in [true, false] {
        let plot = LinePlot {
            log_y,
            ..log_plot()
        };
        let (image, frame) = render(&plot, std::slice::from_ref(&curve), &[]).unwrap();
        // The dot is in the middle of the frame (zero extents are padded symmetrically).
        let cx = ((frame.x.start + frame.x.end) / 2) as u32;
        let cy = ((frame.y.start + frame.y.end) / 2) as u32;
        let dot = (cy - 3..=cy + 3)
            .flat_map(|y| (cx - 3..=cx + 3).map(move |x| (x, y)))
            .filter(|&(x, y)| image.pixel(x, y) == Some(SERIES_COLORS[0]))
            .count();
        assert!(dot >= 9, "log_y {log_y}: {dot} dot pixels");
    }
    // A single point with a marker elsewhere: the x range spans both.
    let marker = Marker {
        x: 10.0,
        label: String::new(),
        dashed: true,
    };
    line_plot(&log_plot(), &[curve], &[marker]).unwrap();
}

#[test]
fn extreme_inputs_render_without_panics() {
    let curve = |points: Vec<[f64; 2]>| Curve {
        name: "a curve with a rather long name for a small legend".into(),
        points,
    };
    let many_markers: Vec<Marker> = (0..40)
        .map(|i| Marker {
            x: f64::from(i),
            label: format!("marker number {i}"),
            dashed: i % 2 == 0,
        })
        .collect();
    let cases = [
        curve(vec![[0.0, 1e-300], [1.0, 1e300]]),
        curve(vec![[1e15, 1.0], [1e15 + 4.0, 2.0]]),
        curve(vec![[-1e300, -1e300], [1e300, 1e300]]),
        curve(vec![[0.0, -0.00201], [1.0, -0.00199]]),
        curve(
            (0..500)
                .map(|i| [f64::from(i), f64::from(i % 7) + 1.0])
                .collect(),
        ),
    ];
    for (width, height) in [(120, 120), (120, 900), (1600, 120), (1000, 600)] {
        for log_y in [false, true] {
            let plot = LinePlot {
                title: "a long title that does not fit into a small plot at all",
                x_label: "x axis description",
                y_label: "y axis description",
                log_y,
                width,
                height,
            };
            for (ci, c) in cases.iter().enumerate() {
                let result = line_plot(&plot, std::slice::from_ref(c), &many_markers);
                // Only the negative data on a log axis is refused.
                if log_y && (ci == 2 || ci == 3) {
                    let err = result.unwrap_err().to_string();
                    assert!(err.contains("point 0 (") && err.contains("y <= 0"), "{err}");
                } else {
                    let image = result
                        .unwrap_or_else(|e| panic!("{width}x{height} log {log_y} case {ci}: {e}"));
                    assert_eq!((image.width, image.height), (width, height));
                }
            }
        }
    }
}

#[test]
fn many_points_are_fine() {
    let curves = [
        decay("train", 20_000, 300.0),
        decay("validation", 20_000, 320.0),
    ];
    let plot = LinePlot {
        width: 900,
        height: 500,
        ..log_plot()
    };
    let image = line_plot(&plot, &curves, &[]).unwrap();
    assert!(count(&image, SERIES_COLORS[0], 40) > 200);
}
