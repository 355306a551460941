//! Sampling grids at points (grid → particles) and scattering particle values to grids
//! (particles → grid), Φ_Flow's `sample`/`reduce_sample` and `PointCloud.at(grid)`, through the
//! [`LatticeKernels`] on the [`SampleLattice`]s of the grids.

use super::kernels::LatticeKernels;
use crate::backend::Backend;
use crate::error::{Result, TensorError};
use crate::tensor::Tensor;

use super::domain::Domain;
use super::grid::{CenteredGrid, StaggeredGrid};
use super::lattice::{SampleLattice, Transfer, staggered_lattices};
use super::point_cloud::PointCloud;

impl SampleLattice {
    /// `values [samples, c]` (row-major over `shape`) interpolated multilinearly at `points [N, d]`:
    /// `[N, c]`, through the backend's [`LatticeKernels::float_lattice_sample`].
    fn sample<B: LatticeKernels>(
        &self,
        values: &Tensor<B>,
        points: &Tensor<B>,
    ) -> Result<Tensor<B>> {
        let out =
            B::float_lattice_sample(self, values.primitive().clone(), points.primitive().clone())?;
        Ok(Tensor::from_primitive(out))
    }

    /// `(Σ w v [samples, c], Σ w [samples, 1])` of `values [N, c]` at `points [N, d]`, through the
    /// backend's [`LatticeKernels::float_lattice_splat`].
    fn splat<B: LatticeKernels>(
        &self,
        points: &Tensor<B>,
        values: &Tensor<B>,
        transfer: Transfer,
    ) -> Result<(Tensor<B>, Tensor<B>)> {
        let (sums, weights) = B::float_lattice_splat(
            self,
            points.primitive().clone(),
            values.primitive().clone(),
            transfer,
        )?;
        Ok((
            Tensor::from_primitive(sums),
            Tensor::from_primitive(weights),
        ))
    }
}

/// `sums / weights` where `weights > 0`, 0 elsewhere, with a denominator that is never zero (so
/// gradients stay finite).
fn normalise<B: Backend>(sums: &Tensor<B>, weights: &Tensor<B>) -> Tensor<B> {
    let empty = weights.compare_scalar(crate::backend::CompareOp::LessEqual, 0.0);
    sums / (weights + empty)
}

fn check_points<B: Backend>(op: &'static str, domain: &Domain, points: &Tensor<B>) -> Result<()> {
    let shape = points.shape();
    if shape.len() != 2 || shape[1] != domain.dim() {
        return Err(TensorError::InvalidArgument {
            op,
            shape,
            reason: format!(
                "points must be [N, {}] for a {}-d domain",
                domain.dim(),
                domain.dim()
            ),
        });
    }
    Ok(())
}

/// `component` as `[samples, 1]` on `lattice`, the lattice of staggered component `axis`; an
/// error naming `op` where its shape is not the lattice's.
fn component_column<B: Backend>(
    op: &'static str,
    component: &Tensor<B>,
    lattice: &SampleLattice,
    axis: usize,
) -> Result<Tensor<B>> {
    if component.shape() != lattice.shape {
        return Err(TensorError::InvalidArgument {
            op,
            shape: component.shape(),
            reason: format!("component {axis} must have shape {:?}", lattice.shape),
        });
    }
    component.reshape(&[component.numel(), 1])
}

/// One staggered component (or any tensor laid out on the faces of `axis`) sampled at
/// `points [N, d]` by multilinear interpolation of its face samples: `[N]`.
///
/// # Errors
/// [`TensorError::InvalidArgument`] when `points` is not `[N, d]` or the component is not of
/// shape `domain.staggered_shape(axis)`.
pub fn sample_face_component<B: LatticeKernels>(
    component: &Tensor<B>,
    domain: &Domain,
    axis: usize,
    points: &Tensor<B>,
) -> Result<Tensor<B>> {
    check_points("sample_face_component", domain, points)?;
    let lattice = SampleLattice::of(domain, Some(axis));
    let flat = component_column("sample_face_component", component, &lattice, axis)?;
    let n = points.shape()[0];
    lattice.sample(&flat, points)?.reshape(&[n])
}

