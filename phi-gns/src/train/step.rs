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
use rayon::prelude::*;

use super::config::TrainConfig;
use super::loss::non_kinematic_weights;
use super::rng::{RngStream, step_rng};
use super::stream::HostBatch;
use super::{
    Adam, ErrorNorm, multi_step_loss, obstacle_weights, one_step_loss, pushforward_loss,
    random_walk_noise,
};
use crate::model::{Gns, GnsKernels, GraphBatch, ModelError};

/// Step `batch.step` of a run of `config`: the number of pushforward unrolls it draws, the
/// loss's inputs ([`HostInputs::assemble`]), then the loss, its gradients and Adam's update
/// ([`train_step_with`]; with `training.parallel_graphs`, [`parallel_graphs_gradients`]). Returns the updated model, the loss before the update and the
/// unrolls.
///
/// # Errors
/// Graph errors for non-finite positions; as [`train_step_with`] ([`ModelError::NonFinite`]
/// leaves `model` and `adam` as they were).
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
    let host = HostInputs::assemble(model, config, batch, unrolls);
    let (model, loss) = if config.training.parallel_graphs && host.examples.len() > 1 {
        let (loss, gradients) = parallel_graphs_gradients(model, &host, device)?;
        let updated = adam.update(model.params(), &gradients)?;
        (model.with_params(updated)?, loss)
    } else {
        let inputs = host.upload(&host.examples, model, device)?;
        train_step_with(model, adam, |tracked| inputs.loss(tracked))?
    };
    Ok((model, loss, unrolls))
}

/// The loss and gradients of `training.parallel_graphs`: each example's loss on a graph of its
/// own, weighted by its share of the batch's counted particles (so that the weighted sum is the
/// batch's loss), differentiated on its own, each a task of the thread pool; the losses and
/// gradients summed in batch order. Which thread differentiates which graph does not change a
/// bit.
///
/// # Errors
/// Graph errors for non-finite positions; as [`train_step_with`].
fn parallel_graphs_gradients<B: AutodiffBackend + GnsKernels>(
    model: &Gns<B>,
    host: &HostInputs<'_>,
    device: &B::Device,
) -> Result<LossAndGradients<B>, ModelError> {
    // Each graph's share of the batch's weighted mean: its particles' loss weights over the
    // batch's (counts of counted particles, exact in f32, without obstacle weights).
    let counted: Vec<f32> = host
        .examples
        .iter()
        .map(|e| host.loss_weights(e, model).iter().sum())
        .collect();
    let total: f32 = counted.iter().sum();
    let jobs: Vec<(Gns<B>, &HostExample<'_>, f32)> = host
        .examples
        .iter()
        .zip(&counted)
        // An example with no counted particle adds nothing to the loss (and would be 0/0).
        .filter(|(_, count)| **count > 0.0)
        .map(|(example, &count)| (model.clone(), example, count / total))
        .collect();
    if jobs.is_empty() {
        // Nothing counts: the batch's own loss reports it.
        let inputs = host.upload(&host.examples, model, device)?;
        return weighted_gradients(model, &inputs, 1.0);
    }
    // One task of the pool per graph, from its upload to its gradients: a thread busy with
    // Burn's own work on one graph leaves the other graph's kernels to the other threads, and a
    // thread done with its graph helps with the kernels of the rest.
    let results: Vec<Result<LossAndGradients<B>, ModelError>> = jobs
        .into_par_iter()
        .map(|(model, example, weight)| {
            let inputs = host.upload(std::slice::from_ref(example), &model, device)?;
            weighted_gradients(&model, &inputs, weight)
        })
        .collect();
    let mut value = 0.0f32;
    let mut sum: Option<Vec<Tensor<B>>> = None;
    for result in results {
        let (loss, gradients) = result?;
        value += loss;
        sum = Some(match sum {
            None => gradients,
            Some(sum) => sum.iter().zip(&gradients).map(|(a, b)| a + b).collect(),
        });
    }
    Ok((value, sum.expect("at least one job")))
}

/// A loss's value and its gradients, one per parameter.
type LossAndGradients<B> = (f32, Vec<Tensor<B>>);

/// `weight ×` the loss of `inputs` and its gradients in every parameter of `model`, from
/// trainable leaves of this call's own (so that no graph is shared with another thread's).
///
/// # Errors
/// As [`train_step_with`].
fn weighted_gradients<B: AutodiffBackend + GnsKernels>(
    model: &Gns<B>,
    inputs: &StepInputs<B>,
    weight: f32,
) -> Result<LossAndGradients<B>, ModelError> {
    let leaves = model.params().map(|_, t| t.require_grad());
    let tracked = model.with_params(leaves.clone())?;
    let loss = checked_loss(inputs.loss(&tracked)? * weight)?;
    let wrt: Vec<&Tensor<B>> = leaves.iter().map(|(_, t)| t).collect();
    Ok((loss.1, loss.0.gradients(&wrt)?))
}

/// `loss` and its value, checked to be one finite value.
///
/// # Errors
/// [`ModelError::Input`] for a loss that is not one value, [`ModelError::NonFinite`] for a NaN
/// or infinite one.
fn checked_loss<B: phi_core::Backend>(loss: Tensor<B>) -> Result<(Tensor<B>, f32), ModelError> {
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
    Ok((loss, value))
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

/// One example of a step on the host: its (noisy, mirrored) window, its target positions, the
/// true frames of a multi-step or pushforward loss and its particle types.
struct HostExample<'a> {
    window: Vec<f32>,
    next: Vec<f32>,
    truth: Vec<f32>,
    types: &'a [i64],
}

/// A step's examples on the host ([`HostExample`]) and what their loss reads of them.
struct HostInputs<'a> {
    examples: Vec<HostExample<'a>>,
    /// Frames of each example's truth (0 for the one-step loss).
    truth_frames: usize,
    pushforward: bool,
    norm: ErrorNorm,
    /// `training.obstacle_weight`, when set.
    obstacle_weight: Option<f32>,
}

