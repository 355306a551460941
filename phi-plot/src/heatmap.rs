//! Heat maps: a 2D array drawn as coloured cells over labelled axes, with a colour bar
//! (thesis fig. 5.4: the share of particles per neighbour count, over time).

use std::ops::Range;
use std::path::Path;

use plotters::prelude::{Color, RGBColor, Rectangle, Text};
use plotters::style::FontTransform;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use crate::PlotError;
use crate::axis::{Axis, pixel_of};
use crate::bitmap::{Bitmap, check_size, render_with};
use crate::chart::{Area, Frame, Labels, draw_frame};
use crate::error::{draw_error, plot_name};
use crate::style::{INK, Metrics};

/// The colours of [`colormap`] at nine evenly spaced points from 0 to 1: matplotlib's viridis,
/// perceptually uniform and readable in grey and by colour-blind readers.
const VIRIDIS: [[u8; 3]; 9] = [
    [68, 1, 84],
    [72, 40, 120],
    [62, 73, 137],
    [49, 104, 142],
    [38, 130, 142],
    [31, 158, 137],
    [53, 183, 121],
    [110, 206, 88],
    [253, 231, 37],
];

/// The colour of the fraction `t` of a heat map's value range (`t` clamped to `0..=1`):
/// viridis, linearly interpolated between nine stops, dark violet at 0 and yellow at 1.
pub fn colormap(t: f64) -> [u8; 3] {
    let t = if t.is_nan() { 0.0 } else { t.clamp(0.0, 1.0) };
    let at = t * (VIRIDIS.len() - 1) as f64;
    let i = (at.floor() as usize).min(VIRIDIS.len() - 2);
    let f = at - i as f64;
    let (a, b) = (VIRIDIS[i], VIRIDIS[i + 1]);
    [0, 1, 2].map(|c| (f64::from(a[c]) + f * (f64::from(b[c]) - f64::from(a[c]))).round() as u8)
}

/// A `rows` × `columns` array of values drawn as cells coloured by [`colormap`], with a title,
/// labelled axes and a colour bar on the right that maps the colours back to values.
///
/// Column `j` spans `x_extent.0 + j·w .. x_extent.0 + (j + 1)·w` with
/// `w = (x_extent.1 − x_extent.0) / columns`, and row `i` likewise along y, row 0 at the bottom.
/// The colour scale runs from the smallest to the largest finite value unless `value_range`
/// sets it; values beyond it take the colour of its end. A non-finite value leaves its cell
/// white.
#[derive(Debug, Clone, PartialEq)]
pub struct HeatMap {
    /// The title above the map; empty for none.
    pub title: String,
    /// The label under the x axis; empty for none.
    pub x_label: String,
    /// The label beside the y axis; empty for none.
    pub y_label: String,
    /// The label of the colour bar: what the colours mean; empty for none.
    pub value_label: String,
    /// Cells along x.
    pub columns: usize,
    /// Cells along y.
    pub rows: usize,
    /// `rows · columns` values, row by row from the bottom: cell (row `i`, column `j`) is
    /// `values[i · columns + j]`.
    pub values: Vec<f64>,
    /// The x values of the left edge of the first column and the right edge of the last.
    pub x_extent: (f64, f64),
    /// The y values of the lower edge of the first row and the upper edge of the last.
    pub y_extent: (f64, f64),
    /// The values at the ends of the colour scale; `None` for the data's smallest and largest.
    pub value_range: Option<(f64, f64)>,
    /// Image width and height in pixels.
    pub size: (u32, u32),
}

/// Where a drawn heat map's parts lie, for tests that read its pixels.
#[derive(Debug, Clone)]
#[cfg_attr(
    not(test),
    allow(dead_code, reason = "read by the tests that locate data in images")
)]
pub(crate) struct HeatMapFrame {
    /// The map's plot area and axes.
    pub map: Frame,
    /// Image pixel columns and rows of the colour bar's gradient (value range low at the
    /// bottom row, high at the top row).
    pub bar: (Range<u32>, Range<u32>),
}

impl HeatMap {
    /// A heat map of 800 × 500 pixels of `values` (see [`HeatMap::values`]) over unit cells
    /// (`x_extent = (0, columns)`, `y_extent = (0, rows)`).
    pub fn new(
        title: impl Into<String>,
        x_label: impl Into<String>,
        y_label: impl Into<String>,
        value_label: impl Into<String>,
        (rows, columns): (usize, usize),
        values: Vec<f64>,
    ) -> HeatMap {
        HeatMap {
            title: title.into(),
            x_label: x_label.into(),
            y_label: y_label.into(),
            value_label: value_label.into(),
            columns,
            rows,
            values,
            x_extent: (0.0, columns as f64),
            y_extent: (0.0, rows as f64),
            value_range: None,
            size: (800, 500),
        }
    }

