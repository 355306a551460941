//! A dataset directory: opening and checking it, streaming its splits, exporting them.

use std::path::{Path, PathBuf};

use phi_io::npz::{NpyArray, NpzWriter, write_npz_streamed};

use super::trajectory::{read_trajectory_and_stats, read_trajectory_identity};
use super::{
    DataError, Metadata, Trajectory, TrajectoryStats, read_metadata, read_trajectory,
    read_trajectory_stats, trajectory_file_name, trajectory_index_from_file_name, trajectory_seed,
};

/// A dataset directory whose `metadata.json` has been read and checked against its files.
///
/// ```
/// use phi_gns::data::{Dataset, LIQUID, Metadata, Trajectory, TrajectoryStats, write_metadata,
///     write_trajectory};
/// # let dir = std::env::temp_dir().join(format!("phi-gns-doc-dataset-{}", std::process::id()));
/// # let _ = std::fs::remove_dir_all(&dir);
/// let mut metadata = Metadata::new(2);
/// metadata.sequence_length = 1;
/// metadata.splits.insert("train".into(), 1);
/// // A train split needs its statistics (all zero would normalise nothing).
/// metadata.vel_std = vec![1e-3; 2];
/// metadata.acc_std = vec![1e-4; 2];
/// let traj = Trajectory::new(2, vec![0.5, 0.5, 0.5, 0.4], vec![LIQUID], 7, 0)?;
/// let path = Dataset::trajectory_path(&dir, "train", 0);
/// std::fs::create_dir_all(path.parent().unwrap()).unwrap();
/// write_trajectory(&path, &traj, &TrajectoryStats::of(&traj))?;
/// write_metadata(&dir, &metadata)?;
///
/// let dataset = Dataset::open(&dir)?;
/// let trajectories: Vec<Trajectory> = dataset.split("train")?.collect::<Result<_, _>>()?;
/// assert_eq!(trajectories, [traj]);
/// # std::fs::remove_dir_all(&dir).unwrap();
/// # Ok::<(), phi_gns::data::DataError>(())
/// ```
#[derive(Debug, Clone)]
pub struct Dataset {
    dir: PathBuf,
    metadata: Metadata,
}

impl Dataset {
    /// Opens the dataset in `dir`: reads `metadata.json` and checks, for every split it lists,
    /// that the split's folder holds exactly the files `traj_00000.npz` .. of its count, and
    /// that each file's positions have `sequence_length + 1` frames of `dim` components (read
    /// from the array headers; the positions themselves are read by [`Dataset::split`]).
    ///
    /// A mismatch is a [`DataError::Metadata`] naming the file and the key (`splits.train`,
    /// `sequence_length`, `dim`). Folders and files the metadata does not list are ignored.
    pub fn open(dir: impl AsRef<Path>) -> Result<Self, DataError> {
        let dir = dir.as_ref().to_path_buf();
        let metadata = read_metadata(&dir)?;
        let dataset = Dataset { dir, metadata };
        for (split, &count) in &dataset.metadata.splits {
            dataset.check_split(split, count)?;
        }
        Ok(dataset)
    }

    fn check_split(&self, split: &str, count: usize) -> Result<(), DataError> {
        let split_dir = self.dir.join(split);
        let key = format!("splits.{split}");
        let entries = std::fs::read_dir(&split_dir).map_err(|e| {
            DataError::metadata(
                &split_dir,
                &key,
                format!("lists {count} trajectories but the folder cannot be read: {e}"),
            )
        })?;
        // The indices found, bounded by the folder's entries (not by the count the metadata
        // claims, which may be anything).
        let mut present = std::collections::BTreeSet::new();
        for entry in entries {
            let entry = entry.map_err(|e| DataError::io(&split_dir, "cannot list", e))?;
            let name = entry.file_name();
            if let Some(index) = name.to_str().and_then(trajectory_index_from_file_name) {
                present.insert(index);
            }
        }
        // The first index below `count` that has no file (the indices are sorted, so it is the
        // first place where the k-th one is not k).
        let missing = present
            .range(..count)
            .enumerate()
            .find(|&(k, &i)| k != i)
            .map_or_else(|| present.range(..count).count(), |(k, _)| k);
        if missing < count {
            return Err(DataError::metadata(
                &split_dir,
                &key,
                format!(
                    "lists {count} trajectories but '{}' is missing",
                    trajectory_file_name(missing)
                ),
            ));
        }
        if let Some(&index) = present.range(count..).next() {
            return Err(DataError::metadata(
                &split_dir,
                &key,
                format!(
                    "lists {count} trajectories but the folder also holds '{}'",
                    trajectory_file_name(index)
                ),
            ));
        }
        for index in 0..count {
            let path = split_dir.join(trajectory_file_name(index));
            let identity = read_trajectory_identity(&path)?;
            self.check_shape(&path, identity.frames, identity.dim)?;
            self.check_identity(&path, split, index, identity.index, identity.seed)?;
        }
        Ok(())
    }

