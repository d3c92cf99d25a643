//! Dot plots with plotters (embedded font, in-memory bitmap): one labelled row per category (a
//! network), a dot per value (a seed) in the value's colour, a tick at the row's mean, and
//! labelled vertical reference lines (a published figure). For results that are a few numbers
//! per category, where a table hides how far apart the seeds are.

use crate::axis::{Axis, linear_ticks, tick_label};
use crate::chart_backend::ChartBackend;
use crate::error::RenderError;
use crate::image::Image;
use crate::lines::Marker;
use crate::plot::{
    AXIS_COLOR, GRID_BOLD, GRID_LIGHT, Range, SERIES_COLORS, check_plot_size, padded, rgb,
    x_label_area,
};
use crate::text::{FAMILY, draw_error, ensure_font};
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

/// One row of a [`dot_plot`]: its label and its values, `values[i]` drawn in
/// [`SERIES_COLORS`]`[i]` (`None`: no value for that index, e.g. a seed not run).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct DotRow {
    pub label: String,
    pub values: Vec<Option<f64>>,
}

/// Title, x description, legend names of the value indices, and size of a [`dot_plot`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DotPlot<'a> {
    pub title: &'a str,
    pub x_label: &'a str,
    /// The legend's name of each value index ("seed 1", …); no legend when empty.
    pub value_names: &'a [&'a str],
    pub width: u32,
    pub height: u32,
}

/// Colour of the reference lines and their labels.
const REFERENCE: [u8; 3] = [90, 90, 100];
/// Colour of a row's mean tick.
const MEAN: [u8; 3] = [40, 40, 46];

/// A dot plot on white: the title; a legend row naming the value indices; one row per
/// [`DotRow`], top to bottom, its label left of the plot area; a dot per value, the values of a
/// row spread a little vertically so that equal ones stay visible; a dark tick at each row's
/// mean; dashed vertical [`Marker`] lines (the `dashed` flag is ignored) with their labels above
/// the plot area. The x axis spans the values and markers with a little padding.
///
/// Errors ([`RenderError`], never a panic): no value in any row, a non-finite value (naming the
/// row and the index) or marker, a size below [`MIN_PLOT_SIZE`](crate::MIN_PLOT_SIZE) or too
/// large.
///
/// ```
/// use mesh_render::{DotPlot, DotRow, Marker, dot_plot};
/// # fn main() -> Result<(), mesh_render::RenderError> {
/// let rows = [
///     DotRow { label: "ours".into(), values: vec![Some(0.021), Some(0.018), Some(0.024)] },
///     DotRow { label: "CoMA".into(), values: vec![Some(0.030), None, Some(0.027)] },
/// ];
/// let plot = DotPlot {
///     title: "horse-gallop",
///     x_label: "mean distance",
///     value_names: &["seed 1", "seed 2", "seed 3"],
///     width: 640,
///     height: 240,
/// };
/// let paper = Marker { x: 0.01995, label: "paper".into(), dashed: true };
/// let image = dot_plot(&plot, &rows, &[paper])?;
/// assert_eq!((image.width, image.height), (640, 240));
///
/// let bad = [DotRow { label: "x".into(), values: vec![Some(f64::NAN)] }];
/// let err = dot_plot(&plot, &bad, &[]).unwrap_err();
/// assert!(err.to_string().contains("row \"x\": value 0"), "{err}");
/// # Ok(()) }
/// ```
pub fn dot_plot(plot: &DotPlot, rows: &[DotRow], markers: &[Marker]) -> Result<Image, RenderError> {
    check_plot_size(plot.width, plot.height)?;
    let values = || rows.iter().flat_map(|r| r.values.iter().flatten());
    if values().next().is_none() {
        return Err(RenderError::Empty { argument: "rows" });
    }
    for r in rows {
        if let Some((i, v)) = (r.values.iter().enumerate())
            .find_map(|(i, v)| v.filter(|v| !v.is_finite()).map(|v| (i, v)))
        {
            return Err(RenderError::invalid(
                "rows",
                format!("row {:?}: value {i} ({v}) is not finite", r.label),
            ));
        }
    }
    if let Some((i, m)) = markers.iter().enumerate().find(|(_, m)| !m.x.is_finite()) {
        return Err(RenderError::invalid(
            "markers",
            format!("marker {i} ({:?}): x = {} is not finite", m.label, m.x),
        ));
    }
    let (lo, hi) = (values().copied())
        .chain(markers.iter().map(|m| m.x))
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
            (lo.min(v), hi.max(v))
        });
    let x_range = padded(lo, hi, 0.06);
    if !(x_range.start.is_finite() && x_range.end.is_finite() && x_range.end > x_range.start) {
        return Err(RenderError::invalid(
            "rows",
            format!("the data range {x_range:?} is too large or too small to plot"),
        ));
    }
    ensure_font()?;
    let mut rgb = vec![255u8; 3 * plot.width as usize * plot.height as usize];
    draw(&mut rgb, plot, rows, markers, x_range).map_err(|e| draw_error("dot plot", e))?;
    Ok(Image {
        width: plot.width,
        height: plot.height,
        rgb,
    })
}

