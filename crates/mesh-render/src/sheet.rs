//! Composition: contact sheets of captioned tiles, and colour bars beside a picture.

use crate::colormap::error_color;
use crate::error::RenderError;
use crate::image::{Image, check_size};
use crate::text::{self, Anchor, Style, Turn};

/// One picture of a [`sheet`] and the caption written under it.
#[derive(Debug, Clone, PartialEq)]
pub struct Tile {
    pub image: Image,
    pub caption: String,
}

/// Caption text height in pixels for tiles `tile_width` wide.
fn caption_font(tile_width: u32) -> f64 {
    (f64::from(tile_width) / 18.0).clamp(11.0, 22.0)
}

/// Height of the caption band under each tile of a sheet whose widest tile is `tile_width`.
pub fn caption_height(tile_width: u32) -> u32 {
    (caption_font(tile_width) * 1.8).ceil() as u32
}

/// A grid of tiles, `columns` per row (fewer if there are fewer tiles), each with its caption
/// underneath, on white. Every cell is as wide as the widest tile and as tall as the tallest
/// plus [`caption_height`]; smaller tiles are centred in their cell. Long captions are shortened
/// with an ellipsis.
pub fn sheet(tiles: &[Tile], columns: usize) -> Result<Image, RenderError> {
    if tiles.is_empty() {
        return Err(RenderError::Empty { argument: "tiles" });
    }
    if columns == 0 {
        return Err(RenderError::invalid("columns", "must be at least 1"));
    }
    for tile in tiles {
        tile.image.validate("tiles")?;
    }
    let columns = columns.min(tiles.len());
    let rows = tiles.len().div_ceil(columns);
    let cell_w = tiles.iter().map(|t| t.image.width).max().unwrap_or(1);
    let tile_h = tiles.iter().map(|t| t.image.height).max().unwrap_or(1);
    let band = caption_height(cell_w);
    let cell_h = tile_h + band;
    let (width, height) = (
        u64::from(cell_w) * columns as u64,
        u64::from(cell_h) * rows as u64,
    );
    let too_big = || RenderError::Size {
        argument: "tiles",
        width,
        height,
        message: "the sheet would be too large; use smaller tiles".into(),
    };
    let width = u32::try_from(width).map_err(|_| too_big())?;
    let height = u32::try_from(height).map_err(|_| too_big())?;
    check_size("tiles", width, height).map_err(|_| too_big())?;
    let mut out = Image::filled(width, height, [255; 3])?;
    let font = caption_font(cell_w);
    let style = Style::new(font);
    for (i, tile) in tiles.iter().enumerate() {
        let (col, row) = ((i % columns) as u32, (i / columns) as u32);
        let (x0, y0) = (col * cell_w, row * cell_h);
        let img = &tile.image;
        out.blit(
            img,
            x0 + (cell_w - img.width) / 2,
            y0 + (tile_h - img.height) / 2,
        );
        // A caption too long for its cell is first set smaller (down to 3/4), then shortened.
        let max_w = cell_w.saturating_sub(6);
        let mut style = style;
        while text::text_size(&tile.caption, &style)?.0 > max_w && style.size > 0.75 * font {
            style.size -= 0.5;
        }
        let caption = text::fit(&tile.caption, &style, max_w)?;
        let centre = (
            (x0 + cell_w / 2) as i32,
            (y0 + tile_h) as i32 + band as i32 / 2 - 2,
        );
        text::draw(&mut out, &caption, centre, Anchor::CENTER, &style)?;
    }
    Ok(out)
}

/// Tick values for a bar from 0 to `max`: multiples of a "nice" step (1, 2, 2.5 or 5 × 10^k),
/// the top one replaced or followed by `max` itself, each with its label.
pub fn ticks(max: f32) -> Vec<(f32, String)> {
    if max <= 0.0 || !max.is_finite() {
        return vec![(0.0, "0".into())];
    }
    let raw = f64::from(max) / 4.0;
    let magnitude = 10f64.powf(raw.log10().floor());
    let mantissa = [1.0, 2.0, 2.5, 5.0, 10.0]
        .into_iter()
        .find(|&m| m * magnitude >= raw)
        .unwrap_or(10.0);
    let step = mantissa * magnitude;
    let mut decimals = (-step.log10() - 1e-9).ceil().max(0.0) as usize;
    if mantissa == 2.5 && magnitude < 1.5 {
        decimals += 1;
    }
    let decimals = decimals.min(9);
    let max64 = f64::from(max);
    let mut out: Vec<(f32, String)> = Vec::new();
    let mut k = 0.0;
    while k * step <= max64 * (1.0 + 1e-9) {
        let v = k * step;
        let label = if k == 0.0 {
            "0".to_string()
        } else {
            format!("{v:.decimals$}")
        };
        out.push((v as f32, label));
        k += 1.0;
    }
    let last = f64::from(out.last().map_or(0.0, |t| t.0));
    let gap = (max64 - last) / step;
    if gap > 1e-6 {
        if gap < 0.4 && out.len() > 1 {
            out.pop();
        }
        out.push((max, significant(max64, 3)));
    }
    out
}

