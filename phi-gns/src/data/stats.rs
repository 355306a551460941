//! Velocity and acceleration statistics: Welford's online moments and their exact merge.

use super::{DataError, LIQUID, Trajectory};

/// Count, mean and sum of squared deviations (`M2`) per component of a stream of vectors:
/// Welford's online algorithm in f64, numerically stable for long streams with a large mean.
///
/// Two accumulators of disjoint streams [`merge`](Moments::merge) into the accumulator of the
/// concatenated stream (Chan, Golub and LeVeque's parallel update), equal to a single pass up to
/// rounding. Mean and standard deviation of an empty accumulator are zero.
///
/// ```
/// use phi_gns::data::Moments;
/// let mut a = Moments::new(1);
/// let mut b = Moments::new(1);
/// a.push(&[1.0]);
/// a.push(&[2.0]);
/// b.push(&[6.0]);
/// a.merge(&b)?;
/// assert_eq!(a.count(), 3);
/// assert_eq!(a.mean(), [3.0]);
/// assert!((a.std()[0] - (14.0f64 / 3.0).sqrt()).abs() < 1e-15);
/// # Ok::<(), phi_gns::data::DataError>(())
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct Moments {
    count: u64,
    mean: Vec<f64>,
    m2: Vec<f64>,
}

impl Moments {
    /// An empty accumulator of `dim`-component vectors.
    pub fn new(dim: usize) -> Self {
        Moments {
            count: 0,
            mean: vec![0.0; dim],
            m2: vec![0.0; dim],
        }
    }

    /// An accumulator from its parts, as stored in a trajectory file. Fails unless `mean` and
    /// `m2` have the same length, every value is finite, `M2 ≥ 0`, and an empty accumulator
    /// (count 0) has zero mean and `M2`.
    pub fn from_parts(count: u64, mean: Vec<f64>, m2: Vec<f64>) -> Result<Self, DataError> {
        let bad = |reason: String| {
            Err(DataError::InvalidInput {
                what: "moments",
                reason,
            })
        };
        if mean.len() != m2.len() {
            return bad(format!(
                "mean has {} components but M2 has {}",
                mean.len(),
                m2.len()
            ));
        }
        if !mean.iter().chain(&m2).all(|x| x.is_finite()) {
            return bad("mean and M2 must be finite".into());
        }
        if m2.iter().any(|&x| x < 0.0) {
            return bad(format!("M2 {m2:?} must not be negative"));
        }
        if count == 0 && mean.iter().chain(&m2).any(|&x| x != 0.0) {
            return bad("an empty accumulator must have zero mean and M2".into());
        }
        Ok(Moments { count, mean, m2 })
    }

    /// The number of components of the vectors.
    pub fn dim(&self) -> usize {
        self.mean.len()
    }

    /// The number of vectors pushed (or merged in).
    pub fn count(&self) -> u64 {
        self.count
    }

    /// The mean of each component (zero when empty).
    pub fn mean(&self) -> &[f64] {
        &self.mean
    }

    /// The sum of squared deviations from the mean, `M2 = Σ (x − mean)²`, of each component.
    pub fn m2(&self) -> &[f64] {
        &self.m2
    }

    /// The population variance `M2 / count` of each component (zero when empty).
    pub fn variance(&self) -> Vec<f64> {
        if self.count == 0 {
            return vec![0.0; self.dim()];
        }
        let n = self.count as f64;
        self.m2.iter().map(|m2| m2 / n).collect()
    }

    /// The population standard deviation `sqrt(M2 / count)` of each component, as DeepMind's
    /// `vel_std` / `acc_std` (zero when empty).
    pub fn std(&self) -> Vec<f64> {
        self.variance().into_iter().map(f64::sqrt).collect()
    }

    /// Adds one vector (Welford's update). Only the first [`dim`](Moments::dim) components of
    /// `x` are read; callers pass exactly `dim` of them.
    pub fn push(&mut self, x: &[f64]) {
        debug_assert_eq!(
            x.len(),
            self.dim(),
            "Moments::push: wrong number of components"
        );
        self.count += 1;
        let n = self.count as f64;
        for ((mean, m2), &x) in self.mean.iter_mut().zip(&mut self.m2).zip(x) {
            let delta = x - *mean;
            *mean += delta / n;
            *m2 += delta * (x - *mean);
        }
    }

