//! One FLIP step (thesis algorithm 1) and the simulation that repeats it.
//!
//! [`FlipSimulation::step_with`] reads as the algorithm: each line is one stage in `stages`
//! (particles → grid, gravity, pressure projection, grid → particles, advection, boundaries);
//! `obstacles` rasterises the obstacles for the projection, and `checks` holds what the step
//! checks and reports beside the algorithm (scene parameters, finiteness, CFL, statistics).

mod checks;
mod obstacles;
mod stages;

use phi_core::Tensor;
use phi_core::backend::Backend;
use phi_core::fields::{Domain, LatticeKernels, Transfer};
use phi_core::solve::{SolveOptions, SolveStats};
use phi_geom::{Geometry, Obstacle};

use crate::error::{FlipError, Result};
use crate::seed::{Placement, seed_particles};
use checks::{check_finite, largest_displacement, largest_speed_per_axis};
use obstacles::ObstacleMasks;

/// The CFL limit of scene files (`simulation.max_cfl`): a step that carries the fastest
/// particle or grid velocity across more than this many cells fails. Far beyond what FLIP
/// handles (≈ 5 cells), far below what blown-up runs reach (10³ and more).
pub const DEFAULT_MAX_CFL: f32 = 20.0;

/// The default of [`FlipParams::max_substeps`].
pub const DEFAULT_MAX_SUBSTEPS: usize = 10_000;

/// The numerical parameters of a FLIP simulation.
#[derive(Debug, Clone, PartialEq)]
pub struct FlipParams {
    /// Time step in seconds.
    pub dt: f32,
    /// Gravity per axis, in domain units per s² (the thesis: `(0, −9.81)` cells/s²).
    pub gravity: Vec<f32>,
    /// `1`: FLIP (particles add the grid's velocity change, thesis default); `0`: PIC (particles
    /// take the grid's velocity); in between a blend `r · FLIP + (1 − r) · PIC`. Must be `0`
    /// with [`apic`](Self::apic).
    pub flip_ratio: f32,
    /// APIC transfer (Jiang et al. 2015, beyond the thesis): particles carry an affine velocity
    /// matrix `C` ([`Particles::affine`]) that the particle → grid transfer adds,
    /// `v + C (x_face − x_p)`, and take the grid's velocity and its gradient back, so a
    /// rotation survives the round trip. A PIC update: requires `flip_ratio = 0`.
    pub apic: bool,
    /// Particle → grid transfer: tent weights (differentiable, the default) or Φ_Flow's
    /// nearest-face mean. Both damp a first-mode sloshing tank 48 × 16 cells deep alike, by 4 to
    /// 9 % of the amplitude per half cycle over FLIP, PIC, blend and APIC, with periods 2 to 4 %
    /// above linear theory (`phi-flip/tests/flip/sloshing.rs`).
    pub transfer: Transfer,
    /// Pressure solve options (default: relative tolerance `1e-5`, at most 1000 iterations, the
    /// method chosen by [`SolveMethod::Auto`](phi_core::solve::SolveMethod::Auto): MIC(0)
    /// conjugate gradients for the pressure's Poisson matrix in 2D and 3D).
    pub solve: SolveOptions,
    /// How far beyond an obstacle's surface pushed particles are placed (domain units; the
    /// thesis code uses 0).
    pub push_offset: f32,
    /// A step whose particles move farther than this many cells logs a CFL warning.
    pub cfl_warning_cells: f32,
    /// Adaptive sub-stepping: when set, each step of `dt` is split into sub-steps short enough
    /// that the CFL number of each stays near this value (see [`FlipSimulation::step_with`]).
    /// `None`: one sub-step of `dt` (the thesis).
    pub cfl: Option<f32>,
    /// A (sub-)step whose CFL number exceeds this fails with [`FlipError::Unstable`]
    /// (`f32::INFINITY`: never).
    pub max_cfl: f32,
    /// The most sub-steps one step may take with [`cfl`](Self::cfl); a step that would need more
    /// fails with [`FlipError::Unstable`].
    pub max_substeps: usize,
}

