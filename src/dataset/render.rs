//! `phi render`: one trajectory of a dataset as an animated GIF, and [`DatasetRenderer`], which
//! draws a dataset's frames (the rollout GIFs of `phi rollout` use it too).

use std::path::Path;

use anyhow::{Context, Result, bail};
use phi_gns::data::{Dataset, LIQUID, Metadata, read_metadata, read_trajectory};

use crate::output::{FrameStyle, GifWriter, KIND_LIQUID, KIND_OBSTACLE, RgbImage, render_frame};

/// Draws frames of stored positions of a 2D dataset: positions are mapped back to cells with
/// the metadata's `position_scale` and `position_offset`, on a grid of
/// `(max − min) / position_scale` cells per axis of the `bounds`; obstacle particles (type 0)
/// and liquid particles (type 1) get the renderer's two colours.
#[derive(Debug, Clone)]
pub struct DatasetRenderer {
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
        Ok(DatasetRenderer {
            scale: metadata.position_scale as f32,
            offset: metadata.position_offset as f32,
            resolution,
            upper,
            style: FrameStyle {
                pixels_per_cell,
                ..FrameStyle::default()
            },
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
/// # Errors
/// A missing dataset or trajectory, I/O errors.
pub fn render_trajectory(
    dir: &Path,
    split: &str,
    index: usize,
    out: &Path,
    pixels_per_cell: u32,
    frame_every: usize,
) -> Result<usize> {
    let metadata = read_metadata(dir)?;
    let count = metadata.splits.get(split).copied().with_context(|| {
        format!(
            "{}: no split {split:?} (the metadata lists {:?})",
            dir.display(),
            metadata.splits.keys().collect::<Vec<_>>()
        )
    })?;
    if index >= count {
        bail!(
            "{}: split {split} has {count} trajectories, no index {index}",
            dir.display()
        );
    }
    let trajectory = read_trajectory(&Dataset::trajectory_path(dir, split, index))?;
    if trajectory.dim != 2 {
        bail!(
            "rendering needs a 2D dataset, this one is {}D",
            trajectory.dim
        );
    }
    let renderer = DatasetRenderer::new(&metadata, pixels_per_cell)?;
    let kinds = DatasetRenderer::kinds(&trajectory.particle_type);
    let mut gif: Option<GifWriter> = None;
    let mut pictures = 0;
    for t in (0..trajectory.frames).step_by(frame_every.max(1)) {
        let image = renderer.render(trajectory.frame(t), &kinds)?;
        let writer = match &mut gif {
            Some(w) => w,
            None => gif.insert(GifWriter::create(out, image.width, image.height, 5)?),
        };
        writer.add_frame(&image)?;
        pictures += 1;
    }
    if let Some(writer) = gif {
        writer.finish()?;
    }
    Ok(pictures)
}
