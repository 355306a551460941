//! The core of phi: the [`backend::Backend`] trait that lists every primitive operation, its
//! implementations (ndarray, Burn, tch), and [`tensor::Tensor`], the value type that code above
//! is written in.

pub mod backend;
pub mod error;
pub mod fields;
pub mod host;
pub mod point_sets;
pub mod solve;
pub mod tensor;

pub use backend::{AutodiffBackend, Backend};
pub use error::{Result, TensorError};
pub use tensor::{IntTensor, Tensor};
