//! [`Tensor`] and [`IntTensor`]: value types over a backend's tensors with shape checks and
//! operator overloading, so that code above reads like the maths.
//!
//! Every method checks its arguments' shapes before the backend sees them; a misfit is a
//! [`TensorError`] naming the operation and both shapes. The arithmetic operators (`+ - * /`,
//! unary `-`) cannot return a `Result`; on a shape misfit they panic with the same message,
//! located at the caller. Use [`Tensor::binary`] where the shapes come from user input.
//!
//! ```
//! # #[cfg(feature = "ndarray")] {
//! use phi_core::backend::ndarray::NdArray;
//! use phi_core::tensor::Tensor;
//!
//! let device = Default::default();
//! let x = Tensor::<NdArray>::from_vec(vec![1.0, 2.0, 3.0, 4.0], &[2, 2], &device).unwrap();
//! let y = &x * 2.0 + 1.0;
//! assert_eq!(y.to_vec(), vec![3.0, 5.0, 7.0, 9.0]);
//! assert_eq!(y.sum().to_scalar().unwrap(), 24.0);
//! # }
//! ```

mod int;
mod ops;
pub mod shape;

use std::ops::Range;

pub use int::IntTensor;

use crate::backend::{AutodiffBackend, Backend, BinaryOp, CompareOp, PadMode, ReduceOp, UnaryOp};
use crate::error::{Result, TensorError};
use crate::solve::{SolveError, SolveOptions, SolveStats, SparseMatrix};
use shape::{broadcast_shapes, broadcasts_to, check_axis, matmul_shape, numel};

/// An `f32` tensor on backend `B`.
#[derive(Debug, Clone)]
pub struct Tensor<B: Backend> {
    primitive: B::Float,
}

impl<B: Backend> Tensor<B> {
    /// Wraps a backend tensor.
    pub fn from_primitive(primitive: B::Float) -> Self {
        Self { primitive }
    }

    /// The backend tensor.
    pub fn primitive(&self) -> &B::Float {
        &self.primitive
    }

    /// The backend tensor, by value.
    pub fn into_primitive(self) -> B::Float {
        self.primitive
    }

    /// The shape.
    pub fn shape(&self) -> Vec<usize> {
        B::float_shape(&self.primitive)
    }

    /// The number of axes.
    pub fn rank(&self) -> usize {
        self.shape().len()
    }

    /// The number of elements.
    pub fn numel(&self) -> usize {
        numel(&self.shape())
    }

    /// The device the tensor lives on.
    pub fn device(&self) -> B::Device {
        B::float_device(&self.primitive)
    }

    /// A copy on `device`. Differentiable.
    pub fn to_device(&self, device: &B::Device) -> Self {
        Self::from_primitive(B::float_to_device(self.primitive.clone(), device))
    }

    // ------------------------------------------------------------------------------ creation

    /// A tensor of `shape` holding `data` in row-major order.
    ///
    /// # Errors
    /// [`TensorError::DataLength`] when `data` does not have exactly one value per element.
    pub fn from_vec(data: Vec<f32>, shape: &[usize], device: &B::Device) -> Result<Self> {
        check_length("from_vec", data.len(), shape)?;
        Ok(Self::from_primitive(B::float_from_vec(data, shape, device)))
    }

    /// A tensor of `shape` holding a copy of `data` in row-major order.
    ///
    /// # Errors
    /// [`TensorError::DataLength`] when `data` does not have exactly one value per element.
    pub fn from_slice(data: &[f32], shape: &[usize], device: &B::Device) -> Result<Self> {
        Self::from_vec(data.to_vec(), shape, device)
    }

    /// A one-element tensor of shape `[1]`.
    pub fn scalar(value: f32, device: &B::Device) -> Self {
        Self::full(&[1], value, device)
    }

    /// A tensor of `shape` with every element `value`.
    pub fn full(shape: &[usize], value: f32, device: &B::Device) -> Self {
        Self::from_primitive(B::float_full(shape, value, device))
    }

    /// A tensor of `shape` filled with zeros.
    pub fn zeros(shape: &[usize], device: &B::Device) -> Self {
        Self::from_primitive(B::float_zeros(shape, device))
    }

    /// A tensor of `shape` filled with ones.
    pub fn ones(shape: &[usize], device: &B::Device) -> Self {
        Self::full(shape, 1.0, device)
    }

