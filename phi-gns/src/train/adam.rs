//! Adam (Kingma & Ba 2015) over the named parameters of a GNS, with DeepMind's learning-rate
//! schedule.
//!
//! The update is PyTorch's `torch.optim.Adam` (the optimiser of geoelements/gns):
//! `m ← β₁m + (1 − β₁)g`, `v ← β₂v + (1 − β₂)g²`, `p ← p − lr · m̂ / (√v̂ + ε)` with the bias
//! corrections `m̂ = m / (1 − β₁ᵗ)`, `v̂ = v / (1 − β₂ᵗ)`. It runs on detached tensors of the
//! parameters' backend, so no gradient history grows across steps.

use phi_core::backend::{Backend, BinaryOp};
use phi_core::tensor::Tensor;
use serde::{Deserialize, Serialize};

use crate::model::{ModelError, Parameters};

/// DeepMind's learning rate: `(initial − final) · 0.1^(step / decay_steps) + final`, times
/// `min(1, (step + 1) / warmup_steps)` during an optional linear warm-up.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LearningRate {
    /// The rate at step 0 (1e-4).
    pub initial: f64,
    /// The rate it decays towards (1e-6).
    pub final_rate: f64,
    /// Steps over which `initial − final` shrinks tenfold (5e6).
    pub decay_steps: f64,
    /// Steps of a linear warm-up from `rate / warmup_steps` to the schedule's rate (0: none,
    /// DeepMind's choice).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub warmup_steps: f64,
}

fn is_zero(x: &f64) -> bool {
    *x == 0.0
}

impl Default for LearningRate {
    fn default() -> Self {
        LearningRate {
            initial: 1e-4,
            final_rate: 1e-6,
            decay_steps: 5e6,
            warmup_steps: 0.0,
        }
    }
}

impl LearningRate {
    /// A constant rate.
    pub fn constant(rate: f64) -> Self {
        LearningRate {
            initial: rate,
            final_rate: rate,
            decay_steps: 1.0,
            warmup_steps: 0.0,
        }
    }

    /// The rate at `step` (counted from 0).
    pub fn at(&self, step: u64) -> f64 {
        let rate = (self.initial - self.final_rate) * 0.1f64.powf(step as f64 / self.decay_steps)
            + self.final_rate;
        if self.warmup_steps > 0.0 {
            rate * ((step + 1) as f64 / self.warmup_steps).min(1.0)
        } else {
            rate
        }
    }
}

/// Adam's constants.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AdamConfig {
    /// `β₁` (0.9).
    pub beta1: f64,
    /// `β₂` (0.999).
    pub beta2: f64,
    /// `ε` (1e-8).
    pub eps: f64,
    /// The learning rate per step.
    pub learning_rate: LearningRate,
    /// Gradients whose global L2 norm (over every parameter) exceeds this are scaled down to it
    /// before the update (absent: no clipping, DeepMind's choice).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub clip_norm: Option<f64>,
}

impl Default for AdamConfig {
    fn default() -> Self {
        AdamConfig {
            beta1: 0.9,
            beta2: 0.999,
            eps: 1e-8,
            learning_rate: LearningRate::default(),
            clip_norm: None,
        }
    }
}

/// Adam's state: the step count and the two moment estimates per parameter.
#[derive(Debug, Clone)]
pub struct Adam<B: Backend> {
    config: AdamConfig,
    step: u64,
    first: Parameters<B>,
    second: Parameters<B>,
}

impl<B: Backend> Adam<B> {
    /// Zero moments for `params`, at step 0.
    pub fn new(config: AdamConfig, params: &Parameters<B>) -> Self {
        let zeros = params.map(|_, t| t.detach().zeros_like());
        Adam {
            config,
            step: 0,
            first: zeros.clone(),
            second: zeros,
        }
    }

    /// Adam's state as a checkpoint stored it: `step` updates made, and the two moment
    /// estimates (of the parameters' layout).
    ///
    /// # Errors
    /// [`ModelError::Input`] when the moments do not have the same names and shapes.
    pub(crate) fn restore(
        config: AdamConfig,
        step: u64,
        first: Parameters<B>,
        second: Parameters<B>,
    ) -> Result<Self, ModelError> {
        let same = first.len() == second.len()
            && first
                .iter()
                .zip(second.iter())
                .all(|((a, x), (b, y))| a == b && x.shape() == y.shape());
        if !same {
            return Err(ModelError::Input {
                what: "Adam moments",
                reason: "the first and second moments have other names or shapes".into(),
            });
        }
        Ok(Adam {
            config,
            step,
            first,
            second,
        })
    }

    /// The number of updates made.
    pub fn step(&self) -> u64 {
        self.step
    }

    /// The constants.
    pub fn config(&self) -> &AdamConfig {
        &self.config
    }

    /// The first and second moment estimates.
    pub fn moments(&self) -> (&Parameters<B>, &Parameters<B>) {
        (&self.first, &self.second)
    }

