//! Finite-difference operators on grids: divergence, gradient, Laplacian, curl and the
//! conversions between centred and staggered vector fields.
//!
//! Every operator is a stencil of [`Tensor::narrow`]s and one [`Tensor::concat`] of ghost cells
//! per axis; the ghost cells come from the [`Domain`](super::Domain)'s boundaries (Φ_Flow 2's extrapolations):
//!
//! | quantity | [`Boundary::Closed`] (free-slip wall) | [`Boundary::Open`] |
//! |---|---|---|
//! | scalar (pressure, density) | zero gradient (Neumann) | zero outside (Dirichlet, `p = 0`) |
//! | normal velocity on a wall face | 0 | zero gradient |
//! | tangential velocity | zero gradient (free slip) | zero gradient |

use crate::backend::Backend;
use crate::error::{Result, TensorError};
use crate::tensor::Tensor;

use super::domain::Boundary;
use super::grid::{CenteredGrid, StaggeredGrid};

/// How a ghost cell beyond one side of an axis is filled.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Ghost {
    /// Zero.
    Zero,
    /// The edge value repeated (zero gradient).
    Edge,
}

impl Ghost {
    /// The ghost of a scalar: zero gradient at a closed wall, zero outside an open side.
    pub(crate) fn scalar(boundary: Boundary) -> Self {
        match boundary {
            Boundary::Closed => Ghost::Edge,
            Boundary::Open => Ghost::Zero,
        }
    }
}

/// `t` with one ghost cell before and after it along `axis`.
pub(crate) fn pad_ghosts<B: Backend>(
    t: &Tensor<B>,
    axis: usize,
    ghosts: [Ghost; 2],
) -> Result<Tensor<B>> {
    let n = t.shape()[axis];
    let ghost = |kind: Ghost, at: usize| -> Result<Tensor<B>> {
        match kind {
            Ghost::Edge => t.narrow(axis, at..at + 1),
            Ghost::Zero => {
                let mut shape = t.shape();
                shape[axis] = 1;
                Ok(Tensor::zeros(&shape, &t.device()))
            }
        }
    };
    Tensor::concat(
        &[ghost(ghosts[0], 0)?, t.clone(), ghost(ghosts[1], n - 1)?],
        axis,
    )
}

/// Forward difference along `axis`: `t[k+1] - t[k]`, one sample shorter.
pub(crate) fn diff<B: Backend>(t: &Tensor<B>, axis: usize) -> Result<Tensor<B>> {
    let n = t.shape()[axis];
    Ok(t.narrow(axis, 1..n)? - t.narrow(axis, 0..n - 1)?)
}

/// Mean of neighbours along `axis`: `(t[k] + t[k+1]) / 2`, one sample shorter.
pub(crate) fn mean_neighbours<B: Backend>(t: &Tensor<B>, axis: usize) -> Result<Tensor<B>> {
    let n = t.shape()[axis];
    Ok((t.narrow(axis, 0..n - 1)? + t.narrow(axis, 1..n)?) * 0.5)
}

/// The normal-velocity ghost rule: wall faces of closed sides are set to zero.
fn zero_closed_wall_faces<B: Backend>(
    component: &Tensor<B>,
    axis: usize,
    boundaries: [Boundary; 2],
) -> Result<Tensor<B>> {
    if boundaries == [Boundary::Open; 2] {
        return Ok(component.clone());
    }
    let n = component.shape()[axis];
    let mut mask = vec![1.0f32; n];
    if boundaries[0] == Boundary::Closed {
        mask[0] = 0.0;
    }
    if boundaries[1] == Boundary::Closed {
        mask[n - 1] = 0.0;
    }
    let rank = component.rank();
    let mut mask_shape = vec![1; rank];
    mask_shape[axis] = n;
    let mask = Tensor::from_vec(mask, &mask_shape, &component.device())?;
    Ok(component * mask)
}

/// The velocity with the no-through-flow condition of closed walls applied: the normal
/// component on every face that lies on a [`Boundary::Closed`] side is set to 0
/// (`u · n = 0`); everything else is kept.
///
/// # Errors
/// Only shape errors, which cannot happen for a valid grid.
pub fn apply_wall_boundaries<B: Backend>(velocity: &StaggeredGrid<B>) -> Result<StaggeredGrid<B>> {
    let boundaries = velocity.domain().boundaries().to_vec();
    velocity.map(|axis, c| zero_closed_wall_faces(c, axis, boundaries[axis]))
}

