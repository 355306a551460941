//! Line plots: [`Series`] of (x, y) points, each with an optional [`Band`], in a [`LinePlot`].

use std::path::Path;

use plotters::prelude::{
    Circle, Color, DrawingAreaErrorKind, DrawingBackend, PathElement, Polygon, RGBColor,
};

use crate::PlotError;
use crate::axis::{Anchor, Axis};
use crate::bitmap::{Bitmap, check_size, render_with};
use crate::canvas::Canvas;
use crate::chart::{
    Area, Chart, Frame, Labels, Legend, LegendEntry, LegendKey, draw_frame, draw_legend,
};
use crate::error::{draw_error, plot_name};
use crate::style::{BAND_OPACITY, Metrics, series_rgb};

/// A shaded envelope around a series, e.g. the minimum and maximum over several rollouts.
/// Both vectors run over the series' `x` values.
#[derive(Debug, Clone, PartialEq)]
pub struct Band {
    /// Lower edge, one value per x value.
    pub lower: Vec<f64>,
    /// Upper edge, one value per x value.
    pub upper: Vec<f64>,
}

/// One curve of a [`LinePlot`]: points (`x[i]`, `y[i]`) joined by straight lines, drawn in the
/// plot's `i`-th palette colour and named `label` in the legend.
///
/// A point with a non-finite coordinate (a rollout that blew up gives `inf` or `NaN`), or with
/// `y ≤ 0` on a logarithmic axis, is not drawn: the line has a gap there, and the point does not
/// count for the axis ranges. A run of one point between gaps is drawn as a dot. The same holds
/// for the band, point by point (a band point needs finite `x`, `lower` and `upper`), except
/// that a band is only drawn over runs of at least two points. A series with an empty label
/// has no legend entry.
#[derive(Debug, Clone, PartialEq)]
pub struct Series {
    /// The name in the legend; empty for no entry.
    pub label: String,
    /// The x values.
    pub x: Vec<f64>,
    /// The y values, one per x value.
    pub y: Vec<f64>,
    /// An optional envelope drawn as a translucent area of the series colour.
    pub band: Option<Band>,
}

impl Series {
    /// A series without a band.
    pub fn new(label: impl Into<String>, x: Vec<f64>, y: Vec<f64>) -> Series {
        Series {
            label: label.into(),
            x,
            y,
            band: None,
        }
    }

    /// This series with the band from `lower` to `upper` (per point, the smaller of the two is
    /// taken as the lower edge).
    pub fn with_band(mut self, lower: Vec<f64>, upper: Vec<f64>) -> Series {
        self.band = Some(Band { lower, upper });
        self
    }
}

/// A chart of [`Series`] against a common x axis, with a title, axis labels and a legend.
///
/// Axis ranges follow the drawable data (see [`Series`]) with a margin of 4 % on each side; a
/// constant series gets a range of ±5 % around its value (±1 around 0, ±0.1 decade on a
/// logarithmic axis). Tick labels are plain decimals, or `2.5×10⁻⁴` when the values are below
/// 10⁻³ or at least 10⁶; on a logarithmic axis ticks sit at powers of ten (or 1, 2, 5 times
/// them over less than three decades).
#[derive(Debug, Clone, PartialEq)]
pub struct LinePlot {
    /// The title above the plot; empty for none.
    pub title: String,
    /// The label under the x axis; empty for none.
    pub x_label: String,
    /// The label beside the y axis; empty for none.
    pub y_label: String,
    /// Whether the y axis is logarithmic (base 10).
    pub log_y: bool,
    /// The curves, coloured in order by [`crate::series_color`].
    pub series: Vec<Series>,
    /// Image width and height in pixels when the plot is drawn alone.
    pub size: (u32, u32),
    /// Where the legend goes.
    pub legend: Legend,
}

/// A series reduced to what is drawn: runs of drawable points and of band points in plot space.
struct PreparedSeries<'s> {
    label: &'s str,
    /// Maximal runs of consecutive drawable points, (x, y) in plot space.
    runs: Vec<Vec<(f64, f64)>>,
    /// Maximal runs of consecutive drawable band points: (x, lower, upper) in plot space.
    band_runs: Vec<Vec<(f64, f64, f64)>>,
}

