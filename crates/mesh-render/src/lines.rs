//! Line plots with plotters (embedded font, in-memory bitmap): training curves — a loss per step
//! or epoch for several splits — on a linear or logarithmic y axis, with labelled vertical markers.

use crate::error::RenderError;
use crate::image::Image;
use crate::plot::{
    AXIS_COLOR, GRID_BOLD, GRID_LIGHT, Range, SERIES_COLORS, check_plot_size, padded, rgb,
};
use crate::text::{FAMILY, draw_error, ensure_font};
use plotters::coord::Shift;
use plotters::coord::ranged1d::{DefaultFormatting, KeyPointHint};
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

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

/// A tick label: up to 5 significant digits without trailing zeros; scientific ("1e-4",
/// "2.5e6") outside 0.001 ≤ |v| < 10⁶.
fn tick_label(v: f64) -> String {
    fn trim(s: &str) -> &str {
        if s.contains('.') {
            s.trim_end_matches('0').trim_end_matches('.')
        } else {
            s
        }
    }
    let a = v.abs();
    if a == 0.0 {
        "0".into()
    } else if (1e-3..1e6).contains(&a) {
        let decimals = (4 - a.log10().floor() as i32).max(0) as usize;
        trim(&format!("{v:.decimals$}")).into()
    } else {
        let s = format!("{v:.3e}");
        match s.split_once('e') {
            Some((mantissa, exponent)) => format!("{}e{exponent}", trim(mantissa)),
            None => s,
        }
    }
}

/// The smallest 1, 2 or 5 × 10ᵏ that is at least `min_step`.
fn nice_step(min_step: f64) -> f64 {
    if !(min_step.is_finite() && min_step > 0.0) {
        return 1.0;
    }
    let base = 10f64.powf(min_step.log10().floor());
    [1.0, 2.0, 5.0, 10.0]
        .into_iter()
        .map(|m| m * base)
        .find(|&s| s >= min_step * (1.0 - 1e-9))
        .unwrap_or(10.0 * base)
}

/// The multiples of `step` inside `range` (none when there would be absurdly many).
fn multiples(range: &Range, step: f64) -> Vec<f64> {
    let first = (range.start / step - 1e-9).ceil();
    let last = (range.end / step + 1e-9).floor();
    if !(first.is_finite() && last.is_finite() && last >= first && last - first <= 1000.0) {
        return Vec::new();
    }
    (first as i64..=last as i64)
        .map(|k| k as f64 * step)
        .collect()
}

/// Bold (labelled) and light grid positions of a linear axis: round steps at least `min_step`
/// apart, light lines halfway.
fn linear_ticks(range: &Range, min_step: f64) -> (Vec<f64>, Vec<f64>) {
    let step = nice_step(min_step);
    (multiples(range, step), multiples(range, step / 2.0))
}

/// Bold and light grid positions of a logarithmic axis over `range` (positive) whose labelled
/// neighbours are at least `min_decades` apart: 1…9, 1-2-3-4-5-7, 1-2-3-5, 1-2-5 or 1 × 10ᵏ, or every few
/// decades; light lines at 1…9 × 10ᵏ. Over less than 1.5 decades (or with fewer than three such
/// ticks), round linear steps instead when they give more labels.
fn log_ticks(range: &Range, min_decades: f64) -> (Vec<f64>, Vec<f64>) {
    let (lo, hi) = (range.start, range.end);
    let (first, last) = (lo.log10().floor() as i32, hi.log10().ceil() as i32);
    let inside = |v: &f64| *v >= lo * (1.0 - 1e-12) && *v <= hi * (1.0 + 1e-12);
    let decade_points = |mantissas: &[f64], every: i32| -> Vec<f64> {
        (first..=last)
            .filter(|e| e.rem_euclid(every) == 0)
            .flat_map(|e| mantissas.iter().map(move |m| m * 10f64.powi(e)))
            .filter(inside)
            .collect()
    };
    let spaced = |t: &[f64]| {
        t.windows(2)
            .all(|w| (w[1] / w[0]).log10() >= min_decades * (1.0 - 1e-9))
    };
    const ALL: [f64; 9] = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0];
    let mantissa_sets: [&[f64]; 5] = [
        &ALL,
        &[1.0, 2.0, 3.0, 4.0, 5.0, 7.0],
        &[1.0, 2.0, 3.0, 5.0],
        &[1.0, 2.0, 5.0],
        &[1.0],
    ];
    let bold = mantissa_sets
        .iter()
        .map(|m| decade_points(m, 1))
        .find(|t| spaced(t))
        .unwrap_or_else(|| {
            let every = [2, 3, 5, 10, 20, 50, 100]
                .into_iter()
                .find(|&k| f64::from(k) >= min_decades)
                .unwrap_or(100);
            decade_points(&[1.0], every)
        });
    if bold.len() < 3 || (hi / lo).log10() < 1.5 {
        // The narrowest gap of linear ticks is at the top: hi / (hi - step) >= 10^min_decades.
        let (linear, light) = linear_ticks(range, hi * (1.0 - 10f64.powf(-min_decades)));
        if linear.len() > bold.len() && linear.iter().all(|v| *v > 0.0) {
            return (linear, light);
        }
    }
    let light = if (hi / lo).log10() <= 8.0 {
        decade_points(&ALL, 1)
    } else {
        decade_points(&[1.0], 1)
    };
    (bold, light)
}

