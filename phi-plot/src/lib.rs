//! Plots for phi as PNG images: line plots with min–max bands ([`LinePlot`], [`Series`]),
//! grouped bar charts ([`BarChart`]), multi-panel figures of both ([`Figure`]) and heat maps
//! with a colour bar ([`HeatMap`], coloured by [`colormap`]); and captions on other pictures
//! ([`draw_text`]).
//!
//! Every chart has a title, labelled axes with ticks and a grid, and a legend; series take the
//! colours of a fixed qualitative palette ([`PALETTE`]) in order, and a series' band is a
//! translucent area of its colour. Text is set in DejaVu Sans, embedded in the binary, so no
//! system font library is needed. Values that cannot be drawn (`inf`, `NaN`, and values ≤ 0 on
//! a logarithmic axis) leave gaps and do not affect the axis ranges; a series with nothing to
//! draw is an error ([`PlotError::NothingToDraw`]) naming the plot and the series.
//!
//! Drawing gives a [`Bitmap`] (8-bit RGB); `write_png` writes it atomically, through a
//! temporary file `.{name}.tmp-{pid}` beside the target that is renamed when complete.
//!
//! ```
//! use phi_plot::{Figure, LinePlot, Series};
//!
//! let t: Vec<f64> = (0..50).map(f64::from).collect();
//! let mse: Vec<f64> = t.iter().map(|t| 1e-4 * (1.0 + 0.1 * t)).collect();
//! let low: Vec<f64> = mse.iter().map(|v| 0.8 * v).collect();
//! let high: Vec<f64> = mse.iter().map(|v| 1.3 * v).collect();
//! let plot = LinePlot::new("Rollout error", "time step", "MSE")
//!     .with_log_y(true)
//!     .with_series(Series::new("GNS", t.clone(), mse).with_band(low, high));
//! let image = plot.render()?;
//! assert_eq!((image.width, image.height), (800, 500));
//!
//! let figure = Figure::new("Water drop", 2)
//!     .with_panel(plot.clone())
//!     .with_panel(plot.with_log_y(false));
//! let path = std::env::temp_dir().join(format!("phi-plot-doc-{}.png", std::process::id()));
//! figure.write_png(&path)?;
//! # std::fs::remove_file(&path).unwrap();
//! # Ok::<(), phi_plot::PlotError>(())
//! ```

mod axis;
mod bar;
mod bitmap;
mod canvas;
mod caption;
mod chart;
mod error;
mod figure;
mod heatmap;
mod line;
mod style;
#[cfg(test)]
mod tests;
mod text;

pub use bar::{BarChart, BarSeries};
pub use bitmap::{Bitmap, MAX_SIDE, MIN_SIZE};
pub use caption::{draw_text, text_size};
pub use chart::Legend;
pub use error::PlotError;
pub use figure::{Figure, Panel};
pub use heatmap::{HeatMap, colormap};
pub use line::{Band, LinePlot, Series};
pub use style::{BAND_OPACITY, PALETTE, series_color};
