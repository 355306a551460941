//! [`Bitmap`], a rendered image, and writing it as PNG atomically.

use std::fs::File;
use std::io::Write;
use std::path::{Path, PathBuf};

use plotters::prelude::{IntoDrawingArea, WHITE};

use crate::PlotError;
use crate::canvas::Canvas;
use crate::chart::Area;
use crate::error::{draw_error, plot_name};
use crate::style::SUPERSAMPLE;
use crate::text;

/// An 8-bit RGB image: `rgb` holds `width · height · 3` bytes, row by row from the top left.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Bitmap {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// The pixels, `[r, g, b]` each, rows from top to bottom.
    pub rgb: Vec<u8>,
}

impl Bitmap {
    /// The colour of pixel (`x`, `y`), counted from the top left; `None` outside the image.
    pub fn pixel(&self, x: u32, y: u32) -> Option<[u8; 3]> {
        if x >= self.width || y >= self.height {
            return None;
        }
        let i = 3 * (y as usize * self.width as usize + x as usize);
        Some([self.rgb[i], self.rgb[i + 1], self.rgb[i + 2]])
    }

    /// Writes the image as an 8-bit RGB PNG file, atomically: into `.{name}.tmp-{pid}` beside
    /// `path`, synced, then renamed to `path`, so that a reader never sees half a file. On error
    /// `path` is left as it was.
    pub fn write_png(&self, path: impl AsRef<Path>) -> Result<(), PlotError> {
        let path = path.as_ref();
        let bytes = self.encode_png(path)?;
        write_atomic(path, &bytes)
    }

    /// The PNG file of this image, in memory. `path` only names the file in errors.
    fn encode_png(&self, path: &Path) -> Result<Vec<u8>, PlotError> {
        let png_error = |source| PlotError::Png {
            path: path.to_path_buf(),
            source,
        };
        let mut bytes = Vec::new();
        let mut encoder = png::Encoder::new(&mut bytes, self.width, self.height);
        encoder.set_color(png::ColorType::Rgb);
        encoder.set_depth(png::BitDepth::Eight);
        let mut writer = encoder.write_header().map_err(png_error)?;
        writer.write_image_data(&self.rgb).map_err(png_error)?;
        writer.finish().map_err(png_error)?;
        Ok(bytes)
    }
}

/// The smallest image that holds a chart's axes and labels, in pixels.
pub const MIN_SIZE: (u32, u32) = (240, 160);

/// The largest image side, in pixels (a guard against sizes that cannot be allocated).
pub const MAX_SIDE: u32 = 16384;

/// Checks that an image of `size` can hold a chart: at least [`MIN_SIZE`], at most
/// [`MAX_SIDE`] on each side.
pub(crate) fn check_size(title: &str, (width, height): (u32, u32)) -> Result<(), PlotError> {
    let (min_width, min_height) = MIN_SIZE;
    if width < min_width || height < min_height || width > MAX_SIDE || height > MAX_SIDE {
        return Err(PlotError::Layout {
            plot: plot_name(title),
            reason: format!(
                "size {width}×{height} pixels is outside {min_width}×{min_height} to \
                 {MAX_SIDE}×{MAX_SIDE}"
            ),
        });
    }
    Ok(())
}

