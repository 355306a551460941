//! One training step, top to bottom (thesis section 5.3, DeepMind's `learning_to_simulate`
//! recipe): the drawn windows of a batch, mirrored and made noisy; the targets; the radius
//! graph; the loss of the variant (one-step, multi-step or pushforward); its gradients; Adam.
//!
//! `take_step` is the step [`super::run::TrainingRun`] takes; [`train_step`] and
//! [`train_step_with`] are its last half (loss → gradients → Adam) for callers with a loss of
//! their own.
//!
//! Every random draw of step `s` comes from a generator keyed by `(training.seed, s)` and a
//! purpose (`train::rng`), so the step is a function of the run's state and `s` alone.

use phi_core::AutodiffBackend;
use phi_core::tensor::Tensor;

use super::config::TrainConfig;
use super::rng::{RngStream, step_rng};
use super::stream::HostBatch;
use super::{
    Adam, ErrorNorm, multi_step_loss, non_kinematic_mask, one_step_loss, pushforward_loss,
    random_walk_noise,
};
use crate::model::{Gns, GnsKernels, GraphBatch, ModelError};

/// Step `batch.step` of a run of `config`: the number of pushforward unrolls it draws, the
/// loss's inputs ([`StepInputs::assemble`]), then the loss, its gradients and Adam's update
/// ([`train_step_with`]). Returns the updated model, the loss before the update and the
/// unrolls.
///
/// # Errors
/// As [`StepInputs::assemble`] and [`train_step_with`] ([`ModelError::NonFinite`] leaves
/// `model` and `adam` as they were).
pub(crate) fn take_step<B: AutodiffBackend + GnsKernels>(
    model: &Gns<B>,
    adam: &mut Adam<B>,
    config: &TrainConfig,
    batch: &HostBatch,
    device: &B::Device,
) -> Result<(Gns<B>, f32, usize), ModelError> {
    let unrolls = config.training.pushforward.as_ref().map_or(0, |p| {
        p.draw(
            batch.step,
            &mut step_rng(config.training.seed, batch.step, RngStream::Pushforward),
        )
    });
    let inputs = StepInputs::assemble(model, config, batch, unrolls, device)?;
    let (model, loss) = train_step_with(model, adam, |tracked| inputs.loss(tracked))?;
    Ok((model, loss, unrolls))
}

/// The inputs of one step's loss, on the device: the (noisy, mirrored) windows and their
/// graph, the targets, the true frames of a multi-step or pushforward loss, the mask of the
/// particles that count.
pub(crate) struct StepInputs<B: GnsKernels> {
    batch: GraphBatch<B>,
    next: Tensor<B>,
    /// `[N, m, dim]`: the true frames the multi-step or pushforward loss reads (none for the
    /// plain one-step loss).
    truth: Option<Tensor<B>>,
    mask: Tensor<B>,
    pushforward: bool,
    norm: ErrorNorm,
}

/// Reflects positions (`dim` components each, row-major) across the plane `x = about / 2` of
/// the first axis: `x ↦ about − x`, with `about` the sum of the axis's lower and upper bounds.
fn mirror_first_axis(positions: &mut [f32], dim: usize, about: f32) {
    for x in positions.iter_mut().step_by(dim) {
        *x = about - *x;
    }
}

