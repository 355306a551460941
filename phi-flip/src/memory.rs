//! What a scene will need in memory, estimated from its keys before anything is allocated, so
//! that a request far beyond the machine (`resolution = [100000, 100000]`,
//! `particles_per_cell = 1000000000`) is refused with the key that asks for it instead of
//! ending in a failed allocation.
//!
//! The estimate is deliberately generous (an upper bound within a small factor of what a step
//! really holds), computed in `f64` so that no product of sizes can overflow:
//! - the grid: [`GRID_FLOATS_PER_CELL`] `f32` values per cell and axis-count (the staggered
//!   velocities of a step, their weights and masks, the pressure and the solver's vectors);
//! - the particles: [`PARTICLE_FLOATS_PER_STEP`] per particle and axis, plus the transfer's
//!   `2^d` corner weights, during a step; their count is bounded by the cells of each liquid's and
//!   each inflow's bounding box times `particles_per_cell` (an inflow's for every emission, as
//!   particles never leave the domain);
//! - what a caller keeps per recorded frame and particle (`phi simulate` keeps every frame),
//!   given as bytes.

use crate::error::{FlipError, Result};
use crate::scene::Scene;

/// `f32` values a step holds per grid cell, per axis (see the module docs).
pub const GRID_FLOATS_PER_CELL: f64 = 24.0;

/// `f32` values a step holds per particle, per axis, besides the transfer's corner weights.
pub const PARTICLE_FLOATS_PER_STEP: f64 = 16.0;

/// The estimated memory of a scene, in bytes, by what asks for it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MemoryEstimate {
    /// Grid cells.
    pub cells: f64,
    /// The most particles the run can hold.
    pub particles: f64,
    /// The grid's share.
    pub grid_bytes: f64,
    /// The particles' share during a step.
    pub particle_bytes: f64,
    /// What the caller records (frames × particles × bytes per particle and frame).
    pub recorded_bytes: f64,
}

impl MemoryEstimate {
    /// The whole estimate.
    pub fn total(&self) -> f64 {
        self.grid_bytes + self.particle_bytes + self.recorded_bytes
    }
}

impl Scene {
    /// The memory a run of `steps` steps needs, when the caller keeps `recorded_frames` frames of
    /// `bytes_per_recorded_particle` bytes per particle each (0 for nothing). Reads the scene's
    /// keys only; allocates nothing.
    pub fn memory_estimate(
        &self,
        steps: usize,
        recorded_frames: usize,
        bytes_per_recorded_particle: f64,
    ) -> MemoryEstimate {
        let d = self.dim();
        let resolution: Vec<f64> = self.domain.resolution.iter().map(|&n| n as f64).collect();
        let size: Vec<f64> = match &self.domain.size {
            Some(size) => size.iter().map(|&s| f64::from(s)).collect(),
            None => resolution.clone(),
        };
        let cells: f64 = resolution.iter().product();
        let ppc = self.simulation.particles_per_cell as f64;
        // Cells whose centre lies in a bounding box, clamped to the domain.
        let cells_in = |geometry: &phi_geom::Geometry| -> f64 {
            let bbox = geometry.bounding_box();
            (0..d)
                .map(|a| {
                    let (n, dx) = (resolution[a], size[a] / resolution[a]);
                    let first = (f64::from(bbox.lower()[a]) / dx - 0.5).ceil().max(0.0);
                    let last = (f64::from(bbox.upper()[a]) / dx - 0.5).floor().min(n - 1.0);
                    (last - first + 1.0).max(0.0)
                })
                .product()
        };
        let mut particles: f64 = self
            .liquids
            .iter()
            .map(|l| cells_in(&l.geometry) * ppc)
            .sum();
        for inflow in &self.inflows {
            let active = inflow.until_step.map_or(steps, |u| u.min(steps)) as f64;
            let emissions = (active / inflow.every as f64).ceil();
            particles += emissions * cells_in(&inflow.geometry) * ppc;
        }
        let d_f = d as f64;
        let corners = 2f64.powi(d as i32);
        MemoryEstimate {
            cells,
            particles,
            grid_bytes: 4.0 * GRID_FLOATS_PER_CELL * d_f * cells,
            particle_bytes: 4.0
                * (PARTICLE_FLOATS_PER_STEP * d_f + 3.0 * d_f * corners)
                * particles,
            recorded_bytes: recorded_frames as f64 * particles * bytes_per_recorded_particle,
        }
    }

