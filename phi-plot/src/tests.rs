//! Tests that look at the drawn pixels: where the series, bands, bars and texts land.

use crate::chart::Frame;
use crate::style::{BAND_OPACITY, series_color};
use crate::{BarChart, BarSeries, Bitmap, Figure, Legend, LinePlot, PlotError, Series};

/// Whether `pixel` is within `tolerance` of `color` in every channel.
fn near(pixel: [u8; 3], color: [u8; 3], tolerance: u8) -> bool {
    pixel
        .iter()
        .zip(&color)
        .all(|(&p, &c)| p.abs_diff(c) <= tolerance)
}

/// Whether `pixel` is `color` drawn over white with a coverage of at least `min_coverage`
/// (antialiased lines blend with the background at their edges).
fn tinted(pixel: [u8; 3], color: [u8; 3], min_coverage: f64) -> bool {
    // The coverage from the channel where `color` differs most from white.
    let (p, c) = pixel
        .iter()
        .zip(&color)
        .map(|(&p, &c)| (f64::from(p), f64::from(c)))
        .max_by(|a, b| (255.0 - a.1).total_cmp(&(255.0 - b.1)))
        .unwrap();
    let coverage = (255.0 - p) / (255.0 - c);
    coverage >= min_coverage
        && pixel.iter().zip(&color).all(|(&p, &c)| {
            let expected = coverage * f64::from(c) + (1.0 - coverage) * 255.0;
            (f64::from(p) - expected).abs() <= 6.0
        })
}

/// Text (near-black, antialiased) is a dark neutral grey; lines, bands and bars are coloured or
/// light.
fn dark(pixel: [u8; 3]) -> bool {
    let (min, max) = (pixel.iter().min().unwrap(), pixel.iter().max().unwrap());
    *max < 150 && max - min < 25
}

/// The colour of a band of `color` over white.
fn band_color(color: [u8; 3]) -> [u8; 3] {
    color.map(|c| (BAND_OPACITY * f64::from(c) + (1.0 - BAND_OPACITY) * 255.0).round() as u8)
}

/// How many pixels of `image` in columns `xs` and rows `ys` satisfy `test`.
fn count(
    image: &Bitmap,
    xs: std::ops::Range<u32>,
    ys: std::ops::Range<u32>,
    test: impl Fn([u8; 3]) -> bool,
) -> usize {
    ys.flat_map(|y| xs.clone().map(move |x| (x, y)))
        .filter(|&(x, y)| test(image.pixel(x, y).unwrap()))
        .count()
}

/// The plot area shrunk by `inset` pixels on every side (to stay clear of the axis lines).
fn inner(frame: &Frame, inset: u32) -> (std::ops::Range<u32>, std::ops::Range<u32>) {
    let (xs, ys) = frame.image_area();
    (
        xs.start + inset..xs.end - inset,
        ys.start + inset..ys.end - inset,
    )
}

fn linspace(n: usize, lo: f64, hi: f64) -> Vec<f64> {
    (0..n)
        .map(|i| lo + (hi - lo) * i as f64 / (n - 1) as f64)
        .collect()
}

/// The message of the error of `result`.
fn message(result: Result<Bitmap, PlotError>) -> String {
    result.unwrap_err().to_string()
}

fn three_series_plot() -> LinePlot {
    let x = linspace(50, 0.0, 1.0);
    let line = |offset: f64| x.iter().map(|x| offset + x).collect::<Vec<_>>();
    LinePlot::new("three lines", "time step", "error")
        .with_size(640, 400)
        .with_series(Series::new("a", x.clone(), line(0.0)))
        .with_series(Series::new("b", x.clone(), line(1.0)))
        .with_series(Series::new("c", x.clone(), line(2.0)))
}

#[test]
fn rendered_image_has_the_requested_size() {
    let image = three_series_plot().render().unwrap();
    assert_eq!((image.width, image.height), (640, 400));
    assert_eq!(image.rgb.len(), 640 * 400 * 3);
}

