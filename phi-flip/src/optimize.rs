//! Optimising initial particle positions through the differentiable FLIP simulation (thesis
//! section 4.3): a liquid is simulated `steps` steps, a loss compares the final particles with a
//! target, and gradient descent moves the initial positions.
//!
//! The set-up is an [`OptimizeConfig`] read from TOML:
//!
//! ```toml
//! description = "Thesis fig. 4.5: a block is optimised into two spheres"
//!
//! [scene]                       # a phi-flip Scene; its [[scene.liquid]] is the initial guess
//! domain = { resolution = [32, 32] }
//! simulation = { dt = 0.05, steps = 20, particles_per_cell = 4 }
//! liquid = [{ geometry = { type = "box", lower = [4, 4], upper = [12, 20] } }]
//!
//! [target]                      # the target's *initial* liquid; it is simulated `steps` steps
//! liquid = [{ type = "sphere", center = [20, 22], radius = 4 }]
//! simulate = true               # false: the seeded points are the target itself
//!
//! [optimize]
//! iterations = 20
//! learning_rate = 1.0
//! loss = "l2"                   # "l2" | "sinkhorn" | "density"
//! sinkhorn_epsilon = 1.0        # ε of the Sinkhorn divergence (domain units²)
//! density_levels = 5            # grids of the density loss: cell sizes 1, 2, 4, … cells
//! ```
//!
//! The target is seeded like the scene's liquid (its `particles_per_cell` and placement, seed
//! `seed + 1000`) and, when it has more points than the liquid has particles, thinned to as many
//! by a seeded choice, so that the L2 loss can pair particle `i` with target point `i`.

use std::path::Path;

use phi_core::fields::Domain;
use phi_core::fields::LatticeKernels;
use phi_core::point_sets::chamfer_distance;
use phi_core::{AutodiffBackend, Backend, Tensor};
use phi_geom::Geometry;
use rand::SeedableRng;
use rand::seq::index::sample;
use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::error::FlipError;
use crate::loss::Loss;
use crate::scene::{PlacementSpec, Scene};
use crate::seed::Placement;
use crate::sim::{FlipSimulation, Particles, SceneParameters};

/// An optimisation file: the scene (whose liquid is the initial guess), the target and the
/// optimiser.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OptimizeConfig {
    /// A short description.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub description: Option<String>,
    /// The simulation set-up; `simulation.steps` is the number of steps simulated per iteration.
    pub scene: Scene,
    /// What the simulated liquid should become.
    pub target: TargetSpec,
    /// The optimiser.
    #[serde(default)]
    pub optimize: OptimizerSpec,
}

/// `[target]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TargetSpec {
    /// Regions seeded with target points (the scene's `particles_per_cell` unless
    /// `particles_per_cell` is given).
    pub liquid: Vec<Geometry>,
    /// Particles per cell of the target seeding (default: the scene's).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub particles_per_cell: Option<usize>,
    /// Whether the seeded target is simulated `steps` steps first (the thesis: the target is the
    /// simulated state of a target shape, whose initial positions are then the optimum).
    #[serde(default = "yes")]
    pub simulate: bool,
}

fn yes() -> bool {
    true
}

/// The loss, as written in a file.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum LossSpec {
    /// Particle `i` against target point `i` (the thesis).
    #[default]
    L2,
    /// Debiased Sinkhorn divergence between the point sets.
    Sinkhorn,
    /// L2 between the densities on the grid.
    Density,
}

/// `[optimize]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OptimizerSpec {
    /// Gradient descent iterations (default 20).
    #[serde(default = "default_iterations")]
    pub iterations: usize,
    /// Step size of gradient descent (default 1, the thesis').
    #[serde(default = "default_learning_rate")]
    pub learning_rate: f32,
    /// The loss (default `"l2"`).
    #[serde(default)]
    pub loss: LossSpec,
    /// `ε` of the Sinkhorn divergence, domain units² (default 1).
    #[serde(default = "default_epsilon")]
    pub sinkhorn_epsilon: f32,
    /// Grids compared by the density loss: the domain's and each coarser by 2 (default 5:
    /// cell sizes 1, 2, 4, 8 and 16 cells, as far as the resolution halves).
    #[serde(default = "default_density_levels")]
    pub density_levels: usize,
    /// Stop when the loss exceeds this many times the first iteration's (default 100): the
    /// optimisation diverged.
    #[serde(default = "default_divergence")]
    pub divergence_factor: f32,
}

