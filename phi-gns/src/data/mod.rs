//! FLIP datasets for Graph Network-based Simulators (thesis section 5.2): the on-disk format, its
//! statistics, conversion to and from DeepMind's `learning_to_simulate` TFRecords, and exports
//! for geoelements/gns and LagrangeBench ([`export`]).
//!
//! # Layout
//!
//! A dataset is a directory:
//!
//! ```text
//! dataset/
//!   metadata.json          Metadata: DeepMind's keys + ours (format, splits, seeds, ...)
//!   train/traj_00000.npz   one file per trajectory, index order, 5 digits (more if needed)
//!   train/traj_00001.npz
//!   valid/traj_00000.npz
//!   test/...
//! ```
//!
//! Each trajectory file is a NumPy `.npz` archive with STORED (uncompressed) entries, so that
//! `np.load` reads it and a loader can stream one trajectory at a time; the ZIP CRC-32 of every
//! entry is checked on read, so truncation and damage are errors naming the file. Members:
//!
//! | member | dtype | shape | meaning |
//! |---|---|---|---|
//! | `position` | f32 | `[frames, n, dim]` | stored positions, `frames = sequence_length + 1` (401) |
//! | `particle_type` | i64 | `[n]` | [`OBSTACLE`] = 0 (static), [`LIQUID`] = 1 |
//! | `stats_velocity` | f64 | `[3, dim]` | rows count, mean, M2 of this trajectory's velocities |
//! | `stats_acceleration` | f64 | `[3, dim]` | the same for accelerations |
//! | `seed` | i64 | `[1]` | the generator's seed (a `u64` stored bit for bit) |
//! | `index` | i64 | `[1]` | the trajectory's index in its split |
//!
//! The stored `index` must be the file's index, and in a split that `metadata.json` lists under
//! `seeds` the stored seed must be [`trajectory_seed`]`(seeds[split], index)`: a file moved to
//! another split or index, or copied from another dataset, is refused on reading.
//!
//! Stored positions are `x_stored = x_cells * position_scale + position_offset` (1/40 and 0.1 for
//! the thesis' 32×32-cell domain, which maps it onto `[0.1, 0.9]²`, DeepMind's `bounds`).
//!
//! # Statistics
//!
//! As DeepMind's `learning_to_simulate` (and the thesis code) define them: velocity
//! `v_t = p_{t+1} − p_t` and acceleration `a_t = p_{t+1} − 2 p_t + p_{t−1}` of the *stored*
//! positions (not divided by `dt`), per component, over liquid particles only, all frames of all
//! trajectories of the split. They are accumulated in f64 with Welford's online algorithm
//! ([`Moments`]), and shards combine exactly with Chan et al.'s parallel update
//! ([`Moments::merge`]), so merging per-trajectory statistics (stored in each file) gives the
//! one-pass result without reading positions again. `metadata.json` holds the population
//! standard deviation `sqrt(M2 / count)`.
//!
//! # Particle types
//!
//! Ours: 0 = obstacle or boundary particle (static), 1 = liquid; the liquid comes first in the
//! generator's files but nothing here relies on it. DeepMind's (in TFRecords): 3 =
//! `KINEMATIC_PARTICLE_ID`, 5 = water; [`tfrecord`] maps between them.
//!
//! # Example
//!
//! ```
//! use phi_gns::data::{LIQUID, OBSTACLE, Trajectory, TrajectoryStats, read_trajectory,
//!     write_trajectory, trajectory_file_name};
//! # let dir = std::env::temp_dir().join(format!("phi-gns-doc-data-{}", std::process::id()));
//! # std::fs::create_dir_all(&dir).unwrap();
//! // Two frames of one liquid and one obstacle particle in 2D.
//! let position = vec![0.5, 0.5, 0.2, 0.2, /* frame 1: */ 0.5, 0.49, 0.2, 0.2];
//! let traj = Trajectory::new(2, position, vec![LIQUID, OBSTACLE], 42, 0)?;
//! let stats = TrajectoryStats::of(&traj);
//! assert_eq!(stats.velocity.count(), 1); // one liquid particle, one frame difference
//! let path = dir.join(trajectory_file_name(0));
//! write_trajectory(&path, &traj, &stats)?;
//! assert_eq!(read_trajectory(&path)?, traj);
//! # std::fs::remove_dir_all(&dir).unwrap();
//! # Ok::<(), phi_gns::data::DataError>(())
//! ```

mod dataset;
pub mod export;
mod metadata;
mod stats;
pub mod tfrecord;
mod trajectory;

use std::path::PathBuf;

