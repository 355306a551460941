//! The frame every chart shares: title, axes with ticks, grid, axis labels and the legend.

use std::ops::Range;

use plotters::chart::SeriesLabelPosition;
use plotters::coord::Shift;
use plotters::prelude::{
    BitMapBackend, Cartesian2d, ChartBuilder, ChartContext, Color, DrawingArea, WHITE,
};

use crate::PlotError;
use crate::axis::Axis;
use crate::error::draw_error;
use crate::style::{GRID, INK, MINOR_GRID, Metrics};

/// The coordinates of a chart: plot space (see [`Axis`]) on both axes, with our own ticks.
pub(crate) type Coord = Cartesian2d<Axis, Axis>;

/// A chart drawn into a bitmap.
pub(crate) type Chart<'a, 'b> = ChartContext<'a, BitMapBackend<'b>, Coord>;

/// Where a chart's legend goes: a corner inside the plot area, or nowhere.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Legend {
    /// Upper right corner of the plot area.
    #[default]
    UpperRight,
    /// Upper left corner of the plot area.
    UpperLeft,
    /// Lower left corner of the plot area.
    LowerLeft,
    /// Lower right corner of the plot area.
    LowerRight,
    /// No legend.
    Hidden,
}

/// What a drawn chart occupies: the plot area in pixels and its axes, so that data can be
/// located in the image.
#[derive(Debug, Clone)]
#[cfg_attr(
    not(test),
    allow(dead_code, reason = "read by the tests that locate data in images")
)]
pub(crate) struct Frame {
    /// Pixel columns and rows of the plot area (inside the axes).
    pub area: (Range<i32>, Range<i32>),
    pub x: Axis,
    pub y: Axis,
}

impl Frame {
    /// The image pixel of the plot-space point (`x`, `y`), as the chart maps it.
    #[cfg(test)]
    pub fn pixel(&self, x: f64, y: f64) -> (u32, u32) {
        use crate::axis::pixel_of;
        // The pixel ranges that plotters gives the coordinates of the plot area.
        let (cols, rows) = &self.area;
        let px = pixel_of(self.x.lo, self.x.hi, x, (cols.start, cols.end - 1));
        let py = pixel_of(self.y.lo, self.y.hi, y, (rows.end - 1, rows.start));
        let s = crate::style::SUPERSAMPLE as i32;
        ((px / s) as u32, (py / s) as u32)
    }

    /// The plot area in image pixels: columns `x0..x1`, rows `y0..y1`.
    #[cfg(test)]
    pub fn image_area(&self) -> (std::ops::Range<u32>, std::ops::Range<u32>) {
        let s = crate::style::SUPERSAMPLE as i32;
        let (cols, rows) = &self.area;
        (
            (cols.start / s) as u32..(cols.end / s) as u32,
            (rows.start / s) as u32..(rows.end / s) as u32,
        )
    }
}

/// The texts around a chart.
pub(crate) struct Labels<'t> {
    pub title: &'t str,
    pub x: &'t str,
    pub y: &'t str,
}

