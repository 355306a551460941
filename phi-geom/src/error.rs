//! [`GeomError`], the error type of the geometry crate.

use phi_core::TensorError;
use thiserror::Error;

/// What can go wrong when building, reading or evaluating a geometry.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum GeomError {
    /// Two things that must have one spatial dimension do not: a geometry and the points or domain
    /// it is evaluated on, two members of a union, a geometry and its rotation, pivot or shift.
    #[error(
        "{context}: dimension mismatch: the geometry is {geometry}-dimensional but {other_name} is \
         {other}-dimensional"
    )]
    DimensionMismatch {
        /// The operation or constructor that noticed.
        context: String,
        /// The geometry's dimension.
        geometry: usize,
        /// What the other thing is ("the points", "the domain", "member 2 of the union", ...).
        other_name: String,
        /// The other thing's dimension.
        other: usize,
    },
    /// A field of a geometry (or obstacle) with a value it cannot have.
    #[error("invalid geometry: {field} = {value}: {reason}")]
    InvalidGeometry {
        /// The field, e.g. `box.upper` or `sphere.radius`.
        field: String,
        /// The offending value, as written.
        value: String,
        /// Why it is invalid.
        reason: String,
    },
    /// Points that are not an `[N, d]` tensor.
    #[error("{op}: points must be an [N, d] tensor, got shape {shape:?}")]
    NotPoints {
        /// The operation.
        op: &'static str,
        /// The shape that was passed.
        shape: Vec<usize>,
    },
    /// An argument of an operation outside its range (a supersampling factor of 0, a missing
    /// axis).
    #[error("{op}: {reason}")]
    InvalidArgument {
        /// The operation.
        op: &'static str,
        /// What is wrong.
        reason: String,
    },
    /// A tensor operation failed underneath.
    #[error(transparent)]
    Tensor(#[from] TensorError),
}

impl GeomError {
    pub(crate) fn invalid(
        field: impl Into<String>,
        value: impl std::fmt::Debug,
        reason: impl Into<String>,
    ) -> Self {
        GeomError::InvalidGeometry {
            field: field.into(),
            value: format!("{value:?}"),
            reason: reason.into(),
        }
    }

    pub(crate) fn dims(
        context: impl Into<String>,
        geometry: usize,
        other_name: impl Into<String>,
        other: usize,
    ) -> Self {
        GeomError::DimensionMismatch {
            context: context.into(),
            geometry,
            other_name: other_name.into(),
            other,
        }
    }
}

/// Result of a geometry operation.
pub type Result<T, E = GeomError> = std::result::Result<T, E>;
