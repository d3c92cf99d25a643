//! Text on images with plotters and the embedded DejaVu Sans font (no system fonts needed).

use crate::error::RenderError;
use crate::image::Image;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use std::sync::OnceLock;

/// The family every text of this crate uses; registered once, from the embedded font.
pub(crate) const FAMILY: &str = "sans-serif";

/// Registers DejaVu Sans as [`FAMILY`] (once per process). Text drawn without a registered font
/// fails (or panics inside plotters), so every drawing function calls this first.
pub(crate) fn ensure_font() -> Result<(), RenderError> {
    static REGISTERED: OnceLock<bool> = OnceLock::new();
    let ok = *REGISTERED.get_or_init(|| {
        plotters::style::register_font(FAMILY, FontStyle::Normal, dejavu::sans::regular()).is_ok()
            && plotters::style::register_font(FAMILY, FontStyle::Bold, dejavu::sans::bold()).is_ok()
    });
    if ok {
        Ok(())
    } else {
        Err(RenderError::Draw {
            what: "text",
            message: "the embedded DejaVu Sans font could not be loaded".into(),
        })
    }
}

pub(crate) fn draw_error(what: &'static str, e: impl std::fmt::Display) -> RenderError {
    RenderError::Draw {
        what,
        message: e.to_string(),
    }
}

/// Where a text's anchor point is, relative to the text.
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

    fn font(&self) -> FontDesc<'static> {
        let style = if self.bold {
            FontStyle::Bold
        } else {
            FontStyle::Normal
        };
        let font = FontDesc::new(FontFamily::Name(FAMILY), self.size, style);
        if self.vertical {
            font.transform(FontTransform::Rotate270)
        } else {
            font
        }
    }
}

/// Width and height in pixels of `text` drawn horizontally in `style`.
pub(crate) fn text_size(text: &str, style: &Style) -> Result<(u32, u32), RenderError> {
    ensure_font()?;
    let font = Style {
        vertical: false,
        ..*style
    }
    .font();
    font.box_size(text).map_err(|e| draw_error("text", e))
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

/// Draws `text` on `image` with its `anchor` point at pixel `(x, y)`.
pub(crate) fn draw(
    image: &mut Image,
    text: &str,
    (x, y): (i32, i32),
    anchor: Anchor,
    style: &Style,
) -> Result<(), RenderError> {
    ensure_font()?;
    if text.is_empty() {
        return Ok(());
    }
    let color = RGBColor(style.color[0], style.color[1], style.color[2]);
    let text_style = TextStyle::from(style.font())
        .color(&color)
        .pos(Pos::new(anchor.h, anchor.v));
    let (w, h) = (image.width, image.height);
    let backend = BitMapBackend::with_buffer(&mut image.rgb, (w, h));
    let area = backend.into_drawing_area();
    area.draw_text(text, &text_style, (x, y))
        .map_err(|e| draw_error("text", e))?;
    area.present().map_err(|e| draw_error("text", e))
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
}
