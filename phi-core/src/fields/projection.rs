//! Pressure projection: the velocity made divergence-free on the liquid cells (thesis eq. 2.9).
//!
//! With unit density and the time step folded into the pressure, the projection finds `p` with
//! `∇·(w ∇p) = ∇·u` on the liquid cells, `p = 0` in air cells (the free surface, Dirichlet),
//! no flux through closed walls and through faces an obstacle blocks (Neumann, face weight
//! `w = 0`), and returns `u − w ∇p`. The discrete system is [`poisson_matrix`]'s; it is solved
//! with [`Tensor::linear_solve`], so on the autodiff backends the projection is differentiable
//! with respect to the velocity (one adjoint solve per backward pass). The masks — which cells
//! are liquid, which faces are open — are constants, as in Φ_Flow.

use crate::backend::Backend;
use crate::error::TensorError;
use crate::solve::{PoissonSystem, SolveError, SolveOptions, SolveStats};
use crate::tensor::{IntTensor, Tensor};

use super::grid::{CenteredGrid, StaggeredGrid};
use super::ops::{apply_wall_boundaries, divergence, gradient};
use super::poisson::{all_faces_open, poisson_matrix};

/// The result of [`pressure_projection`].
#[derive(Debug, Clone)]
pub struct Projection<B: Backend> {
    /// The projected velocity: divergence-free on the liquid cells (to the solver's tolerance),
    /// `u · n = 0` on closed walls, the obstacle velocity on blocked faces.
    pub velocity: StaggeredGrid<B>,
    /// The pressure `[res..., 1]` (times `Δt / ρ`): 0 outside the liquid.
    pub pressure: CenteredGrid<B>,
    /// Iterations and residual of the linear solve (zeros when there was no liquid).
    pub stats: SolveStats,
    /// Number of unknowns (liquid cells) of the solve.
    pub unknowns: usize,
}

/// Where the liquid and the obstacles are, for [`pressure_projection`].
#[derive(Debug, Clone, Copy)]
pub struct ProjectionMasks<'a, B: Backend> {
    /// `[res..., 1]`: cells whose value exceeds `0.5` are liquid (the unknowns); the rest is air.
    pub liquid: &'a CenteredGrid<B>,
    /// Per face, the fraction that is open to flow, in `[0, 1]` (`0`: blocked by an obstacle).
    /// `None`: every face open. The domain's closed sides are walls regardless.
    pub face_open: Option<&'a StaggeredGrid<B>>,
    /// The obstacles' velocity on the faces they block (`None`: obstacles at rest). A face with
    /// open fraction `w` carries `w u + (1 − w) u_obstacle` into the solve.
    pub obstacle_velocity: Option<&'a StaggeredGrid<B>>,
}

impl<'a, B: Backend> ProjectionMasks<'a, B> {
    /// Liquid cells only: no obstacles.
    pub fn liquid(liquid: &'a CenteredGrid<B>) -> Self {
        Self {
            liquid,
            face_open: None,
            obstacle_velocity: None,
        }
    }
}

