//! Line plots with plotters (embedded font, in-memory bitmap): training curves — a loss per step
//! or epoch for several splits — on a linear or logarithmic y axis, with labelled vertical markers.

use crate::axis::{Axis, tick_label};
use crate::chart_backend::ChartBackend;
use crate::error::RenderError;
use crate::image::Image;
use crate::plot::{
    AXIS_COLOR, GRID_BOLD, GRID_LIGHT, Range, SERIES_COLORS, check_plot_size, padded, rgb,
};
use crate::text::{FAMILY, draw_error, ensure_font};
use layout::layout;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

mod layout;
#[cfg(test)]
mod tests;

/// One curve of a [`line_plot`].
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Curve {
    /// Shown in the legend (no legend when every name is empty).
    pub name: String,
    /// `[x, y]` points, joined in this order (usually by increasing x).
    pub points: Vec<[f64; 2]>,
}

/// A vertical marker line with a short label (e.g. "best", "lr ×0.5").
#[derive(Debug, Clone, PartialEq)]
pub struct Marker {
    pub x: f64,
    /// Written just above the plot area, centred over the line (may be empty; left out when
    /// too many labels crowd there).
    pub label: String,
    /// A light grey dashed line instead of a dark grey solid one.
    pub dashed: bool,
}

/// Title, axis descriptions, y scale and size of a [`line_plot`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LinePlot<'a> {
    pub title: &'a str,
    pub x_label: &'a str,
    pub y_label: &'a str,
    /// Logarithmic y axis (ticks at 1-2-5 × 10ᵏ or similar); every y must then be positive.
    pub log_y: bool,
    pub width: u32,
    pub height: u32,
}

impl Default for LinePlot<'_> {
    /// No texts, linear y, 800×500.
    fn default() -> Self {
        LinePlot {
            title: "",
            x_label: "",
            y_label: "",
            log_y: false,
            width: 800,
            height: 500,
        }
    }
}

/// Colour of a solid marker line (and its label).
const MARKER_SOLID: [u8; 3] = [72, 72, 80];
/// Colour of a dashed marker line; its label uses [`MARKER_DASHED_TEXT`].
const MARKER_DASHED: [u8; 3] = [150, 150, 160];
const MARKER_DASHED_TEXT: [u8; 3] = [105, 105, 115];

/// A line plot on white: title, axis descriptions, a light grid, the curves as lines (colours of
/// [`SERIES_COLORS`] in order; a single-point curve is a dot), a legend with the curve names in
/// the emptiest corner (upper right unless the curves pass there), and vertical marker lines
/// whose labels sit just above the plot area (stacked in up to three rows where they would
/// overlap; labels that still do not fit are left out, those of solid markers last).
///
/// The x axis spans the data (curves and markers) exactly; the y axis spans the curves with a
/// little padding, logarithmically with [`LinePlot::log_y`]. Curves with many points (tens of
/// thousands) are fine: dense curves are drawn with thin anti-aliased lines.
///
/// Errors ([`RenderError`], never a panic): no points in any curve, a non-finite coordinate or
/// (with `log_y`) a y ≤ 0 — naming the curve and the point index —, a non-finite marker x, a size
/// below [`MIN_PLOT_SIZE`](crate::MIN_PLOT_SIZE) or too large.
///
/// ```
/// use mesh_render::{Curve, LinePlot, Marker, line_plot};
/// # fn main() -> Result<(), mesh_render::RenderError> {
/// let loss = |name: &str, offset: f64| Curve {
///     name: name.into(),
///     points: (0..300)
///         .map(|step| {
///             let x = f64::from(step);
///             [x, 1000.0 * (-x / 50.0).exp() + offset]
///         })
///         .collect(),
/// };
/// let plot = LinePlot {
///     title: "Reconstruction loss",
///     x_label: "epoch",
///     y_label: "MSE",
///     log_y: true,
///     width: 640,
///     height: 400,
/// };
/// let best = Marker { x: 240.0, label: "best".into(), dashed: false };
/// let image = line_plot(&plot, &[loss("train", 300.0), loss("validation", 340.0)], &[best])?;
/// assert_eq!((image.width, image.height), (640, 400));
/// image.encode_png()?;
///
/// // A logarithmic axis cannot show zero: the error names the curve and the point.
/// let bad = Curve { name: "test".into(), points: vec![[0.0, 2.0], [1.0, 0.0]] };
/// let err = line_plot(&plot, &[bad], &[]).unwrap_err();
/// assert!(err.to_string().contains("curve \"test\": point 1"), "{err}");
/// # Ok(()) }
/// ```
pub fn line_plot(
    plot: &LinePlot,
    curves: &[Curve],
    markers: &[Marker],
) -> Result<Image, RenderError> {
    render(plot, curves, markers).map(|(image, _)| image)
}

