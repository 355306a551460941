//! [`IntTensor`]: `i64` tensors for indices.

use std::ops::{Add, Mul, Range, Sub};

use super::shape::{broadcast_shapes, check_axis, numel};
use super::{Tensor, check_length, full_ranges};
use crate::backend::{Backend, IntBinaryOp, ReduceOp};
use crate::error::{Result, TensorError};

/// An `i64` tensor on backend `B`, used for indices. Nothing on it is differentiable.
#[derive(Debug, Clone)]
pub struct IntTensor<B: Backend> {
    primitive: B::Int,
}

impl<B: Backend> IntTensor<B> {
    /// Wraps a backend tensor.
    pub fn from_primitive(primitive: B::Int) -> Self {
        Self { primitive }
    }

    /// The backend tensor.
    pub fn primitive(&self) -> &B::Int {
        &self.primitive
    }

    /// The shape.
    pub fn shape(&self) -> Vec<usize> {
        B::int_shape(&self.primitive)
    }

    /// The number of elements.
    pub fn numel(&self) -> usize {
        numel(&self.shape())
    }

    /// The device the tensor lives on.
    pub fn device(&self) -> B::Device {
        B::int_device(&self.primitive)
    }

    /// A copy on `device`.
    pub fn to_device(&self, device: &B::Device) -> Self {
        Self::from_primitive(B::int_to_device(self.primitive.clone(), device))
    }

    /// A tensor of `shape` holding `data` in row-major order.
    ///
    /// # Errors
    /// [`TensorError::DataLength`] when `data` does not have exactly one value per element.
    pub fn from_vec(data: Vec<i64>, shape: &[usize], device: &B::Device) -> Result<Self> {
        check_length("IntTensor::from_vec", data.len(), shape)?;
        Ok(Self::from_primitive(B::int_from_vec(data, shape, device)))
    }

    /// `[0, 1, ..., n-1]`.
    pub fn arange(n: usize, device: &B::Device) -> Self {
        Self::from_primitive(B::int_arange(n, device))
    }

    /// The values in row-major order, copied to the host.
    pub fn to_vec(&self) -> Vec<i64> {
        B::int_to_vec(&self.primitive)
    }

    /// The values as floats.
    pub fn to_float(&self) -> Tensor<B> {
        Tensor::from_primitive(B::int_to_float(self.primitive.clone()))
    }

    /// The same elements under `shape`.
    ///
    /// # Errors
    /// [`TensorError::InvalidArgument`] when the element counts differ.
    pub fn reshape(&self, shape: &[usize]) -> Result<Self> {
        let own = self.shape();
        if numel(&own) != numel(shape) {
            return Err(TensorError::InvalidArgument {
                op: "IntTensor::reshape",
                shape: own,
                reason: format!(
                    "cannot hold the {} elements of shape {shape:?}",
                    numel(shape)
                ),
            });
        }
        Ok(Self::from_primitive(B::int_reshape(
            self.primitive.clone(),
            shape,
        )))
    }

    /// The block given by one range per leading axis; later axes are kept whole.
    ///
    /// # Errors
    /// [`TensorError::InvalidArgument`] for a range that does not fit.
    pub fn slice(&self, ranges: &[Range<usize>]) -> Result<Self> {
        let full = full_ranges("IntTensor::slice", &self.shape(), ranges)?;
        Ok(Self::from_primitive(B::int_slice(
            self.primitive.clone(),
            &full,
        )))
    }

