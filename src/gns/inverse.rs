//! Inverse problems through a learned simulator: `phi optimize --simulator gns --model DIR`.
//!
//! The optimisation of thesis section 4.3 with a trained GNS in place of FLIP between the initial
//! positions and the loss ([`GnsForward`], a [`Forward`] of phi-flip's optimiser); the scene, the
//! target (FLIP's, when the target is simulated), the loss and gradient descent are the same.
//!
//! The model sees the scene as it saw its training data:
//! - positions in the dataset's stored units, `x_cells · s + 0.1` with `s = 0.8 / max(resolution)`
//!   (the scene's grid must fit the model's `bounds`);
//! - a history of `C + 1` frames before the first prediction, made from the initial positions
//!   and the liquid's initial velocity `v` (cells per second): frame `−k` is `x₀ − k·v·dt`, so a
//!   liquid at rest starts with `C` zero velocities;
//! - one obstacle particle (type 0) at the centre of every solid cell of the scene, static, and
//!   the liquid as type 1; a model trained without boundary features (1snb) needs the scene's
//!   walls as obstacles, as its dataset had them;
//! - one model step per scene step, so the scene's `dt` should be the dataset's frame interval.
//!
//! Gradients flow through every predicted position into the next window; the radius graph is
//! rebuilt from the values at each step and carries none.

use std::path::Path;

use anyhow::{Context, Result, bail};
use phi_core::fields::LatticeKernels;
use phi_core::{Backend, Tensor};
use phi_flip::optimize::Forward;
use phi_flip::{FlipError, OptimizeProblem};
use phi_gns::data::{LIQUID, OBSTACLE};
use phi_gns::model::{Gns, GnsKernels, GraphBatch, load_model};
use phi_gns::rollout::Rollout;

/// A trained GNS rolled out over an optimisation's scene, differentiably.
pub struct GnsForward<B: GnsKernels> {
    model: Gns<B>,
    /// The model directory, for messages.
    name: String,
    steps: usize,
    /// Stored = cells · scale + offset.
    scale: f32,
    offset: f32,
    /// Per-step displacement of the history, cells: `v · dt` per liquid particle, `[N · d]`.
    history_step: Vec<f32>,
    /// Obstacle particles in stored units, `[M · d]`.
    obstacles: Vec<f32>,
    dim: usize,
}

impl<B: GnsKernels + LatticeKernels> GnsForward<B> {
    /// The model of `dir` for `problem`'s scene.
    ///
    /// # Errors
    /// A model that cannot be read, or one whose dimension, particle types or bounds do not fit
    /// the scene: the message names the model and the scene's key.
    pub fn new(dir: &Path, problem: &OptimizeProblem<B>, origin: &str) -> Result<Self> {
        let device = B::default_device();
        let model = load_model::<B>(dir, &device)
            .with_context(|| format!("loading the model {}", dir.display()))?;
        let name = dir.display().to_string();
        let spec = model.spec();
        let domain = problem.simulation.domain();
        let dim = domain.dim();
        if spec.config.dim != dim {
            bail!(
                "{origin}: scene.domain: a {dim}D scene for the {}D model {name}",
                spec.config.dim
            );
        }
        if spec.config.particle_types <= OBSTACLE.max(LIQUID) as usize {
            bail!(
                "model {name}: {} particle types; phi's datasets use 0 (obstacle) and 1 (liquid)",
                spec.config.particle_types
            );
        }
        let resolution = domain.resolution();
        let longest = resolution.iter().copied().max().unwrap_or(1).max(1);
        let scale = 0.8 / longest as f32;
        let offset = 0.1f32;
        for (axis, (&n, bounds)) in resolution.iter().zip(&spec.bounds).enumerate() {
            let upper = offset as f64 + n as f64 * scale as f64;
            if (bounds[0] - offset as f64).abs() > 1e-6 || (bounds[1] - upper).abs() > 1e-6 {
                bail!(
                    "{origin}: scene.domain.resolution: axis {axis} of {n} cells maps onto \
                     [{offset}, {upper:.6}] in the model's units, but the model {name} was \
                     trained on bounds [{}, {}]",
                    bounds[0],
                    bounds[1]
                );
            }
        }
        let solid = problem.simulation.solid_cells(0.0)?;
        let obstacles: Vec<f32> = if dim == 2 {
            phi_flip::cell_centres(&solid, resolution[1])
                .iter()
                .map(|&x| x * scale + offset)
                .collect()
        } else if solid.iter().any(|&s| s) {
            bail!("{origin}: scene.obstacle: obstacles through a GNS are supported in 2D only");
        } else {
            Vec::new()
        };
        let dt = problem.simulation.params().dt;
        let history_step = problem
            .initial
            .velocities
            .to_vec()
            .iter()
            .map(|v| v * dt)
            .collect();
        Ok(GnsForward {
            model,
            name,
            steps: problem.steps,
            scale,
            offset,
            history_step,
            obstacles,
            dim,
        })
    }

    /// The model's name in messages (its directory).
    pub fn name(&self) -> &str {
        &self.name
    }

    fn run_model(
        &self,
        initial: &Tensor<B>,
    ) -> Result<Tensor<B>, Box<dyn std::error::Error + Send + Sync>> {
        let device = initial.device();
        let spec = self.model.spec();
        let (d, c) = (self.dim, spec.config.input_velocities);
        let n = initial.shape()[0];
        let m = self.obstacles.len() / d;
        let stored = &(initial * self.scale) + self.offset;
        let back = Tensor::from_vec(
            self.history_step.iter().map(|v| v * self.scale).collect(),
            &[n, d],
            &device,
        )?;
        let obstacles = Tensor::from_vec(self.obstacles.clone(), &[m, d], &device)?;
        // Frames −C ..= 0, oldest first, each liquid then obstacles.
        let frames: Vec<Tensor<B>> = (0..=c)
            .rev()
            .map(|k| {
                let liquid = &stored - &(&back * k as f32);
                Tensor::concat(&[liquid, obstacles.clone()], 0)?.unsqueeze(1)
            })
            .collect::<Result<_, _>>()?;
        let window = Tensor::concat(&frames, 1)?;
        let mut types = vec![LIQUID; n];
        types.extend(std::iter::repeat_n(OBSTACLE, m));
        let host = window.to_vec();
        let batch = GraphBatch::from_host(&host, &types, spec, &device)?.with_positions(window)?;
        let mut rollout = Rollout::new(&self.model, batch)?;
        // The obstacles are kinematic: each step puts them back where they are (the liquid's
        // rows are the model's).
        let kinematic = Tensor::concat(&[Tensor::zeros(&[n, d], &device), obstacles], 0)?;
        let mut liquid = stored;
        // A non-finite prediction stops the next step's graph with an error naming it; one in
        // the last frame makes the loss non-finite, which the optimiser reports.
        for _ in 0..self.steps {
            liquid = rollout.step(&kinematic)?.narrow(0, 0..n)?;
        }
        Ok(&(&liquid - self.offset) * (1.0 / self.scale))
    }
}

impl<B: GnsKernels + LatticeKernels + Backend> Forward<B> for GnsForward<B> {
    fn run(&self, initial: &Tensor<B>) -> Result<Tensor<B>, FlipError> {
        self.run_model(initial)
            .map_err(|source| FlipError::Simulator {
                simulator: format!("GNS {}", self.name),
                source,
            })
    }
}