/// A staggered vector field sampled at `points [N, d]`: component `i` of the result is
/// component `i` of the grid interpolated multilinearly from its `2^d` surrounding faces,
/// `u(x) = Σ_corners Πⱼ (1 − |xⱼ − x_corner,j| / Δxⱼ) u_corner`: `[N, d]`.
///
/// Points beyond the outermost faces are clamped (the value of the nearest boundary sample).
/// Differentiable in the grid values and the positions.
///
/// # Errors
/// [`TensorError::InvalidArgument`] when `points` is not `[N, d]`.
pub fn sample_staggered<B: LatticeKernels>(
    velocity: &StaggeredGrid<B>,
    points: &Tensor<B>,
) -> Result<Tensor<B>> {
    let domain = velocity.domain();
    check_points("sample_staggered", domain, points)?;
    let lattices = staggered_lattices(domain);
    let components = lattices
        .iter()
        .enumerate()
        .map(|(axis, lattice)| {
            let column =
                component_column("sample_staggered", velocity.component(axis), lattice, axis)?;
            Ok(column.into_primitive())
        })
        .collect::<Result<Vec<_>>>()?;
    Ok(Tensor::from_primitive(B::float_lattice_sample_columns(
        &lattices,
        &components,
        points.primitive().clone(),
    )?))
}

/// A centred grid `[res..., c]` sampled at `points [N, d]` by multilinear interpolation of the
/// `2^d` surrounding cell centres: `[N, c]`. Points beyond the outermost cell centres are
/// clamped. Differentiable in the grid values and the positions.
///
/// # Errors
/// [`TensorError::InvalidArgument`] when `points` is not `[N, d]`.
pub fn sample_centered<B: LatticeKernels>(
    grid: &CenteredGrid<B>,
    points: &Tensor<B>,
) -> Result<Tensor<B>> {
    let domain = grid.domain();
    check_points("sample_centered", domain, points)?;
    let lattice = SampleLattice::of(domain, None);
    let flat = grid
        .values()
        .reshape(&[domain.cell_count(), grid.channels()])?;
    lattice.sample(&flat, points)
}

/// Particle velocities `cloud.values() [N, d]` at `cloud.positions() [N, d]` transferred to the
/// faces of `domain`: component `i` of particle velocity goes to the faces of component `i`.
///
/// Returns `(velocity, weights)`: `weights` holds per face the summed transfer weights `Σ w`
/// (tent weights for [`Transfer::Linear`], particle counts for [`Transfer::NearestFace`]), and
/// `velocity = Σ w v / Σ w` there, 0 on faces no particle reaches. The tent weights of one
/// particle sum to 1 per component, so `Σ weights = N` for each component. Positions beyond the
/// outermost faces are clamped onto them. No boundary condition is applied (see
/// [`super::apply_wall_boundaries`]). Differentiable in values and (for `Linear`) positions.
///
/// # Errors
/// [`TensorError::InvalidArgument`] when the cloud's dimension differs from the domain's or the
/// values are not `d` velocity components.
pub fn particles_to_staggered<B: LatticeKernels>(
    cloud: &PointCloud<B>,
    domain: &Domain,
    transfer: Transfer,
) -> Result<(StaggeredGrid<B>, StaggeredGrid<B>)> {
    let d = domain.dim();
    check_points("particles_to_staggered", domain, cloud.positions())?;
    if cloud.channels() != d {
        return Err(TensorError::InvalidArgument {
            op: "particles_to_staggered",
            shape: cloud.values().shape(),
            reason: format!(
                "needs {d}-component velocities [N, {d}], got {} channels",
                cloud.channels()
            ),
        });
    }
    let lattices: Vec<SampleLattice> = (0..d)
        .map(|axis| SampleLattice::of(domain, Some(axis)))
        .collect();
    // Velocity component `axis` onto the faces of `axis`, all components in one backend call.
    let splats = B::float_lattice_splat_columns(
        &lattices,
        cloud.positions().primitive().clone(),
        cloud.values().primitive().clone(),
        transfer,
    )?;
    let mut values = Vec::with_capacity(d);
    let mut weights = Vec::with_capacity(d);
    for (lattice, (sums, weight_sums)) in lattices.iter().zip(splats) {
        let (sums, weight_sums) = (
            Tensor::from_primitive(sums),
            Tensor::from_primitive(weight_sums),
        );
        debug_assert_eq!(sums.shape()[0], lattice.shape.iter().product::<usize>());
        values.push(normalise(&sums, &weight_sums).reshape(&lattice.shape)?);
        weights.push(weight_sums.reshape(&lattice.shape)?);
    }
    Ok((
        StaggeredGrid::new(values, domain.clone())?,
        StaggeredGrid::new(weights, domain.clone())?,
    ))
}