#[test]
fn every_series_colour_is_drawn_inside_the_plot_area_only() {
    let (image, frame) = three_series_plot()
        .with_legend(Legend::Hidden)
        .render_framed()
        .unwrap();
    let (xs, ys) = frame.image_area();
    for index in 0..3 {
        let color = series_color(index);
        let line = |p| tinted(p, color, 0.5);
        let inside = count(&image, xs.clone(), ys.clone(), line);
        // A line across the plot area covers at least half of a pixel in every column.
        assert!(inside >= xs.len(), "series {index}: {inside} pixels");
        let all = count(&image, 0..image.width, 0..image.height, line);
        assert_eq!(all, inside, "series {index} drawn outside the plot area");
    }
    // Line `a` runs from (0, 0) to (1, 1): its colour is at the pixel of (0.5, 0.5).
    let (px, py) = frame.pixel(0.5, 0.5);
    let hit = count(&image, px - 2..px + 3, py - 2..py + 3, |p| {
        tinted(p, series_color(0), 0.5)
    });
    assert!(hit > 0, "series a not at its data position");
}

#[test]
fn band_fills_between_lower_and_upper_edges_only() {
    let x = linspace(20, 0.0, 1.0);
    let series =
        Series::new("mean", x.clone(), vec![0.5; 20]).with_band(vec![0.2; 20], vec![0.8; 20]);
    // A second series widens the y range so that there is room above and below the band.
    let other = Series::new("range", vec![0.0, 1.0], vec![-0.5, 1.5]);
    let (image, frame) = LinePlot::new("band", "", "")
        .with_legend(Legend::Hidden)
        .with_series(series)
        .with_series(other)
        .render_framed()
        .unwrap();
    let band = band_color(series_color(0));
    let (column, _) = frame.pixel(0.55, 0.0);
    let (_, top) = frame.pixel(0.55, 0.8);
    let (_, bottom) = frame.pixel(0.55, 0.2);
    let (_, line) = frame.pixel(0.55, 0.5);
    // Inside the band, away from its edges, the centre line and the grid lines.
    let inside: Vec<u32> = (top + 3..bottom - 2)
        .filter(|y| y.abs_diff(line) > 3)
        .collect();
    let banded = inside
        .iter()
        .filter(|&&y| near(image.pixel(column, y).unwrap(), band, 6))
        .count();
    assert!(
        banded * 10 >= inside.len() * 8,
        "{banded} of {} pixels in the band have its colour",
        inside.len()
    );
    let (_, area_rows) = frame.image_area();
    let outside = count(&image, column..column + 1, area_rows.start..top - 2, |p| {
        near(p, band, 6)
    }) + count(&image, column..column + 1, bottom + 3..area_rows.end, |p| {
        near(p, band, 6)
    });
    assert_eq!(outside, 0, "band colour outside the band");
}

#[test]
fn non_finite_values_leave_a_gap_and_do_not_stretch_the_axes() {
    let x: Vec<f64> = (0..11).map(f64::from).collect();
    let mut y = vec![1.0; 11];
    y[5] = f64::NAN;
    y[8] = f64::INFINITY;
    y[9] = f64::NEG_INFINITY;
    let mut x_with_nan = x.clone();
    x_with_nan[2] = f64::NAN;
    let plot = LinePlot::new("gaps", "t", "e")
        .with_legend(Legend::Hidden)
        .with_series(Series::new("s", x_with_nan, y));
    let (image, frame) = plot.render_framed().unwrap();
    // Only finite points set the ranges: x over 0..10, y constant 1.
    assert!(frame.x.lo > -1.0 && frame.x.hi < 11.0, "{:?}", frame.x);
    assert!(frame.y.lo > 0.9 && frame.y.hi < 1.1, "{:?}", frame.y);
    let color = series_color(0);
    let (_, rows) = frame.image_area();
    let column_has_line = |x: f64| {
        let (px, _) = frame.pixel(x, 1.0);
        count(&image, px..px + 1, rows.clone(), |p| tinted(p, color, 0.5)) > 0
    };
    // Runs: 0..1, 3..4, 6..7, 10 (a dot). Gaps around x = 2, 5 and 8.5.
    for x in [0.5, 3.5, 6.5, 10.0] {
        assert!(column_has_line(x), "no line at x = {x}");
    }
    for x in [2.0, 5.0, 8.5] {
        assert!(!column_has_line(x), "line drawn across the gap at x = {x}");
    }
}