type DrawResult<T> = Result<T, Box<dyn std::error::Error>>;

fn draw(
    buf: &mut [u8],
    plot: &DotPlot,
    rows: &[DotRow],
    markers: &[Marker],
    x_range: Range,
) -> DrawResult<()> {
    let (width, height) = (f64::from(plot.width), f64::from(plot.height));
    let h = height.min(width * 1.5);
    let title_px = (h / 20.0).clamp(13.0, 22.0);
    let desc_px = (h / 30.0).clamp(11.0, 16.0);
    let tick_px = (h / 38.0).clamp(10.0, 14.0);
    let margin = (h / 40.0).max(6.0).round() as i32;
    let root = ChartBackend::with_buffer(buf, (plot.width, plot.height)).into_drawing_area();
    root.fill(&WHITE)?;
    let tick_style = TextStyle::from((FAMILY, tick_px).into_font()).color(&AXIS_COLOR);
    let row_px = (tick_px * 1.5).ceil() as i32;

    let mut top = margin;
    if !plot.title.is_empty() {
        let style = (FAMILY, title_px)
            .into_font()
            .color(&RGBColor(30, 30, 34))
            .pos(Pos::new(HPos::Center, VPos::Top));
        root.draw_text(plot.title, &style, (plot.width as i32 / 2, top))?;
        top += root.estimate_text_size(plot.title, &style)?.1 as i32 + 4;
    }
    if !plot.value_names.is_empty() {
        legend(&root, plot, &tick_style, top, row_px)?;
        top += row_px;
    }
    let labelled = markers.iter().filter(|m| !m.label.is_empty()).count();
    top += row_px * labelled.min(3) as i32;

    let label_w = rows.iter().try_fold(0, |w, r| {
        Ok::<_, Box<dyn std::error::Error>>(
            w.max(root.estimate_text_size(&r.label, &tick_style)?.0),
        )
    })? as i32;
    let x_area = x_label_area(tick_px, desc_px, !plot.x_label.is_empty()) as i32;
    let plot_w = (plot.width as i32 - 2 * margin - label_w - 10).max(1);
    let ticks = linear_ticks(
        &x_range,
        (x_range.end - x_range.start) / f64::from((plot_w / 90).max(2)),
    );
    let n = rows.len().max(1) as f64;
    let mut chart = ChartBuilder::on(&root)
        .margin(margin)
        .margin_top(top)
        .x_label_area_size(x_area)
        .y_label_area_size(label_w + 10)
        .build_cartesian_2d(Axis::new(&x_range, false, ticks), -0.5..n - 0.5)?;
    let format = |v: &f64| tick_label(*v);
    let mut mesh = chart.configure_mesh();
    mesh.x_label_formatter(&format)
        .y_labels(0)
        .disable_y_mesh()
        .label_style(tick_style.clone())
        .axis_desc_style((FAMILY, desc_px).into_font().color(&AXIS_COLOR))
        .axis_style(AXIS_COLOR)
        .bold_line_style(GRID_BOLD)
        .light_line_style(GRID_LIGHT);
    if !plot.x_label.is_empty() {
        mesh.x_desc(plot.x_label);
    }
    mesh.draw()?;
    let (frame_x, frame_y) = chart.plotting_area().get_pixel_range();

    // Row i sits at y = n − 1 − i, so the first row is at the top.
    let y_of = |i: usize| n - 1.0 - i as f64;
    let label_style = tick_style.pos(Pos::new(HPos::Right, VPos::Center));
    for (i, r) in rows.iter().enumerate() {
        let (_, y) = chart.backend_coord(&(x_range.start, y_of(i)));
        let line = vec![(x_range.start, y_of(i)), (x_range.end, y_of(i))];
        chart.draw_series(std::iter::once(PathElement::new(line, GRID_LIGHT)))?;
        root.draw_text(&r.label, &label_style, (frame_x.start - 6, y))?;
    }
    for m in markers {
        let line = vec![(m.x, -0.5), (m.x, n - 0.5)];
        chart.draw_series(DashedLineSeries::new(
            line,
            6,
            4,
            rgb(REFERENCE).stroke_width(1),
        ))?;
    }
    let radius = (h / 90.0).clamp(3.0, 5.0).round() as i32;
    for (i, r) in rows.iter().enumerate() {
        let present: Vec<f64> = r.values.iter().flatten().copied().collect();
        if present.is_empty() {
            continue;
        }
        let mean = present.iter().sum::<f64>() / present.len() as f64;
        let tick = vec![(mean, y_of(i) - 0.32), (mean, y_of(i) + 0.32)];
        chart.draw_series(std::iter::once(PathElement::new(
            tick,
            rgb(MEAN).stroke_width(2),
        )))?;
        let k = r.values.len() as f64;
        for (j, v) in r.values.iter().enumerate() {
            let Some(v) = v else { continue };
            // Spread over ±0.2 of a row, so that equal values do not hide each other.
            let dy = if k > 1.0 {
                0.4 * (j as f64 / (k - 1.0) - 0.5)
            } else {
                0.0
            };
            let color = rgb(SERIES_COLORS[j % SERIES_COLORS.len()]);
            chart.draw_series(std::iter::once(Circle::new(
                (*v, y_of(i) - dy),
                radius,
                color.filled(),
            )))?;
        }
    }

    // Marker labels above the plot area, each in the lowest of three rows where it overlaps no
    // earlier one; labels that fit nowhere are left out.
    let ref_color = rgb(REFERENCE);
    let ref_style = tick_style.color(&ref_color);
    let mut taken: Vec<Vec<(i32, i32)>> = vec![Vec::new(); 3];
    for m in markers.iter().filter(|m| !m.label.is_empty()) {
        let (x, _) = chart.backend_coord(&(m.x, 0.0));
        let w = root.estimate_text_size(&m.label, &ref_style)?.0 as i32;
        let left = (x - w / 2).clamp(2, (plot.width as i32 - 2 - w).max(2));
        let span = (left - 4, left + w + 4);
        let Some(row) = (0..3).find(|&k| taken[k].iter().all(|&(a, b)| span.1 <= a || span.0 >= b))
        else {
            continue;
        };
        taken[row].push(span);
        let y = frame_y.start - 3 - (row as i32 + 1) * row_px + (row_px - tick_px as i32) / 2;
        root.draw_text(&m.label, &ref_style, (left, y))?;
    }
    root.present()?;
    Ok(())
}