type DrawResult<T> = Result<T, Box<dyn std::error::Error>>;
type Root<'b> = DrawingArea<BitMapBackend<'b>, Shift>;

/// Pixel sizes of the texts and the reserved areas, derived from the image size.
struct Layout {
    title_px: f64,
    tick_px: f64,
    desc_px: f64,
    margin: i32,
    margin_right: i32,
    /// Above the plot area: margin, title, marker label rows.
    top: i32,
    x_area: i32,
    y_area: i32,
    row_px: i32,
    /// Row of each marker's label (0 = just above the plot area); `None`: no label, or no room.
    marker_rows: Vec<Option<usize>>,
    x_ticks: (Vec<f64>, Vec<f64>),
    y_ticks: (Vec<f64>, Vec<f64>),
}

fn text_width(root: &Root, text: &str, style: &TextStyle) -> DrawResult<f64> {
    if text.is_empty() {
        return Ok(0.0);
    }
    Ok(f64::from(root.estimate_text_size(text, style)?.0))
}

fn max_width(root: &Root, values: &[f64], style: &TextStyle) -> DrawResult<f64> {
    values.iter().try_fold(0.0f64, |w, v| {
        Ok(w.max(text_width(root, &tick_label(*v), style)?))
    })
}

fn layout(
    root: &Root,
    plot: &LinePlot,
    markers: &[Marker],
    (x_range, y_range): (&Range, &Range),
) -> DrawResult<Layout> {
    let (width, height) = (f64::from(plot.width), f64::from(plot.height));
    let h = height.min(width * 1.5);
    let title_px = (h / 20.0).clamp(13.0, 26.0);
    let desc_px = (h / 30.0).clamp(11.0, 19.0);
    let tick_px = (h / 38.0).clamp(10.0, 16.0);
    let tick_style = TextStyle::from((FAMILY, tick_px).into_font());
    let margin = (h / 40.0).max(6.0).round();
    let title_h = if plot.title.is_empty() {
        0.0
    } else {
        let style = TextStyle::from((FAMILY, title_px).into_font());
        let th = f64::from(root.estimate_text_size(plot.title, &style)?.1);
        th + 2.0 * (th / 2.0).min(5.0).floor()
    };
    let row_px = (tick_px * 1.35).ceil();
    let any_label = markers.iter().any(|m| !m.label.is_empty());
    let x_area = (tick_px
        + 10.0
        + if plot.x_label.is_empty() {
            0.0
        } else {
            desc_px * 1.6
        })
    .ceil();
    let label_gap = 2.4 * tick_px;

    // y ticks, for the plot height expected with one row of marker labels.
    let plot_h = |rows: usize| {
        let band = if any_label {
            rows as f64 * row_px + 4.0
        } else {
            0.0
        };
        (height - 2.0 * margin - title_h - band - x_area).max(20.0)
    };
    let y_ticks = if plot.log_y {
        let decades = (y_range.end / y_range.start).log10();
        log_ticks(y_range, decades * label_gap / plot_h(1))
    } else {
        let extent = y_range.end - y_range.start;
        linear_ticks(y_range, extent * label_gap / plot_h(1))
    };
    let y_desc = if plot.y_label.is_empty() {
        0.0
    } else {
        desc_px * 1.7
    };
    let y_area = (max_width(root, &y_ticks.0, &tick_style)? + 10.0 + 6.0 + y_desc).ceil();

    // x ticks far enough apart for their labels; widen the right margin for the last label.
    let x_extent = x_range.end - x_range.start;
    let widest = max_width(root, &[x_range.start, x_range.end], &tick_style)?;
    let mut margin_right = margin.max(widest / 2.0 + 4.0);
    let mut label_w = widest.max(text_width(root, "0000", &tick_style)?);
    let mut x_ticks = (Vec::new(), Vec::new());
    for _ in 0..3 {
        let plot_w = (width - margin - y_area - margin_right).max(20.0);
        x_ticks = linear_ticks(x_range, x_extent * (label_w + 2.0 * tick_px) / plot_w);
        let w = max_width(root, &x_ticks.0, &tick_style)?;
        margin_right = margin_right.max(w / 2.0 + 4.0);
        if w <= label_w {
            break;
        }
        label_w = w;
    }

    // Marker labels centred over their lines, stacked in rows where they would overlap.
    let (left, right) = (margin + y_area, width - margin_right);
    let spans: Vec<(f64, f64)> = markers
        .iter()
        .map(|m| {
            let w = text_width(root, &m.label, &tick_style)?;
            let px = left + (m.x - x_range.start) / x_extent * (right - left);
            let start = (px - w / 2.0).clamp(2.0, (width - 2.0 - w).max(2.0));
            Ok((start, start + w))
        })
        .collect::<DrawResult<_>>()?;
    // At most three rows, and at most 15% of the height.
    let max_rows = ((0.15 * plot_h(1) / row_px) as usize).clamp(1, 3);
    let marker_rows = label_rows(markers, &spans, tick_px * 0.8, max_rows);
    let rows = marker_rows
        .iter()
        .flatten()
        .map(|r| r + 1)
        .max()
        .unwrap_or(0);
    let band = if any_label {
        rows as f64 * row_px + 4.0
    } else {
        0.0
    };
    Ok(Layout {
        title_px,
        tick_px,
        desc_px,
        margin: margin as i32,
        margin_right: margin_right.ceil() as i32,
        top: (margin + title_h + band) as i32,
        x_area: x_area as i32,
        y_area: y_area as i32,
        row_px: row_px as i32,
        marker_rows,
        x_ticks,
        y_ticks,
    })
}