impl LinePlot {
    /// An empty plot of 800 × 500 pixels with linear axes and the legend in the upper right.
    pub fn new(
        title: impl Into<String>,
        x_label: impl Into<String>,
        y_label: impl Into<String>,
    ) -> LinePlot {
        LinePlot {
            title: title.into(),
            x_label: x_label.into(),
            y_label: y_label.into(),
            log_y: false,
            series: Vec::new(),
            size: (800, 500),
            legend: Legend::UpperRight,
        }
    }

    /// This plot with `series` added.
    pub fn with_series(mut self, series: Series) -> LinePlot {
        self.series.push(series);
        self
    }

    /// This plot with a logarithmic (`true`) or linear y axis.
    pub fn with_log_y(mut self, log_y: bool) -> LinePlot {
        self.log_y = log_y;
        self
    }

    /// This plot at `width` × `height` pixels.
    pub fn with_size(mut self, width: u32, height: u32) -> LinePlot {
        self.size = (width, height);
        self
    }

    /// This plot with its legend at `legend`.
    pub fn with_legend(mut self, legend: Legend) -> LinePlot {
        self.legend = legend;
        self
    }

    /// Draws the plot into an image of [`LinePlot::size`].
    ///
    /// Errors: [`PlotError::Empty`] without series, [`PlotError::LengthMismatch`] when a series'
    /// vectors differ in length, [`PlotError::NothingToDraw`] for a series without a drawable
    /// point, [`PlotError::Layout`] for a size too small for the axes.
    pub fn render(&self) -> Result<Bitmap, PlotError> {
        Ok(self.render_framed()?.0)
    }

    /// Draws the plot and writes it as a PNG file at `path`, atomically (see
    /// [`Bitmap::write_png`]).
    pub fn write_png(&self, path: impl AsRef<Path>) -> Result<(), PlotError> {
        self.render()?.write_png(path)
    }

    /// [`LinePlot::render`], also returning where the plot area lies.
    pub(crate) fn render_framed(&self) -> Result<(Bitmap, Frame), PlotError> {
        check_size(&self.title, self.size)?;
        let prepared = self.prepare()?;
        render_with(&self.title, self.size, |area| {
            self.draw_prepared(area, &prepared)
        })
    }

    /// Draws the plot onto `area` (a whole image or a panel of a figure).
    pub(crate) fn draw_on(&self, area: &Area<'_>) -> Result<Frame, PlotError> {
        let prepared = self.prepare()?;
        self.draw_prepared(area, &prepared)
    }

