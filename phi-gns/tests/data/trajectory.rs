//! Trajectory files: round trip, damage, truncation, numpy.

use phi_gns::data::{
    DataError, LIQUID, OBSTACLE, Trajectory, TrajectoryStats, read_trajectory,
    read_trajectory_stats, trajectory_file_name, trajectory_index_from_file_name, write_trajectory,
};

use crate::common::{python_with_numpy, run_python, sample_trajectory, temp_dir};

#[test]
fn write_then_read_gives_the_same_trajectory_and_stats() {
    let dir = temp_dir("traj-round-trip");
    for dim in [2, 3] {
        let traj = sample_trajectory(u64::MAX - 3, 17, 12, 9, 4, dim);
        let stats = TrajectoryStats::of(&traj);
        let path = dir.join(trajectory_file_name(traj.index));
        write_trajectory(&path, &traj, &stats).unwrap();
        let back = read_trajectory(&path).unwrap();
        assert_eq!(back, traj);
        assert_eq!(
            back.seed,
            u64::MAX - 3,
            "a u64 seed survives its i64 member"
        );
        assert_eq!(read_trajectory_stats(&path).unwrap(), stats);
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn trajectory_new_checks_its_input() {
    let ok = Trajectory::new(2, vec![0.5; 12], vec![LIQUID, OBSTACLE], 0, 0).unwrap();
    assert_eq!((ok.frames, ok.particles, ok.dim), (3, 2, 2));
    assert_eq!(ok.frame(1), &[0.5; 4]);
    assert_eq!(ok.liquid_particles(), 1);
    let cases: [(usize, Vec<f32>, Vec<i64>, &str); 6] = [
        (
            2,
            vec![0.5; 11],
            vec![LIQUID, OBSTACLE],
            "11 position values",
        ),
        (2, vec![], vec![LIQUID], "0 position values"),
        (2, vec![0.5, f32::NAN], vec![LIQUID], "not finite"),
        (2, vec![0.5; 2], vec![], "no particles"),
        (4, vec![0.5; 4], vec![LIQUID], "dimension 4"),
        (1, vec![0.5; 2], vec![LIQUID, 5], "type 5"),
    ];
    for (dim, position, types, expected) in cases {
        let err = Trajectory::new(dim, position, types, 0, 0).unwrap_err();
        assert!(matches!(err, DataError::InvalidInput { .. }), "{err}");
        assert!(err.to_string().contains(expected), "{err}");
    }
}

#[test]
fn file_names_have_five_digits_or_more() {
    assert_eq!(trajectory_file_name(7), "traj_00007.npz");
    assert_eq!(trajectory_file_name(123_456), "traj_123456.npz");
    for index in [0, 7, 99_999, 100_000, 123_456] {
        assert_eq!(
            trajectory_index_from_file_name(&trajectory_file_name(index)),
            Some(index)
        );
    }
    for name in [
        "traj_7.npz",
        "traj_0000007.npz",
        ".traj_00001.npz.tmp-42",
        "traj_00001.npy",
        "traj_-0001.npz",
        "metadata.json",
    ] {
        assert_eq!(trajectory_index_from_file_name(name), None, "{name}");
    }
}

#[test]
fn a_flipped_byte_is_a_checksum_error_naming_the_file() {
    let dir = temp_dir("traj-flipped");
    let traj = sample_trajectory(1, 0, 20, 30, 5, 2);
    let stats = TrajectoryStats::of(&traj);
    let path = dir.join("traj_00000.npz");
    write_trajectory(&path, &traj, &stats).unwrap();
    let good = std::fs::read(&path).unwrap();
    // The middle of the file lies in the positions (by far the largest member).
    let mut bad = good.clone();
    bad[good.len() / 2] ^= 0x10;
    std::fs::write(&path, &bad).unwrap();
    let err = read_trajectory(&path).unwrap_err();
    let msg = err.to_string();
    assert!(
        msg.contains("traj_00000.npz") && msg.contains("CRC-32"),
        "{msg}"
    );
    // The statistics are separate members with their own checksums: still readable.
    assert_eq!(read_trajectory_stats(&path).unwrap(), stats);

    // Damage inside a statistics member is caught when reading it.
    let needle = stats.velocity.mean()[0].to_le_bytes();
    let at = good
        .windows(8)
        .position(|w| w == needle)
        .expect("the velocity mean is stored little-endian");
    let mut bad = good.clone();
    bad[at] ^= 0x01;
    std::fs::write(&path, &bad).unwrap();
    let msg = read_trajectory_stats(&path).unwrap_err().to_string();
    assert!(
        msg.contains("traj_00000.npz") && msg.contains("CRC-32"),
        "{msg}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_truncated_file_is_an_error_naming_the_file() {
    let dir = temp_dir("traj-truncated");
    let traj = sample_trajectory(2, 0, 5, 4, 2, 2);
    let path = dir.join("traj_00000.npz");
    write_trajectory(&path, &traj, &TrajectoryStats::of(&traj)).unwrap();
    let full = std::fs::read(&path).unwrap();
    for len in (0..full.len()).step_by(7).chain([full.len() - 1]) {
        std::fs::write(&path, &full[..len]).unwrap();
        let msg = read_trajectory(&path).unwrap_err().to_string();
        assert!(msg.contains("traj_00000.npz"), "length {len}: {msg}");
        let msg = read_trajectory_stats(&path).unwrap_err().to_string();
        assert!(msg.contains("traj_00000.npz"), "length {len}: {msg}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn statistics_of_the_wrong_dimension_are_refused() {
    let dir = temp_dir("traj-stats-dim");
    let traj = sample_trajectory(3, 0, 4, 3, 1, 2);
    let err = write_trajectory(&dir.join("t.npz"), &traj, &TrajectoryStats::new(3)).unwrap_err();
    assert!(err.to_string().contains("t.npz"), "{err}");
    assert!(!dir.join("t.npz").exists());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn numpy_reads_a_trajectory_file() {
    let Some(python) = python_with_numpy() else {
        println!("note: skipping numpy_reads_a_trajectory_file, no Python with numpy");
        return;
    };
    let dir = temp_dir("traj-numpy");
    let traj = sample_trajectory(5, 3, 8, 6, 2, 2);
    let stats = TrajectoryStats::of(&traj);
    let path = dir.join(trajectory_file_name(3));
    write_trajectory(&path, &traj, &stats).unwrap();
    let script = format!(
        r#"
import numpy as np
d = np.load({path:?})
p, t = d["position"], d["particle_type"]
assert p.dtype == np.float32 and p.shape == (8, 8, 2), (p.dtype, p.shape)
assert t.dtype == np.int64 and list(t) == [1] * 6 + [0] * 2, t
assert d["index"][0] == 3 and d["seed"].view(np.uint64)[0] == 5
liquid = p[:, t == 1].astype(np.float64)
v = (liquid[1:] - liquid[:-1]).reshape(-1, 2)
a = (liquid[2:] - 2 * liquid[1:-1] + liquid[:-2]).reshape(-1, 2)
sv, sa = d["stats_velocity"], d["stats_acceleration"]
assert sv.dtype == np.float64 and sv.shape == (3, 2)
assert (sv[0] == len(v)).all() and (sa[0] == len(a)).all()
assert np.allclose(sv[1], v.mean(0), rtol=1e-12, atol=1e-15), (sv[1], v.mean(0))
assert np.allclose(sv[2], ((v - v.mean(0)) ** 2).sum(0), rtol=1e-9, atol=1e-18)
assert np.allclose(sa[1], a.mean(0), rtol=1e-12, atol=1e-15)
print(repr(float(p.astype(np.float64).sum())))
"#,
        path = path.display().to_string()
    );
    let sum: f64 = run_python(&python, &script).trim().parse().unwrap();
    let expected: f64 = traj.position.iter().map(|&x| f64::from(x)).sum();
    assert!((sum - expected).abs() < 1e-9, "{sum} vs {expected}");
    let _ = std::fs::remove_dir_all(&dir);
}