impl FlipParams {
    /// The thesis' parameters for a `d`-dimensional domain with time step `dt`: FLIP, gravity
    /// `−9.81` along the last axis, linear transfer, default solve, push offset 0, no
    /// sub-stepping and no CFL limit (scene files set one, [`DEFAULT_MAX_CFL`]).
    pub fn thesis(dim: usize, dt: f32) -> Self {
        let mut gravity = vec![0.0; dim];
        if let Some(g) = gravity.last_mut() {
            *g = -9.81;
        }
        Self {
            dt,
            gravity,
            flip_ratio: 1.0,
            apic: false,
            transfer: Transfer::Linear,
            solve: SolveOptions::default(),
            push_offset: 0.0,
            cfl_warning_cells: 3.0,
            cfl: None,
            max_cfl: f32::INFINITY,
            max_substeps: DEFAULT_MAX_SUBSTEPS,
        }
    }

    fn validate(&self, dim: usize) -> Result<()> {
        let invalid = |name, reason: String| Err(FlipError::InvalidParameter { name, reason });
        if !(self.dt.is_finite() && self.dt > 0.0) {
            return invalid(
                "dt",
                format!("must be positive and finite, got {}", self.dt),
            );
        }
        if self.gravity.len() != dim || self.gravity.iter().any(|g| !g.is_finite()) {
            return invalid(
                "gravity",
                format!("needs {dim} finite components, got {:?}", self.gravity),
            );
        }
        if !(0.0..=1.0).contains(&self.flip_ratio) {
            return invalid(
                "flip_ratio",
                format!("must lie in [0, 1], got {}", self.flip_ratio),
            );
        }
        if self.apic && self.flip_ratio != 0.0 {
            return invalid(
                "flip_ratio",
                format!(
                    "must be 0 with APIC (a PIC update with affine matrices), got {}",
                    self.flip_ratio
                ),
            );
        }
        if !(self.push_offset.is_finite() && self.push_offset >= 0.0) {
            return invalid(
                "push_offset",
                format!("must be finite and not negative, got {}", self.push_offset),
            );
        }
        if let Some(cfl) = self.cfl
            && !(cfl.is_finite() && cfl > 0.0)
        {
            return invalid("cfl", format!("must be positive and finite, got {cfl}"));
        }
        if self.max_cfl.is_nan() || self.max_cfl <= 0.0 {
            return invalid(
                "max_cfl",
                format!("must be positive (inf: no limit), got {}", self.max_cfl),
            );
        }
        if self.max_substeps == 0 {
            return invalid("max_substeps", "must be at least 1".into());
        }
        Ok(())
    }
}

/// A source of liquid: every `every` steps, the cells of `geometry` are seeded with particles
/// moving at `velocity`.
#[derive(Debug, Clone, PartialEq)]
pub struct Inflow {
    /// Where particles appear.
    pub geometry: Geometry,
    /// Their initial velocity.
    pub velocity: Vec<f32>,
    /// Emit on steps `0, every, 2·every, ...` (before the step runs).
    pub every: usize,
    /// Stop emitting at this step (exclusive); `None`: never stop.
    pub until_step: Option<usize>,
    /// Particles per cell of each emission.
    pub particles_per_cell: usize,
}

/// The liquid: particle positions `[N, d]` and velocities `[N, d]`, and with APIC their affine
/// velocity matrices `[N, d, d]`.
#[derive(Debug, Clone)]
pub struct Particles<B: Backend> {
    /// Positions in domain units.
    pub positions: Tensor<B>,
    /// Velocities in domain units per second.
    pub velocities: Tensor<B>,
    /// APIC's affine matrices `[N, d, d]`: row `a` is the velocity gradient of component `a`
    /// (`∂v_a/∂x_j` at `[p, a, j]`, per second). `None` stands for zero matrices: FLIP and PIC
    /// steps neither read nor write it, an APIC step reads `None` as zero and always writes it.
    pub affine: Option<Tensor<B>>,
}

