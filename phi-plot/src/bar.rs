//! Grouped bar charts: one group of bars per category (e.g. a metric), one bar per series
//! (e.g. a model) in each group.

use std::path::Path;

use plotters::prelude::{Color, Rectangle};

use crate::PlotError;
use crate::axis::{Anchor, Axis};
use crate::bitmap::{Bitmap, check_size, render_with};
use crate::chart::{
    Area, Frame, Labels, Legend, LegendEntry, LegendKey, draw_frame, draw_legend, legend_height,
};
use crate::error::{draw_error, plot_name};
use crate::style::{Metrics, series_rgb};

/// Fraction of a group's width that its bars take together; the rest separates the groups.
const GROUP_FILL: f64 = 0.8;
/// Fraction of a bar's slot that the bar fills; the rest separates neighbouring bars.
const BAR_FILL: f64 = 0.9;

/// The bars of one series: `values[g]` is its bar in group `g`.
#[derive(Debug, Clone, PartialEq)]
pub struct BarSeries {
    /// The name in the legend; empty for no entry.
    pub label: String,
    /// One value per group. A non-finite value (or, on a logarithmic axis, one ≤ 0) leaves its
    /// bar out.
    pub values: Vec<f64>,
}

impl BarSeries {
    /// A series named `label` with one value per group.
    pub fn new(label: impl Into<String>, values: Vec<f64>) -> BarSeries {
        BarSeries {
            label: label.into(),
            values,
        }
    }
}

/// A grouped bar chart: the groups side by side along the x axis, labelled by their names, and
/// in each group one bar per series in the series' palette colour.
///
/// On a linear axis bars rise from zero and the range includes zero; on a logarithmic axis they
/// rise from the bottom of the axis. The value range has a margin of 4 % (none below zero on a
/// linear axis).
#[derive(Debug, Clone, PartialEq)]
pub struct BarChart {
    /// The title above the chart; empty for none.
    pub title: String,
    /// The label under the x axis; empty for none.
    pub x_label: String,
    /// The label beside the y axis; empty for none.
    pub y_label: String,
    /// The names of the groups, in order along the x axis.
    pub groups: Vec<String>,
    /// The series, coloured in order by [`crate::series_color`].
    pub series: Vec<BarSeries>,
    /// Whether the y axis is logarithmic (base 10).
    pub log_y: bool,
    /// Image width and height in pixels when the chart is drawn alone.
    pub size: (u32, u32),
    /// Where the legend goes.
    pub legend: Legend,
}

impl BarChart {
    /// A chart of 800 × 500 pixels over `groups`, without series, with a linear y axis and the
    /// legend in the upper right.
    pub fn new(
        title: impl Into<String>,
        y_label: impl Into<String>,
        groups: impl IntoIterator<Item = impl Into<String>>,
    ) -> BarChart {
        BarChart {
            title: title.into(),
            x_label: String::new(),
            y_label: y_label.into(),
            groups: groups.into_iter().map(Into::into).collect(),
            series: Vec::new(),
            log_y: false,
            size: (800, 500),
            legend: Legend::UpperRight,
        }
    }

    /// This chart with `series` added.
    pub fn with_series(mut self, series: BarSeries) -> BarChart {
        self.series.push(series);
        self
    }

    /// This chart with a logarithmic (`true`) or linear y axis.
    pub fn with_log_y(mut self, log_y: bool) -> BarChart {
        self.log_y = log_y;
        self
    }

    /// This chart at `width` × `height` pixels.
    pub fn with_size(mut self, width: u32, height: u32) -> BarChart {
        self.size = (width, height);
        self
    }

    /// This chart with its legend at `legend`.
    pub fn with_legend(mut self, legend: Legend) -> BarChart {
        self.legend = legend;
        self
    }

    /// Draws the chart into an image of [`BarChart::size`].
    ///
    /// Errors: [`PlotError::Empty`] without groups or series, [`PlotError::LengthMismatch`]
    /// when a series has not one value per group, [`PlotError::NothingToDraw`] for a series
    /// without a drawable bar, [`PlotError::Layout`] for a size too small for the axes.
    pub fn render(&self) -> Result<Bitmap, PlotError> {
        Ok(self.render_framed()?.0)
    }

    /// Draws the chart and writes it as a PNG file at `path`, atomically (see
    /// [`Bitmap::write_png`]).
    pub fn write_png(&self, path: impl AsRef<Path>) -> Result<(), PlotError> {
        self.render()?.write_png(path)
    }

