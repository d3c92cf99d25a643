//! `Image` (8-bit RGB pixels), PNG encoding/decoding, and side-by-side composition.

use crate::error::RenderError;
use std::io::Cursor;
use std::path::{Path, PathBuf};

/// Largest width or height accepted anywhere (render, sheet, plot, decode).
pub const MAX_SIDE: u32 = 32_768;
/// Largest pixel count of one image (192 MB of RGB): bigger requests are errors, not OOM aborts.
pub const MAX_PIXELS: u64 = 1 << 26;

/// An 8-bit RGB image, rows top to bottom, `rgb.len() == 3 × width × height`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Image {
    pub width: u32,
    pub height: u32,
    pub rgb: Vec<u8>,
}

impl Image {
    /// An image of one colour. Fails on a zero or too large size.
    pub fn filled(width: u32, height: u32, color: [u8; 3]) -> Result<Image, RenderError> {
        check_size("size", width, height)?;
        let rgb = color.repeat(width as usize * height as usize);
        Ok(Image { width, height, rgb })
    }

    /// Checks the invariant `rgb.len() == 3 × width × height` and the size limits; `argument`
    /// names the image in the error.
    pub fn validate(&self, argument: &'static str) -> Result<(), RenderError> {
        check_size(argument, self.width, self.height)?;
        let expected = 3 * self.width as u64 * self.height as u64;
        if self.rgb.len() as u64 != expected {
            return Err(RenderError::Size {
                argument,
                width: self.width.into(),
                height: self.height.into(),
                message: format!("{} bytes of RGB, expected {expected}", self.rgb.len()),
            });
        }
        Ok(())
    }

    /// The pixel at column `x`, row `y` (row 0 at the top); `None` outside the image.
    pub fn pixel(&self, x: u32, y: u32) -> Option<[u8; 3]> {
        if x >= self.width || y >= self.height {
            return None;
        }
        let i = 3 * (y as usize * self.width as usize + x as usize);
        let p = self.rgb.get(i..i + 3)?;
        Some([p[0], p[1], p[2]])
    }

    /// Encodes the image as an 8-bit RGB PNG.
    pub fn encode_png(&self) -> Result<Vec<u8>, RenderError> {
        self.validate("image")?;
        let mut bytes = Vec::new();
        write_png(&mut bytes, self).map_err(|e| png_error(Path::new("<memory>"), e))?;
        Ok(bytes)
    }

    /// Writes the image as PNG to `path`, atomically: on any error no file (and no partial file)
    /// is left at `path`.
    pub fn save_png(&self, path: &Path) -> Result<(), RenderError> {
        // Encode first so that an encoding error never touches the file system.
        let bytes = self.encode_png()?;
        mesh_io::atomic::write_bytes_atomic(path, &bytes)?;
        Ok(())
    }

    /// Decodes a PNG (any colour type and depth; alpha is composited over white) into RGB.
    pub fn decode_png(bytes: &[u8]) -> Result<Image, RenderError> {
        decode(bytes, Path::new("<memory>"))
    }

    /// Reads and decodes a PNG file.
    pub fn load_png(path: &Path) -> Result<Image, RenderError> {
        let bytes = std::fs::read(path).map_err(|e| mesh_io::MeshIoError::Io {
            path: path.into(),
            source: e,
        })?;
        decode(&bytes, path)
    }

    /// Copies `src` into `self` with its top-left corner at `(x, y)`, clipped to `self`.
    pub(crate) fn blit(&mut self, src: &Image, x: u32, y: u32) {
        let w = self.width.saturating_sub(x).min(src.width) as usize;
        let (dw, sw) = (self.width as usize, src.width as usize);
        for row in 0..src.height.min(self.height.saturating_sub(y)) as usize {
            let d = 3 * ((y as usize + row) * dw + x as usize);
            let s = 3 * row * sw;
            self.rgb[d..d + 3 * w].copy_from_slice(&src.rgb[s..s + 3 * w]);
        }
    }

    /// Fills the rectangle `[x0, x1) × [y0, y1)`, clipped to the image.
    pub(crate) fn fill_rect(&mut self, x0: u32, y0: u32, x1: u32, y1: u32, color: [u8; 3]) {
        let (x1, y1) = (x1.min(self.width), y1.min(self.height));
        for y in y0..y1 {
            for x in x0..x1 {
                let i = 3 * (y as usize * self.width as usize + x as usize);
                self.rgb[i..i + 3].copy_from_slice(&color);
            }
        }
    }
}

