//! The one-step loss (thesis equation 5.1, DeepMind's training loss).

use phi_core::backend::BinaryOp;
use phi_core::tensor::Tensor;

use crate::model::{Gns, GnsKernels, GraphBatch, ModelError};

/// How a particle's error in normalised acceleration is scored: the per-component error `r`
/// goes through this and is summed over components.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum ErrorNorm {
    /// `r²`: the mean squared error of thesis equation 5.1 and DeepMind's loss.
    #[default]
    Squared,
    /// `r²` for `|r| ≤ δ`, `2δ|r| − δ²` beyond: twice Huber's loss, so that it equals the squared
    /// error where that is small and grows linearly on outliers (wall impacts), whose gradient
    /// then no longer outweighs the rest of the batch.
    Huber {
        /// `δ`, in normalised units.
        delta: f32,
    },
    /// `s² |r|² / (|t|² + s²)` per particle, `r` its error and `t` its target acceleration
    /// (normalised, summed over components): the squared error relative to the size of the
    /// particle's own acceleration, floored at `s`. A particle accelerating by much more than `s`
    /// (a wall impact) counts its relative error; one at rest counts its error as the squared
    /// error would. The weight is data: no gradient flows through the target's size.
    Relative {
        /// `s`, in normalised units.
        scale: f32,
    },
}

/// `1.0` for particles that count in the loss, `0.0` for kinematic ones: `[N]`.
///
/// # Errors
/// Only tensor errors (none for a valid device).
pub fn non_kinematic_mask<B: phi_core::Backend>(
    particle_type: &[i64],
    kinematic_types: &[i64],
    device: &B::Device,
) -> Result<Tensor<B>, ModelError> {
    let mask = non_kinematic_weights(particle_type, kinematic_types);
    Ok(Tensor::from_vec(mask, &[particle_type.len()], device)?)
}

/// [`non_kinematic_mask`]'s values on the host.
pub(crate) fn non_kinematic_weights(particle_type: &[i64], kinematic_types: &[i64]) -> Vec<f32> {
    particle_type
        .iter()
        .map(|t| {
            if kinematic_types.contains(t) {
                0.0
            } else {
                1.0
            }
        })
        .collect()
}

/// The loss weights of one graph, `[N]`: 0 for kinematic particles, `weight` for a counted
/// particle with a kinematic particle (an obstacle) within `radius` in `latest` (`[N, dim]`
/// positions), 1 for the other counted ones. With these as the mask, the losses of this module
/// are the weighted mean of the particles' errors; `weight = 1` gives
/// [`non_kinematic_mask`]'s values.
///
/// Brute force over the pairs of counted and kinematic particles: a training graph has ~10³
/// particles and ~10² obstacle particles.
pub fn obstacle_weights(
    latest: &[f32],
    dim: usize,
    particle_type: &[i64],
    kinematic_types: &[i64],
    radius: f32,
    weight: f32,
) -> Vec<f32> {
    let kinematic: Vec<&[f32]> = particle_type
        .iter()
        .enumerate()
        .filter(|(_, t)| kinematic_types.contains(t))
        .map(|(i, _)| &latest[i * dim..(i + 1) * dim])
        .collect();
    let reach = radius * radius;
    particle_type
        .iter()
        .enumerate()
        .map(|(i, t)| {
            if kinematic_types.contains(t) {
                return 0.0;
            }
            let p = &latest[i * dim..(i + 1) * dim];
            let near = kinematic.iter().any(|q| {
                p.iter()
                    .zip(q.iter())
                    .map(|(a, b)| (a - b) * (a - b))
                    .sum::<f32>()
                    <= reach
            });
            if near { weight } else { 1.0 }
        })
        .collect()
}

