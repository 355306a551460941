//! Helpers shared by the data tests: temporary directories, sample trajectories and datasets.

use std::path::{Path, PathBuf};
use std::process::Command;

use phi_gns::data::{
    Dataset, LIQUID, Metadata, OBSTACLE, Trajectory, TrajectoryStats, write_metadata,
    write_trajectory,
};

/// A fresh, empty directory for one test.
pub fn temp_dir(test: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("phi-gns-data-test-{}-{test}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("create test directory");
    dir
}

#[path = "../shared/rng.rs"]
mod rng;
pub use rng::Rng;

/// A trajectory of `liquid` falling, jittering liquid particles followed by `obstacles` static
/// ones, `frames` frames in `dim` dimensions, positions inside `[0.1, 0.9]`.
pub fn sample_trajectory(
    seed: u64,
    index: usize,
    frames: usize,
    liquid: usize,
    obstacles: usize,
    dim: usize,
) -> Trajectory {
    let mut rng = Rng::new(seed);
    let n = liquid + obstacles;
    let start: Vec<f64> = (0..n * dim).map(|_| 0.2 + 0.6 * rng.uniform()).collect();
    let velocity: Vec<f64> = (0..dim).map(|_| 0.002 * (rng.uniform() - 0.5)).collect();
    let mut position = Vec::with_capacity(frames * n * dim);
    for t in 0..frames {
        for i in 0..n {
            for k in 0..dim {
                let x0 = start[i * dim + k];
                let x = if i < liquid {
                    let fall = if k == dim - 1 {
                        -1e-4 * (t * t) as f64
                    } else {
                        0.0
                    };
                    x0 + velocity[k] * t as f64 + fall + 1e-3 * (rng.uniform() - 0.5)
                } else {
                    x0
                };
                position.push(x.clamp(0.1, 0.9) as f32);
            }
        }
    }
    let mut types = vec![LIQUID; liquid];
    types.extend(std::iter::repeat_n(OBSTACLE, obstacles));
    Trajectory::new(dim, position, types, seed, index).expect("valid sample trajectory")
}

/// Writes a dataset with the given splits (name, count) of `frames`-frame trajectories in
/// `dim` dimensions; `metadata.json` holds the training split's statistics. Returns the
/// trajectories by split.
pub fn write_sample_dataset(
    dir: &Path,
    splits: &[(&str, usize)],
    frames: usize,
    dim: usize,
) -> Vec<Vec<Trajectory>> {
    let mut metadata = Metadata::new(dim);
    metadata.sequence_length = frames - 1;
    let mut all = Vec::new();
    for (s, &(split, count)) in splits.iter().enumerate() {
        std::fs::create_dir_all(dir.join(split)).unwrap();
        let mut split_stats = TrajectoryStats::new(dim);
        let mut trajectories = Vec::new();
        for index in 0..count {
            let seed = phi_gns::data::trajectory_seed(1000 * s as u64, index);
            let traj = sample_trajectory(seed, index, frames, 5 + index, 3, dim);
            let stats = TrajectoryStats::of(&traj);
            split_stats.merge(&stats).unwrap();
            write_trajectory(&Dataset::trajectory_path(dir, split, index), &traj, &stats).unwrap();
            trajectories.push(traj);
        }
        if split == "train" {
            metadata.set_statistics(&split_stats).unwrap();
        }
        metadata.splits.insert(split.to_string(), count);
        metadata.seeds.insert(split.to_string(), 1000 * s as u64);
        all.push(trajectories);
    }
    metadata.generator = serde_json::json!({ "test": true, "frames": frames });
    write_metadata(dir, &metadata).unwrap();
    all
}

/// A Python interpreter with numpy, if there is one: `$PHI_PYTHON` first, then the usual
/// places.
pub fn python_with_numpy() -> Option<PathBuf> {
    std::env::var_os("PHI_PYTHON")
        .map(PathBuf::from)
        .into_iter()
        .chain(["/work/phiflow-venv/bin/python", "python3"].map(PathBuf::from))
        .find(|python| {
            Command::new(python)
                .args(["-c", "import numpy"])
                .output()
                .is_ok_and(|o| o.status.success())
        })
}

/// Runs a Python script and returns its standard output; panics with its output on failure.
pub fn run_python(python: &Path, script: &str) -> String {
    let out = Command::new(python)
        .args(["-c", script])
        .output()
        .expect("run python");
    assert!(
        out.status.success(),
        "python failed:\n{}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// `|a - b| <= tol * max(|a|, |b|, tiny)`.
pub fn assert_rel_close(a: f64, b: f64, tol: f64, what: &str) {
    let scale = a.abs().max(b.abs()).max(1e-300);
    assert!(
        (a - b).abs() <= tol * scale,
        "{what}: {a} vs {b} (relative difference {:e})",
        (a - b).abs() / scale
    );
}