impl<'a> HostInputs<'a> {
    /// The windows of `batch` with the step's noise, the targets and the true frames. With
    /// `unrolls` pushforward steps, the start window ends `unrolls` frames before the latest
    /// input frame `t` of the drawn window, and the truth holds frames `t − unrolls ..= t + 1`;
    /// with `n` extra steps, frames `t ..= t + n + 1`.
    fn assemble<B: GnsKernels>(
        model: &Gns<B>,
        config: &TrainConfig,
        batch: &'a HostBatch,
        unrolls: usize,
    ) -> Self {
        let c = config.model.input_velocities;
        let n = config.training.extra_steps;
        let sigma = config.model.noise_std;
        let mut noise_rng = step_rng(config.training.seed, batch.step, RngStream::Noise);
        let mut mirror_rng = step_rng(config.training.seed, batch.step, RngStream::Mirror);
        let axis = model.spec().bounds[0];
        let mirror_about = (axis[0] + axis[1]) as f32;
        let truth_frames = if unrolls > 0 {
            unrolls + 2
        } else if n > 0 {
            n + 2
        } else {
            0
        };
        let mut examples = Vec::with_capacity(batch.examples.len());
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
            let mut next = example
                .positions_at(start + 1)
                .expect("the sampler's window spans it")
                .to_vec();
            // A stream of its own: turning mirroring on leaves the windows and the noise as
            // they were, and only reflects the examples whose draw is odd.
            let mirrored =
                config.training.mirror && rand::RngCore::next_u64(&mut mirror_rng) & 1 == 1;
            if mirrored {
                mirror_first_axis(&mut window, dim, mirror_about);
                mirror_first_axis(&mut next, dim, mirror_about);
            }
            if sigma > 0.0 {
                let noise = random_walk_noise(&kinematic, c + 1, dim, sigma, &mut noise_rng);
                window = noise.apply(&window);
                next = noise.adjust_target(&next);
            }
            let mut truth = Vec::new();
            if truth_frames > 0 {
                let first = if unrolls > 0 { start } else { example.frame };
                let rows: Vec<&[f32]> = (first..first + truth_frames)
                    .map(|f| {
                        example
                            .positions_at(f)
                            .expect("the sampler's window spans it")
                    })
                    .collect();
                truth = vec![0.0f32; count * truth_frames * dim];
                crate::rollout::fill_window(&rows, count, dim, &mut truth);
                if mirrored {
                    mirror_first_axis(&mut truth, dim, mirror_about);
                }
            }
            examples.push(HostExample {
                window,
                next,
                truth,
                types: &example.particle_type,
            });
        }
        HostInputs {
            examples,
            truth_frames,
            pushforward: unrolls > 0,
            norm: config.training.error_norm(),
            obstacle_weight: config.training.obstacle_weight.map(|w| w as f32),
        }
    }

    /// The weight of each particle of `example` in the loss: 0 for kinematic particles, 1 for
    /// the counted ones, or with `training.obstacle_weight` that weight for the counted particles
    /// with an obstacle within the connectivity radius in the latest input frame
    /// ([`obstacle_weights`]).
    fn loss_weights<B: GnsKernels>(&self, example: &HostExample<'_>, model: &Gns<B>) -> Vec<f32> {
        let spec = model.spec();
        let kinematic = &spec.kinematic_types;
        let Some(weight) = self.obstacle_weight else {
            return non_kinematic_weights(example.types, kinematic);
        };
        // The latest input frame: the last of each particle's C + 1 window frames.
        let (frames, dim) = (spec.config.input_velocities + 1, spec.config.dim);
        let latest: Vec<f32> = example
            .window
            .chunks_exact(frames * dim)
            .flat_map(|particle| &particle[(frames - 1) * dim..])
            .copied()
            .collect();
        obstacle_weights(
            &latest,
            dim,
            example.types,
            kinematic,
            spec.config.connectivity_radius as f32,
            weight,
        )
    }

    /// The inputs of the loss of `examples` (a range of [`Self::examples`]) as one graph.
    ///
    /// # Errors
    /// Graph errors for non-finite positions; shape errors.
    fn upload<B: GnsKernels>(
        &self,
        examples: &[HostExample<'_>],
        model: &Gns<B>,
        device: &B::Device,
    ) -> Result<StepInputs<B>, ModelError> {
        let spec = model.spec();
        let graphs: Vec<(&[f32], &[i64])> = examples
            .iter()
            .map(|e| (e.window.as_slice(), e.types))
            .collect();
        let batch = GraphBatch::from_host_batch(&graphs, spec, device)?;
        let particles: usize = examples.iter().map(|e| e.types.len()).sum();
        let (dim, frames) = (spec.config.dim, self.truth_frames);
        let next = examples.iter().flat_map(|e| &e.next).copied().collect();
        let next = Tensor::from_vec(next, &[particles, dim], device)?;
        let truth = (frames > 0)
            .then(|| {
                let truth = examples.iter().flat_map(|e| &e.truth).copied().collect();
                Tensor::from_vec(truth, &[particles, frames, dim], device)
            })
            .transpose()?;
        let weights = examples
            .iter()
            .flat_map(|e| self.loss_weights(e, model))
            .collect();
        let mask = Tensor::from_vec(weights, &[particles], device)?;
        Ok(StepInputs {
            batch,
            next,
            truth,
            mask,
            pushforward: self.pushforward,
            norm: self.norm,
        })
    }
}