/// Renders `draw` onto a white canvas for a `width` × `height` image and returns the image with
/// whatever `draw` returns. The canvas has [`SUPERSAMPLE`] times the resolution in each
/// direction and is averaged down. `title` names the plot in errors.
pub(crate) fn render_with<T>(
    title: &str,
    (width, height): (u32, u32),
    draw: impl FnOnce(&Area<'_>) -> Result<T, PlotError>,
) -> Result<(Bitmap, T), PlotError> {
    text::face()?;
    let (fine_width, fine_height) = (width * SUPERSAMPLE, height * SUPERSAMPLE);
    let mut fine = vec![255u8; fine_width as usize * fine_height as usize * 3];
    let result = {
        let root = Canvas::new(&mut fine, (fine_width, fine_height)).into_drawing_area();
        root.fill(&WHITE).map_err(draw_error(title))?;
        let result = draw(&root)?;
        root.present().map_err(draw_error(title))?;
        result
    };
    Ok((downsample(&fine, width, height, SUPERSAMPLE), result))
}

/// The `width` × `height` image whose pixels are the means of `factor` × `factor` blocks of the
/// RGB image `fine` (`width · factor` pixels wide).
fn downsample(fine: &[u8], width: u32, height: u32, factor: u32) -> Bitmap {
    let (width_us, factor_us) = (width as usize, factor as usize);
    let fine_row = width_us * factor_us * 3;
    let block = factor * factor;
    let mut rgb = Vec::with_capacity(width_us * height as usize * 3);
    for y in 0..height as usize {
        for x in 0..width_us {
            let mut sum = [0u32; 3];
            for dy in 0..factor_us {
                let row = (y * factor_us + dy) * fine_row;
                for dx in 0..factor_us {
                    let i = row + (x * factor_us + dx) * 3;
                    for (s, &v) in sum.iter_mut().zip(&fine[i..i + 3]) {
                        *s += u32::from(v);
                    }
                }
            }
            rgb.extend(sum.map(|s| ((s + block / 2) / block) as u8));
        }
    }
    Bitmap { width, height, rgb }
}

/// `.{name}.tmp-{pid}` beside `path`.
fn temp_path(path: &Path) -> Result<PathBuf, PlotError> {
    let name = path.file_name().ok_or_else(|| PlotError::Io {
        path: path.to_path_buf(),
        action: "cannot write to",
        source: std::io::Error::new(std::io::ErrorKind::InvalidInput, "not a file name"),
    })?;
    let mut temp = std::ffi::OsString::from(".");
    temp.push(name);
    temp.push(format!(".tmp-{}", std::process::id()));
    Ok(path.with_file_name(temp))
}

/// Writes `bytes` to `path` through a temporary file in the same directory: write, sync, rename.
/// The temporary file is removed if any step fails.
fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), PlotError> {
    let temp = temp_path(path)?;
    let io = |path: &Path, action| {
        let path = path.to_path_buf();
        move |source| PlotError::Io {
            path,
            action,
            source,
        }
    };
    let result = (|| {
        let mut file = File::create(&temp).map_err(io(&temp, "cannot create"))?;
        file.write_all(bytes).map_err(io(&temp, "cannot write"))?;
        file.sync_all().map_err(io(&temp, "cannot sync"))?;
        drop(file);
        std::fs::rename(&temp, path).map_err(io(path, "cannot rename a temporary file to"))
    })();
    if result.is_err() {
        // Best effort: the temporary file may not even exist.
        let _ = std::fs::remove_file(&temp);
    }
    result
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn downsampling_averages_blocks() {
        // A 4 × 2 image of 2 × 2 blocks: black | white, and one block half red.
        #[rustfmt::skip]
        let fine: Vec<u8> = [
            [0, 0, 0], [0, 0, 0], [255, 255, 255], [255, 0, 0],
            [0, 0, 0], [0, 0, 0], [255, 255, 255], [255, 0, 0],
        ].concat();
        let image = downsample(&fine, 2, 1, 2);
        assert_eq!(image.pixel(0, 0), Some([0, 0, 0]));
        assert_eq!(image.pixel(1, 0), Some([255, 128, 128]));
    }

    #[test]
    fn temp_file_sits_beside_the_target_and_is_gone_after_writing() {
        let dir = std::env::temp_dir().join(format!("phi-plot-atomic-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("out.png");
        let temp = temp_path(&path).unwrap();
        assert_eq!(temp.parent(), Some(dir.as_path()));
        assert_eq!(
            temp.file_name().unwrap().to_str().unwrap(),
            format!(".out.png.tmp-{}", std::process::id())
        );
        std::fs::write(&path, b"old").unwrap();
        write_atomic(&path, b"new").unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), b"new");
        assert!(!temp.exists());
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn failed_write_names_the_file_and_leaves_no_temp() {
        let path = Path::new("/nonexistent-dir-for-phi-plot-tests/out.png");
        let err = write_atomic(path, b"x").unwrap_err();
        assert!(
            err.to_string()
                .contains("/nonexistent-dir-for-phi-plot-tests/")
        );
        assert!(!temp_path(path).unwrap().exists());
    }
}
