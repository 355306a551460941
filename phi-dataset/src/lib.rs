//! The FLIP datasets of thesis section 5.2 (table 5.1): trajectories of liquid simulated by
//! [`phi_flip`] and written in the format of [`phi_gns::data`], for the Graph Network-based
//! Simulators to learn from.
//!
//! - [`generate`]: draws and simulates the trajectories of a dataset (train and valid: random
//!   scenes from [`RandomSceneParams`](phi_flip::RandomSceneParams); test: the ten hand-made
//!   scenes of `scenes/test/`, or scene files of a folder), in parallel over trajectories,
//!   resumable and shardable, reporting its progress to a callback;
//! - [`merge`]: joins the shard directories of a sharded run into one dataset;
//! - [`manifest`]: what a dataset directory records about how it was made (`generator.json`
//!   and the `generator` entry of `metadata.json`), which resumed, sharded and merged runs are
//!   checked against.
//!
//! The files are those of [`phi_gns::data`]: `DIR/metadata.json` and
//! `DIR/{train,valid,test}/traj_NNNNN.npz`. `phi dataset generate` and `phi dataset merge` are
//! the command-line front ends; the Python module calls the same functions.
//!
//! The crate sits above both `phi-flip` and `phi-gns`, which know nothing of each other: it is
//! where the simulator meets the dataset format.

pub mod generate;
pub mod manifest;
pub mod merge;
mod scenes;
mod split;

use std::path::PathBuf;

pub use generate::{GenerateEvent, GenerateOptions, GenerateSummary, generate};
pub use manifest::{GENERATE_OUTPUTS, GeneratorConfig, MANIFEST, MERGE_OUTPUTS, Manifest, Shard};
pub use merge::{MergeSummary, merge};
pub use phi_gns::data::{splitmix64, trajectory_seed};
pub use scenes::{RawTrajectory, TEST_SCENES, TestScenes, position_scale, simulate_trajectory};
pub use split::Split;

/// What can go wrong while making, merging or checking a dataset: each error names the file or
/// the option and what is wrong.
#[derive(Debug, thiserror::Error)]
pub enum DatasetError {
    /// The options of a run contradict each other or are out of range (the option is named
    /// as the command line spells it: `--force`, `--trajectories`, ...).
    #[error("{0}")]
    Options(String),
    /// A dataset directory holds something this run may not use or replace (another
    /// configuration's dataset, files beyond the count asked for, a foreign folder, ...).
    #[error("{path} {reason}", path = path.display())]
    Directory {
        /// The directory.
        path: PathBuf,
        /// What is wrong, and what to do about it.
        reason: String,
    },
    /// A file's content is not what it must be (a scene file, `generator.json`, ...).
    #[error("{path}: {reason}")]
    Invalid {
        /// The file, as named to the user (`scenes/test/01_tall_drop.toml`).
        path: String,
        /// What is wrong.
        reason: String,
    },
    /// A trajectory failed to simulate or to be written.
    #[error("{split} trajectory {index} (seed {seed})")]
    Trajectory {
        /// Its split.
        split: Split,
        /// Its index in the split.
        index: usize,
        /// The seed it was drawn from.
        seed: u64,
        /// What failed.
        #[source]
        source: Box<DatasetError>,
    },
    /// The bookkeeping of the run would need more memory than the limit allows.
    #[error(
        "{trajectories} trajectories ({asked_by}) needs about {needed} of memory, more than the \
         limit of {limit} (the machine's memory, or PHI_MEMORY_LIMIT)",
        needed = phi_flip::memory::human_bytes(*needed as f64),
        limit = phi_flip::memory::human_bytes(*limit as f64)
    )]
    Memory {
        /// Trajectories asked for (all splits).
        trajectories: u128,
        /// What asked for them: `--trajectories` or the counts of `generator.json`.
        asked_by: &'static str,
        /// Bytes needed.
        needed: u128,
        /// The limit, bytes.
        limit: u64,
    },
    /// The progress callback asked the run to stop; the finished trajectories are kept and a
    /// run of the same options continues from them.
    #[error(
        "stopped on request after writing {written} of {planned} trajectories; run again to \
         continue"
    )]
    Stopped {
        /// Trajectories written before the stop.
        written: usize,
        /// Trajectories this run was to write.
        planned: usize,
    },
    /// The target folder is refused (see [`phi_io::output_dir`]), or clearing it failed
    /// (boxed: the refusals carry the folder's entries).
    #[error(transparent)]
    Output(Box<phi_io::output_dir::OutputDirError>),
    /// A file of the dataset cannot be read, parsed or written.
    #[error(transparent)]
    Data(#[from] phi_gns::data::DataError),
    /// Reading or writing a file failed; the error names it.
    #[error(transparent)]
    File(#[from] phi_io::IoError),
    /// A scene cannot be drawn, built or simulated.
    #[error(transparent)]
    Flip(#[from] phi_flip::FlipError),
    /// A scene's geometry is invalid.
    #[error(transparent)]
    Geometry(#[from] phi_geom::GeomError),
}

impl From<phi_io::output_dir::OutputDirError> for DatasetError {
    fn from(error: phi_io::output_dir::OutputDirError) -> Self {
        DatasetError::Output(Box::new(error))
    }
}

impl DatasetError {
    /// An operating-system error on `path` while doing `action`.
    pub(crate) fn io(path: &std::path::Path, action: &'static str, e: std::io::Error) -> Self {
        DatasetError::File(phi_io::IoError::io(path, action, e))
    }
}

/// The result type of this crate.
pub type Result<T, E = DatasetError> = std::result::Result<T, E>;

#[cfg(test)]
pub(crate) mod test_util {
    use std::path::PathBuf;

    /// A fresh, empty directory under the system's temporary directory for one test.
    pub fn temp_dir(test: &str) -> PathBuf {
        let dir =
            std::env::temp_dir().join(format!("phi-dataset-test-{}-{test}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("create test directory");
        dir
    }
}
