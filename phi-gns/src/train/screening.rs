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
//!   MSE 400, by which the thesis picks its checkpoints;
//!
//! and, where asked (`emd_every > 0`), a third:
//!
//! - **rollout EMD**: the exact earth mover's distance (squared Euclidean ground cost) between
//!   the predicted and the true liquid of every `emd_every`-th predicted frame of those same
//!   rollouts (and of the last), averaged over those frames, then over the trajectories. Every
//!   frame is the evaluation's EMD (`phi eval`); a sample of the frames costs a fraction of it.
//!   Rollout MSE rewards a prediction near the mean of the possible futures, EMD one whose liquid
//!   sits where FLIP's does, so the two may pick different checkpoints.
//!
//! The screening runs on whatever backend the caller passes the model on; `phi train` moves the
//! weights to the fast forward-only host backend for it.

use phi_core::point_sets::{EmdSolver, GroundCost};

use crate::data::Trajectory;
use crate::eval::metrics::liquid_positions;
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
    /// The rollout EMD (stored position units²), where asked; infinite where a rollout blew up.
    pub emd: Option<f64>,
}

/// What a screening measures: one-step windows every `window_stride` frames, rollouts of
/// `rollout_steps` steps (capped at each trajectory's length) and, for `emd_every > 0`, the EMD
/// of every `emd_every`-th predicted frame of them.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct ScreeningPlan {
    /// One-step windows every this many frames.
    pub window_stride: usize,
    /// Steps of each rollout.
    pub rollout_steps: usize,
    /// The EMD of every this many predicted frames (and of the last); 0: none.
    pub emd_every: usize,
}

/// Screens `model` on `trajectories` as `plan` says.
///
/// # Errors
/// [`ModelError::Input`] for no trajectories, a trajectory too short for one window, or one
/// with only kinematic particles. A rollout that blows up (a non-finite position) makes the
/// rollout MSE and EMD infinite.
pub(crate) fn screen<B: GnsKernels>(
    model: &Gns<B>,
    trajectories: &[Trajectory],
    plan: ScreeningPlan,
    device: &B::Device,
) -> Result<Screening, ModelError> {
    let ScreeningPlan {
        window_stride,
        rollout_steps,
        emd_every,
    } = plan;
    let c = model.spec().config.input_velocities;
    if trajectories.is_empty() {
        return Err(ModelError::Input {
            what: "screening",
            reason: "no validation trajectories".into(),
        });
    }
    let (mut acc_sum, mut windows) = (0.0f64, 0usize);
    let (mut rollout_sum, mut used_steps) = (0.0f64, usize::MAX);
    let mut emd_sum = 0.0f64;
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
        let liquid: Vec<bool> = kinematic.iter().map(|k| !k).collect();
        let dim = trajectory.dim;
        let mut sum = 0.0;
        // Sampled frames are further apart than consecutive ones, but the previous assignment
        // is still a good start.
        let mut solver = EmdSolver::new();
        let (mut emd, mut emd_frames) = (0.0f64, 0usize);
        let ran = rollout(
            model,
            trajectory,
            RolloutRange { start: c, steps },
            device,
            |step, positions| {
                let truth = trajectory.frame(c + step);
                sum += position_mse(positions, truth, &kinematic, dim);
                if emd_every > 0 && (step % emd_every == 0 || step == steps) {
                    emd += solver
                        .solve(
                            &liquid_positions(positions, &liquid, dim),
                            &liquid_positions(truth, &liquid, dim),
                            dim,
                            GroundCost::SquaredEuclidean,
                        )
                        .map_err(|e| ModelError::Input {
                            what: "screening",
                            reason: format!("EMD of step {step}: {e}"),
                        })?;
                    emd_frames += 1;
                }
                Ok(())
            },
        );
        match ran {
            Ok(()) => {
                rollout_sum += sum / steps as f64;
                emd_sum += emd / emd_frames.max(1) as f64;
            }
            // A model early in training may fling particles to infinity: its rollout error is
            // infinite, which is a screening result, not a reason to stop training.
            Err(ModelError::NonFinitePrediction { .. }) => {
                rollout_sum = f64::INFINITY;
                emd_sum = f64::INFINITY;
            }
            Err(e) => return Err(e),
        }
    }
    Ok(Screening {
        mse_acc1: acc_sum / windows as f64,
        rollout_mse: rollout_sum / trajectories.len() as f64,
        rollout_steps: used_steps,
        emd: (emd_every > 0).then(|| emd_sum / trajectories.len() as f64),
    })
}