    /// This map with the cells spanning `x` and `y` (lower and upper edges).
    pub fn with_extent(mut self, x: (f64, f64), y: (f64, f64)) -> HeatMap {
        self.x_extent = x;
        self.y_extent = y;
        self
    }

    /// This map with the colour scale from `low` to `high`.
    pub fn with_value_range(mut self, low: f64, high: f64) -> HeatMap {
        self.value_range = Some((low, high));
        self
    }

    /// This map at `width` × `height` pixels.
    pub fn with_size(mut self, width: u32, height: u32) -> HeatMap {
        self.size = (width, height);
        self
    }

    /// Draws the map into an image of [`HeatMap::size`].
    ///
    /// Errors: [`PlotError::Empty`] without cells, [`PlotError::LengthMismatch`] when `values`
    /// does not hold `rows · columns` values, [`PlotError::NothingToDraw`] when none is finite,
    /// [`PlotError::Layout`] for an extent or value range that is not finite and increasing, or
    /// a size too small.
    pub fn render(&self) -> Result<Bitmap, PlotError> {
        Ok(self.render_framed()?.0)
    }

    /// Draws the map and writes it as a PNG file at `path`, atomically (see
    /// [`Bitmap::write_png`]).
    pub fn write_png(&self, path: impl AsRef<Path>) -> Result<(), PlotError> {
        self.render()?.write_png(path)
    }

    /// The ends of the colour scale: [`HeatMap::value_range`] or the finite values' extent
    /// (widened around a single value, so that the scale is never empty).
    fn scale(&self) -> Result<(f64, f64), PlotError> {
        if self.rows == 0 || self.columns == 0 {
            return Err(PlotError::Empty {
                plot: plot_name(&self.title),
                what: "cells",
            });
        }
        let expected = self.rows.checked_mul(self.columns);
        if expected != Some(self.values.len()) {
            return Err(PlotError::LengthMismatch {
                plot: plot_name(&self.title),
                series: self.value_label.clone(),
                what: "values",
                got: self.values.len(),
                expected: expected.unwrap_or(usize::MAX),
                per: "cell (rows × columns)",
            });
        }
        let layout = |reason: String| PlotError::Layout {
            plot: plot_name(&self.title),
            reason,
        };
        for (name, (lo, hi)) in [("x extent", self.x_extent), ("y extent", self.y_extent)] {
            if !(lo.is_finite() && hi.is_finite() && lo < hi) {
                return Err(layout(format!(
                    "{name} ({lo}, {hi}) must be finite and increasing"
                )));
            }
        }
        if let Some((lo, hi)) = self.value_range {
            if !(lo.is_finite() && hi.is_finite() && lo < hi) {
                return Err(layout(format!(
                    "value range ({lo}, {hi}) must be finite and increasing"
                )));
            }
            return Ok((lo, hi));
        }
        let (lo, hi) = self
            .values
            .iter()
            .filter(|v| v.is_finite())
            .fold(None, |acc: Option<(f64, f64)>, &v| match acc {
                None => Some((v, v)),
                Some((lo, hi)) => Some((lo.min(v), hi.max(v))),
            })
            .ok_or_else(|| PlotError::NothingToDraw {
                plot: plot_name(&self.title),
                series: self.value_label.clone(),
                points: self.values.len(),
                log_axis: false,
            })?;
        if lo < hi {
            return Ok((lo, hi));
        }
        let half = if lo == 0.0 { 1.0 } else { 0.05 * lo.abs() };
        Ok((lo - half, lo + half))
    }

    /// [`HeatMap::render`], also returning where the map and the colour bar lie.
    pub(crate) fn render_framed(&self) -> Result<(Bitmap, HeatMapFrame), PlotError> {
        check_size(&self.title, self.size)?;
        let scale = self.scale()?;
        render_with(&self.title, self.size, |area| self.draw_on(area, scale))
    }