#[test]
fn log_axis_skips_non_positive_values() {
    let x: Vec<f64> = (0..6).map(f64::from).collect();
    let y = vec![1e-3, 0.0, -5.0, 1e-2, 1e-1, 1.0];
    let (image, frame) = LinePlot::new("log", "t", "loss")
        .with_log_y(true)
        .with_series(Series::new("loss", x, y))
        .render_framed()
        .unwrap();
    // The range is that of the positive values, 10⁻³ … 1, in decades.
    assert!(frame.y.log);
    assert!((frame.y.lo - -3.12).abs() < 1e-9, "{:?}", frame.y);
    assert!((frame.y.hi - 0.12).abs() < 1e-9, "{:?}", frame.y);
    assert_eq!(frame.y.labels, ["0.001", "0.01", "0.1", "1"]);
    // The point (3, 10⁻²) is drawn at its place on the log axis.
    let (px, py) = frame.pixel(3.5, -1.5);
    let hit = count(&image, px - 2..px + 3, py - 2..py + 3, |p| {
        tinted(p, series_color(0), 0.5)
    });
    assert!(hit > 0);

    let err = LinePlot::new("log", "t", "loss")
        .with_log_y(true)
        .with_series(Series::new("zeros", vec![0.0, 1.0], vec![0.0, -1.0]))
        .render()
        .unwrap_err();
    assert!(
        matches!(
            &err,
            PlotError::NothingToDraw {
                log_axis: true,
                points: 2,
                ..
            }
        ),
        "{err}"
    );
    let message = err.to_string();
    assert!(
        message.contains("'log'") && message.contains("'zeros'"),
        "{message}"
    );
    assert!(message.contains("logarithmic"), "{message}");
}

#[test]
fn titles_labels_and_legend_put_text_where_they_belong() {
    let plot = three_series_plot();
    let bare = LinePlot {
        title: String::new(),
        x_label: String::new(),
        y_label: String::new(),
        legend: Legend::Hidden,
        ..plot.clone()
    };
    let (image, frame) = plot.render_framed().unwrap();
    let (bare_image, bare_frame) = bare.render_framed().unwrap();
    let (xs, ys) = frame.image_area();
    let (bxs, bys) = bare_frame.image_area();
    let (w, h) = (image.width, image.height);

    // Title: dark pixels above the plot area, none without a title.
    let title = count(&image, 0..w, 0..ys.start - 2, dark);
    assert!(title > 50, "title: {title} dark pixels");
    assert_eq!(count(&bare_image, 0..w, 0..bys.start - 2, dark), 0);

    // Below the plot area: tick labels in both, more with the x label.
    let below = count(&image, 0..w, ys.end + 1..h, dark);
    let bare_below = count(&bare_image, 0..w, bys.end + 1..h, dark);
    assert!(bare_below > 20, "x tick labels: {bare_below}");
    assert!(below > bare_below + 10, "x label: {below} vs {bare_below}");

    // Left of the plot area: tick labels in both, more with the (rotated) y label.
    let left = count(&image, 0..xs.start - 1, 0..h, dark);
    let bare_left = count(&bare_image, 0..bxs.start - 1, 0..h, dark);
    assert!(bare_left > 20, "y tick labels: {bare_left}");
    assert!(left > bare_left + 10, "y label: {left} vs {bare_left}");

    // Inside the plot area only the legend's text is dark (lines and grid are not).
    let (ixs, iys) = inner(&frame, 3);
    let legend = count(&image, ixs.clone(), iys.clone(), dark);
    assert!(legend > 20, "legend text: {legend}");
    let (bixs, biys) = inner(&bare_frame, 3);
    assert_eq!(count(&bare_image, bixs, biys, dark), 0);
    // The legend sits in the upper right quarter.
    let upper_right = count(
        &image,
        (ixs.start + ixs.end) / 2..ixs.end,
        iys.start..(iys.start + iys.end) / 2,
        dark,
    );
    assert_eq!(upper_right, legend);
}

#[test]
fn unlabelled_series_have_no_legend() {
    let x = vec![0.0, 1.0];
    let plot = LinePlot::new("t", "", "").with_series(Series::new("", x.clone(), x.clone()));
    let (image, frame) = plot.render_framed().unwrap();
    let (xs, ys) = inner(&frame, 3);
    assert_eq!(count(&image, xs, ys, dark), 0);
    let labelled = plot.with_series(Series::new("named", x.clone(), vec![1.0, 0.0]));
    let (image, frame) = labelled.render_framed().unwrap();
    let (xs, ys) = inner(&frame, 3);
    assert!(count(&image, xs, ys, dark) > 0);
}