impl<B: GnsKernels> StepInputs<B> {
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
    let (loss, value) = checked_loss(loss(&tracked)?)?;
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

    #[cfg(feature = "burn")]
    mod parallel_graphs {
        use burn_flex::Flex;
        use phi_core::backend::burn::Burn;
        use phi_core::tensor::Tensor;
        use rand::{Rng, SeedableRng};
        use rand_chacha::ChaCha8Rng;

        use super::super::{HostInputs, parallel_graphs_gradients, weighted_gradients};
        use crate::data::{LIQUID, Metadata, OBSTACLE};
        use crate::model::{Gns, GnsConfig, ModelSpec};
        use crate::train::TrainConfig;
        use crate::train::stream::{HostBatch, HostExample};

        type B = Burn<Flex>;

        /// The CPU 2ss preset with noise and mirroring, so that every draw of a step is used.
        fn config() -> TrainConfig {
            let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../configs/gns/cpu/2ss.toml");
            let text = std::fs::read_to_string(path).expect("the CPU 2ss preset");
            let text = text
                .replace("noise_std = 0.0", "noise_std = 3e-4")
                .replace("log_every = 100", "log_every = 100\nmirror = true");
            TrainConfig::from_toml(&text, "2ss.toml").expect("the preset parses")
        }

        /// A small model of `config`'s input velocities.
        fn model() -> Gns<B> {
            let mut metadata = Metadata::new(2);
            metadata.vel_std = vec![1e-3; 2];
            metadata.acc_std = vec![1e-4; 2];
            let mut gns = GnsConfig::thesis(2);
            (gns.latent_size, gns.hidden_size, gns.message_passing_steps) = (16, 16, 2);
            gns.connectivity_radius = 0.08;
            Gns::init(
                ModelSpec::for_dataset(&metadata, gns, 3),
                &Default::default(),
            )
            .expect("a valid model")
        }