    fn draw_on(&self, area: &Area<'_>, (lo, hi): (f64, f64)) -> Result<HeatMapFrame, PlotError> {
        let err = draw_error(&self.title);
        let (width, height) = area.dim_in_pixel();
        let metrics = Metrics::for_drawing(width, height);
        let tick_font = metrics.tick_font();
        let axis_font = metrics.axis_label_font();
        let gap = metrics.px(6.0);
        let tick = metrics.tick_length() as u32;
        let bar_width = metrics.px(20.0);
        let bar_axis = Axis::with_range(lo, hi, false, 5);
        let mut widest = 0;
        for label in &bar_axis.labels {
            widest = widest.max(area.estimate_text_size(label, &tick_font).map_err(&err)?.0);
        }
        let label_height = if self.value_label.is_empty() {
            0
        } else {
            area.estimate_text_size("Ag", &axis_font).map_err(&err)?.1 + gap
        };
        let strip = bar_width + tick + 2 * gap + widest + label_height + metrics.margin();
        if strip + metrics.px(120.0) > width {
            return Err(PlotError::Layout {
                plot: plot_name(&self.title),
                reason: format!(
                    "{} pixels are too narrow for the map and its colour bar",
                    width / crate::style::SUPERSAMPLE
                ),
            });
        }
        let (left, _) = area.split_horizontally(width - strip);
        let labels = Labels {
            title: &self.title,
            x: &self.x_label,
            y: &self.y_label,
        };
        let (x0, x1) = self.x_extent;
        let (y0, y1) = self.y_extent;
        let (mut chart, map) = draw_frame(
            &left,
            &metrics,
            &labels,
            |ticks| Axis::with_range(x0, x1, false, ticks),
            |ticks, _| Axis::with_range(y0, y1, false, ticks),
            false,
        )?;
        let (w, h) = (
            (x1 - x0) / self.columns as f64,
            (y1 - y0) / self.rows as f64,
        );
        let cells = self.values.iter().enumerate().filter_map(|(k, &v)| {
            if !v.is_finite() {
                return None;
            }
            let (i, j) = (k / self.columns, k % self.columns);
            let [r, g, b] = colormap((v - lo) / (hi - lo));
            let corners = [
                (x0 + j as f64 * w, y0 + i as f64 * h),
                (x0 + (j + 1) as f64 * w, y0 + (i + 1) as f64 * h),
            ];
            Some(Rectangle::new(corners, RGBColor(r, g, b).filled()))
        });
        chart.draw_series(cells).map_err(&err)?;

        // The colour bar beside the plot area, as tall as it, in the area's own coordinates.
        let (base_x, base_y) = area.get_base_pixel();
        let (cols, rows) = &map.area;
        let (top, bottom) = (rows.start - base_y, rows.end - 1 - base_y);
        let bar_left = cols.end - base_x + metrics.px(16.0) as i32;
        let bar_right = bar_left + bar_width as i32 - 1;
        // The outline first: the gradient covers its inner half.
        area.draw(&Rectangle::new(
            [(bar_left - 1, top - 1), (bar_right + 1, bottom + 1)],
            INK.stroke_width(metrics.px(1.0)),
        ))
        .map_err(&err)?;
        for row in top..=bottom {
            let t = f64::from(bottom - row) / f64::from((bottom - top).max(1));
            let [r, g, b] = colormap(t);
            area.draw(&Rectangle::new(
                [(bar_left, row), (bar_right + 1, row + 1)],
                RGBColor(r, g, b).filled(),
            ))
            .map_err(&err)?;
        }
        let label_style = tick_font.pos(Pos::new(HPos::Left, VPos::Center));
        for (value, label) in bar_axis.ticks.iter().zip(&bar_axis.labels) {
            let y = pixel_of(lo, hi, *value, (bottom, top));
            area.draw(&Rectangle::new(
                [(bar_right + 1, y), (bar_right + tick as i32, y)],
                INK.stroke_width(metrics.px(1.0)),
            ))
            .map_err(&err)?;
            area.draw(&Text::new(
                label.clone(),
                (bar_right + (tick + gap) as i32, y),
                label_style.clone(),
            ))
            .map_err(&err)?;
        }
        if !self.value_label.is_empty() {
            let x = bar_right + (tick + 2 * gap + widest) as i32;
            let style = axis_font
                .transform(FontTransform::Rotate270)
                .pos(Pos::new(HPos::Center, VPos::Top));
            area.draw(&Text::new(
                self.value_label.clone(),
                (x, (top + bottom) / 2),
                style,
            ))
            .map_err(&err)?;
        }
        let s = crate::style::SUPERSAMPLE as i32;
        let image = |a: i32, b: i32| (((a + base_x) / s) as u32)..(((b + base_x) / s) as u32);
        let bar = (
            image(bar_left, bar_right + 1),
            (((top + base_y) / s) as u32)..(((bottom + 1 + base_y) / s) as u32),
        );
        Ok(HeatMapFrame { map, bar })
    }
}