impl<B: Backend> Particles<B> {
    /// Particles from host data `[N * d]` (row-major `[N, d]`).
    ///
    /// # Errors
    /// When the lengths do not match `d`.
    pub fn from_host(
        positions: Vec<f32>,
        velocities: Vec<f32>,
        dim: usize,
        device: &B::Device,
    ) -> Result<Self> {
        let n = positions.len() / dim.max(1);
        Ok(Self {
            positions: Tensor::from_vec(positions, &[n, dim], device)?,
            velocities: Tensor::from_vec(velocities, &[n, dim], device)?,
            affine: None,
        })
    }

    /// Particles at `positions [N, d]` moving at `velocities [N, d]`, without affine matrices.
    pub fn new(positions: Tensor<B>, velocities: Tensor<B>) -> Self {
        Self {
            positions,
            velocities,
            affine: None,
        }
    }

    /// The affine matrices `[N, d, d]`, zeros when there are none.
    pub(crate) fn affine_or_zeros(&self) -> Tensor<B> {
        match &self.affine {
            Some(c) => c.clone(),
            None => {
                let shape = self.positions.shape();
                let (n, d) = (shape[0], shape[1]);
                Tensor::zeros(&[n, d, d], &self.positions.device())
            }
        }
    }

    /// These particles followed by `other`'s; affine matrices are kept when either has them
    /// (zeros for the other).
    ///
    /// # Errors
    /// When the dimensions differ.
    pub fn concat(&self, other: &Self) -> Result<Self> {
        let affine = match (&self.affine, &other.affine) {
            (None, None) => None,
            _ => Some(Tensor::concat(
                &[self.affine_or_zeros(), other.affine_or_zeros()],
                0,
            )?),
        };
        Ok(Self {
            positions: Tensor::concat(&[self.positions.clone(), other.positions.clone()], 0)?,
            velocities: Tensor::concat(&[self.velocities.clone(), other.velocities.clone()], 0)?,
            affine,
        })
    }

    /// Number of particles.
    pub fn len(&self) -> usize {
        self.positions.shape()[0]
    }

    /// Whether there are no particles.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// The scene parameters a step reads, as tensors, so that gradients reach them on an autodiff
/// backend: make a copy with [`Tensor::require_grad`] leaves and pass it to
/// [`FlipSimulation::step_with`].
///
/// [`FlipSimulation::scene_parameters`] gives the values the simulation was built with.
#[derive(Debug, Clone)]
pub struct SceneParameters<B: Backend> {
    /// Gravity `[d]`, domain units per s².
    pub gravity: Tensor<B>,
    /// Per obstacle, a translation `[1, d]` of its geometry (zero: where the scene puts it). The
    /// gradient reaches it through the push out of the obstacle, `push(x − c) + c`; the obstacle's
    /// cells and blocked faces are rasterised at its value and held constant.
    pub obstacle_offsets: Vec<Tensor<B>>,
    /// Per inflow, the velocity `[1, d]` of the particles it emits.
    pub inflow_velocities: Vec<Tensor<B>>,
}

impl<B: Backend> SceneParameters<B> {
    /// Every parameter as a tracked leaf (same values), for taking gradients.
    pub fn require_grad(&self) -> Self
    where
        B: phi_core::AutodiffBackend,
    {
        Self {
            gravity: self.gravity.require_grad(),
            obstacle_offsets: self
                .obstacle_offsets
                .iter()
                .map(Tensor::require_grad)
                .collect(),
            inflow_velocities: self
                .inflow_velocities
                .iter()
                .map(Tensor::require_grad)
                .collect(),
        }
    }

