//! `phi dataset ...` and `phi render`: the FLIP dataset of thesis section 5.2 (table 5.1).
//!
//! Generation and merging live in [`phi_dataset`] (re-exported here), which the Python module
//! calls too; the commands parse their arguments, call it and report ([`cli`], [`generate`]).
//! Here besides:
//! - [`compare`]: two datasets of the same scenes measured against each other as `phi eval`
//!   measures a rollout (the spread of the simulator itself);
//! - [`stats`]: particle counts and the neighbour-count distribution over time (thesis fig. 5.4);
//! - [`render`]: a GIF of one trajectory;
//! - [`export`]: the dataset for numpy, DeepMind's TFRecord reader, geoelements/gns and
//!   LagrangeBench.
//!
//! The files are those of [`phi_gns::data`]: `DIR/metadata.json` and
//! `DIR/{train,valid,test}/traj_NNNNN.npz`. `docs/datasets.md` describes the format and the
//! commands.

pub mod cli;
pub mod compare;
pub mod export;
pub mod generate;
pub mod render;
pub mod stats;

pub use phi_dataset::{
    GenerateEvent, GenerateOptions, GenerateSummary, MergeSummary, RawTrajectory, Split,
    TEST_SCENES, TestScenes, manifest, merge, position_scale, simulate_trajectory, splitmix64,
    trajectory_seed,
};
