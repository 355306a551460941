//! Tests of the training data pipeline of [`crate::train`]: per-step generators,
//! the window sampler, the trajectory cache and the batch stream, with modules by topic.

mod cache;
mod common;
mod rng;
mod sampler;
mod stream;
