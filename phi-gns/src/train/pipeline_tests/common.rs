//! Helpers shared by the training data tests: temporary directories and small datasets.

use std::path::{Path, PathBuf};

use crate::data::{
    Dataset, LIQUID, Metadata, OBSTACLE, Trajectory, TrajectoryStats, write_metadata,
    write_trajectory,
};

pub use crate::test_data::Rng;

/// A fresh, empty directory for one test.
pub fn temp_dir(test: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!(
        "phi-gns-train-data-test-{}-{test}",
        std::process::id()
    ));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("create test directory");
    dir
}

/// Writes a 2D dataset whose split `train` holds one trajectory of `particles[i]` particles per
/// entry, each of `frames` frames of distinct random positions in `[0.1, 0.9]` (the last
/// particle an obstacle); returns the trajectories.
pub fn write_dataset(dir: &Path, particles: &[usize], frames: usize) -> Vec<Trajectory> {
    let dim = 2;
    let mut metadata = Metadata::new(dim);
    metadata.sequence_length = frames - 1;
    std::fs::create_dir_all(dir.join("train")).unwrap();
    let mut split_stats = TrajectoryStats::new(dim);
    let mut trajectories = Vec::new();
    for (index, &n) in particles.iter().enumerate() {
        let mut rng = Rng::new(100 + index as u64);
        let position: Vec<f32> = (0..frames * n * dim)
            .map(|_| (0.1 + 0.8 * rng.uniform()) as f32)
            .collect();
        let mut types = vec![LIQUID; n - 1];
        types.push(OBSTACLE);
        let traj = Trajectory::new(dim, position, types, index as u64, index).unwrap();
        let stats = TrajectoryStats::of(&traj);
        split_stats.merge(&stats).unwrap();
        write_trajectory(
            &Dataset::trajectory_path(dir, "train", index),
            &traj,
            &stats,
        )
        .unwrap();
        trajectories.push(traj);
    }
    metadata.set_statistics(&split_stats).unwrap();
    metadata.splits.insert("train".to_string(), particles.len());
    write_metadata(dir, &metadata).unwrap();
    trajectories
}

/// Flips bytes of the stored positions of `trajectory` in its file `path`, so that the
/// member's CRC-32 no longer matches.
pub fn damage(path: &Path, trajectory: &Trajectory) {
    let mut bytes = std::fs::read(path).unwrap();
    let first: Vec<u8> = trajectory.position[..4]
        .iter()
        .flat_map(|x| x.to_le_bytes())
        .collect();
    let at = bytes
        .windows(first.len())
        .position(|w| w == first)
        .expect("the positions are stored uncompressed");
    for b in &mut bytes[at..at + first.len()] {
        *b = !*b;
    }
    std::fs::write(path, bytes).unwrap();
}

/// An upper bound of the chi-square statistic over `bins` equally likely bins that a correct
/// sampler exceeds with probability below 1e-9 (Chernoff: `P(χ²_k ≥ x) ≤ (x/k · e^{1−x/k})^{k/2}`
/// for `k = bins − 1` degrees of freedom), found by bisection.
pub fn chi_square_bound(bins: usize) -> f64 {
    let k = (bins - 1) as f64;
    let log_tail = |x: f64| 0.5 * k * ((x / k).ln() + 1.0 - x / k);
    let (mut lo, mut hi) = (k, 100.0 * k + 100.0);
    for _ in 0..100 {
        let mid = 0.5 * (lo + hi);
        if log_tail(mid) > (1e-9f64).ln() {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    hi
}

/// The chi-square statistic of `counts` against equal expected counts.
pub fn chi_square(counts: &[u64]) -> f64 {
    let total: u64 = counts.iter().sum();
    let expected = total as f64 / counts.len() as f64;
    counts
        .iter()
        .map(|&c| (c as f64 - expected).powi(2) / expected)
        .sum()
}
