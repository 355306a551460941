//! Dataset directories: metadata, opening checks, streaming splits, npz export.

use phi_gns::data::{
    DataError, Dataset, METADATA_FILE, Metadata, TrajectoryStats, Variant, export_npz,
    read_metadata, write_metadata,
};

use crate::common::{python_with_numpy, run_python, temp_dir, write_sample_dataset};

#[test]
fn a_dataset_streams_its_splits_in_index_order() {
    let dir = temp_dir("dataset-stream");
    let written = write_sample_dataset(&dir, &[("train", 3), ("valid", 2)], 6, 2);
    let dataset = Dataset::open(&dir).unwrap();
    assert_eq!(dataset.metadata().frames(), 6);
    for (split, expected) in ["train", "valid"].into_iter().zip(&written) {
        let reader = dataset.split(split).unwrap();
        assert_eq!(reader.len(), expected.len());
        let read: Vec<_> = reader.map(Result::unwrap).collect();
        assert_eq!(&read, expected);
        // The stored per-file statistics merge to the statistics of the positions.
        let mut from_positions = TrajectoryStats::new(2);
        for traj in expected {
            from_positions.merge(&TrajectoryStats::of(traj)).unwrap();
        }
        assert_eq!(dataset.split_statistics(split).unwrap(), from_positions);
    }
    let train = dataset.split_statistics("train").unwrap();
    assert_eq!(dataset.metadata().vel_mean, train.velocity.mean());
    assert_eq!(dataset.metadata().acc_std, train.acceleration.std());
    let (traj, stats) = dataset.read_with_stats("valid", 1).unwrap();
    assert_eq!(traj, written[1][1]);
    assert_eq!(stats, TrajectoryStats::of(&traj));

    let err = dataset.split("test").unwrap_err();
    assert!(matches!(err, DataError::UnknownSplit { .. }), "{err}");
    assert!(dataset.read_with_stats("valid", 2).is_err());
    let _ = std::fs::remove_dir_all(&dir);
}

fn edit_metadata(dir: &std::path::Path, edit: impl FnOnce(&mut Metadata)) {
    let mut metadata = read_metadata(dir).unwrap();
    edit(&mut metadata);
    write_metadata(dir, &metadata).unwrap();
}

fn open_error(dir: &std::path::Path) -> (String, String) {
    match Dataset::open(dir).unwrap_err() {
        DataError::Metadata { path, key, reason } => {
            (path.display().to_string(), format!("{key}: {reason}"))
        }
        other => panic!("expected a metadata error, got {other}"),
    }
}

