//! # mesh-render: pictures of meshes and plots, as PNG, in pure Rust
//!
//! **In:** triangle meshes (positions + faces, optionally a colour per vertex, e.g. from
//! [`error_colors`]), 2-D point series, curves over steps or epochs. **Out:** RGB [`Image`]s —
//! shaded renders ([`render`]), captioned contact sheets ([`sheet`]), colour bars
//! ([`with_colorbar`]), scatter plots ([`scatter`]), line plots of training curves with a log
//! y axis and markers ([`line_plot`]), dot plots of a few values per category ([`dot_plot`]),
//! side-by-side panels ([`hstack`]) — written as PNG ([`Image::save_png`], atomically).
//!
//! [`render`] is a software rasterizer: orthographic camera from one of six [`View`]s, or by
//! default `View::Auto` (along the box's thinnest axis, y up where possible: long shapes are seen
//! broadside, standing ones standing), framing a box ([`Bounds`]; give several renders the same
//! one to compare sizes and to get one view for all), z-buffer, Lambert shading with a headlight
//! and ambient term, both sides of every face lit (open meshes show their inside, darker), smooth
//! normals except at creases, 2×2 supersampling, rayon over bands of rows. Text uses the embedded DejaVu Sans font: no GPU, no system library, no font files.
//! Bad input (a face index out of range, NaN, a zero size, colours of the wrong length, …) is a
//! [`RenderError`] naming the argument, never a panic.
//!
//! ```
//! use mesh_render::{RenderOptions, View, render};
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let capsule = mesh_io::synth::rest_capsule(&mesh_io::synth::SynthConfig::default());
//! let options = RenderOptions { width: 96, height: 128, view: View::Front, ..Default::default() };
//! let image = render(&capsule.positions, &capsule.faces, None, &options)?;
//! assert_eq!((image.width, image.height, image.rgb.len()), (96, 128, 96 * 128 * 3));
//! // The capsule (along z) is seen end-on from the front: a shaded blob in the middle,
//! // white background in the corners.
//! assert_eq!(image.pixel(0, 0), Some([255, 255, 255]));
//! let centre = image.pixel(48, 64).unwrap();
//! assert!(centre != [255, 255, 255] && centre[0] > 60);
//!
//! // Colour by a per-vertex error and add a colour bar.
//! let errors: Vec<f32> = capsule.positions.iter().map(|p| p[0].abs()).collect();
//! let colors = mesh_render::error_colors(&errors, 0.6);
//! let side = RenderOptions { view: View::Left, ..options };
//! let image = render(&capsule.positions, &capsule.faces, Some(&colors), &side)?;
//! let with_bar = mesh_render::with_colorbar(&image, 0.6, "distance")?;
//! assert!(with_bar.width > image.width && with_bar.height == image.height);
//! let png = with_bar.encode_png()?;
//! assert_eq!(mesh_render::Image::decode_png(&png)?, with_bar);
//! # Ok(()) }
//! ```

mod axis;
mod camera;
mod chart_backend;
pub mod colormap;
mod dots;
mod error;
mod image;
mod lines;
mod plot;
mod raster;
mod sheet;
mod text;

pub use camera::{Bounds, MARGIN, View};
pub use colormap::{error_color, error_colors};
pub use dots::{DotPlot, DotRow, dot_plot};
pub use error::RenderError;
pub use image::{Image, MAX_PIXELS, MAX_SIDE, hstack};
pub use lines::{Curve, LinePlot, Marker, line_plot};
pub use plot::{MIN_PLOT_SIZE, SERIES_COLORS, Series, scatter};
pub use raster::{MAX_RENDER_PIXELS, NEUTRAL_GREY, RenderOptions, SUPERSAMPLING, render};
pub use sheet::{Tile, caption_height, sheet, ticks, with_colorbar, with_colorbar_on_top};
