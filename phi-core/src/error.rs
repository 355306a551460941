//! The error type of tensor operations.

use thiserror::Error;

/// What can go wrong in a tensor operation: a shape that does not fit, an index out of range, data
/// of the wrong length, or an error reported by the engine underneath a backend.
///
/// Shape errors name the operation and both shapes, so that the message alone says which call
/// made them.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum TensorError {
    /// Two operands whose shapes do not fit together (broadcasting, matmul, concat, ...).
    #[error("{op}: shapes {lhs:?} and {rhs:?} do not fit: {reason}")]
    ShapeMismatch {
        op: &'static str,
        lhs: Vec<usize>,
        rhs: Vec<usize>,
        reason: String,
    },
    /// A shape or an axis argument that is invalid for the operand.
    #[error("{op}: invalid for a tensor of shape {shape:?}: {reason}")]
    InvalidArgument {
        op: &'static str,
        shape: Vec<usize>,
        reason: String,
    },
    /// An index outside `0..bound` handed to a gather or scatter.
    #[error("{op}: index {index} is out of range for an axis of length {bound}")]
    IndexOutOfRange {
        op: &'static str,
        index: i64,
        bound: usize,
    },
    /// Host data whose length does not match the requested shape.
    #[error("{op}: {got} values do not fill a tensor of shape {shape:?} ({expected} values)")]
    DataLength {
        op: &'static str,
        shape: Vec<usize>,
        expected: usize,
        got: usize,
    },
    /// An operation that needs a one-element tensor (a loss, a scalar read-back) got more.
    #[error("{op}: expected a tensor with one element, got shape {shape:?}")]
    NotScalar { op: &'static str, shape: Vec<usize> },
    /// An error raised by the engine underneath a backend (libtorch, Burn).
    #[error("{backend}: {message}")]
    Backend {
        backend: &'static str,
        message: String,
    },
}

/// Result of a tensor operation.
pub type Result<T, E = TensorError> = std::result::Result<T, E>;