    /// Checks the series and splits them into drawable runs.
    fn prepare(&self) -> Result<Vec<PreparedSeries<'_>>, PlotError> {
        if self.series.is_empty() {
            return Err(PlotError::Empty {
                plot: plot_name(&self.title),
                what: "series",
            });
        }
        self.series.iter().map(|s| self.prepare_series(s)).collect()
    }

    fn prepare_series<'s>(&self, series: &'s Series) -> Result<PreparedSeries<'s>, PlotError> {
        let mismatch = |what, got| PlotError::LengthMismatch {
            plot: plot_name(&self.title),
            series: series.label.clone(),
            what,
            got,
            expected: series.x.len(),
            per: "x value",
        };
        if series.y.len() != series.x.len() {
            return Err(mismatch("y", series.y.len()));
        }
        if let Some(band) = &series.band {
            if band.lower.len() != series.x.len() {
                return Err(mismatch("band lower", band.lower.len()));
            }
            if band.upper.len() != series.x.len() {
                return Err(mismatch("band upper", band.upper.len()));
            }
        }
        let log = self.log_y;
        let y_plot = |v: f64| -> Option<f64> {
            let drawable = v.is_finite() && (!log || v > 0.0);
            drawable.then(|| if log { v.log10() } else { v })
        };
        let x_plot = |v: f64| v.is_finite().then_some(v);
        let runs = split_runs(
            series
                .x
                .iter()
                .zip(&series.y)
                .map(|(&x, &y)| Some((x_plot(x)?, y_plot(y)?))),
        );
        if runs.is_empty() {
            return Err(PlotError::NothingToDraw {
                plot: plot_name(&self.title),
                series: series.label.clone(),
                points: series.x.len(),
                log_axis: log,
            });
        }
        let band_runs = match &series.band {
            None => Vec::new(),
            Some(band) => split_runs(series.x.iter().zip(band.lower.iter().zip(&band.upper)).map(
                |(&x, (&a, &b))| {
                    let (a, b) = (y_plot(a)?, y_plot(b)?);
                    Some((x_plot(x)?, a.min(b), a.max(b)))
                },
            )),
        };
        Ok(PreparedSeries {
            label: &series.label,
            runs,
            band_runs,
        })
    }

    fn draw_prepared(
        &self,
        area: &Area<'_>,
        prepared: &[PreparedSeries<'_>],
    ) -> Result<Frame, PlotError> {
        let (width, height) = area.dim_in_pixel();
        let metrics = Metrics::for_drawing(width, height);
        let err = draw_error(&self.title);
        let xs = || {
            prepared.iter().flat_map(|s| {
                let line = s.runs.iter().flatten().map(|p| p.0);
                let band = s.band_runs.iter().flatten().map(|p| p.0);
                line.chain(band)
            })
        };
        let ys = || {
            prepared.iter().flat_map(|s| {
                let line = s.runs.iter().flatten().map(|p| p.1);
                let band = s.band_runs.iter().flatten().flat_map(|p| [p.1, p.2]);
                line.chain(band)
            })
        };
        let x_axis = |ticks| {
            Axis::from_data(xs(), false, Anchor::None, ticks).expect("a prepared series has points")
        };
        let y_axis = |ticks, _| {
            Axis::from_data(ys(), self.log_y, Anchor::None, ticks)
                .expect("a prepared series has points")
        };
        let labels = Labels {
            title: &self.title,
            x: &self.x_label,
            y: &self.y_label,
        };
        let (mut chart, frame) = draw_frame(area, &metrics, &labels, x_axis, y_axis, true)?;

        // Bands first, so that every line lies on top of every band.
        for (index, series) in prepared.iter().enumerate() {
            let fill = series_rgb(index).mix(BAND_OPACITY).filled();
            for run in series.band_runs.iter().filter(|r| r.len() >= 2) {
                let outline: Vec<(f64, f64)> = run
                    .iter()
                    .map(|&(x, lo, _)| (x, lo))
                    .chain(run.iter().rev().map(|&(x, _, hi)| (x, hi)))
                    .collect();
                chart
                    .draw_series(std::iter::once(Polygon::new(outline, fill)))
                    .map_err(&err)?;
            }
        }
        let stroke_width = metrics.line_width();
        let dot_radius = metrics.px(3.0) as i32;
        let mut entries = Vec::new();
        for (index, series) in prepared.iter().enumerate() {
            let color = series_rgb(index);
            for run in &series.runs {
                draw_run(&mut chart, run, color, stroke_width, dot_radius).map_err(&err)?;
            }
            // A series without a label has no entry.
            if !series.label.is_empty() {
                entries.push(LegendEntry {
                    label: series.label,
                    key: LegendKey::Line {
                        color,
                        width: stroke_width,
                        band: !series.band_runs.is_empty(),
                    },
                });
            }
        }
        draw_legend(&chart, &metrics, self.legend, &entries, &self.title)?;
        Ok(frame)
    }
}

/// Draws one run of points: a line, or a dot for a run of one point.
fn draw_run(
    chart: &mut Chart<'_, '_>,
    run: &[(f64, f64)],
    color: RGBColor,
    stroke_width: u32,
    dot_radius: i32,
) -> Result<(), DrawingAreaErrorKind<<Canvas<'static> as DrawingBackend>::ErrorType>> {
    if let [point] = run {
        chart.draw_series(std::iter::once(Circle::new(
            *point,
            dot_radius,
            color.filled(),
        )))?;
    } else {
        chart.draw_series(std::iter::once(PathElement::new(
            run.to_vec(),
            color.stroke_width(stroke_width),
        )))?;
    }
    Ok(())
}

/// The maximal runs of consecutive `Some` items.
fn split_runs<T>(points: impl Iterator<Item = Option<T>>) -> Vec<Vec<T>> {
    let mut runs = Vec::new();
    let mut current = Vec::new();
    for point in points {
        match point {
            Some(p) => current.push(p),
            None if !current.is_empty() => runs.push(std::mem::take(&mut current)),
            None => {}
        }
    }
    if !current.is_empty() {
        runs.push(current);
    }
    runs
}