    /// Adds the vectors that `other` accumulated (Chan et al.'s parallel update):
    /// `n = n_a + n_b`, `δ = mean_b − mean_a`, `mean = mean_a + δ n_b / n`,
    /// `M2 = M2_a + M2_b + δ² n_a n_b / n`. Fails when the dimensions differ.
    pub fn merge(&mut self, other: &Moments) -> Result<(), DataError> {
        if other.dim() != self.dim() {
            return Err(DataError::InvalidInput {
                what: "moments",
                reason: format!(
                    "cannot merge statistics of {} components into statistics of {}",
                    other.dim(),
                    self.dim()
                ),
            });
        }
        if other.count == 0 {
            return Ok(());
        }
        if self.count == 0 {
            *self = other.clone();
            return Ok(());
        }
        let (na, nb) = (self.count as f64, other.count as f64);
        let n = na + nb;
        for i in 0..self.dim() {
            let delta = other.mean[i] - self.mean[i];
            self.mean[i] += delta * (nb / n);
            self.m2[i] += other.m2[i] + delta * delta * (na * nb / n);
        }
        self.count += other.count;
        Ok(())
    }
}

/// The velocity and acceleration [`Moments`] of one trajectory, a split or a dataset.
///
/// Velocities `p[t+1] − p[t]` and accelerations `p[t+1] − 2 p[t] + p[t−1]` of the stored
/// positions (no division by `dt`), per component, of liquid particles only, computed in f64
/// from the f32 positions.
#[derive(Debug, Clone, PartialEq)]
pub struct TrajectoryStats {
    /// Moments of the velocities: `(frames − 1) · liquid` vectors per trajectory.
    pub velocity: Moments,
    /// Moments of the accelerations: `(frames − 2) · liquid` vectors per trajectory.
    pub acceleration: Moments,
}

impl TrajectoryStats {
    /// Empty statistics of `dim`-dimensional positions.
    pub fn new(dim: usize) -> Self {
        TrajectoryStats {
            velocity: Moments::new(dim),
            acceleration: Moments::new(dim),
        }
    }

    /// The statistics of one trajectory, in one pass over its frames.
    pub fn of(traj: &Trajectory) -> Self {
        let dim = traj.dim;
        let mut stats = TrajectoryStats::new(dim);
        let liquid: Vec<usize> = (0..traj.particles)
            .filter(|&i| traj.particle_type[i] == LIQUID)
            .collect();
        let mut v = vec![0.0; dim];
        let mut a = vec![0.0; dim];
        for t in 1..traj.frames {
            let (prev, now) = (traj.frame(t - 1), traj.frame(t));
            let before = (t >= 2).then(|| traj.frame(t - 2));
            for &i in &liquid {
                let range = i * dim..(i + 1) * dim;
                for (k, (&p1, &p0)) in now[range.clone()]
                    .iter()
                    .zip(&prev[range.clone()])
                    .enumerate()
                {
                    v[k] = f64::from(p1) - f64::from(p0);
                }
                stats.velocity.push(&v);
                if let Some(before) = before {
                    for (k, ((&p1, &p0), &pm)) in now[range.clone()]
                        .iter()
                        .zip(&prev[range.clone()])
                        .zip(&before[range.clone()])
                        .enumerate()
                    {
                        a[k] = f64::from(p1) - 2.0 * f64::from(p0) + f64::from(pm);
                    }
                    stats.acceleration.push(&a);
                }
            }
        }
        stats
    }

    /// Adds the statistics of other trajectories (exact parallel merge of both [`Moments`]).
    pub fn merge(&mut self, other: &TrajectoryStats) -> Result<(), DataError> {
        self.velocity.merge(&other.velocity)?;
        self.acceleration.merge(&other.acceleration)
    }
}