#[test]
fn constant_series_gets_a_range_around_its_value() {
    let (_, frame) = LinePlot::new("flat", "", "")
        .with_series(Series::new("c", vec![2.0, 2.0], vec![5.0, 5.0]))
        .render_framed()
        .unwrap();
    assert!((frame.x.lo - 1.9).abs() < 1e-12 && (frame.x.hi - 2.1).abs() < 1e-12);
    assert!((frame.y.lo - 4.75).abs() < 1e-12 && (frame.y.hi - 5.25).abs() < 1e-12);
    assert!(frame.y.ticks.len() >= 2);
}

#[test]
fn bars_rise_from_zero_in_their_group_and_missing_values_leave_no_bar() {
    let chart = BarChart::new("metrics", "value", ["MSE", "EMD", "Chamfer"])
        .with_legend(Legend::Hidden)
        .with_series(BarSeries::new("ours", vec![1.0, 2.0, 3.0]))
        .with_series(BarSeries::new("theirs", vec![2.0, f64::NAN, 1.0]));
    let (image, frame) = chart.render_framed().unwrap();
    assert_eq!(frame.y.lo, 0.0);
    assert_eq!(frame.x.labels, ["MSE", "EMD", "Chamfer"]);
    let (ours, theirs) = (series_color(0), series_color(1));
    // Group g spans g..g + 1 with the bars in its middle 80 %: ours left, theirs right.
    let at = |x: f64, y: f64| {
        let (px, py) = frame.pixel(x, y);
        image.pixel(px, py).unwrap()
    };
    assert!(near(at(0.3, 0.5), ours, 2));
    assert!(near(at(0.7, 1.5), theirs, 2));
    assert!(near(at(1.3, 1.9), ours, 2));
    assert!(!near(at(1.3, 2.1), ours, 40), "bar of 2 is taller");
    assert!(near(at(2.3, 2.9), ours, 2));
    // No bar for the NaN in group EMD.
    let (px0, _) = frame.pixel(1.55, 0.0);
    let (px1, _) = frame.pixel(1.85, 0.0);
    let (_, rows) = frame.image_area();
    assert_eq!(count(&image, px0..px1, rows, |p| near(p, theirs, 40)), 0);
}

#[test]
fn bar_legend_keeps_clear_of_the_bars() {
    let chart = BarChart::new("metrics", "value", ["a", "b"])
        .with_series(BarSeries::new("one", vec![1.0, 5.0]))
        .with_series(BarSeries::new("two", vec![2.0, 5.0]));
    let (image, frame) = chart.render_framed().unwrap();
    let (xs, rows) = inner(&frame, 3);
    // The legend text is above the tallest bars.
    let (_, top_of_bars) = frame.pixel(1.5, 5.0);
    let legend_rows: Vec<u32> = rows
        .filter(|&y| count(&image, xs.clone(), y..y + 1, dark) > 0)
        .collect();
    assert!(!legend_rows.is_empty());
    assert!(
        legend_rows.iter().all(|&y| y < top_of_bars),
        "{legend_rows:?} vs {top_of_bars}"
    );
}

#[test]
fn figure_lays_panels_out_row_by_row() {
    // Every panel's only series takes palette colour 0.
    let panel = |title: &str| {
        LinePlot::new(title, "t", "e")
            .with_size(400, 300)
            .with_legend(Legend::Hidden)
            .with_series(Series::new("s", vec![0.0, 1.0], vec![0.0, 1.0]))
    };
    let figure = Figure::new("", 2)
        .with_panel(panel("one"))
        .with_panel(panel("two"))
        .with_panel(
            BarChart::new("three", "", ["g"])
                .with_size(300, 200)
                .with_series(BarSeries::new("b", vec![1.0])),
        );
    assert_eq!(figure.size().unwrap(), (800, 600));
    let image = figure.render().unwrap();
    assert_eq!((image.width, image.height), (800, 600));
    let color = series_color(0);
    // One line per cell of the first row, a bar in the first cell of the second, nothing in the
    // fourth.
    for (x0, y0, expected) in [
        (0, 0, true),
        (400, 0, true),
        (0, 300, true),
        (400, 300, false),
    ] {
        let n = count(&image, x0..x0 + 400, y0..y0 + 300, |p| {
            tinted(p, color, 0.5)
        });
        assert_eq!(n > 0, expected, "cell at ({x0}, {y0}): {n} pixels");
    }
    let titled = Figure {
        title: "all".into(),
        ..figure
    };
    let (w, h) = titled.size().unwrap();
    assert_eq!(w, 800);
    assert!(h > 600);
}