    /// One update: the new values of `params` (detached) from their `gradients` (one per
    /// parameter, by name, as [`Parameters::iter`] orders them), scaled down to
    /// [`AdamConfig::clip_norm`] first when their global norm exceeds it.
    ///
    /// # Errors
    /// [`ModelError::Input`] when a gradient is missing or of another shape,
    /// [`ModelError::NonFinite`] when one is not finite (the parameters and moments are then left
    /// as they were).
    pub fn update(
        &mut self,
        params: &Parameters<B>,
        gradients: &[Tensor<B>],
    ) -> Result<Parameters<B>, ModelError> {
        if gradients.len() != params.len() {
            return Err(ModelError::Input {
                what: "gradients",
                reason: format!(
                    "{} gradients for {} parameters",
                    gradients.len(),
                    params.len()
                ),
            });
        }
        for ((name, p), g) in params.iter().zip(gradients) {
            if g.shape() != p.shape() {
                return Err(ModelError::Input {
                    what: "gradients",
                    reason: format!(
                        "'{name}': gradient {:?} for shape {:?}",
                        g.shape(),
                        p.shape()
                    ),
                });
            }
        }
        let squared_norm = squared_norm(params, gradients)?;
        let c = self.config;
        let scale = clip_scale(c.clip_norm, squared_norm.sqrt());
        let t = self.step + 1;
        let lr = c.learning_rate.at(self.step);
        let first_correction = 1.0 - c.beta1.powf(t as f64);
        let second_correction = 1.0 - c.beta2.powf(t as f64);
        let mut index = 0;
        let mut first = Vec::with_capacity(params.len());
        let mut second = Vec::with_capacity(params.len());
        let updated = params.map(|name, p| {
            let g = gradients[index].detach();
            let g = if scale < 1.0 { &g * scale as f32 } else { g };
            index += 1;
            let m = &self
                .first
                .get(name)
                .binary_scalar(BinaryOp::Mul, c.beta1 as f32)
                + &(&g * (1.0 - c.beta1) as f32);
            let v = &self
                .second
                .get(name)
                .binary_scalar(BinaryOp::Mul, c.beta2 as f32)
                + &(g.square() * (1.0 - c.beta2) as f32);
            let denominator = (&v * (1.0 / second_correction) as f32).sqrt() + c.eps as f32;
            let step = (&m * (lr / first_correction) as f32)
                .binary(BinaryOp::Div, &denominator)
                .expect("moments have the parameter's shape");
            first.push((name.to_string(), m));
            second.push((name.to_string(), v));
            p.detach()
                .binary(BinaryOp::Sub, &step)
                .expect("the update has the parameter's shape")
        });
        let (mut first, mut second) = (first.into_iter(), second.into_iter());
        self.first = self
            .first
            .map(|_, _| first.next().expect("one per parameter").1);
        self.second = self
            .second
            .map(|_, _| second.next().expect("one per parameter").1);
        self.step = t;
        Ok(updated)
    }
}

/// The squared global norm of `gradients` in f64, with one read from their device: each
/// gradient's sum of squares is taken where it lives and the sums come back together. A sum that
/// is not finite means a non-finite gradient or squares beyond f32's range; only then are that
/// gradient's values read, to tell the two apart and to sum them in f64.
///
/// # Errors
/// [`ModelError::NonFinite`] naming the first parameter whose gradient is not finite.
fn squared_norm<B: Backend>(
    params: &Parameters<B>,
    gradients: &[Tensor<B>],
) -> Result<f64, ModelError> {
    if gradients.is_empty() {
        return Ok(0.0);
    }
    let sums: Vec<Tensor<B>> = gradients.iter().map(|g| g.square().sum()).collect();
    let sums = Tensor::concat(&sums, 0)?.to_vec();
    let mut total = 0.0f64;
    for (((name, _), g), sum) in params.iter().zip(gradients).zip(sums) {
        if sum.is_finite() {
            total += f64::from(sum);
            continue;
        }
        let values = g.host_values();
        if !values.iter().all(|x| x.is_finite()) {
            return Err(ModelError::NonFinite {
                what: "gradients",
                reason: format!("'{name}': a non-finite gradient"),
            });
        }
        total += values
            .iter()
            .map(|&x| f64::from(x) * f64::from(x))
            .sum::<f64>();
    }
    Ok(total)
}

/// The factor that brings gradients of global norm `norm` down to `clip` (1 when they are within
/// it or there is no clipping).
fn clip_scale(clip: Option<f64>, norm: f64) -> f64 {
    match clip {
        Some(clip) if norm > clip => clip / norm,
        _ => 1.0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn warm_up_ramps_linearly_to_the_schedule() {
        let mut rate = LearningRate::constant(1e-3);
        rate.warmup_steps = 4.0;
        let rates: Vec<f64> = (0..6).map(|s| rate.at(s)).collect();
        for (got, want) in rates.iter().zip([2.5e-4, 5e-4, 7.5e-4, 1e-3, 1e-3, 1e-3]) {
            approx::assert_relative_eq!(*got, want, max_relative = 1e-12);
        }
        rate.warmup_steps = 0.0;
        assert_eq!(rate.at(0), 1e-3);
    }

    #[test]
    fn clipping_scales_only_norms_above_the_limit() {
        assert_eq!(clip_scale(None, 10.0), 1.0);
        assert_eq!(clip_scale(Some(2.0), 1.5), 1.0);
        approx::assert_relative_eq!(clip_scale(Some(2.0), 8.0), 0.25);
    }
}
