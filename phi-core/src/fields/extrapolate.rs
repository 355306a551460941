//! Growing the valid region of a field: Φ_Flow's `extrapolate_valid_values`, used by FLIP to
//! carry the velocities of the liquid a few cells beyond it (thesis fig. 4.1), so that particles
//! at the border of the liquid do not interpolate zeros.

use super::kernels::LatticeKernels;
use crate::backend::{Backend, CompareOp};
use crate::error::{Result, TensorError};
use crate::tensor::Tensor;

use super::grid::{CenteredGrid, StaggeredGrid};
use super::ops::{Ghost, pad_ghosts};

/// The sum over the `3^d` box around each sample of the first `d` axes (zero beyond the edges).
fn box_sum<B: Backend>(t: &Tensor<B>, spatial_dims: usize) -> Result<Tensor<B>> {
    let mut sum = t.clone();
    for axis in 0..spatial_dims {
        let n = sum.shape()[axis];
        let padded = pad_ghosts(&sum, axis, [Ghost::Zero, Ghost::Zero])?;
        sum = padded.narrow(axis, 0..n)?
            + padded.narrow(axis, 1..n + 1)?
            + padded.narrow(axis, 2..n + 2)?;
    }
    Ok(sum)
}

/// Grows the valid region of `values` by `cells` layers: in each of `cells` iterations, every
/// invalid sample with at least one valid sample among its `3^d − 1` neighbours (diagonals
/// included, along the first `spatial_dims` axes) becomes valid and takes the mean of those
/// valid neighbours. Valid samples keep their values; samples still invalid at the end keep
/// theirs. Returns `(values, valid)`.
///
/// `valid` is a `0/1` mask of the shape of `values`, or of `values` with a trailing axis of
/// length 1 (one mask for all channels). Differentiable in `values`.
///
/// # Errors
/// [`TensorError::ShapeMismatch`] when `valid` does not broadcast to `values`;
/// [`TensorError::InvalidArgument`] when `spatial_dims` exceeds the mask's rank.
pub fn extrapolate_valid_tensor<B: LatticeKernels>(
    values: &Tensor<B>,
    valid: &Tensor<B>,
    spatial_dims: usize,
    cells: usize,
) -> Result<(Tensor<B>, Tensor<B>)> {
    let (shape, mask_shape) = (values.shape(), valid.shape());
    let fits = mask_shape.len() == shape.len()
        && mask_shape.len() >= spatial_dims
        && mask_shape[..spatial_dims] == shape[..spatial_dims]
        && mask_shape
            .iter()
            .zip(&shape)
            .skip(spatial_dims)
            .all(|(&m, &v)| m == v || m == 1);
    if !fits {
        return Err(TensorError::ShapeMismatch {
            op: "extrapolate_valid",
            lhs: shape,
            rhs: mask_shape,
            reason: format!(
                "the mask must match the values on the {spatial_dims} spatial axes and broadcast \
                 over the rest"
            ),
        });
    }
    let (values, valid) = B::float_extrapolate_valid(
        values.primitive().clone(),
        valid.primitive().clone(),
        spatial_dims,
        cells,
    )?;
    Ok((
        Tensor::from_primitive(values),
        Tensor::from_primitive(valid),
    ))
}

/// [`LatticeKernels::float_extrapolate_valid`] from tensor operations (the default of every backend;
/// differentiable in `values`).
pub(crate) fn composite_extrapolate_valid<B: Backend>(
    values: B::Float,
    valid: B::Float,
    spatial_dims: usize,
    cells: usize,
) -> Result<(B::Float, B::Float)> {
    let mut values = Tensor::<B>::from_primitive(values);
    let mut valid = Tensor::<B>::from_primitive(valid).compare_scalar(CompareOp::NotEqual, 0.0);
    for _ in 0..cells {
        let neighbour_sum = box_sum(&(&values * &valid), spatial_dims)?;
        let neighbour_count = box_sum(&valid, spatial_dims)?;
        let reached = neighbour_count.greater_scalar(0.0);
        let empty = neighbour_count.compare_scalar(CompareOp::LessEqual, 0.0);
        let mean = neighbour_sum / (&neighbour_count + &empty);
        let newly = &reached - &(&reached * &valid);
        values = Tensor::select(&newly, &mean, &values)?;
        valid = reached;
    }
    Ok((values.into_primitive(), valid.into_primitive()))
}

/// A grid whose valid region can be grown ([`extrapolate_valid`]) and that can be advected
/// ([`super::advect_semi_lagrangian`]).
pub trait GridField<B: LatticeKernels>: Sized {
    /// See [`extrapolate_valid`].
    ///
    /// # Errors
    /// See [`extrapolate_valid`].
    fn extrapolate_valid(&self, valid: &Self, cells: usize) -> Result<(Self, Self)>;

    /// See [`super::advect_semi_lagrangian`].
    ///
    /// # Errors
    /// See [`super::advect_semi_lagrangian`].
    fn advect_semi_lagrangian(&self, velocity: &StaggeredGrid<B>, dt: f32) -> Result<Self>;
}

impl<B: LatticeKernels> GridField<B> for CenteredGrid<B> {
    fn extrapolate_valid(&self, valid: &Self, cells: usize) -> Result<(Self, Self)> {
        self.domain()
            .check_same(valid.domain(), "extrapolate_valid")?;
        let d = self.domain().dim();
        let (values, mask) = extrapolate_valid_tensor(self.values(), valid.values(), d, cells)?;
        Ok((self.with_values(values)?, valid.with_values(mask)?))
    }

    fn advect_semi_lagrangian(&self, velocity: &StaggeredGrid<B>, dt: f32) -> Result<Self> {
        super::advect::advect_centered(self, velocity, dt)
    }
}

impl<B: LatticeKernels> GridField<B> for StaggeredGrid<B> {
    fn extrapolate_valid(&self, valid: &Self, cells: usize) -> Result<(Self, Self)> {
        self.domain()
            .check_same(valid.domain(), "extrapolate_valid")?;
        let d = self.domain().dim();
        let mut values = Vec::with_capacity(d);
        let mut masks = Vec::with_capacity(d);
        for (component, mask) in self.components().iter().zip(valid.components()) {
            let (v, m) = extrapolate_valid_tensor(component, mask, d, cells)?;
            values.push(v);
            masks.push(m);
        }
        Ok((self.with_components(values)?, valid.with_components(masks)?))
    }

    fn advect_semi_lagrangian(&self, velocity: &StaggeredGrid<B>, dt: f32) -> Result<Self> {
        super::advect::advect_staggered(self, velocity, dt)
    }
}

/// Grows the valid region of a grid by `cells` layers, each newly valid sample taking the mean
/// of its valid neighbours (`3^d` box, diagonals included), like Φ_Flow's
/// `extrapolate_valid_values`. For a [`StaggeredGrid`] each component is extrapolated on its own
/// faces with its own mask (thesis fig. 4.1); for a [`CenteredGrid`] the mask is `[res..., 1]`
/// (all channels) or `[res..., c]`. Returns `(values, valid)`; valid samples are untouched.
///
/// # Errors
/// [`TensorError::InvalidArgument`] for grids on different domains,
/// [`TensorError::ShapeMismatch`] for a mask with other channels.
pub fn extrapolate_valid<B: LatticeKernels, G: GridField<B>>(
    field: &G,
    valid: &G,
    cells: usize,
) -> Result<(G, G)> {
    field.extrapolate_valid(valid, cells)
}