/// Particle values `cloud.values() [N, c]` transferred to the cell centres of `domain`.
///
/// Returns `(values, weights)`, both centred grids: `weights [res..., 1]` is the summed transfer
/// weight per cell (a smooth particle density for [`Transfer::Linear`], the particle count per
/// nearest cell for [`Transfer::NearestFace`]) and `values [res..., c] = Σ w v / Σ w`, 0 in cells
/// no particle reaches. Positions beyond the outermost cell centres are clamped onto them.
///
/// # Errors
/// [`TensorError::InvalidArgument`] when the cloud's dimension differs from the domain's or the
/// cloud has no channels.
pub fn particles_to_centered<B: LatticeKernels>(
    cloud: &PointCloud<B>,
    domain: &Domain,
    transfer: Transfer,
) -> Result<(CenteredGrid<B>, CenteredGrid<B>)> {
    check_points("particles_to_centered", domain, cloud.positions())?;
    let c = cloud.channels();
    if c == 0 {
        return Err(TensorError::InvalidArgument {
            op: "particles_to_centered",
            shape: cloud.values().shape(),
            reason: "the cloud carries no values; use count_particles for occupancy".into(),
        });
    }
    let lattice = SampleLattice::of(domain, None);
    let (sums, weight_sums) = lattice.splat(cloud.positions(), cloud.values(), transfer)?;
    let mut shape = domain.resolution().to_vec();
    shape.push(c);
    let values = normalise(&sums, &weight_sums).reshape(&shape)?;
    *shape.last_mut().expect("a grid has axes") = 1;
    Ok((
        CenteredGrid::new(values, domain.clone())?,
        CenteredGrid::new(weight_sums.reshape(&shape)?, domain.clone())?,
    ))
}

/// The number of `points [N, d]` in each cell (the cell that contains the point; points outside
/// the domain count in the nearest boundary cell): `[res..., 1]`. Not differentiable.
///
/// # Errors
/// [`TensorError::InvalidArgument`] when `points` is not `[N, d]`.
pub fn count_particles<B: Backend>(points: &Tensor<B>, domain: &Domain) -> Result<CenteredGrid<B>> {
    check_points("count_particles", domain, points)?;
    let n = points.shape()[0];
    // The containing cell is the nearest cell centre.
    let stencil = SampleLattice::of(domain, None).nearest_stencil(points)?;
    let device = points.device();
    let counts = Tensor::zeros(&[domain.cell_count(), 1], &device)
        .scatter_add_rows(&stencil.indices, &Tensor::ones(&[n, 1], &device))?;
    let mut shape = domain.resolution().to_vec();
    shape.push(1);
    CenteredGrid::new(counts.reshape(&shape)?, domain.clone())
}

/// The cells holding at least one of `points [N, d]`, as a `0/1` mask `[res..., 1]`
/// (Φ_Flow's FLIP `occupied` mask). Not differentiable.
///
/// # Errors
/// [`TensorError::InvalidArgument`] when `points` is not `[N, d]`.
pub fn occupied_cells<B: Backend>(points: &Tensor<B>, domain: &Domain) -> Result<CenteredGrid<B>> {
    check_points("occupied_cells", domain, points)?;
    occupied_cells_from_host(&points.host_values(), domain, &points.device())
}