        /// `liquid` falling particles above `obstacles` resting ones, frames 0..8 (the window of
        /// frame 5 with two frames after it).
        fn example(liquid: usize, obstacles: usize, seed: u64) -> HostExample {
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            let particles = liquid + obstacles;
            let start: Vec<[f32; 2]> = (0..particles)
                .map(|i| {
                    let y = if i < liquid { 0.45..0.85 } else { 0.12..0.3 };
                    [rng.random_range(0.15..0.85), rng.random_range(y)]
                })
                .collect();
            let mut frames = Vec::new();
            for f in 0..8 {
                for (i, p) in start.iter().enumerate() {
                    let fall = if i < liquid {
                        2e-4 * (f * f) as f32
                    } else {
                        0.0
                    };
                    frames.extend([p[0] + 1e-4 * f as f32 * (i % 3) as f32, p[1] - fall]);
                }
            }
            let mut particle_type = vec![LIQUID; liquid];
            particle_type.extend(vec![OBSTACLE; obstacles]);
            HostExample {
                trajectory: 0,
                frame: 5,
                first_frame: 0,
                particles,
                dim: 2,
                particle_type,
                frames,
            }
        }

        fn values(tensors: &[Tensor<B>]) -> Vec<f32> {
            tensors.iter().flat_map(|t| t.to_vec()).collect()
        }

        /// The step's loss and gradients, as one graph of the batch and as a graph per example
        /// on a pool of `threads`.
        fn both(batch: &HostBatch, threads: usize) -> ((f32, Vec<f32>), (f32, Vec<f32>)) {
            both_with(&config(), batch, threads)
        }

        fn both_with(
            config: &TrainConfig,
            batch: &HostBatch,
            threads: usize,
        ) -> ((f32, Vec<f32>), (f32, Vec<f32>)) {
            let (model, device) = (model(), Default::default());
            let host = HostInputs::assemble(&model, config, batch, 0);
            let inputs = host.upload(&host.examples, &model, &device).unwrap();
            let (loss, gradients) = weighted_gradients(&model, &inputs, 1.0).unwrap();
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            let (split, split_gradients) = pool
                .install(|| parallel_graphs_gradients(&model, &host, &device))
                .unwrap();
            (
                (loss, values(&gradients)),
                (split, values(&split_gradients)),
            )
        }

