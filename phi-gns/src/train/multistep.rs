//! The multi-step loss (thesis equation 5.2): the model is run `n` steps past the one-step
//! prediction on its own output, and each step's acceleration is compared with the ground
//! truth's, so that training sees the model's own errors in its input.
//!
//! # Frames
//!
//! The input window of `batch` holds frames `t − C ..= t` (`t` its latest frame, possibly
//! noisy), and `truth` the true frames `t ..= t + n + 1`, `[N, n + 2, dim]`. Step 0 is the
//! one-step loss of equation 5.1 against `next`. Step `i ≥ 1` runs on the window of step
//! `i − 1` with its oldest frame dropped and the model's prediction of frame `t + i` appended,
//! kinematic particles taking the true `truth[i]` instead; the radius graph is rebuilt from the
//! new latest positions within each example. Its target is the true acceleration
//! `p̈_GT^{t+i} = truth[i + 1] − 2 truth[i] + truth[i − 1]`, normalised like the network's
//! output. Gradients flow through the predicted positions into the later steps (not through
//! the graph, which is piecewise constant in the positions).
//!
//! Equation 5.2 writes a prefactor `1/n` before its `n + 1` terms; the loss here is their mean,
//! `1/(n + 1)`, so that `n = 0` is the one-step loss and a learning rate means the same for
//! every `n` (the factor only rescales the gradient, to which Adam is nearly invariant).

use phi_core::tensor::Tensor;

use super::loss::{ErrorNorm, counted_particles, masked_error};
use crate::model::{Gns, GnsKernels, GraphBatch, ModelError};
use crate::rollout::Rollout;

/// The multi-step loss of `model` (see the [module docs](self)): the mean over steps
/// `0 ..= n` of the one-step losses, `n = truth.shape()[1] − 2`.
///
/// - `batch`: the step-0 input window `[N, C + 1, dim]` (may be noisy);
/// - `next`: the step-0 target positions `[N, dim]`, as [`one_step_loss`](super::one_step_loss)
///   takes them (noise-adjusted for a noisy window);
/// - `truth`: the true positions of frames `t ..= t + n + 1`, `[N, n + 2, dim]`, `t` the latest
///   input frame;
/// - `mask`: `[N]`, 1 where a particle counts in the loss, 0 for kinematic particles, which
///   follow `truth` in the later windows;
/// - `norm`: how each step's error is scored.
///
/// With `n = 0` the result is [`one_step_loss`](super::one_step_loss)'s, bit for bit.
///
/// # Errors
/// [`ModelError::Input`] when no particle counts or the shapes do not fit each other;
/// [`ModelError::Graph`] when a predicted position is not finite.
pub fn multi_step_loss<B: GnsKernels>(
    model: &Gns<B>,
    batch: &GraphBatch<B>,
    next: &Tensor<B>,
    truth: &Tensor<B>,
    mask: &Tensor<B>,
    norm: ErrorNorm,
) -> Result<Tensor<B>, ModelError> {
    let steps = extra_steps(batch, truth, "multi-step truth")?;
    let counted = counted_particles(batch, mask)?;
    let predicted = model.normalised_acceleration(batch)?;
    let mut total = masked_error(
        &predicted,
        &model.target_acceleration(batch, next)?,
        mask,
        counted,
        norm,
    )?;
    let mut rollout = Rollout::with_mask(model, batch.clone(), mask)?;
    let mut predicted = predicted;
    for i in 1..=steps {
        rollout.step_with(&predicted, &truth_frame(truth, i)?)?;
        predicted = model.normalised_acceleration(rollout.window()?)?;
        let target = true_acceleration(model, truth, i)?;
        total = total + masked_error(&predicted, &target, mask, counted, norm)?;
    }
    Ok(total / (steps + 1) as f32)
}

/// The number of steps past the first that `truth` (`[N, steps + 2, dim]`) covers, checked
/// against the window of `batch`.
pub(crate) fn extra_steps<B: phi_core::Backend>(
    batch: &GraphBatch<B>,
    truth: &Tensor<B>,
    what: &'static str,
) -> Result<usize, ModelError> {
    let window = batch.positions().shape();
    let (n, dim) = (window[0], window[2]);
    let shape = truth.shape();
    if shape.len() != 3 || shape[0] != n || shape[1] < 2 || shape[2] != dim {
        return Err(ModelError::Input {
            what,
            reason: format!(
                "shape {shape:?}; a window of {n} particles in {dim}D needs [{n}, steps + 2, \
                 {dim}] (frames t ..= t + steps + 1)"
            ),
        });
    }
    Ok(shape[1] - 2)
}

/// Frame `i` of `truth` (`[N, F, dim]`): `[N, dim]`.
pub(crate) fn truth_frame<B: phi_core::Backend>(
    truth: &Tensor<B>,
    i: usize,
) -> Result<Tensor<B>, ModelError> {
    let shape = truth.shape();
    Ok(truth.narrow(1, i..i + 1)?.reshape(&[shape[0], shape[2]])?)
}

/// The true acceleration at frame `i` of `truth`, `truth[i + 1] − 2 truth[i] + truth[i − 1]`,
/// normalised like the network's output: `[N, dim]`.
pub(crate) fn true_acceleration<B: GnsKernels>(
    model: &Gns<B>,
    truth: &Tensor<B>,
    i: usize,
) -> Result<Tensor<B>, ModelError> {
    let latest = truth_frame(truth, i)?;
    let acceleration = truth_frame(truth, i + 1)?
        .binary(phi_core::backend::BinaryOp::Sub, &(&latest * 2.0))?
        + truth_frame(truth, i - 1)?;
    model.normalise_acceleration(&acceleration)
}
