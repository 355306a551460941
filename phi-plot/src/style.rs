//! The look shared by all plots: the series palette, the embedded font and sizes that scale with
//! the image.

use plotters::style::{FontFamily, RGBColor, TextStyle};

/// The family name in text styles; [`crate::canvas::Canvas`] draws all text in the embedded
/// DejaVu Sans whatever the style names.
const FAMILY: &str = "DejaVu Sans";

/// The series colours, in order: the ten colours of the Tableau 10 qualitative palette
/// (matplotlib's default colour cycle), chosen to stay apart from each other and from the black
/// text and grey grid.
pub const PALETTE: [[u8; 3]; 10] = [
    [31, 119, 180],  // blue
    [255, 127, 14],  // orange
    [44, 160, 44],   // green
    [214, 39, 40],   // red
    [148, 103, 189], // purple
    [140, 86, 75],   // brown
    [227, 119, 194], // pink
    [127, 127, 127], // grey
    [188, 189, 34],  // olive
    [23, 190, 207],  // cyan
];

/// The colour of the `index`-th series of a plot: [`PALETTE`] repeated.
pub fn series_color(index: usize) -> [u8; 3] {
    PALETTE[index % PALETTE.len()]
}

/// [`series_color`] as a plotters colour.
pub(crate) fn series_rgb(index: usize) -> RGBColor {
    let [r, g, b] = series_color(index);
    RGBColor(r, g, b)
}

/// Opacity of a series' band (a min–max envelope) over the white background.
pub const BAND_OPACITY: f64 = 0.25;

/// Grid lines at labelled ticks.
pub(crate) const GRID: RGBColor = RGBColor(222, 222, 222);
/// Grid lines at minor ticks of a logarithmic axis.
pub(crate) const MINOR_GRID: RGBColor = RGBColor(242, 242, 242);
/// Text, axes and tick marks.
pub(crate) const INK: RGBColor = RGBColor(20, 20, 20);

/// Charts are drawn at this many times the image resolution in each direction and then
/// averaged down, which smooths the edges of lines, bands and bars (the drawing library does
/// not antialias them).
pub(crate) const SUPERSAMPLE: u32 = 2;

/// Sizes in drawing pixels (see [`SUPERSAMPLE`]) for one chart. Everything scales with the
/// chart's image size, so that a larger image is the same picture at a higher resolution;
/// 800 × 500 image pixels is scale 1.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Metrics {
    /// Drawing pixels per pixel of an 800 × 500 image.
    scale: f64,
}

impl Metrics {
    /// The sizes for a chart of `width` × `height` image pixels.
    pub fn new(width: u32, height: u32) -> Metrics {
        let image_scale = (f64::from(width) / 800.0)
            .min(f64::from(height) / 500.0)
            .clamp(0.5, 3.0);
        Metrics {
            scale: image_scale * f64::from(SUPERSAMPLE),
        }
    }

    /// The sizes for a drawing area of `width` × `height` drawing pixels.
    pub(crate) fn for_drawing(width: u32, height: u32) -> Metrics {
        Metrics::new(width / SUPERSAMPLE, height / SUPERSAMPLE)
    }

    /// `pixels` at scale 1, scaled and rounded, at least 1.
    pub fn px(&self, pixels: f64) -> u32 {
        (pixels * self.scale).round().max(1.0) as u32
    }

    pub fn text(&self, pixels: f64) -> TextStyle<'static> {
        TextStyle::from((FontFamily::Name(FAMILY), pixels * self.scale)).color(&INK)
    }

    pub(crate) fn title_font(&self) -> TextStyle<'static> {
        self.text(22.0)
    }

    pub(crate) fn axis_label_font(&self) -> TextStyle<'static> {
        self.text(18.0)
    }

    pub(crate) fn tick_font(&self) -> TextStyle<'static> {
        self.text(15.0)
    }

    pub(crate) fn legend_font(&self) -> TextStyle<'static> {
        self.text(self.legend_font_size() / self.scale)
    }

    /// The legend's font size in drawing pixels.
    pub(crate) fn legend_font_size(&self) -> f64 {
        15.0 * self.scale
    }

    /// Distance between the lines of the legend.
    pub(crate) fn legend_line_height(&self) -> u32 {
        (1.35 * self.legend_font_size()).ceil() as u32
    }

    /// Padding inside the legend box.
    pub(crate) fn legend_margin(&self) -> u32 {
        self.px(8.0)
    }

    /// Distance of the legend box from the frame of the plot area.
    pub(crate) fn legend_inset(&self) -> u32 {
        self.px(10.0)
    }

    /// Width reserved for the line or swatch of a legend entry.
    pub(crate) fn legend_key_width(&self) -> u32 {
        self.px(28.0)
    }

    pub(crate) fn line_width(&self) -> u32 {
        self.px(2.0)
    }

    pub fn margin(&self) -> u32 {
        self.px(14.0)
    }

    pub(crate) fn tick_length(&self) -> i32 {
        self.px(5.0) as i32
    }

    /// Pixels along the x axis per labelled tick, about.
    pub(crate) fn x_tick_spacing(&self) -> f64 {
        110.0 * self.scale
    }

    /// Pixels along the y axis per labelled tick, about.
    pub(crate) fn y_tick_spacing(&self) -> f64 {
        60.0 * self.scale
    }
}