/// Divergence of a staggered vector field, `∇·u = Σᵢ (uᵢ[k+1] − uᵢ[k]) / Δxᵢ`, at the cell
/// centres: a 1-channel [`CenteredGrid`] `[res..., 1]`.
///
/// The faces on the domain's sides enter with the values the grid holds (apply
/// [`apply_wall_boundaries`] first to impose `u · n = 0` on closed walls), so this is the exact
/// discrete flux balance of each cell. Exact for fields linear in each coordinate.
///
/// # Errors
/// Only shape errors, which cannot happen for a valid grid.
pub fn divergence<B: Backend>(velocity: &StaggeredGrid<B>) -> Result<CenteredGrid<B>> {
    let domain = velocity.domain();
    let dx = domain.cell_size();
    let mut total: Option<Tensor<B>> = None;
    for (axis, component) in velocity.components().iter().enumerate() {
        let term = diff(component, axis)? * (1.0 / dx[axis]);
        total = Some(match total {
            None => term,
            Some(t) => t + term,
        });
    }
    let total = total.expect("a domain has at least one axis");
    let mut shape = domain.resolution().to_vec();
    shape.push(1);
    CenteredGrid::new(total.reshape(&shape)?, domain.clone())
}

/// Gradient of a scalar field at the faces, `(∇p)ᵢ[k] = (p[k] − p[k−1]) / Δxᵢ`: a
/// [`StaggeredGrid`] whose component `i` has shape `staggered_shape(i)`.
///
/// Ghost cells from the domain's boundaries: on a closed side the ghost repeats the edge cell
/// (zero gradient), so the wall face gets exactly 0; on an open side the ghost is 0 (`p = 0`
/// outside), so the wall face gets `± p_edge / Δx`. Exact for quadratics at interior faces
/// (central difference).
///
/// # Errors
/// [`TensorError::InvalidArgument`] when the grid has more than one channel.
pub fn gradient<B: Backend>(scalar: &CenteredGrid<B>) -> Result<StaggeredGrid<B>> {
    let domain = scalar.domain();
    let p = scalar.scalar_values("gradient")?;
    let dx = domain.cell_size();
    let components = (0..domain.dim())
        .map(|axis| {
            let [lo, hi] = domain.boundaries()[axis];
            let padded = pad_ghosts(&p, axis, [Ghost::scalar(lo), Ghost::scalar(hi)])?;
            Ok(diff(&padded, axis)? * (1.0 / dx[axis]))
        })
        .collect::<Result<Vec<_>>>()?;
    StaggeredGrid::new(components, domain.clone())
}

/// Laplacian at the cell centres, `Δf = Σᵢ (f[k+1] − 2 f[k] + f[k−1]) / Δxᵢ²`, for every
/// channel of a [`CenteredGrid`] `[res..., c]` (same shape out).
///
/// Ghost cells as for scalars: zero gradient beyond a closed side, zero beyond an open one.
/// Second-order accurate where the stencil stays inside the domain (and at closed walls for
/// fields with zero normal derivative there).
///
/// # Errors
/// Only shape errors, which cannot happen for a valid grid.
pub fn laplace<B: Backend>(field: &CenteredGrid<B>) -> Result<CenteredGrid<B>> {
    let domain = field.domain();
    let f = field.values();
    let dx = domain.cell_size();
    let mut total: Option<Tensor<B>> = None;
    for (axis, (&[lo, hi], h)) in domain.boundaries().iter().zip(&dx).enumerate() {
        let padded = pad_ghosts(f, axis, [Ghost::scalar(lo), Ghost::scalar(hi)])?;
        let second = diff(&diff(&padded, axis)?, axis)? * (1.0 / (h * h));
        total = Some(match total {
            None => second,
            Some(t) => t + second,
        });
    }
    field.with_values(total.expect("a domain has at least one axis"))
}

/// `∂u_c/∂x_b` at the edges (corners in 2D) where the faces of component `c` meet along axis
/// `b`: the tangential component `u_c` gets one zero-gradient ghost (free slip) on each side of
/// axis `b`, then a forward difference. Shape: the staggered shape of `c` with one more sample
/// along `b`.
fn edge_derivative<B: Backend>(
    velocity: &StaggeredGrid<B>,
    c: usize,
    b: usize,
) -> Result<Tensor<B>> {
    let dx = velocity.domain().cell_size();
    let padded = pad_ghosts(velocity.component(c), b, [Ghost::Edge, Ghost::Edge])?;
    Ok(diff(&padded, b)? * (1.0 / dx[b]))
}