#[test]
fn data_errors_name_the_plot_and_the_series() {
    let plot = LinePlot::new("rollout", "t", "e");
    assert_eq!(message(plot.render()), "plot 'rollout' has no series");
    let empty = plot
        .clone()
        .with_series(Series::new("empty", vec![], vec![]));
    let m = message(empty.render());
    assert!(
        m.contains("'rollout'") && m.contains("'empty'") && m.contains("0 points"),
        "{m}"
    );
    let blown = plot.clone().with_series(Series::new(
        "blown",
        vec![0.0, 1.0],
        vec![f64::NAN, f64::INFINITY],
    ));
    let m = message(blown.render());
    assert!(m.contains("'blown'") && m.contains("finite"), "{m}");
    let ragged = plot
        .clone()
        .with_series(Series::new("ragged", vec![0.0, 1.0], vec![1.0]));
    assert_eq!(
        message(ragged.render()),
        "plot 'rollout', series 'ragged': y has 1 values, expected 2 (one per x value)"
    );
    let bad_band = plot.clone().with_series(
        Series::new("band", vec![0.0, 1.0], vec![1.0, 2.0]).with_band(vec![0.0], vec![3.0, 3.0]),
    );
    assert!(message(bad_band.render()).contains("band lower has 1 values"));
    let tiny = plot.clone().with_size(100, 100).with_series(Series::new(
        "s",
        vec![0.0, 1.0],
        vec![1.0, 2.0],
    ));
    assert!(matches!(tiny.render(), Err(PlotError::Layout { .. })));
}

#[test]
fn bar_errors_name_the_chart_and_the_series() {
    let bars =
        BarChart::new("bars", "v", ["a", "b"]).with_series(BarSeries::new("short", vec![1.0]));
    assert_eq!(
        message(bars.render()),
        "plot 'bars', series 'short': values has 1 values, expected 2 (one per group)"
    );
    let no_groups = BarChart::new("bars", "v", Vec::<String>::new());
    assert_eq!(message(no_groups.render()), "plot 'bars' has no groups");
    let no_series = BarChart::new("bars", "v", ["a"]);
    assert_eq!(message(no_series.render()), "plot 'bars' has no series");
    let missing =
        BarChart::new("bars", "v", ["a"]).with_series(BarSeries::new("nan", vec![f64::NAN]));
    assert!(matches!(
        missing.render(),
        Err(PlotError::NothingToDraw { .. })
    ));
    let negative_on_log = BarChart::new("bars", "v", ["a"])
        .with_log_y(true)
        .with_series(BarSeries::new("neg", vec![-1.0]));
    assert!(message(negative_on_log.render()).contains("logarithmic"));
}

#[test]
fn figure_errors_name_the_figure() {
    assert_eq!(
        message(Figure::new("fig", 2).render()),
        "plot 'fig' has no panels"
    );
    let no_columns = Figure::new("fig", 0).with_panel(three_series_plot());
    assert!(matches!(no_columns.render(), Err(PlotError::Layout { .. })));
    // A panel's data error names the panel.
    let broken = Figure::new("fig", 1).with_panel(LinePlot::new("empty panel", "", ""));
    assert_eq!(message(broken.render()), "plot 'empty panel' has no series");
}

mod heat_map {
    use super::near;
    use crate::{HeatMap, PlotError, colormap};

    /// 2 rows × 3 columns, the values 0 to 5 row by row from the bottom.
    fn six_cells() -> HeatMap {
        HeatMap::new(
            "six cells",
            "frame",
            "neighbours",
            "share",
            (2, 3),
            vec![0.0, 1.0, 2.0, 3.0, 4.0, 5.0],
        )
        .with_extent((-0.5, 2.5), (10.0, 12.0))
        .with_size(600, 400)
    }

    #[test]
    fn colormap_runs_from_violet_to_yellow() {
        assert_eq!(colormap(0.0), [68, 1, 84]);
        assert_eq!(colormap(0.5), [38, 130, 142]);
        assert_eq!(colormap(1.0), [253, 231, 37]);
        assert_eq!(colormap(-3.0), colormap(0.0));
        assert_eq!(colormap(7.0), colormap(1.0));
        // Halfway between the first two stops.
        assert_eq!(colormap(0.0625), [70, 21, 102]);
    }