/// Where the plot area (inside the axes) ended up, in image pixels; `end`s are exclusive.
#[derive(Debug, Clone, PartialEq)]
struct Frame {
    x: std::ops::Range<i32>,
    y: std::ops::Range<i32>,
}

fn render(
    plot: &LinePlot,
    curves: &[Curve],
    markers: &[Marker],
) -> Result<(Image, Frame), RenderError> {
    check_plot_size(plot.width, plot.height)?;
    if curves.iter().all(|c| c.points.is_empty()) {
        return Err(RenderError::Empty { argument: "curves" });
    }
    validate(curves, markers, plot.log_y)?;
    let ranges = data_ranges(curves, markers, plot.log_y)?;
    ensure_font()?;
    let (width, height) = (plot.width, plot.height);
    let mut rgb = vec![255u8; 3 * width as usize * height as usize];
    let frame =
        draw(&mut rgb, plot, curves, markers, ranges).map_err(|e| draw_error("line plot", e))?;
    Ok((Image { width, height, rgb }, frame))
}

fn validate(curves: &[Curve], markers: &[Marker], log_y: bool) -> Result<(), RenderError> {
    for c in curves {
        for (i, p) in c.points.iter().enumerate() {
            let problem = if !(p[0].is_finite() && p[1].is_finite()) {
                "is not finite"
            } else if log_y && p[1] <= 0.0 {
                "has y <= 0, which a logarithmic y axis cannot show"
            } else {
                continue;
            };
            return Err(RenderError::invalid(
                "curves",
                format!(
                    "curve {:?}: point {i} ({}, {}) {problem}",
                    c.name,
                    show(p[0]),
                    show(p[1])
                ),
            ));
        }
    }
    if let Some((i, m)) = markers.iter().enumerate().find(|(_, m)| !m.x.is_finite()) {
        return Err(RenderError::invalid(
            "markers",
            format!("marker {i} ({:?}): x = {} is not finite", m.label, m.x),
        ));
    }
    Ok(())
}

/// A value in a message: as written in code, in scientific notation when very large or small.
fn show(v: f64) -> String {
    let a = v.abs();
    if !v.is_finite() || a == 0.0 || (1e-4..1e15).contains(&a) {
        format!("{v}")
    } else {
        format!("{v:e}")
    }
}

