//! Graph Network-based Simulators trained on FLIP datasets.
//!
//! - [`data`]: the on-disk dataset format (trajectories, statistics, `metadata.json`), its
//!   readers and writers, and conversion to and from DeepMind's TFRecord format.
//! - [`graph`]: the radius graph of the GNS (every particle pair within the connectivity radius,
//!   self-edges included), batched with node offsets.
//! - [`model`]: the network (features, encode-process-decode, integration), its parameters and
//!   its model files, generic over the backend through [`model::GnsKernels`].
//! - [`train`]: the random-walk input noise, the one-step, multi-step and pushforward losses,
//!   and Adam.
//! - [`rollout`]: a model run forward from ground-truth frames, kinematic particles following the
//!   ground truth.
//! - [`eval`]: the thesis's metrics (MSE-acc 1, MSE 20, MSE 400, EMD) and more, per trajectory
//!   and per model.

pub mod data;
pub mod eval;
pub mod graph;
pub mod model;
pub mod rollout;
pub mod train;

// The helpers of the data tests (tests/data), shared with the unit tests; they name the crate
// `phi_gns`.
#[cfg(test)]
extern crate self as phi_gns;
#[cfg(test)]
#[allow(dead_code)]
#[path = "../tests/data/common.rs"]
mod test_data;
