//! Scenes as TOML files: the domain, the liquid, obstacles, inflows and the numerical
//! parameters of a simulation.
//!
//! ```toml
//! # A block of liquid falling into a pool (thesis fig. 4.2, left).
//! [domain]
//! resolution = [64, 64]          # cells per axis
//! size = [64, 64]                # physical extent (default: one unit per cell)
//! open_sides = []                # e.g. ["y+"]: sides that are open instead of walls
//!
//! [simulation]
//! dt = 0.1
//! steps = 100
//! gravity = [0, -9.81]           # default: −9.81 along the last axis
//! scheme = "flip"                # "flip" | "pic" | "blend" (with flip_ratio) | "apic"
//! transfer = "linear"            # "linear" (tent weights) | "nearest" (Φ_Flow's nearest face)
//! particles_per_cell = 8
//! placement = "jittered"         # "jittered" | "centered"
//! seed = 0
//! cfl = 1.0                      # optional: sub-step so that the CFL number stays ≤ 1
//! max_cfl = 20                   # a step above this CFL number stops the run (default 20)
//!
//! [solver]
//! tolerance = 1e-5               # relative residual of the pressure solve
//! max_iterations = 1000
//! method = "auto"                # "auto" / "cg" (MIC(0) conjugate gradients) | "cholesky" (direct)
//!
//! [[liquid]]
//! geometry = { type = "box", lower = [0, 0], upper = [64, 15] }
//!
//! [[liquid]]
//! geometry = { type = "box", lower = [20, 30], upper = [44, 50] }
//! velocity = [0, 0]
//!
//! [[obstacle]]
//! geometry = { type = "rotated", angle = 20, geometry = { type = "box", lower = [10, 20], upper = [30, 23] } }
//! ```
//!
//! Unknown keys are errors, and every error names the file, the key and the problem.

use std::path::Path;

use phi_core::backend::Backend;
use phi_core::fields::LatticeKernels;
use phi_core::fields::{Boundary, Domain, Transfer};
use phi_core::solve::{Preconditioner, SolveMethod, SolveOptions};
use phi_geom::{Geometry, Obstacle};
use serde::{Deserialize, Serialize};

use crate::error::{FlipError, Result};
use crate::seed::Placement;
use crate::sim::{
    DEFAULT_MAX_CFL, DEFAULT_MAX_SUBSTEPS, FlipParams, FlipSimulation, Inflow, Particles,
};

/// A scene file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scene {
    /// A short description (shown in run summaries).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub description: Option<String>,
    /// The grid and its walls.
    pub domain: DomainSpec,
    /// Time stepping and the FLIP scheme.
    pub simulation: SimulationSpec,
    /// The pressure solve.
    #[serde(default)]
    pub solver: SolverSpec,
    /// Initial liquid regions.
    #[serde(default, rename = "liquid")]
    pub liquids: Vec<LiquidSpec>,
    /// Obstacles.
    #[serde(default, rename = "obstacle")]
    pub obstacles: Vec<Obstacle>,
    /// Inflows.
    #[serde(default, rename = "inflow")]
    pub inflows: Vec<InflowSpec>,
    /// Where to run (informative; the command line may override it).
    #[serde(default)]
    pub run: RunSpec,
}

/// `[domain]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DomainSpec {
    /// Cells per axis (2 or 3 axes).
    pub resolution: Vec<usize>,
    /// Physical size per axis; the domain spans `[0, size]`. Default: one unit per cell.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub size: Option<Vec<f32>>,
    /// Sides that are open (free outflow, `p = 0`) instead of closed walls: `"x-"`, `"x+"`,
    /// `"y-"`, `"y+"`, `"z-"`, `"z+"`.
    #[serde(default)]
    pub open_sides: Vec<String>,
}