    /// The obstacle offsets on the host, one `Vec` of `d` values per obstacle.
    fn offsets_on_host(&self) -> Vec<Vec<f32>> {
        self.obstacle_offsets.iter().map(Tensor::to_vec).collect()
    }
}

/// What one step did.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct StepStats {
    /// The pressure solve's iterations (0 for a direct solve; summed over the sub-steps) and
    /// residual (the largest of the sub-steps).
    pub solve: SolveStats,
    /// Liquid cells (unknowns of the pressure solve of the last sub-step).
    pub liquid_cells: usize,
    /// Particles after the step.
    pub particles: usize,
    /// The largest particle displacement of the step, in cells.
    pub max_displacement_cells: f32,
    /// The largest CFL number of its sub-steps (see [`FlipSimulation::step_with`]).
    pub cfl: f32,
    /// Sub-steps taken (1 without [`FlipParams::cfl`]).
    pub substeps: usize,
}

/// A FLIP liquid simulation on a [`Domain`] with obstacles and inflows, generic over the backend.
///
/// The step is thesis algorithm 1: particles → staggered grid; gravity; pressure projection on the
/// cells that hold particles, with obstacles (with the nearest-face transfer, of the velocity
/// extrapolated one layer beyond the faces the particles reached, as in Φ_Flow); particle velocities updated by FLIP (adding the
/// grid's velocity change), PIC, a blend or APIC (beyond the thesis: PIC with an affine velocity
/// matrix per particle, [`FlipParams::apic`]); the grid velocity extrapolated beyond the liquid;
/// particles advected by RK4 through it; particles pushed out of obstacles and back into the
/// domain. Inflows emit before a step.
///
/// # Beside Φ_Flow 2.1.4
/// The same algorithm, with these differences (all deliberate): the default transfer is the
/// tent-weighted one (differentiable; `Transfer::NearestFace` is Φ_Flow's, though it rounds ties
/// up where NumPy rounds half to even); gravity is added on every face, not only on occupied ones;
/// the FLIP/PIC update and the advection read velocities extrapolated from the faces that received
/// particle weight after the projection; RK4 uses one extrapolation that covers the step's reach
/// (`⌈max|u| Δt / Δx⌉ + 2` layers) instead of one per stage; particles pushed out of obstacles land
/// on the surface plus `push_offset` (0 by default, as in the thesis code; Φ_Flow uses 0.5).
///
/// # What is differentiable
/// The step is built from tensor operations: on an autodiff backend, gradients flow from any
/// later particle state to earlier positions and velocities (and APIC's affine matrices) and,
/// through
/// [`step_with`](Self::step_with) and [`SceneParameters`], to the gravity, each obstacle's offset
/// (through the push `push(x − c) + c`: particles pushed onto an obstacle's surface move with it)
/// and each inflow's velocity. The pressure solve is differentiated implicitly (one adjoint solve
/// with the same matrix). Held constant, as in Φ_Flow — the gradient is that of the smooth piece
/// the state lies on:
/// - which cells are liquid (occupancy is computed from detached positions) and so the
///   pressure matrix;
/// - which faces are valid (received particle weight) or blocked by an obstacle, and the
///   obstacles' rasterisation (computed on the host at the offsets' values);
/// - which cell and which grid samples a particle falls between (the transfer weights are
///   differentiated, their indices are not), and which obstacle side a particle is pushed to;
/// - the number of extrapolation layers (from the step's largest grid speed, read on the host);
/// - where inflows seed their particles (only their velocity is a parameter);
/// - the clamp into the domain (zero gradient across a wall for a clamped coordinate).
///
/// Finite differences agree with these gradients wherever a perturbation changes none of the
/// above (`phi-flip/tests/flip/gradients.rs`, and `apic.rs` for APIC).
#[derive(Debug, Clone)]
pub struct FlipSimulation<B: Backend> {
    domain: Domain,
    params: FlipParams,
    obstacles: Vec<Obstacle>,
    inflows: Vec<Inflow>,
    seed: u64,
    device: B::Device,
    static_masks: Option<ObstacleMasks<B>>,
    obstacle_union: Option<Geometry>,
    /// Whether the CFL warning was logged (once per simulation; later ones go to `debug`).
    cfl_warned: std::sync::Arc<std::sync::atomic::AtomicBool>,
    /// [`FlipSimulation::scene_parameters`], built once: what [`FlipSimulation::step`] uses.
    defaults: SceneParameters<B>,
}

