use super::ChartBackend;
use crate::image::Image;
use crate::text::tests::{black, glyph_centres, ink_box};
use crate::text::{self, Anchor, FAMILY, Style, Turn, ensure_font};
use plotters::backend::RGBPixel;
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use plotters::style::{FontStyle, FontTransform};

type Root<'b> = DrawingArea<ChartBackend<'b>, Shift>;

/// A `w`×`h` image drawn on white by `draw` through a [`ChartBackend`].
fn chart(w: u32, h: u32, draw: impl FnOnce(&Root)) -> Image {
    ensure_font().unwrap();
    let mut rgb = vec![255u8; 3 * w as usize * h as usize];
    {
        let root = ChartBackend::with_buffer(&mut rgb, (w, h)).into_drawing_area();
        draw(&root);
        root.present().unwrap();
    }
    Image {
        width: w,
        height: h,
        rgb,
    }
}

/// Black text of `size` pixels as a chart asks for it, anchored at `pos`.
fn chart_style(size: f64, pos: Pos) -> TextStyle<'static> {
    (FAMILY, size).into_font().color(&BLACK).pos(pos)
}

/// The largest difference of any channel between two images of the same size.
fn max_difference(a: &Image, b: &Image) -> u8 {
    assert_eq!((a.width, a.height), (b.width, b.height));
    a.rgb
        .iter()
        .zip(&b.rgb)
        .map(|(p, q)| p.abs_diff(*q))
        .max()
        .unwrap_or(0)
}

#[test]
fn tick_labels_drawn_through_the_backend_have_evenly_spaced_digits() {
    let left = Pos::new(HPos::Left, VPos::Center);
    for size in [10.0, 11.0, 12.0, 13.0, 14.0, 16.0] {
        // The digits of each label, by index among its glyphs (the runs of dark columns).
        for (label, glyphs, digits) in [
            ("01010101", 8, 0..8),
            ("18181818", 8, 0..8),
            ("0.188", 5, 2..5),
            ("-100.0", 6, 1..4),
            ("-0.1100", 7, 3..7),
        ] {
            let image = chart(120, 30, |root| {
                root.draw_text(label, &chart_style(size, left), (5, 15))
                    .unwrap()
            });
            let centres = glyph_centres(&image);
            assert_eq!(centres.len(), glyphs, "{label} at {size} px: {centres:?}");
            // DejaVu's digits share one advance and are centred in it: one advance apart.
            let pitch: Vec<f32> = centres[digits].windows(2).map(|w| w[1] - w[0]).collect();
            let min = pitch.iter().copied().fold(f32::INFINITY, f32::min);
            let max = pitch.iter().copied().fold(0.0, f32::max);
            assert!(max - min <= 0.5, "{label} at {size} px: pitch {pitch:?}");
        }
    }
}

#[test]
fn estimated_text_size_is_text_size() {
    for size in [10.0, 13.5, 16.0, 26.0] {
        for bold in [false, true] {
            for text in ["", "0", "0.188", "-100.0", "loss (MSE × 10⁴)", "validation"] {
                let font_style = if bold {
                    FontStyle::Bold
                } else {
                    FontStyle::Normal
                };
                let style = Style {
                    bold,
                    ..Style::new(size)
                };
                let expected = text::text_size(text, &style).unwrap();
                chart(10, 10, |root| {
                    let chart_style = (FAMILY, size, font_style).into_font();
                    let turned = chart_style.transform(FontTransform::Rotate270);
                    for s in [chart_style, turned] {
                        let got = root.estimate_text_size(text, &s.into()).unwrap();
                        assert_eq!(got, expected, "{text:?} at {size} px, bold {bold}");
                    }
                });
            }
        }
    }
    // Bold is wider than regular.
    let regular = text::text_size("validation", &Style::new(14.0)).unwrap();
    chart(10, 10, |root| {
        let bold = (FAMILY, 14.0, FontStyle::Bold).into_font();
        assert!(
            root.estimate_text_size("validation", &bold.into())
                .unwrap()
                .0
                > regular.0
        );
    });
}

#[test]
fn text_is_drawn_as_the_text_module_draws_it_for_every_anchor_and_turn() {
    let hs = [HPos::Left, HPos::Center, HPos::Right];
    let vs = [VPos::Top, VPos::Center, VPos::Bottom];
    let turns = [
        (FontTransform::None, Turn::None),
        (FontTransform::Rotate90, Turn::Cw90),
        (FontTransform::Rotate180, Turn::Cw180),
        (FontTransform::Rotate270, Turn::Cw270),
    ];
    for (transform, turn) in turns {
        for h in hs {
            for v in vs {
                let at = (60, 61);
                let charted = chart(120, 120, |root| {
                    let style = chart_style(14.0, Pos::new(h, v)).transform(transform.clone());
                    root.draw_text("y 0.188", &style, at).unwrap();
                });
                let mut expected = Image::filled(120, 120, [255; 3]).unwrap();
                let style = Style {
                    turn,
                    ..black(14.0)
                };
                text::draw(&mut expected, "y 0.188", at, Anchor { h, v }, &style).unwrap();
                assert!(ink_box(&expected).0.0 < 120, "{turn:?}: nothing drawn");
                // Blending rounds a little differently in the bitmap backend.
                let d = max_difference(&charted, &expected);
                assert!(d <= 2, "{turn:?}: differs by {d}");
            }
        }
    }
}

