//! The public interface of phi-plot: images of the requested size, PNG files that decode to
//! them, written atomically.

use std::fs::File;
use std::path::{Path, PathBuf};

use phi_plot::{BarChart, BarSeries, Bitmap, Figure, LinePlot, PlotError, Series};

/// A fresh, empty directory for one test.
fn temp_dir(test: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("phi-plot-test-{}-{test}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Decodes an 8-bit RGB PNG file.
fn read_png(path: &Path) -> Bitmap {
    let decoder = png::Decoder::new(std::io::BufReader::new(File::open(path).unwrap()));
    let mut reader = decoder.read_info().unwrap();
    let mut rgb = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut rgb).unwrap();
    assert_eq!(info.color_type, png::ColorType::Rgb);
    assert_eq!(info.bit_depth, png::BitDepth::Eight);
    rgb.truncate(info.buffer_size());
    Bitmap {
        width: info.width,
        height: info.height,
        rgb,
    }
}

/// The names of the files in `dir`.
fn file_names(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .collect();
    names.sort();
    names
}

fn error_plot() -> LinePlot {
    let t: Vec<f64> = (0..30).map(f64::from).collect();
    let error: Vec<f64> = t.iter().map(|t| 1e-4 * (1.0 + t * t)).collect();
    let lower = error.iter().map(|e| 0.5 * e).collect();
    let upper = error.iter().map(|e| 2.0 * e).collect();
    LinePlot::new("MSE over time", "time step", "MSE")
        .with_log_y(true)
        .with_size(500, 320)
        .with_series(Series::new("model", t, error).with_band(lower, upper))
}

fn metric_bars() -> BarChart {
    BarChart::new("metrics", "value", ["MSE", "EMD"])
        .with_size(400, 300)
        .with_series(BarSeries::new("a", vec![1.0, 2.0]))
}

#[test]
fn written_png_decodes_to_the_rendered_image() {
    let dir = temp_dir("round-trip");
    let plot = error_plot();
    let path = dir.join("error.png");
    plot.write_png(&path).unwrap();
    let decoded = read_png(&path);
    assert_eq!((decoded.width, decoded.height), (500, 320));
    assert_eq!(decoded, plot.render().unwrap());
    // Atomic writing leaves no temporary file behind.
    assert_eq!(file_names(&dir), ["error.png"]);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn bar_charts_are_written_at_their_size() {
    let dir = temp_dir("bars");
    let path = dir.join("bars.png");
    metric_bars().write_png(&path).unwrap();
    let decoded = read_png(&path);
    assert_eq!((decoded.width, decoded.height), (400, 300));
    assert_eq!(decoded, metric_bars().render().unwrap());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn figures_are_written_as_a_grid_of_cells() {
    let dir = temp_dir("figure");
    let figure = Figure::new("", 2)
        .with_panel(error_plot())
        .with_panel(error_plot().with_log_y(false))
        .with_panel(metric_bars());
    let path = dir.join("figure.png");
    figure.write_png(&path).unwrap();
    let decoded = read_png(&path);
    // Cells of the largest panel, 500 × 320, two per row.
    assert_eq!((decoded.width, decoded.height), (1000, 640));
    assert_eq!(figure.size().unwrap(), (1000, 640));
    assert_eq!(file_names(&dir), ["figure.png"]);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_failed_write_names_the_file_and_keeps_the_old_one() {
    let dir = temp_dir("failure");
    let path = dir.join("plot.png");
    std::fs::write(&path, b"old").unwrap();
    // Drawing fails before anything is written: the old file stays.
    let empty = LinePlot::new("empty", "", "");
    assert!(matches!(
        empty.write_png(&path),
        Err(PlotError::Empty { .. })
    ));
    assert_eq!(std::fs::read(&path).unwrap(), b"old");
    // Writing into a missing directory fails with its path in the message.
    let missing = dir.join("missing").join("plot.png");
    let err = error_plot().write_png(&missing).unwrap_err();
    assert!(matches!(err, PlotError::Io { .. }), "{err}");
    assert!(err.to_string().contains("missing"), "{err}");
    assert_eq!(file_names(&dir), ["plot.png"]);
    let _ = std::fs::remove_dir_all(&dir);
}