impl<B: LatticeKernels> FlipSimulation<B> {
    /// A simulation of `domain` with `obstacles` and `inflows`. `seed` drives the jitter of
    /// inflow particles.
    ///
    /// # Errors
    /// [`FlipError::InvalidParameter`] for invalid parameters or a dimension mismatch.
    pub fn new(
        domain: Domain,
        params: FlipParams,
        obstacles: Vec<Obstacle>,
        inflows: Vec<Inflow>,
        seed: u64,
        device: &B::Device,
    ) -> Result<Self> {
        let d = domain.dim();
        params.validate(d)?;
        for (i, o) in obstacles.iter().enumerate() {
            if o.geometry().dim() != d {
                return Err(FlipError::InvalidParameter {
                    name: "obstacles",
                    reason: format!(
                        "obstacle {i} is {}-dimensional in a {d}-dimensional domain",
                        o.geometry().dim()
                    ),
                });
            }
        }
        for (i, inflow) in inflows.iter().enumerate() {
            if inflow.geometry.dim() != d || inflow.velocity.len() != d {
                return Err(FlipError::InvalidParameter {
                    name: "inflows",
                    reason: format!("inflow {i} does not match the {d}-dimensional domain"),
                });
            }
            if inflow.every == 0 {
                return Err(FlipError::InvalidParameter {
                    name: "inflows",
                    reason: format!("inflow {i}: `every` must be at least 1"),
                });
            }
        }
        let obstacle_union = match obstacles.len() {
            0 => None,
            1 => Some(obstacles[0].geometry().clone()),
            _ => Some(Geometry::union(
                obstacles.iter().map(|o| o.geometry().clone()).collect(),
            )?),
        };
        let defaults = SceneParameters {
            gravity: Tensor::from_vec(params.gravity.clone(), &[d], device)?,
            obstacle_offsets: obstacles
                .iter()
                .map(|_| Tensor::zeros(&[1, d], device))
                .collect(),
            inflow_velocities: inflows
                .iter()
                .map(|f| Tensor::from_vec(f.velocity.clone(), &[1, d], device))
                .collect::<std::result::Result<_, _>>()?,
        };
        let mut simulation = Self {
            domain,
            params,
            obstacles,
            inflows,
            seed,
            device: device.clone(),
            static_masks: None,
            obstacle_union,
            cfl_warned: Default::default(),
            defaults,
        };
        if !simulation.obstacles.iter().any(Obstacle::is_moving) {
            simulation.static_masks = Some(simulation.obstacle_masks(0.0, &[])?);
        }
        Ok(simulation)
    }

    /// The domain.
    pub fn domain(&self) -> &Domain {
        &self.domain
    }

    /// The parameters.
    pub fn params(&self) -> &FlipParams {
        &self.params
    }

    /// The obstacles (at time 0).
    pub fn obstacles(&self) -> &[Obstacle] {
        &self.obstacles
    }

    /// The obstacles at `time` (moved by their velocity).
    ///
    /// # Errors
    /// Only geometry errors, which cannot happen for valid obstacles.
    pub(crate) fn obstacles_at(&self, time: f32) -> Result<Vec<Obstacle>> {
        self.shifted_obstacles_at(time, &[])
    }

    /// The scene parameters this simulation was built with, as tensors: the gravity of
    /// [`FlipParams`], zero obstacle offsets and the inflows' velocities.
    ///
    /// # Errors
    /// Only tensor errors.
    pub fn scene_parameters(&self) -> Result<SceneParameters<B>> {
        Ok(self.defaults.clone())
    }

