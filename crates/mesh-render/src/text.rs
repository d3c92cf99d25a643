//! Text on images, laid out and rasterised with ab_glyph from the embedded DejaVu Sans font (no
//! system fonts needed). Glyphs sit at fractional pen positions: rounding each advance to whole
//! pixels (as plotters' text path does) makes digit spacing visibly uneven at caption sizes.

use crate::error::RenderError;
use crate::image::{Image, MAX_PIXELS};
use ab_glyph::{Font, FontRef, Glyph, PxScale, ScaleFont, point};
use plotters::style::FontStyle;
use plotters::style::text_anchor::{HPos, VPos};
use std::sync::OnceLock;

/// The family plotters' own chart text (plot and line-plot axes) uses; registered once, from the
/// embedded font.
pub(crate) const FAMILY: &str = "sans-serif";

/// Registers DejaVu Sans as [`FAMILY`] for plotters (once per process). Text drawn by plotters
/// without a registered font fails (or panics inside plotters), so plotting functions call this.
pub(crate) fn ensure_font() -> Result<(), RenderError> {
    static REGISTERED: OnceLock<bool> = OnceLock::new();
    let ok = *REGISTERED.get_or_init(|| {
        plotters::style::register_font(FAMILY, FontStyle::Normal, dejavu::sans::regular()).is_ok()
            && plotters::style::register_font(FAMILY, FontStyle::Bold, dejavu::sans::bold()).is_ok()
    });
    if ok { Ok(()) } else { Err(font_error()) }
}

fn font_error() -> RenderError {
    RenderError::Draw {
        what: "text",
        message: "the embedded DejaVu Sans font could not be loaded".into(),
    }
}

/// The parsed regular or bold face (parsed once per process).
fn face(bold: bool) -> Result<&'static FontRef<'static>, RenderError> {
    static FACES: OnceLock<Option<[FontRef<'static>; 2]>> = OnceLock::new();
    let faces = FACES.get_or_init(|| {
        let regular = FontRef::try_from_slice(dejavu::sans::regular()).ok()?;
        let bold = FontRef::try_from_slice(dejavu::sans::bold()).ok()?;
        Some([regular, bold])
    });
    faces
        .as_ref()
        .map(|f| &f[usize::from(bold)])
        .ok_or_else(font_error)
}

pub(crate) fn draw_error(what: &'static str, e: impl std::fmt::Display) -> RenderError {
    RenderError::Draw {
        what,
        message: e.to_string(),
    }
}

/// Where a text's anchor point is, relative to the text's box (advance width × line height,
/// from the font's ascent to its descent).
#[derive(Clone, Copy)]
pub(crate) struct Anchor {
    pub h: HPos,
    pub v: VPos,
}

impl Anchor {
    pub const CENTER: Anchor = Anchor {
        h: HPos::Center,
        v: VPos::Center,
    };
    pub const LEFT_CENTER: Anchor = Anchor {
        h: HPos::Left,
        v: VPos::Center,
    };
    pub const CENTER_TOP: Anchor = Anchor {
        h: HPos::Center,
        v: VPos::Top,
    };
}

/// How a text looks: size in pixels, colour, bold, rotated by 270° (reading bottom to top).
/// The size is ab_glyph's pixel scale (ascent − descent), as plotters used it, so glyphs are as
/// large as they were when plotters drew them.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Style {
    pub size: f64,
    pub color: [u8; 3],
    pub bold: bool,
    pub vertical: bool,
}

impl Style {
    pub fn new(size: f64) -> Style {
        Style {
            size,
            color: [30, 30, 34],
            bold: false,
            vertical: false,
        }
    }

    /// Nothing is drawn (and sizes are 0) for a size that is not a positive finite number.
    fn scale(&self) -> Option<PxScale> {
        let size = self.size as f32;
        (size.is_finite() && size > 0.0).then(|| PxScale::from(size))
    }
}

/// Glyphs at fractional pen positions along a baseline at y = 0, starting at x = 0.
struct Line {
    glyphs: Vec<Glyph>,
    /// Pen position after the last glyph: the box width.
    advance: f32,
    ascent: f32,
    /// Below the baseline, so negative.
    descent: f32,
}

