//! The trajectory cache: its contents, its bound, its eviction order and its errors.

use crate::data::{DataError, Dataset};
use crate::train::cache::{TrajectoryCache, trajectory_bytes};

use super::common::{Rng, damage, temp_dir, write_dataset};

#[test]
fn the_cache_never_holds_more_than_its_capacity_and_returns_the_files_trajectories() {
    let dir = temp_dir("cache-bound");
    let written = write_dataset(&dir, &[3, 9, 4, 7, 5, 12], 6);
    let dataset = Dataset::open(&dir).unwrap();
    let bytes: Vec<usize> = written.iter().map(trajectory_bytes).collect();
    // Room for two to four of the six.
    let capacity = bytes[1] + bytes[5];
    let mut cache = TrajectoryCache::new(&dataset, "train", capacity).unwrap();
    let mut rng = Rng::new(9);
    let mut most_held = 0;
    for _ in 0..200 {
        let index = (rng.next_u64() % written.len() as u64) as usize;
        let trajectory = cache.get(index).unwrap();
        assert_eq!(*trajectory, written[index]);
        assert!(cache.contains(index), "a trajectory that fits is kept");
        let held: usize = (0..written.len())
            .filter(|&i| cache.contains(i))
            .map(|i| bytes[i])
            .sum();
        assert_eq!(cache.held_bytes(), held);
        assert!(held <= capacity, "{held} bytes held, capacity {capacity}");
        most_held = most_held.max(cache.len());
    }
    assert!(most_held >= 2, "the cache held at most {most_held}");
    assert!(cache.loads() < 200, "every get read its file");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn the_least_recently_used_trajectory_is_evicted_first() {
    let dir = temp_dir("cache-lru");
    let written = write_dataset(&dir, &[4, 4, 4], 5);
    let dataset = Dataset::open(&dir).unwrap();
    let capacity = 2 * trajectory_bytes(&written[0]);
    let mut cache = TrajectoryCache::new(&dataset, "train", capacity).unwrap();
    for index in [0, 1, 0, 2] {
        cache.get(index).unwrap();
    }
    assert!(cache.contains(0) && !cache.contains(1) && cache.contains(2));
    assert_eq!(cache.loads(), 3);
    cache.get(0).unwrap();
    assert_eq!(cache.loads(), 3, "a held trajectory is not read again");
    cache.get(1).unwrap();
    assert!(cache.contains(0) && cache.contains(1) && !cache.contains(2));
    assert_eq!((cache.len(), cache.held_bytes()), (2, capacity));

    // A trajectory larger than the capacity is returned but not kept.
    let mut small = TrajectoryCache::new(&dataset, "train", capacity / 2 - 1).unwrap();
    assert_eq!(*small.get(1).unwrap(), written[1]);
    assert!(small.is_empty() && small.held_bytes() == 0);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_missing_or_damaged_file_is_an_error_naming_it() {
    let dir = temp_dir("cache-errors");
    let written = write_dataset(&dir, &[3, 3, 3], 5);
    let dataset = Dataset::open(&dir).unwrap();
    std::fs::remove_file(Dataset::trajectory_path(&dir, "train", 1)).unwrap();
    damage(&Dataset::trajectory_path(&dir, "train", 2), &written[2]);
    let mut cache = TrajectoryCache::new(&dataset, "train", usize::MAX).unwrap();
    assert!(cache.get(0).is_ok());
    for index in [1, 2] {
        let err = cache.get(index).unwrap_err();
        let text = err.to_string();
        assert!(
            matches!(err, DataError::File(_)) && text.contains(&format!("traj_0000{index}.npz")),
            "{text}"
        );
        assert!(!cache.contains(index));
    }
    assert!(cache.get(3).is_err(), "beyond the split");
    let err = TrajectoryCache::new(&dataset, "valid", 0).unwrap_err();
    assert!(matches!(err, DataError::UnknownSplit { .. }), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}