    /// A tensor of zeros with the shape and device of `self`.
    pub fn zeros_like(&self) -> Self {
        Self::zeros(&self.shape(), &self.device())
    }

    /// `[0, 1, ..., n-1]` as floats.
    pub fn arange(n: usize, device: &B::Device) -> Self {
        IntTensor::<B>::arange(n, device).to_float()
    }

    /// Uniform random values in `[low, high)`, the same for one `seed` on every backend.
    pub fn random_uniform(
        shape: &[usize],
        low: f32,
        high: f32,
        seed: u64,
        device: &B::Device,
    ) -> Self {
        Self::from_primitive(B::float_random_uniform(shape, low, high, seed, device))
    }

    /// Normal random values, the same for one `seed` on every backend.
    pub fn random_normal(
        shape: &[usize],
        mean: f32,
        std: f32,
        seed: u64,
        device: &B::Device,
    ) -> Self {
        Self::from_primitive(B::float_random_normal(shape, mean, std, seed, device))
    }

    /// The values in row-major order, copied to the host.
    pub fn to_vec(&self) -> Vec<f32> {
        B::float_to_vec(&self.primitive)
    }

    /// The values in row-major order on the host, without a copy where the backend keeps them
    /// there (ndarray): for reading, where [`Tensor::to_vec`] would copy.
    pub fn host_values(&self) -> std::borrow::Cow<'_, [f32]> {
        B::float_host_values(&self.primitive)
    }

    /// The value of a one-element tensor.
    ///
    /// # Errors
    /// [`TensorError::NotScalar`] when the tensor has another number of elements.
    pub fn to_scalar(&self) -> Result<f32> {
        let shape = self.shape();
        if numel(&shape) != 1 {
            return Err(TensorError::NotScalar {
                op: "to_scalar",
                shape,
            });
        }
        Ok(self.to_vec()[0])
    }

    // ------------------------------------------------------------------------------ shape

    /// The same elements under `shape`.
    ///
    /// # Errors
    /// [`TensorError::InvalidArgument`] when the element counts differ.
    pub fn reshape(&self, shape: &[usize]) -> Result<Self> {
        let own = self.shape();
        if numel(&own) != numel(shape) {
            return Err(TensorError::InvalidArgument {
                op: "reshape",
                shape: own,
                reason: format!(
                    "cannot hold the {} elements of shape {shape:?}",
                    numel(shape)
                ),
            });
        }
        Ok(Self::from_primitive(B::float_reshape(
            self.primitive.clone(),
            shape,
        )))
    }

    /// All elements as one axis.
    pub fn flatten(&self) -> Self {
        Self::from_primitive(B::float_reshape(self.primitive.clone(), &[self.numel()]))
    }

    /// A new axis of length 1 at `axis` (`0..=rank`).
    ///
    /// # Errors
    /// [`TensorError::InvalidArgument`] when `axis > rank`.
    pub fn unsqueeze(&self, axis: usize) -> Result<Self> {
        let mut shape = self.shape();
        if axis > shape.len() {
            return Err(TensorError::InvalidArgument {
                op: "unsqueeze",
                shape,
                reason: format!("cannot insert an axis at position {axis}"),
            });
        }
        shape.insert(axis, 1);
        self.reshape(&shape)
    }

    /// `axis`, of length 1, removed.
    ///
    /// # Errors
    /// [`TensorError::InvalidArgument`] when the axis does not exist, does not have length 1,
    /// or is the only axis.
    pub fn squeeze(&self, axis: usize) -> Result<Self> {
        let mut shape = self.shape();
        check_axis("squeeze", &shape, axis)?;
        if shape[axis] != 1 || shape.len() == 1 {
            return Err(TensorError::InvalidArgument {
                op: "squeeze",
                shape,
                reason: format!("axis {axis} is not a removable axis of length 1"),
            });
        }
        shape.remove(axis);
        self.reshape(&shape)
    }

    /// Axes reordered: output axis `i` is input axis `axes[i]`.
    ///
    /// # Errors
    /// [`TensorError::InvalidArgument`] when `axes` is not a permutation of `0..rank`.
    pub fn permute(&self, axes: &[usize]) -> Result<Self> {
        let shape = self.shape();
        let mut seen = vec![false; shape.len()];
        let valid = axes.len() == shape.len()
            && axes
                .iter()
                .all(|&a| a < seen.len() && !std::mem::replace(&mut seen[a], true));
        if !valid {
            return Err(TensorError::InvalidArgument {
                op: "permute",
                shape,
                reason: format!("{axes:?} is not a permutation of the axes"),
            });
        }
        Ok(Self::from_primitive(B::float_permute(
            self.primitive.clone(),
            axes,
        )))
    }

    /// The last two axes swapped.
    ///
    /// # Errors
    /// [`TensorError::InvalidArgument`] for a tensor with fewer than two axes.
    pub fn transpose(&self) -> Result<Self> {
        let rank = self.rank();
        if rank < 2 {
            return Err(TensorError::InvalidArgument {
                op: "transpose",
                shape: self.shape(),
                reason: "needs at least two axes".into(),
            });
        }
        let mut axes: Vec<usize> = (0..rank).collect();
        axes.swap(rank - 2, rank - 1);
        self.permute(&axes)
    }

    /// The block given by one range per leading axis; axes without a range are kept whole.
    ///
    /// # Errors
    /// [`TensorError::InvalidArgument`] for more ranges than axes, or a range that is inverted
    /// or reaches past its axis.
    pub fn slice(&self, ranges: &[Range<usize>]) -> Result<Self> {
        let full = full_ranges("slice", &self.shape(), ranges)?;
        Ok(Self::from_primitive(B::float_slice(
            self.primitive.clone(),
            &full,
        )))
    }

    /// The elements `range` along `axis`, everything along the other axes.
    ///
    /// # Errors
    /// [`TensorError::InvalidArgument`] for a missing axis or a range outside it.
    pub fn narrow(&self, axis: usize, range: Range<usize>) -> Result<Self> {
        let shape = self.shape();
        check_axis("narrow", &shape, axis)?;
        let mut ranges: Vec<Range<usize>> = shape.iter().map(|&n| 0..n).collect();
        ranges[axis] = range;
        self.slice(&ranges)
    }

    /// The tensors joined along `axis`.
    ///
    /// # Errors
    /// [`TensorError::InvalidArgument`] for an empty list or a missing axis,
    /// [`TensorError::ShapeMismatch`] when the shapes differ off `axis`.
    pub fn concat(tensors: &[Tensor<B>], axis: usize) -> Result<Self> {
        let first = tensors
            .first()
            .ok_or_else(|| TensorError::InvalidArgument {
                op: "concat",
                shape: vec![],
                reason: "needs at least one tensor".into(),
            })?;
        let reference = first.shape();
        check_axis("concat", &reference, axis)?;
        for t in &tensors[1..] {
            let shape = t.shape();
            let fits = shape.len() == reference.len()
                && shape
                    .iter()
                    .zip(&reference)
                    .enumerate()
                    .all(|(i, (a, b))| i == axis || a == b);
            if !fits {
                return Err(TensorError::ShapeMismatch {
                    op: "concat",
                    lhs: reference,
                    rhs: shape,
                    reason: format!("the shapes must agree on every axis but {axis}"),
                });
            }
        }
        let primitives = tensors.iter().map(|t| t.primitive.clone()).collect();
        Ok(Self::from_primitive(B::float_concat(primitives, axis)))
    }

    /// The tensors, all of one shape, joined along a new axis at `axis`.
    ///
    /// # Errors
    /// [`TensorError::InvalidArgument`] for an empty list or `axis > rank`,
    /// [`TensorError::ShapeMismatch`] when the shapes differ.
    pub fn stack(tensors: &[Tensor<B>], axis: usize) -> Result<Self> {
        let first = tensors
            .first()
            .ok_or_else(|| TensorError::InvalidArgument {
                op: "stack",
                shape: vec![],
                reason: "needs at least one tensor".into(),
            })?;
        let reference = first.shape();
        if axis > reference.len() {
            return Err(TensorError::InvalidArgument {
                op: "stack",
                shape: reference,
                reason: format!("cannot insert an axis at position {axis}"),
            });
        }
        for t in &tensors[1..] {
            let shape = t.shape();
            if shape != reference {
                return Err(TensorError::ShapeMismatch {
                    op: "stack",
                    lhs: reference,
                    rhs: shape,
                    reason: "stacked tensors must have one shape".into(),
                });
            }
        }
        let primitives = tensors.iter().map(|t| t.primitive.clone()).collect();
        Ok(Self::from_primitive(B::float_stack(primitives, axis)))
    }

    /// Widened by `widths[axis] = (before, after)` cells per axis (missing axes are not padded),
    /// filled according to `mode`.
    ///
    /// # Errors
    /// [`TensorError::InvalidArgument`] for more widths than axes, or a periodic or symmetric
    /// width longer than its axis.
    pub fn pad(&self, widths: &[(usize, usize)], mode: PadMode) -> Result<Self> {
        let shape = self.shape();
        if widths.len() > shape.len() {
            return Err(TensorError::InvalidArgument {
                op: "pad",
                shape,
                reason: format!("{} widths for {} axes", widths.len(), self.rank()),
            });
        }
        if matches!(mode, PadMode::Periodic | PadMode::Symmetric) {
            for (axis, &(before, after)) in widths.iter().enumerate() {
                if before.max(after) > shape[axis] {
                    return Err(TensorError::InvalidArgument {
                        op: "pad",
                        shape,
                        reason: format!(
                            "{mode:?} padding of ({before}, {after}) is wider than axis {axis}"
                        ),
                    });
                }
            }
        }
        if matches!(mode, PadMode::Edge) {
            for (axis, &(before, after)) in widths.iter().enumerate() {
                if shape[axis] == 0 && before + after > 0 {
                    return Err(TensorError::InvalidArgument {
                        op: "pad",
                        shape,
                        reason: format!("an empty axis {axis} has no edge to repeat"),
                    });
                }
            }
        }
        let mut all = widths.to_vec();
        all.resize(shape.len(), (0, 0));
        Ok(Self::from_primitive(B::float_pad(
            self.primitive.clone(),
            &all,
            mode,
        )))
    }

    /// Repeated to `shape` by NumPy broadcasting.
    ///
    /// # Errors
    /// [`TensorError::ShapeMismatch`] when the shape does not broadcast to `shape`.
    pub fn broadcast_to(&self, shape: &[usize]) -> Result<Self> {
        let own = self.shape();
        if !broadcasts_to(&own, shape) {
            return Err(TensorError::ShapeMismatch {
                op: "broadcast_to",
                lhs: own,
                rhs: shape.to_vec(),
                reason: "every axis must be equal or of length 1".into(),
            });
        }
        Ok(Self::from_primitive(B::float_broadcast_to(
            self.primitive.clone(),
            shape,
        )))
    }

    // ------------------------------------------------------------------------------ element-wise

    /// `op(self)` element by element.
    pub fn unary(&self, op: UnaryOp) -> Self {
        Self::from_primitive(B::float_unary(op, self.primitive.clone()))
    }

    /// `op(self, other)` element by element, broadcasting.
    ///
    /// # Errors
    /// [`TensorError::ShapeMismatch`] when the shapes do not broadcast.
    pub fn binary(&self, op: BinaryOp, other: &Tensor<B>) -> Result<Self> {
        broadcast_shapes(binary_name(op), &self.shape(), &other.shape())?;
        Ok(Self::from_primitive(B::float_binary(
            op,
            self.primitive.clone(),
            other.primitive.clone(),
        )))
    }

    /// `op(self, scalar)` element by element.
    pub fn binary_scalar(&self, op: BinaryOp, scalar: f32) -> Self {
        Self::from_primitive(B::float_binary_scalar(op, self.primitive.clone(), scalar))
    }

    /// `√x`
    pub fn sqrt(&self) -> Self {
        self.unary(UnaryOp::Sqrt)
    }
    /// `eˣ`
    pub fn exp(&self) -> Self {
        self.unary(UnaryOp::Exp)
    }
    /// `ln x`
    pub fn log(&self) -> Self {
        self.unary(UnaryOp::Log)
    }
    /// `|x|`
    pub fn abs(&self) -> Self {
        self.unary(UnaryOp::Abs)
    }
    /// `sin x`
    pub fn sin(&self) -> Self {
        self.unary(UnaryOp::Sin)
    }
    /// `cos x`
    pub fn cos(&self) -> Self {
        self.unary(UnaryOp::Cos)
    }
    /// `tanh x`
    pub fn tanh(&self) -> Self {
        self.unary(UnaryOp::Tanh)
    }
    /// `⌊x⌋`
    pub fn floor(&self) -> Self {
        self.unary(UnaryOp::Floor)
    }
    /// `sign x`
    pub fn sign(&self) -> Self {
        self.unary(UnaryOp::Sign)
    }
    /// `max(x, 0)`
    pub fn relu(&self) -> Self {
        self.unary(UnaryOp::Relu)
    }
    /// `1 / x`
    pub fn recip(&self) -> Self {
        self.unary(UnaryOp::Recip)
    }
    /// `xᵖ` for a scalar exponent.
    pub fn powf(&self, exponent: f32) -> Self {
        self.binary_scalar(BinaryOp::Pow, exponent)
    }
    /// `x²`
    pub fn square(&self) -> Self {
        self * self
    }

    /// `selfᵒᵗʰᵉʳ`, broadcasting.
    ///
    /// # Errors
    /// [`TensorError::ShapeMismatch`] when the shapes do not broadcast.
    pub fn pow(&self, other: &Tensor<B>) -> Result<Self> {
        self.binary(BinaryOp::Pow, other)
    }

    /// `min(self, other)`, broadcasting.
    ///
    /// # Errors
    /// [`TensorError::ShapeMismatch`] when the shapes do not broadcast.
    pub fn minimum(&self, other: &Tensor<B>) -> Result<Self> {
        self.binary(BinaryOp::Min, other)
    }

    /// `max(self, other)`, broadcasting.
    ///
    /// # Errors
    /// [`TensorError::ShapeMismatch`] when the shapes do not broadcast.
    pub fn maximum(&self, other: &Tensor<B>) -> Result<Self> {
        self.binary(BinaryOp::Max, other)
    }

    /// `atan2(self, other)`, broadcasting.
    ///
    /// # Errors
    /// [`TensorError::ShapeMismatch`] when the shapes do not broadcast.
    pub fn atan2(&self, other: &Tensor<B>) -> Result<Self> {
        self.binary(BinaryOp::Atan2, other)
    }

    /// Every element limited to `[min, max]`.
    ///
    /// # Panics
    /// When `min > max` or either is NaN: that is a programming error, not a data error.
    pub fn clamp(&self, min: f32, max: f32) -> Self {
        assert!(min <= max, "clamp: min {min} is not ≤ max {max}");
        Self::from_primitive(B::float_clamp(self.primitive.clone(), min, max))
    }

    /// The same values with no gradient flowing through.
    pub fn detach(&self) -> Self {
        Self::from_primitive(B::float_detach(self.primitive.clone()))
    }

    // ------------------------------------------------------------------------ comparisons

    /// `op(self, other)` as a `0/1` mask, broadcasting.
    ///
    /// # Errors
    /// [`TensorError::ShapeMismatch`] when the shapes do not broadcast.
    pub fn compare(&self, op: CompareOp, other: &Tensor<B>) -> Result<Self> {
        broadcast_shapes("compare", &self.shape(), &other.shape())?;
        Ok(Self::from_primitive(B::float_compare(
            op,
            self.primitive.clone(),
            other.primitive.clone(),
        )))
    }

    /// `op(self, scalar)` as a `0/1` mask.
    pub fn compare_scalar(&self, op: CompareOp, scalar: f32) -> Self {
        Self::from_primitive(B::float_compare_scalar(op, self.primitive.clone(), scalar))
    }

    /// `self > scalar` as a `0/1` mask.
    pub fn greater_scalar(&self, scalar: f32) -> Self {
        self.compare_scalar(CompareOp::Greater, scalar)
    }

    /// `self < scalar` as a `0/1` mask.
    pub fn less_scalar(&self, scalar: f32) -> Self {
        self.compare_scalar(CompareOp::Less, scalar)
    }

    /// `if mask ≠ 0 { on_true } else { on_false }`, broadcasting all three.
    ///
    /// # Errors
    /// [`TensorError::ShapeMismatch`] when the shapes do not broadcast.
    pub fn select(mask: &Tensor<B>, on_true: &Tensor<B>, on_false: &Tensor<B>) -> Result<Self> {
        let values = broadcast_shapes("select", &on_true.shape(), &on_false.shape())?;
        broadcast_shapes("select", &mask.shape(), &values)?;
        Ok(Self::from_primitive(B::float_where(
            mask.primitive.clone(),
            on_true.primitive.clone(),
            on_false.primitive.clone(),
        )))
    }

    // ------------------------------------------------------------------------ reductions

    /// The sum of all elements, shape `[1]`.
    pub fn sum(&self) -> Self {
        Self::from_primitive(B::float_reduce(ReduceOp::Sum, self.primitive.clone()))
    }

    /// The mean of all elements, shape `[1]` (NaN when empty).
    pub fn mean(&self) -> Self {
        Self::from_primitive(B::float_reduce(ReduceOp::Mean, self.primitive.clone()))
    }

    /// `op` over all elements, shape `[1]`.
    ///
    /// # Errors
    /// [`TensorError::InvalidArgument`] for `Max` or `Min` of an empty tensor.
    pub fn reduce(&self, op: ReduceOp) -> Result<Self> {
        if matches!(op, ReduceOp::Max | ReduceOp::Min) && self.numel() == 0 {
            return Err(TensorError::InvalidArgument {
                op: "reduce",
                shape: self.shape(),
                reason: format!("{op:?} of no elements"),
            });
        }
        Ok(Self::from_primitive(B::float_reduce(
            op,
            self.primitive.clone(),
        )))
    }

    /// `op` over `axis`; the axis is kept with length 1 when `keep_axis`, removed otherwise
    /// (unless it is the only one).
    ///
    /// # Errors
    /// [`TensorError::InvalidArgument`] for a missing axis, or `Max`/`Min` over an empty axis.
    pub fn reduce_axis(&self, op: ReduceOp, axis: usize, keep_axis: bool) -> Result<Self> {
        let shape = self.shape();
        check_axis("reduce_axis", &shape, axis)?;
        if matches!(op, ReduceOp::Max | ReduceOp::Min) && shape[axis] == 0 {
            return Err(TensorError::InvalidArgument {
                op: "reduce_axis",
                shape,
                reason: format!("{op:?} over the empty axis {axis}"),
            });
        }
        let reduced = Self::from_primitive(B::float_reduce_axis(op, self.primitive.clone(), axis));
        if keep_axis || shape.len() == 1 {
            Ok(reduced)
        } else {
            reduced.squeeze(axis)
        }
    }

    /// The sum over `axis`, which is removed.
    ///
    /// # Errors
    /// [`TensorError::InvalidArgument`] for a missing axis.
    pub fn sum_axis(&self, axis: usize) -> Result<Self> {
        self.reduce_axis(ReduceOp::Sum, axis, false)
    }

    /// The mean over `axis`, which is removed.
    ///
    /// # Errors
    /// [`TensorError::InvalidArgument`] for a missing axis.
    pub fn mean_axis(&self, axis: usize) -> Result<Self> {
        self.reduce_axis(ReduceOp::Mean, axis, false)
    }

    // ------------------------------------------------------------------------ matmul

    /// Batched matrix product `[..., m, k] × [..., k, n] → [..., m, n]`, broadcasting the batch
    /// axes.
    ///
    /// # Errors
    /// [`TensorError::ShapeMismatch`] when the inner dimensions or the batch axes do not fit.
    pub fn matmul(&self, other: &Tensor<B>) -> Result<Self> {
        let (lhs_shape, rhs_shape) = (self.shape(), other.shape());
        let (batch, _) = matmul_shape(&lhs_shape, &rhs_shape)?;
        let expand = |t: &Tensor<B>, shape: &[usize]| -> Tensor<B> {
            let mut target = batch.clone();
            target.extend_from_slice(&shape[shape.len() - 2..]);
            if target == shape {
                t.clone()
            } else {
                Self::from_primitive(B::float_broadcast_to(t.primitive.clone(), &target))
            }
        };
        let (lhs, rhs) = (expand(self, &lhs_shape), expand(other, &rhs_shape));
        Ok(Self::from_primitive(B::float_matmul(
            lhs.primitive,
            rhs.primitive,
        )))
    }

    // ------------------------------------------------------------------------ gather, scatter

    /// Rows picked by `indices` (`[n, ...] × [m] → [m, ...]`).
    ///
    /// # Errors
    /// [`TensorError::InvalidArgument`] for a rank-0 shape or indices that are not one axis;
    /// [`TensorError::IndexOutOfRange`] for an index outside `0..n`.
    pub fn gather_rows(&self, indices: &IntTensor<B>) -> Result<Self> {
        check_row_indices("gather_rows", &self.shape(), &indices.shape())?;
        B::float_gather_rows(self.primitive.clone(), indices.primitive().clone())
            .map(Self::from_primitive)
    }

    /// `self` plus `values` added to the rows named by `indices`; repeated indices accumulate.
    ///
    /// # Errors
    /// [`TensorError::ShapeMismatch`] when `values` is not `[m, rest...]` for `m` indices;
    /// [`TensorError::IndexOutOfRange`] for an index outside `0..n`.
    pub fn scatter_add_rows(&self, indices: &IntTensor<B>, values: &Tensor<B>) -> Result<Self> {
        let (shape, index_shape, value_shape) = (self.shape(), indices.shape(), values.shape());
        check_row_indices("scatter_add_rows", &shape, &index_shape)?;
        let mut expected = index_shape.clone();
        expected.extend_from_slice(&shape[1..]);
        if value_shape != expected {
            return Err(TensorError::ShapeMismatch {
                op: "scatter_add_rows",
                lhs: shape,
                rhs: value_shape,
                reason: format!(
                    "values must have shape {expected:?} for {} indices",
                    index_shape[0]
                ),
            });
        }
        B::float_scatter_add_rows(
            self.primitive.clone(),
            indices.primitive().clone(),
            values.primitive.clone(),
        )
        .map(Self::from_primitive)
    }

    /// Elements picked by multi-indices `[m, k]` into the first `k` axes: `[m, rest...]`.
    ///
    /// # Errors
    /// [`TensorError::InvalidArgument`] when `indices` is not `[m, k]` with `1 ≤ k ≤ rank`;
    /// [`TensorError::IndexOutOfRange`] for an index outside its axis.
    pub fn gather_nd(&self, indices: &IntTensor<B>) -> Result<Self> {
        check_nd_indices("gather_nd", &self.shape(), &indices.shape())?;
        B::float_gather_nd(self.primitive.clone(), indices.primitive().clone())
            .map(Self::from_primitive)
    }

    /// `self` plus `values [m, rest...]` added at multi-indices `[m, k]`; repeated indices
    /// accumulate.
    ///
    /// # Errors
    /// As [`Tensor::gather_nd`], and [`TensorError::ShapeMismatch`] for misshapen `values`.
    pub fn scatter_add_nd(&self, indices: &IntTensor<B>, values: &Tensor<B>) -> Result<Self> {
        let (shape, index_shape, value_shape) = (self.shape(), indices.shape(), values.shape());
        check_nd_indices("scatter_add_nd", &shape, &index_shape)?;
        let mut expected = vec![index_shape[0]];
        expected.extend_from_slice(&shape[index_shape[1]..]);
        if value_shape != expected {
            return Err(TensorError::ShapeMismatch {
                op: "scatter_add_nd",
                lhs: shape,
                rhs: value_shape,
                reason: format!("values must have shape {expected:?}"),
            });
        }
        B::float_scatter_add_nd(
            self.primitive.clone(),
            indices.primitive().clone(),
            values.primitive.clone(),
        )
        .map(Self::from_primitive)
    }

    // ------------------------------------------------------------------------ casts

    /// Rounded toward zero to integers.
    pub fn to_int(&self) -> IntTensor<B> {
        IntTensor::from_primitive(B::float_to_int(self.primitive.clone()))
    }
}