/// `v` with `digits` significant digits, without trailing zeros.
fn significant(v: f64, digits: i32) -> String {
    if v == 0.0 {
        return "0".into();
    }
    let decimals = (digits - 1 - v.abs().log10().floor() as i32).clamp(0, 12) as usize;
    let s = format!("{v:.decimals$}");
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    }
}

/// The picture with a vertical colour bar of the error map (0 at the bottom, `max` at the top),
/// tick labels and `label` (written vertically) appended on its right, on white. The height is
/// unchanged. Errors: a bad image, a negative or non-finite `max`.
pub fn with_colorbar(image: &Image, max: f32, label: &str) -> Result<Image, RenderError> {
    image.validate("image")?;
    if !max.is_finite() || max < 0.0 {
        return Err(RenderError::invalid(
            "max",
            format!("the colour bar's maximum must be finite and >= 0, got {max}"),
        ));
    }
    let h = image.height;
    let font = (f64::from(h) / 34.0).clamp(11.0, 17.0);
    let style = Style::new(font);
    let ticks = ticks(max);
    let mut label_w = 0;
    for (_, t) in &ticks {
        label_w = label_w.max(text::text_size(t, &style)?.0);
    }
    let font_px = font.ceil() as u32;
    let bar_w = (font_px * 6 / 5).max(12);
    let bar_h = (h * 7 / 10).clamp(1, 480);
    let (tick_len, gap) = (5, 4);
    let bar_x = font_px;
    let label_x = bar_x + bar_w + tick_len + gap;
    let title_x = label_x + label_w + font_px;
    let panel_w = title_x + if label.is_empty() { 0 } else { font_px * 2 };
    let mut panel = Image::filled(panel_w, h, [255; 3])?;
    let bar_y = (h - bar_h) / 2;
    for row in 0..bar_h {
        let t = 1.0 - row as f32 / (bar_h.max(2) - 1) as f32;
        panel.fill_rect(
            bar_x,
            bar_y + row,
            bar_x + bar_w,
            bar_y + row + 1,
            error_color(t),
        );
    }
    outline(&mut panel, (bar_x, bar_y), (bar_w, bar_h));
    for (value, tick) in &ticks {
        let t = if max > 0.0 { value / max } else { 0.0 };
        let y = bar_y + ((1.0 - t) * (bar_h - 1) as f32).round() as u32;
        panel.fill_rect(bar_x + bar_w, y, bar_x + bar_w + tick_len, y + 1, FRAME);
        text::draw(
            &mut panel,
            tick,
            (label_x as i32, y as i32),
            Anchor::LEFT_CENTER,
            &style,
        )?;
    }
    if !label.is_empty() {
        let vertical = Style {
            turn: Turn::Cw270,
            ..style
        };
        let fitted = text::fit(label, &style, h.saturating_sub(8))?;
        let centre = ((title_x + font_px / 2) as i32, (h / 2) as i32);
        text::draw(&mut panel, &fitted, centre, Anchor::CENTER, &vertical)?;
    }
    crate::image::hstack(&[image.clone(), panel])
}

/// The colour of a bar's frame and tick marks.
const FRAME: [u8; 3] = [90, 90, 96];

/// A one-pixel frame around the `w`×`h` rectangle at `(x, y)`.
fn outline(image: &mut Image, (x, y): (u32, u32), (w, h): (u32, u32)) {
    image.fill_rect(x, y, x + w, y + 1, FRAME);
    image.fill_rect(x, y + h - 1, x + w, y + h, FRAME);
    image.fill_rect(x, y, x + 1, y + h, FRAME);
    image.fill_rect(x + w - 1, y, x + w, y + h, FRAME);
}