/// Curl of a staggered velocity at the cell centres.
///
/// - 2D: the scalar vorticity `ω = ∂v/∂x − ∂u/∂y`, a 1-channel grid `[nx, ny, 1]`.
/// - 3D: the vector `ω = ∇ × u = (∂w/∂y − ∂v/∂z, ∂u/∂z − ∂w/∂x, ∂v/∂x − ∂u/∂y)`, a 3-channel
///   grid `[nx, ny, nz, 3]`.
///
/// Each term is a compact difference at the cell corners (2D) or edges (3D), where the
/// staggered samples meet, averaged to the centres. Tangential velocities get zero-gradient
/// ghosts (free slip), so cells touching the domain's sides see a one-sided estimate; interior
/// cells are exact for velocities linear in each coordinate (a solid rotation gives `2Ω`).
///
/// # Errors
/// [`TensorError::InvalidArgument`] for a 1-d domain.
pub fn curl<B: Backend>(velocity: &StaggeredGrid<B>) -> Result<CenteredGrid<B>> {
    let domain = velocity.domain();
    // ω_a = ∂u_c/∂x_b − ∂u_b/∂x_c, on the b-c edges, averaged along b and c to the centres.
    let term = |b: usize, c: usize| -> Result<Tensor<B>> {
        let edges = edge_derivative(velocity, c, b)? - edge_derivative(velocity, b, c)?;
        mean_neighbours(&mean_neighbours(&edges, b)?, c)
    };
    let mut shape = domain.resolution().to_vec();
    match domain.dim() {
        2 => {
            shape.push(1);
            CenteredGrid::new(term(0, 1)?.reshape(&shape)?, domain.clone())
        }
        3 => {
            let omega = [term(1, 2)?, term(2, 0)?, term(0, 1)?];
            CenteredGrid::new(Tensor::stack(&omega, 3)?, domain.clone())
        }
        d => Err(TensorError::InvalidArgument {
            op: "curl",
            shape: domain.resolution().to_vec(),
            reason: format!("the curl is defined in 2 and 3 dimensions, not {d}"),
        }),
    }
}

/// A staggered vector field averaged to the cell centres, `u_c = (uᵢ[k] + uᵢ[k+1]) / 2` per
/// component: a `d`-channel [`CenteredGrid`] `[res..., d]`. Exact for linear fields.
///
/// # Errors
/// Only shape errors, which cannot happen for a valid grid.
pub fn staggered_to_centered<B: Backend>(velocity: &StaggeredGrid<B>) -> Result<CenteredGrid<B>> {
    let domain = velocity.domain();
    let centred = velocity
        .components()
        .iter()
        .enumerate()
        .map(|(axis, c)| mean_neighbours(c, axis))
        .collect::<Result<Vec<_>>>()?;
    CenteredGrid::new(Tensor::stack(&centred, domain.dim())?, domain.clone())
}

/// A centred vector field `[res..., d]` interpolated to the faces,
/// `uᵢ[k] = (uᵢ,c[k−1] + uᵢ,c[k]) / 2`: a [`StaggeredGrid`].
///
/// Faces on the domain's sides: 0 on a closed wall (`u · n = 0`), the edge cell's value on an
/// open side (zero gradient). Exact for linear fields at interior faces.
///
/// # Errors
/// [`TensorError::InvalidArgument`] when the grid does not have `d` channels.
pub fn centered_to_staggered<B: Backend>(field: &CenteredGrid<B>) -> Result<StaggeredGrid<B>> {
    let domain = field.domain();
    let d = domain.dim();
    if field.channels() != d {
        return Err(TensorError::InvalidArgument {
            op: "centered_to_staggered",
            shape: field.values().shape(),
            reason: format!(
                "needs a vector field with {d} channels, got {}",
                field.channels()
            ),
        });
    }
    let components = (0..d)
        .map(|axis| {
            let channel = field
                .values()
                .narrow(d, axis..axis + 1)?
                .reshape(domain.resolution())?;
            let padded = pad_ghosts(&channel, axis, [Ghost::Edge, Ghost::Edge])?;
            let faces = mean_neighbours(&padded, axis)?;
            zero_closed_wall_faces(&faces, axis, domain.boundaries()[axis])
        })
        .collect::<Result<Vec<_>>>()?;
    StaggeredGrid::new(components, domain.clone())
}
