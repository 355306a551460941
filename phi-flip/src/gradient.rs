//! A FLIP run as a differentiable function of its initial state, for front ends that keep their
//! own autodiff (PyTorch): the forward map `(x₀, v₀) ↦ (x_T, v_T)` of `T` steps and its
//! vector-Jacobian product
//!
//! `(ḡₓ, ḡᵥ) ↦ (∂x_T/∂x₀ᵀ ḡₓ + ∂v_T/∂x₀ᵀ ḡᵥ,  ∂x_T/∂v₀ᵀ ḡₓ + ∂v_T/∂v₀ᵀ ḡᵥ)`,
//!
//! the backward pass another framework asks of an operation. The product is the gradient of the
//! scalar `Σ ḡₓ ⊙ x_T + Σ ḡᵥ ⊙ v_T` through the steps on the autodiff backend, so it is exact
//! for the run's smooth piece (the liquid cells, valid faces and interpolation cells of the
//! forward pass held constant, as every gradient of phi's FLIP is).
//!
//! ```
//! use phi_core::Backend;
//! use phi_core::backend::burn::Burn;
//! use phi_flip::{FlipGradient, HostState, Scene};
//!
//! let scene = Scene::from_toml(
//!     "domain = { resolution = [8, 8] }\n\
//!      simulation = { dt = 0.05, steps = 3 }\n\
//!      liquid = [{ geometry = { type = \"box\", lower = [2, 2], upper = [4, 4] } }]",
//!     "<doc>",
//! )?;
//! let (flip, initial) = FlipGradient::<Burn>::from_scene(&scene, "<doc>", None, &Default::default())?;
//! let end = flip.run_host(&initial)?;
//! // ∂(Σ y_T)/∂(x₀, v₀): an upstream gradient of ones on the final heights.
//! let mut upstream = HostState::zeros(end.particles(), 2);
//! upstream.positions.iter_mut().skip(1).step_by(2).for_each(|g| *g = 1.0);
//! let gradient = flip.vjp_host(&initial, &upstream)?;
//! assert_eq!(gradient.positions.len(), initial.positions.len());
//! # Ok::<(), phi_flip::FlipError>(())
//! ```

use phi_core::backend::BinaryOp;
use phi_core::fields::LatticeKernels;
use phi_core::{AutodiffBackend, Backend, Tensor};

use crate::error::{FlipError, Result};
use crate::optimize::simulate;
use crate::scene::Scene;
use crate::sim::{FlipSimulation, Particles};

/// Particle positions and velocities on the host, each row-major `[N, d]`.
#[derive(Debug, Clone, PartialEq)]
pub struct HostState {
    /// Positions `[N·d]`, domain units (or, as an upstream gradient, per position).
    pub positions: Vec<f32>,
    /// Velocities `[N·d]`, domain units per second (or a gradient per velocity).
    pub velocities: Vec<f32>,
    /// `d`.
    pub dim: usize,
}

impl HostState {
    /// `n` particles of dimension `dim`, all zeros (an upstream gradient to fill in).
    pub fn zeros(n: usize, dim: usize) -> Self {
        Self {
            positions: vec![0.0; n * dim],
            velocities: vec![0.0; n * dim],
            dim,
        }
    }

    /// `N`.
    pub fn particles(&self) -> usize {
        self.positions.len() / self.dim.max(1)
    }

    /// The state's tensors on `device`.
    ///
    /// # Errors
    /// [`FlipError::InvalidParameter`] naming `what` when the positions and velocities do not
    /// both fill `[N, d]`.
    fn to_particles<B: Backend>(
        &self,
        what: &'static str,
        device: &B::Device,
    ) -> Result<Particles<B>> {
        let d = self.dim.max(1);
        if !self.positions.len().is_multiple_of(d) || self.positions.len() != self.velocities.len()
        {
            return Err(FlipError::InvalidParameter {
                name: what,
                reason: format!(
                    "{} position and {} velocity values do not both fill [N, {d}]",
                    self.positions.len(),
                    self.velocities.len()
                ),
            });
        }
        Particles::from_host(self.positions.clone(), self.velocities.clone(), d, device)
    }

    fn from_particles<B: Backend>(particles: &Particles<B>, dim: usize) -> Self {
        Self {
            positions: particles.positions.to_vec(),
            velocities: particles.velocities.to_vec(),
            dim,
        }
    }
}