fn lay_out(text: &str, style: &Style) -> Result<Option<Line>, RenderError> {
    let Some(scale) = style.scale() else {
        return Ok(None);
    };
    let font = face(style.bold)?.as_scaled(scale);
    let mut glyphs = Vec::with_capacity(text.len());
    let mut x = 0.0f32;
    let mut prev = None;
    for c in text.chars() {
        let id = font.glyph_id(c);
        if let Some(prev) = prev {
            x += font.kern(prev, id);
        }
        glyphs.push(Glyph {
            id,
            scale,
            position: point(x, 0.0),
        });
        x += font.h_advance(id);
        prev = Some(id);
    }
    Ok(Some(Line {
        glyphs,
        advance: x,
        ascent: font.ascent(),
        descent: font.descent(),
    }))
}

/// Width and height in pixels of the box of `text` drawn horizontally in `style`: the advance
/// width and the line height (ascent − descent), rounded up.
pub(crate) fn text_size(text: &str, style: &Style) -> Result<(u32, u32), RenderError> {
    Ok(match lay_out(text, style)? {
        Some(line) if !text.is_empty() => (
            line.advance.max(0.0).ceil() as u32,
            (line.ascent - line.descent).ceil() as u32,
        ),
        _ => (0, 0),
    })
}

/// `text` shortened with an ellipsis until it is at most `max_width` pixels wide in `style`.
pub(crate) fn fit(text: &str, style: &Style, max_width: u32) -> Result<String, RenderError> {
    if text_size(text, style)?.0 <= max_width {
        return Ok(text.to_owned());
    }
    let chars: Vec<char> = text.chars().collect();
    for keep in (0..chars.len()).rev() {
        let candidate: String = chars[..keep].iter().chain(['…'].iter()).collect();
        if text_size(&candidate, style)?.0 <= max_width {
            return Ok(candidate);
        }
    }
    Ok(String::new())
}

/// Coverage (0–1) of a horizontal text on a pixel grid; cell `(i, j)` is the pixel whose top-left
/// corner is at `(x0 + i, y0 + j)` in the frame the glyphs were positioned in.
struct Coverage {
    x0: i64,
    y0: i64,
    width: usize,
    height: usize,
    alpha: Vec<f32>,
}

/// Rasterises `line` with its box origin (left end of the ascent line) at `origin`; the baseline
/// is snapped to a whole pixel once for the whole line (crisper horizontal strokes), x is not.
fn rasterise(line: &Line, origin: (f32, f32), style: &Style) -> Result<Coverage, RenderError> {
    let font = face(style.bold)?;
    let baseline = (origin.1 + line.ascent).round();
    let outlined: Vec<_> = line
        .glyphs
        .iter()
        .filter_map(|g| {
            let mut g = g.clone();
            g.position = point(origin.0 + g.position.x, baseline);
            font.outline_glyph(g)
        })
        .collect();
    let (mut x0, mut y0, mut x1, mut y1) = (i64::MAX, i64::MAX, i64::MIN, i64::MIN);
    for o in &outlined {
        let b = o.px_bounds();
        x0 = x0.min(b.min.x as i64);
        y0 = y0.min(b.min.y as i64);
        x1 = x1.max(b.max.x as i64);
        y1 = y1.max(b.max.y as i64);
    }
    if outlined.is_empty() || x1 <= x0 || y1 <= y0 {
        return Ok(Coverage {
            x0: 0,
            y0: 0,
            width: 0,
            height: 0,
            alpha: Vec::new(),
        });
    }
    if (x1 - x0).saturating_mul(y1 - y0) > MAX_PIXELS as i64 {
        return Err(draw_error(
            "text",
            format!("text of size {} is too large", style.size),
        ));
    }
    let (width, height) = ((x1 - x0) as usize, (y1 - y0) as usize);
    let mut alpha = vec![0.0f32; width * height];
    for o in &outlined {
        let min = o.px_bounds().min;
        let (dx, dy) = ((min.x as i64 - x0) as usize, (min.y as i64 - y0) as usize);
        o.draw(|gx, gy, c| {
            let a = &mut alpha[(dy + gy as usize) * width + dx + gx as usize];
            // Overlapping glyphs (kerned pairs) add up; coverage saturates at full ink.
            *a = (*a + c).min(1.0);
        });
    }
    Ok(Coverage {
        x0,
        y0,
        width,
        height,
        alpha,
    })
}

