//! Random-walk noise on the input window (DeepMind's `get_random_walk_noise_for_position_sequence`).
//!
//! Each of the `C` input velocities gets independent noise `N(0, σ²/C)` per component; the noise
//! of the velocities is accumulated over the window (a random walk, so the last velocity's noise
//! has standard deviation `σ`), and integrated into the positions, the first position unchanged.
//! Kinematic particles get none. The training target is then the next position shifted by the
//! latest position's noise, so that the model learns to bring a noisy particle back onto its true
//! path ([`RandomWalkNoise::adjust_target`]).

use rand::Rng;
use rand_distr::{Distribution, Normal};

/// The noise of one window: `[N, C + 1, dim]` position offsets, row-major.
#[derive(Debug, Clone, PartialEq)]
pub struct RandomWalkNoise {
    offsets: Vec<f32>,
    particles: usize,
    window: usize,
    dim: usize,
}

impl RandomWalkNoise {
    /// The offsets `[N, C + 1, dim]`, row-major.
    pub fn offsets(&self) -> &[f32] {
        &self.offsets
    }

    /// `window + noise`, both `[N, C + 1, dim]` row-major.
    ///
    /// # Panics
    /// If `window` has another length (a caller's bug: the noise was drawn for its shape).
    pub fn apply(&self, window: &[f32]) -> Vec<f32> {
        assert_eq!(
            window.len(),
            self.offsets.len(),
            "noise drawn for another window"
        );
        window
            .iter()
            .zip(&self.offsets)
            .map(|(p, n)| p + n)
            .collect()
    }

    /// The next positions `[N, dim]` shifted by the latest position's noise: the target that
    /// makes the model undo the noise (DeepMind's `next_position_adjusted`).
    ///
    /// # Panics
    /// If `next` is not `[N, dim]`.
    pub fn adjust_target(&self, next: &[f32]) -> Vec<f32> {
        let (n, w, d) = (self.particles, self.window, self.dim);
        assert_eq!(next.len(), n * d, "next positions of another shape");
        let mut adjusted = next.to_vec();
        for i in 0..n {
            let last = (i * w + w - 1) * d;
            for k in 0..d {
                adjusted[i * d + k] += self.offsets[last + k];
            }
        }
        adjusted
    }
}

/// Random-walk noise of standard deviation `noise_std` at the last velocity for a window of
/// `window = C + 1` positions of `kinematic.len()` particles in `dim` dimensions; particles
/// marked `kinematic` get none. Drawn from `rng` in particle, then velocity, then component order.
pub fn random_walk_noise(
    kinematic: &[bool],
    window: usize,
    dim: usize,
    noise_std: f64,
    rng: &mut impl Rng,
) -> RandomWalkNoise {
    let n = kinematic.len();
    let velocities = window.saturating_sub(1);
    let mut offsets = vec![0.0f32; n * window * dim];
    let per_step = if velocities > 0 {
        noise_std / (velocities as f64).sqrt()
    } else {
        0.0
    };
    // A zero or invalid std draws nothing (Normal::new rejects only non-finite values).
    let normal = Normal::new(0.0, per_step).ok().filter(|_| per_step > 0.0);
    for (i, &fixed) in kinematic.iter().enumerate() {
        let Some(normal) = normal.filter(|_| !fixed) else {
            continue;
        };
        let mut velocity = vec![0.0f64; dim];
        let mut position = vec![0.0f64; dim];
        for t in 1..window {
            for k in 0..dim {
                velocity[k] += normal.sample(rng);
                position[k] += velocity[k];
                offsets[(i * window + t) * dim + k] = position[k] as f32;
            }
        }
    }
    RandomWalkNoise {
        offsets,
        particles: n,
        window,
        dim,
    }
}