/// [`occupied_cells`] of points already on the host, `points` row-major `[N, d]`, as a mask on
/// `device`. Marks the same cells as [`count_particles`] counts: the nearest cell centre, with the
/// same single-precision arithmetic, so both agree on points on a cell's side.
///
/// # Errors
/// [`TensorError::InvalidArgument`] when the length of `points` is not a multiple of `d`.
pub fn occupied_cells_from_host<B: Backend>(
    points: &[f32],
    domain: &Domain,
    device: &B::Device,
) -> Result<CenteredGrid<B>> {
    let lattice = SampleLattice::of(domain, None);
    let d = lattice.dim();
    if !points.len().is_multiple_of(d) {
        return Err(TensorError::InvalidArgument {
            op: "occupied_cells_from_host",
            shape: vec![points.len()],
            reason: format!(
                "{} values are not a whole number of {d}-d points",
                points.len()
            ),
        });
    }
    if i32::try_from(domain.cell_count()).is_err() {
        return Err(TensorError::InvalidArgument {
            op: "occupied_cells_from_host",
            shape: domain.resolution().to_vec(),
            reason: "more cells than 32-bit indices address".into(),
        });
    }
    let mut mask = vec![0.0f32; domain.cell_count()];
    match d {
        1 => mark_nearest_cells::<1>(&lattice, points, &mut mask),
        2 => mark_nearest_cells::<2>(&lattice, points, &mut mask),
        3 => mark_nearest_cells::<3>(&lattice, points, &mut mask),
        _ => unreachable!("domains have one to three dimensions"),
    }
    let mut shape = domain.resolution().to_vec();
    shape.push(1);
    CenteredGrid::new(Tensor::from_vec(mask, &shape, device)?, domain.clone())
}

/// Sets `mask` to 1 at the cell nearest to each of `points [N, D]` (row-major) on the cell-centre
/// `lattice`: [`occupied_cells_from_host`]'s loop, with the axes unrolled and the index arithmetic
/// done for blocks of points in lanes (vectorised; the stores stay scalar).
fn mark_nearest_cells<const D: usize>(lattice: &SampleLattice, points: &[f32], mask: &mut [f32]) {
    const LANES: usize = 16;
    let origin: [f32; D] = std::array::from_fn(|axis| lattice.origin[axis]);
    let inverse: [f32; D] = std::array::from_fn(|axis| 1.0 / lattice.spacing[axis]);
    let upper: [f32; D] = std::array::from_fn(|axis| (lattice.shape[axis] - 1) as f32);
    let last: [i32; D] = std::array::from_fn(|axis| (lattice.shape[axis] - 1) as i32);
    let strides = lattice.strides();
    let strides: [i32; D] = std::array::from_fn(|axis| strides[axis] as i32);
    // As `continuous_indices` and `nearest_stencil`: clamp, round half up, clamp. `max` also
    // maps NaN to 0. The index is then ≥ 0, so truncation is `floor`; a cell index fits `i32`
    // (the caller checks the cell count).
    let nearest = |x: f32, axis: usize| {
        let index = ((x - origin[axis]) * inverse[axis])
            .max(0.0)
            .min(upper[axis]);
        // SAFETY: `index + 0.5` is finite and in `[0.5, shape − 0.5]`, within `i32` (the cell
        // count is checked), so the unchecked conversion is exact truncation; the saturating
        // `as i32` adds fix-ups per lane that keep the loop scalar.
        let whole: i32 = unsafe { (index + 0.5).to_int_unchecked() };
        whole.min(last[axis]) * strides[axis]
    };
    let blocks = points.chunks_exact(D * LANES);
    let rest = blocks.remainder();
    for block in blocks {
        let mut flat = [0i32; LANES];
        for (lane, flat) in flat.iter_mut().enumerate() {
            for axis in 0..D {
                *flat += nearest(block[lane * D + axis], axis);
            }
        }
        for at in flat {
            mask[at as usize] = 1.0;
        }
    }
    for point in rest.chunks_exact(D) {
        let flat: i32 = (0..D).map(|axis| nearest(point[axis], axis)).sum();
        mask[flat as usize] = 1.0;
    }
}

/// The faces whose transfer weight is positive (the `weights` of [`particles_to_staggered`]), as
/// `0/1` masks per component: the faces that received particle data.
///
/// # Errors
/// Only shape errors, which cannot happen for a valid grid.
pub fn valid_faces<B: Backend>(weights: &StaggeredGrid<B>) -> Result<StaggeredGrid<B>> {
    weights.map(|_, w| Ok(w.greater_scalar(0.0)))
}