/// The velocity update of the particles.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum Scheme {
    /// Particles add the grid's velocity change (the thesis).
    #[default]
    Flip,
    /// Particles take the grid's velocity.
    Pic,
    /// `flip_ratio · FLIP + (1 − flip_ratio) · PIC`.
    Blend,
    /// APIC (Jiang et al. 2015, beyond the thesis): PIC with an affine velocity matrix per
    /// particle, which keeps rotations (angular momentum) that PIC damps.
    Apic,
}

/// Particle → grid transfer.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum TransferSpec {
    /// Tent weights, normalised (differentiable in the positions).
    #[default]
    Linear,
    /// Nearest face, plain mean (Φ_Flow 2.1.4). A face reached by no particle, such as the
    /// one above a partly filled surface cell, takes its neighbours' velocity before the
    /// projection, as in Φ_Flow; the liquid then sloshes as with `linear`.
    Nearest,
}

/// Placement of seeded particles in their cells.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum PlacementSpec {
    /// Uniformly random in the cell.
    #[default]
    Jittered,
    /// At the cell centre.
    Centered,
}

/// `[simulation]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SimulationSpec {
    /// Time step in seconds.
    pub dt: f32,
    /// Number of steps.
    pub steps: usize,
    /// Gravity per axis (default: −9.81 along the last axis).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gravity: Option<Vec<f32>>,
    /// The velocity update.
    #[serde(default)]
    pub scheme: Scheme,
    /// The FLIP share of a `blend` (required for `blend`, not allowed otherwise, `apic` included).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub flip_ratio: Option<f32>,
    /// Particle → grid transfer.
    #[serde(default)]
    pub transfer: TransferSpec,
    /// Particles per liquid cell (default 8).
    #[serde(default = "default_ppc")]
    pub particles_per_cell: usize,
    /// Where seeded particles go in their cell.
    #[serde(default)]
    pub placement: PlacementSpec,
    /// Seed of the jitter.
    #[serde(default)]
    pub seed: u64,
    /// Distance beyond an obstacle surface that pushed particles land at (default 0).
    #[serde(default)]
    pub push_offset: f32,
    /// Adaptive sub-stepping: split each step into sub-steps whose CFL number stays at or
    /// below this (e.g. `1.0`). Default: no sub-steps.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cfl: Option<f32>,
    /// A (sub-)step whose CFL number exceeds this stops the run as unstable (default
    /// [`DEFAULT_MAX_CFL`]; `inf` turns the check off).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_cfl: Option<f32>,
    /// The most sub-steps one step may take with `cfl` (default [`DEFAULT_MAX_SUBSTEPS`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_substeps: Option<usize>,
}

fn default_ppc() -> usize {
    8
}

/// `[solver]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SolverSpec {
    /// Relative residual tolerance (default `1e-5`).
    #[serde(default = "default_tolerance")]
    pub tolerance: f64,
    /// Iteration limit of conjugate gradients (default 1000).
    #[serde(default = "default_iterations")]
    pub max_iterations: usize,
    /// `"auto"` (MIC(0) conjugate gradients for the pressure), `"cg"` (the same, named) or
    /// `"cholesky"` (a direct solve, exact to rounding).
    #[serde(default = "default_method")]
    pub method: String,
}

impl Default for SolverSpec {
    fn default() -> Self {
        Self {
            tolerance: default_tolerance(),
            max_iterations: default_iterations(),
            method: default_method(),
        }
    }
}

fn default_tolerance() -> f64 {
    1e-5
}
fn default_iterations() -> usize {
    1000
}
fn default_method() -> String {
    "auto".into()
}

/// `[[liquid]]`: a region filled with liquid at the start.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LiquidSpec {
    /// The region.
    pub geometry: Geometry,
    /// Initial velocity (default: at rest).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub velocity: Option<Vec<f32>>,
}

/// `[[inflow]]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct InflowSpec {
    /// Where particles appear.
    pub geometry: Geometry,
    /// Their velocity.
    pub velocity: Vec<f32>,
    /// Emit every this many steps (default 1).
    #[serde(default = "default_every")]
    pub every: usize,
    /// Stop emitting at this step.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub until_step: Option<usize>,
}

