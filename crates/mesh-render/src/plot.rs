//! Scatter plots with plotters (embedded font, in-memory bitmap): latent embeddings, PCA, t-SNE.

use crate::chart_backend::ChartBackend;
use crate::colormap::{VIRIDIS_STOPS, sample};
use crate::error::RenderError;
use crate::image::{Image, check_size};
use crate::text::{FAMILY, draw_error, ensure_font};
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

/// One set of 2-D points of a [`scatter`] plot.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Series {
    /// Shown in the legend (no legend when every name is empty).
    pub name: String,
    pub points: Vec<[f32; 2]>,
    /// Join consecutive points with line segments (e.g. an interpolation path).
    pub joined: bool,
    /// Colour points (and segments) by their index along viridis (first dark violet, last
    /// yellow) instead of one colour per series.
    pub color_by_order: bool,
}

/// Colours of successive series (a ten-colour categorical palette).
pub const SERIES_COLORS: [[u8; 3]; 10] = [
    [31, 119, 180],
    [255, 127, 14],
    [44, 160, 44],
    [214, 39, 40],
    [148, 103, 189],
    [140, 86, 75],
    [227, 119, 194],
    [127, 127, 127],
    [188, 189, 34],
    [23, 190, 207],
];

/// Axis lines, tick labels and axis descriptions of every plot.
pub(crate) const AXIS_COLOR: RGBColor = RGBColor(60, 60, 66);
/// Grid lines at labelled ticks, and the lighter ones between them.
pub(crate) const GRID_BOLD: RGBColor = RGBColor(222, 224, 228);
pub(crate) const GRID_LIGHT: RGBColor = RGBColor(242, 243, 245);

/// Smallest plot accepted: below this the axes and labels do not fit.
pub const MIN_PLOT_SIZE: u32 = 120;

/// A scatter plot on white: title, axis descriptions, a light grid, the series' points (joined
/// in order if asked), and a legend when series are named, in a band above the data (the y
/// range grows to make room for it) so that it hides no point. Errors: no points at all, a
/// non-finite coordinate, a size below [`MIN_PLOT_SIZE`] or too large.
pub fn scatter(
    title: &str,
    x_label: &str,
    y_label: &str,
    series: &[Series],
    width: u32,
    height: u32,
) -> Result<Image, RenderError> {
    check_plot_size(width, height)?;
    if series.iter().all(|s| s.points.is_empty()) {
        return Err(RenderError::Empty { argument: "series" });
    }
    for s in series {
        if let Some((i, p)) = s
            .points
            .iter()
            .enumerate()
            .find(|(_, p)| !p.iter().all(|c| c.is_finite()))
        {
            return Err(RenderError::invalid(
                "series",
                format!(
                    "series {:?}: point {i} ({}, {}) is not finite",
                    s.name, p[0], p[1]
                ),
            ));
        }
    }
    ensure_font()?;
    let (x_range, mut y_range) = ranges(series);
    let named = series.iter().filter(|s| !s.name.is_empty()).count();
    if named > 0 {
        // A band above the data for the legend, so that it covers no point.
        let legend_px = named as f64 * 1.6 * tick_size(width, height) + 14.0;
        let plot_px = 0.75 * f64::from(height);
        let share = (legend_px / plot_px).min(0.5);
        y_range.end += (y_range.end - y_range.start) * share / (1.0 - share);
    }
    let mut rgb = vec![255u8; 3 * width as usize * height as usize];
    draw(
        &mut rgb,
        (width, height),
        (title, x_label, y_label),
        series,
        (x_range, y_range),
    )
    .map_err(|e| draw_error("scatter plot", e))?;
    Ok(Image { width, height, rgb })
}

/// The size checks of every plot: [`check_size`], and at least [`MIN_PLOT_SIZE`] per side.
pub(crate) fn check_plot_size(width: u32, height: u32) -> Result<(), RenderError> {
    check_size("width/height", width, height)?;
    if width < MIN_PLOT_SIZE || height < MIN_PLOT_SIZE {
        return Err(RenderError::Size {
            argument: "width/height",
            width: width.into(),
            height: height.into(),
            message: format!("plots need at least {MIN_PLOT_SIZE} pixels per side"),
        });
    }
    Ok(())
}

pub(crate) type Range = std::ops::Range<f64>;

/// The data ranges with 6% padding; a zero extent becomes ±0.5 (or ±10%) around the value.
fn ranges(series: &[Series]) -> (Range, Range) {
    let mut lo = [f64::MAX; 2];
    let mut hi = [f64::MIN; 2];
    for p in series.iter().flat_map(|s| &s.points) {
        for k in 0..2 {
            lo[k] = lo[k].min(f64::from(p[k]));
            hi[k] = hi[k].max(f64::from(p[k]));
        }
    }
    (padded(lo[0], hi[0], 0.06), padded(lo[1], hi[1], 0.06))
}

/// `lo..hi` widened by `fraction` of the extent on each side; a zero extent becomes ±0.5 (or
/// ±10%) around the value.
pub(crate) fn padded(lo: f64, hi: f64, fraction: f64) -> Range {
    let extent = hi - lo;
    if extent > 0.0 {
        lo - fraction * extent..hi + fraction * extent
    } else {
        let half = (0.1 * lo.abs()).max(0.5);
        lo - half..hi + half
    }
}