/// Greedy rows for labels spanning `spans` (pixels): by start, each in the lowest row where it
/// keeps `gap` from the previous label; a label that fits in none of `max_rows` rows, and an
/// empty label, gets `None` (the marker line is still drawn).
fn label_rows(
    markers: &[Marker],
    spans: &[(f64, f64)],
    gap: f64,
    max_rows: usize,
) -> Vec<Option<usize>> {
    let mut order: Vec<usize> = (0..markers.len())
        .filter(|&i| !markers[i].label.is_empty())
        .collect();
    // Solid markers (e.g. "best") first, so that they keep their labels; then by position.
    order.sort_by(|&a, &b| {
        (markers[a].dashed.cmp(&markers[b].dashed)).then(spans[a].0.total_cmp(&spans[b].0))
    });
    let mut placed: Vec<Vec<(f64, f64)>> = vec![Vec::new(); max_rows];
    let mut rows = vec![None; markers.len()];
    for i in order {
        let (start, end) = spans[i];
        let free =
            |row: &Vec<(f64, f64)>| row.iter().all(|&(s, e)| end + gap <= s || e + gap <= start);
        if let Some(r) = placed.iter().position(free) {
            placed[r].push(spans[i]);
            rows[i] = Some(r);
        }
    }
    rows
}

/// An axis for plotters: plotters' own linear or logarithmic (`log_scale`) mapping, with our
/// tick positions (bold ones labelled) instead of plotters' choice.
struct Axis {
    scale: Scale,
    range: Range,
    bold: Vec<f64>,
    light: Vec<f64>,
}

enum Scale {
    Linear(RangedCoordf64),
    Log(LogCoord<f64>),
}

