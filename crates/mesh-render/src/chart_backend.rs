//! The drawing backend of every chart: plotters' `BitMapBackend` draws the lines, shapes and fills,
//! and this crate's text renderer ([`crate::text`]) lays out, measures and draws every text
//! (titles, axis descriptions, tick labels, legends). plotters' own text path puts each glyph at a
//! whole-pixel pen position and drops its left side bearing, which spaces digits unevenly
//! ("-1 00.0"); here chart text is spaced like captions and colour-bar labels.

use crate::error::RenderError;
use crate::text::{self, Anchor, Style, Turn};
use plotters::prelude::{BitMapBackend, DrawingBackend};
use plotters_backend::{
    BackendColor, BackendCoord, BackendStyle, BackendTextStyle, DrawingErrorKind, FontStyle,
    FontTransform,
};

/// A `BitMapBackend` on an RGB buffer whose text goes through [`crate::text`].
pub(crate) struct ChartBackend<'a> {
    inner: BitMapBackend<'a>,
}

impl<'a> ChartBackend<'a> {
    /// Draws into `buf`: RGB rows of `size.0` × `size.1` pixels, as `BitMapBackend::with_buffer`.
    pub fn with_buffer(buf: &'a mut [u8], size: (u32, u32)) -> Self {
        ChartBackend {
            inner: BitMapBackend::with_buffer(buf, size),
        }
    }
}

type Inner<'a> = BitMapBackend<'a>;
type DrawResult<'a, T = ()> = Result<T, DrawingErrorKind<<Inner<'a> as DrawingBackend>::ErrorType>>;

/// plotters' text style as this crate's: the same pixel size (both are ab_glyph's scale), bold or
/// not, turned as plotters would turn it. Every family is drawn in DejaVu Sans, the only font the
/// charts ask for (italic and oblique are drawn upright).
fn style_of<S: BackendTextStyle>(style: &S) -> Style {
    let (r, g, b) = style.color().rgb;
    Style {
        size: style.size(),
        color: [r, g, b],
        bold: matches!(style.style(), FontStyle::Bold),
        turn: match style.transform() {
            FontTransform::None => Turn::None,
            FontTransform::Rotate90 => Turn::Cw90,
            FontTransform::Rotate180 => Turn::Cw180,
            FontTransform::Rotate270 => Turn::Cw270,
        },
    }
}

fn anchor_of<S: BackendTextStyle>(style: &S) -> Anchor {
    let pos = style.anchor();
    Anchor {
        h: pos.h_pos,
        v: pos.v_pos,
    }
}

fn font_error<E: std::error::Error + Send + Sync>(e: RenderError) -> DrawingErrorKind<E> {
    DrawingErrorKind::FontError(Box::new(e))
}

/// Everything but text is the inner backend's own drawing, unchanged.
impl<'a> DrawingBackend for ChartBackend<'a> {
    type ErrorType = <Inner<'a> as DrawingBackend>::ErrorType;

    fn get_size(&self) -> (u32, u32) {
        self.inner.get_size()
    }

    fn ensure_prepared(&mut self) -> DrawResult<'a> {
        self.inner.ensure_prepared()
    }

    fn present(&mut self) -> DrawResult<'a> {
        self.inner.present()
    }

    fn draw_pixel(&mut self, point: BackendCoord, color: BackendColor) -> DrawResult<'a> {
        self.inner.draw_pixel(point, color)
    }

    fn draw_line<S: BackendStyle>(
        &mut self,
        from: BackendCoord,
        to: BackendCoord,
        style: &S,
    ) -> DrawResult<'a> {
        self.inner.draw_line(from, to, style)
    }

    fn draw_rect<S: BackendStyle>(
        &mut self,
        upper_left: BackendCoord,
        bottom_right: BackendCoord,
        style: &S,
        fill: bool,
    ) -> DrawResult<'a> {
        self.inner.draw_rect(upper_left, bottom_right, style, fill)
    }

    fn draw_path<S: BackendStyle, I: IntoIterator<Item = BackendCoord>>(
        &mut self,
        path: I,
        style: &S,
    ) -> DrawResult<'a> {
        self.inner.draw_path(path, style)
    }

    fn draw_circle<S: BackendStyle>(
        &mut self,
        center: BackendCoord,
        radius: u32,
        style: &S,
        fill: bool,
    ) -> DrawResult<'a> {
        self.inner.draw_circle(center, radius, style, fill)
    }

    fn fill_polygon<S: BackendStyle, I: IntoIterator<Item = BackendCoord>>(
        &mut self,
        vert: I,
        style: &S,
    ) -> DrawResult<'a> {
        self.inner.fill_polygon(vert, style)
    }

    fn blit_bitmap(&mut self, pos: BackendCoord, size: (u32, u32), src: &[u8]) -> DrawResult<'a> {
        self.inner.blit_bitmap(pos, size, src)
    }

    /// Draws as [`text::draw`] would, blending each pixel's coverage × the colour's alpha in
    /// through the inner backend.
    fn draw_text<S: BackendTextStyle>(
        &mut self,
        text: &str,
        style: &S,
        pos: BackendCoord,
    ) -> DrawResult<'a> {
        let color = style.color();
        if color.alpha <= 0.0 {
            return Ok(());
        }
        let (w, h) = self.inner.get_size();
        let inner = &mut self.inner;
        let mut drawn = Ok(());
        text::ink(text, pos, anchor_of(style), &style_of(style), |x, y, c| {
            let inside = (0..i64::from(w)).contains(&x) && (0..i64::from(h)).contains(&y);
            if c > 0.0 && inside && drawn.is_ok() {
                drawn = inner.draw_pixel((x as i32, y as i32), color.mix(f64::from(c)));
            }
        })
        .map_err(font_error)?;
        drawn
    }

    /// [`text::text_size`] of the unturned text (plotters turns boxes itself where it needs to).
    fn estimate_text_size<S: BackendTextStyle>(
        &self,
        text: &str,
        style: &S,
    ) -> DrawResult<'a, (u32, u32)> {
        text::text_size(text, &style_of(style)).map_err(font_error)
    }
}

#[cfg(test)]
mod tests;