    /// [`BarChart::render`], also returning where the plot area lies.
    pub(crate) fn render_framed(&self) -> Result<(Bitmap, Frame), PlotError> {
        check_size(&self.title, self.size)?;
        let bars = self.prepare()?;
        render_with(&self.title, self.size, |area| {
            self.draw_prepared(area, &bars)
        })
    }

    /// Draws the chart onto `area` (a whole image or a panel of a figure).
    pub(crate) fn draw_on(&self, area: &Area<'_>) -> Result<Frame, PlotError> {
        let bars = self.prepare()?;
        self.draw_prepared(area, &bars)
    }

    /// Checks the series; returns per series the drawable bars as (group, value in plot space).
    fn prepare(&self) -> Result<Vec<Vec<(usize, f64)>>, PlotError> {
        let plot = || plot_name(&self.title);
        for (what, empty) in [
            ("groups", self.groups.is_empty()),
            ("series", self.series.is_empty()),
        ] {
            if empty {
                return Err(PlotError::Empty { plot: plot(), what });
            }
        }
        self.series
            .iter()
            .map(|series| {
                if series.values.len() != self.groups.len() {
                    return Err(PlotError::LengthMismatch {
                        plot: plot(),
                        series: series.label.clone(),
                        what: "values",
                        got: series.values.len(),
                        expected: self.groups.len(),
                        per: "group",
                    });
                }
                let bars: Vec<(usize, f64)> = series
                    .values
                    .iter()
                    .enumerate()
                    .filter(|(_, v)| v.is_finite() && (!self.log_y || **v > 0.0))
                    .map(|(g, &v)| (g, if self.log_y { v.log10() } else { v }))
                    .collect();
                if bars.is_empty() {
                    return Err(PlotError::NothingToDraw {
                        plot: plot(),
                        series: series.label.clone(),
                        points: series.values.len(),
                        log_axis: self.log_y,
                    });
                }
                Ok(bars)
            })
            .collect()
    }

    fn draw_prepared(
        &self,
        area: &Area<'_>,
        bars: &[Vec<(usize, f64)>],
    ) -> Result<Frame, PlotError> {
        let (width, height) = area.dim_in_pixel();
        let metrics = Metrics::for_drawing(width, height);
        let values = || bars.iter().flatten().map(|&(_, v)| v);
        let x_axis = |_| Axis::categories(&self.groups);
        // Bars rise from zero on a linear axis, so the range includes it.
        let anchor = if self.log_y {
            Anchor::None
        } else {
            Anchor::Zero
        };
        let y_axis = |ticks, plot_height: u32| {
            let axis = Axis::from_data(values(), self.log_y, anchor, ticks)
                .expect("a prepared series has bars");
            // Bars are wide: keep the tallest below a legend in an upper corner by raising the
            // top of the axis by the legend's share of the plot height.
            let entries = self.series.iter().filter(|s| !s.label.is_empty()).count();
            if entries == 0 || !matches!(self.legend, Legend::UpperLeft | Legend::UpperRight) {
                return axis;
            }
            let legend = f64::from(legend_height(&metrics, entries));
            let share = (legend / f64::from(plot_height.max(1))).min(0.5);
            let hi = axis.lo + (axis.hi - axis.lo) / (1.0 - share);
            Axis::with_range(axis.lo, hi, self.log_y, ticks)
        };
        let labels = Labels {
            title: &self.title,
            x: &self.x_label,
            y: &self.y_label,
        };
        let (mut chart, frame) = draw_frame(area, &metrics, &labels, x_axis, y_axis, false)?;
        let base = if self.log_y { frame.y.lo } else { 0.0 };
        let slot = GROUP_FILL / bars.len() as f64;
        let err = draw_error(&self.title);
        let mut entries = Vec::new();
        for (index, (series, bars)) in self.series.iter().zip(bars).enumerate() {
            let color = series_rgb(index);
            let left_of = |group: usize| {
                group as f64
                    + 0.5 * (1.0 - GROUP_FILL)
                    + index as f64 * slot
                    + 0.5 * (1.0 - BAR_FILL) * slot
            };
            let rectangles = bars.iter().map(|&(group, value)| {
                let left = left_of(group);
                Rectangle::new(
                    [(left, base), (left + BAR_FILL * slot, value)],
                    color.filled(),
                )
            });
            chart.draw_series(rectangles).map_err(&err)?;
            // A series without a label has no entry.
            if !series.label.is_empty() {
                entries.push(LegendEntry {
                    label: &series.label,
                    key: LegendKey::Swatch(color),
                });
            }
        }
        draw_legend(&chart, &metrics, self.legend, &entries, &self.title)?;
        Ok(frame)
    }
}
