//! An exponential moving average of the weights over the optimisation steps.
//!
//! A batch that holds a wall impact moves the weights a long way, so the weights of one step
//! are a noisy sample of what training has learnt: the screening of a run jumps from one
//! checkpoint to the next. The average `ā ← ā + (1 − d)(w − ā)` after every step smooths that
//! over about `1 / (1 − d)` steps; it never feeds back into training (Adam updates `w`), so the
//! loss curve of a run is the same with or without it. As TensorFlow's
//! `ExponentialMovingAverage` does with `num_updates`, the decay of update `n` (from 0) is
//! `min(d, (1 + n) / (10 + n))`, so that the average of a fresh run forgets the initial
//! weights within tens of steps instead of `1 / (1 − d)`.
//!
//! The average lives on the host (one read of the weights a step; the model is small beside
//! its graph) in `f32`, updated in a fixed order, so a resumed run continues it bit for bit.

use phi_core::backend::{Backend, Host};
use phi_core::tensor::Tensor;

use crate::model::Parameters;

/// The moving average of a run's weights.
#[derive(Debug, Clone)]
pub struct WeightAverage {
    decay: f64,
    updates: u64,
    params: Parameters<Host>,
}

impl WeightAverage {
    /// An average that starts at `weights`, with no update yet.
    pub fn new<B: Backend>(decay: f64, weights: &Parameters<B>) -> Self {
        WeightAverage {
            decay,
            updates: 0,
            params: weights.to_backend::<Host>(&Default::default()),
        }
    }

    /// The average `params` after `updates` updates, as a checkpoint holds it.
    pub(crate) fn restore(decay: f64, params: Parameters<Host>, updates: u64) -> Self {
        WeightAverage {
            decay,
            updates,
            params,
        }
    }

    /// The decay of the next update: `min(d, (1 + n) / (10 + n))`.
    pub(crate) fn next_decay(&self) -> f64 {
        let n = self.updates as f64;
        self.decay.min((1.0 + n) / (10.0 + n))
    }

    /// Moves the average towards `weights` (the weights after a step).
    pub fn update<B: Backend>(&mut self, weights: &Parameters<B>) {
        let rate = (1.0 - self.next_decay()) as f32;
        self.params = self.params.map(|name, average| {
            let target = weights.get(name).to_vec();
            let mut values = average.to_vec();
            for (a, w) in values.iter_mut().zip(&target) {
                *a += rate * (w - *a);
            }
            Tensor::from_vec(values, &average.shape(), &Default::default())
                .expect("the average keeps the shape of its parameter")
        });
        self.updates += 1;
    }

    /// The averaged weights.
    pub fn params(&self) -> &Parameters<Host> {
        &self.params
    }

    /// Updates done since the average started.
    pub fn updates(&self) -> u64 {
        self.updates
    }
}

#[cfg(test)]
mod tests {
    use approx::assert_relative_eq;

    use super::*;
    use crate::model::GnsConfig;

    fn config() -> GnsConfig {
        GnsConfig {
            latent_size: 4,
            hidden_size: 4,
            hidden_layers: 1,
            message_passing_steps: 1,
            embedding_size: 2,
            ..GnsConfig::thesis(2)
        }
    }

    fn filled(value: f32) -> Parameters<Host> {
        Parameters::<Host>::init(&config(), 1, &Default::default())
            .map(|_, t| Tensor::full(&t.shape(), value, &Default::default()))
    }

    fn values(p: &Parameters<Host>) -> Vec<f32> {
        p.iter().flat_map(|(_, t)| t.to_vec()).collect()
    }

    #[test]
    fn constant_weights_are_their_own_average() {
        let w = Parameters::<Host>::init(&config(), 5, &Default::default());
        let mut average = WeightAverage::new(0.999, &w);
        for _ in 0..50 {
            average.update(&w);
        }
        assert_eq!(values(average.params()), values(&w));
        assert_eq!(average.updates(), 50);
    }

    #[test]
    fn the_decay_warms_up_to_d_and_the_average_is_the_weighted_sum() {
        let mut average = WeightAverage::new(0.9, &filled(0.0));
        assert_relative_eq!(average.next_decay(), 0.1);
        // First update towards 1 with decay 1/10: 0.9.
        average.update(&filled(1.0));
        assert!(
            values(average.params())
                .iter()
                .all(|&a| (a - 0.9).abs() < 1e-6)
        );
        // Decays 2/11, 3/12, … reach d = 0.9 at n = 80 and stay there.
        let mut expected = 0.9f64;
        for n in 1..200u64 {
            let d = 0.9f64.min((1.0 + n as f64) / (10.0 + n as f64));
            assert_relative_eq!(average.next_decay(), d);
            let w = if n % 2 == 0 { 1.0 } else { -1.0 };
            expected = d * expected + (1.0 - d) * w;
            average.update(&filled(w as f32));
        }
        assert_relative_eq!(average.next_decay(), 0.9);
        for a in values(average.params()) {
            assert!((f64::from(a) - expected).abs() < 1e-5, "{a} vs {expected}");
        }
    }

    #[test]
    fn a_restored_average_continues_bit_for_bit() {
        let weights: Vec<Parameters<Host>> = (0..12)
            .map(|s| Parameters::<Host>::init(&config(), s, &Default::default()))
            .collect();
        let mut whole = WeightAverage::new(0.99, &weights[0]);
        for w in &weights {
            whole.update(w);
        }
        let mut first = WeightAverage::new(0.99, &weights[0]);
        for w in &weights[..5] {
            first.update(w);
        }
        let mut resumed = WeightAverage::restore(0.99, first.params().clone(), first.updates());
        for w in &weights[5..] {
            resumed.update(w);
        }
        assert_eq!(values(resumed.params()), values(whole.params()));
        assert_eq!(resumed.updates(), 12);
    }
}