fn default_iterations() -> usize {
    20
}
fn default_learning_rate() -> f32 {
    1.0
}
fn default_epsilon() -> f32 {
    1.0
}
fn default_density_levels() -> usize {
    5
}
fn default_divergence() -> f32 {
    100.0
}

impl Default for OptimizerSpec {
    fn default() -> Self {
        Self {
            iterations: default_iterations(),
            learning_rate: default_learning_rate(),
            loss: LossSpec::default(),
            sinkhorn_epsilon: default_epsilon(),
            density_levels: default_density_levels(),
            divergence_factor: default_divergence(),
        }
    }
}

/// What can go wrong in an optimisation.
#[derive(Debug, Error)]
pub enum OptimizeError {
    /// A configuration problem (file, key, reason) or a simulation set-up error.
    #[error(transparent)]
    Setup(#[from] FlipError),
    /// The simulation or the loss failed at an iteration.
    #[error("iteration {iteration}: {source}")]
    Iteration {
        /// The iteration (0-based).
        iteration: usize,
        /// What failed.
        source: FlipError,
    },
    /// The loss or its gradient is NaN or infinite.
    #[error(
        "iteration {iteration}: the {what} is not finite; the optimisation diverged (lower the learning rate)"
    )]
    NonFinite {
        /// The iteration (0-based).
        iteration: usize,
        /// `"loss"` or `"gradient"`.
        what: &'static str,
    },
    /// The loss grew beyond `divergence_factor` times its first value.
    #[error(
        "iteration {iteration}: loss {loss} exceeds {factor} × the first loss {first}; the optimisation diverged (lower the learning rate)"
    )]
    Diverged {
        /// The iteration (0-based).
        iteration: usize,
        /// Its loss.
        loss: f32,
        /// The first iteration's loss.
        first: f32,
        /// The configured factor.
        factor: f32,
    },
}

impl OptimizeConfig {
    /// Reads and validates an optimisation file.
    ///
    /// # Errors
    /// [`FlipError::Scene`] naming the file, the key and the problem.
    pub fn from_file(path: &Path) -> Result<Self, FlipError> {
        let (text, name) = crate::toml_file::read(path)?;
        Self::from_toml(&text, &name)
    }

    /// Parses and validates an optimisation from TOML text; `origin` names it in errors.
    ///
    /// # Errors
    /// [`FlipError::Scene`] naming `origin`, the key and the problem.
    pub fn from_toml(text: &str, origin: &str) -> Result<Self, FlipError> {
        let config: OptimizeConfig = crate::toml_file::parse(text, origin)?;
        config.validate(origin)?;
        Ok(config)
    }

    fn validate(&self, origin: &str) -> Result<(), FlipError> {
        let error = |key: String, reason: String| FlipError::Scene {
            path: origin.into(),
            key,
            reason,
        };
        // The scene's own checks, with its keys under `scene.`.
        let scene_text =
            toml::to_string(&self.scene).map_err(|e| error("scene".into(), e.to_string()))?;
        Scene::from_toml(&scene_text, origin).map_err(|e| crate::toml_file::under("scene", e))?;
        if self.scene.liquids.is_empty() {
            return Err(error(
                "scene.liquid".into(),
                "the optimised liquid is the scene's [[scene.liquid]]; there is none".into(),
            ));
        }
        let d = self.scene.dim();
        if self.target.liquid.is_empty() {
            return Err(error(
                "target.liquid".into(),
                "the target is empty: give at least one region".into(),
            ));
        }
        for (i, g) in self.target.liquid.iter().enumerate() {
            if g.dim() != d {
                return Err(error(
                    format!("target.liquid[{i}]"),
                    format!(
                        "a {}-dimensional target in a {d}-dimensional scene",
                        g.dim()
                    ),
                ));
            }
        }
        if self.target.particles_per_cell == Some(0) {
            return Err(error(
                "target.particles_per_cell".into(),
                "must be at least 1".into(),
            ));
        }
        let o = &self.optimize;
        if o.iterations == 0 {
            return Err(error(
                "optimize.iterations".into(),
                "must be at least 1".into(),
            ));
        }
        if !(o.learning_rate.is_finite() && o.learning_rate > 0.0) {
            return Err(error(
                "optimize.learning_rate".into(),
                format!("must be positive and finite, got {}", o.learning_rate),
            ));
        }
        if !(o.sinkhorn_epsilon.is_finite() && o.sinkhorn_epsilon > 0.0) {
            return Err(error(
                "optimize.sinkhorn_epsilon".into(),
                format!("must be positive and finite, got {}", o.sinkhorn_epsilon),
            ));
        }
        if o.density_levels == 0 {
            return Err(error(
                "optimize.density_levels".into(),
                "must be at least 1 (1: the domain's grid alone)".into(),
            ));
        }
        if !(o.divergence_factor.is_finite() && o.divergence_factor > 1.0) {
            return Err(error(
                "optimize.divergence_factor".into(),
                format!("must be finite and above 1, got {}", o.divergence_factor),
            ));
        }
        Ok(())
    }

