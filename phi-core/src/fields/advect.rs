//! Advection: semi-Lagrangian advection of grids and explicit advection of points.

use super::kernels::{Integrator, LatticeKernels};
use crate::error::{Result, TensorError};
use crate::tensor::Tensor;

use super::grid::{CenteredGrid, StaggeredGrid, cell_centers, face_centers};
use super::lattice::staggered_lattices;
use super::sample::{sample_centered, sample_face_component, sample_staggered};

pub(crate) fn advect_centered<B: LatticeKernels>(
    field: &CenteredGrid<B>,
    velocity: &StaggeredGrid<B>,
    dt: f32,
) -> Result<CenteredGrid<B>> {
    let domain = field.domain();
    domain.check_same(velocity.domain(), "advect_semi_lagrangian")?;
    let d = domain.dim();
    let device = field.values().device();
    let points = cell_centers::<B>(domain, &device).reshape(&[domain.cell_count(), d])?;
    let back = &points - &(sample_staggered(velocity, &points)? * dt);
    let sampled = sample_centered(field, &back)?;
    field.with_values(sampled.reshape(&field.values().shape())?)
}

pub(crate) fn advect_staggered<B: LatticeKernels>(
    field: &StaggeredGrid<B>,
    velocity: &StaggeredGrid<B>,
    dt: f32,
) -> Result<StaggeredGrid<B>> {
    let domain = field.domain();
    domain.check_same(velocity.domain(), "advect_semi_lagrangian")?;
    let d = domain.dim();
    let device = field.component(0).device();
    field.map(|axis, component| {
        let shape = component.shape();
        let count = component.numel();
        let points = face_centers::<B>(domain, axis, &device).reshape(&[count, d])?;
        let back = &points - &(sample_staggered(velocity, &points)? * dt);
        sample_face_component(component, domain, axis, &back)?.reshape(&shape)
    })
}

/// `points [N, d]` moved through the (frozen) staggered `velocity` over `dt`, the velocity
/// sampled as [`sample_staggered`] samples it: Euler `x + Δt u(x)`, or RK4
/// `x + Δt/6 (k₁ + 2k₂ + 2k₃ + k₄)` with `k₁ = u(x)`, `k₂ = u(x + Δt/2 k₁)`,
/// `k₃ = u(x + Δt/2 k₂)`, `k₄ = u(x + Δt k₃)`. Through [`LatticeKernels::float_advect_points`], one
/// fused pass over the points on the ndarray backend. Differentiable in the points and the
/// velocity.
///
/// # Errors
/// [`TensorError::InvalidArgument`] when `points` is not `[N, d]`.
pub fn advect_points<B: LatticeKernels>(
    points: &Tensor<B>,
    velocity: &StaggeredGrid<B>,
    dt: f32,
    integrator: Integrator,
) -> Result<Tensor<B>> {
    let shape = points.shape();
    if shape.len() != 2 || shape[1] != velocity.domain().dim() {
        return Err(TensorError::InvalidArgument {
            op: "advect_points",
            shape,
            reason: format!("points must be [N, {}]", velocity.domain().dim()),
        });
    }
    let lattices = staggered_lattices(velocity.domain());
    let components = velocity
        .components()
        .iter()
        .map(|c| Ok(c.reshape(&[c.numel(), 1])?.into_primitive()))
        .collect::<Result<Vec<_>>>()?;
    let moved = B::float_advect_points(
        &lattices,
        &components,
        points.primitive().clone(),
        dt,
        integrator,
    )?;
    Ok(Tensor::from_primitive(moved))
}
