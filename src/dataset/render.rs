//! `phi render`: one trajectory of a dataset as an animated GIF, and [`DatasetRenderer`], which
//! draws a dataset's frames (the rollout GIFs of `phi rollout` use it too).

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use phi_gns::data::{Dataset, LIQUID, METADATA_FILE, Metadata};

use crate::output::target::{OutputFile, check_file};
use crate::output::{
    FrameStyle, GifWriter, KIND_LIQUID, KIND_OBSTACLE, MAX_PIXELS, RgbImage, render_frame,
};

/// Draws frames of stored positions of a 2D dataset: positions are mapped back to cells with
/// the metadata's `position_scale` and `position_offset`, on a grid of
/// `(max − min) / position_scale` cells per axis of the `bounds`; obstacle particles (type 0)
/// and liquid particles (type 1) get the renderer's two colours.
#[derive(Debug, Clone)]
pub(crate) struct DatasetRenderer {
    scale: f32,
    offset: f32,
    resolution: Vec<usize>,
    upper: Vec<f32>,
    style: FrameStyle,
}

impl DatasetRenderer {
    /// The renderer of a dataset's frames, `pixels_per_cell` pixels per cell.
    ///
    /// # Errors
    /// A dataset that is not 2D.
    pub fn new(metadata: &Metadata, pixels_per_cell: u32) -> Result<Self> {
        if metadata.dim != 2 {
            bail!(
                "rendering needs a 2D dataset, this one is {}D",
                metadata.dim
            );
        }
        let resolution: Vec<usize> = metadata
            .bounds
            .iter()
            .map(|[lo, hi]| ((hi - lo) / metadata.position_scale).round().max(1.0) as usize)
            .collect();
        let upper = resolution.iter().map(|&n| n as f32).collect();
        let style = FrameStyle {
            pixels_per_cell,
            ..FrameStyle::default()
        };
        if pixels_per_cell == 0 {
            bail!("--pixels-per-cell must be at least 1");
        }
        // In f64, so that no size overflows: the picture render_frame would draw.
        let side =
            |n: usize| n as f64 * f64::from(pixels_per_cell) + 2.0 * f64::from(style.frame_width);
        let (width, height) = (side(resolution[0]), side(resolution[1]));
        if width * height > MAX_PIXELS as f64 {
            bail!(
                "metadata keys bounds {:?} and position_scale {}: a grid of {}x{} cells, drawn at \
                 {pixels_per_cell} pixels per cell (--pixels-per-cell), is a {width:.0}x{height:.0} \
                 picture, more than the {MAX_PIXELS} pixels a picture may have",
                metadata.bounds,
                metadata.position_scale,
                resolution[0],
                resolution[1],
            );
        }
        Ok(DatasetRenderer {
            scale: metadata.position_scale as f32,
            offset: metadata.position_offset as f32,
            resolution,
            upper,
            style,
        })
    }

    /// The renderer's particle kinds of dataset particle types.
    pub fn kinds(particle_type: &[i64]) -> Vec<u8> {
        particle_type
            .iter()
            .map(|&t| {
                if t == LIQUID {
                    KIND_LIQUID
                } else {
                    KIND_OBSTACLE
                }
            })
            .collect()
    }

    /// One picture of the stored positions `frame` (`[n, 2]`) of particles of `kinds`
    /// ([`DatasetRenderer::kinds`]).
    ///
    /// # Errors
    /// Lengths that disagree, a picture too large.
    pub fn render(&self, frame: &[f32], kinds: &[u8]) -> Result<RgbImage> {
        let cells: Vec<f32> = frame
            .iter()
            .map(|x| (x - self.offset) / self.scale)
            .collect();
        Ok(render_frame(
            &cells,
            2,
            kinds,
            &[0.0, 0.0],
            &self.upper,
            &self.resolution,
            None,
            &self.style,
        )?)
    }
}

/// Renders trajectory `index` of `split` of the dataset in `dir` to the GIF `out`, one picture
/// every `frame_every` frames; returns the number of pictures (see [`DatasetRenderer`]).
///
/// The dataset is opened and checked ([`Dataset::open`]), and the trajectory read is checked
/// against its place (index, seed). The GIF is drawn into a temporary file renamed to `out` when
/// complete. An existing GIF `out` is replaced only with `force`; any other file is refused
/// ([`RENDER_OUTPUT`]).
///
/// # Errors
/// A missing or inconsistent dataset or trajectory, an `out` that would destroy another file,
/// I/O errors.
pub(crate) fn render_trajectory(
    dir: &Path,
    split: &str,
    index: usize,
    out: &Path,
    pixels_per_cell: u32,
    frame_every: usize,
    force: bool,
) -> Result<usize> {
    check_file(out, &RENDER_OUTPUT, force)?;
    let dataset = Dataset::open(dir)?;
    let metadata = dataset.metadata();
    let count = crate::cli::split_len(&dataset, dir, split)?;
    if index >= count {
        bail!(
            "{}: --trajectory {index}: split {split} has {count} trajectories, no index {index}",
            dir.display()
        );
    }
    let (trajectory, _) = dataset.read_with_stats(split, index)?;
    if trajectory.dim != 2 {
        bail!(
            "rendering needs a 2D dataset, this one is {}D",
            trajectory.dim
        );
    }
    let renderer = DatasetRenderer::new(metadata, pixels_per_cell)
        .with_context(|| format!("{}", dir.join(METADATA_FILE).display()))?;
    let kinds = DatasetRenderer::kinds(&trajectory.particle_type);
    let temp = temp_path(out)?;
    let result = (|| -> Result<usize> {
        let mut gif: Option<GifWriter> = None;
        let mut pictures = 0;
        for t in (0..trajectory.frames).step_by(frame_every.max(1)) {
            let image = renderer.render(trajectory.frame(t), &kinds)?;
            let writer = match &mut gif {
                Some(w) => w,
                None => gif.insert(GifWriter::create(&temp, image.width, image.height, 5)?),
            };
            writer.add_frame(&image)?;
            pictures += 1;
        }
        if let Some(writer) = gif {
            writer.finish()?;
        }
        std::fs::rename(&temp, out)
            .with_context(|| format!("renaming {} to {}", temp.display(), out.display()))?;
        Ok(pictures)
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&temp);
    }
    result
}

/// `.{name}.tmp-{pid}` beside `out`.
fn temp_path(out: &Path) -> Result<PathBuf> {
    let name = out
        .file_name()
        .with_context(|| format!("--out {} names no file", out.display()))?;
    let mut temp = std::ffi::OsString::from(".");
    temp.push(name);
    temp.push(format!(".tmp-{}", std::process::id()));
    Ok(out.with_file_name(temp))
}

/// What `phi render` writes: a GIF, replaced only with `--force`.
pub(crate) const RENDER_OUTPUT: OutputFile = OutputFile {
    command: "phi render",
    flag: "--out",
    kind: "a GIF",
    magic: &[b"GIF89a", b"GIF87a"],
};
