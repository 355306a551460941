//! Windows drawn in proportion to their impacts on obstacles (`[training.impact_sampling]`).
//!
//! A block that lands on an obstacle is stopped within a frame or two, and those frames are
//! rare in the data: a uniform draw finds an obstacle within the connectivity radius of a liquid
//! particle in ~3 % of particle-frames, and the first contacts of a fall, where the stop is
//! largest, in far fewer. A FLIP restart from the positions alone (`examples/flip_observed.rs`)
//! reproduces that stop, so the model's inputs determine it, yet models trained on uniform draws
//! brake at first contact by a third of it. With impact sampling a fraction `share` of the draws
//! comes from the windows whose targets hold an *obstacle impact* — a liquid particle within the
//! connectivity radius of a kinematic particle at the latest input frame whose normalised target
//! acceleration exceeds `threshold` (Euclidean norm over the dimensions, in units of the
//! dataset's `acc_std` after removing `acc_mean`) — each with weight its number of such
//! particles; the rest are drawn uniformly as before.
//!
//! Drawing other windows more often changes which inputs the model sees, not what follows from
//! an input, so the loss is left unweighted: its minimiser for each input is the same, and the
//! rare inputs get more of the steps.

use serde::{Deserialize, Serialize};

use super::loss::obstacle_weights;
use super::rng::uniform_index;
use super::sampler::WindowSampler;
use crate::data::{DataError, Dataset};

/// `[training.impact_sampling]`: see the [module documentation](self).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ImpactSampling {
    /// The fraction of the draws taken from the windows with obstacle impacts, in `(0, 1]`.
    pub share: f64,
    /// The normalised acceleration above which a liquid particle near an obstacle counts as an
    /// impact (default 3).
    #[serde(default = "ImpactSampling::default_threshold")]
    pub threshold: f64,
}

impl ImpactSampling {
    fn default_threshold() -> f64 {
        3.0
    }

    /// The share and threshold checked: `Err(key, reason)`.
    pub(crate) fn check(&self) -> Result<(), (&'static str, String)> {
        if !(self.share > 0.0 && self.share <= 1.0) {
            return Err((
                "training.impact_sampling.share",
                format!("{} is not in (0, 1]", self.share),
            ));
        }
        if !(self.threshold.is_finite() && self.threshold > 0.0) {
            return Err((
                "training.impact_sampling.threshold",
                format!("{} is not > 0", self.threshold),
            ));
        }
        Ok(())
    }
}

/// What makes a liquid particle of a window an obstacle impact: the particle types that are
/// kinematic (obstacles), the connectivity radius, and the normalisation of the accelerations.
#[derive(Debug, Clone, PartialEq)]
pub struct ImpactCriterion {
    /// Kinematic (obstacle) particle types.
    pub kinematic_types: Vec<i64>,
    /// The connectivity radius in stored units.
    pub radius: f64,
    /// The dataset's `acc_mean` per dimension (stored units per frame²).
    pub acc_mean: Vec<f64>,
    /// The dataset's `acc_std` per dimension.
    pub acc_std: Vec<f64>,
    /// [`ImpactSampling::threshold`].
    pub threshold: f64,
}

impl ImpactCriterion {
    /// The number of obstacle impacts of the window whose latest input frame is `now`
    /// (`[N·dim]` positions each, `before` the frame before it, `next` the target frame).
    pub fn count(
        &self,
        before: &[f32],
        now: &[f32],
        next: &[f32],
        particle_type: &[i64],
        dim: usize,
    ) -> u32 {
        // Weight 2 marks the counted particles with an obstacle within R ([`obstacle_weights`]).
        let near = obstacle_weights(
            now,
            dim,
            particle_type,
            &self.kinematic_types,
            self.radius as f32,
            2.0,
        );
        let mut count = 0;
        for (i, weight) in near.iter().enumerate() {
            if *weight != 2.0 {
                continue;
            }
            let size: f64 = (0..dim)
                .map(|a| {
                    let k = i * dim + a;
                    let acc = f64::from(next[k]) - 2.0 * f64::from(now[k]) + f64::from(before[k]);
                    ((acc - self.acc_mean[a]) / self.acc_std[a]).powi(2)
                })
                .sum::<f64>()
                .sqrt();
            if size > self.threshold {
                count += 1;
            }
        }
        count
    }
}

/// The windows of a sampler with obstacle impacts, each drawn with probability in proportion to
/// its number of impacts.
#[derive(Debug, Clone, PartialEq)]
pub struct ImpactPool {
    /// The windows, as the sampler numbers them ([`WindowSampler::window`]), ascending.
    windows: Vec<usize>,
    /// `ends[j]`: the impacts of windows `0..=j` of the pool.
    ends: Vec<u64>,
}

impl ImpactPool {
    /// The pool of `windows` (the sampler's numbers, ascending) with their impact counts; the
    /// windows without impacts are left out.
    pub fn new(counts: impl IntoIterator<Item = (usize, u32)>) -> Self {
        let mut windows = Vec::new();
        let mut ends = Vec::new();
        let mut total = 0u64;
        for (window, count) in counts {
            if count > 0 {
                total += u64::from(count);
                windows.push(window);
                ends.push(total);
            }
        }
        ImpactPool { windows, ends }
    }