    /// The loss of `[optimize]`.
    pub fn loss(&self) -> Loss {
        match self.optimize.loss {
            LossSpec::L2 => Loss::L2,
            LossSpec::Sinkhorn => Loss::Sinkhorn {
                epsilon: self.optimize.sinkhorn_epsilon,
            },
            LossSpec::Density => Loss::Density {
                levels: self.optimize.density_levels,
            },
        }
    }

    /// Builds the simulation, the initial guess and the target.
    ///
    /// # Errors
    /// [`FlipError::Scene`] for an invalid configuration, a target that covers no free cell,
    /// or (L2) a target with fewer points than the liquid has particles.
    pub fn build<B: LatticeKernels>(
        &self,
        origin: &str,
        device: &B::Device,
    ) -> Result<OptimizeProblem<B>, FlipError> {
        self.validate(origin)?;
        let error = |key: &str, reason: String| FlipError::Scene {
            path: origin.into(),
            key: key.into(),
            reason,
        };
        let setup = self
            .scene
            .build::<B>(origin, device)
            .map_err(|e| crate::toml_file::under("scene", e))?;
        let simulation = setup.simulation;
        let d = self.scene.dim();
        let s = &self.scene.simulation;
        let ppc = self
            .target
            .particles_per_cell
            .unwrap_or(s.particles_per_cell);
        let placement = match s.placement {
            PlacementSpec::Jittered => Placement::Jittered,
            PlacementSpec::Centered => Placement::Centered,
        };
        let mut points = Vec::new();
        for (i, region) in self.target.liquid.iter().enumerate() {
            let seeded = simulation.seed(
                region,
                &vec![0.0; d],
                ppc,
                placement,
                s.seed.wrapping_add(1000 + i as u64),
            )?;
            points.extend(seeded.positions.to_vec());
        }
        let n = setup.particles.len();
        let m = points.len() / d;
        if m == 0 {
            return Err(error(
                "target.liquid",
                "covers no cell centre outside the obstacles: the target is empty".into(),
            ));
        }
        let loss = self.loss();
        if m < n && loss == Loss::L2 {
            return Err(error(
                "target.liquid",
                format!(
                    "the l2 loss pairs particle i with target point i, but the target has {m} \
                     points for {n} particles: enlarge it or raise target.particles_per_cell"
                ),
            ));
        }
        if m > n {
            // A seeded choice of n points, kept in seeding order.
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(s.seed.wrapping_add(2000));
            let mut chosen = sample(&mut rng, m, n).into_vec();
            chosen.sort_unstable();
            points = chosen
                .iter()
                .flat_map(|&i| points[i * d..(i + 1) * d].to_vec())
                .collect();
        }
        let count = points.len() / d;
        let target_initial = Particles::from_host(points, vec![0.0; count * d], d, device)?;
        let target = if self.target.simulate {
            simulate(&simulation, &target_initial, setup.steps, None)?
                .positions
                .detach()
        } else {
            target_initial.positions.clone()
        };
        Ok(OptimizeProblem {
            simulation,
            initial: setup.particles,
            target_initial: target_initial.positions,
            target,
            steps: setup.steps,
            loss,
            learning_rate: self.optimize.learning_rate,
            iterations: self.optimize.iterations,
            divergence_factor: self.optimize.divergence_factor,
        })
    }
}

/// `steps` FLIP steps from `particles`, with the scene parameters `scene` (default: the
/// simulation's own).
///
/// # Errors
/// The first step's error.
pub fn simulate<B: LatticeKernels>(
    simulation: &FlipSimulation<B>,
    particles: &Particles<B>,
    steps: usize,
    scene: Option<&SceneParameters<B>>,
) -> Result<Particles<B>, FlipError> {
    let owned;
    let scene = match scene {
        Some(s) => s,
        None => {
            owned = simulation.scene_parameters()?;
            &owned
        }
    };
    let mut p = particles.clone();
    for step in 0..steps {
        p = simulation.step_with(&p, step, scene)?.0;
    }
    Ok(p)
}

