//! Where the parts of a line plot go: text sizes, the areas for the title, axis labels and
//! marker labels, the ticks, and the rows of the marker labels.

use super::{DrawResult, LinePlot, Marker};
use crate::axis::{linear_ticks, log_ticks, tick_label};
use crate::chart_backend::ChartBackend;
use crate::plot::{Range, x_label_area};
use crate::text::FAMILY;
use plotters::coord::Shift;
use plotters::prelude::*;

type Root<'b> = DrawingArea<ChartBackend<'b>, Shift>;

/// Pixel sizes of the texts and the reserved areas, derived from the image size.
pub(super) struct Layout {
    pub title_px: f64,
    pub tick_px: f64,
    pub desc_px: f64,
    pub margin: i32,
    pub margin_right: i32,
    /// Above the plot area: margin, title, marker label rows.
    pub top: i32,
    pub x_area: i32,
    pub y_area: i32,
    pub row_px: i32,
    /// Row of each marker's label (0 = just above the plot area); `None`: no label, or no room.
    pub marker_rows: Vec<Option<usize>>,
    pub x_ticks: (Vec<f64>, Vec<f64>),
    pub y_ticks: (Vec<f64>, Vec<f64>),
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

pub(super) fn layout(
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
        // The title's box (ascent to descent) has room above the capitals: a gap below only.
        th + (th / 2.0).min(5.0).floor()
    };
    let row_px = (tick_px * 1.35).ceil();
    let any_label = markers.iter().any(|m| !m.label.is_empty());
    let x_area = x_label_area(tick_px, desc_px, !plot.x_label.is_empty()).ceil();
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

#[cfg(test)]
mod tests {
    use super::*;

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
}
