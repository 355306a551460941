//! Screening during training (thesis fig. 5.5): the model of the moment on the validation split.
//!
//! Two numbers per screening, both in f64 and both over the non-kinematic particles:
//!
//! - **MSE-acc 1**: the squared error of the normalised one-step accelerations (eq. 5.1, no
//!   noise), averaged over particles and dimensions within a window, then over the windows
//!   (latest input frames `C, C + stride, …` of every screened trajectory);
//! - **rollout MSE**: the position error of a rollout from the first full input window of each
//!   trajectory (frame `C`), averaged over its predicted frames, particles and dimensions, then
//!   over the trajectories. With the rollout as long as the trajectory it is the thesis's
//!   MSE 400, by which the thesis picks its checkpoints.
//!
//! The screening runs on whatever backend the caller passes the model on; `phi train` moves the
//! weights to the fast forward-only host backend for it.

use crate::data::Trajectory;
use crate::eval::mse_acc1;
use crate::model::{Gns, GnsKernels, ModelError};
use crate::rollout::{RolloutRange, position_mse, rollout};

/// The result of one screening.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Screening {
    /// MSE-acc 1 (normalised acceleration units²).
    pub mse_acc1: f64,
    /// The rollout position MSE (stored position units²).
    pub rollout_mse: f64,
    /// The rollout length used (shorter than asked where a trajectory is short).
    pub rollout_steps: usize,
}

/// Screens `model` on `trajectories`: one-step windows every `window_stride` frames and
/// rollouts of `rollout_steps` steps (capped at each trajectory's length).
///
/// # Errors
/// [`ModelError::Input`] for no trajectories, a trajectory too short for one window, or one
/// with only kinematic particles. A rollout that blows up (a non-finite position) makes the
/// rollout MSE infinite.
pub fn screen<B: GnsKernels>(
    model: &Gns<B>,
    trajectories: &[Trajectory],
    window_stride: usize,
    rollout_steps: usize,
    device: &B::Device,
) -> Result<Screening, ModelError> {
    let c = model.spec().config.input_velocities;
    if trajectories.is_empty() {
        return Err(ModelError::Input {
            what: "screening",
            reason: "no validation trajectories".into(),
        });
    }
    let (mut acc_sum, mut windows) = (0.0f64, 0usize);
    let (mut rollout_sum, mut used_steps) = (0.0f64, usize::MAX);
    for trajectory in trajectories {
        let frames = trajectory.frames;
        if frames < c + 2 {
            return Err(ModelError::Input {
                what: "screening",
                reason: format!(
                    "a validation trajectory of {frames} frames has no window of {} frames and a \
                     target",
                    c + 1
                ),
            });
        }
        let (mse, count) = mse_acc1(model, trajectory, window_stride, device)?;
        acc_sum += mse * count as f64;
        windows += count;
        let steps = rollout_steps.min(frames - 1 - c);
        used_steps = used_steps.min(steps);
        let kinematic = model.spec().kinematic(&trajectory.particle_type);
        let mut sum = 0.0;
        let ran = rollout(
            model,
            trajectory,
            RolloutRange { start: c, steps },
            device,
            |step, positions| {
                let truth = trajectory.frame(c + step);
                sum += position_mse(positions, truth, &kinematic, trajectory.dim);
                Ok(())
            },
        );
        match ran {
            Ok(()) => rollout_sum += sum / steps as f64,
            // A model early in training may fling particles to infinity: its rollout error is
            // infinite, which is a screening result, not a reason to stop training.
            Err(ModelError::NonFinitePrediction { .. }) => rollout_sum = f64::INFINITY,
            Err(e) => return Err(e),
        }
    }
    Ok(Screening {
        mse_acc1: acc_sum / windows as f64,
        rollout_mse: rollout_sum / trajectories.len() as f64,
        rollout_steps: used_steps,
    })
}
