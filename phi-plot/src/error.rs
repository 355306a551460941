//! [`PlotError`], the one error type of this crate.

use std::path::PathBuf;

/// Errors of drawing and writing plots. Errors about data name the plot (by its title) and the
/// series; errors about files name the file.
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    /// A plot, chart or figure has nothing of some kind it needs (no series, no groups, no
    /// panels).
    #[error("plot '{plot}' has no {what}")]
    Empty {
        /// The title of the plot.
        plot: String,
        /// What is missing: "series", "groups", "panels".
        what: &'static str,
    },
    /// A series has vectors of different lengths.
    #[error(
        "plot '{plot}', series '{series}': {what} has {got} values, expected {expected} (one per {per})"
    )]
    LengthMismatch {
        /// The title of the plot.
        plot: String,
        /// The label of the series.
        series: String,
        /// The vector of the wrong length ("y", "band lower", "band upper", "values").
        what: &'static str,
        /// Its length.
        got: usize,
        /// The length it should have.
        expected: usize,
        /// What the expected length counts ("x value", "group").
        per: &'static str,
    },
    /// A series has no point that can be drawn: it is empty, or every point has a non-finite
    /// coordinate (or, on a logarithmic axis, a value that is not positive).
    #[error(
        "plot '{plot}', series '{series}': nothing to draw among its {points} points \
         (a point needs finite coordinates{log_note})",
        log_note = if *log_axis { " and a positive value on the logarithmic axis" } else { "" }
    )]
    NothingToDraw {
        /// The title of the plot.
        plot: String,
        /// The label of the series.
        series: String,
        /// How many points the series has.
        points: usize,
        /// Whether the value axis is logarithmic.
        log_axis: bool,
    },
    /// The requested image size is too small to hold the axes and labels, or a figure's layout
    /// is invalid.
    #[error("plot '{plot}': {reason}")]
    Layout {
        /// The title of the plot or figure.
        plot: String,
        /// What is wrong.
        reason: String,
    },
    /// The embedded font could not be registered with the drawing library.
    #[error("cannot load the embedded DejaVu Sans font")]
    Font,
    /// The drawing library failed.
    #[error("plot '{plot}': drawing failed: {message}")]
    Draw {
        /// The title of the plot.
        plot: String,
        /// The drawing library's message.
        message: String,
    },
    /// An operating-system I/O operation on `path` failed.
    #[error("{action} '{path}': {source}", path = path.display())]
    Io {
        /// The file involved.
        path: PathBuf,
        /// What was being done, e.g. "cannot create".
        action: &'static str,
        /// The underlying error.
        #[source]
        source: std::io::Error,
    },
    /// PNG encoding failed.
    #[error("cannot encode '{path}' as PNG: {source}", path = path.display())]
    Png {
        /// The file being written.
        path: PathBuf,
        /// The encoder's error.
        #[source]
        source: png::EncodingError,
    },
}

/// The name of a plot in messages: its title, or "untitled".
pub(crate) fn plot_name(title: &str) -> String {
    if title.trim().is_empty() {
        "untitled".to_string()
    } else {
        title.to_string()
    }
}

/// Maps a drawing-library error to [`PlotError::Draw`] for the plot titled `title`.
pub(crate) fn draw_error<E: std::fmt::Display>(title: &str) -> impl Fn(E) -> PlotError + '_ {
    move |e| PlotError::Draw {
        plot: plot_name(title),
        message: e.to_string(),
    }
}