/// `steps` FLIP steps of a simulation from a given initial state, with their gradient.
///
/// The run is [`simulate`](crate::optimize::simulate) with the simulation's own scene parameters
/// (gravity, obstacles, inflows): the steps `phi simulate` takes, from step index 0. APIC scenes
/// start from zero affine matrices. With inflows, the final state holds the emitted particles
/// after the initial ones (`N_T ≥ N`).
#[derive(Debug, Clone)]
pub struct FlipGradient<B: Backend> {
    simulation: FlipSimulation<B>,
    steps: usize,
    device: B::Device,
}

impl<B: LatticeKernels> FlipGradient<B> {
    /// `steps` steps of `simulation`.
    ///
    /// # Errors
    /// When the simulation's scene parameters cannot be built.
    pub fn new(simulation: FlipSimulation<B>, steps: usize) -> Result<Self> {
        let device = simulation.scene_parameters()?.gravity.device();
        Ok(Self {
            simulation,
            steps,
            device,
        })
    }

    /// A scene's simulation (`steps`, default the scene's `simulation.steps`) and its seeded
    /// initial state; `origin` names the scene in errors.
    ///
    /// # Errors
    /// [`FlipError::Scene`] for a scene that does not build.
    pub fn from_scene(
        scene: &Scene,
        origin: &str,
        steps: Option<usize>,
        device: &B::Device,
    ) -> Result<(Self, HostState)> {
        let setup = scene.build::<B>(origin, device)?;
        let initial = HostState::from_particles(&setup.particles, scene.dim());
        let steps = steps.unwrap_or(setup.steps);
        Ok((Self::new(setup.simulation, steps)?, initial))
    }

    /// The simulation.
    pub fn simulation(&self) -> &FlipSimulation<B> {
        &self.simulation
    }

    /// The number of steps of a run.
    pub fn steps(&self) -> usize {
        self.steps
    }

    /// The state after the run from `initial` (positions and velocities `[N, d]`); on an
    /// autodiff backend differentiable with respect to `initial`'s tensors.
    ///
    /// # Errors
    /// [`FlipError::InvalidParameter`] for tensors that are not both `[N, d]` of the domain's
    /// `d`, and the first failed step's error.
    pub fn run(&self, initial: &Particles<B>) -> Result<Particles<B>> {
        self.check_initial(initial)?;
        let start = Particles::new(initial.positions.clone(), initial.velocities.clone());
        simulate(&self.simulation, &start, self.steps, None)
    }

    /// [`FlipGradient::run`] on host data.
    ///
    /// # Errors
    /// As [`FlipGradient::run`].
    pub fn run_host(&self, initial: &HostState) -> Result<HostState> {
        let device = &self.device;
        let end = self.run(&initial.to_particles("initial state", device)?)?;
        Ok(HostState::from_particles(&end, self.dim()))
    }

    fn dim(&self) -> usize {
        self.simulation.domain().dim()
    }

    fn check_initial(&self, initial: &Particles<B>) -> Result<()> {
        let (p, v) = (initial.positions.shape(), initial.velocities.shape());
        let d = self.dim();
        if p.len() != 2 || p[1] != d || p != v {
            return Err(FlipError::InvalidParameter {
                name: "initial state",
                reason: format!(
                    "positions {p:?} and velocities {v:?} must both be [N, {d}] in this \
                     {d}-dimensional domain"
                ),
            });
        }
        Ok(())
    }
}

impl<B: AutodiffBackend + LatticeKernels> FlipGradient<B> {
    /// The vector-Jacobian product of the run at `initial`: the gradients with respect to the
    /// initial positions and velocities `[N, d]` of `Σ grad_positions ⊙ x_T + Σ grad_velocities
    /// ⊙ v_T`, where `grad_*` are the upstream gradients `[N_T, d]` of the final state. Runs the
    /// steps once more, recording them (the forward pass holds no graph between calls, so any
    /// number of products can be asked of one state). Returns `(∂/∂x₀, ∂/∂v₀)` as untracked
    /// tensors.
    ///
    /// # Errors
    /// As [`FlipGradient::run`], and [`FlipError::InvalidParameter`] when an upstream gradient
    /// does not have the final state's shape.
    pub fn vjp(
        &self,
        initial: &Particles<B>,
        grad_positions: &Tensor<B>,
        grad_velocities: &Tensor<B>,
    ) -> Result<(Tensor<B>, Tensor<B>)> {
        let x0 = initial.positions.detach().require_grad();
        let v0 = initial.velocities.detach().require_grad();
        let end = self.run(&Particles::new(x0.clone(), v0.clone()))?;
        for (name, upstream, state) in [
            ("grad_positions", grad_positions, &end.positions),
            ("grad_velocities", grad_velocities, &end.velocities),
        ] {
            if upstream.shape() != state.shape() {
                return Err(FlipError::InvalidParameter {
                    name,
                    reason: format!(
                        "shape {:?}: the gradient of the final state must have its shape {:?}",
                        upstream.shape(),
                        state.shape()
                    ),
                });
            }
        }
        let weighted = end
            .positions
            .binary(BinaryOp::Mul, &grad_positions.detach())?
            .sum()
            .binary(
                BinaryOp::Add,
                &end.velocities
                    .binary(BinaryOp::Mul, &grad_velocities.detach())?
                    .sum(),
            )?;
        let mut gradients = weighted.gradients(&[&x0, &v0])?;
        let dv0 = gradients.pop().expect("two gradients for two leaves");
        let dx0 = gradients.pop().expect("two gradients for two leaves");
        Ok((dx0, dv0))
    }

