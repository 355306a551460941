//! Evaluating a trained GNS as the thesis does (section 5.4, table B.1, figs. 5.6–5.7), and a
//! little beyond.
//!
//! Per test trajectory ([`evaluate_trajectory`]), over the liquid (non-kinematic) particles, in
//! f64 on the host:
//!
//! - **MSE-acc 1**: the one-step loss of eq. 5.1 on normalised accelerations, without noise, per
//!   dimension, averaged over every one-step window (latest input frame `C ..= F − 2`);
//! - **MSE 20**: rollouts of 20 steps started from the ground truth at frames `C, C + 20, …`
//!   (while 20 frames follow); each one's position MSE over its 20 predicted frames, particles
//!   and dimensions, averaged over the rollouts. (The thesis: "20 frames, taken at each 20 steps
//!   of the full 400-step rollouts" and "averaged over 20-step rollouts"; this reading fits both
//!   and table B.1's MSE 20 being ~500× below its MSE 400.)
//! - **MSE 400**: the full rollout from the first input window (frames `0 ..= C`, the 6-frame
//!   history for `C = 5`), predicting frames `C + 1 ..= F − 1`; the position MSE over all of
//!   them;
//! - **EMD** (eq. 5.3): per predicted frame, the exact optimal-transport cost between the
//!   predicted and the true liquid particles with uniform weights (squared Euclidean ground cost
//!   by default, POT's default), averaged over the frames;
//! - beyond the thesis: the debiased **Sinkhorn divergence** (LagrangeBench reports it; `ε`
//!   stated in [`EvalOptions`]), the relative **kinetic-energy error** and the **density**
//!   ratio (mean neighbour count of a liquid particle within a radius, predicted over true: the
//!   thesis finds that most variants compress the liquid, which makes it larger than 1).
//!
//! [`ModelSummary`] averages a model's trajectories (table B.1's row); [`Band`] gives the mean
//! and the min–max range per frame over the trajectories (fig. 5.7). Positions are in the
//! dataset's stored units.

pub mod metrics;
pub mod probe;
mod summary;
mod trajectory;

pub use probe::{ProbeResult, ProbeScene, probe, probe_scene};
pub use summary::{Band, ModelSummary, PlausibilitySummary};
pub use trajectory::{
    Curves, EmdCost, EvalOptions, OneStepErrors, Plausibility, TrajectoryComparison,
    TrajectoryEvaluation, compare_trajectories, evaluate_trajectory, evaluate_trajectory_with,
    mse_acc1, mse_acc1_in, one_step_errors,
};

use phi_core::point_sets::PointSetError;

use crate::model::ModelError;

/// What can go wrong in an evaluation.
#[derive(Debug, thiserror::Error)]
pub enum EvalError {
    /// The model failed (other than by blowing up, which is a result).
    #[error(transparent)]
    Model(#[from] ModelError),
    /// A point-set metric refused its inputs.
    #[error(transparent)]
    Metric(#[from] PointSetError),
    /// An input the evaluation cannot take.
    #[error("{what}: {reason}")]
    Input {
        /// The input.
        what: &'static str,
        /// What is wrong.
        reason: String,
    },
}
