//! What a step checks and reports beside the algorithm: scene parameters that fit, a finite
//! state, the CFL warning and the step's statistics.

use std::sync::atomic::Ordering;

use phi_core::backend::Backend;
use phi_core::fields::Domain;
use phi_core::host::all_finite;

use super::{FlipSimulation, Particles, SceneParameters};
use crate::error::{FlipError, Result};

impl<B: Backend> FlipSimulation<B> {
    /// Checks that `scene` fits this simulation (shapes and counts).
    pub(super) fn check_scene_parameters(&self, scene: &SceneParameters<B>) -> Result<()> {
        let d = self.domain.dim();
        let invalid = |reason: String| {
            Err(FlipError::InvalidParameter {
                name: "scene parameters",
                reason,
            })
        };
        if scene.gravity.shape() != [d] {
            return invalid(format!(
                "gravity must have shape [{d}], got {:?}",
                scene.gravity.shape()
            ));
        }
        for (what, tensors, count) in [
            (
                "obstacle_offsets",
                &scene.obstacle_offsets,
                self.obstacles.len(),
            ),
            (
                "inflow_velocities",
                &scene.inflow_velocities,
                self.inflows.len(),
            ),
        ] {
            if tensors.len() != count {
                return invalid(format!(
                    "{what}: one per {}, {count} expected, got {}",
                    if what.starts_with("obstacle") {
                        "obstacle"
                    } else {
                        "inflow"
                    },
                    tensors.len()
                ));
            }
            if let Some(t) = tensors.iter().find(|t| t.shape() != [1, d]) {
                return invalid(format!(
                    "{what} must have shape [1, {d}], got {:?}",
                    t.shape()
                ));
            }
        }
        Ok(())
    }

    /// Logs that the grid velocity moves particles `reach_cells` cells in one step when that
    /// exceeds [`FlipParams::cfl_warning_cells`]: a warning the first time in this simulation,
    /// at debug level afterwards.
    ///
    /// [`FlipParams::cfl_warning_cells`]: super::FlipParams::cfl_warning_cells
    pub(super) fn log_cfl(&self, reach_cells: f32, step: usize) {
        let limit = self.params.cfl_warning_cells;
        if reach_cells > limit {
            if !self.cfl_warned.swap(true, Ordering::Relaxed) {
                tracing::warn!(
                    step,
                    "the grid velocity moves particles {reach_cells:.1} cells in one step (CFL \
                     limit {limit} cells); consider a smaller dt (later steps are logged at debug \
                     level)"
                );
            } else {
                tracing::debug!(step, cells = reach_cells, "CFL limit exceeded");
            }
        }
    }
}

/// Checks that the particles a step produced are finite: their `positions` and `velocities`
/// (host data `[N·d]`, read back once for this, the CFL number and the statistics) and affine
/// matrices.
///
/// # Errors
/// [`FlipError::NonFinite`] naming `step` and the first quantity that is not finite.
pub(super) fn check_finite<B: Backend>(
    positions: &[f32],
    velocities: &[f32],
    particles: &Particles<B>,
    step: usize,
) -> Result<()> {
    let non_finite = |what| Err(FlipError::NonFinite { step, what });
    if !all_finite(positions) {
        return non_finite("particle positions");
    }
    if !all_finite(velocities) {
        return non_finite("particle velocities");
    }
    if let Some(c) = &particles.affine
        && !all_finite(&c.host_values())
    {
        return non_finite("particle affine matrices");
    }
    Ok(())
}

/// The largest absolute value per axis of velocities `[N·d]` (row-major `[N, d]`); NaN when
/// one is NaN.
pub(super) fn largest_speed_per_axis(velocities: &[f32], d: usize) -> Vec<f32> {
    let mut largest = vec![0.0f32; d];
    for v in velocities.chunks_exact(d) {
        for (m, x) in largest.iter_mut().zip(v) {
            let a = x.abs();
            if a > *m || a.is_nan() {
                *m = a;
            }
        }
    }
    largest
}

/// The largest distance in cells between `after` and `before` (host data `[N·d]`, finite).
pub(super) fn largest_displacement(after: &[f32], before: &[f32], domain: &Domain) -> f32 {
    match domain.dim() {
        1 => largest_displacement_in::<1>(after, before, domain),
        2 => largest_displacement_in::<2>(after, before, domain),
        _ => largest_displacement_in::<3>(after, before, domain),
    }
}

/// The largest distance in cells between `after` and `before` (points `[N, D]`, row-major, all
/// finite). The square root is taken once, of the largest square (it is monotonic), and the
/// maximum runs in independent lanes: a running maximum over the points would chain them all.
fn largest_displacement_in<const D: usize>(after: &[f32], before: &[f32], domain: &Domain) -> f32 {
    const LANES: usize = 8;
    let dx = domain.cell_size();
    let squared = |a: &[f32], b: &[f32]| {
        let mut sum = 0.0f32;
        for axis in 0..D {
            let t = (a[axis] - b[axis]) / dx[axis];
            sum += t * t;
        }
        sum
    };
    let mut largest = [0.0f32; LANES];
    let (a_blocks, b_blocks) = (
        after.chunks_exact(D * LANES),
        before.chunks_exact(D * LANES),
    );
    let (a_rest, b_rest) = (a_blocks.remainder(), b_blocks.remainder());
    for (a, b) in a_blocks.zip(b_blocks) {
        for (lane, largest) in largest.iter_mut().enumerate() {
            let at = lane * D..(lane + 1) * D;
            *largest = largest.max(squared(&a[at.clone()], &b[at]));
        }
    }
    for (a, b) in a_rest.chunks_exact(D).zip(b_rest.chunks_exact(D)) {
        largest[0] = largest[0].max(squared(a, b));
    }
    largest.into_iter().fold(0.0f32, f32::max).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The largest displacement is the largest Euclidean distance in cells, with anisotropic
    /// cells and with points in the lanes and in the remainder.
    #[test]
    fn largest_displacement_is_the_largest_distance_in_cells() {
        let domain = Domain::new(
            &[4, 8],
            &[0.0, 0.0],
            &[2.0, 2.0],
            &[[phi_core::fields::Boundary::Closed; 2]; 2],
        )
        .unwrap();
        for n in [1usize, 8, 9, 21] {
            let before: Vec<f32> = (0..2 * n).map(|i| (i % 7) as f32 * 0.1).collect();
            let mut after = before.clone();
            // Point k moves by (0.01 k, 0.02 k); cells are 0.5 × 0.25.
            for k in 0..n {
                after[2 * k] += 0.01 * k as f32;
                after[2 * k + 1] += 0.02 * k as f32;
            }
            let want = (0..n)
                .map(|k| {
                    let (x, y) = (
                        (after[2 * k] - before[2 * k]) / 0.5,
                        (after[2 * k + 1] - before[2 * k + 1]) / 0.25,
                    );
                    (x * x + y * y).sqrt()
                })
                .fold(0.0f32, f32::max);
            let got = largest_displacement_in::<2>(&after, &before, &domain);
            assert_eq!(got, want, "n {n}");
        }
    }
}