impl Axis {
    fn new(range: &Range, log: bool, (bold, light): (Vec<f64>, Vec<f64>)) -> Axis {
        let scale = if log {
            Scale::Log(range.clone().log_scale().into())
        } else {
            Scale::Linear(range.clone().into())
        };
        Axis {
            scale,
            range: range.clone(),
            bold,
            light,
        }
    }
}

impl Ranged for Axis {
    type FormatOption = DefaultFormatting;
    type ValueType = f64;

    fn map(&self, value: &f64, limit: (i32, i32)) -> i32 {
        match &self.scale {
            Scale::Linear(s) => s.map(value, limit),
            Scale::Log(s) => s.map(value, limit),
        }
    }

    fn key_points<Hint: KeyPointHint>(&self, hint: Hint) -> Vec<f64> {
        if hint.weight().allow_light_points() {
            self.light.clone()
        } else {
            self.bold.clone()
        }
    }

    fn range(&self) -> Range {
        self.range.clone()
    }
}

type Chart<'a, 'b> = ChartContext<'a, BitMapBackend<'b>, Cartesian2d<Axis, Axis>>;

fn draw(
    buf: &mut [u8],
    plot: &LinePlot,
    curves: &[Curve],
    markers: &[Marker],
    (x_range, y_range): (Range, Range),
) -> DrawResult<Frame> {
    let root = BitMapBackend::with_buffer(buf, (plot.width, plot.height)).into_drawing_area();
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
        let th = root.estimate_text_size(plot.title, &style)?.1 as i32;
        root.draw_text(
            plot.title,
            &style,
            (plot.width as i32 / 2, layout.margin + (th / 2).min(5)),
        )?;
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

#[cfg(test)]
mod tests {
    use super::*;

    fn decay(name: &str, n: usize, offset: f64) -> Curve {
        Curve {
            name: name.into(),
            points: (0..n)
                .map(|i| {
                    let x = i as f64;
                    [x, 1000.0 * (-x / (n as f64 / 6.0)).exp() + offset]
                })
                .collect(),
        }
    }

    fn log_plot() -> LinePlot<'static> {
        LinePlot {
            title: "loss",
            x_label: "step",
            y_label: "MSE",
            log_y: true,
            width: 480,
            height: 320,
        }
    }

    fn near(p: [u8; 3], c: [u8; 3], tolerance: i32) -> bool {
        p.iter()
            .zip(c)
            .all(|(a, b)| (i32::from(*a) - i32::from(b)).abs() <= tolerance)
    }

    /// Pixels of the image within `tolerance` of `c` in every channel.
    fn count(image: &Image, c: [u8; 3], tolerance: i32) -> usize {
        image
            .rgb
            .chunks_exact(3)
            .filter(|p| near([p[0], p[1], p[2]], c, tolerance))
            .count()
    }

    #[test]
    fn two_curve_log_plot_shows_both_colours() {
        // Unnamed curves: no legend, so the colours can only come from the curves themselves.
        let curves = [decay("", 60, 300.0), decay("", 60, 30.0)];
        let image = line_plot(&log_plot(), &curves, &[]).unwrap();
        assert_eq!((image.width, image.height), (480, 320));
        assert_eq!(image.rgb.len(), 480 * 320 * 3);
        assert!(image.rgb.iter().any(|&v| v < 200), "all white");
        for color in &SERIES_COLORS[..2] {
            let n = count(&image, *color, 12);
            assert!(n > 100, "{n} pixels of curve colour {color:?}");
        }
        assert_eq!(
            count(&image, SERIES_COLORS[2], 12),
            0,
            "a third colour appeared"
        );
        // Named: a legend appears in the (empty) upper right corner and adds the colours there.
        let named = [decay("train", 60, 300.0), decay("validation", 60, 30.0)];
        let with_legend = line_plot(&log_plot(), &named, &[]).unwrap();
        assert_ne!(with_legend, image);
        let in_upper_right = |image: &Image| {
            let mut n = 0;
            for y in 0..image.height / 2 {
                for x in image.width / 2..image.width {
                    n += usize::from(near(image.pixel(x, y).unwrap(), SERIES_COLORS[1], 12));
                }
            }
            n
        };
        assert!(in_upper_right(&with_legend) > in_upper_right(&image));
    }

    #[test]
    fn log_axis_spans_decades_and_linear_axis_does_not() {
        // Same data, 300 .. 1300 on a log axis vs a linear one: on the log axis the curve's
        // start (high) lies proportionally lower in the frame.
        let curves = [decay("", 100, 1.0)];
        let log = render(&log_plot(), &curves, &[]).unwrap();
        let linear_plot = LinePlot {
            log_y: false,
            ..log_plot()
        };
        let linear = render(&linear_plot, &curves, &[]).unwrap();
        // Height (from the bottom of the frame) of the curve at 1/3 of the x range.
        let curve_height = |(image, frame): &(Image, Frame)| {
            let x = (frame.x.start + (frame.x.end - frame.x.start) / 3) as u32;
            let y = (frame.y.start..frame.y.end)
                .find(|&y| near(image.pixel(x, y as u32).unwrap(), SERIES_COLORS[0], 40))
                .expect("curve pixel in the column");
            f64::from(frame.y.end - y) / f64::from(frame.y.end - frame.y.start)
        };
        // y at x = 33 is 1000·e^-2 + 1 ≈ 136 of 1..1001: linear ≈ 0.14, log ≈ 0.71.
        let (hl, hg) = (curve_height(&linear), curve_height(&log));
        assert!((0.08..0.25).contains(&hl), "linear {hl}");
        assert!((0.6..0.8).contains(&hg), "log {hg}");
    }

    #[test]
    fn solid_marker_is_a_column_at_its_x() {
        let curves = [decay("train", 200, 300.0)];
        let marker = Marker {
            x: 150.0,
            label: "best".into(),
            dashed: false,
        };
        let (image, frame) = render(&log_plot(), &curves, &[marker]).unwrap();
        // Expected column: linear map of x over the data range 0..199 onto the frame.
        let t = 150.0 / 199.0;
        let expected = frame.x.start + (t * f64::from(frame.x.end - frame.x.start)).floor() as i32;
        let column_share = |x: i32| {
            let on = (frame.y.start..frame.y.end)
                .filter(|&y| image.pixel(x as u32, y as u32) == Some(MARKER_SOLID))
                .count();
            on as f64 / f64::from(frame.y.end - frame.y.start)
        };
        let best = (expected - 1..=expected + 1)
            .map(column_share)
            .fold(0.0, f64::max);
        assert!(best > 0.8, "marker column covers only {best}");
        // And nowhere else: columns well away from it have no marker pixels.
        assert!(column_share(expected - 20) < 0.05);
        assert!(column_share(expected + 20) < 0.05);
    }

    #[test]
    fn dashed_marker_is_a_broken_column() {
        let curves = [decay("train", 200, 300.0)];
        let marker = Marker {
            x: 50.0,
            label: "lr ×0.5".into(),
            dashed: true,
        };
        let (image, frame) = render(&log_plot(), &curves, &[marker]).unwrap();
        let x =
            frame.x.start + (50.0 / 199.0 * f64::from(frame.x.end - frame.x.start)).floor() as i32;
        let (on, gaps) = (frame.y.start..frame.y.end).fold((0, 0), |(on, gaps), y| {
            match image.pixel(x as u32, y as u32) == Some(MARKER_DASHED) {
                true => (on + 1, gaps),
                false => (on, gaps + 1),
            }
        });
        let share = f64::from(on) / f64::from(on + gaps);
        assert!((0.4..0.8).contains(&share), "dashed share {share}");
    }

    #[test]
    fn log_y_rejects_zero_and_negative_naming_the_curve() {
        let mut bad = decay("validation", 10, 300.0);
        bad.points[7][1] = 0.0;
        let err = line_plot(&log_plot(), &[decay("train", 10, 300.0), bad.clone()], &[])
            .unwrap_err()
            .to_string();
        assert!(err.starts_with("curves: "), "{err}");
        assert!(err.contains("curve \"validation\": point 7"), "{err}");
        bad.points[7][1] = -2.0;
        let err = line_plot(&log_plot(), &[bad.clone()], &[]).unwrap_err();
        assert!(err.to_string().contains("point 7 (7, -2)"), "{err}");
        // A linear y axis shows them.
        let linear = LinePlot {
            log_y: false,
            ..log_plot()
        };
        line_plot(&linear, &[bad], &[]).unwrap();
    }

    #[test]
    fn non_finite_values_are_errors() {
        let mut nan = decay("test", 10, 300.0);
        nan.points[3][0] = f64::NAN;
        let linear = LinePlot {
            log_y: false,
            ..log_plot()
        };
        for plot in [log_plot(), linear] {
            let err = line_plot(&plot, &[nan.clone()], &[])
                .unwrap_err()
                .to_string();
            assert!(err.contains("curve \"test\": point 3 (NaN, "), "{err}");
            assert!(err.contains("not finite"), "{err}");
        }
        let marker = Marker {
            x: f64::INFINITY,
            label: "best".into(),
            dashed: false,
        };
        let err = line_plot(&log_plot(), &[decay("a", 10, 1.0)], &[marker]).unwrap_err();
        assert!(
            matches!(
                err,
                RenderError::InvalidArgument {
                    argument: "markers",
                    ..
                }
            ),
            "{err}"
        );
        assert!(err.to_string().contains("\"best\""), "{err}");
    }

    #[test]
    fn empty_and_too_small_are_errors() {
        let empty = Curve::default();
        for curves in [&[][..], &[empty.clone(), empty][..]] {
            let err = line_plot(&log_plot(), curves, &[]).unwrap_err();
            assert!(
                matches!(err, RenderError::Empty { argument: "curves" }),
                "{err}"
            );
        }
        let small = LinePlot {
            width: crate::MIN_PLOT_SIZE - 1,
            ..log_plot()
        };
        let err = line_plot(&small, &[decay("a", 10, 1.0)], &[]).unwrap_err();
        assert!(matches!(err, RenderError::Size { .. }), "{err}");
        // The smallest allowed size works, with texts and markers.
        let smallest = LinePlot {
            width: crate::MIN_PLOT_SIZE,
            height: crate::MIN_PLOT_SIZE,
            ..log_plot()
        };
        let marker = Marker {
            x: 3.0,
            label: "best".into(),
            dashed: false,
        };
        line_plot(&smallest, &[decay("a", 10, 1.0)], &[marker]).unwrap();
    }

    #[test]
    fn single_point_curve_is_a_dot() {
        let curve = Curve {
            name: "only".into(),
            points: vec![[5.0, 42.0]],
        };
        for log_y in [true, false] {
            let plot = LinePlot {
                log_y,
                ..log_plot()
            };
            let (image, frame) = render(&plot, std::slice::from_ref(&curve), &[]).unwrap();
            // The dot is in the middle of the frame (zero extents are padded symmetrically).
            let cx = ((frame.x.start + frame.x.end) / 2) as u32;
            let cy = ((frame.y.start + frame.y.end) / 2) as u32;
            let dot = (cy - 3..=cy + 3)
                .flat_map(|y| (cx - 3..=cx + 3).map(move |x| (x, y)))
                .filter(|&(x, y)| image.pixel(x, y) == Some(SERIES_COLORS[0]))
                .count();
            assert!(dot >= 9, "log_y {log_y}: {dot} dot pixels");
        }
        // A single point with a marker elsewhere: the x range spans both.
        let marker = Marker {
            x: 10.0,
            label: String::new(),
            dashed: true,
        };
        line_plot(&log_plot(), &[curve], &[marker]).unwrap();
    }

    #[test]
    fn extreme_inputs_render_without_panics() {
        let curve = |points: Vec<[f64; 2]>| Curve {
            name: "a curve with a rather long name for a small legend".into(),
            points,
        };
        let many_markers: Vec<Marker> = (0..40)
            .map(|i| Marker {
                x: f64::from(i),
                label: format!("marker number {i}"),
                dashed: i % 2 == 0,
            })
            .collect();
        let cases = [
            curve(vec![[0.0, 1e-300], [1.0, 1e300]]),
            curve(vec![[1e15, 1.0], [1e15 + 4.0, 2.0]]),
            curve(vec![[-1e300, -1e300], [1e300, 1e300]]),
            curve(vec![[0.0, -0.00201], [1.0, -0.00199]]),
            curve(
                (0..500)
                    .map(|i| [f64::from(i), f64::from(i % 7) + 1.0])
                    .collect(),
            ),
        ];
        for (width, height) in [(120, 120), (120, 900), (1600, 120), (1000, 600)] {
            for log_y in [false, true] {
                let plot = LinePlot {
                    title: "a long title that does not fit into a small plot at all",
                    x_label: "x axis description",
                    y_label: "y axis description",
                    log_y,
                    width,
                    height,
                };
                for (ci, c) in cases.iter().enumerate() {
                    let result = line_plot(&plot, std::slice::from_ref(c), &many_markers);
                    // Only the negative data on a log axis is refused.
                    if log_y && (ci == 2 || ci == 3) {
                        let err = result.unwrap_err().to_string();
                        assert!(err.contains("point 0 (") && err.contains("y <= 0"), "{err}");
                    } else {
                        let image = result.unwrap_or_else(|e| {
                            panic!("{width}x{height} log {log_y} case {ci}: {e}")
                        });
                        assert_eq!((image.width, image.height), (width, height));
                    }
                }
            }
        }
    }

    #[test]
    fn many_points_are_fine() {
        let curves = [
            decay("train", 20_000, 300.0),
            decay("validation", 20_000, 320.0),
        ];
        let plot = LinePlot {
            width: 900,
            height: 500,
            ..log_plot()
        };
        let image = line_plot(&plot, &curves, &[]).unwrap();
        assert!(count(&image, SERIES_COLORS[0], 40) > 200);
    }

    #[test]
    fn crowded_marker_labels_stack_and_solid_ones_win() {
        let m = |dashed| Marker {
            x: 0.0,
            label: "x".into(),
            dashed,
        };
        let markers = [m(true), m(true), m(false), m(true), m(true)];
        // Four labels at the same place, one far right; two rows only.
        let spans = [
            (10.0, 50.0),
            (12.0, 52.0),
            (11.0, 51.0),
            (300.0, 340.0),
            (14.0, 54.0),
        ];
        let rows = label_rows(&markers, &spans, 4.0, 2);
        assert_eq!(rows[2], Some(0), "the solid marker's label goes first");
        assert_eq!(rows[3], Some(0), "a label far away shares the row");
        assert_eq!(rows[0], Some(1));
        assert_eq!((rows[1], rows[4]), (None, None), "no room left");
        let mut unlabelled = markers.to_vec();
        unlabelled[2].label.clear();
        assert_eq!(label_rows(&unlabelled, &spans, 4.0, 2)[2], None);
    }

    #[test]
    fn tick_labels_are_short() {
        let cases = [
            (0.0, "0"),
            (-0.0, "0"),
            (500.0, "500"),
            (0.30000000000000004, "0.3"),
            (1234.5, "1234.5"),
            (0.00125, "0.00125"),
            (2.5e6, "2.5e6"),
            (1e-4, "1e-4"),
            (-3e-7, "-3e-7"),
            (20000.0, "20000"),
        ];
        for (v, s) in cases {
            assert_eq!(tick_label(v), s, "{v}");
        }
    }

    #[test]
    fn log_ticks_are_round_and_spaced() {
        // Three decades with room: 1-2-3-5 × 10^k.
        let (bold, light) = log_ticks(&(1.0..1000.0), 0.15);
        assert_eq!(bold.first(), Some(&1.0));
        assert!(bold.contains(&30.0) && bold.contains(&1000.0), "{bold:?}");
        assert!(light.contains(&70.0));
        // Crowded: only powers of ten, then every other one.
        let (bold, _) = log_ticks(&(1.0..1000.0), 0.9);
        assert_eq!(bold, vec![1.0, 10.0, 100.0, 1000.0]);
        let (bold, _) = log_ticks(&(1e-8..1e8), 1.5);
        assert!(
            bold.iter().all(|v| v.log10().round() as i32 % 2 == 0),
            "{bold:?}"
        );
        // Within a decade: round linear steps.
        let (bold, _) = log_ticks(&(280.0..1400.0), 0.06);
        assert!(bold.len() >= 4, "{bold:?}");
        assert!(
            bold.iter()
                .all(|v| *v >= 280.0 && *v <= 1400.0 && v % 100.0 == 0.0)
        );
    }
}
