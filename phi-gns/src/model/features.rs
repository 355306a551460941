//! The encoder preprocessor and decoder postprocessor of the GNS (DeepMind's
//! `_encoder_preprocessor` and `_decoder_postprocessor`): node and edge features from a window of
//! positions, and positions from a normalised acceleration.
//!
//! Node features, in column order: the `C` normalised velocities oldest first (`v₀ₓ v₀ᵧ v₁ₓ …`),
//! the distances of the latest position to the lower bounds per axis and then to the upper bounds
//! per axis, divided by `R` times the boundary horizon (1 unless the model says otherwise) and
//! clipped to `[−1, 1]` (when the model has boundary features), and
//! the particle-type embedding (with more than one type). Edge features: `(p_s − p_r) / R` per
//! axis, then its norm.

use phi_core::backend::{Backend, BinaryOp};
use phi_core::tensor::{IntTensor, Tensor};

use super::{GraphBatch, ModelError, Parameters};

/// The per-component constants of the pre- and postprocessor, each a `[dim]` tensor.
#[derive(Debug, Clone)]
pub(crate) struct Normalisers<B: Backend> {
    /// The mean velocity.
    pub vel_mean: Tensor<B>,
    /// `sqrt(vel_std² + σ²)`.
    pub vel_scale: Tensor<B>,
    /// The mean acceleration.
    pub acc_mean: Tensor<B>,
    /// `sqrt(acc_std² + σ²)`.
    pub acc_scale: Tensor<B>,
    /// The lower bound of each axis.
    pub lower: Tensor<B>,
    /// The upper bound of each axis.
    pub upper: Tensor<B>,
}

/// The velocities `p_{t+1} − p_t` of a window `[N, C + 1, dim]`: `[N, C, dim]`.
pub(crate) fn window_velocities<B: Backend>(
    positions: &Tensor<B>,
) -> Result<Tensor<B>, ModelError> {
    let steps = positions.shape()[1];
    let later = positions.narrow(1, 1..steps)?;
    let earlier = positions.narrow(1, 0..steps - 1)?;
    Ok(later.binary(BinaryOp::Sub, &earlier)?)
}

/// The latest positions of a window `[N, C + 1, dim]`: `[N, dim]`.
pub(crate) fn latest_positions<B: Backend>(positions: &Tensor<B>) -> Result<Tensor<B>, ModelError> {
    let shape = positions.shape();
    Ok(positions
        .narrow(1, shape[1] - 1..shape[1])?
        .reshape(&[shape[0], shape[2]])?)
}

/// The positions before the latest of a window `[N, C + 1, dim]`: `[N, dim]`.
pub(crate) fn previous_positions<B: Backend>(
    positions: &Tensor<B>,
) -> Result<Tensor<B>, ModelError> {
    let shape = positions.shape();
    Ok(positions
        .narrow(1, shape[1] - 2..shape[1] - 1)?
        .reshape(&[shape[0], shape[2]])?)
}

/// Node features `[N, node_features]` of a batch (see the [module docs](self)); the boundary
/// distances are divided by `boundary_scale` (`R · boundary_horizon`), left out for `None`.
pub(crate) fn node_features<B: Backend>(
    batch: &GraphBatch<B>,
    params: &Parameters<B>,
    normalisers: &Normalisers<B>,
    boundary_scale: Option<f32>,
    embedding: bool,
) -> Result<Tensor<B>, ModelError> {
    let positions = batch.positions();
    let [n, window, dim] = positions.shape()[..] else {
        unreachable!("GraphBatch keeps a rank-3 window")
    };
    let velocities = window_velocities(positions)?
        .binary(BinaryOp::Sub, &normalisers.vel_mean)?
        .binary(BinaryOp::Div, &normalisers.vel_scale)?;
    let mut columns = vec![velocities.reshape(&[n, (window - 1) * dim])?];
    if let Some(scale) = boundary_scale {
        let latest = latest_positions(positions)?;
        let to_lower = latest.binary(BinaryOp::Sub, &normalisers.lower)? / scale;
        let to_upper = normalisers.upper.binary(BinaryOp::Sub, &latest)? / scale;
        columns.push(to_lower.clamp(-1.0, 1.0));
        columns.push(to_upper.clamp(-1.0, 1.0));
    }
    if embedding {
        columns.push(
            params
                .get("embedding.weight")
                .gather_rows(batch.particle_type())?,
        );
    }
    Ok(Tensor::concat(&columns, 1)?)
}

