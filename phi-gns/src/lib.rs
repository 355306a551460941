//! Graph Network-based Simulators trained on FLIP datasets.
//!
//! - [`data`]: the on-disk dataset format (trajectories, statistics, `metadata.json`), its
//!   readers and writers, and conversion to and from DeepMind's TFRecord format.

pub mod data;