fn default_every() -> usize {
    1
}

/// `[run]`: the backend and device a scene is meant for.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct RunSpec {
    /// `"ndarray"`, `"burn"`, `"burn-wgpu"` or `"tch"`: the spellings of `--backend` (whether
    /// this build has it is the front end's to check).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub backend: Option<String>,
    /// `"cpu"` (the CPU backends have no other device).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub device: Option<String>,
}

/// A scene turned into a simulation and its initial particles.
#[derive(Debug, Clone)]
pub struct SceneSetup<B: Backend> {
    /// The simulation.
    pub simulation: FlipSimulation<B>,
    /// The liquid at step 0.
    pub particles: Particles<B>,
    /// Number of steps to run.
    pub steps: usize,
}

impl Scene {
    /// Reads and validates a scene file.
    ///
    /// # Errors
    /// [`FlipError::Scene`] naming the file, the key and the problem.
    pub fn from_file(path: &Path) -> Result<Self> {
        let (text, name) = crate::toml_file::read(path)?;
        Self::from_toml(&text, &name)
    }

    /// Parses and validates a scene from TOML text; `origin` names it in errors.
    ///
    /// # Errors
    /// [`FlipError::Scene`] naming `origin`, the key and the problem.
    pub fn from_toml(text: &str, origin: &str) -> Result<Self> {
        let scene: Scene = crate::toml_file::parse(text, origin)?;
        scene.validate(origin)?;
        Ok(scene)
    }

    /// The dimension of the scene.
    pub fn dim(&self) -> usize {
        self.domain.resolution.len()
    }

    /// The domain.
    ///
    /// # Errors
    /// [`FlipError::Scene`] for an invalid `[domain]`.
    pub fn domain(&self, origin: &str) -> Result<Domain> {
        let error = |key: &str, reason: String| FlipError::Scene {
            path: origin.into(),
            key: key.into(),
            reason,
        };
        let spec = &self.domain;
        let d = spec.resolution.len();
        let size: Vec<f32> = match &spec.size {
            Some(size) => size.clone(),
            None => spec.resolution.iter().map(|&n| n as f32).collect(),
        };
        let mut boundaries = vec![[Boundary::Closed; 2]; d];
        for side in &spec.open_sides {
            let axis = match side.chars().next() {
                Some('x') => 0,
                Some('y') => 1,
                Some('z') => 2,
                _ => usize::MAX,
            };
            let upper = match side.get(1..) {
                Some("+") => Some(1),
                Some("-") => Some(0),
                _ => None,
            };
            match (axis < d, upper) {
                (true, Some(u)) => boundaries[axis][u] = Boundary::Open,
                _ => {
                    return Err(error(
                        "domain.open_sides",
                        format!(
                            "unknown side {side:?}; sides are x-, x+, y-, y+ (and z-, z+ in 3D)"
                        ),
                    ));
                }
            }
        }
        Domain::new(&spec.resolution, &vec![0.0; d], &size, &boundaries)
            .map_err(|e| error("domain", e.to_string()))
    }

