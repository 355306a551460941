//! The stages of one FLIP step, thesis algorithm 1, lines 3–8, in the order
//! [`FlipSimulation::step_with`] calls them.
//!
//! Shapes: `N` particles in `d` dimensions on a grid of resolution `[n₀, …, n_{d−1}]`; positions
//! and velocities are `[N, d]` (domain units, domain units per second), APIC's affine matrices
//! `[N, d, d]` (per second); a staggered grid holds one tensor per axis `a`, the resolution with
//! one more sample along `a`.

use phi_core::backend::{Backend, ReduceOp};
use phi_core::fields::LatticeKernels;
use phi_core::fields::{
    Domain, Integrator, PointCloud, Projection, ProjectionMasks, StaggeredGrid, Transfer,
    advect_points, extrapolate_valid, occupied_cells_from_host, particles_to_staggered,
    particles_to_staggered_affine, pressure_projection, sample_staggered,
    sample_staggered_gradient, valid_faces,
};
use phi_core::{Tensor, TensorError};
use phi_geom::PushDirection;

use super::obstacles::ObstacleMasks;
use super::{FlipSimulation, Particles};
use crate::error::{FlipError, Result};

impl<B: LatticeKernels> FlipSimulation<B> {
    /// Line 3, "map particle values to staggered grid to get the velocity field `uᵢ`": the
    /// particles' velocities splatted onto the faces with [`FlipParams::transfer`]
    /// (APIC adds each particle's affine velocity `C (x_face − x_p)`). Returns `uᵢ` and the
    /// faces that received particle weight (`0/1`), both staggered.
    ///
    /// [`FlipParams::transfer`]: super::FlipParams::transfer
    pub(super) fn particles_to_grid(
        &self,
        particles: &Particles<B>,
    ) -> Result<(StaggeredGrid<B>, StaggeredGrid<B>)> {
        let (domain, transfer) = (&self.domain, self.params.transfer);
        let cloud = PointCloud::new(particles.positions.clone(), particles.velocities.clone())?;
        let (grid, weights) = match &particles.affine {
            Some(affine) if self.params.apic => {
                particles_to_staggered_affine(&cloud, affine, domain, transfer)?
            }
            _ => particles_to_staggered(&cloud, domain, transfer)?,
        };
        Ok((grid, valid_faces(&weights)?))
    }

    /// Line 4, "add forces (e.g. gravity) to `uᵢ`": `u + g Δt` on every face, with the gravity
    /// `g` `[d]` in domain units per s² and the (sub-)step `dt`.
    pub(super) fn add_gravity(
        &self,
        velocity: &StaggeredGrid<B>,
        gravity: &Tensor<B>,
        dt: f32,
    ) -> Result<StaggeredGrid<B>> {
        Ok(velocity.map(|axis, c| Ok(c + &(gravity.narrow(0, axis..axis + 1)? * dt)))?)
    }

    /// Line 5, "subtract pressure gradient from `uᵢ` and receive divergence-free velocity field
    /// `u_f`": the pressure projection on the liquid cells, those that hold one of the particles
    /// at `positions` (host data `[N·d]`) and are not inside an obstacle, with the faces the
    /// obstacles block closed (carrying the obstacles' velocity when they move).
    ///
    /// With the nearest-face transfer the velocity is first extrapolated one layer beyond the
    /// `valid` faces (the ones the particles reached), as Φ_Flow does: a face of a liquid cell
    /// that no particle reached takes the mean of its valid neighbours instead of gravity
    /// alone. That face is the free surface's above a partly filled cell, and without the
    /// extrapolation the projection would stop the liquid rising into it (a first-mode
    /// sloshing tank then lost about half its amplitude per half cycle). Tent weights reach
    /// every face of a liquid cell, so the linear transfer does not need the step and skips it:
    /// with it, some trajectories of the seed-0 dataset came out otherwise (training trajectory
    /// 2 by up to 0.75 stored units by its end, a splash amplifying a small change), and
    /// without it runs and datasets made with the linear transfer stay bit for bit those of
    /// earlier versions.
    ///
    /// # Errors
    /// [`FlipError::Solve`] (naming `step`) when the pressure solve fails.
    pub(super) fn make_incompressible(
        &self,
        velocity: &StaggeredGrid<B>,
        valid: &StaggeredGrid<B>,
        positions: &[f32],
        masks: &ObstacleMasks<B>,
        step: usize,
    ) -> Result<Projection<B>> {
        let occupied = occupied_cells_from_host(positions, &self.domain, &self.device)?;
        let liquid = occupied.with_values(occupied.values() * &(1.0 - masks.solid.values()))?;
        let extrapolated = match self.params.transfer {
            Transfer::NearestFace => Some(extrapolate_valid(velocity, valid, 1)?.0),
            Transfer::Linear => None,
        };
        pressure_projection(
            extrapolated.as_ref().unwrap_or(velocity),
            ProjectionMasks {
                liquid: &liquid,
                face_open: Some(&masks.face_open),
                obstacle_velocity: masks.velocity.as_ref(),
            },
            &self.params.solve,
        )
        .map_err(|source| FlipError::Solve { step, source })
    }