    /// Cells whose centre lies inside an obstacle at `time`, row-major over the resolution.
    ///
    /// # Errors
    /// Only geometry errors.
    pub fn solid_cells(&self, time: f32) -> Result<Vec<bool>> {
        let masks = self.masks_at(time, &[])?;
        Ok(masks
            .solid
            .values()
            .to_vec()
            .iter()
            .map(|&v| v > 0.5)
            .collect())
    }

    /// Particles filling the cells of `geometry` that are free of obstacles, `particles_per_cell`
    /// each, all moving at `velocity`.
    ///
    /// # Errors
    /// A dimension mismatch.
    pub fn seed(
        &self,
        geometry: &Geometry,
        velocity: &[f32],
        particles_per_cell: usize,
        placement: Placement,
        seed: u64,
    ) -> Result<Particles<B>> {
        let d = self.domain.dim();
        if velocity.len() != d {
            return Err(FlipError::InvalidParameter {
                name: "velocity",
                reason: format!("needs {d} components, got {}", velocity.len()),
            });
        }
        let positions = seed_particles(
            geometry,
            self.obstacle_union.as_ref(),
            &self.domain,
            particles_per_cell,
            placement,
            seed,
        )?;
        let n = positions.len() / d;
        let velocities = velocity.iter().copied().cycle().take(n * d).collect();
        Particles::from_host(positions, velocities, d, &self.device)
    }

    /// Adds the particles of the inflows that emit before step `step`.
    ///
    /// # Errors
    /// Only tensor errors.
    pub fn emit(&self, particles: &Particles<B>, step: usize) -> Result<Particles<B>> {
        self.emit_with(particles, step, &self.defaults)
    }

    /// [`emit`](Self::emit) with the inflow velocities of `scene`.
    ///
    /// # Errors
    /// Only tensor errors.
    pub(crate) fn emit_with(
        &self,
        particles: &Particles<B>,
        step: usize,
        scene: &SceneParameters<B>,
    ) -> Result<Particles<B>> {
        let mut out = particles.clone();
        for (i, inflow) in self.inflows.iter().enumerate() {
            let active =
                step.is_multiple_of(inflow.every) && inflow.until_step.is_none_or(|u| step < u);
            if !active {
                continue;
            }
            let seed = self
                .seed
                .wrapping_mul(0x9E37_79B9_7F4A_7C15)
                .wrapping_add((step as u64) << 8 | i as u64);
            let new = self.seed(
                &inflow.geometry,
                &inflow.velocity,
                inflow.particles_per_cell,
                Placement::Jittered,
                seed,
            )?;
            if new.is_empty() {
                continue;
            }
            // The emitted velocity is the (possibly tracked) inflow parameter, broadcast.
            let new = Particles {
                velocities: new.velocities.zeros_like() + &scene.inflow_velocities[i],
                positions: new.positions,
                affine: None,
            };
            out = if out.is_empty() {
                new
            } else {
                out.concat(&new)?
            };
        }
        Ok(out)
    }

    /// One step from `particles` at step index `step` (time `step · dt`): inflows emit, then
    /// thesis algorithm 1 (in sub-steps with [`FlipParams::cfl`]).
    ///
    /// # Errors
    /// [`FlipError::Solve`] when the pressure solve fails, [`FlipError::NonFinite`] when the new
    /// state is not finite, [`FlipError::Unstable`] when the CFL number exceeds
    /// [`FlipParams::max_cfl`] or sub-stepping would need more than
    /// [`FlipParams::max_substeps`].
    pub fn step(&self, particles: &Particles<B>, step: usize) -> Result<(Particles<B>, StepStats)> {
        self.step_with(particles, step, &self.defaults)
    }