/// Fails unless `0 < width, height ≤ MAX_SIDE` and `width × height ≤ MAX_PIXELS`.
pub(crate) fn check_size(
    argument: &'static str,
    width: u32,
    height: u32,
) -> Result<(), RenderError> {
    let bad = |message: String| RenderError::Size {
        argument,
        width: width.into(),
        height: height.into(),
        message,
    };
    if width == 0 || height == 0 {
        return Err(bad("width and height must be positive".into()));
    }
    if width > MAX_SIDE || height > MAX_SIDE || width as u64 * height as u64 > MAX_PIXELS {
        return Err(bad(format!(
            "larger than the limit ({MAX_SIDE} per side, {MAX_PIXELS} pixels)"
        )));
    }
    Ok(())
}

/// Several images side by side, left to right (e.g. latent embedding | PCA | t-SNE), each
/// centred vertically on a white background as tall as the tallest. The width is the sum of the
/// widths.
pub fn hstack(images: &[Image]) -> Result<Image, RenderError> {
    if images.is_empty() {
        return Err(RenderError::Empty { argument: "images" });
    }
    for image in images {
        image.validate("images")?;
    }
    let width: u64 = images.iter().map(|i| u64::from(i.width)).sum();
    let height = images.iter().map(|i| i.height).max().unwrap_or(1);
    let width = u32::try_from(width).unwrap_or(u32::MAX);
    let mut out = Image::filled(width, height, [255; 3])?;
    let mut x = 0;
    for image in images {
        out.blit(image, x, (height - image.height) / 2);
        x += image.width;
    }
    Ok(out)
}

fn write_png(w: &mut Vec<u8>, image: &Image) -> Result<(), png::EncodingError> {
    let mut encoder = png::Encoder::new(w, image.width, image.height);
    encoder.set_color(png::ColorType::Rgb);
    encoder.set_depth(png::BitDepth::Eight);
    let mut writer = encoder.write_header()?;
    writer.write_image_data(&image.rgb)?;
    writer.finish()
}

fn png_error(path: &Path, e: impl std::fmt::Display) -> RenderError {
    RenderError::Png {
        path: PathBuf::from(path),
        message: e.to_string(),
    }
}

fn decode(bytes: &[u8], path: &Path) -> Result<Image, RenderError> {
    let mut decoder = png::Decoder::new(Cursor::new(bytes));
    decoder.set_transformations(png::Transformations::EXPAND | png::Transformations::STRIP_16);
    let mut reader = decoder.read_info().map_err(|e| png_error(path, e))?;
    let (width, height) = (reader.info().width, reader.info().height);
    check_size("PNG", width, height).map_err(|e| png_error(path, e))?;
    let size = reader
        .output_buffer_size()
        .ok_or_else(|| png_error(path, "image too large"))?;
    let mut buf = vec![0; size];
    let info = reader
        .next_frame(&mut buf)
        .map_err(|e| png_error(path, e))?;
    let channels = match info.color_type {
        png::ColorType::Grayscale => 1,
        png::ColorType::GrayscaleAlpha => 2,
        png::ColorType::Rgb => 3,
        png::ColorType::Rgba => 4,
        png::ColorType::Indexed => {
            return Err(png_error(path, "palette not expanded"));
        }
    };
    let (w, h) = (info.width as usize, info.height as usize);
    let mut rgb = Vec::with_capacity(3 * w * h);
    for y in 0..h {
        let row = &buf[y * info.line_size..][..w * channels];
        for px in row.chunks_exact(channels) {
            let (color, alpha) = match channels {
                1 => ([px[0]; 3], 255),
                2 => ([px[0]; 3], px[1]),
                3 => ([px[0], px[1], px[2]], 255),
                _ => ([px[0], px[1], px[2]], px[3]),
            };
            // Composite over white, the background of every picture this crate makes.
            let a = u32::from(alpha);
            rgb.extend(color.map(|c| ((u32::from(c) * a + 255 * (255 - a) + 127) / 255) as u8));
        }
    }
    Ok(Image {
        width: info.width,
        height: info.height,
        rgb,
    })
}
