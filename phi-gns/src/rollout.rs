//! Rollouts: a trained GNS run forward from ground-truth frames, feeding its predictions back.
//!
//! A rollout starts from the `C + 1` frames of a trajectory ending at frame `start` and predicts
//! frames `start + 1 ..= start + steps`. Kinematic particles (obstacles, walls) take their next
//! positions from the ground truth at every step, as in DeepMind's evaluation, so a rollout
//! cannot run past the trajectory's last frame.

use crate::data::Trajectory;
use crate::model::{Gns, GnsKernels, GraphBatch, ModelError};

/// Where a rollout starts and how far it runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RolloutRange {
    /// The last ground-truth frame of the input window (at least `C`).
    pub start: usize,
    /// The number of predicted frames.
    pub steps: usize,
}

impl RolloutRange {
    /// From the first possible frame (`C`) to the end of a trajectory of `frames` frames.
    pub fn full(input_velocities: usize, frames: usize) -> Self {
        RolloutRange {
            start: input_velocities,
            steps: frames.saturating_sub(input_velocities + 1),
        }
    }

    /// Checks the range against a model's window and a trajectory's length.
    ///
    /// # Errors
    /// [`ModelError::Input`] when the window would begin before frame 0 or the rollout would
    /// end after the last frame.
    pub fn check(&self, input_velocities: usize, frames: usize) -> Result<(), ModelError> {
        if self.start < input_velocities {
            return Err(ModelError::Input {
                what: "rollout start",
                reason: format!(
                    "frame {} leaves no room for the {} frames before it that the model reads",
                    self.start, input_velocities
                ),
            });
        }
        // Checked: a step count near usize::MAX must be refused, not wrap around.
        if self
            .start
            .checked_add(self.steps)
            .is_none_or(|end| end >= frames)
        {
            return Err(ModelError::Input {
                what: "rollout steps",
                reason: format!(
                    "{} steps from frame {} end after the trajectory's last frame {} (kinematic \
                     particles follow the ground truth)",
                    self.steps,
                    self.start,
                    frames.saturating_sub(1)
                ),
            });
        }
        Ok(())
    }
}

/// Rolls `model` out on `trajectory` over `range`, calling `on_frame(step, positions)` with each
/// predicted frame (`step` counts from 1, `positions` is `[N, dim]` row-major in stored units)
/// as soon as it exists, so that a caller can stream frames to a file.
///
/// # Errors
/// [`ModelError::Input`] for a range or trajectory that does not fit the model;
/// [`ModelError::NonFinitePrediction`] at the first step with a NaN or infinite position (every
/// earlier frame has been handed to `on_frame`); whatever `on_frame` returns.
pub fn rollout<B: GnsKernels>(
    model: &Gns<B>,
    trajectory: &Trajectory,
    range: RolloutRange,
    device: &B::Device,
    mut on_frame: impl FnMut(usize, &[f32]) -> Result<(), ModelError>,
) -> Result<(), ModelError> {
    let config = &model.spec().config;
    let (dim, c) = (config.dim, config.input_velocities);
    if trajectory.dim != dim {
        return Err(ModelError::Input {
            what: "trajectory",
            reason: format!("{}D positions for a {dim}D model", trajectory.dim),
        });
    }
    range.check(c, trajectory.frames)?;
    let n = trajectory.particles;
    let kinematic: Vec<bool> = trajectory
        .particle_type
        .iter()
        .map(|t| model.spec().kinematic_types.contains(t))
        .collect();
    let mut history: Vec<Vec<f32>> = (range.start - c..=range.start)
        .map(|t| trajectory.frame(t).to_vec())
        .collect();
    let mut window = vec![0.0f32; n * (c + 1) * dim];
    for step in 1..=range.steps {
        fill_window(&history, n, dim, &mut window);
        let batch =
            GraphBatch::from_host(&window, &trajectory.particle_type, model.spec(), device)?;
        let mut next = model.next_positions(&batch)?.to_vec();
        let frame = range.start + step;
        let truth = trajectory.frame(frame);
        for (i, _) in kinematic.iter().enumerate().filter(|(_, k)| **k) {
            next[i * dim..(i + 1) * dim].copy_from_slice(&truth[i * dim..(i + 1) * dim]);
        }
        if let Some(bad) = next.iter().position(|x| !x.is_finite()) {
            return Err(ModelError::NonFinitePrediction {
                step,
                frame,
                particle: bad / dim,
            });
        }
        on_frame(step, &next)?;
        history.remove(0);
        history.push(next);
    }
    Ok(())
}

/// The predicted frames of [`rollout`] collected: `[steps, N, dim]` row-major.
///
/// # Errors
/// As [`rollout`] (the frames before a non-finite prediction are lost; use [`rollout`] to keep
/// them).
pub fn rollout_positions<B: GnsKernels>(
    model: &Gns<B>,
    trajectory: &Trajectory,
    range: RolloutRange,
    device: &B::Device,
) -> Result<Vec<f32>, ModelError> {
    let mut frames = Vec::with_capacity(range.steps * trajectory.particles * trajectory.dim);
    rollout(model, trajectory, range, device, |_, positions| {
        frames.extend_from_slice(positions);
        Ok(())
    })?;
    Ok(frames)
}

/// The position MSE of one frame: the mean of `(predicted − truth)²` over the particles that
/// are not `kinematic` and the `dim` components (0 when every particle is kinematic), in f64.
pub fn position_mse(predicted: &[f32], truth: &[f32], kinematic: &[bool], dim: usize) -> f64 {
    let mut sum = 0.0f64;
    let mut count = 0usize;
    for (i, _) in kinematic.iter().enumerate().filter(|(_, k)| !**k) {
        for a in i * dim..(i + 1) * dim {
            let d = f64::from(predicted[a]) - f64::from(truth[a]);
            sum += d * d;
            count += 1;
        }
    }
    if count == 0 { 0.0 } else { sum / count as f64 }
}

/// The model's input window `[N, C + 1, dim]` (row-major) of frames `frame − C ..= frame` of
/// `trajectory`, for `C = input_velocities`.
///
/// # Panics
/// If `frame < C` or `frame` is not a frame of the trajectory (check with
/// [`RolloutRange::check`]).
pub fn input_window(trajectory: &Trajectory, frame: usize, input_velocities: usize) -> Vec<f32> {
    let frames: Vec<&[f32]> = (frame - input_velocities..=frame)
        .map(|t| trajectory.frame(t))
        .collect();
    let mut window = vec![0.0; trajectory.particles * frames.len() * trajectory.dim];
    fill_window(&frames, trajectory.particles, trajectory.dim, &mut window);
    window
}

/// `window [N, C + 1, dim]` from `C + 1` frames `[N, dim]`, oldest first.
pub(crate) fn fill_window<F: AsRef<[f32]>>(
    history: &[F],
    n: usize,
    dim: usize,
    window: &mut [f32],
) {
    let frames = history.len();
    for i in 0..n {
        for (t, frame) in history.iter().enumerate() {
            let dst = (i * frames + t) * dim;
            window[dst..dst + dim].copy_from_slice(&frame.as_ref()[i * dim..(i + 1) * dim]);
        }
    }
}