    /// [`step`](Self::step) with the scene parameters `scene` (gravity, obstacle offsets, inflow
    /// velocities) given as tensors, so that gradients reach them.
    ///
    /// # Stability
    /// Every (sub-)step measures its CFL number `C = h · maxₐ max|uₐ| / Δxₐ`, over the grid
    /// velocity after the projection and the particles' new velocities (`h` the sub-step
    /// length), and fails with [`FlipError::Unstable`] when `C` exceeds
    /// [`FlipParams::max_cfl`]. That one number covers the ways a run blows up: exploding
    /// velocities raise it directly, and particles can only pile onto a wall or a corner by
    /// being carried across the domain in one step, which is a large `C` (the advection moves no
    /// particle farther than `C` cells). Non-finite states fail with [`FlipError::NonFinite`].
    ///
    /// # Sub-steps
    /// With [`FlipParams::cfl`] = `c`, the step of `dt` runs as sub-steps, each as long as
    /// possible up to what is left of `dt`: a sub-step of length `h` whose particles move at
    /// most `|vₐ|` (read before it) and which gravity speeds up by `|gₐ| h` satisfies
    /// `h (|vₐ| + |gₐ| h) ≤ c Δxₐ` on every axis. A last piece shorter than one such sub-step is
    /// shared with the one before (two halves), so no sub-step is tiny. Inflows emit once, before
    /// the first sub-step. The number of sub-steps is chosen on the host and held constant for
    /// gradients, like the other discrete choices.
    ///
    /// # Errors
    /// As [`step`](Self::step), and [`FlipError::InvalidParameter`] when `scene` does not fit the
    /// simulation.
    pub fn step_with(
        &self,
        particles: &Particles<B>,
        step: usize,
        scene: &SceneParameters<B>,
    ) -> Result<(Particles<B>, StepStats)> {
        self.check_scene_parameters(scene)?;
        let offsets = scene.offsets_on_host();
        let particles = self.emit_with(particles, step, scene)?;
        if particles.is_empty() {
            return Ok((particles, StepStats::default()));
        }
        let dt = self.params.dt;
        let start = step as f32 * dt;
        // Read back once per sub-step: the occupancy of the projection and the displacement.
        let before = particles.positions.host_values().into_owned();
        let mut state = particles;
        let mut host = before.clone();
        let mut stats = StepStats::default();
        let mut done = 0.0f32;
        loop {
            let remaining = dt - done;
            let h = match self.params.cfl {
                None => dt,
                Some(target) => self.substep_length(&state, remaining, target, step, stats)?,
            };
            let last = h >= remaining;
            let h = if last { remaining } else { h };
            let sub = self.substep(&state, &host, start + done, h, step, scene, &offsets)?;
            state = sub.particles;
            host = sub.positions;
            stats.substeps += 1;
            stats.cfl = stats.cfl.max(sub.cfl);
            stats.solve.iterations += sub.projection.stats.iterations;
            stats.solve.residual = stats.solve.residual.max(sub.projection.stats.residual);
            stats.liquid_cells = sub.projection.unknowns;
            if last {
                break;
            }
            done += h;
        }
        stats.particles = state.len();
        stats.max_displacement_cells = largest_displacement(&host, &before, &self.domain);
        Ok((state, stats))
    }

