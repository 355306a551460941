//! Integration tests of `phi_gns::data`, the dataset format, with modules by topic.

#[path = "data/common.rs"]
mod common;
#[path = "data/dataset.rs"]
mod dataset;
#[path = "data/export.rs"]
mod export;
#[path = "data/stats.rs"]
mod stats;
#[path = "data/trajectory.rs"]
mod trajectory;