/// Makes `velocity` divergence-free on the liquid cells of `masks` (see the module docs).
///
/// Steps: impose the obstacle velocity on blocked faces and `u · n = 0` on closed walls; take the
/// divergence on the liquid cells; in each liquid region that touches neither air nor an open
/// side (a closed container filled to the brim), remove the mean of the divergence, which no
/// pressure can remove; solve `A p = −∇·u` ([`poisson_matrix`]); subtract `w ∇p`.
///
/// # Errors
/// - [`SolveError::Tensor`] when a mask's domain or shape differs from the velocity's.
/// - [`SolveError::NonFinite`] when the velocity holds NaN or infinity next to the liquid (the
///   solve rejects the non-finite divergence).
/// - [`SolveError::NotConverged`] when the solver does not reach `options`' tolerance.
pub fn pressure_projection<B: Backend>(
    velocity: &StaggeredGrid<B>,
    masks: ProjectionMasks<'_, B>,
    options: &SolveOptions,
) -> Result<Projection<B>, SolveError> {
    let domain = velocity.domain();
    domain.check_same(masks.liquid.domain(), "pressure_projection (liquid mask)")?;
    let liquid = masks
        .liquid
        .scalar_values("pressure_projection (liquid mask)")?;
    let device = velocity.component(0).device();

    // The face weights on the host (for the matrix) and as tensors (for the velocity).
    let face_open = match masks.face_open {
        Some(open) => {
            domain.check_same(open.domain(), "pressure_projection (face weights)")?;
            Some(open.map(|_, w| Ok(w.clamp(0.0, 1.0)))?)
        }
        None => None,
    };
    let mut u = match (&face_open, masks.obstacle_velocity) {
        (Some(open), Some(solid)) => {
            domain.check_same(solid.domain(), "pressure_projection (obstacle velocity)")?;
            // w u + (1 − w) u_s = u_s + w (u − u_s)
            solid.add(&open.mul(&velocity.sub(solid)?)?)?
        }
        (Some(open), None) => velocity.mul(open)?,
        (None, _) => velocity.clone(),
    };
    u = apply_wall_boundaries(&u)?;

    let liquid_host = liquid.host_values();
    let system = match &face_open {
        Some(open) => {
            let weights: Vec<_> = open.components().iter().map(|c| c.host_values()).collect();
            poisson_matrix(domain, &liquid_host, &weights)?
        }
        None => poisson_matrix(domain, &liquid_host, &all_faces_open(domain))?,
    };
    let n = system.unknowns();
    let mut pressure_shape = domain.resolution().to_vec();
    pressure_shape.push(1);
    if n == 0 {
        return Ok(Projection {
            velocity: u,
            pressure: CenteredGrid::new(Tensor::zeros(&pressure_shape, &device), domain.clone())?,
            stats: SolveStats::default(),
            unknowns: 0,
        });
    }

    let cells = domain.cell_count();
    let unknown_cells = IntTensor::from_vec(system.unknown_cells_i64(), &[n], &device)?;
    let div = divergence(&u)?.values().reshape(&[cells, 1])?;
    let mut rhs = -div.gather_rows(&unknown_cells)?;
    if !system.pinned.is_empty() {
        rhs = remove_singular_means(&system, &rhs)?;
    }
    let (p, stats) = rhs.linear_solve(&system.matrix, options)?;
    let p_cells = Tensor::zeros(&[cells, 1], &device).scatter_add_rows(&unknown_cells, &p)?;
    let pressure = CenteredGrid::new(p_cells.reshape(&pressure_shape)?, domain.clone())?;

    let mut grad = gradient(&pressure)?;
    if let Some(open) = &face_open {
        grad = grad.mul(open)?;
    }
    let projected = apply_wall_boundaries(&u.sub(&grad)?)?;
    Ok(Projection {
        velocity: projected,
        pressure,
        stats,
        unknowns: n,
    })
}

/// `rhs [n, 1]` minus, in every pure-Neumann region, the region's mean (the tensor version of
/// [`PoissonSystem::remove_singular_means`], differentiable in `rhs`).
fn remove_singular_means<B: Backend>(
    system: &PoissonSystem,
    rhs: &Tensor<B>,
) -> Result<Tensor<B>, TensorError> {
    let device = rhs.device();
    let n = system.unknowns();
    let regions = system.region_is_singular.len();
    let region_of: Vec<i64> = system.region_of.iter().map(|&r| r as i64).collect();
    let region_of = IntTensor::from_vec(region_of, &[n], &device)?;
    let mut counts = vec![0.0f32; regions];
    for &r in &system.region_of {
        counts[r] += 1.0;
    }
    let scale: Vec<f32> = counts
        .iter()
        .zip(&system.region_is_singular)
        .map(|(&c, &singular)| if singular { 1.0 / c } else { 0.0 })
        .collect();
    let scale = Tensor::from_vec(scale, &[regions, 1], &device)?;
    let sums = Tensor::zeros(&[regions, 1], &device).scatter_add_rows(&region_of, rhs)?;
    let means = (sums * scale).gather_rows(&region_of)?;
    Ok(rhs - means)
}