    /// [`FlipGradient::vjp`] on host data: `upstream` holds the upstream gradients of the final
    /// positions and velocities; returns the gradients of the initial ones.
    ///
    /// # Errors
    /// As [`FlipGradient::vjp`].
    pub fn vjp_host(&self, initial: &HostState, upstream: &HostState) -> Result<HostState> {
        let device = &self.device;
        let initial = initial.to_particles("initial state", device)?;
        let upstream = upstream.to_particles("upstream gradient", device)?;
        let (dx0, dv0) = self.vjp(&initial, &upstream.positions, &upstream.velocities)?;
        Ok(HostState {
            positions: dx0.to_vec(),
            velocities: dv0.to_vec(),
            dim: self.dim(),
        })
    }
}

#[cfg(test)]
mod tests {
    //! The vector-Jacobian product against central finite differences of the forward map.
    //!
    //! The projection `u·x_T + w·v_T` (fixed pseudo-random `u`, `w`) is accumulated in `f64`, so
    //! the difference quotient's round-off is that of the `f32` states alone, `~ε·|x|·√n / h`.
    //! As in `tests/flip/gradients.rs`, an element is compared only where `FD(h)` and `FD(h/2)`
    //! agree to `2·10⁻³ + 10⁻²|FD|` (its stencil lies on one smooth piece: no particle crosses
    //! a face or cell line), and at least 80 % must; those agree with the product to
    //! `5·10⁻³ (1 + |FD|)`. Measured on Burn, `|vjp − FD| / (10⁻² + |FD|)` is at most
    //! `1.9·10⁻³` for the falling block (48 of 48 compared) and `3.7·10⁻²` next to the obstacle
    //! (45 of 48).

    use super::*;
    use phi_core::fields::{Boundary, Domain};
    use phi_geom::{Geometry, Obstacle};

    use crate::sim::FlipParams;

    phi_core::autodiff_backend_tests!(
        vjp_of_a_falling_block_matches_finite_differences,
        vjp_next_to_an_obstacle_matches_finite_differences,
        vjp_refuses_misshapen_upstream_gradients,
    );

    const H: f32 = 1e-2;

    /// Three particles per cell of `[x0, x0 + 2) × [y0, y0 + 2)`, off the face and centre lines,
    /// with a smooth velocity field.
    fn block(x0: f32, y0: f32, vy: f32) -> HostState {
        let (mut p, mut v) = (Vec::new(), Vec::new());
        for i in 0..2 {
            for j in 0..2 {
                for (a, b) in [(0.2, 0.3), (0.7, 0.15), (0.35, 0.8)] {
                    let (x, y) = (x0 + i as f32 + a, y0 + j as f32 + b);
                    p.extend([x, y]);
                    v.extend([0.8 * (0.7 * y).sin(), vy + 0.5 * (0.9 * x).cos()]);
                }
            }
        }
        HostState {
            positions: p,
            velocities: v,
            dim: 2,
        }
    }

    fn flip<B: LatticeKernels>(obstacles: Vec<Obstacle>, steps: usize) -> FlipGradient<B> {
        let domain = Domain::new(
            &[8, 8],
            &[0.0, 0.0],
            &[8.0, 8.0],
            &[[Boundary::Closed; 2]; 2],
        )
        .unwrap();
        let simulation = FlipSimulation::new(
            domain,
            FlipParams::thesis(2, 0.05),
            obstacles,
            vec![],
            3,
            &B::default_device(),
        )
        .unwrap();
        FlipGradient::new(simulation, steps).unwrap()
    }

    /// Fixed upstream gradients of `n` particles.
    fn upstream(n: usize) -> HostState {
        let weights = |phase: f32| -> Vec<f32> {
            (0..2 * n)
                .map(|k| 1.0 + 0.5 * (1.3 * k as f32 + phase).sin())
                .collect()
        };
        HostState {
            positions: weights(0.4),
            velocities: weights(1.1).iter().map(|w| 0.1 * w).collect(),
            dim: 2,
        }
    }