    /// The tensors joined along `axis`.
    ///
    /// # Errors
    /// [`TensorError::InvalidArgument`] for an empty list or a missing axis,
    /// [`TensorError::ShapeMismatch`] when the shapes differ off `axis`.
    pub fn concat(tensors: &[IntTensor<B>], axis: usize) -> Result<Self> {
        let first = tensors
            .first()
            .ok_or_else(|| TensorError::InvalidArgument {
                op: "IntTensor::concat",
                shape: vec![],
                reason: "needs at least one tensor".into(),
            })?;
        let reference = first.shape();
        check_axis("IntTensor::concat", &reference, axis)?;
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
                    op: "IntTensor::concat",
                    lhs: reference,
                    rhs: shape,
                    reason: format!("the shapes must agree on every axis but {axis}"),
                });
            }
        }
        let primitives = tensors.iter().map(|t| t.primitive.clone()).collect();
        Ok(Self::from_primitive(B::int_concat(primitives, axis)))
    }

    /// `op(self, other)` element by element, broadcasting.
    ///
    /// # Errors
    /// [`TensorError::ShapeMismatch`] when the shapes do not broadcast.
    pub fn binary(&self, op: IntBinaryOp, other: &IntTensor<B>) -> Result<Self> {
        broadcast_shapes("IntTensor::binary", &self.shape(), &other.shape())?;
        Ok(Self::from_primitive(B::int_binary(
            op,
            self.primitive.clone(),
            other.primitive.clone(),
        )))
    }

    /// `op(self, scalar)` element by element.
    ///
    /// # Panics
    /// On a zero divisor for `FloorDiv` or `Rem`, a programming error.
    pub fn binary_scalar(&self, op: IntBinaryOp, scalar: i64) -> Self {
        assert!(
            scalar != 0 || !matches!(op, IntBinaryOp::FloorDiv | IntBinaryOp::Rem),
            "IntTensor::{op:?} by zero"
        );
        Self::from_primitive(B::int_binary_scalar(op, self.primitive.clone(), scalar))
    }

    /// Every element limited to `[min, max]`.
    pub fn clamp(&self, min: i64, max: i64) -> Self {
        assert!(min <= max, "IntTensor::clamp: min {min} is not ≤ max {max}");
        Self::from_primitive(B::int_clamp(self.primitive.clone(), min, max))
    }

    /// `op` over `axis`, which is kept with length 1.
    ///
    /// # Errors
    /// [`TensorError::InvalidArgument`] for a missing axis, or `Max`/`Min` over an empty axis.
    pub fn reduce_axis(&self, op: ReduceOp, axis: usize) -> Result<Self> {
        let shape = self.shape();
        check_axis("IntTensor::reduce_axis", &shape, axis)?;
        if matches!(op, ReduceOp::Max | ReduceOp::Min) && shape[axis] == 0 {
            return Err(TensorError::InvalidArgument {
                op: "IntTensor::reduce_axis",
                shape,
                reason: format!("{op:?} over the empty axis {axis}"),
            });
        }
        Ok(Self::from_primitive(B::int_reduce_axis(
            op,
            self.primitive.clone(),
            axis,
        )))
    }

    /// Rows picked by `indices`.
    ///
    /// # Errors
    /// [`TensorError::IndexOutOfRange`] for an index outside the first axis.
    pub fn gather_rows(&self, indices: &IntTensor<B>) -> Result<Self> {
        super::check_row_indices("IntTensor::gather_rows", &self.shape(), &indices.shape())?;
        B::int_gather_rows(self.primitive.clone(), indices.primitive.clone())
            .map(Self::from_primitive)
    }
}

macro_rules! int_operator {
    ($trait:ident, $method:ident, $op:expr) => {
        impl<B: Backend> $trait<&IntTensor<B>> for &IntTensor<B> {
            type Output = IntTensor<B>;
            #[track_caller]
            fn $method(self, rhs: &IntTensor<B>) -> IntTensor<B> {
                self.binary($op, rhs).unwrap_or_else(|e| panic!("{e}"))
            }
        }
        impl<B: Backend> $trait<i64> for &IntTensor<B> {
            type Output = IntTensor<B>;
            fn $method(self, rhs: i64) -> IntTensor<B> {
                self.binary_scalar($op, rhs)
            }
        }
    };
}

int_operator!(Add, add, IntBinaryOp::Add);
int_operator!(Sub, sub, IntBinaryOp::Sub);
int_operator!(Mul, mul, IntBinaryOp::Mul);