    /// Checks a file's stored index and seed against its place: its index in the split, and in
    /// a split listed under `seeds` the seed derived from the split's ([`trajectory_seed`]).
    fn check_identity(
        &self,
        path: &Path,
        split: &str,
        index: usize,
        stored_index: usize,
        stored_seed: u64,
    ) -> Result<(), DataError> {
        if stored_index != index {
            return Err(DataError::metadata(
                path,
                format!("splits.{split}"),
                format!(
                    "the file stores index {stored_index} instead of {index}: it is another \
                     trajectory's file (moved, swapped or copied)"
                ),
            ));
        }
        if let Some(&base) = self.metadata.seeds.get(split) {
            let expected = trajectory_seed(base, index);
            if stored_seed != expected {
                return Err(DataError::metadata(
                    path,
                    format!("seeds.{split}"),
                    format!(
                        "the file stores seed {stored_seed}, but trajectory {index} of split \
                         '{split}' has seed {expected}: the file belongs to another split or \
                         another dataset"
                    ),
                ));
            }
        }
        Ok(())
    }

    /// Checks a file's frame count and dimension against the metadata.
    fn check_shape(&self, path: &Path, frames: usize, dim: usize) -> Result<(), DataError> {
        if dim != self.metadata.dim {
            return Err(DataError::metadata(
                path,
                "dim",
                format!(
                    "the metadata says {} but the positions have {dim} components",
                    self.metadata.dim
                ),
            ));
        }
        if frames != self.metadata.frames() {
            return Err(DataError::metadata(
                path,
                "sequence_length",
                format!(
                    "the metadata says {} steps ({} frames) but the file has {frames} frames",
                    self.metadata.sequence_length,
                    self.metadata.frames()
                ),
            ));
        }
        Ok(())
    }

    /// The path of trajectory `index` of `split` in the dataset directory `dir`:
    /// `dir/split/traj_00000.npz`.
    pub fn trajectory_path(dir: &Path, split: &str, index: usize) -> PathBuf {
        dir.join(split).join(trajectory_file_name(index))
    }

    /// The dataset's directory.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// The content of `metadata.json`.
    pub fn metadata(&self) -> &Metadata {
        &self.metadata
    }

    /// The number of trajectories in `split`.
    pub fn split_len(&self, split: &str) -> Result<usize, DataError> {
        self.metadata
            .splits
            .get(split)
            .copied()
            .ok_or_else(|| DataError::UnknownSplit {
                path: self.dir.clone(),
                split: split.to_string(),
                known: self.metadata.splits.keys().cloned().collect(),
            })
    }