pub use dataset::{Dataset, SplitReader, export_npz};
pub use metadata::{FORMAT, METADATA_FILE, Metadata, Variant, read_metadata, write_metadata};
pub use phi_io::IoError;
pub use stats::{Moments, TrajectoryStats};
pub use trajectory::{
    Trajectory, read_trajectory, read_trajectory_and_stats, read_trajectory_stats,
    trajectory_file_name, trajectory_index_from_file_name, write_trajectory,
};

/// Particle type of obstacle and boundary particles (static).
pub const OBSTACLE: i64 = 0;
/// Particle type of liquid particles.
pub const LIQUID: i64 = 1;

/// SplitMix64's output function: a bijective mix of 64 bits, so distinct inputs give distinct,
/// well-spread seeds.
pub fn splitmix64(x: u64) -> u64 {
    let mut z = x.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// The seed of trajectory `index` of a split whose base seed (`metadata.json`'s `seeds`) is
/// `split_seed`: a function of the two only, so a file's stored seed tells which split and index
/// it was made for. [`Dataset`] checks every file of a split listed in `seeds` against it.
pub fn trajectory_seed(split_seed: u64, index: usize) -> u64 {
    splitmix64(split_seed ^ splitmix64(index as u64))
}

/// The split names of the thesis' datasets, in the order they are usually listed.
pub(crate) const SPLITS: [&str; 3] = ["train", "valid", "test"];

/// Errors of [`crate::data`]: each names the file (or the input) and what is wrong with it.
#[derive(Debug, thiserror::Error)]
pub enum DataError {
    /// Reading or writing a file failed, or an `.npz` archive is truncated or damaged (its
    /// CRC-32 does not match); the error names the file.
    #[error(transparent)]
    File(#[from] IoError),
    /// A file can be read but its content is not what the format asks for (a missing member,
    /// a wrong dtype or shape, a particle type other than 0 and 1, ...).
    #[error("'{path}': {reason}", path = path.display())]
    Invalid {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// `metadata.json` disagrees with the files of the dataset, or has a value out of range.
    #[error("'{path}': metadata key '{key}': {reason}", path = path.display())]
    Metadata {
        /// The file that disagrees (`metadata.json` or a trajectory file).
        path: PathBuf,
        /// The metadata key, e.g. `splits.train` or `dim`.
        key: String,
        /// What is wrong.
        reason: String,
    },
    /// A JSON file does not parse or does not have the expected keys.
    #[error("'{path}': invalid JSON: {source}", path = path.display())]
    Json {
        /// The file.
        path: PathBuf,
        /// The parser's error (with line and column).
        #[source]
        source: serde_json::Error,
    },
    /// A TFRecord file is truncated or damaged, or a record is not a valid
    /// `tf.train.SequenceExample` of the `learning_to_simulate` format.
    #[error("'{path}', record {record}: {reason}", path = path.display())]
    Record {
        /// The file.
        path: PathBuf,
        /// The record's number, counted from 0.
        record: u64,
        /// What is wrong.
        reason: String,
    },
    /// A directory to be written holds files already, which writing would overwrite or mix
    /// with.
    #[error("'{path}' is not empty: refusing to write a dataset into it", path = path.display())]
    NotEmpty {
        /// The directory.
        path: PathBuf,
    },
    /// The dataset has no split of that name.
    #[error("'{path}': no split '{split}' (the metadata lists {known:?})", path = path.display())]
    UnknownSplit {
        /// The dataset's directory.
        path: PathBuf,
        /// The split asked for.
        split: String,
        /// The splits the metadata lists.
        known: Vec<String>,
    },
    /// Values given to a constructor are inconsistent (lengths, non-finite positions,
    /// dimensions of statistics that are merged, ...).
    #[error("invalid {what}: {reason}")]
    InvalidInput {
        /// What was being built, e.g. "trajectory".
        what: &'static str,
        /// What is wrong.
        reason: String,
    },
}

impl DataError {
    pub(crate) fn invalid(path: impl Into<PathBuf>, reason: impl Into<String>) -> Self {
        DataError::Invalid {
            path: path.into(),
            reason: reason.into(),
        }
    }

    pub(crate) fn metadata(
        path: impl Into<PathBuf>,
        key: impl Into<String>,
        reason: impl Into<String>,
    ) -> Self {
        DataError::Metadata {
            path: path.into(),
            key: key.into(),
            reason: reason.into(),
        }
    }

    pub(crate) fn io(path: &std::path::Path, action: &'static str, e: std::io::Error) -> Self {
        DataError::File(IoError::io(path, action, e))
    }
}