#[test]
fn metadata_that_does_not_match_the_files_is_an_error_naming_file_and_key() {
    let dir = temp_dir("dataset-mismatch");
    write_sample_dataset(&dir, &[("train", 3)], 5, 2);
    assert!(Dataset::open(&dir).is_ok());

    // One trajectory more than the folder holds.
    edit_metadata(&dir, |m| *m.splits.get_mut("train").unwrap() = 4);
    let (path, msg) = open_error(&dir);
    assert!(
        path.ends_with("train") && msg.contains("splits.train"),
        "{path}: {msg}"
    );
    assert!(msg.contains("traj_00003.npz"), "{msg}");

    // One fewer.
    edit_metadata(&dir, |m| *m.splits.get_mut("train").unwrap() = 2);
    let (_, msg) = open_error(&dir);
    assert!(
        msg.contains("splits.train") && msg.contains("traj_00002.npz"),
        "{msg}"
    );

    // A split without a folder.
    edit_metadata(&dir, |m| {
        m.splits.insert("train".into(), 3);
        m.splits.insert("valid".into(), 1);
    });
    let (path, msg) = open_error(&dir);
    assert!(
        path.ends_with("valid") && msg.contains("splits.valid"),
        "{path}: {msg}"
    );

    // Frames.
    edit_metadata(&dir, |m| {
        m.splits.remove("valid");
        m.sequence_length = 9;
    });
    let (path, msg) = open_error(&dir);
    assert!(path.ends_with("traj_00000.npz"), "{path}");
    assert!(
        msg.contains("sequence_length") && msg.contains("5 frames"),
        "{msg}"
    );

    // Dimension (a valid 3D metadata over 2D files).
    edit_metadata(&dir, |m| {
        let splits = m.splits.clone();
        *m = Metadata::new(3);
        m.sequence_length = 4;
        m.splits = splits;
        m.vel_std = vec![1e-3; 3];
        m.acc_std = vec![1e-4; 3];
    });
    let (path, msg) = open_error(&dir);
    assert!(
        path.ends_with("traj_00000.npz") && msg.starts_with("dim:"),
        "{path}: {msg}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_damaged_file_is_reported_when_its_split_is_read() {
    let dir = temp_dir("dataset-damaged");
    write_sample_dataset(&dir, &[("train", 2)], 5, 2);
    let path = Dataset::trajectory_path(&dir, "train", 1);
    let mut bytes = std::fs::read(&path).unwrap();
    // Damage a position value (the ZIP headers' dates are not covered by the CRC).
    let traj = phi_gns::data::read_trajectory(&path).unwrap();
    let needle = traj.position[7].to_le_bytes();
    let at = bytes.windows(4).position(|w| w == needle).unwrap();
    bytes[at] ^= 0xFF;
    std::fs::write(&path, &bytes).unwrap();
    // Opening reads the headers only; the damage shows when the trajectory is read.
    let dataset = Dataset::open(&dir).unwrap();
    let results: Vec<_> = dataset.split("train").unwrap().collect();
    assert!(results[0].is_ok());
    let msg = results[1].as_ref().unwrap_err().to_string();
    assert!(
        msg.contains("traj_00001.npz") && msg.contains("CRC-32"),
        "{msg}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn metadata_json_has_deepmind_keys_and_ours() {
    let dir = temp_dir("dataset-metadata");
    write_sample_dataset(&dir, &[("train", 2), ("valid", 1)], 5, 2);
    let text = std::fs::read_to_string(dir.join(METADATA_FILE)).unwrap();
    let json: serde_json::Value = serde_json::from_str(&text).unwrap();
    for key in [
        "bounds",
        "sequence_length",
        "default_connectivity_radius",
        "dim",
        "dt",
        "vel_mean",
        "vel_std",
        "acc_mean",
        "acc_std",
    ] {
        assert!(json.get(key).is_some(), "missing DeepMind key {key}");
    }
    assert_eq!(json["bounds"], serde_json::json!([[0.1, 0.9], [0.1, 0.9]]));
    assert_eq!(json["sequence_length"], 4);
    assert_eq!(json["dt"], 0.05);
    assert_eq!(json["format"], "phi-dataset");
    assert_eq!(json["format_version"], 1);
    assert_eq!(json["splits"], serde_json::json!({"train": 2, "valid": 1}));
    assert_eq!(
        json["particle_types"],
        serde_json::json!({"0": "obstacle", "1": "liquid"})
    );
    assert_eq!(json["position_scale"], 0.025);
    assert_eq!(json["position_offset"], 0.1);
    assert_eq!(json["variant"], "obstacles");
    assert_eq!(json["generator"]["test"], true);
    assert_eq!(json["seeds"]["valid"], 1000);
    assert_eq!(json["vel_std"].as_array().unwrap().len(), 2);

    // Round trip, including the other variant.
    let mut metadata = read_metadata(&dir).unwrap();
    metadata.variant = Variant::WallsAsParticles;
    write_metadata(&dir, &metadata).unwrap();
    assert_eq!(read_metadata(&dir).unwrap(), metadata);
    assert!(
        std::fs::read_to_string(dir.join(METADATA_FILE))
            .unwrap()
            .contains("walls_as_particles")
    );

    // Broken JSON and inconsistent values name the file (and the key).
    std::fs::write(dir.join(METADATA_FILE), "{\"dim\": 2,").unwrap();
    let err = read_metadata(&dir).unwrap_err();
    assert!(
        matches!(err, DataError::Json { .. }) && err.to_string().contains(METADATA_FILE),
        "{err}"
    );
    let mut bad = metadata.clone();
    bad.vel_mean = vec![0.0; 3];
    let err = write_metadata(&dir, &bad).unwrap_err();
    assert!(err.to_string().contains("vel_mean"), "{err}");
    let mut bad = metadata.clone();
    bad.format_version = 2;
    let err = write_metadata(&dir, &bad).unwrap_err();
    assert!(err.to_string().contains("format_version"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn export_npz_holds_every_trajectory_of_the_split() {
    let dir = temp_dir("dataset-export-npz");
    let written = write_sample_dataset(&dir, &[("train", 3)], 4, 2);
    let dataset = Dataset::open(&dir).unwrap();
    let out = dir.join("train.npz");
    assert_eq!(export_npz(&dataset, "train", &out).unwrap(), 3);
    let arrays = phi_io::npz::read_npz(&out).unwrap();
    assert_eq!(arrays.len(), 6);
    for (i, traj) in written[0].iter().enumerate() {
        let (name, position) = &arrays[2 * i];
        assert_eq!(name, &format!("trajectory_{i}_position"));
        assert_eq!(position.shape, [4, traj.particles, 2]);
        assert_eq!(position.as_f32().unwrap(), traj.position);
        let (name, types) = &arrays[2 * i + 1];
        assert_eq!(name, &format!("trajectory_{i}_particle_type"));
        assert_eq!(types.as_i64().unwrap(), traj.particle_type);
    }
    if let Some(python) = python_with_numpy() {
        let script = format!(
            "import numpy as np\nd = np.load({:?})\nprint(sorted(d.keys())[0], d['trajectory_2_position'].shape)",
            out.display().to_string()
        );
        let printed = run_python(&python, &script);
        assert_eq!(printed.trim(), "trajectory_0_particle_type (4, 10, 2)");
    } else {
        println!("note: no Python with numpy; checked the export with our reader only");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// The error `Metadata::validate` gives after `edit`, as `key: reason`.
fn validation_error(edit: impl FnOnce(&mut Metadata)) -> String {
    let mut metadata = Metadata::new(2);
    metadata.splits.insert("train".into(), 2);
    metadata.vel_std = vec![1e-3, 2e-3];
    metadata.acc_std = vec![1e-4, 2e-4];
    let path = std::path::Path::new("data/metadata.json");
    metadata.validate(path).unwrap();
    edit(&mut metadata);
    match metadata.validate(path).unwrap_err() {
        DataError::Metadata { path, key, reason } => {
            assert_eq!(path, std::path::Path::new("data/metadata.json"));
            format!("{key}: {reason}")
        }
        other => panic!("expected a metadata error, got {other}"),
    }
}

#[test]
fn metadata_values_out_of_range_are_errors_naming_the_key() {
    for (scale, shown) in [(0.0, "0"), (-0.025, "-0.025"), (f64::INFINITY, "inf")] {
        let msg = validation_error(|m| m.position_scale = scale);
        assert_eq!(
            msg,
            format!("position_scale: {shown} (must be a positive number)")
        );
    }
    let msg = validation_error(|m| m.bounds[1] = [0.9, 0.1]);
    assert!(
        msg.starts_with("bounds[1]: [0.9, 0.1] is empty or reversed"),
        "{msg}"
    );
    let msg = validation_error(|m| m.bounds[0] = [0.5, 0.5]);
    assert!(msg.starts_with("bounds[0]: [0.5, 0.5] is empty"), "{msg}");
    let msg = validation_error(|m| m.bounds[0] = [f64::NEG_INFINITY, 0.9]);
    assert_eq!(msg, "bounds[0]: [-inf, 0.9] is not finite");
    let msg = validation_error(|m| m.position_offset = f64::NAN);
    assert_eq!(msg, "position_offset: NaN is not finite");
    let msg = validation_error(|m| m.default_connectivity_radius = 0.0);
    assert!(msg.starts_with("default_connectivity_radius: 0 "), "{msg}");
    let msg = validation_error(|m| m.vel_std = vec![0.0, 0.0]);
    assert!(
        msg.starts_with("vel_std: [0.0, 0.0] for a train split of 2"),
        "{msg}"
    );
    let msg = validation_error(|m| m.acc_std = vec![1e-4, -1e-4]);
    assert!(msg.contains("negative standard deviation"), "{msg}");
    // Without a training split there are no statistics to have: zeros are what `new` writes.
    let mut test_only = Metadata::new(2);
    test_only.splits.insert("test".into(), 1);
    test_only.validate(std::path::Path::new("m.json")).unwrap();
}

#[test]
fn a_file_moved_to_another_split_or_index_is_refused() {
    let dir = temp_dir("dataset-identity");
    write_sample_dataset(&dir, &[("train", 2), ("valid", 2)], 4, 2);
    Dataset::open(&dir).unwrap();
    let train0 = Dataset::trajectory_path(&dir, "train", 0);
    let train1 = Dataset::trajectory_path(&dir, "train", 1);
    let valid0 = Dataset::trajectory_path(&dir, "valid", 0);
    let original = std::fs::read(&valid0).unwrap();

    // Another split's file of the same index: only its seed tells.
    std::fs::copy(&train0, &valid0).unwrap();
    let (path, msg) = open_error(&dir);
    assert!(path.ends_with("valid/traj_00000.npz"), "{path}");
    assert!(
        msg.starts_with("seeds.valid: the file stores seed"),
        "{msg}"
    );
    std::fs::write(&valid0, &original).unwrap();
    Dataset::open(&dir).unwrap();

    // Two files of a split swapped.
    let (a, b) = (
        std::fs::read(&train0).unwrap(),
        std::fs::read(&train1).unwrap(),
    );
    std::fs::write(&train0, &b).unwrap();
    std::fs::write(&train1, &a).unwrap();
    let (path, msg) = open_error(&dir);
    assert!(path.ends_with("train/traj_00000.npz"), "{path}");
    assert!(
        msg.starts_with("splits.train: the file stores index 1 instead of 0"),
        "{msg}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_huge_claimed_count_is_a_missing_file_not_an_allocation() {
    let dir = temp_dir("dataset-huge-count");
    write_sample_dataset(&dir, &[("train", 2)], 4, 2);
    edit_metadata(&dir, |m| {
        *m.splits.get_mut("train").unwrap() = 1_000_000_000_000_000
    });
    let (_, msg) = open_error(&dir);
    assert!(
        msg.starts_with("splits.train: lists 1000000000000000 trajectories but 'traj_00002.npz'"),
        "{msg}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
