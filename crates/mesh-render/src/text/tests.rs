use super::*;

#[test]
fn text_is_drawn_dark_where_it_is_anchored_and_fit_shortens() {
    let mut image = Image::filled(200, 60, [255; 3]).unwrap();
    draw(
        &mut image,
        "Hello",
        (100, 30),
        Anchor::CENTER,
        &Style::new(20.0),
    )
    .unwrap();
    let dark: Vec<(u32, u32)> = (0..60)
        .flat_map(|y| (0..200).map(move |x| (x, y)))
        .filter(|&(x, y)| image.pixel(x, y).unwrap()[0] < 100)
        .collect();
    assert!(dark.len() > 50, "{} dark pixels", dark.len());
    let mean_x = dark.iter().map(|p| p.0 as f32).sum::<f32>() / dark.len() as f32;
    assert!((mean_x - 100.0).abs() < 15.0, "centred at {mean_x}");
    assert!(
        dark.iter()
            .all(|&(x, y)| (60..140).contains(&x) && (15..45).contains(&y))
    );

    let style = Style::new(14.0);
    let long = "a rather long caption that cannot fit";
    let short = fit(long, &style, 80).unwrap();
    assert!(short.ends_with('…') && short.len() < long.len());
    assert!(text_size(&short, &style).unwrap().0 <= 80);
    assert_eq!(fit("ok", &style, 80).unwrap(), "ok");
}

/// Darkness (0–1) of a pixel drawn in black on white.
pub(crate) fn ink(image: &Image, x: u32, y: u32) -> f32 {
    1.0 - f32::from(image.pixel(x, y).unwrap()[0]) / 255.0
}

/// The first and last column of each run of columns holding a half-dark pixel or darker.
pub(crate) fn column_runs(image: &Image) -> Vec<(u32, u32)> {
    let dark = |x: u32| (0..image.height).any(|y| ink(image, x, y) > 0.5);
    let mut runs = Vec::new();
    let mut start = None;
    for x in 0..=image.width {
        match (x < image.width && dark(x), start) {
            (true, None) => start = Some(x),
            (false, Some(s)) => {
                runs.push((s, x - 1));
                start = None;
            }
            _ => {}
        }
    }
    runs
}

/// The bounding box (x0, y0, x1, y1, inclusive) of pixels with a fifth of full ink or more,
/// and the ink-weighted centre of all ink.
pub(crate) fn ink_box(image: &Image) -> ((u32, u32, u32, u32), (f32, f32)) {
    let (mut b, mut sum, mut sx, mut sy) = ((u32::MAX, u32::MAX, 0, 0), 0.0, 0.0, 0.0);
    for y in 0..image.height {
        for x in 0..image.width {
            let c = ink(image, x, y);
            if c >= 0.2 {
                b = (b.0.min(x), b.1.min(y), b.2.max(x), b.3.max(y));
            }
            (sum, sx, sy) = (sum + c, sx + c * x as f32, sy + c * y as f32);
        }
    }
    (b, (sx / sum, sy / sum))
}

pub(crate) fn black(size: f64) -> Style {
    Style {
        color: [0; 3],
        ..Style::new(size)
    }
}

/// The ink-weighted x centre of each glyph: columns are split between the runs of dark
/// columns halfway across the gaps, so faint anti-aliased ink still counts.
pub(crate) fn glyph_centres(image: &Image) -> Vec<f32> {
    let runs = column_runs(image);
    let cuts: Vec<u32> = runs
        .windows(2)
        .map(|w| (w[0].1 + w[1].0).div_ceil(2))
        .collect();
    let mut centres = vec![(0.0f32, 0.0f32); runs.len()];
    for x in 0..image.width {
        let k = cuts.iter().filter(|&&c| x >= c).count();
        let c: f32 = (0..image.height).map(|y| ink(image, x, y)).sum();
        centres[k] = (centres[k].0 + c, centres[k].1 + c * x as f32);
    }
    centres.iter().map(|(sum, sx)| sx / sum).collect()
}

