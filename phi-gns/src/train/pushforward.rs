//! Pushforward training (Brandstetter et al. 2022, as LagrangeBench trains its GNS): the model
//! first runs `k` steps from a ground-truth window without gradient, and the one-step loss is
//! taken on the window it arrives at, so that the model learns to correct the kind of error it
//! makes itself, at the cost of one extra forward pass per unroll step and no extra memory.
//!
//! # What is done, step by step
//!
//! - **How many unrolls.** One `k` per batch, drawn by [`Pushforward::draw`] from a
//!   schedule over the training step: entry `i` of `unrolls` becomes possible from step
//!   `steps[i]` on, and `k` is drawn among the possible entries with chances proportional to
//!   their `probabilities` (LagrangeBench: unrolls 0, 1, 2, 3 with weights 18 : 2 : 1 : 1,
//!   introduced after steps 20 000, 300 000 and 400 000).
//! - **Noise.** The start window may carry the random-walk noise of
//!   [`RandomWalkNoise`](super::RandomWalkNoise) (LagrangeBench adds it there, whatever `k`).
//! - **The unroll.** Each step predicts the next positions of every particle, drops the
//!   window's oldest frame and appends them; kinematic particles take their true positions
//!   (as in a rollout, [`crate::rollout`]); the radius graph is rebuilt from the new latest
//!   positions. The steps use the current parameters with gradients cut, and the window they
//!   end at is detached. LagrangeBench's training unroll leaves its walls to the model's
//!   prediction (only its evaluation resets them); here they follow the truth in both, since a
//!   rollout of this crate always resets them.
//! - **The target.** For `k = 0`, the one-step target `next` (noise-adjusted for a noisy
//!   window). For `k ≥ 1`, the true acceleration at the pushed-forward window's latest frame
//!   `t`, `p_{t+1} − 2 p_t + p_{t−1}` of the ground truth, not the acceleration that would take
//!   the pushed-forward window to the true next frame: LagrangeBench's target, which is the
//!   noise-shifted ground truth's acceleration, and the shift (the start window's last noise,
//!   the same on every later frame) cancels in it.
//!
//! # Frames
//!
//! For an example whose pushed-forward window ends at frame `t`, with `k` unrolls and `C`
//! input velocities: the start window (`batch`) holds frames `t − k − C ..= t − k`, `truth`
//! the true frames `t − k ..= t + 1` (`[N, k + 2, dim]`, the layout of
//! [`multi_step_loss`](super::multi_step_loss)'s `truth`); the unroll predicts frames
//! `t − k + 1 ..= t`, kinematic particles taking `truth[1 ..= k]`, and the loss compares the
//! model's acceleration on frames `t − C ..= t` with the true one from `truth[k − 1 ..= k + 1]`.
//! A trainer therefore reads the `k + C + 2` frames `t − k − C ..= t + 1` of a trajectory, and
//! can draw `t` from `k + C ..= frames − 2`.

use std::path::Path;

use phi_core::tensor::Tensor;
use rand::Rng;
use serde::{Deserialize, Serialize};

use super::loss::{ErrorNorm, acceleration_loss, counted_particles};
use super::multistep::{extra_steps, true_acceleration, truth_frame};
use super::one_step_loss;
use crate::model::{Gns, GnsKernels, GraphBatch, ModelError};
use crate::rollout::Rollout;

/// The schedule of pushforward unrolls over training (see the [module docs](self)): entry `i`
/// allows `unrolls[i]` unroll steps from training step `steps[i]` on (steps counted from 0,
/// as [`Adam::step`](super::Adam::step) counts the updates made), with weight
/// `probabilities[i]` among the entries allowed so far.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Pushforward {
    /// The first training step at which each entry is allowed; strictly increasing, from 0.
    pub steps: Vec<u64>,
    /// The number of unroll steps of each entry; non-decreasing.
    pub unrolls: Vec<usize>,
    /// The weight of each entry among those allowed (need not sum to 1); the first positive.
    pub probabilities: Vec<f64>,
}

impl Default for Pushforward {
    fn default() -> Self {
        Self::none()
    }
}

impl Pushforward {
    /// No pushforward: always 0 unroll steps (plain one-step training).
    pub fn none() -> Self {
        Pushforward {
            steps: vec![0],
            unrolls: vec![0],
            probabilities: vec![1.0],
        }
    }