#[test]
fn a_y_axis_label_turned_by_270_degrees_is_taller_than_wide_and_reads_upwards() {
    let image = chart(60, 160, |root| {
        let style = chart_style(14.0, Pos::new(HPos::Center, VPos::Top))
            .transform(FontTransform::Rotate270);
        // As plotters places a left axis description: top of the text at the area's left edge.
        root.draw_text("loss (MSE)", &style, (10, 80)).unwrap();
    });
    let ((x0, y0, x1, y1), (_, cy)) = ink_box(&image);
    assert!(y1 - y0 > 3 * (x1 - x0), "ink {x0}..={x1} × {y0}..={y1}");
    assert!((10..=14).contains(&x0) && x1 < 10 + 15, "{x0}..={x1}");
    assert!((cy - 80.0).abs() <= 2.0, "centred at {cy}");
    // "l" first: it reaches furthest left (up in the text), at the bottom end.
    let column = |x: u32| (y0..=y1).filter(move |&y| image.pixel(x, y).unwrap()[0] < 128);
    let lowest = column(x0).max().unwrap();
    assert!(lowest > (y0 + y1) / 2, "the l at the bottom: {lowest}");
}

#[test]
fn translucent_transparent_and_clipped_text() {
    let image = chart(40, 20, |root| {
        let style = (FAMILY, 14.0).into_font().color(&BLACK.mix(0.5));
        root.draw_text("00", &style, (5, 2)).unwrap();
        let invisible = (FAMILY, 14.0).into_font().color(&TRANSPARENT);
        root.draw_text("00", &invisible, (25, 2)).unwrap();
    });
    let darkest = image.rgb.iter().copied().min().unwrap();
    assert!(
        (120..=135).contains(&darkest),
        "half-transparent black: {darkest}"
    );
    let right_half = (20..40).flat_map(|x| (0..20).map(move |y| (x, y)));
    assert!(
        right_half
            .clone()
            .all(|(x, y)| image.pixel(x, y) == Some([255; 3])),
        "transparent text left ink"
    );
    // Partly or wholly off the image: clipped, no panic.
    let clipped = chart(40, 20, |root| {
        let style = chart_style(16.0, Pos::new(HPos::Center, VPos::Center));
        for at in [(-30, 5), (35, -10), (i32::MAX, i32::MIN), (i32::MIN, 0)] {
            root.draw_text("clipped 0.188", &style, at).unwrap();
        }
    });
    assert!(
        clipped.rgb.iter().any(|&v| v < 128),
        "the visible parts are drawn"
    );
}

#[test]
fn everything_but_text_is_drawn_as_the_bitmap_backend_draws_it() {
    let (w, h) = (80u32, 60u32);
    // Plain, translucent and wide strokes, fills, polygons, pixels and a bitmap.
    fn shapes<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>) {
        let blue = RGBColor(31, 119, 180);
        root.fill(&WHITE).unwrap();
        root.draw(&Rectangle::new([(3, 4), (30, 20)], blue.mix(0.5).filled()))
            .unwrap();
        root.draw(&Rectangle::new([(5, 6), (70, 50)], RED.stroke_width(1)))
            .unwrap();
        root.draw(&Circle::new((40, 30), 9, GREEN.filled()))
            .unwrap();
        root.draw(&Circle::new((40, 30), 12, BLACK.stroke_width(1)))
            .unwrap();
        let path = vec![(0, 59), (20, 10), (50, 45), (79, 0)];
        root.draw(&PathElement::new(path.clone(), blue.stroke_width(3)))
            .unwrap();
        root.draw(&PathElement::new(path, BLACK.mix(0.4))).unwrap();
        root.draw(&Polygon::new(vec![(60, 50), (75, 58), (66, 40)], blue))
            .unwrap();
        root.draw_pixel((1, 1), &BLACK).unwrap();
        let bitmap: Vec<u8> = (0..5 * 4 * 3).map(|i| (i * 13 % 256) as u8).collect();
        root.draw(
            &BitMapElement::<_, RGBPixel>::with_owned_buffer((70, 2), (5, 4), bitmap).unwrap(),
        )
        .unwrap();
    }
    fn drawn<DB: DrawingBackend>(backend: DB) {
        let root = backend.into_drawing_area();
        shapes(&root);
        root.present().unwrap();
    }
    let (mut charted, mut bitmap) = (
        vec![0u8; 3 * (w * h) as usize],
        vec![0u8; 3 * (w * h) as usize],
    );
    drawn(ChartBackend::with_buffer(&mut charted, (w, h)));
    drawn(BitMapBackend::with_buffer(&mut bitmap, (w, h)));
    assert!(charted.iter().any(|&v| v != 255) && charted.contains(&255));
    assert!(charted == bitmap, "the backends drew different pixels");
}