#[test]
fn digits_are_evenly_spaced() {
    // DejaVu's digits all have the same advance and are centred in it, so their centres
    // should be one advance apart. Whole-pixel pen positions and dropped side bearings (the
    // plotters text path) put them 6 and 9 px apart alternately in "01010101" at 14 px.
    for digits in ["00000000", "01010101", "18181818", "90210188"] {
        for size in [11.0, 12.0, 13.0, 14.0] {
            let mut image = Image::filled(120, 30, [255; 3]).unwrap();
            draw(
                &mut image,
                digits,
                (5, 15),
                Anchor::LEFT_CENTER,
                &black(size),
            )
            .unwrap();
            let centres = glyph_centres(&image);
            assert_eq!(centres.len(), 8, "{digits} at {size} px: {centres:?}");
            let pitch: Vec<f32> = centres.windows(2).map(|w| w[1] - w[0]).collect();
            let min = pitch.iter().copied().fold(f32::INFINITY, f32::min);
            let max = pitch.iter().copied().fold(0.0, f32::max);
            assert!(max - min <= 0.5, "{digits} at {size} px: pitch {pitch:?}");
        }
    }
}

#[test]
fn text_size_grows_with_the_text_and_matches_the_ink() {
    let style = black(14.0);
    let mut last = 0;
    // Digits 0 and 8 have side bearings under a pixel, so box and ink nearly coincide.
    for text in [
        "0",
        "00",
        "0.0",
        "0880",
        "0.1880",
        "0013 rec. 0",
        "0013 rec., mean 0.188",
    ] {
        let (w, h) = text_size(text, &style).unwrap();
        assert!(w > last, "{text}: {w}");
        assert_eq!(h, 14);
        last = w;
        let mut image = Image::filled(220, 30, [255; 3]).unwrap();
        draw(&mut image, text, (10, 15), Anchor::LEFT_CENTER, &style).unwrap();
        let ((x0, _, x1, _), _) = ink_box(&image);
        let inked = x1 + 1 - x0;
        assert!(w.abs_diff(inked) <= 2, "{text}: size {w}, ink {inked}");
    }
    assert_eq!(text_size("", &style).unwrap(), (0, 0));
}

#[test]
fn centred_text_is_centred_on_its_anchor() {
    for (text, size) in [("0000", 14.0), ("H0H", 12.0), ("808", 20.0)] {
        for anchor_x in [40, 41] {
            let mut image = Image::filled(90, 40, [255; 3]).unwrap();
            let at = (anchor_x, 20);
            draw(&mut image, text, at, Anchor::CENTER, &black(size)).unwrap();
            let (_, (cx, cy)) = ink_box(&image);
            assert!((cx - at.0 as f32).abs() <= 1.0, "{text}: x {cx} vs {at:?}");
            assert!((cy - at.1 as f32).abs() <= 1.0, "{text}: y {cy} vs {at:?}");
        }
    }
    // Right-anchored text ends where left-anchored text begins.
    let mut image = Image::filled(90, 40, [255; 3]).unwrap();
    let right = Anchor {
        h: HPos::Right,
        v: VPos::Bottom,
    };
    draw(&mut image, "00", (44, 30), right, &black(14.0)).unwrap();
    let ((_, _, x1, y1), _) = ink_box(&image);
    assert!(
        (42..=44).contains(&x1) && (24..=30).contains(&y1),
        "{x1} {y1}"
    );
}

#[test]
fn vertical_text_reads_upwards_around_its_anchor() {
    let mut image = Image::filled(60, 120, [255; 3]).unwrap();
    let style = Style {
        turn: Turn::Cw270,
        ..black(14.0)
    };
    draw(&mut image, "mean error", (30, 60), Anchor::CENTER, &style).unwrap();
    let ((x0, y0, x1, y1), (cx, cy)) = ink_box(&image);
    assert!(y1 - y0 > 3 * (x1 - x0), "ink {x0}..{x1} × {y0}..{y1}");
    assert!(
        (cx - 30.0).abs() <= 1.5 && (cy - 60.0).abs() <= 1.5,
        "({cx}, {cy})"
    );
    // The first letter ("m", wide and low) is at the bottom: more ink below the centre.
    let below: f32 = (61..120).flat_map(|y| (0..60).map(move |x| (x, y))).count() as f32;
    assert!(below > 0.0);
    let ink_rows = |ys: std::ops::Range<u32>| -> f32 {
        ys.flat_map(|y| (0..60).map(move |x| (x, y)))
            .map(|(x, y)| ink(&image, x, y))
            .sum()
    };
    assert!(
        ink_rows(y1 - 8..y1 + 1) > ink_rows(y0..y0 + 9),
        "m at the bottom"
    );
}

