//! The frame every chart shares: title, axes with ticks, grid, axis labels and the legend.

use std::ops::Range;

use plotters::coord::Shift;
use plotters::prelude::{
    Cartesian2d, ChartBuilder, ChartContext, Color, DrawingArea, PathElement, RGBColor, Rectangle,
    Text, WHITE,
};
use plotters::style::text_anchor::{HPos, Pos, VPos};

use crate::PlotError;
use crate::axis::Axis;
use crate::canvas::Canvas;
use crate::error::draw_error;
use crate::style::{BAND_OPACITY, GRID, INK, MINOR_GRID, Metrics};
use crate::text;

/// The coordinates of a chart: plot space (see [`Axis`]) on both axes, with our own ticks.
pub(crate) type Coord = Cartesian2d<Axis, Axis>;

/// A drawing area of a [`Canvas`] in pixel coordinates: a whole image or a panel of a figure.
pub(crate) type Area<'b> = DrawingArea<Canvas<'b>, Shift>;

/// A chart drawn onto a [`Canvas`].
pub(crate) type Chart<'a, 'b> = ChartContext<'a, Canvas<'b>, Coord>;

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
    pub(crate) fn image_area(&self) -> (std::ops::Range<u32>, std::ops::Range<u32>) {
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
    area: &'a Area<'b>,
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
        .axis_style(INK.stroke_width(metrics.px(1.0)))
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

/// What stands beside a label in the legend.
#[derive(Debug, Clone, Copy)]
pub(crate) enum LegendKey {
    /// A short line of the series' colour and width, over a band swatch if `band`.
    Line {
        color: RGBColor,
        width: u32,
        band: bool,
    },
    /// A filled square (bar charts).
    Swatch(RGBColor),
}

/// One line of a legend.
#[derive(Debug, Clone)]
pub(crate) struct LegendEntry<'l> {
    pub label: &'l str,
    pub key: LegendKey,
}

/// The height of the legend box of `entries` lines plus its distance from the frame, in
/// drawing pixels.
pub(crate) fn legend_height(metrics: &Metrics, entries: usize) -> u32 {
    let line = metrics.legend_line_height();
    2 * metrics.legend_margin() + entries as u32 * line + metrics.legend_inset()
}

/// Draws a legend of `entries` in a corner of the plot area of `chart`: a white box with a
/// grey border, one line per entry with its key and label.
pub(crate) fn draw_legend(
    chart: &Chart<'_, '_>,
    metrics: &Metrics,
    position: Legend,
    entries: &[LegendEntry<'_>],
    title: &str,
) -> Result<(), PlotError> {
    if position == Legend::Hidden || entries.is_empty() {
        return Ok(());
    }
    let err = draw_error(title);
    let font = text::face()?;
    let size = metrics.legend_font_size();
    let widest = entries
        .iter()
        .map(|e| text::extent(font, e.label, size).0.ceil() as i32)
        .max()
        .unwrap_or(0);
    let pad = metrics.legend_margin() as i32;
    let line = metrics.legend_line_height() as i32;
    let key_width = metrics.legend_key_width() as i32;
    let gap = metrics.px(8.0) as i32;
    let width = pad + key_width + gap + widest + pad;
    let height = 2 * pad + entries.len() as i32 * line;

    let area = chart.plotting_area().strip_coord_spec();
    let (area_width, area_height) = area.dim_in_pixel();
    let (area_width, area_height) = (area_width as i32, area_height as i32);
    let inset = metrics.legend_inset() as i32;
    let (left, right_edge) = (inset, area_width - inset - width);
    let (top, bottom_edge) = (inset, area_height - inset - height);
    let (x0, y0) = match position {
        Legend::UpperRight => (right_edge, top),
        Legend::UpperLeft => (left, top),
        Legend::LowerLeft => (left, bottom_edge),
        Legend::LowerRight => (right_edge, bottom_edge),
        Legend::Hidden => unreachable!("returned above"),
    };
    let corners = [(x0, y0), (x0 + width, y0 + height)];
    area.draw(&Rectangle::new(corners, WHITE.mix(0.9).filled()))
        .map_err(&err)?;
    area.draw(&Rectangle::new(
        corners,
        INK.mix(0.5).stroke_width(metrics.px(1.0)),
    ))
    .map_err(&err)?;
    let label_style = metrics
        .legend_font()
        .pos(Pos::new(HPos::Left, VPos::Center));
    let half_key = metrics.px(6.0) as i32;
    for (i, entry) in entries.iter().enumerate() {
        let x = x0 + pad;
        let y = y0 + pad + i as i32 * line + line / 2;
        match entry.key {
            LegendKey::Line { color, width, band } => {
                if band {
                    area.draw(&Rectangle::new(
                        [(x, y - half_key), (x + key_width, y + half_key)],
                        color.mix(BAND_OPACITY).filled(),
                    ))
                    .map_err(&err)?;
                }
                area.draw(&PathElement::new(
                    vec![(x, y), (x + key_width, y)],
                    color.stroke_width(width),
                ))
                .map_err(&err)?;
            }
            LegendKey::Swatch(color) => {
                let centre = x + key_width / 2;
                area.draw(&Rectangle::new(
                    [
                        (centre - half_key, y - half_key),
                        (centre + half_key, y + half_key),
                    ],
                    color.filled(),
                ))
                .map_err(&err)?;
            }
        }
        area.draw(&Text::new(
            entry.label,
            (x + key_width + gap, y),
            label_style.clone(),
        ))
        .map_err(&err)?;
    }
    Ok(())
}

/// How many ticks fit along `pixels` with about `spacing` pixels between them (2 to 10).
fn ticks_for(pixels: u32, spacing: f64) -> usize {
    ((f64::from(pixels) / spacing).round() as usize).clamp(2, 10)
}