    /// The numerical parameters.
    ///
    /// # Errors
    /// [`FlipError::Scene`] for an invalid `[simulation]` or `[solver]`.
    pub fn params(&self, origin: &str) -> Result<FlipParams> {
        let error = |key: &str, reason: String| FlipError::Scene {
            path: origin.into(),
            key: key.into(),
            reason,
        };
        let s = &self.simulation;
        let d = self.dim();
        let mut params = FlipParams::thesis(d, s.dt);
        if let Some(g) = &s.gravity {
            params.gravity = g.clone();
        }
        params.flip_ratio = match (s.scheme, s.flip_ratio) {
            (Scheme::Flip, None) => 1.0,
            (Scheme::Pic, None) => 0.0,
            (Scheme::Apic, None) => {
                params.apic = true;
                0.0
            }
            (Scheme::Blend, Some(r)) => r,
            (Scheme::Blend, None) => {
                return Err(error(
                    "simulation.flip_ratio",
                    "a blend needs a flip_ratio in [0, 1]".into(),
                ));
            }
            (scheme, Some(_)) => {
                let name = match scheme {
                    Scheme::Flip => "flip",
                    Scheme::Pic => "pic",
                    Scheme::Apic => "apic (a PIC update with affine matrices, no FLIP share)",
                    Scheme::Blend => unreachable!("matched above"),
                };
                return Err(error(
                    "simulation.flip_ratio",
                    format!("only allowed with scheme = \"blend\", not with {name}"),
                ));
            }
        };
        params.transfer = match s.transfer {
            TransferSpec::Linear => Transfer::Linear,
            TransferSpec::Nearest => Transfer::NearestFace,
        };
        params.push_offset = s.push_offset;
        params.cfl = s.cfl;
        params.max_cfl = s.max_cfl.unwrap_or(DEFAULT_MAX_CFL);
        params.max_substeps = s.max_substeps.unwrap_or(DEFAULT_MAX_SUBSTEPS);
        let solver = &self.solver;
        let method = match solver.method.as_str() {
            "auto" => SolveMethod::Auto,
            "cg" => SolveMethod::ConjugateGradient(Preconditioner::ModifiedIncompleteCholesky),
            "cholesky" => SolveMethod::Cholesky,
            other => {
                return Err(error(
                    "solver.method",
                    format!("unknown method {other:?}; use \"auto\", \"cg\" or \"cholesky\""),
                ));
            }
        };
        if !(solver.tolerance.is_finite() && solver.tolerance > 0.0 && solver.tolerance < 1.0) {
            return Err(error(
                "solver.tolerance",
                format!("must lie in (0, 1), got {}", solver.tolerance),
            ));
        }
        if solver.max_iterations == 0 {
            return Err(error("solver.max_iterations", "must be at least 1".into()));
        }
        params.solve = SolveOptions {
            relative_tolerance: solver.tolerance,
            max_iterations: solver.max_iterations,
            method,
            ..SolveOptions::default()
        };
        Ok(params)
    }

