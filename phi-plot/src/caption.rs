//! Text on pictures that are not charts: a caption above each panel of a rollout GIF, a frame
//! counter. The same DejaVu Sans as the charts, anti-aliased by blending towards the colour.

use crate::PlotError;
use crate::text;

/// Width and height in pixels of the box that [`draw_text`] fills with `text` at `size` pixels
/// (ascent − descent), rounded up.
///
/// # Errors
/// [`PlotError::Font`] when the embedded font cannot be parsed.
pub fn text_size(text: &str, size: f64) -> Result<(u32, u32), PlotError> {
    let (width, height) = text::extent(text::face()?, text, size);
    Ok((width.ceil() as u32, height.ceil() as u32))
}

/// Draws one line of `text` at `size` pixels into `rgb`, an RGB image of `width · height`
/// pixels (3 bytes each, rows from the top), with the top left of its box at (`x`, `y`).
/// Each covered pixel is blended towards `color` by the glyph's coverage; what falls outside the
/// image is clipped.
///
/// # Errors
/// [`PlotError::Font`] when the embedded font cannot be parsed, [`PlotError::Layout`] when `rgb`
/// does not hold `width · height` pixels.
pub fn draw_text(
    rgb: &mut [u8],
    (width, height): (u32, u32),
    text: &str,
    (x, y): (i32, i32),
    size: f64,
    color: [u8; 3],
) -> Result<(), PlotError> {
    if rgb.len() as u64 != 3 * u64::from(width) * u64::from(height) {
        return Err(PlotError::Layout {
            plot: format!("caption '{text}'"),
            reason: format!(
                "the image holds {} bytes, not the {} of {width}x{height} RGB pixels",
                rgb.len(),
                3 * u64::from(width) * u64::from(height)
            ),
        });
    }
    let font = text::face()?;
    text::rasterize(font, text, size, |px, py, coverage| {
        let (px, py) = (x + px, y + py);
        if px < 0 || py < 0 || px as u32 >= width || py as u32 >= height {
            return;
        }
        let at = 3 * (py as usize * width as usize + px as usize);
        let a = coverage.clamp(0.0, 1.0);
        for (channel, target) in rgb[at..at + 3].iter_mut().zip(color) {
            *channel = (f32::from(*channel) * (1.0 - a) + f32::from(target) * a).round() as u8;
        }
    });
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn text_darkens_pixels_inside_its_box_only() {
        let (w, h) = (120u32, 40u32);
        let mut rgb = vec![255u8; (3 * w * h) as usize];
        let (tw, th) = text_size("truth 12", 16.0).unwrap();
        assert!(tw > 30 && tw < 100 && (15..=20).contains(&th), "{tw}x{th}");
        draw_text(&mut rgb, (w, h), "truth 12", (10, 5), 16.0, [0, 0, 0]).unwrap();
        let dark = |x: u32, y: u32| rgb[(3 * (y * w + x)) as usize] < 128;
        let mut inside = 0;
        for y in 0..h {
            for x in 0..w {
                let in_box = (10..10 + tw + 1).contains(&x) && (5..5 + th + 1).contains(&y);
                if dark(x, y) {
                    assert!(in_box, "dark pixel ({x}, {y}) outside the text box");
                    inside += 1;
                }
            }
        }
        assert!(inside > 40, "only {inside} dark pixels");
    }

    #[test]
    fn text_is_clipped_at_the_edges_and_sizes_are_checked() {
        let (w, h) = (20u32, 10u32);
        let mut rgb = vec![255u8; (3 * w * h) as usize];
        draw_text(&mut rgb, (w, h), "clipped text", (-5, -3), 14.0, [0, 0, 0]).unwrap();
        assert!(rgb.iter().any(|&c| c < 255));
        let mut short = vec![0u8; 5];
        assert!(matches!(
            draw_text(&mut short, (w, h), "x", (0, 0), 12.0, [0, 0, 0]),
            Err(PlotError::Layout { .. })
        ));
    }
}