    #[test]
    fn each_cell_has_the_colour_of_its_value_where_the_axes_put_it() {
        let (image, frame) = six_cells().render_framed().unwrap();
        assert_eq!((image.width, image.height), (600, 400));
        for (k, value) in (0..6).map(|k| (k, k as f64)) {
            let (row, column) = (k / 3, k % 3);
            // The cell's centre in data coordinates: x = column, y = 10.5 + row.
            let (x, y) = frame.map.pixel(column as f64, 10.5 + row as f64);
            let pixel = image.pixel(x, y).unwrap();
            assert!(
                near(pixel, colormap(value / 5.0), 1),
                "cell {k} at ({x}, {y}): {pixel:?}, expected {:?}",
                colormap(value / 5.0)
            );
        }
        // Row 0 is at the bottom: the cell of 0 is below the cell of 3.
        assert!(frame.map.pixel(0.0, 10.5).1 > frame.map.pixel(0.0, 11.5).1);
    }

    #[test]
    fn the_colour_bar_ends_are_the_maps_ends() {
        let (image, frame) = six_cells().render_framed().unwrap();
        let (xs, ys) = frame.bar.clone();
        let x = (xs.start + xs.end) / 2;
        let bottom = image.pixel(x, ys.end - 1).unwrap();
        let top = image.pixel(x, ys.start).unwrap();
        let (low_cell, high_cell) = (frame.map.pixel(0.0, 10.5), frame.map.pixel(2.0, 11.5));
        let low = image.pixel(low_cell.0, low_cell.1).unwrap();
        let high = image.pixel(high_cell.0, high_cell.1).unwrap();
        assert!(
            near(bottom, low, 3),
            "bar bottom {bottom:?}, lowest cell {low:?}"
        );
        assert!(near(top, high, 3), "bar top {top:?}, highest cell {high:?}");
        // Halfway up the bar is halfway along the scale.
        let middle = image.pixel(x, (ys.start + ys.end) / 2).unwrap();
        assert!(near(middle, colormap(0.5), 6), "{middle:?}");
        // The bar stands right of the map, as tall as its plot area.
        let (map_xs, map_ys) = frame.map.image_area();
        assert!(xs.start > map_xs.end);
        assert!(ys.start.abs_diff(map_ys.start) <= 1 && ys.end.abs_diff(map_ys.end) <= 1);
    }

    #[test]
    fn a_value_range_clamps_and_non_finite_cells_stay_white() {
        let mut map = six_cells().with_value_range(1.0, 4.0);
        map.values[4] = f64::NAN;
        let (image, frame) = map.render_framed().unwrap();
        let at = |x: f64, y: f64| {
            let (x, y) = frame.map.pixel(x, y);
            image.pixel(x, y).unwrap()
        };
        assert!(near(at(0.0, 10.5), colormap(0.0), 1), "below the range");
        assert!(near(at(2.0, 11.5), colormap(1.0), 1), "above the range");
        assert!(near(at(1.0, 11.5), [255, 255, 255], 1), "NaN cell");
    }

    #[test]
    fn bad_input_is_an_error_naming_the_map() {
        let mut short = six_cells();
        short.values.pop();
        let error = short.render().unwrap_err().to_string();
        assert!(
            error.contains("six cells") && error.contains("5 values, expected 6"),
            "{error}"
        );
        let mut none = six_cells();
        none.values = vec![f64::NAN; 6];
        assert!(matches!(
            none.render(),
            Err(PlotError::NothingToDraw { .. })
        ));
        let flat = six_cells().with_extent((1.0, 1.0), (0.0, 1.0));
        assert!(flat.render().unwrap_err().to_string().contains("x extent"));
        let empty = HeatMap::new("empty", "", "", "", (0, 3), vec![]);
        assert!(matches!(empty.render(), Err(PlotError::Empty { .. })));
    }

    #[test]
    fn the_png_has_the_maps_size() {
        let path = std::env::temp_dir().join(format!("phi-plot-heat-{}.png", std::process::id()));
        six_cells().write_png(&path).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        assert_eq!(&bytes[1..4], b"PNG");
        let size = |at: usize| u32::from_be_bytes(bytes[at..at + 4].try_into().unwrap());
        assert_eq!((size(16), size(20)), (600, 400));
        let _ = std::fs::remove_file(&path);
    }
}