/// Blends `color` into the pixel at `(x, y)` by coverage `c`; pixels outside the image are skipped.
fn blend(image: &mut Image, (x, y): (i64, i64), color: [u8; 3], c: f32) {
    if c <= 0.0 || x < 0 || y < 0 || x >= i64::from(image.width) || y >= i64::from(image.height) {
        return;
    }
    let i = 3 * (y as usize * image.width as usize + x as usize);
    let c = c.min(1.0);
    for (p, &k) in image.rgb[i..i + 3].iter_mut().zip(&color) {
        *p = (f32::from(*p) * (1.0 - c) + f32::from(k) * c).round() as u8;
    }
}

/// The anchor's fraction of the box along its width and its height.
fn fractions(anchor: Anchor) -> (f32, f32) {
    let h = match anchor.h {
        HPos::Left => 0.0,
        HPos::Center => 0.5,
        HPos::Right => 1.0,
    };
    let v = match anchor.v {
        VPos::Top => 0.0,
        VPos::Center => 0.5,
        VPos::Bottom => 1.0,
    };
    (h, v)
}

/// Draws `text` on `image` with its `anchor` point at pixel `(x, y)`, anti-aliased. The anchor
/// point is taken at the same fraction of the pixel as of the box, so a Left/Top anchored box
/// starts at the pixel's top-left corner and a centred one is centred on the pixel. Vertical
/// text is the horizontal text turned by 270° about the anchor (reading bottom to top). Ink
/// outside the image is clipped.
pub(crate) fn draw(
    image: &mut Image,
    text: &str,
    (x, y): (i32, i32),
    anchor: Anchor,
    style: &Style,
) -> Result<(), RenderError> {
    let Some(line) = lay_out(text, style)? else {
        return Ok(());
    };
    if text.is_empty() {
        return Ok(());
    }
    let (fh, fv) = fractions(anchor);
    let (w, h) = (line.advance, line.ascent - line.descent);
    let (x, y) = (x as f32, y as f32);
    if !style.vertical {
        let origin = (x + fh - fh * w, y + fv - fv * h);
        let cov = rasterise(&line, origin, style)?;
        for j in 0..cov.height {
            for i in 0..cov.width {
                let at = (cov.x0 + i as i64, cov.y0 + j as i64);
                blend(image, at, style.color, cov.alpha[j * cov.width + i]);
            }
        }
        return Ok(());
    }
    // Turned by 270°, a point (u, v) of the horizontal box (relative to its anchor point) lands
    // at (ax + v, ay − u); along the image's y the box's width runs upwards. Rasterise in the
    // box frame shifted by the anchor's fractional part so whole pixels map to whole pixels.
    let (ax, ay) = (x + fv, y + 1.0 - fh);
    let (sx, sy) = (ay.ceil() - ay, ax - ax.floor());
    let origin = (sx - fh * w, sy - fv * h);
    let cov = rasterise(&line, origin, style)?;
    let (px, py) = (ax.floor() as i64, ay.ceil() as i64);
    for j in 0..cov.height {
        for i in 0..cov.width {
            // Box pixel [u, u+1) × [v, v+1) covers image column px + v and row py − u − 1.
            let (u, v) = (cov.x0 + i as i64, cov.y0 + j as i64);
            blend(
                image,
                (px + v, py - u - 1),
                style.color,
                cov.alpha[j * cov.width + i],
            );
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
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
    fn ink(image: &Image, x: u32, y: u32) -> f32 {
        1.0 - f32::from(image.pixel(x, y).unwrap()[0]) / 255.0
    }

    /// The first and last column of each run of columns holding a half-dark pixel or darker.
    fn column_runs(image: &Image) -> Vec<(u32, u32)> {
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
    fn ink_box(image: &Image) -> ((u32, u32, u32, u32), (f32, f32)) {
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

    fn black(size: f64) -> Style {
        Style {
            color: [0; 3],
            ..Style::new(size)
        }
    }

    /// The ink-weighted x centre of each glyph: columns are split between the runs of dark
    /// columns halfway across the gaps, so faint anti-aliased ink still counts.
    fn glyph_centres(image: &Image) -> Vec<f32> {
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
            vertical: true,
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
    fn text_partly_or_wholly_off_the_image_is_clipped() {
        for vertical in [false, true] {
            let style = Style {
                vertical,
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
}