/// Edge features `[E, dim + 1]`: the displacement from receiver to sender over `R` and its norm.
///
/// The norm's derivative is undefined at zero, which every self-edge has; the squared norm is
/// floored at the smallest normal `f32` so that gradients through positions stay finite (the
/// value differs from zero by ~1e-19, far below `f32` resolution of the other features).
pub(crate) fn edge_features<B: Backend>(
    latest: &Tensor<B>,
    senders: &IntTensor<B>,
    receivers: &IntTensor<B>,
    radius: f32,
) -> Result<Tensor<B>, ModelError> {
    let displacement = latest
        .gather_rows(senders)?
        .binary(BinaryOp::Sub, &latest.gather_rows(receivers)?)?
        / radius;
    let norm = displacement
        .square()
        .sum_axis(1)?
        .unsqueeze(1)?
        .binary_scalar(BinaryOp::Max, f32::MIN_POSITIVE)
        .sqrt();
    Ok(Tensor::concat(&[displacement, norm], 1)?)
}

/// The acceleration in stored units from the network's normalised output `[N, dim]`.
pub(crate) fn denormalise_acceleration<B: Backend>(
    normalised: &Tensor<B>,
    normalisers: &Normalisers<B>,
) -> Result<Tensor<B>, ModelError> {
    Ok(normalised
        .binary(BinaryOp::Mul, &normalisers.acc_scale)?
        .binary(BinaryOp::Add, &normalisers.acc_mean)?)
}

/// The normalised acceleration from one in stored units `[N, dim]` (the training target's
/// normalisation).
pub(crate) fn normalise_acceleration<B: Backend>(
    acceleration: &Tensor<B>,
    normalisers: &Normalisers<B>,
) -> Result<Tensor<B>, ModelError> {
    Ok(acceleration
        .binary(BinaryOp::Sub, &normalisers.acc_mean)?
        .binary(BinaryOp::Div, &normalisers.acc_scale)?)
}

/// Semi-implicit Euler in stored units (dt = 1): `v = p_t − p_{t−1} + a`, `p_{t+1} = p_t + v`.
/// `positions` is the window `[N, C + 1, dim]`, `acceleration` `[N, dim]`.
pub(crate) fn integrate<B: Backend>(
    positions: &Tensor<B>,
    acceleration: &Tensor<B>,
) -> Result<Tensor<B>, ModelError> {
    let latest = latest_positions(positions)?;
    let previous = previous_positions(positions)?;
    let velocity = latest
        .binary(BinaryOp::Sub, &previous)?
        .binary(BinaryOp::Add, acceleration)?;
    Ok(latest.binary(BinaryOp::Add, &velocity)?)
}

impl<B: Backend> Normalisers<B> {
    /// The constants of `spec` on `device`.
    pub(crate) fn new(spec: &super::ModelSpec, device: &B::Device) -> Result<Self, ModelError> {
        let noise = spec.config.noise_std;
        let n = &spec.normalisation;
        let dim = spec.config.dim;
        let tensor = |values: Vec<f64>| {
            Tensor::from_vec(
                values.into_iter().map(|v| v as f32).collect(),
                &[dim],
                device,
            )
        };
        Ok(Normalisers {
            vel_mean: tensor(n.vel_mean.clone())?,
            vel_scale: tensor(super::Normalisation::scale(&n.vel_std, noise))?,
            acc_mean: tensor(n.acc_mean.clone())?,
            acc_scale: tensor(super::Normalisation::scale(&n.acc_std, noise))?,
            lower: tensor(spec.bounds.iter().map(|b| b[0]).collect())?,
            upper: tensor(spec.bounds.iter().map(|b| b[1]).collect())?,
        })
    }
}
