//! A bounded cache of decoded trajectories, so that training reads each file once while it is
//! drawn often, and memory does not grow with the split.

use std::collections::HashMap;
use std::sync::Arc;

use crate::data::{DataError, Dataset, Trajectory};

/// The bytes a decoded trajectory occupies: its positions (f32), particle types (i64) and the
/// struct itself. This is what [`TrajectoryCache`] counts against its capacity.
pub(crate) fn trajectory_bytes(trajectory: &Trajectory) -> usize {
    std::mem::size_of::<Trajectory>()
        + trajectory.position.len() * std::mem::size_of::<f32>()
        + trajectory.particle_type.len() * std::mem::size_of::<i64>()
}

/// The trajectories of one split of a dataset, read on demand and kept, least recently used
/// first out, while their [`trajectory_bytes`] sum to at most `capacity_bytes`.
///
/// Each is read with [`Dataset::read_with_stats`], which checks its CRC-32, index, frames and
/// dimension against the metadata, so a damaged or missing file is an error naming the file.
/// A trajectory larger than the whole capacity is returned but not kept. The bound is on what the
/// cache holds: an [`Arc`] handed out keeps its trajectory alive until the caller drops it.
#[derive(Debug, Clone)]
pub struct TrajectoryCache {
    dataset: Dataset,
    split: String,
    capacity_bytes: usize,
    held_bytes: usize,
    entries: HashMap<usize, Entry>,
    /// Counts uses; an entry's `last_use` orders evictions.
    clock: u64,
    loads: u64,
}

#[derive(Debug, Clone)]
struct Entry {
    trajectory: Arc<Trajectory>,
    bytes: usize,
    last_use: u64,
}

impl TrajectoryCache {
    /// An empty cache of `split` of `dataset` holding at most `capacity_bytes`.
    ///
    /// # Errors
    /// [`DataError::UnknownSplit`] when the dataset has no such split.
    pub fn new(dataset: &Dataset, split: &str, capacity_bytes: usize) -> Result<Self, DataError> {
        dataset.split_len(split)?;
        Ok(TrajectoryCache {
            dataset: dataset.clone(),
            split: split.to_string(),
            capacity_bytes,
            held_bytes: 0,
            entries: HashMap::new(),
            clock: 0,
            loads: 0,
        })
    }

    /// Trajectory `index` of the split, from memory or read from its file (then kept, evicting
    /// the least recently used ones until it fits).
    ///
    /// # Errors
    /// As [`Dataset::read_with_stats`]: the index is beyond the split, or the file is missing,
    /// damaged or disagrees with the metadata; the error names the file.
    pub fn get(&mut self, index: usize) -> Result<Arc<Trajectory>, DataError> {
        self.clock += 1;
        if let Some(entry) = self.entries.get_mut(&index) {
            entry.last_use = self.clock;
            return Ok(Arc::clone(&entry.trajectory));
        }
        let (trajectory, _stats) = self.dataset.read_with_stats(&self.split, index)?;
        self.loads += 1;
        let trajectory = Arc::new(trajectory);
        let bytes = trajectory_bytes(&trajectory);
        if bytes <= self.capacity_bytes {
            while self.held_bytes + bytes > self.capacity_bytes {
                self.evict_least_recent();
            }
            self.held_bytes += bytes;
            self.entries.insert(
                index,
                Entry {
                    trajectory: Arc::clone(&trajectory),
                    bytes,
                    last_use: self.clock,
                },
            );
        }
        Ok(trajectory)
    }

    fn evict_least_recent(&mut self) {
        let oldest = self
            .entries
            .iter()
            .min_by_key(|(_, entry)| entry.last_use)
            .map(|(&index, _)| index);
        if let Some(entry) = oldest.and_then(|index| self.entries.remove(&index)) {
            self.held_bytes -= entry.bytes;
        }
    }

    /// The dataset the trajectories come from.
    pub fn dataset(&self) -> &Dataset {
        &self.dataset
    }

    /// The split's name.
    pub fn split(&self) -> &str {
        &self.split
    }

    /// The bytes of the trajectories held now (at most the capacity).
    #[cfg(test)]
    pub(crate) fn held_bytes(&self) -> usize {
        self.held_bytes
    }

    /// The number of trajectories held now.
    pub fn len(&self) -> usize {
        self.entries.len()
    }

    /// Whether no trajectory is held.
    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    /// Whether trajectory `index` is held now.
    pub fn contains(&self, index: usize) -> bool {
        self.entries.contains_key(&index)
    }

    /// The number of files read so far (a [`get`](Self::get) that was not served from memory).
    pub fn loads(&self) -> u64 {
        self.loads
    }
}