    /// The trajectories of `split` in index order, read one at a time (one in memory at a
    /// time). Each is checked against the metadata again (its index, frames and dimension).
    pub fn split(&self, split: &str) -> Result<SplitReader<'_>, DataError> {
        let count = self.split_len(split)?;
        Ok(SplitReader {
            dataset: self,
            split: split.to_string(),
            next: 0,
            count,
        })
    }

    /// The statistics of `split`, merged from the statistics stored in its files (the
    /// positions are not read).
    pub fn split_statistics(&self, split: &str) -> Result<TrajectoryStats, DataError> {
        let count = self.split_len(split)?;
        let mut total = TrajectoryStats::new(self.metadata.dim);
        for index in 0..count {
            let path = Self::trajectory_path(&self.dir, split, index);
            let stats = read_trajectory_stats(&path)?;
            total
                .merge(&stats)
                .map_err(|e| DataError::invalid(&path, e.to_string()))?;
        }
        Ok(total)
    }

    /// Reads trajectory `index` of `split` and the statistics stored with it.
    pub fn read_with_stats(
        &self,
        split: &str,
        index: usize,
    ) -> Result<(Trajectory, TrajectoryStats), DataError> {
        let path = self.checked_path(split, index)?;
        let (traj, stats) = read_trajectory_and_stats(&path)?;
        self.check_trajectory(&path, split, &traj, index)?;
        Ok((traj, stats))
    }

    fn checked_path(&self, split: &str, index: usize) -> Result<PathBuf, DataError> {
        let count = self.split_len(split)?;
        let path = Self::trajectory_path(&self.dir, split, index);
        if index >= count {
            return Err(DataError::metadata(
                &path,
                format!("splits.{split}"),
                format!("index {index} is beyond the {count} trajectories listed"),
            ));
        }
        Ok(path)
    }

    fn check_trajectory(
        &self,
        path: &Path,
        split: &str,
        traj: &Trajectory,
        index: usize,
    ) -> Result<(), DataError> {
        self.check_shape(path, traj.frames, traj.dim)?;
        self.check_identity(path, split, index, traj.index, traj.seed)
    }
}

/// The trajectories of one split in index order, one read per [`Iterator::next`] (see
/// [`Dataset::split`]).
#[derive(Debug)]
pub struct SplitReader<'a> {
    dataset: &'a Dataset,
    split: String,
    next: usize,
    count: usize,
}

impl SplitReader<'_> {
    /// The split's name.
    pub fn name(&self) -> &str {
        &self.split
    }
}

impl Iterator for SplitReader<'_> {
    type Item = Result<Trajectory, DataError>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.next >= self.count {
            return None;
        }
        let index = self.next;
        self.next += 1;
        let path = Dataset::trajectory_path(&self.dataset.dir, &self.split, index);
        Some(read_trajectory(&path).and_then(|traj| {
            self.dataset
                .check_trajectory(&path, &self.split, &traj, index)?;
            Ok(traj)
        }))
    }

    fn size_hint(&self) -> (usize, Option<usize>) {
        let left = self.count - self.next;
        (left, Some(left))
    }
}

impl ExactSizeIterator for SplitReader<'_> {}

/// Writes `split` of `dataset` as one `.npz` archive for numpy users: for each trajectory `i`,
/// `trajectory_{i}_position` (f32 `[frames, n, dim]`) and `trajectory_{i}_particle_type` (i64
/// `[n]`, 0 = obstacle, 1 = liquid). Streamed: one trajectory is in memory at a time. Written
/// atomically; returns the number of trajectories.
pub fn export_npz(
    dataset: &Dataset,
    split: &str,
    out_file: impl AsRef<Path>,
) -> Result<usize, DataError> {
    write_split_npz(dataset, split, out_file.as_ref(), |npz, traj| {
        let i = traj.index;
        let position = NpyArray {
            shape: vec![traj.frames, traj.particles, traj.dim],
            data: traj.position.into(),
        };
        npz.add(&format!("trajectory_{i}_position"), &position)?;
        let types = NpyArray::from_vec(traj.particle_type);
        npz.add(&format!("trajectory_{i}_particle_type"), &types)?;
        Ok(())
    })
}

/// Streams `split` of `dataset` into one `.npz` archive at `out_file`, written atomically:
/// `entries` adds each trajectory's arrays, in index order, with one trajectory in memory at a
/// time. Returns the number of trajectories.
pub(crate) fn write_split_npz(
    dataset: &Dataset,
    split: &str,
    out_file: &Path,
    mut entries: impl FnMut(&mut NpzWriter<'_>, Trajectory) -> Result<(), DataError>,
) -> Result<usize, DataError> {
    let reader = dataset.split(split)?;
    let mut count = 0;
    write_npz_streamed(out_file, |npz| {
        for traj in reader {
            entries(npz, traj?)?;
            count += 1;
        }
        Ok::<(), DataError>(())
    })?;
    Ok(count)
}