/// x: exactly the data (curves and markers); y: the curves with 6% padding (in decades with
/// `log_y`). A zero extent is padded as in the scatter plot.
fn data_ranges(
    curves: &[Curve],
    markers: &[Marker],
    log_y: bool,
) -> Result<(Range, Range), RenderError> {
    let (mut x_lo, mut x_hi) = (f64::INFINITY, f64::NEG_INFINITY);
    let (mut y_lo, mut y_hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for p in curves.iter().flat_map(|c| &c.points) {
        (x_lo, x_hi) = (x_lo.min(p[0]), x_hi.max(p[0]));
        (y_lo, y_hi) = (y_lo.min(p[1]), y_hi.max(p[1]));
    }
    for m in markers {
        (x_lo, x_hi) = (x_lo.min(m.x), x_hi.max(m.x));
    }
    let x = if x_hi > x_lo {
        x_lo..x_hi
    } else {
        padded(x_lo, x_hi, 0.0)
    };
    let y = if log_y {
        // Padding stays within the normal range of f64 (1e-300 .. 1e300 data can be shown).
        let (lo, hi) = (y_lo.log10(), y_hi.log10());
        let decades = padded(lo, hi, 0.06);
        10f64.powf(decades.start.max(-307.0).min(lo))..10f64.powf(decades.end.min(308.0).max(hi))
    } else {
        padded(y_lo, y_hi, 0.06)
    };
    let usable = |r: &Range| r.start.is_finite() && r.end.is_finite() && r.end > r.start;
    if !(usable(&x) && usable(&y) && (!log_y || y.start > 0.0)) {
        return Err(RenderError::invalid(
            "curves",
            format!("the data range (x {x:?}, y {y:?}) is too large or too small to plot"),
        ));
    }
    Ok((x, y))
}

type DrawResult<T> = Result<T, Box<dyn std::error::Error>>;

type Chart<'a, 'b> = ChartContext<'a, ChartBackend<'b>, Cartesian2d<Axis, Axis>>;

fn draw(
    buf: &mut [u8],
    plot: &LinePlot,
    curves: &[Curve],
    markers: &[Marker],
    (x_range, y_range): (Range, Range),
) -> DrawResult<Frame> {
    let root = ChartBackend::with_buffer(buf, (plot.width, plot.height)).into_drawing_area();
    root.fill(&WHITE)?;
    let mut layout = layout(&root, plot, markers, (&x_range, &y_range))?;
    let x_axis = Axis::new(&x_range, false, std::mem::take(&mut layout.x_ticks));
    let y_axis = Axis::new(&y_range, plot.log_y, std::mem::take(&mut layout.y_ticks));
    let axis = AXIS_COLOR;
    let tick_style = (FAMILY, layout.tick_px).into_font().color(&axis);
    if !plot.title.is_empty() {
        let style = (FAMILY, layout.title_px)
            .into_font()
            .color(&RGBColor(30, 30, 34))
            .pos(Pos::new(HPos::Center, VPos::Top));
        root.draw_text(plot.title, &style, (plot.width as i32 / 2, layout.margin))?;
    }
    let mut chart = ChartBuilder::on(&root)
        .margin(layout.margin)
        .margin_top(layout.top)
        .margin_right(layout.margin_right)
        .x_label_area_size(layout.x_area)
        .y_label_area_size(layout.y_area)
        .build_cartesian_2d(x_axis, y_axis)?;
    let format = |v: &f64| tick_label(*v);
    let mut mesh = chart.configure_mesh();
    mesh.x_label_formatter(&format)
        .y_label_formatter(&format)
        .label_style(tick_style.clone())
        .axis_desc_style((FAMILY, layout.desc_px).into_font().color(&axis))
        .axis_style(axis)
        .bold_line_style(GRID_BOLD)
        .light_line_style(GRID_LIGHT);
    if !plot.x_label.is_empty() {
        mesh.x_desc(plot.x_label);
    }
    if !plot.y_label.is_empty() {
        mesh.y_desc(plot.y_label);
    }
    mesh.draw()?;
    let (px, py) = chart.plotting_area().get_pixel_range();
    let frame = Frame { x: px, y: py };
    let plot_w = (frame.x.end - frame.x.start).max(1) as usize;

    // Marker lines under the curves.
    for m in markers {
        let line = vec![(m.x, y_range.start), (m.x, y_range.end)];
        if m.dashed {
            let style = rgb(MARKER_DASHED).stroke_width(1);
            chart.draw_series(DashedLineSeries::new(line, 6, 4, style))?;
        } else {
            chart.draw_series(std::iter::once(PathElement::new(line, rgb(MARKER_SOLID))))?;
        }
    }

    // Curves: 2 px wide, or thin (anti-aliased) when denser than one point per two pixels.
    let mut legend = Vec::new();
    for (ci, c) in curves.iter().enumerate() {
        let color = rgb(SERIES_COLORS[ci % SERIES_COLORS.len()]);
        let xy = |p: &[f64; 2]| (p[0], p[1]);
        let annotation = match c.points.len() {
            0 => continue,
            1 => chart.draw_series(std::iter::once(Circle::new(
                xy(&c.points[0]),
                3,
                color.filled(),
            )))?,
            n if n > plot_w / 2 => {
                let path = PathElement::new(c.points.iter().map(xy).collect::<Vec<_>>(), color);
                chart.draw_series(std::iter::once(path))?
            }
            _ => {
                // About 2 px wide and still anti-aliased: the thin line three times, shifted by
                // a pixel right and down (plotters' wide lines are jagged polygons).
                let pixels: Vec<(i32, i32)> = c
                    .points
                    .iter()
                    .map(|p| chart.backend_coord(&xy(p)))
                    .collect();
                for (dx, dy) in [(0, 0), (1, 0), (0, 1)] {
                    let shifted = pixels.iter().map(|&(x, y)| (x + dx, y + dy));
                    root.draw(&PathElement::new(shifted.collect::<Vec<_>>(), color))?;
                }
                chart.draw_series(std::iter::empty::<PathElement<(f64, f64)>>())?
            }
        };
        if !c.name.is_empty() {
            let sample = (layout.tick_px * 1.6) as i32;
            annotation.label(c.name.as_str()).legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + sample, y)], color.stroke_width(2))
            });
            legend.push(c.name.as_str());
        }
    }
    if !legend.is_empty() {
        let legend_area = (layout.tick_px * 2.4) as i32;
        let legend_margin = (layout.tick_px * 0.6) as i32;
        let text_w = legend.iter().try_fold(0, |w, name| {
            Ok::<_, Box<dyn std::error::Error>>(
                w.max(root.estimate_text_size(name, &tick_style)?.0),
            )
        })? as i32;
        let size = (
            text_w + legend_area + 2 * legend_margin,
            (legend.len() as f64 * layout.tick_px * 1.3) as i32 + 2 * legend_margin,
        );
        let position = legend_corner(&chart, curves, &frame, size);
        chart
            .configure_series_labels()
            .label_font(tick_style.clone())
            .legend_area_size(legend_area)
            .margin(legend_margin)
            .background_style(WHITE)
            .border_style(RGBColor(200, 200, 205))
            .position(position)
            .draw()?;
    }

    // Marker labels just above the plot area, centred over their lines.
    for (m, row) in markers.iter().zip(&layout.marker_rows) {
        let Some(row) = row else { continue };
        let (x, _) = chart.backend_coord(&(m.x, y_range.end));
        let color = if m.dashed {
            MARKER_DASHED_TEXT
        } else {
            MARKER_SOLID
        };
        let color = rgb(color);
        let style = tick_style.color(&color);
        let w = root.estimate_text_size(&m.label, &style)?.0 as i32;
        let left = (x - w / 2).clamp(2, (plot.width as i32 - 2 - w).max(2));
        let y = frame.y.start - 3 - (*row as i32 + 1) * layout.row_px;
        root.draw_text(
            &m.label,
            &style,
            (left, y + (layout.row_px - layout.tick_px as i32) / 2),
        )?;
    }
    root.present()?;
    Ok(frame)
}

