//! Growing the valid region of a field: Φ_Flow's `extrapolate_valid_values`, used by FLIP to
//! carry the velocities of the liquid a few cells beyond it (thesis fig. 4.1), so that particles
//! at the border of the liquid do not interpolate zeros.

use super::kernels::LatticeKernels;
use crate::error::{Result, TensorError};
use crate::tensor::Tensor;

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