    /// [`memory_estimate`](Self::memory_estimate), refused when it exceeds `limit` bytes.
    ///
    /// # Errors
    /// [`FlipError::Scene`] naming `origin`, the key to change (`domain.resolution` when the
    /// grid alone exceeds the limit, `simulation.particles_per_cell` when one frame of particles
    /// does, else the largest share, `simulation.steps` for the recorded frames), the estimate and
    /// the limit.
    pub fn check_memory(
        &self,
        origin: &str,
        steps: usize,
        recorded_frames: usize,
        bytes_per_recorded_particle: f64,
        limit: f64,
    ) -> Result<MemoryEstimate> {
        let estimate = self.memory_estimate(steps, recorded_frames, bytes_per_recorded_particle);
        if estimate.total() <= limit {
            return Ok(estimate);
        }
        let shares = [
            (
                estimate.grid_bytes,
                "domain.resolution",
                format!("{:.3e} cells", estimate.cells),
            ),
            (
                estimate.particle_bytes,
                "simulation.particles_per_cell",
                format!(
                    "up to {:.3e} particles ({} per cell)",
                    estimate.particles, self.simulation.particles_per_cell
                ),
            ),
            (
                estimate.recorded_bytes,
                "simulation.steps",
                format!(
                    "{recorded_frames} recorded frames of up to {:.3e} particles",
                    estimate.particles
                ),
            ),
        ];
        // The key to change: the grid when it alone is too large, the particles when one frame
        // of them is, else whichever share weighs most.
        let one_frame =
            estimate.particle_bytes + estimate.recorded_bytes / recorded_frames.max(1) as f64;
        let (_, key, what) = if estimate.grid_bytes > limit {
            &shares[0]
        } else if one_frame > limit {
            &shares[1]
        } else {
            shares
                .iter()
                .max_by(|a, b| a.0.total_cmp(&b.0))
                .expect("three shares")
        };
        Err(FlipError::Scene {
            path: origin.into(),
            key: (*key).into(),
            reason: format!(
                "{what} need about {} of memory (grid {}, particles {}, recorded frames {}), \
                 more than the limit of {}",
                human_bytes(estimate.total()),
                human_bytes(estimate.grid_bytes),
                human_bytes(estimate.particle_bytes),
                human_bytes(estimate.recorded_bytes),
                human_bytes(limit)
            ),
        })
    }
}

/// `bytes` in binary units (`1.5 GiB`).
pub fn human_bytes(bytes: f64) -> String {
    const UNITS: [&str; 7] = ["B", "KiB", "MiB", "GiB", "TiB", "PiB", "EiB"];
    let mut value = bytes;
    let mut unit = 0;
    while value >= 1024.0 && unit + 1 < UNITS.len() {
        value /= 1024.0;
        unit += 1;
    }
    if unit == 0 {
        format!("{value:.0} B")
    } else if value.is_finite() && value < 1e4 {
        format!("{value:.1} {}", UNITS[unit])
    } else {
        format!("{value:.3e} {}", UNITS[unit])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scene(resolution: &str, ppc: u64, extra: &str) -> Scene {
        let text = format!(
            "[domain]\nresolution = {resolution}\n[simulation]\ndt = 0.1\nsteps = 10\n\
             particles_per_cell = {ppc}\n[[liquid]]\n\
             geometry = {{ type = \"box\", lower = [0, 0], upper = [4, 2] }}\n{extra}"
        );
        Scene::from_toml(&text, "t.toml").unwrap()
    }

    /// The particle bound counts the cell centres of the bounding box, inflows per emission.
    #[test]
    fn particles_are_bounded_by_the_cells_of_the_regions() {
        let s = scene("[8, 8]", 3, "");
        let e = s.memory_estimate(10, 0, 0.0);
        assert_eq!(e.cells, 64.0);
        assert_eq!(e.particles, 4.0 * 2.0 * 3.0);
        assert_eq!(e.recorded_bytes, 0.0);
        let s = scene(
            "[8, 8]",
            3,
            "[[inflow]]\ngeometry = { type = \"box\", lower = [0, 6], upper = [1, 8] }\n\
             velocity = [0, 0]\nevery = 3\nuntil_step = 7\n",
        );
        // Emissions at steps 0, 3 and 6, of 1 × 2 cells.
        let e = s.memory_estimate(10, 11, 8.0);
        assert_eq!(e.particles, 24.0 + 3.0 * 2.0 * 3.0);
        assert_eq!(e.recorded_bytes, 11.0 * e.particles * 8.0);
    }

    /// A request past the limit names the key that weighs most, the estimate and the limit.
    #[test]
    fn too_large_requests_name_the_key() {
        let s = scene("[100000, 100000]", 1, "");
        let e = s
            .check_memory("t.toml", 10, 0, 0.0, 1e9)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("t.toml") && e.contains("domain.resolution") && e.contains("limit"),
            "{e}"
        );
        let s = scene("[8, 8]", 1_000_000_000, "");
        let e = s
            .check_memory("t.toml", 10, 11, 24.0, 1e9)
            .unwrap_err()
            .to_string();
        assert!(e.contains("simulation.particles_per_cell"), "{e}");
        let s = scene("[8, 8]", 8, "");
        let e = s
            .check_memory("t.toml", 10, 100_000_000, 24.0, 1e9)
            .unwrap_err()
            .to_string();
        assert!(e.contains("simulation.steps"), "{e}");
        assert!(s.check_memory("t.toml", 10, 11, 24.0, 1e9).is_ok());
    }

    #[test]
    fn bytes_read_in_binary_units() {
        assert_eq!(human_bytes(512.0), "512 B");
        assert_eq!(human_bytes(1536.0), "1.5 KiB");
        assert_eq!(human_bytes(3.0 * 1024f64.powi(3)), "3.0 GiB");
    }
}