impl<B: Backend> Tensor<B> {
    /// The solution `x` of `matrix · x = self` for a right-hand side `self` of shape `[n]` or
    /// `[n, k]` (`k` right-hand sides), with `n = matrix.nrows()`, and what the solve did. See
    /// [`Backend::float_linear_solve`]: differentiable in `self` on the autodiff backends through
    /// one adjoint solve; the matrix is a constant.
    ///
    /// # Errors
    /// [`SolveError::Tensor`] wrapping [`TensorError::InvalidArgument`] for a rank other than 1
    /// or 2, [`SolveError::DimensionMismatch`] when the matrix is not square or `n` does not fit;
    /// otherwise those of the solve ([`SolveError::NotConverged`], [`SolveError::NonFinite`],
    /// ...).
    pub fn linear_solve(
        &self,
        matrix: &std::sync::Arc<SparseMatrix>,
        options: &SolveOptions,
    ) -> std::result::Result<(Self, SolveStats), SolveError> {
        let shape = self.shape();
        if shape.is_empty() || shape.len() > 2 {
            return Err(TensorError::InvalidArgument {
                op: "linear_solve",
                shape,
                reason: "the right-hand side must be [n] or [n, k]".into(),
            }
            .into());
        }
        if matrix.nrows() != matrix.ncols() {
            return Err(SolveError::DimensionMismatch {
                what: "linear_solve: columns of the (square) matrix".into(),
                expected: matrix.nrows(),
                got: matrix.ncols(),
            });
        }
        if shape[0] != matrix.nrows() {
            return Err(SolveError::DimensionMismatch {
                what: format!("linear_solve: rows of the right-hand side of shape {shape:?}"),
                expected: matrix.nrows(),
                got: shape[0],
            });
        }
        let (x, stats) = B::float_linear_solve(matrix.clone(), self.primitive.clone(), options)?;
        Ok((Self::from_primitive(x), stats))
    }
}