/// An optimisation ready to run.
#[derive(Debug, Clone)]
pub struct OptimizeProblem<B: Backend> {
    /// The simulation.
    pub simulation: FlipSimulation<B>,
    /// The initial guess (positions are optimised, velocities kept).
    pub initial: Particles<B>,
    /// The target's initial positions `[M, d]` (the optimum when the target is simulated).
    pub target_initial: Tensor<B>,
    /// The target `[M, d]`.
    pub target: Tensor<B>,
    /// Steps simulated per iteration.
    pub steps: usize,
    /// The loss.
    pub loss: Loss,
    /// Gradient descent step size.
    pub learning_rate: f32,
    /// Iterations (gradient evaluations).
    pub iterations: usize,
    /// Stop when the loss exceeds this factor times the first loss.
    pub divergence_factor: f32,
}

/// One iteration: the loss of the initial positions it started from.
#[derive(Debug, Clone, PartialEq)]
pub struct IterationRecord {
    /// The iteration (0: the initial guess).
    pub iteration: usize,
    /// The loss.
    pub loss: f32,
    /// The norm of the loss' gradient with respect to the initial positions.
    pub gradient_norm: f32,
    /// Mean distance of the simulated particles to their target points (`√(2 L2 / N)`; the
    /// L2 pairing, whatever the loss) when the counts match, else `NaN`.
    pub rms_distance: f32,
    /// Chamfer distance of the simulated particles to the target (domain units).
    pub chamfer: f32,
    /// The initial positions, host `[N·d]`.
    pub initial_positions: Vec<f32>,
    /// The simulated positions after `steps` steps, host `[N·d]`.
    pub final_positions: Vec<f32>,
}

/// The result of [`OptimizeProblem::run`].
#[derive(Debug)]
pub struct OptimizeOutcome {
    /// One record per completed iteration, then (when the run did not stop early) one for the
    /// final positions, without a gradient step after it.
    pub records: Vec<IterationRecord>,
    /// Why the run stopped early; the records end with the last good state.
    pub stopped: Option<OptimizeError>,
}

impl OptimizeOutcome {
    /// The last good record.
    pub fn last(&self) -> Option<&IterationRecord> {
        self.records.last()
    }
}

/// A differentiable simulator of the optimised liquid: initial positions `[N, d]` (domain
/// units, carrying gradients) to positions after the run, `[N, d]`. FLIP is one
/// ([`OptimizeProblem`] itself); a learned simulator driven over the same scene is another.
pub trait Forward<B: Backend> {
    /// The positions after the run from `initial`, differentiable with respect to `initial`.
    ///
    /// # Errors
    /// Whatever the simulator reports.
    fn run(&self, initial: &Tensor<B>) -> Result<Tensor<B>, FlipError>;
}

/// FLIP: the problem's simulation, `steps` steps, with the initial guess's velocities.
impl<B: LatticeKernels> Forward<B> for OptimizeProblem<B> {
    fn run(&self, initial: &Tensor<B>) -> Result<Tensor<B>, FlipError> {
        let start = Particles {
            positions: initial.clone(),
            velocities: self.initial.velocities.clone(),
            affine: self.initial.affine.clone(),
        };
        Ok(simulate(&self.simulation, &start, self.steps, None)?.positions)
    }
}

impl<B: AutodiffBackend + LatticeKernels> OptimizeProblem<B> {
    /// The loss, its gradient with respect to the initial positions `positions` `[N, d]`, and
    /// the simulated final positions, through FLIP.
    ///
    /// # Errors
    /// Simulation and loss errors.
    pub fn loss_and_gradient(
        &self,
        positions: &Tensor<B>,
    ) -> Result<(f32, Tensor<B>, Tensor<B>), FlipError> {
        self.loss_and_gradient_through(self, positions)
    }

    /// [`OptimizeProblem::loss_and_gradient`] through another simulator.
    ///
    /// # Errors
    /// Simulation and loss errors.
    pub(crate) fn loss_and_gradient_through(
        &self,
        forward: &dyn Forward<B>,
        positions: &Tensor<B>,
    ) -> Result<(f32, Tensor<B>, Tensor<B>), FlipError> {
        let x0 = positions.detach().require_grad();
        let end = forward.run(&x0)?;
        let loss = self
            .loss
            .evaluate(&end, &self.target, self.simulation.domain())?;
        let value = loss.to_scalar()?;
        let gradient = loss.gradients(&[&x0])?.remove(0);
        Ok((value, gradient, end.detach()))
    }