impl<B: GnsKernels> StepInputs<B> {
    /// The windows of `batch` with the step's noise, the targets and the mask. With `unrolls`
    /// pushforward steps, the start window ends `unrolls` frames before the latest input frame
    /// `t` of the drawn window, and the truth holds frames `t − unrolls ..= t + 1`; with `n`
    /// extra steps, frames `t ..= t + n + 1`.
    ///
    /// # Errors
    /// Graph errors for non-finite positions; shape errors.
    pub(crate) fn assemble(
        model: &Gns<B>,
        config: &TrainConfig,
        batch: &HostBatch,
        unrolls: usize,
        device: &B::Device,
    ) -> Result<Self, ModelError> {
        let c = config.model.input_velocities;
        let n = config.training.extra_steps;
        let sigma = config.model.noise_std;
        let kinematic_types = &model.spec().kinematic_types;
        let mut noise_rng = step_rng(config.training.seed, batch.step, RngStream::Noise);
        let mut mirror_rng = step_rng(config.training.seed, batch.step, RngStream::Mirror);
        let axis = model.spec().bounds[0];
        let mirror_about = (axis[0] + axis[1]) as f32;
        let mut windows = Vec::with_capacity(batch.examples.len());
        let (mut next, mut truth, mut types) = (Vec::new(), Vec::new(), Vec::new());
        let truth_frames = if unrolls > 0 {
            unrolls + 2
        } else if n > 0 {
            n + 2
        } else {
            0
        };
        for example in &batch.examples {
            let (count, dim) = (example.particles, example.dim);
            let start = example.frame - unrolls;
            let frames: Vec<&[f32]> = (start - c..=start)
                .map(|f| {
                    example
                        .positions_at(f)
                        .expect("the sampler's window spans it")
                })
                .collect();
            let mut window = vec![0.0f32; count * (c + 1) * dim];
            crate::rollout::fill_window(&frames, count, dim, &mut window);
            let kinematic = model.spec().kinematic(&example.particle_type);
            let mut target = example
                .positions_at(start + 1)
                .expect("the sampler's window spans it")
                .to_vec();
            // A stream of its own: turning mirroring on leaves the windows and the noise as
            // they were, and only reflects the examples whose draw is odd.
            let mirrored =
                config.training.mirror && rand::RngCore::next_u64(&mut mirror_rng) & 1 == 1;
            if mirrored {
                mirror_first_axis(&mut window, dim, mirror_about);
                mirror_first_axis(&mut target, dim, mirror_about);
            }
            if sigma > 0.0 {
                let noise = random_walk_noise(&kinematic, c + 1, dim, sigma, &mut noise_rng);
                window = noise.apply(&window);
                next.extend(noise.adjust_target(&target));
            } else {
                next.extend_from_slice(&target);
            }
            if truth_frames > 0 {
                let first = if unrolls > 0 { start } else { example.frame };
                let rows: Vec<&[f32]> = (first..first + truth_frames)
                    .map(|f| {
                        example
                            .positions_at(f)
                            .expect("the sampler's window spans it")
                    })
                    .collect();
                let mut block = vec![0.0f32; count * truth_frames * dim];
                crate::rollout::fill_window(&rows, count, dim, &mut block);
                if mirrored {
                    mirror_first_axis(&mut block, dim, mirror_about);
                }
                truth.extend(block);
            }
            windows.push(window);
            types.extend_from_slice(&example.particle_type);
        }
        let examples: Vec<(&[f32], &[i64])> = windows
            .iter()
            .zip(&batch.examples)
            .map(|(w, e)| (w.as_slice(), e.particle_type.as_slice()))
            .collect();
        let graph = GraphBatch::from_host_batch(&examples, model.spec(), device)?;
        let (particles, dim) = (types.len(), model.spec().config.dim);
        let next = Tensor::from_vec(next, &[particles, dim], device)?;
        let truth = (truth_frames > 0)
            .then(|| Tensor::from_vec(truth, &[particles, truth_frames, dim], device))
            .transpose()?;
        let mask = non_kinematic_mask::<B>(&types, kinematic_types, device)?;
        Ok(StepInputs {
            batch: graph,
            next,
            truth,
            mask,
            pushforward: unrolls > 0,
            norm: config.training.error_norm(),
        })
    }

    /// The loss of the run's variant on these inputs.
    ///
    /// # Errors
    /// As [`one_step_loss`], [`multi_step_loss`] or [`pushforward_loss`].
    pub fn loss(&self, model: &Gns<B>) -> Result<Tensor<B>, ModelError> {
        match (&self.truth, self.pushforward) {
            (None, _) => one_step_loss(model, &self.batch, &self.next, &self.mask, self.norm),
            (Some(truth), true) => {
                pushforward_loss(model, &self.batch, &self.next, truth, &self.mask, self.norm)
            }
            (Some(truth), false) => {
                multi_step_loss(model, &self.batch, &self.next, truth, &self.mask, self.norm)
            }
        }
    }
}

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

#[cfg(test)]
mod tests {
    use super::mirror_first_axis;

    #[test]
    fn mirroring_reflects_the_first_axis_only_and_undoes_itself() {
        // Three 2D positions in [0.1, 0.9]²: about = 1.0.
        let original = vec![0.1f32, 0.2, 0.5, 0.7, 0.85, 0.3];
        let mut p = original.clone();
        mirror_first_axis(&mut p, 2, 1.0);
        assert_eq!(p, vec![0.9, 0.2, 0.5, 0.7, 1.0 - 0.85, 0.3]);
        mirror_first_axis(&mut p, 2, 1.0);
        for (a, b) in p.iter().zip(&original) {
            assert!((a - b).abs() <= 1e-7, "{a} vs {b}");
        }
        // 3D: x only, y (gravity's axis in 2D) and z untouched.
        let mut q = vec![0.2f32, 0.3, 0.4];
        mirror_first_axis(&mut q, 3, 1.0);
        assert_eq!(q, vec![0.8, 0.3, 0.4]);
    }
}
