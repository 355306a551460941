//! phi: differentiable liquid simulation and learned simulators.
//!
//! This facade re-exports the crates of the workspace:
//! - [`phi_core`]: the [`Backend`] trait and its implementations, [`Tensor`], fields and solvers;
//! - [`phi_geom`]: geometries and obstacles;
//! - [`phi_flip`]: the FLIP liquid simulator;
//! - [`phi_gns`]: Graph Network-based Simulators;
//! - [`phi_dataset`]: the FLIP datasets they learn from (generation, merging).

pub mod allocator;
pub mod backends;
pub mod cli;
pub mod dataset;
pub mod demo;
pub mod gns;
pub mod memory;
pub mod optimize;
pub mod output;
pub mod progress;
pub mod simulate;

pub use phi_core;
pub use phi_core::{AutodiffBackend, Backend, IntTensor, Tensor, TensorError};
pub use phi_dataset;
pub use phi_flip;
pub use phi_geom;
pub use phi_gns;

/// The code of `README.md`, compiled and run as doc tests, so the README's example stays true.
#[cfg(all(doctest, feature = "ndarray"))]
#[doc = include_str!("../README.md")]
pub(crate) struct ReadmeExamples;