    /// LagrangeBench's schedule: 0 unrolls from the start, 1, 2 and 3 unrolls added after
    /// 20 000, 300 000 and 400 000 steps, weighted 18 : 2 : 1 : 1. LagrangeBench writes the
    /// steps as `[−1, 20000, 300000, 400000]` and allows an entry once the step *exceeds* its
    /// value; here a step is the first at which the entry is allowed, so the same schedule
    /// reads `[0, 20001, 300001, 400001]`.
    pub fn lagrangebench() -> Self {
        Pushforward {
            steps: vec![0, 20_001, 300_001, 400_001],
            unrolls: vec![0, 1, 2, 3],
            probabilities: vec![18.0, 2.0, 1.0, 1.0],
        }
    }

    /// Checks the schedule; `key` is where it sits in the file `path` (e.g.
    /// `training.pushforward`), and errors name `key.steps`, `key.unrolls` or
    /// `key.probabilities`.
    ///
    /// # Errors
    /// [`ModelError::Config`] when the three lists are empty or of different lengths, the
    /// steps do not start at 0 or do not increase, the unrolls decrease, or a probability is
    /// negative or not finite, or the first is not positive (at step 0 nothing could be drawn).
    pub fn validate(&self, path: &Path, key: &str) -> Result<(), ModelError> {
        let fail = |field: &str, reason: String| {
            Err(ModelError::Config {
                path: path.to_path_buf(),
                key: format!("{key}.{field}"),
                reason,
            })
        };
        let n = self.steps.len();
        if n == 0 {
            return fail("steps", "the schedule has no entry".into());
        }
        for (field, len) in [
            ("unrolls", self.unrolls.len()),
            ("probabilities", self.probabilities.len()),
        ] {
            if len != n {
                return fail(field, format!("{len} entries for {n} steps"));
            }
        }
        if self.steps[0] != 0 {
            return fail(
                "steps",
                format!(
                    "the first entry is allowed from step {}, so nothing could be drawn before \
                     it; it must be 0",
                    self.steps[0]
                ),
            );
        }
        if let Some(i) = (1..n).find(|&i| self.steps[i] <= self.steps[i - 1]) {
            return fail(
                "steps",
                format!(
                    "entry {i} ({}) does not come after entry {} ({})",
                    self.steps[i],
                    i - 1,
                    self.steps[i - 1]
                ),
            );
        }
        if let Some(i) = (1..n).find(|&i| self.unrolls[i] < self.unrolls[i - 1]) {
            return fail(
                "unrolls",
                format!(
                    "entry {i} ({}) is fewer than entry {} ({}); they must not decrease",
                    self.unrolls[i],
                    i - 1,
                    self.unrolls[i - 1]
                ),
            );
        }
        if let Some((i, p)) = self
            .probabilities
            .iter()
            .enumerate()
            .find(|(_, p)| !(p.is_finite() && **p >= 0.0))
        {
            return fail(
                "probabilities",
                format!("entry {i} ({p}) is not a finite number ≥ 0"),
            );
        }
        if self.probabilities[0] <= 0.0 {
            return fail(
                "probabilities",
                "the first entry is the only one allowed at step 0 and must be positive".into(),
            );
        }
        Ok(())
    }

    /// The largest number of unroll steps the schedule can draw (the frames a trainer must
    /// read beyond a one-step example).
    pub fn max_unroll(&self) -> usize {
        self.unrolls.iter().copied().max().unwrap_or(0)
    }

    /// The entries allowed at training `step`: those with `steps[i] ≤ step`.
    pub fn allowed(&self, step: u64) -> usize {
        let n = self
            .steps
            .len()
            .min(self.unrolls.len())
            .min(self.probabilities.len());
        self.steps[..n].iter().filter(|&&s| s <= step).count()
    }