    /// Line 6, "map `u_f − uᵢ` to each particle by interpolation": the new particle velocities
    /// `[N, d]` from the grid velocity `uᵢ` of line 3 (`splatted`) and `u_f` of line 5
    /// (`projected`), both read from values extrapolated one layer beyond the `valid` faces (the
    /// ones the particles reached). FLIP adds the change `u_f − uᵢ` to each particle's velocity,
    /// PIC takes `u_f`, a blend weighs them by [`FlipParams::flip_ratio`]; APIC takes the PIC
    /// velocity and, as the new affine matrices `[N, d, d]` (the second value, `None` unless
    /// APIC), the gradient of the same interpolant.
    ///
    /// [`FlipParams::flip_ratio`]: super::FlipParams::flip_ratio
    pub(super) fn map_velocity_to_particles(
        &self,
        particles: &Particles<B>,
        splatted: &StaggeredGrid<B>,
        projected: &StaggeredGrid<B>,
        valid: &StaggeredGrid<B>,
    ) -> Result<(Tensor<B>, Option<Tensor<B>>)> {
        let positions = &particles.positions;
        if self.params.apic {
            let (extended, _) = extrapolate_valid(projected, valid, 1)?;
            return Ok((
                sample_staggered(&extended, positions)?,
                Some(sample_staggered_gradient(&extended, positions)?),
            ));
        }
        let r = self.params.flip_ratio;
        let mut result: Option<Tensor<B>> = None;
        if r > 0.0 {
            let change = projected.sub(splatted)?;
            let (change, _) = extrapolate_valid(&change, valid, 1)?;
            let flip = &particles.velocities + &sample_staggered(&change, positions)?;
            result = Some(if r < 1.0 { flip * r } else { flip });
        }
        if r < 1.0 {
            let (extended, _) = extrapolate_valid(projected, valid, 1)?;
            let pic = sample_staggered(&extended, positions)? * (1.0 - r);
            result = Some(match result {
                Some(f) => f + pic,
                None => pic,
            });
        }
        Ok((
            result.expect("one of FLIP and PIC has a positive weight"),
            None,
        ))
    }

    /// Line 7, "advect particles and their values on the grid using an ODE solver": the grid
    /// velocity `u_f` extrapolated beyond the `valid` faces far enough for this step's motion
    /// ([`extrapolation_layers`](Self::extrapolation_layers)), and the `positions` `[N, d]`
    /// moved through it by RK4 over the (sub-)step `dt`. Returns the new positions `[N, d]` and
    /// the largest speed of `u_f` per axis.
    pub(super) fn advect(
        &self,
        positions: &Tensor<B>,
        velocity: &StaggeredGrid<B>,
        valid: &StaggeredGrid<B>,
        dt: f32,
        step: usize,
    ) -> Result<(Tensor<B>, Vec<f32>)> {
        let (layers, speed) = self.extrapolation_layers(velocity, dt, step)?;
        let (advection_field, _) = extrapolate_valid(velocity, valid, layers)?;
        Ok((
            advect_points(positions, &advection_field, dt, Integrator::Rk4)?,
            speed,
        ))
    }

    /// How many layers of extrapolation cover the motion of a (sub-)step of `dt`:
    /// `⌈max|u| Δt / Δx⌉ + 2` (the fastest face, the smallest cell side), at most the largest
    /// resolution; logs a CFL warning (once per simulation) when the reach exceeds
    /// [`FlipParams::cfl_warning_cells`]. Returns the layers and the largest `|uₐ|` per axis.
    ///
    /// [`FlipParams::cfl_warning_cells`]: super::FlipParams::cfl_warning_cells
    fn extrapolation_layers(
        &self,
        velocity: &StaggeredGrid<B>,
        dt: f32,
        step: usize,
    ) -> Result<(usize, Vec<f32>)> {
        let domain = &self.domain;
        let per_axis = velocity
            .components()
            .iter()
            .map(|c| c.abs().reduce(ReduceOp::Max).map(|m| m.to_vec()[0]))
            .collect::<std::result::Result<Vec<f32>, TensorError>>()?;
        let speed = per_axis.iter().copied().fold(0.0f32, f32::max);
        let min_dx = domain.cell_size().into_iter().fold(f32::INFINITY, f32::min);
        let reach_cells = speed * dt / min_dx;
        self.log_cfl(reach_cells, step);
        // A non-finite reach casts to the largest usize, clamped to the resolution below.
        let layers = (reach_cells.ceil() as usize)
            .saturating_add(2)
            .min(domain.resolution().iter().copied().max().unwrap_or(1));
        Ok((layers, per_axis))
    }

    /// Line 8, "push particles outside of boundaries or obstacles": `positions` `[N, d]` pushed
    /// out of each obstacle as it stands at `time` (the end of the step), then clamped into the
    /// domain. Each obstacle pushes in its own frame, `push(x − c) + c`, so that the gradient
    /// reaches its offset `c` (`offsets`, one `[1, d]` per obstacle).
    pub(super) fn respect_boundaries(
        &self,
        mut positions: Tensor<B>,
        time: f32,
        offsets: &[Tensor<B>],
    ) -> Result<Tensor<B>> {
        for (obstacle, offset) in self.obstacles_at(time)?.iter().zip(offsets) {
            let local = &positions - offset;
            positions = obstacle.geometry().push(
                &local,
                PushDirection::Outward,
                self.params.push_offset,
            )? + offset;
        }
        clamp_into(&positions, &self.domain)
    }
}

/// Points `[N, d]` clamped into the closed box of the domain (a point on the upper side belongs
/// to the last cell).
fn clamp_into<B: Backend>(points: &Tensor<B>, domain: &Domain) -> Result<Tensor<B>> {
    let d = domain.dim();
    let device = points.device();
    let dx = domain.cell_size();
    // Keep a sliver away from the upper side so that the point's cell is the last one.
    let upper: Vec<f32> = (0..d).map(|a| domain.upper()[a] - 1e-4 * dx[a]).collect();
    let lower = Tensor::from_vec(domain.lower().to_vec(), &[1, d], &device)?;
    let upper = Tensor::from_vec(upper, &[1, d], &device)?;
    Ok(points.maximum(&lower)?.minimum(&upper)?)
}