impl<B: AutodiffBackend> Tensor<B> {
    /// A leaf with the values of `self` whose gradient is tracked (a parameter).
    pub fn require_grad(&self) -> Self {
        Self::from_primitive(B::float_require_grad(self.primitive.clone()))
    }

    /// Whether gradients are tracked through `self`.
    pub fn is_tracked(&self) -> bool {
        B::float_is_tracked(&self.primitive)
    }

    /// `∂self/∂t` for each `t` in `wrt`, where `self` is a one-element loss. Tensors `self` does
    /// not depend on get zeros. Consumes the graph behind `self`.
    ///
    /// # Errors
    /// [`TensorError::NotScalar`] when `self` has more than one element;
    /// [`TensorError::Backend`] when the engine refuses.
    pub fn gradients(&self, wrt: &[&Tensor<B>]) -> Result<Vec<Tensor<B>>> {
        let shape = self.shape();
        if numel(&shape) != 1 {
            return Err(TensorError::NotScalar {
                op: "gradients",
                shape,
            });
        }
        let primitives: Vec<&B::Float> = wrt.iter().map(|t| &t.primitive).collect();
        Ok(B::gradients(&self.primitive, &primitives)?
            .into_iter()
            .map(Self::from_primitive)
            .collect())
    }
}

/// Checks that `data` fills `shape`.
fn check_length(op: &'static str, got: usize, shape: &[usize]) -> Result<()> {
    let expected = numel(shape);
    if got == expected {
        Ok(())
    } else {
        Err(TensorError::DataLength {
            op,
            shape: shape.to_vec(),
            expected,
            got,
        })
    }
}