/// The error (squared, or as `norm` says) between the predicted and the target normalised
/// acceleration, summed over dimensions and averaged over the particles of `mask` (`[N]`, 1 where a particle counts): a
/// one-element tensor, differentiable in the model's parameters and the batch's positions. The
/// target is the acceleration that takes the window of `batch` to `next` (`[N, dim]`, with a
/// noisy window: the adjusted next positions of
/// [`RandomWalkNoise::adjust_target`](super::RandomWalkNoise::adjust_target)).
///
/// # Errors
/// [`ModelError::Input`] when no particle counts (the mean would be 0/0), and shape errors.
pub fn one_step_loss<B: GnsKernels>(
    model: &Gns<B>,
    batch: &GraphBatch<B>,
    next: &Tensor<B>,
    mask: &Tensor<B>,
    norm: ErrorNorm,
) -> Result<Tensor<B>, ModelError> {
    let target = model.target_acceleration(batch, next)?;
    acceleration_loss(model, batch, &target, mask, norm)
}

/// The loss of [`one_step_loss`] against a given normalised target acceleration `target`
/// (`[N, dim]`, in the units of [`Gns::normalised_acceleration`]): the error of `norm` summed
/// over dimensions and averaged over the particles of `mask`.
///
/// # Errors
/// [`ModelError::Input`] when no particle counts or `mask` is not `[N]`, and shape errors.
pub fn acceleration_loss<B: GnsKernels>(
    model: &Gns<B>,
    batch: &GraphBatch<B>,
    target: &Tensor<B>,
    mask: &Tensor<B>,
    norm: ErrorNorm,
) -> Result<Tensor<B>, ModelError> {
    let counted = counted_particles(batch, mask)?;
    let predicted = model.normalised_acceleration(batch)?;
    masked_error(&predicted, target, mask, counted, norm)
}

/// The number of particles that count in the loss: the sum of `mask`, checked to be `[N]` and
/// positive.
pub(crate) fn counted_particles<B: phi_core::Backend>(
    batch: &GraphBatch<B>,
    mask: &Tensor<B>,
) -> Result<f32, ModelError> {
    let n = batch.positions().shape()[0];
    if mask.shape() != [n] {
        return Err(ModelError::Input {
            what: "loss mask",
            reason: format!("shape {:?} for {n} particles", mask.shape()),
        });
    }
    let counted = mask.sum().to_scalar()?;
    if counted <= 0.0 {
        return Err(ModelError::Input {
            what: "loss mask",
            reason: "no particle of the batch counts in the loss (all are kinematic)".into(),
        });
    }
    Ok(counted)
}

/// `Σ_i mask_i Σ_a (predicted_ia − target_ia)² / counted`.
pub(crate) fn squared_error<B: phi_core::Backend>(
    predicted: &Tensor<B>,
    target: &Tensor<B>,
    mask: &Tensor<B>,
    counted: f32,
) -> Result<Tensor<B>, ModelError> {
    masked_error(predicted, target, mask, counted, ErrorNorm::Squared)
}

/// `Σ_i mask_i e_i / counted`, `e_i` particle `i`'s error of `norm` (summed over components).
pub(crate) fn masked_error<B: phi_core::Backend>(
    predicted: &Tensor<B>,
    target: &Tensor<B>,
    mask: &Tensor<B>,
    counted: f32,
    norm: ErrorNorm,
) -> Result<Tensor<B>, ModelError> {
    let residual = predicted.binary(BinaryOp::Sub, target)?;
    let per_particle = match norm {
        ErrorNorm::Squared => residual.square().sum_axis(1)?,
        ErrorNorm::Huber { delta } => {
            // q = min(|r|, δ): q² + 2δ(|r| − q) is r² inside δ and 2δ|r| − δ² outside.
            let size = residual.abs();
            let inner = size.clamp(0.0, delta);
            (inner.square() + size.binary(BinaryOp::Sub, &inner)? * (2.0 * delta)).sum_axis(1)?
        }
        ErrorNorm::Relative { scale } => {
            let floor = scale * scale;
            let size = target.detach().square().sum_axis(1)?;
            let weight = floor / (size + floor);
            residual
                .square()
                .sum_axis(1)?
                .binary(BinaryOp::Mul, &weight)?
        }
    };
    Ok(per_particle.binary(BinaryOp::Mul, mask)?.sum() / counted)
}
