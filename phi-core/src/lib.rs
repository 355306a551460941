//! The core of phi: the [`backend::Backend`] trait that lists every primitive operation, its
//! implementations (ndarray, Burn, tch), and [`tensor::Tensor`], the value type that code above
//! is written in.
//!
//! The modules are layers; each imports only those below it:
//! [`point_sets`] (distances between point sets) and [`fields`] (grids, operators, the pressure
//! projection and their fused kernels, [`fields::LatticeKernels`]) over [`tensor`] over
//! [`backend`] over [`solve`] (sparse matrices and solvers on host data) over [`host`] and
//! [`error`].

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