    /// The number of unroll steps for a batch at training `step`: one of the allowed entries'
    /// `unrolls`, drawn with chances proportional to their `probabilities` (one uniform draw
    /// from `rng`). A schedule that [`Pushforward::validate`] refuses never panics here: it
    /// draws among the allowed entries with positive finite weight, and 0 when there is none.
    pub fn draw(&self, step: u64, rng: &mut impl Rng) -> usize {
        let allowed = self.allowed(step);
        let weight = |p: f64| if p.is_finite() && p > 0.0 { p } else { 0.0 };
        let weights: Vec<f64> = self.probabilities[..allowed]
            .iter()
            .map(|&p| weight(p))
            .collect();
        let total: f64 = weights.iter().sum();
        if total <= 0.0 || !total.is_finite() {
            return 0;
        }
        let u = rng.random::<f64>() * total;
        let mut cumulative = 0.0;
        let mut last = 0;
        for (i, &w) in weights.iter().enumerate().filter(|(_, w)| **w > 0.0) {
            cumulative += w;
            last = i;
            if u < cumulative {
                return self.unrolls[i];
            }
        }
        // Rounding in the cumulative sum can leave u at the very top: the last entry.
        self.unrolls[last]
    }
}

/// The window `k` model steps on from `batch` (see the [module docs](self)), with `k` the
/// frames of `truth` (`[N, k, dim]`: the true positions of the `k` frames after the window's
/// latest). Each step predicts every particle's next positions, takes `truth`'s for the
/// particles where `mask` (`[N]`) is 0 (the kinematic ones), drops the oldest frame and
/// rebuilds the radius graph within each example. No gradient flows: the steps run on detached
/// parameters and the returned window is detached. `k = 0` returns `batch`'s window detached.
///
/// # Errors
/// [`ModelError::Input`] when `truth` or `mask` do not fit the window; [`ModelError::Graph`]
/// when a predicted position is not finite.
pub fn push_forward<B: GnsKernels>(
    model: &Gns<B>,
    batch: &GraphBatch<B>,
    truth: &Tensor<B>,
    mask: &Tensor<B>,
) -> Result<GraphBatch<B>, ModelError> {
    let window = batch.positions().shape();
    let (n, dim) = (window[0], window[2]);
    let shape = truth.shape();
    if shape.len() != 3 || shape[0] != n || shape[2] != dim {
        return Err(ModelError::Input {
            what: "pushforward truth",
            reason: format!(
                "shape {shape:?}; a window of {n} particles in {dim}D needs [{n}, unrolls, {dim}]"
            ),
        });
    }
    if mask.shape() != [n] {
        return Err(ModelError::Input {
            what: "loss mask",
            reason: format!("shape {:?} for {n} particles", mask.shape()),
        });
    }
    let frozen = model.with_params(model.params().map(|_, t| t.detach()))?;
    let truth = truth.detach();
    let pushed = batch.with_positions(batch.positions().detach())?;
    let mut rollout = Rollout::with_mask(&frozen, pushed, &mask.detach())?;
    for i in 0..shape[1] {
        rollout.step(&truth_frame(&truth, i)?)?;
    }
    Ok(rollout.window()?.clone())
}

/// The pushforward loss (see the [module docs](self)): `k = truth.shape()[1] − 2` detached
/// model steps from `batch`, then the one-step loss on the window they arrive at against the
/// true acceleration there; for `k = 0`, [`one_step_loss`] against `next`.
///
/// - `batch`: the start window `[N, C + 1, dim]` of frames `t − k − C ..= t − k` (may be
///   noisy);
/// - `next`: the target positions `[N, dim]` of the start window, as
///   [`one_step_loss`] takes them (noise-adjusted for a noisy window); used only for `k = 0`;
/// - `truth`: the true frames `t − k ..= t + 1`, `[N, k + 2, dim]`;
/// - `mask`: `[N]`, 1 where a particle counts in the loss, 0 for the kinematic ones, which
///   follow `truth` in the unroll;
/// - `norm`: how the error is scored.
///
/// The gradient is that of the one-step loss on the pushed-forward window held fixed.
///
/// # Errors
/// As [`push_forward`] and [`one_step_loss`].
pub fn pushforward_loss<B: GnsKernels>(
    model: &Gns<B>,
    batch: &GraphBatch<B>,
    next: &Tensor<B>,
    truth: &Tensor<B>,
    mask: &Tensor<B>,
    norm: ErrorNorm,
) -> Result<Tensor<B>, ModelError> {
    let unrolls = extra_steps(batch, truth, "pushforward truth")?;
    if unrolls == 0 {
        return one_step_loss(model, batch, next, mask, norm);
    }
    counted_particles(batch, mask)?;
    let pushed = push_forward(model, batch, &truth.narrow(1, 1..unrolls + 1)?, mask)?;
    let target = true_acceleration(model, truth, unrolls)?;
    acceleration_loss(model, &pushed, &target.detach(), mask, norm)
}