/// One range per axis: those given, then whole axes.
fn full_ranges(
    op: &'static str,
    shape: &[usize],
    ranges: &[Range<usize>],
) -> Result<Vec<Range<usize>>> {
    if ranges.len() > shape.len() {
        return Err(TensorError::InvalidArgument {
            op,
            shape: shape.to_vec(),
            reason: format!("{} ranges for {} axes", ranges.len(), shape.len()),
        });
    }
    for (axis, range) in ranges.iter().enumerate() {
        if range.start > range.end || range.end > shape[axis] {
            return Err(TensorError::InvalidArgument {
                op,
                shape: shape.to_vec(),
                reason: format!(
                    "range {range:?} does not fit axis {axis} of length {}",
                    shape[axis]
                ),
            });
        }
    }
    let mut full = ranges.to_vec();
    full.extend(shape[ranges.len()..].iter().map(|&n| 0..n));
    Ok(full)
}

fn check_row_indices(op: &'static str, shape: &[usize], index_shape: &[usize]) -> Result<()> {
    if shape.is_empty() || index_shape.len() != 1 {
        return Err(TensorError::ShapeMismatch {
            op,
            lhs: shape.to_vec(),
            rhs: index_shape.to_vec(),
            reason: "needs a tensor with at least one axis and indices with exactly one".into(),
        });
    }
    Ok(())
}

fn check_nd_indices(op: &'static str, shape: &[usize], index_shape: &[usize]) -> Result<()> {
    if index_shape.len() != 2 || index_shape[1] == 0 || index_shape[1] > shape.len() {
        return Err(TensorError::ShapeMismatch {
            op,
            lhs: shape.to_vec(),
            rhs: index_shape.to_vec(),
            reason: "indices must be [m, k] with 1 ≤ k ≤ the tensor's rank".into(),
        });
    }
    Ok(())
}

/// The name of a binary operation in error messages.
fn binary_name(op: BinaryOp) -> &'static str {
    match op {
        BinaryOp::Add => "add",
        BinaryOp::Sub => "sub",
        BinaryOp::Mul => "mul",
        BinaryOp::Div => "div",
        BinaryOp::Pow => "pow",
        BinaryOp::Min => "minimum",
        BinaryOp::Max => "maximum",
        BinaryOp::Atan2 => "atan2",
    }
}