/// The gradient of the multilinear interpolant of one staggered component (or any tensor laid out
/// on the faces of `axis`) at `points [N, d]`: `[N, d]`, column `j` = `∂u/∂x_j`.
///
/// This is `Σ_corners u_corner ∇w_corner(x)` for the stencil [`sample_face_component`] uses (the
/// same lower corner, clamped indices): along axis `j` the difference of the interpolants on the
/// two sample planes `j = base` and `j = base + 1` that enclose the point, divided by `Δx_j`. On
/// the stencil's cell it is exact for a multilinear field, so a linear field `u(x) = u₀ + a·x`
/// gives `a` everywhere, also within half a cell of the outermost samples where the value is
/// clamped. Along an axis with a single sample it is 0. Differentiable in the component values
/// and in the other coordinates of the points (the gradient of a multilinear interpolant does
/// not depend on the coordinate it is taken along, within a cell).
///
/// # Errors
/// [`TensorError::InvalidArgument`] when `points` is not `[N, d]` or the component is not of
/// shape `domain.staggered_shape(axis)`.
pub fn sample_face_component_gradient<B: LatticeKernels>(
    component: &Tensor<B>,
    domain: &Domain,
    axis: usize,
    points: &Tensor<B>,
) -> Result<Tensor<B>> {
    check_points("sample_face_component_gradient", domain, points)?;
    let lattice = SampleLattice::of(domain, Some(axis));
    let flat = component_column("sample_face_component_gradient", component, &lattice, axis)?;
    let d = lattice.dim();
    let n = points.shape()[0];
    let device = points.device();
    // The stencil's lower corner, as in `linear_stencil`, and its position.
    let highest_base: Vec<f32> = lattice
        .shape
        .iter()
        .map(|&s| s.saturating_sub(2) as f32)
        .collect();
    let highest_base = Tensor::from_vec(highest_base, &[1, d], &device)?;
    let base = lattice
        .continuous_indices(&points.detach())?
        .floor()
        .minimum(&highest_base)?;
    let origin = Tensor::from_slice(&lattice.origin, &[1, d], &device)?;
    let spacing = Tensor::from_slice(&lattice.spacing, &[1, d], &device)?;
    let lower = base * &spacing + &origin;
    let upper = &lower + &spacing;
    // Per differentiated axis, the points moved onto the lower and the upper plane, all sampled
    // in one call: `[2 · axes · N, d]`.
    let axes: Vec<usize> = (0..d).filter(|&j| lattice.shape[j] > 1).collect();
    if axes.is_empty() {
        return Ok(Tensor::zeros(&[n, d], &device));
    }
    let mut moved = Vec::with_capacity(2 * axes.len());
    for &j in &axes {
        let mut one_hot = vec![0.0f32; d];
        one_hot[j] = 1.0;
        let one_hot = Tensor::from_vec(one_hot, &[1, d], &device)?;
        let keep = 1.0 - &one_hot;
        let kept = points * &keep;
        moved.push(&kept + &(&lower * &one_hot));
        moved.push(kept + &(&upper * &one_hot));
    }
    let moved = Tensor::concat(&moved, 0)?;
    let planes = lattice
        .sample(&flat, &moved)?
        .reshape(&[axes.len(), 2, n])?;
    let mut columns = Vec::with_capacity(d);
    for j in 0..d {
        columns.push(match axes.iter().position(|&k| k == j) {
            Some(k) => {
                let pair = planes.narrow(0, k..k + 1)?;
                let difference = pair.narrow(1, 1..2)? - pair.narrow(1, 0..1)?;
                (difference * (1.0 / lattice.spacing[j])).reshape(&[n, 1])?
            }
            None => Tensor::zeros(&[n, 1], &device),
        });
    }
    Tensor::concat(&columns, 1)
}

/// The velocity gradient of a staggered field at `points [N, d]`: `[N, d, d]`, row `a` the
/// gradient of component `a`'s multilinear interpolant ([`sample_face_component_gradient`]),
/// `∂u_a/∂x_j` at `[p, a, j]`. This is APIC's affine matrix `C = B D⁻¹` for multilinear weights
/// (Jiang et al. 2015).
///
/// # Errors
/// [`TensorError::InvalidArgument`] when `points` is not `[N, d]`.
pub fn sample_staggered_gradient<B: LatticeKernels>(
    velocity: &StaggeredGrid<B>,
    points: &Tensor<B>,
) -> Result<Tensor<B>> {
    let domain = velocity.domain();
    check_points("sample_staggered_gradient", domain, points)?;
    let d = domain.dim();
    let n = points.shape()[0];
    let rows = (0..d)
        .map(|axis| {
            sample_face_component_gradient(velocity.component(axis), domain, axis, points)?
                .reshape(&[n, 1, d])
        })
        .collect::<Result<Vec<_>>>()?;
    Tensor::concat(&rows, 1)
}