    /// `u·x_T + w·v_T`, accumulated in `f64`.
    fn projection<B: LatticeKernels>(
        flip: &FlipGradient<B>,
        initial: &HostState,
        u: &HostState,
    ) -> f64 {
        let end = flip.run_host(initial).unwrap();
        let dot = |a: &[f32], b: &[f32]| -> f64 {
            a.iter()
                .zip(b)
                .map(|(x, y)| f64::from(*x) * f64::from(*y))
                .sum()
        };
        dot(&end.positions, &u.positions) + dot(&end.velocities, &u.velocities)
    }

    /// Central differences of the projection with step `h`, positions then velocities.
    fn finite_differences<B: LatticeKernels>(
        flip: &FlipGradient<B>,
        initial: &HostState,
        u: &HostState,
        h: f32,
    ) -> Vec<f64> {
        let n = initial.positions.len();
        (0..2 * n)
            .map(|e| {
                let (mut plus, mut minus) = (initial.clone(), initial.clone());
                let (p, m) = if e < n {
                    (&mut plus.positions[e], &mut minus.positions[e])
                } else {
                    (&mut plus.velocities[e - n], &mut minus.velocities[e - n])
                };
                *p += h;
                *m -= h;
                let step = f64::from(*p) - f64::from(*m);
                (projection(flip, &plus, u) - projection(flip, &minus, u)) / step
            })
            .collect()
    }

    fn check<B: AutodiffBackend + LatticeKernels>(flip: &FlipGradient<B>, initial: &HostState) {
        let u = upstream(initial.particles());
        let analytic = flip.vjp_host(initial, &u).unwrap();
        let analytic: Vec<f64> = analytic
            .positions
            .iter()
            .chain(&analytic.velocities)
            .map(|&g| f64::from(g))
            .collect();
        let fd = finite_differences(flip, initial, &u, H);
        let fd_half = finite_differences(flip, initial, &u, H / 2.0);
        let mut compared = 0;
        let mut worst = 0.0f64;
        for (e, ((a, f), f2)) in analytic.iter().zip(&fd).zip(&fd_half).enumerate() {
            if (f - f2).abs() > 2e-3 + 1e-2 * f.abs() {
                continue;
            }
            compared += 1;
            worst = worst.max((a - f).abs() / (1e-2 + f.abs()));
            assert!(
                (a - f).abs() <= 5e-3 + 5e-3 * f.abs(),
                "element {e}: vjp {a}, finite differences {f} (h/2: {f2})"
            );
        }
        println!(
            "{compared} of {} elements compared; worst |vjp − fd| / (10⁻² + |fd|) {worst:.2e}",
            analytic.len()
        );
        assert!(
            compared * 5 >= analytic.len() * 4,
            "only {compared} compared"
        );
        // Both halves carry gradient: the product is not trivially zero anywhere.
        let n = initial.positions.len();
        for part in [&analytic[..n], &analytic[n..]] {
            assert!(part.iter().any(|g| g.abs() > 1e-2), "{part:?}");
        }
    }

    fn vjp_of_a_falling_block_matches_finite_differences<B: AutodiffBackend + LatticeKernels>() {
        check(&flip::<B>(vec![], 4), &block(3.0, 3.0, -1.0));
    }

    fn vjp_next_to_an_obstacle_matches_finite_differences<B: AutodiffBackend + LatticeKernels>() {
        // A block falling onto a thin box between cell centres: particles that end a step in it
        // are pushed out, and the gradient runs through the pushes.
        let obstacle = Obstacle::at_rest(Geometry::boxed(vec![2.6, 2.6], vec![5.4, 3.4]).unwrap());
        check(
            &flip::<B>(vec![obstacle.unwrap()], 3),
            &block(3.0, 4.0, -12.0),
        );
    }

    fn vjp_refuses_misshapen_upstream_gradients<B: AutodiffBackend + LatticeKernels>() {
        let flip = flip::<B>(vec![], 1);
        let initial = block(3.0, 3.0, 0.0);
        let short = HostState::zeros(initial.particles() - 1, 2);
        let error = flip.vjp_host(&initial, &short).unwrap_err().to_string();
        assert!(
            error.contains("grad_positions") && error.contains("[11, 2]"),
            "{error}"
        );
        let three_d = HostState::zeros(4, 3);
        let error = flip.run_host(&three_d).unwrap_err().to_string();
        assert!(error.contains("[N, 2]"), "{error}");
    }
}