    fn validate(&self, origin: &str) -> Result<()> {
        let error = |key: String, reason: String| FlipError::Scene {
            path: origin.into(),
            key,
            reason,
        };
        let d = self.dim();
        if !(2..=3).contains(&d) {
            return Err(error(
                "domain.resolution".into(),
                format!("a scene is 2- or 3-dimensional, got {d} axes"),
            ));
        }
        if let Some(i) = self.domain.resolution.iter().position(|&n| n == 0) {
            return Err(error(
                format!("domain.resolution[{i}]"),
                "must be at least 1".into(),
            ));
        }
        if let Some(size) = &self.domain.size {
            if size.len() != d {
                return Err(error(
                    "domain.size".into(),
                    format!("needs {d} entries like the resolution, got {}", size.len()),
                ));
            }
            if let Some(i) = size.iter().position(|s| !(s.is_finite() && *s > 0.0)) {
                return Err(error(
                    format!("domain.size[{i}]"),
                    format!("must be positive and finite, got {}", size[i]),
                ));
            }
        }
        let domain = self.domain(origin)?;
        let s = &self.simulation;
        if !(s.dt.is_finite() && s.dt > 0.0) {
            return Err(error(
                "simulation.dt".into(),
                format!("must be positive and finite, got {}", s.dt),
            ));
        }
        if let Some(g) = &s.gravity
            && (g.len() != d || g.iter().any(|v| !v.is_finite()))
        {
            return Err(error(
                "simulation.gravity".into(),
                format!("needs {d} finite components, got {g:?}"),
            ));
        }
        if let Some(r) = s.flip_ratio
            && !(0.0..=1.0).contains(&r)
        {
            return Err(error(
                "simulation.flip_ratio".into(),
                format!("must lie in [0, 1], got {r}"),
            ));
        }
        if s.particles_per_cell == 0 {
            return Err(error(
                "simulation.particles_per_cell".into(),
                "must be at least 1".into(),
            ));
        }
        if !(s.push_offset.is_finite() && s.push_offset >= 0.0) {
            return Err(error(
                "simulation.push_offset".into(),
                format!("must be finite and not negative, got {}", s.push_offset),
            ));
        }
        // A push beyond the domain's smallest extent throws every pushed particle out of the
        // domain (to be clamped onto a wall): no meaningful scene asks for that.
        let extent = (0..d)
            .map(|a| domain.upper()[a] - domain.lower()[a])
            .fold(f32::INFINITY, f32::min);
        if s.push_offset >= extent {
            return Err(error(
                "simulation.push_offset".into(),
                format!(
                    "{} reaches across the whole domain (its smallest extent is {extent}); pushed \
                     particles would land outside it. Use a fraction of a cell (Φ_Flow: 0.5)",
                    s.push_offset
                ),
            ));
        }
        if let Some(c) = s.cfl
            && !(c.is_finite() && c > 0.0)
        {
            return Err(error(
                "simulation.cfl".into(),
                format!("must be positive and finite, got {c}"),
            ));
        }
        if let Some(c) = s.max_cfl
            && (c.is_nan() || c <= 0.0)
        {
            return Err(error(
                "simulation.max_cfl".into(),
                format!("must be positive (inf turns the check off), got {c}"),
            ));
        }
        let max = s.max_cfl.unwrap_or(DEFAULT_MAX_CFL);
        if let Some(c) = s.cfl
            && c > max
        {
            return Err(error(
                "simulation.cfl".into(),
                format!("the sub-step target {c} lies above simulation.max_cfl = {max}"),
            ));
        }
        if s.max_substeps == Some(0) {
            return Err(error(
                "simulation.max_substeps".into(),
                "must be at least 1".into(),
            ));
        }
        self.params(origin)?;
        let check_geometry = |key: String, g: &Geometry| -> Result<()> {
            if g.dim() != d {
                return Err(error(
                    key,
                    format!(
                        "a {}-dimensional geometry in a {d}-dimensional domain",
                        g.dim()
                    ),
                ));
            }
            let bbox = g.bounding_box();
            let overlaps = (0..d).all(|a| {
                bbox.lower()[a] < domain.upper()[a] && bbox.upper()[a] > domain.lower()[a]
            });
            if !overlaps {
                return Err(error(
                    key,
                    format!(
                        "lies entirely outside the domain [{:?}, {:?}] (its bounding box is [{:?}, {:?}])",
                        domain.lower(),
                        domain.upper(),
                        bbox.lower(),
                        bbox.upper()
                    ),
                ));
            }
            Ok(())
        };
        let check_velocity = |key: String, v: &[f32]| -> Result<()> {
            if v.len() != d || v.iter().any(|x| !x.is_finite()) {
                return Err(error(
                    key,
                    format!("needs {d} finite components, got {v:?}"),
                ));
            }
            Ok(())
        };
        if self.liquids.is_empty() && self.inflows.is_empty() {
            return Err(error(
                "liquid".into(),
                "the scene has neither liquid nor an inflow".into(),
            ));
        }
        for (i, l) in self.liquids.iter().enumerate() {
            check_geometry(format!("liquid[{i}].geometry"), &l.geometry)?;
            if let Some(v) = &l.velocity {
                check_velocity(format!("liquid[{i}].velocity"), v)?;
            }
        }
        for (i, o) in self.obstacles.iter().enumerate() {
            check_geometry(format!("obstacle[{i}].geometry"), o.geometry())?;
            check_velocity(format!("obstacle[{i}].velocity"), o.velocity())?;
        }
        for (i, f) in self.inflows.iter().enumerate() {
            check_geometry(format!("inflow[{i}].geometry"), &f.geometry)?;
            check_velocity(format!("inflow[{i}].velocity"), &f.velocity)?;
            if f.every == 0 {
                return Err(error(
                    format!("inflow[{i}].every"),
                    "must be at least 1".into(),
                ));
            }
            if f.until_step == Some(0) {
                return Err(error(
                    format!("inflow[{i}].until_step"),
                    "0 stops the inflow before its first emission (at step 0): it would emit \
                     nothing"
                        .into(),
                ));
            }
        }
        if let Some(b) = &self.run.backend
            && !["ndarray", "burn", "burn-wgpu", "tch"].contains(&b.as_str())
        {
            return Err(error(
                "run.backend".into(),
                format!("unknown backend {b:?}"),
            ));
        }
        Ok(())
    }

