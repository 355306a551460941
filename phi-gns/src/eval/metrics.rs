//! The per-frame metrics of a rollout on host data: position error, kinetic energy and density.
//!
//! Every function reads frames `[N·dim]` row-major in stored units and a `liquid` mask of the
//! particles that count (the non-kinematic ones); sums are taken in f64.

use crate::graph::RadiusGraph;
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
/// measure of the evaluation (a compressed liquid has more neighbours than the truth). The
/// radius graph is the GNS's own, whose self-edges are left out here. 0 without liquid
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
    let graph = RadiusGraph::for_positions(&positions, dim, radius)?;
    Ok((graph.edges() - particles) as f64 / particles as f64)
}
