//! Integration tests of `phi_gns::model`, `phi_gns::rollout` and `phi_gns::eval`, with modules
//! by topic. Every backend is checked against `reference.rs`, an f64 forward pass of the
//! documented layout written on the host, and against a PyTorch implementation through a
//! committed fixture.

#[path = "model/batching.rs"]
mod batching;
#[path = "model/bounds.rs"]
mod bounds;
#[path = "model/common.rs"]
mod common;
#[path = "model/conformance.rs"]
mod conformance;
#[path = "model/eval.rs"]
mod eval;
#[path = "model/files.rs"]
mod files;
#[path = "model/floors.rs"]
mod floors;
#[path = "model/gradients.rs"]
mod gradients;
#[path = "model/kernels.rs"]
mod kernels;
#[path = "model/multistep.rs"]
mod multistep;
#[path = "model/optimise.rs"]
mod optimise;
#[path = "model/pytorch.rs"]
mod pytorch;
#[path = "model/reference.rs"]
mod reference;
#[path = "model/rollout.rs"]
mod rollout;
#[path = "model/training.rs"]
mod training;