/// The affine particle → grid transfer of APIC (Jiang et al. 2015): particle velocities
/// `cloud.values() [N, d]` with affine matrices `affine [N, d, d]` (row `a` the velocity gradient
/// of component `a`, as [`sample_staggered_gradient`] gives) at `cloud.positions() [N, d]`. Face
/// `i` of component `a` receives `Σ w (v_a + c_a · (x_i − x_p)) / Σ w`, 0 where no particle
/// reaches; `weights` as in [`particles_to_staggered`], which this equals for `affine = 0`.
///
/// `x_p` is the particle's position clamped onto the faces' lattice, the point the transfer
/// weights and [`sample_staggered`] use, so that an affine field sampled by
/// [`sample_staggered`] and [`sample_staggered_gradient`] comes back exactly on every face a
/// particle reaches. The sums go through the backend's splat, with the extra channels
/// `Σ w (v_a − c_a · (x_p − o))` and `Σ w c_a` (`o` the domain's centre, to keep the
/// cancellation small) and `(x_i − o) · Σ w c_a` added on the grid. Differentiable like
/// [`particles_to_staggered`], and in `affine`.
///
/// # Errors
/// [`TensorError::InvalidArgument`] when the shapes do not fit the domain.
pub fn particles_to_staggered_affine<B: LatticeKernels>(
    cloud: &PointCloud<B>,
    affine: &Tensor<B>,
    domain: &Domain,
    transfer: Transfer,
) -> Result<(StaggeredGrid<B>, StaggeredGrid<B>)> {
    let d = domain.dim();
    let points = cloud.positions();
    check_points("particles_to_staggered_affine", domain, points)?;
    let n = points.shape()[0];
    if cloud.channels() != d || affine.shape() != [n, d, d] {
        return Err(TensorError::InvalidArgument {
            op: "particles_to_staggered_affine",
            shape: affine.shape(),
            reason: format!(
                "needs velocities [N, {d}] and affine matrices [N, {d}, {d}] for {n} particles, \
                 got {:?} and {:?}",
                cloud.values().shape(),
                affine.shape()
            ),
        });
    }
    let device = points.device();
    let centre: Vec<f32> = (0..d)
        .map(|i| 0.5 * (domain.lower()[i] + domain.upper()[i]))
        .collect();
    let centre = Tensor::from_vec(centre, &[1, d], &device)?;
    let mut values = Vec::with_capacity(d);
    let mut weights = Vec::with_capacity(d);
    for axis in 0..d {
        let lattice = SampleLattice::of(domain, Some(axis));
        let samples: usize = lattice.shape.iter().product();
        let lowest = Tensor::from_slice(&lattice.origin, &[1, d], &device)?;
        let highest: Vec<f32> = (0..d)
            .map(|i| {
                lattice.origin[i] + lattice.shape[i].saturating_sub(1) as f32 * lattice.spacing[i]
            })
            .collect();
        let highest = Tensor::from_vec(highest, &[1, d], &device)?;
        let relative = points.maximum(&lowest)?.minimum(&highest)? - &centre;
        let c = affine.narrow(1, axis..axis + 1)?.reshape(&[n, d])?;
        let v = cloud.values().narrow(1, axis..axis + 1)?;
        let shifted = v - (&c * &relative).sum_axis(1)?.reshape(&[n, 1])?;
        let channels = Tensor::concat(&[shifted, c], 1)?;
        let (sums, weight_sums) = lattice.splat(points, &channels, transfer)?;
        let faces =
            super::grid::face_centers::<B>(domain, axis, &device).reshape(&[samples, d])? - &centre;
        let sum = sums.narrow(1, 0..1)?
            + (sums.narrow(1, 1..d + 1)? * &faces)
                .sum_axis(1)?
                .reshape(&[samples, 1])?;
        values.push(normalise(&sum, &weight_sums).reshape(&lattice.shape)?);
        weights.push(weight_sums.reshape(&lattice.shape)?);
    }
    Ok((
        StaggeredGrid::new(values, domain.clone())?,
        StaggeredGrid::new(weights, domain.clone())?,
    ))
}
