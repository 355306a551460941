//! Training the GNS (thesis section 5.3): its pieces.
//!
//! - [`noise`]: DeepMind's random-walk noise on the input positions, and the matching target;
//! - [`adam`]: Adam over the named parameters, with DeepMind's learning-rate schedule;
//! - [`loss`]: the one-step loss of equation 5.1 on normalised accelerations;
//! - the data pipeline: [`rng`] (per-step generators), [`sampler`] (windows), [`cache`]
//!   (trajectories) and [`stream`] (batches read ahead on another thread).
//! - [`multistep`]: the multi-step loss of equation 5.2, the model run on its own predictions;
//! - [`pushforward`]: LagrangeBench's pushforward training, a one-step loss after unrolled
//!   steps without gradient, and its schedule.
//!
//! - [`average`]: a moving average of the weights over the steps, screened and kept instead
//!   of the weights of one step.
//!
//! [`train_step`] and [`train_step_with`] take one Adam step on a loss. A whole run, with its
//! presets ([`config`]), checkpoints ([`checkpoint`]), screening on the validation split
//! ([`screening`]) and files, is [`run::TrainingRun`]; `phi train` drives it.

pub mod adam;
pub mod average;
pub mod cache;
pub mod checkpoint;
pub mod config;
mod error;
pub mod loss;
pub mod multistep;
pub mod noise;
pub mod pushforward;
pub mod rng;
pub mod run;
pub mod sampler;
pub mod screening;
pub mod stream;

pub use adam::{Adam, AdamConfig, LearningRate};
pub use average::WeightAverage;
pub use config::TrainConfig;
pub use error::TrainError;
pub use loss::{ErrorNorm, acceleration_loss, non_kinematic_mask, one_step_loss};
pub use multistep::multi_step_loss;
pub use noise::{RandomWalkNoise, random_walk_noise};
pub use pushforward::{Pushforward, push_forward, pushforward_loss};
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
/// As [`one_step_loss`] and [`train_step_with`].
pub fn train_step<B: AutodiffBackend + GnsKernels>(
    model: &Gns<B>,
    adam: &mut Adam<B>,
    batch: &GraphBatch<B>,
    next: &Tensor<B>,
    mask: &Tensor<B>,
) -> Result<(Gns<B>, f32), ModelError> {
    train_step_with(model, adam, |tracked| {
        one_step_loss(tracked, batch, next, mask, ErrorNorm::Squared)
    })
}

/// One optimisation step on any loss: `loss` is called with `model` whose parameters are
/// trainable leaves and returns a one-element tensor ([`one_step_loss`], [`multi_step_loss`],
/// [`pushforward_loss`], ...); its gradients in every parameter go to Adam's update. Returns the
/// updated model and the loss before the update.
///
/// # Errors
/// Whatever `loss` returns; [`ModelError::Input`] for a loss that is not one value,
/// [`ModelError::NonFinite`] for a NaN or infinite loss or gradient (nothing is updated).
pub fn train_step_with<B, F>(
    model: &Gns<B>,
    adam: &mut Adam<B>,
    loss: F,
) -> Result<(Gns<B>, f32), ModelError>
where
    B: AutodiffBackend + GnsKernels,
    F: FnOnce(&Gns<B>) -> Result<Tensor<B>, ModelError>,
{
    let leaves = model.params().map(|_, t| t.require_grad());
    let tracked = model.with_params(leaves.clone())?;
    let loss = loss(&tracked)?;
    if loss.numel() != 1 {
        return Err(ModelError::Input {
            what: "loss",
            reason: format!("shape {:?}; a loss is one value", loss.shape()),
        });
    }
    let value = loss.to_scalar()?;
    if !value.is_finite() {
        return Err(ModelError::NonFinite {
            what: "loss",
            reason: format!("the loss is {value}"),
        });
    }
    let wrt: Vec<&Tensor<B>> = leaves.iter().map(|(_, t)| t).collect();
    let gradients = loss.gradients(&wrt)?;
    let updated = adam.update(model.params(), &gradients)?;
    Ok((model.with_params(updated)?, value))
}