/// Height of the band under a plot area for the x tick labels (`tick_px` high) and, when there
/// is one, the x axis description (`desc_px` high).
pub(crate) fn x_label_area(tick_px: f64, desc_px: f64, described: bool) -> f64 {
    tick_px + 10.0 + if described { desc_px * 1.6 } else { 0.0 }
}

pub(crate) fn rgb(c: [u8; 3]) -> RGBColor {
    RGBColor(c[0], c[1], c[2])
}

fn darker(c: [u8; 3]) -> RGBColor {
    let [r, g, b] = c.map(|v| (f32::from(v) * 0.6) as u8);
    RGBColor(r, g, b)
}

fn order_color(i: usize, n: usize) -> [u8; 3] {
    sample(&VIRIDIS_STOPS, i as f32 / (n.max(2) - 1) as f32)
}

type DrawResult = Result<(), Box<dyn std::error::Error>>;

/// Tick-label font size of a plot of this size.
fn tick_size(width: u32, height: u32) -> f64 {
    (f64::from(height.min(width * 3 / 2)) / 38.0).clamp(10.0, 16.0)
}

fn draw(
    buf: &mut [u8],
    (width, height): (u32, u32),
    (title, x_label, y_label): (&str, &str, &str),
    series: &[Series],
    (x_range, y_range): (Range, Range),
) -> DrawResult {
    let h = f64::from(height.min(width * 3 / 2));
    let title_px = (h / 20.0).clamp(13.0, 26.0);
    let desc_px = (h / 30.0).clamp(11.0, 19.0);
    let tick_px = tick_size(width, height);
    let radius = (f64::from(width.min(height)) / 150.0)
        .clamp(2.5, 6.0)
        .round() as i32;
    let root = ChartBackend::with_buffer(buf, (width, height)).into_drawing_area();
    root.fill(&WHITE)?;
    // The title at the top margin and a gap below it (as in the line plot): its box (ascent to
    // descent) already has room above the capitals, which plotters' caption would pad again.
    let margin = (h / 40.0).max(6.0) as u32;
    let title_style =
        TextStyle::from((FAMILY, title_px).into_font()).pos(Pos::new(HPos::Center, VPos::Top));
    let th = root.estimate_text_size(title, &title_style)?.1;
    root.draw_text(title, &title_style, (width as i32 / 2, margin as i32))?;
    let mut chart = ChartBuilder::on(&root)
        .margin(margin)
        .margin_top(margin + th + (th / 2).min(5))
        .x_label_area_size((tick_px + desc_px * 2.2) as u32)
        .y_label_area_size((tick_px * 4.0 + desc_px * 1.8) as u32)
        .build_cartesian_2d(x_range, y_range)?;
    let axis = AXIS_COLOR;
    chart
        .configure_mesh()
        .x_desc(x_label)
        .y_desc(y_label)
        .label_style((FAMILY, tick_px).into_font().color(&axis))
        .axis_desc_style((FAMILY, desc_px).into_font().color(&axis))
        .axis_style(axis)
        .bold_line_style(GRID_BOLD)
        .light_line_style(GRID_LIGHT)
        .x_labels(6)
        .y_labels(6)
        .draw()?;
    let mut legend = false;
    for (si, s) in series.iter().enumerate() {
        let base = SERIES_COLORS[si % SERIES_COLORS.len()];
        let n = s.points.len();
        let color_of = |i: usize| {
            if s.color_by_order {
                order_color(i, n)
            } else {
                base
            }
        };
        let xy = |p: &[f32; 2]| (f64::from(p[0]), f64::from(p[1]));
        if s.joined && n > 1 {
            let stroke = (radius / 3).max(1) as u32;
            chart.draw_series(s.points.windows(2).enumerate().map(|(i, w)| {
                let c = color_of(i);
                PathElement::new(vec![xy(&w[0]), xy(&w[1])], rgb(c).stroke_width(stroke))
            }))?;
        }
        let points = s.points.iter().enumerate().map(|(i, p)| {
            let c = color_of(i);
            EmptyElement::at(xy(p))
                + Circle::new((0, 0), radius, rgb(c).filled())
                + Circle::new((0, 0), radius, darker(c).stroke_width(1))
        });
        let annotation = chart.draw_series(points)?;
        if !s.name.is_empty() {
            legend = true;
            let c = if s.color_by_order {
                order_color(1, 3)
            } else {
                base
            };
            annotation
                .label(s.name.as_str())
                .legend(move |(x, y)| Circle::new((x + 6, y), radius.max(4), rgb(c).filled()));
        }
    }
    if legend {
        chart
            .configure_series_labels()
            .label_font((FAMILY, tick_px).into_font().color(&axis))
            .background_style(WHITE.mix(0.88))
            .border_style(RGBColor(200, 200, 205))
            .position(SeriesLabelPosition::UpperRight)
            .draw()?;
    }
    root.present()?;
    Ok(())
}