    /// Builds the simulation and seeds the initial liquid (`particles_per_cell` per cell of each
    /// liquid region, outside the obstacles; region `i` jittered with seed `seed + i`).
    ///
    /// # Errors
    /// [`FlipError::Scene`] for an invalid scene or a liquid region that covers no free cell.
    pub fn build<B: LatticeKernels>(
        &self,
        origin: &str,
        device: &B::Device,
    ) -> Result<SceneSetup<B>> {
        self.validate(origin)?;
        let domain = self.domain(origin)?;
        let params = self.params(origin)?;
        let d = self.dim();
        let s = &self.simulation;
        let cell = domain.cell_size().into_iter().fold(f32::INFINITY, f32::min);
        if s.push_offset > cell && !self.obstacles.is_empty() {
            tracing::warn!(
                "{origin}: simulation.push_offset = {} is more than a cell ({cell}): particles \
                 pushed out of obstacles jump over the liquid next to them",
                s.push_offset
            );
        }
        let inflows = self
            .inflows
            .iter()
            .map(|f| Inflow {
                geometry: f.geometry.clone(),
                velocity: f.velocity.clone(),
                every: f.every,
                until_step: f.until_step,
                particles_per_cell: s.particles_per_cell,
            })
            .collect();
        let simulation = FlipSimulation::<B>::new(
            domain,
            params,
            self.obstacles.clone(),
            inflows,
            s.seed,
            device,
        )?;
        let placement = match s.placement {
            PlacementSpec::Jittered => Placement::Jittered,
            PlacementSpec::Centered => Placement::Centered,
        };
        let mut positions = Vec::new();
        let mut velocities = Vec::new();
        for (i, liquid) in self.liquids.iter().enumerate() {
            let velocity = liquid.velocity.clone().unwrap_or_else(|| vec![0.0; d]);
            let seeded = simulation.seed(
                &liquid.geometry,
                &velocity,
                s.particles_per_cell,
                placement,
                s.seed.wrapping_add(i as u64),
            )?;
            if seeded.is_empty() {
                return Err(FlipError::Scene {
                    path: origin.into(),
                    key: format!("liquid[{i}].geometry"),
                    reason: "covers no cell centre outside the obstacles: no particle was seeded"
                        .into(),
                });
            }
            positions.extend(seeded.positions.to_vec());
            velocities.extend(seeded.velocities.to_vec());
        }
        for (i, inflow) in self.inflows.iter().enumerate() {
            // Inflows seed outside the obstacles as they stand at time 0, on every emission
            // alike: one that covers no free cell centre now never emits.
            let seeded = simulation.seed(
                &inflow.geometry,
                &inflow.velocity,
                1,
                Placement::Centered,
                0,
            )?;
            if seeded.is_empty() {
                return Err(FlipError::Scene {
                    path: origin.into(),
                    key: format!("inflow[{i}].geometry"),
                    reason: "covers no cell centre outside the obstacles: the inflow would emit \
                             no particle"
                        .into(),
                });
            }
        }
        let particles = Particles::from_host(positions, velocities, d, device)?;
        Ok(SceneSetup {
            simulation,
            particles,
            steps: s.steps,
        })
    }
}
