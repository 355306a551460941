//! Text set in DejaVu Sans (embedded) through `ab_glyph`: measuring and rasterising one line.
//!
//! plotters is used without its own font features: enabling its `ab_glyph` feature would switch
//! every plotters user in the same build (criterion's report charts among them) to a font
//! registry in which nothing is registered, and their text would fail. Text is drawn here
//! instead, by the drawing backend of this crate ([`crate::canvas::Canvas`]).

use std::sync::OnceLock;

use ab_glyph::{Font, FontRef, GlyphId, PxScaleFont, ScaleFont, point};

use crate::PlotError;

/// The embedded DejaVu Sans, parsed once per process.
pub(crate) fn face() -> Result<&'static FontRef<'static>, PlotError> {
    static FACE: OnceLock<Option<FontRef<'static>>> = OnceLock::new();
    FACE.get_or_init(|| FontRef::try_from_slice(dejavu::sans::regular()).ok())
        .as_ref()
        .ok_or(PlotError::Font)
}

/// The glyphs of `text` at `size` pixels (ascent − descent) with their pen positions along the
/// baseline: horizontal advances plus kerning.
fn layout<'f>(
    font: &'f FontRef<'static>,
    text: &str,
    size: f64,
) -> (PxScaleFont<&'f FontRef<'static>>, Vec<(GlyphId, f32)>, f32) {
    let scaled = font.as_scaled(size as f32);
    let mut pen = 0.0f32;
    let mut previous: Option<GlyphId> = None;
    let mut glyphs = Vec::with_capacity(text.len());
    for c in text.chars() {
        let id = scaled.glyph_id(c);
        if let Some(previous) = previous {
            pen += scaled.kern(previous, id);
        }
        glyphs.push((id, pen));
        pen += scaled.h_advance(id);
        previous = Some(id);
    }
    (scaled, glyphs, pen)
}

/// Width and height in pixels of the box of `text` at `size` pixels: the advance of the line by
/// the font's ascent − descent (which is `size`).
pub(crate) fn extent(font: &FontRef<'static>, text: &str, size: f64) -> (f32, f32) {
    let (scaled, _, width) = layout(font, text, size);
    (width, scaled.height())
}

/// Rasterises `text` at `size` pixels, calling `put(x, y, coverage)` for every covered pixel,
/// with (0, 0) the top left of the box of [`extent`] (the baseline lies at the ascent).
pub(crate) fn rasterize(
    font: &FontRef<'static>,
    text: &str,
    size: f64,
    mut put: impl FnMut(i32, i32, f32),
) {
    let (scaled, glyphs, _) = layout(font, text, size);
    let ascent = scaled.ascent();
    for (id, pen) in glyphs {
        let glyph = id.with_scale_and_position(scaled.scale(), point(pen, ascent));
        if let Some(outline) = font.outline_glyph(glyph) {
            let bounds = outline.px_bounds();
            let (left, top) = (bounds.min.x as i32, bounds.min.y as i32);
            outline.draw(|x, y, coverage| put(left + x as i32, top + y as i32, coverage));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn text_extent_grows_with_the_text_and_the_size() {
        let font = face().unwrap();
        let (w1, h1) = extent(font, "MSE", 20.0);
        let (w2, _) = extent(font, "MSE over time", 20.0);
        let (w3, h3) = extent(font, "MSE", 40.0);
        assert!(w1 > 20.0 && w2 > 2.0 * w1, "{w1} {w2}");
        assert!((w3 - 2.0 * w1).abs() < 1.0, "{w1} {w3}");
        assert!(
            (h1 - 20.0).abs() < 0.01 && (h3 - 40.0).abs() < 0.01,
            "{h1} {h3}"
        );
    }

    /// Other plotters users in the same build (criterion's report charts) keep plotters' own
    /// text layout: this crate turns on no plotters font feature that would need registered
    /// fonts.
    #[test]
    fn plotters_default_text_layout_keeps_working() {
        use plotters::style::{FontDesc, FontFamily, FontStyle};
        let font = FontDesc::new(FontFamily::SansSerif, 12.0, FontStyle::Normal);
        assert!(font.box_size("label").is_ok());
    }

    #[test]
    fn glyphs_fall_inside_their_box() {
        let font = face().unwrap();
        let (w, h) = extent(font, "Ag×10⁻³", 30.0);
        let mut inked = 0;
        rasterize(font, "Ag×10⁻³", 30.0, |x, y, coverage| {
            assert!(x >= -1 && (x as f32) <= w + 1.0, "x = {x} outside 0..{w}");
            assert!(y >= -1 && (y as f32) <= h + 1.0, "y = {y} outside 0..{h}");
            if coverage > 0.5 {
                inked += 1;
            }
        });
        assert!(inked > 7 * 20, "{inked} pixels inked");
        // The characters of tick labels all have glyphs (id 0 is the missing-glyph box).
        for c in "0123456789.×−⁰¹²³⁴⁵⁶⁷⁸⁹⁻".chars() {
            assert_ne!(font.glyph_id(c).0, 0, "no glyph for {c}");
        }
    }
}
