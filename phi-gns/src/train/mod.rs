//! Training the GNS (thesis section 5.3): its pieces.
//!
//! - [`noise`]: DeepMind's random-walk noise on the input positions, and the matching target;
//! - [`adam`]: Adam over the named parameters, with DeepMind's learning-rate schedule;
//! - [`loss`]: the one-step loss of equation 5.1 on normalised accelerations;
//! - the data pipeline: [`rng`] (per-step generators), [`sampler`] (windows), [`cache`]
//!   (trajectories) and [`stream`] (batches read ahead on another thread).

pub mod adam;
pub mod cache;
pub mod loss;
pub mod noise;
pub mod rng;
pub mod sampler;
pub mod stream;

pub use adam::{Adam, AdamConfig, LearningRate};
pub use loss::{non_kinematic_mask, one_step_loss};
pub use noise::{RandomWalkNoise, random_walk_noise};
pub use rng::{RngStream, step_rng};
pub use sampler::{WindowRef, WindowSampler, WindowSpec};
pub use stream::{BatchConfig, BatchSource, BatchStream, HostBatch, HostExample};

use phi_core::AutodiffBackend;
use phi_core::tensor::Tensor;

use crate::model::{Gns, GnsKernels, GraphBatch, ModelError};

/// One optimisation step on the one-step loss: the loss of `model` on `batch` against `next`
/// (`[N, dim]`, counted where `mask` is 1), its gradients in every parameter, and Adam's update.
/// Returns the updated model and the loss before the update.
///
/// # Errors
/// As [`one_step_loss`]; [`ModelError::Input`] for a non-finite loss or gradient (nothing is
/// updated).
pub fn train_step<B: AutodiffBackend + GnsKernels>(
    model: &Gns<B>,
    adam: &mut Adam<B>,
    batch: &GraphBatch<B>,
    next: &Tensor<B>,
    mask: &Tensor<B>,
) -> Result<(Gns<B>, f32), ModelError> {
    let leaves = model.params().map(|_, t| t.require_grad());
    let tracked = model.with_params(leaves.clone())?;
    let loss = one_step_loss(&tracked, batch, next, mask)?;
    let value = loss.to_scalar()?;
    if !value.is_finite() {
        return Err(ModelError::Input {
            what: "loss",
            reason: format!("the one-step loss is {value}"),
        });
    }
    let wrt: Vec<&Tensor<B>> = leaves.iter().map(|(_, t)| t).collect();
    let gradients = loss.gradients(&wrt)?;
    let updated = adam.update(model.params(), &gradients)?;
    Ok((model.with_params(updated)?, value))
}
