//! Text on images, laid out and rasterised with ab_glyph from the embedded DejaVu Sans font (no
//! system fonts needed). Glyphs sit at fractional pen positions: rounding each advance to whole
//! pixels (as plotters' text path does) makes digit spacing visibly uneven at caption sizes.
//! Captions and colour bars draw with [`draw`]; charts draw through plotters, whose text
//! [`crate::chart_backend`] sends here ([`ink`], [`text_size`]).

use crate::error::RenderError;
use crate::image::{Image, MAX_PIXELS};
use ab_glyph::{Font, FontRef, Glyph, PxScale, ScaleFont, point};
use plotters::style::FontStyle;
use plotters::style::text_anchor::{HPos, VPos};
use std::sync::OnceLock;

/// The family chart text asks plotters for; registered once, from the embedded font.
pub(crate) const FAMILY: &str = "sans-serif";

/// Registers DejaVu Sans as [`FAMILY`] for plotters (once per process). Chart text is drawn and
/// measured by this module, but plotters still sizes legends with its own font lookup, which
/// fails without a registered font, so plotting functions call this.
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

/// How a text is turned about its anchor point, clockwise on the image, as plotters'
/// `FontTransform` turns it: `Cw270` reads bottom to top (a y-axis label).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Turn {
    None,
    Cw90,
    Cw180,
    Cw270,
}

impl Turn {
    /// Where the offset `(u, v)` of the horizontal box (along the text, down its height) lands.
    fn apply<T: std::ops::Neg<Output = T>>(self, (u, v): (T, T)) -> (T, T) {
        match self {
            Turn::None => (u, v),
            Turn::Cw90 => (-v, u),
            Turn::Cw180 => (-u, -v),
            Turn::Cw270 => (v, -u),
        }
    }

    /// The inverse of [`Turn::apply`].
    fn undo(self, (x, y): (f32, f32)) -> (f32, f32) {
        match self {
            Turn::None => (x, y),
            Turn::Cw90 => (y, -x),
            Turn::Cw180 => (-x, -y),
            Turn::Cw270 => (-y, x),
        }
    }

    /// The top-left corner of the turned unit square whose untouched top-left corner is `(u, v)`.
    fn corner<T>(self, (u, v): (T, T), one: T) -> (T, T)
    where
        T: std::ops::Neg<Output = T> + std::ops::Add<Output = T> + PartialOrd + Copy,
    {
        let (a, b) = (self.apply((u, v)), self.apply((u + one, v + one)));
        let min = |p: T, q: T| if p < q { p } else { q };
        (min(a.0, b.0), min(a.1, b.1))
    }
}

/// How a text looks: size in pixels, colour, bold, turn. The size is ab_glyph's pixel scale
/// (ascent − descent), as plotters used it, so glyphs are as large as they were when plotters
/// drew them.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Style {
    pub size: f64,
    pub color: [u8; 3],
    pub bold: bool,
    pub turn: Turn,
}

impl Style {
    pub fn new(size: f64) -> Style {
        Style {
            size,
            color: [30, 30, 34],
            bold: false,
            turn: Turn::None,
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
    // Float noise (26.000002 for a 26 px line) does not round up to the next pixel.
    let ceil = |v: f32| (v - 1e-3).max(0.0).ceil() as u32;
    Ok(match lay_out(text, style)? {
        Some(line) if !text.is_empty() => (ceil(line.advance), ceil(line.ascent - line.descent)),
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

/// Draws `text` on `image` with its `anchor` point at pixel `(x, y)`, anti-aliased; see [`ink`].
pub(crate) fn draw(
    image: &mut Image,
    text: &str,
    at: (i32, i32),
    anchor: Anchor,
    style: &Style,
) -> Result<(), RenderError> {
    ink(text, at, anchor, style, |x, y, c| {
        blend(image, (x, y), style.color, c)
    })
}

/// Calls `paint(x, y, coverage)` for each pixel that `text` covers when its `anchor` point is at
/// pixel `at` (coverage in 0–1; pixels may lie outside any image: the caller clips). The anchor
/// point is taken at the same fraction of the pixel as of the box, so a Left/Top anchored box
/// starts at the pixel's top-left corner and a centred one is centred on the pixel. A turned text
/// is the horizontal text turned about the anchor; anchors refer to the unturned box.
pub(crate) fn ink(
    text: &str,
    at: (i32, i32),
    anchor: Anchor,
    style: &Style,
    mut paint: impl FnMut(i64, i64, f32),
) -> Result<(), RenderError> {
    let Some(line) = lay_out(text, style)? else {
        return Ok(());
    };
    if text.is_empty() {
        return Ok(());
    }
    let (fh, fv) = fractions(anchor);
    let (w, h) = (line.advance, line.ascent - line.descent);
    let turn = style.turn;
    // The anchor point on the image: the anchor pixel is the turned unit square around it.
    let c = turn.corner((-fh, -fv), 1.0);
    let a = (at.0 as f32 - c.0, at.1 as f32 - c.1);
    // Rasterise in the box frame with the anchor at `s`, chosen so that the frame's whole pixels
    // land on whole image pixels: frame point p is image point `base + turn(p)`.
    let base = (a.0.floor(), a.1.floor());
    let s = turn.undo((a.0 - base.0, a.1 - base.1));
    let cov = rasterise(&line, (s.0 - fh * w, s.1 - fv * h), style)?;
    let base = (base.0 as i64, base.1 as i64);
    for j in 0..cov.height {
        for i in 0..cov.width {
            let (x, y) = turn.corner((cov.x0 + i as i64, cov.y0 + j as i64), 1);
            paint(base.0 + x, base.1 + y, cov.alpha[j * cov.width + i]);
        }
    }
    Ok(())
}

#[cfg(test)]
pub(crate) mod tests;
