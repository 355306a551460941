//! Integration tests of the training data pipeline of `phi_gns::train`: per-step generators,
//! the window sampler, the trajectory cache and the batch stream, with modules by topic.

#[path = "train_data/cache.rs"]
mod cache;
#[path = "train_data/common.rs"]
mod common;
#[path = "train_data/rng.rs"]
mod rng;
#[path = "train_data/sampler.rs"]
mod sampler;
#[path = "train_data/stream.rs"]
mod stream;