    /// Gradient descent on the initial positions through FLIP: `x ← clamp(x − lr ∇L)` into the
    /// domain. Calls `on_record` after each iteration (for progress and output). Stops early,
    /// keeping the last good state, when the loss or gradient is not finite, the loss exceeds
    /// `divergence_factor` times the first, or the simulation fails.
    pub fn run(&self, on_record: impl FnMut(&IterationRecord)) -> OptimizeOutcome {
        self.run_through(self, on_record)
    }

    /// [`OptimizeProblem::run`] with another simulator between the initial positions and the
    /// loss; the target stays the problem's (FLIP's, when the target is simulated).
    pub fn run_through(
        &self,
        forward: &dyn Forward<B>,
        mut on_record: impl FnMut(&IterationRecord),
    ) -> OptimizeOutcome {
        let domain = self.simulation.domain().clone();
        let d = domain.dim();
        let target_host = self.target.to_vec();
        let mut positions = self.initial.positions.detach();
        let mut records = Vec::new();
        let mut first_loss = None;
        for iteration in 0..=self.iterations {
            let (loss, gradient, end) = match self.loss_and_gradient_through(forward, &positions) {
                Ok(r) => r,
                Err(source) => {
                    return OptimizeOutcome {
                        records,
                        stopped: Some(OptimizeError::Iteration { iteration, source }),
                    };
                }
            };
            let stop = |e| OptimizeOutcome {
                records: records.clone(),
                stopped: Some(e),
            };
            if !loss.is_finite() {
                return stop(OptimizeError::NonFinite {
                    iteration,
                    what: "loss",
                });
            }
            let g = gradient.to_vec();
            if g.iter().any(|v| !v.is_finite()) {
                return stop(OptimizeError::NonFinite {
                    iteration,
                    what: "gradient",
                });
            }
            let first = *first_loss.get_or_insert(loss);
            if loss > self.divergence_factor * first.max(f32::MIN_POSITIVE) {
                return stop(OptimizeError::Diverged {
                    iteration,
                    loss,
                    first,
                    factor: self.divergence_factor,
                });
            }
            let final_positions = end.to_vec();
            let record = IterationRecord {
                iteration,
                loss,
                gradient_norm: g.iter().map(|v| v * v).sum::<f32>().sqrt(),
                rms_distance: rms_distance(&final_positions, &target_host, d),
                chamfer: chamfer_distance(&final_positions, &target_host, d),
                initial_positions: positions.to_vec(),
                final_positions,
            };
            on_record(&record);
            records.push(record);
            if iteration == self.iterations {
                break;
            }
            positions = match descend(&positions, &gradient, self.learning_rate, &domain) {
                Ok(p) => p,
                Err(source) => {
                    return OptimizeOutcome {
                        records,
                        stopped: Some(OptimizeError::Iteration { iteration, source }),
                    };
                }
            };
        }
        OptimizeOutcome {
            records,
            stopped: None,
        }
    }
}

/// `√(mean |aᵢ − bᵢ|²)` when the sets have the same size, else `NaN`.
pub fn rms_distance(a: &[f32], b: &[f32], d: usize) -> f32 {
    if a.len() != b.len() || a.is_empty() || d == 0 {
        return f32::NAN;
    }
    let n = a.len() / d;
    let s: f64 = a.iter().zip(b).map(|(x, y)| f64::from(x - y).powi(2)).sum();
    (s / n as f64).sqrt() as f32
}

/// `clamp(x − lr g)` into the domain's closed box (a sliver inside the upper sides, as the
/// simulation's own clamp).
fn descend<B: Backend>(
    x: &Tensor<B>,
    gradient: &Tensor<B>,
    learning_rate: f32,
    domain: &Domain,
) -> Result<Tensor<B>, FlipError> {
    let d = domain.dim();
    let device = x.device();
    let dx = domain.cell_size();
    let upper: Vec<f32> = (0..d).map(|a| domain.upper()[a] - 1e-4 * dx[a]).collect();
    let lower = Tensor::from_vec(domain.lower().to_vec(), &[1, d], &device)?;
    let upper = Tensor::from_vec(upper, &[1, d], &device)?;
    let moved = x - &(gradient * learning_rate);
    Ok(moved.maximum(&lower)?.minimum(&upper)?.detach())
}