/// The legend corner (upper right first) crossed by the fewest curve segments, for a legend of
/// `size` pixels placed as plotters does (5 pixels from the plot area's sides).
fn legend_corner(
    chart: &Chart,
    curves: &[Curve],
    frame: &Frame,
    (w, h): (i32, i32),
) -> SeriesLabelPosition {
    let (fw, fh) = (frame.x.end - frame.x.start, frame.y.end - frame.y.start);
    let corners = [
        (SeriesLabelPosition::UpperRight, fw - w - 5, 5),
        (SeriesLabelPosition::LowerRight, fw - w - 5, fh - h - 5),
        (SeriesLabelPosition::UpperLeft, 5, 5),
        (SeriesLabelPosition::LowerLeft, 5, fh - h - 5),
    ];
    let pixels: Vec<Vec<(f64, f64)>> = curves
        .iter()
        .map(|c| {
            c.points
                .iter()
                .map(|p| {
                    let (x, y) = chart.backend_coord(&(p[0], p[1]));
                    (f64::from(x - frame.x.start), f64::from(y - frame.y.start))
                })
                .collect()
        })
        .collect();
    let hits = |x0: i32, y0: i32| {
        let rect = (
            f64::from(x0 - 2),
            f64::from(y0 - 2),
            f64::from(x0 + w + 2),
            f64::from(y0 + h + 2),
        );
        pixels
            .iter()
            .map(|c| match c.as_slice() {
                [p] => usize::from(segment_hits(*p, *p, rect)),
                c => c
                    .windows(2)
                    .filter(|s| segment_hits(s[0], s[1], rect))
                    .count(),
            })
            .sum::<usize>()
    };
    let mut best = (usize::MAX, SeriesLabelPosition::UpperRight);
    for (position, x0, y0) in corners {
        let n = hits(x0, y0);
        if n < best.0 {
            best = (n, position);
        }
    }
    best.1
}

/// Whether the segment a–b meets the rectangle (x0, y0, x1, y1) (Liang–Barsky clipping).
fn segment_hits(a: (f64, f64), b: (f64, f64), (x0, y0, x1, y1): (f64, f64, f64, f64)) -> bool {
    let (dx, dy) = (b.0 - a.0, b.1 - a.1);
    let (mut t0, mut t1) = (0.0f64, 1.0f64);
    for (p, q) in [
        (-dx, a.0 - x0),
        (dx, x1 - a.0),
        (-dy, a.1 - y0),
        (dy, y1 - a.1),
    ] {
        if p == 0.0 {
            if q < 0.0 {
                return false;
            }
        } else {
            let t = q / p;
            if p < 0.0 {
                t0 = t0.max(t);
            } else {
                t1 = t1.min(t);
            }
        }
    }
    t0 <= t1
}