    /// Reads every trajectory of `sampler`'s split and counts the impacts of each window (the
    /// first target frame after its latest input frame).
    ///
    /// # Errors
    /// A trajectory file that cannot be read (named).
    pub fn scan(
        dataset: &Dataset,
        sampler: &WindowSampler,
        criterion: &ImpactCriterion,
    ) -> Result<Self, DataError> {
        let spec = sampler.spec();
        let mut counts = Vec::new();
        let mut first_window = 0;
        for (index, &frames) in sampler.lengths().iter().enumerate() {
            let windows = spec.windows_in(frames);
            if windows > 0 {
                let (trajectory, _) = dataset.read_with_stats(sampler.split(), index)?;
                let dim = trajectory.dim;
                for w in 0..windows {
                    let t = spec.first_latest_frame() + w;
                    let count = criterion.count(
                        trajectory.frame(t - 1),
                        trajectory.frame(t),
                        trajectory.frame(t + 1),
                        &trajectory.particle_type,
                        dim,
                    );
                    counts.push((first_window + w, count));
                }
            }
            first_window += windows;
        }
        Ok(Self::new(counts))
    }

    /// The number of windows with an impact.
    pub fn windows(&self) -> usize {
        self.windows.len()
    }

    /// The number of impacts over all windows.
    pub fn impacts(&self) -> u64 {
        self.ends.last().copied().unwrap_or(0)
    }

    /// One window, in proportion to its impacts; `None` for an empty pool.
    pub(crate) fn draw(&self, rng: &mut impl rand::RngCore) -> Option<usize> {
        let total = self.impacts();
        if total == 0 {
            return None;
        }
        let k = uniform_index(rng, total as usize) as u64;
        let j = self.ends.partition_point(|&end| end <= k);
        Some(self.windows[j])
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::train::rng::{RngStream, step_rng};

    fn criterion() -> ImpactCriterion {
        ImpactCriterion {
            kinematic_types: vec![3],
            radius: 0.03,
            acc_mean: vec![0.0, 0.0],
            acc_std: vec![1e-4, 1e-4],
            threshold: 3.0,
        }
    }

    #[test]
    fn an_impact_is_a_large_acceleration_near_an_obstacle() {
        // An obstacle particle at (0.5, 0.5); liquid stopped beside it (an impact), stopped far
        // from it (a wall's business), and moving steadily beside it (no acceleration).
        let types = [3, 5, 5, 5];
        let now = [0.5f32, 0.5, 0.5, 0.52, 0.8, 0.8, 0.48, 0.5];
        // 1e-3 a frame downwards before, at rest after: 10 acc_std upwards.
        let before = [0.5f32, 0.5, 0.5, 0.521, 0.8, 0.801, 0.48, 0.5001];
        let next = [0.5f32, 0.5, 0.5, 0.52, 0.8, 0.8, 0.48, 0.4999];
        assert_eq!(criterion().count(&before, &now, &next, &types, 2), 1);
        // The stop beside the obstacle is below a threshold of 20 standard deviations.
        let high = ImpactCriterion {
            threshold: 20.0,
            ..criterion()
        };
        assert_eq!(high.count(&before, &now, &next, &types, 2), 0);
        // Without obstacle particles there is no impact.
        assert_eq!(criterion().count(&before, &now, &next, &[5, 5, 5, 5], 2), 0);
    }

    #[test]
    fn the_pool_draws_windows_in_proportion_to_their_impacts() {
        let pool = ImpactPool::new([(2, 1), (4, 0), (7, 3)]);
        assert_eq!((pool.windows(), pool.impacts()), (2, 4));
        let mut rng = step_rng(0, 0, RngStream::Sampling);
        let draws = 40_000;
        let sevens = (0..draws)
            .filter(|_| pool.draw(&mut rng) == Some(7))
            .count();
        // 3 of 4; the standard deviation of the share is ~0.002.
        let share = sevens as f64 / f64::from(draws);
        assert!((share - 0.75).abs() < 0.01, "{share}");
        assert_eq!(ImpactPool::new([(1, 0)]).draw(&mut rng), None);
    }

    #[test]
    fn share_and_threshold_are_checked() {
        let good = ImpactSampling {
            share: 0.5,
            threshold: 3.0,
        };
        assert!(good.check().is_ok());
        for bad in [0.0, -0.1, 1.5, f64::NAN] {
            let (key, _) = ImpactSampling { share: bad, ..good }.check().unwrap_err();
            assert_eq!(key, "training.impact_sampling.share");
        }
        for bad in [0.0, -1.0, f64::INFINITY] {
            let (key, _) = ImpactSampling {
                threshold: bad,
                ..good
            }
            .check()
            .unwrap_err();
            assert_eq!(key, "training.impact_sampling.threshold");
        }
    }
}