/// Draws the frame of a chart on `area` and returns the chart to draw series into.
///
/// The axes are made once the space left for the plot area is known, so that the number of
/// ticks follows the pixels available: `x_axis` and `y_axis` receive a target tick count, and
/// `y_axis` also the height of the plot area in drawing pixels.
/// `x_grid` says whether vertical grid lines are drawn at the x ticks.
pub(crate) fn draw_frame<'a, 'b>(
    area: &'a DrawingArea<BitMapBackend<'b>, Shift>,
    metrics: &Metrics,
    labels: &Labels<'_>,
    x_axis: impl FnOnce(usize) -> Axis,
    y_axis: impl FnOnce(usize, u32) -> Axis,
    x_grid: bool,
) -> Result<(Chart<'a, 'b>, Frame), PlotError> {
    let err = draw_error(labels.title);
    let (width, height) = area.dim_in_pixel();
    let margin = metrics.margin();
    let tick_font = metrics.tick_font();
    let axis_font = metrics.axis_label_font();
    let title_font = metrics.title_font();
    let text_height = |font: &plotters::style::TextStyle<'_>| -> Result<u32, PlotError> {
        Ok(area.estimate_text_size("Ag", font).map_err(&err)?.1)
    };
    let gap = metrics.px(6.0);
    let tick = metrics.tick_length() as u32;
    let title_height = if labels.title.is_empty() {
        0
    } else {
        text_height(&title_font)? + gap * 2
    };
    let x_label_area = text_height(&tick_font)?
        + tick
        + gap * 2
        + if labels.x.is_empty() {
            0
        } else {
            text_height(&axis_font)? + gap
        };
    let plot_height = height
        .saturating_sub(title_height + x_label_area + 2 * margin)
        .max(1);
    let y = y_axis(
        ticks_for(plot_height, metrics.y_tick_spacing()),
        plot_height,
    );
    let mut widest_y_label = 0;
    for label in &y.labels {
        widest_y_label =
            widest_y_label.max(area.estimate_text_size(label, &tick_font).map_err(&err)?.0);
    }
    let y_label_area = widest_y_label
        + tick
        + gap * 2
        + if labels.y.is_empty() {
            0
        } else {
            text_height(&axis_font)? + gap
        };
    let plot_width = width.saturating_sub(y_label_area + 3 * margin).max(1);
    let x = x_axis(ticks_for(plot_width, metrics.x_tick_spacing()));
    // The last x tick label is centred on its tick and may stick out past the plot area.
    let last_x_label = match x.labels.last() {
        Some(label) => area.estimate_text_size(label, &tick_font).map_err(&err)?.0,
        None => 0,
    };
    let right_margin = margin.max(last_x_label / 2 + gap);

    let mut builder = ChartBuilder::on(area);
    builder
        .margin(margin)
        .margin_right(right_margin)
        .x_label_area_size(x_label_area)
        .y_label_area_size(y_label_area);
    if !labels.title.is_empty() {
        builder.caption(labels.title, title_font);
    }
    let mut chart = builder
        .build_cartesian_2d(x.clone(), y.clone())
        .map_err(&err)?;

    let format_x = |v: &f64| x.label_at(*v);
    let format_y = |v: &f64| y.label_at(*v);
    let mut mesh = chart.configure_mesh();
    mesh.x_label_formatter(&format_x)
        .y_label_formatter(&format_y)
        .label_style(tick_font.clone())
        .axis_desc_style(axis_font)
        .bold_line_style(GRID.stroke_width(1))
        .light_line_style(MINOR_GRID.stroke_width(1))
        .axis_style(INK.stroke_width(1))
        .set_all_tick_mark_size(metrics.tick_length());
    if !labels.x.is_empty() {
        mesh.x_desc(labels.x);
    }
    if !labels.y.is_empty() {
        mesh.y_desc(labels.y);
    }
    if !x_grid {
        mesh.disable_x_mesh();
    }
    mesh.draw().map_err(&err)?;

    let frame = Frame {
        area: chart.plotting_area().get_pixel_range(),
        x,
        y,
    };
    Ok((chart, frame))
}

/// Draws the legend of the labelled series of `chart` at `position`.
pub(crate) fn draw_legend<'a, 'b: 'a>(
    chart: &mut Chart<'a, 'b>,
    metrics: &Metrics,
    position: Legend,
    title: &str,
) -> Result<(), PlotError> {
    let position = match position {
        Legend::UpperRight => SeriesLabelPosition::UpperRight,
        Legend::UpperLeft => SeriesLabelPosition::UpperLeft,
        Legend::LowerLeft => SeriesLabelPosition::LowerLeft,
        Legend::LowerRight => SeriesLabelPosition::LowerRight,
        Legend::Hidden => return Ok(()),
    };
    chart
        .configure_series_labels()
        .position(position)
        .margin(metrics.legend_margin())
        .legend_area_size(metrics.legend_key_width())
        .label_font(metrics.legend_font())
        .background_style(WHITE.mix(0.9))
        .border_style(INK.mix(0.5).stroke_width(1))
        .draw()
        .map_err(draw_error(title))
}

/// How many ticks fit along `pixels` with about `spacing` pixels between them (2 to 10).
fn ticks_for(pixels: u32, spacing: f64) -> usize {
    ((f64::from(pixels) / spacing).round() as usize).clamp(2, 10)
}