#[test]
fn every_turn_is_centred_on_its_anchor_with_its_first_letter_where_the_text_starts() {
    // "m" first: the start of the text has more ink than its end ("r").
    for (turn, tall) in [
        (Turn::None, false),
        (Turn::Cw90, true),
        (Turn::Cw180, false),
        (Turn::Cw270, true),
    ] {
        let mut image = Image::filled(120, 120, [255; 3]).unwrap();
        let style = Style {
            turn,
            ..black(14.0)
        };
        draw(&mut image, "mean error", (60, 60), Anchor::CENTER, &style).unwrap();
        let ((x0, y0, x1, y1), (cx, cy)) = ink_box(&image);
        let (w, h) = (x1 - x0, y1 - y0);
        assert_eq!(h > 3 * w, tall, "{turn:?}: ink {x0}..{x1} × {y0}..{y1}");
        assert!(
            (cx - 60.0).abs() <= 1.5 && (cy - 60.0).abs() <= 1.5,
            "{turn:?}: ({cx}, {cy})"
        );
        // Ink in the first and the last 8 pixels along the reading direction.
        let sum = |xs: std::ops::RangeInclusive<u32>, ys: std::ops::RangeInclusive<u32>| -> f32 {
            xs.flat_map(|x| ys.clone().map(move |y| (x, y)))
                .map(|(x, y)| ink(&image, x, y))
                .sum()
        };
        let (start, end) = match turn {
            Turn::None => (sum(x0..=x0 + 8, y0..=y1), sum(x1 - 8..=x1, y0..=y1)),
            Turn::Cw90 => (sum(x0..=x1, y0..=y0 + 8), sum(x0..=x1, y1 - 8..=y1)),
            Turn::Cw180 => (sum(x1 - 8..=x1, y0..=y1), sum(x0..=x0 + 8, y0..=y1)),
            Turn::Cw270 => (sum(x0..=x1, y1 - 8..=y1), sum(x0..=x1, y0..=y0 + 8)),
        };
        assert!(start > end, "{turn:?}: start {start}, end {end}");
    }
}

#[test]
fn text_partly_or_wholly_off_the_image_is_clipped() {
    for turn in [Turn::None, Turn::Cw90, Turn::Cw180, Turn::Cw270] {
        let style = Style {
            turn,
            ..black(16.0)
        };
        for at in [
            (-20, 5),
            (25, -3),
            (38, 18),
            (-500, -500),
            (i32::MAX, i32::MIN),
        ] {
            let mut image = Image::filled(40, 20, [255; 3]).unwrap();
            draw(&mut image, "clipped 0.188", at, Anchor::CENTER, &style).unwrap();
        }
    }
    let mut image = Image::filled(40, 20, [255; 3]).unwrap();
    draw(
        &mut image,
        "0.188",
        (-8, 10),
        Anchor::LEFT_CENTER,
        &black(14.0),
    )
    .unwrap();
    let x0 = ink_box(&image).0.0;
    assert!(x0 <= 2, "the visible part is drawn from {x0}");
    for size in [0.0, -3.0, f64::NAN] {
        draw(&mut image, "x", (5, 5), Anchor::CENTER, &black(size)).unwrap();
        assert_eq!(text_size("x", &black(size)).unwrap(), (0, 0));
    }
}

#[test]
fn whole_pixel_sizes_are_not_rounded_up_by_float_noise() {
    // ascent − descent is the pixel size, give or take f32 rounding (26.000002 at 26 px).
    for size in [10.0, 13.0, 14.0, 16.0, 25.0, 26.0, 27.0] {
        assert_eq!(text_size("x", &Style::new(size)).unwrap().1, size as u32);
    }
    assert_eq!(text_size("x", &Style::new(13.5)).unwrap().1, 14);
}
