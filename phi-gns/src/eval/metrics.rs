//! The per-frame metrics of a rollout on host data: position error, kinetic energy, density,
//! and whether the liquid stays in its container and out of the obstacles.
//!
//! Every function reads frames `[N·dim]` row-major in stored units and a `liquid` mask of the
//! particles that count (the non-kinematic ones); sums are taken in f64.

use serde::{Deserialize, Serialize};

use crate::graph::neighbour_counts;
use crate::model::ModelError;

/// The positions of the `liquid` particles of a frame `[N·dim]`: `[L·dim]`.
pub fn liquid_positions(frame: &[f32], liquid: &[bool], dim: usize) -> Vec<f32> {
    liquid
        .iter()
        .enumerate()
        .filter(|(_, l)| **l)
        .flat_map(|(i, _)| frame[i * dim..(i + 1) * dim].iter().copied())
        .collect()
}

/// The kinetic energy per liquid particle of unit mass between two consecutive frames:
/// `½ mean_i |p_t,i − p_{t−1},i|²` (stored units² per frame², velocities as per-frame
/// displacements, the units the GNS integrates in). 0 without liquid particles.
pub fn kinetic_energy(previous: &[f32], current: &[f32], liquid: &[bool], dim: usize) -> f64 {
    let mut sum = 0.0f64;
    let mut count = 0usize;
    for (i, _) in liquid.iter().enumerate().filter(|(_, l)| **l) {
        for a in i * dim..(i + 1) * dim {
            let v = f64::from(current[a]) - f64::from(previous[a]);
            sum += v * v;
        }
        count += 1;
    }
    if count == 0 {
        0.0
    } else {
        0.5 * sum / count as f64
    }
}

/// The mean number of other liquid particles within `radius` of a liquid particle: the density
/// measure of the evaluation (a compressed liquid has more neighbours than the truth), on the
/// GNS's own radius graph without its self-edges ([`neighbour_counts`]). 0 without liquid
/// particles.
///
/// # Errors
/// [`ModelError::Graph`] for non-finite positions or a radius that is not positive and finite.
pub fn mean_neighbour_count(
    frame: &[f32],
    liquid: &[bool],
    dim: usize,
    radius: f64,
) -> Result<f64, ModelError> {
    let positions = liquid_positions(frame, liquid, dim);
    let particles = positions.len() / dim.max(1);
    if particles == 0 {
        return Ok(0.0);
    }
    let counts = neighbour_counts(&positions, dim, radius)?;
    Ok(counts.iter().sum::<usize>() as f64 / particles as f64)
}

/// The domain a rollout must stay in and the cells its obstacles fill: what the plausibility
/// metrics of an evaluation measure against.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Container {
    /// `[min, max]` per axis, stored units.
    pub bounds: Vec<[f64; 2]>,
    /// The side of a grid cell in stored units (the dataset's `position_scale`); obstacle
    /// particles sit one at the centre of each obstacle cell.
    pub cell_size: f64,
}

impl Container {
    /// The integer cell of a position, counted from the lower bounds.
    fn cell_of(&self, p: &[f32]) -> Vec<i64> {
        p.iter()
            .zip(&self.bounds)
            .map(|(x, [lo, _])| ((f64::from(*x) - lo) / self.cell_size).floor() as i64)
            .collect()
    }

    /// The cells holding an obstacle particle of `frame` (those not `liquid`).
    pub fn obstacle_cells(
        &self,
        frame: &[f32],
        liquid: &[bool],
        dim: usize,
    ) -> std::collections::HashSet<Vec<i64>> {
        liquid
            .iter()
            .enumerate()
            .filter(|(_, l)| !**l)
            .map(|(i, _)| self.cell_of(&frame[i * dim..(i + 1) * dim]))
            .collect()
    }

    /// How many liquid particles of `frame` lie outside the bounds, and how many inside a cell
    /// of `obstacles` ([`Container::obstacle_cells`]).
    pub fn misplaced(
        &self,
        frame: &[f32],
        liquid: &[bool],
        dim: usize,
        obstacles: &std::collections::HashSet<Vec<i64>>,
    ) -> (usize, usize) {
        let (mut outside, mut inside) = (0, 0);
        for (i, _) in liquid.iter().enumerate().filter(|(_, l)| **l) {
            let p = &frame[i * dim..(i + 1) * dim];
            let out = p
                .iter()
                .zip(&self.bounds)
                .any(|(x, [lo, hi])| !(*lo..=*hi).contains(&f64::from(*x)));
            if out {
                outside += 1;
            } else if obstacles.contains(&self.cell_of(p)) {
                inside += 1;
            }
        }
        (outside, inside)
    }
}

/// The centre of mass of the liquid particles of `frame` (unit masses).
pub fn centre_of_mass(frame: &[f32], liquid: &[bool], dim: usize) -> Vec<f64> {
    let mut sum = vec![0.0f64; dim];
    let mut count = 0usize;
    for (i, _) in liquid.iter().enumerate().filter(|(_, l)| **l) {
        count += 1;
        for (a, s) in sum.iter_mut().enumerate() {
            *s += f64::from(frame[i * dim + a]);
        }
    }
    sum.iter().map(|s| s / count.max(1) as f64).collect()
}
