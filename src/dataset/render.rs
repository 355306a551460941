//! `phi render`: one trajectory of a dataset as an animated GIF.

use std::path::Path;

use anyhow::{Context, Result, bail};
use phi_gns::data::{Dataset, LIQUID, read_metadata, read_trajectory};

use crate::output::{FrameStyle, GifWriter, KIND_LIQUID, KIND_OBSTACLE, render_frame};

/// Renders trajectory `index` of `split` of the dataset in `dir` to the GIF `out`, one picture
/// every `frame_every` frames; returns the number of pictures. Stored positions are mapped back
/// to cells with the metadata's `position_scale` and `position_offset`; obstacle particles
/// (type 0) and liquid particles (type 1) get the renderer's two colours.
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
    let dim = trajectory.dim;
    if dim != 2 {
        bail!("rendering needs a 2D dataset, this one is {dim}D");
    }
    let (scale, offset) = (
        metadata.position_scale as f32,
        metadata.position_offset as f32,
    );
    let resolution: Vec<usize> = metadata
        .bounds
        .iter()
        .map(|[lo, hi]| ((hi - lo) / metadata.position_scale).round().max(1.0) as usize)
        .collect();
    let upper: Vec<f32> = resolution.iter().map(|&n| n as f32).collect();
    let kinds: Vec<u8> = trajectory
        .particle_type
        .iter()
        .map(|&t| {
            if t == LIQUID {
                KIND_LIQUID
            } else {
                KIND_OBSTACLE
            }
        })
        .collect();
    let style = FrameStyle {
        pixels_per_cell,
        ..FrameStyle::default()
    };
    let mut gif: Option<GifWriter> = None;
    let mut pictures = 0;
    for t in (0..trajectory.frames).step_by(frame_every.max(1)) {
        let cells: Vec<f32> = trajectory
            .frame(t)
            .iter()
            .map(|x| (x - offset) / scale)
            .collect();
        let image = render_frame(
            &cells,
            dim,
            &kinds,
            &[0.0, 0.0],
            &upper,
            &resolution,
            None,
            &style,
        )?;
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