/// The picture under a horizontal colour bar of the error map (0 on the left, `max` on the
/// right), with tick labels beneath it and `label` on its left, in a white band on top: the
/// first thing seen on a long sheet. The width grows only if the band needs more room.
/// Errors: a bad image, a negative or non-finite `max`.
pub fn with_colorbar_on_top(image: &Image, max: f32, label: &str) -> Result<Image, RenderError> {
    image.validate("image")?;
    if !max.is_finite() || max < 0.0 {
        return Err(RenderError::invalid(
            "max",
            format!("the colour bar's maximum must be finite and >= 0, got {max}"),
        ));
    }
    let font = (f64::from(image.width) / 60.0).clamp(12.0, 17.0);
    let style = Style::new(font);
    let font_px = font.ceil() as u32;
    let margin = font_px;
    let label_w = if label.is_empty() {
        0
    } else {
        text::text_size(label, &style)?.0 + font_px
    };
    let bar_w = (image.width * 2 / 5).clamp(160, 520);
    let bar_h = (font_px * 6 / 5).max(12);
    let ticks = ticks(max);
    let last_w = ticks
        .last()
        .map_or(Ok(0), |(_, t)| text::text_size(t, &style).map(|s| s.0))?;
    let needed = margin + label_w + bar_w + last_w + margin;
    let width = image.width.max(needed);
    let band_h = margin + bar_h + 5 + font_px * 2 + margin / 2;
    let mut out = Image::filled(width, band_h + image.height, [255; 3])?;
    let bar_x = margin + label_w;
    let bar_y = margin;
    for col in 0..bar_w {
        let t = col as f32 / (bar_w.max(2) - 1) as f32;
        out.fill_rect(
            bar_x + col,
            bar_y,
            bar_x + col + 1,
            bar_y + bar_h,
            error_color(t),
        );
    }
    outline(&mut out, (bar_x, bar_y), (bar_w, bar_h));
    for (value, tick) in &ticks {
        let t = if max > 0.0 { value / max } else { 0.0 };
        let x = bar_x + (t * (bar_w - 1) as f32).round() as u32;
        out.fill_rect(x, bar_y + bar_h, x + 1, bar_y + bar_h + 5, FRAME);
        text::draw(
            &mut out,
            tick,
            (x as i32, (bar_y + bar_h + 7) as i32),
            Anchor::CENTER_TOP,
            &style,
        )?;
    }
    if !label.is_empty() {
        let centre = (margin as i32, (bar_y + bar_h / 2) as i32);
        text::draw(&mut out, label, centre, Anchor::LEFT_CENTER, &style)?;
    }
    out.blit(image, (width - image.width) / 2, band_h);
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_top_colour_bar_runs_from_cool_to_hot_above_the_picture() {
        let picture = Image::filled(400, 100, [10, 200, 10]).unwrap();
        let out = with_colorbar_on_top(&picture, 0.5, "error").unwrap();
        assert_eq!(out.width, 400);
        let band = out.height - 100;
        assert!(band > 30, "band {band}");
        // The picture sits under the band, unchanged.
        assert_eq!(out.pixel(200, band + 50), Some([10, 200, 10]));
        // Along the bar's middle row: the first stop on the left, the last on the right.
        let row = (0..band)
            .find(|&y| out.pixel(200, y) != Some([255; 3]))
            .unwrap()
            + 3;
        let xs: Vec<u32> = (0..400)
            .filter(|&x| out.pixel(x, row) != Some([255; 3]))
            .collect();
        let (left, right) = (xs[2], xs[xs.len() - 3]);
        let lum = |c: [u8; 3]| c.iter().map(|&v| u32::from(v)).sum::<u32>();
        assert!(lum(out.pixel(left, row).unwrap()) > lum(out.pixel(right, row).unwrap()));
        assert!(with_colorbar_on_top(&picture, f32::NAN, "").is_err());
    }

    #[test]
    fn ticks_are_nice_and_end_at_max() {
        let labels = |max: f32| ticks(max).into_iter().map(|t| t.1).collect::<Vec<_>>();
        assert_eq!(labels(1.0), ["0", "0.25", "0.50", "0.75", "1.00"]);
        assert_eq!(labels(0.0123), ["0", "0.005", "0.010", "0.0123"]);
        assert_eq!(labels(0.0104), ["0", "0.005", "0.0104"]);
        assert_eq!(labels(40.0), ["0", "10", "20", "30", "40"]);
        assert_eq!(labels(0.0), ["0"]);
        let t = ticks(0.0123);
        assert_eq!(t.last().unwrap().0, 0.0123);
        assert!(t.windows(2).all(|p| p[1].0 > p[0].0));
    }
}