    /// Thesis algorithm 1, lines 3 to 8, one stage each, over `h` seconds from `time`, for
    /// `particles` at `positions` (their host data `[N·d]`); checks the new state (finite, CFL
    /// number within [`FlipParams::max_cfl`]).
    #[allow(clippy::too_many_arguments)]
    fn substep(
        &self,
        particles: &Particles<B>,
        positions: &[f32],
        time: f32,
        h: f32,
        step: usize,
        scene: &SceneParameters<B>,
        offsets: &[Vec<f32>],
    ) -> Result<Substep<B>> {
        let masks = self.masks_at(time, offsets)?;
        let (splatted, valid) = self.particles_to_grid(particles)?;
        let forced = self.add_gravity(&splatted, &scene.gravity, h)?;
        let projection = self.make_incompressible(&forced, &valid, positions, &masks, step)?;
        let (velocities, affine) =
            self.map_velocity_to_particles(particles, &splatted, &projection.velocity, &valid)?;
        let (advected, grid_speed) =
            self.advect(&particles.positions, &projection.velocity, &valid, h, step)?;
        let positions = self.respect_boundaries(advected, time + h, &scene.obstacle_offsets)?;
        let next = Particles {
            positions,
            velocities,
            affine,
        };
        let after = next.positions.host_values().into_owned();
        let velocities = next.velocities.host_values();
        check_finite(&after, &velocities, &next, step)?;
        let particle_speed = largest_speed_per_axis(&velocities, self.domain.dim());
        let cfl = self
            .cfl_number(&grid_speed, h)
            .max(self.cfl_number(&particle_speed, h));
        if cfl.is_nan() || cfl > self.params.max_cfl {
            return Err(FlipError::Unstable {
                step,
                cfl,
                dt: h,
                why: format!(
                    "(the fastest velocity crosses {cfl:.3} cells in one step), above the limit \
                     max_cfl = {}",
                    self.params.max_cfl
                ),
            });
        }
        Ok(Substep {
            particles: next,
            positions: after,
            projection,
            cfl,
        })
    }

    /// `h · maxₐ speedₐ / Δxₐ`: the CFL number of per-axis speeds `speed` over `h` seconds.
    fn cfl_number(&self, speed: &[f32], h: f32) -> f32 {
        let dx = self.domain.cell_size();
        speed
            .iter()
            .zip(&dx)
            .map(|(s, dx)| h * s / dx)
            .fold(0.0f32, |m, c| if c.is_nan() { c } else { m.max(c) })
    }

    /// The length of the next sub-step with CFL target `target` when `remaining` seconds of
    /// the step are left (see [`step_with`](Self::step_with)); `stats` counts the sub-steps
    /// taken so far.
    fn substep_length(
        &self,
        particles: &Particles<B>,
        remaining: f32,
        target: f32,
        step: usize,
        stats: StepStats,
    ) -> Result<f32> {
        let speed = largest_speed_per_axis(&particles.velocities.host_values(), self.domain.dim());
        let dx = self.domain.cell_size();
        // The largest h with h (v + g h) ≤ c Δx, in the form that cannot cancel:
        // h = 2 c Δx / (v + √(v² + 4 g c Δx)).
        let longest = speed
            .iter()
            .zip(&self.params.gravity)
            .zip(&dx)
            .map(|((&v, &g), &dx)| {
                // In f64: v² of a fast (finite) f32 velocity would overflow f32.
                let (v, g) = (f64::from(v), f64::from(g.abs()));
                let budget = f64::from(target) * f64::from(dx);
                let denominator = v + (v * v + 4.0 * g * budget).sqrt();
                if denominator > 0.0 {
                    (2.0 * budget / denominator) as f32
                } else {
                    f32::INFINITY
                }
            })
            .fold(f32::INFINITY, f32::min);
        let h = if longest >= remaining {
            remaining
        } else if 2.0 * longest > remaining {
            0.5 * remaining
        } else {
            longest
        };
        let needed = stats.substeps as f64 + (f64::from(remaining) / f64::from(h)).ceil();
        if h.is_nan() || h <= 0.0 || needed > self.params.max_substeps as f64 {
            let cfl = self.cfl_number(&speed, self.params.dt);
            return Err(FlipError::Unstable {
                step,
                cfl,
                dt: self.params.dt,
                why: format!(
                    "(estimated from the particle velocities and gravity): keeping it below cfl = \
                     {target} needs about {needed:.3e} sub-steps, more than max_substeps = {}",
                    self.params.max_substeps
                ),
            });
        }
        Ok(h)
    }
}

/// What one sub-step produced.
struct Substep<B: Backend> {
    particles: Particles<B>,
    /// The new positions on the host, `[N·d]`.
    positions: Vec<f32>,
    projection: phi_core::fields::Projection<B>,
    cfl: f32,
}