/// "● seed 1   ● seed 2 …", centred in a row at `top`.
fn legend(
    root: &DrawingArea<ChartBackend<'_>, plotters::coord::Shift>,
    plot: &DotPlot,
    style: &TextStyle,
    top: i32,
    row_px: i32,
) -> DrawResult<()> {
    let dot = (row_px / 4).max(3);
    let gap = 3 * dot;
    let widths = (plot.value_names.iter())
        .map(|name| Ok(root.estimate_text_size(name, style)?.0 as i32))
        .collect::<DrawResult<Vec<i32>>>()?;
    let total: i32 = widths.iter().map(|w| w + 3 * dot + gap).sum::<i32>() - gap;
    let mut x = (plot.width as i32 - total) / 2;
    let y = top + row_px / 2;
    for (j, (name, w)) in plot.value_names.iter().zip(&widths).enumerate() {
        let color = rgb(SERIES_COLORS[j % SERIES_COLORS.len()]);
        root.draw(&Circle::new((x + dot, y), dot, color.filled()))?;
        let text = style.pos(Pos::new(HPos::Left, VPos::Center));
        root.draw_text(name, &text, (x + 3 * dot, y))?;
        x += w + 3 * dot + gap;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn plot<'a>() -> DotPlot<'a> {
        DotPlot {
            title: "t",
            x_label: "x",
            value_names: &["seed 1", "seed 2"],
            width: 400,
            height: 200,
        }
    }

    /// Pixels of exactly `color` in the columns `x0..x1` and rows `y0..y1`.
    fn count(image: &Image, color: [u8; 3], (x0, x1): (u32, u32), (y0, y1): (u32, u32)) -> usize {
        (y0..y1)
            .flat_map(|y| (x0..x1).map(move |x| (x, y)))
            .filter(|&(x, y)| image.pixel(x, y) == Some(color))
            .count()
    }

    #[test]
    fn each_value_is_a_dot_of_its_colour_in_its_row_and_place() {
        // The first row's value is the smallest, the second row's the largest: the first
        // colour's dot sits upper left, the second colour's lower right.
        let rows = [
            DotRow {
                label: "first".into(),
                values: vec![Some(1.0), None],
            },
            DotRow {
                label: "second".into(),
                values: vec![None, Some(2.0)],
            },
        ];
        let image = dot_plot(&plot(), &rows, &[]).unwrap();
        let (w, h) = (image.width, image.height);
        let [c0, c1] = [SERIES_COLORS[0], SERIES_COLORS[1]];
        // The legend draws both colours too, centred above the plot: look at the outer
        // quarters only.
        let (left, right) = ((0, w / 4), (3 * w / 4, w));
        assert!(count(&image, c0, left, (0, h / 2)) > 10);
        assert_eq!(count(&image, c0, left, (h / 2, h)), 0);
        assert_eq!(count(&image, c0, right, (0, h)), 0);
        assert!(count(&image, c1, right, (h / 2, h)) > 10);
        assert_eq!(count(&image, c1, right, (0, h / 2)), 0);
        assert_eq!(count(&image, c1, left, (0, h)), 0);
        // Deterministic: the same input draws the same bytes.
        assert_eq!(dot_plot(&plot(), &rows, &[]).unwrap(), image);
    }

    #[test]
    fn bad_input_is_an_error_naming_what_is_wrong() {
        let empty = [DotRow {
            label: "a".into(),
            values: vec![None],
        }];
        assert!(matches!(
            dot_plot(&plot(), &empty, &[]),
            Err(RenderError::Empty { argument: "rows" })
        ));
        let inf = [DotRow {
            label: "a".into(),
            values: vec![Some(1.0), Some(f64::INFINITY)],
        }];
        let err = dot_plot(&plot(), &inf, &[]).unwrap_err().to_string();
        assert!(
            err.contains("row \"a\": value 1 (inf) is not finite"),
            "{err}"
        );
        let ok = [DotRow {
            label: "a".into(),
            values: vec![Some(1.0)],
        }];
        let bad = Marker {
            x: f64::NAN,
            label: "paper".into(),
            dashed: true,
        };
        let err = dot_plot(&plot(), &ok, &[bad]).unwrap_err().to_string();
        assert!(err.contains("marker 0 (\"paper\")"), "{err}");
        let small = DotPlot {
            width: 50,
            ..plot()
        };
        assert!(matches!(
            dot_plot(&small, &ok, &[]),
            Err(RenderError::Size { .. })
        ));
        // One value (no spread) and a marker on it still draw.
        let marker = Marker {
            x: 1.0,
            label: "paper".into(),
            dashed: true,
        };
        assert!(dot_plot(&plot(), &ok, &[marker]).is_ok());
    }
}