        fn relative_difference(a: &[f32], b: &[f32]) -> f64 {
            let norm = |v: &[f64]| v.iter().map(|x| x * x).sum::<f64>().sqrt();
            let d: Vec<f64> = a.iter().zip(b).map(|(x, y)| (x - y) as f64).collect();
            let b: Vec<f64> = b.iter().map(|&y| y as f64).collect();
            norm(&d) / norm(&b)
        }

        #[test]
        fn a_graph_per_example_gives_the_batchs_loss_and_gradients_on_any_thread_count() {
            // Three examples of different sizes, one of them all obstacle: it counts for
            // nothing in the batch's loss and is left out of the split one.
            let batch = HostBatch {
                step: 7,
                examples: vec![example(40, 12, 1), example(0, 9, 2), example(25, 20, 3)],
            };
            let ((loss, gradients), (split, one)) = both(&batch, 1);
            let (_, (split_two, two)) = both(&batch, 2);
            assert!(loss > 0.0 && gradients.iter().any(|g| *g != 0.0));
            assert!(
                ((split - loss) / loss).abs() < 1e-6,
                "loss {split} against the batch's {loss}"
            );
            let difference = relative_difference(&one, &gradients);
            assert!(difference < 1e-5, "gradients differ by {difference:e}");
            // The same sums in the same order whichever thread runs which graph.
            assert_eq!(split.to_bits(), split_two.to_bits());
            assert!(
                one.iter()
                    .zip(&two)
                    .all(|(a, b)| a.to_bits() == b.to_bits())
            );
        }

        #[test]
        fn obstacle_weights_weigh_the_batch_and_each_graph_alike() {
            // The obstacles moved up into the liquid, so that some liquid is within R of them.
            let near = |liquid, obstacles, seed| {
                let mut e = example(liquid, obstacles, seed);
                for frame in e.frames.chunks_exact_mut(e.particles * 2) {
                    for p in frame[liquid * 2..].chunks_exact_mut(2) {
                        p[1] += 0.4;
                    }
                }
                e
            };
            let batch = HostBatch {
                step: 3,
                examples: vec![near(40, 12, 1), near(25, 20, 3)],
            };
            let mut weighted = config();
            weighted.training.obstacle_weight = Some(4.0);
            let model = model();
            let host = HostInputs::assemble(&model, &weighted, &batch, 0);
            let weights: Vec<f32> = host
                .examples
                .iter()
                .flat_map(|e| host.loss_weights(e, &model))
                .collect();
            let count = |w: f32| weights.iter().filter(|&&v| v == w).count();
            assert_eq!(count(0.0), 32, "the obstacles count for nothing");
            assert!(count(4.0) > 0 && count(1.0) > 0, "{weights:?}");
            assert_eq!(count(4.0) + count(1.0), 65);
            let ((loss, gradients), (split, one)) = both_with(&weighted, &batch, 2);
            assert!(
                ((split - loss) / loss).abs() < 1e-6,
                "loss {split} against the batch's {loss}"
            );
            let difference = relative_difference(&one, &gradients);
            assert!(difference < 1e-5, "gradients differ by {difference:e}");
            let ((plain, _), _) = both_with(&config(), &batch, 1);
            assert!(
                ((plain - loss) / loss).abs() > 1e-4,
                "the weights change the loss: {plain} and {loss}"
            );
        }

        #[test]
        fn a_batch_where_nothing_counts_is_refused_as_the_batchs_loss_is() {
            let batch = HostBatch {
                step: 1,
                examples: vec![example(0, 9, 2), example(0, 5, 4)],
            };
            let (config, model, device) = (config(), model(), Default::default());
            let host = HostInputs::assemble(&model, &config, &batch, 0);
            let error = parallel_graphs_gradients(&model, &host, &device)
                .map(|_| ())
                .expect_err("no particle counts");
            assert!(error.to_string().contains("kinematic"), "{error}");
        }
    }
}
