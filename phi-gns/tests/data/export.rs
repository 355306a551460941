//! The exports for geoelements/gns and LagrangeBench: file structure checked here, and, where a
//! Python with numpy is found (`$PHI_PYTHON` first), the files read by `scripts/check_exports.py`
//! with the tools' own reading logic.

use std::path::{Path, PathBuf};
use std::process::Command;

use phi_gns::data::export::{
    GNS_KINEMATIC, GNS_WATER, LB_FLUID, LB_SOLID_WALL, export_gns, export_lagrangebench_arrays,
    lagrangebench_metadata,
};
use phi_gns::data::{Dataset, LIQUID, Trajectory};
use phi_io::npz::{NpyArray, NpzReader, read_npz};
use phi_io::pickle::object_array_npy;

use crate::common::{assert_rel_close, python_with_numpy, temp_dir, write_sample_dataset};

fn check_script() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../scripts/check_exports.py")
}

/// Runs `check_exports.py FORMAT DIR` and returns its JSON lines; `None` without numpy (or,
/// for `needs`, without that module).
fn run_check(format: &str, dir: &Path, needs: &str) -> Option<Vec<serde_json::Value>> {
    let python = python_with_numpy()?;
    let has = Command::new(&python)
        .args(["-c", &format!("import {needs}")])
        .output()
        .is_ok_and(|o| o.status.success());
    if !has {
        println!(
            "note: no {needs} in {}; structure checked only",
            python.display()
        );
        return None;
    }
    let out = Command::new(&python)
        .arg(check_script())
        .arg(format)
        .arg(dir)
        .output()
        .expect("run check_exports.py");
    assert!(
        out.status.success(),
        "check_exports.py {format} failed:\n{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    Some(
        String::from_utf8_lossy(&out.stdout)
            .lines()
            .map(|l| serde_json::from_str(l).expect("a JSON line"))
            .collect(),
    )
}

fn position_sum(traj: &Trajectory) -> f64 {
    traj.position.iter().map(|&x| f64::from(x)).sum()
}

#[test]
fn gns_export_holds_position_and_type_pairs_and_gns_metadata() {
    let dir = temp_dir("export-gns");
    let (data, out) = (dir.join("data"), dir.join("gns"));
    let written = write_sample_dataset(&data, &[("train", 2), ("test", 1)], 8, 2);
    let dataset = Dataset::open(&data).unwrap();
    let mut ticks = 0;
    let counts = export_gns(&dataset, &out, &mut || ticks += 1).unwrap();
    assert_eq!(counts, [("test".to_string(), 1), ("train".to_string(), 2)]);
    assert_eq!(ticks, 3);

    // Each entry is the object array [positions f32 [T, N, D], types i64 [N]] with gns's types.
    for (split, trajectories) in [("train", &written[0]), ("test", &written[1])] {
        let path = out.join(format!("{split}.npz"));
        let mut npz = NpzReader::open(&path).unwrap();
        let names: Vec<String> = npz.names().map(str::to_string).collect();
        let expected: Vec<String> = (0..trajectories.len())
            .map(|i| format!("trajectory_{i}"))
            .collect();
        assert_eq!(names, expected);
        for traj in trajectories {
            let positions = NpyArray::new(
                vec![traj.frames, traj.particles, traj.dim],
                traj.position.clone(),
            )
            .unwrap();
            let types: Vec<i64> = traj
                .particle_type
                .iter()
                .map(|&t| {
                    if t == LIQUID {
                        GNS_WATER
                    } else {
                        GNS_KINEMATIC
                    }
                })
                .collect();
            assert!(types.contains(&GNS_WATER) && types.contains(&GNS_KINEMATIC));
            let want = object_array_npy(&[&positions, &NpyArray::from_vec(types)]).unwrap();
            let got = npz
                .read_npy_bytes(&format!("trajectory_{}", traj.index))
                .unwrap();
            assert_eq!(got, want, "{split} trajectory {}", traj.index);
        }
    }

    // metadata.json: exactly gns's nine keys, with the dataset's values.
    let text = std::fs::read_to_string(out.join("metadata.json")).unwrap();
    let json: serde_json::Value = serde_json::from_str(&text).unwrap();
    let mut keys: Vec<&str> = json
        .as_object()
        .unwrap()
        .keys()
        .map(String::as_str)
        .collect();
    keys.sort_unstable();
    assert_eq!(
        keys,
        [
            "acc_mean",
            "acc_std",
            "bounds",
            "default_connectivity_radius",
            "dim",
            "dt",
            "sequence_length",
            "vel_mean",
            "vel_std"
        ]
    );
    let m = dataset.metadata();
    assert_eq!(json["sequence_length"], 7);
    assert_eq!(json["vel_std"], serde_json::json!(m.vel_std));
    assert_eq!(json["bounds"], serde_json::json!(m.bounds));

    if let Some(lines) = run_check("gns", &out, "numpy") {
        assert_eq!(lines.len(), 2);
        for line in &lines {
            let trajectories = if line["split"] == "train" {
                &written[0]
            } else {
                &written[1]
            };
            assert_eq!(line["trajectories"], trajectories.len());
            // SamplesDataset: frames − 6 samples per trajectory.
            assert_eq!(line["samples"], trajectories.len() * (8 - 6));
            for (item, traj) in line["items"].as_array().unwrap().iter().zip(trajectories) {
                assert_eq!(item["frames"], 8);
                assert_eq!(item["particles"], traj.particles);
                assert_eq!(item["kinematic"], 3);
                assert_eq!(item["types"], serde_json::json!([3, 5]));
                let sum = item["position_sum"].as_f64().unwrap();
                assert_rel_close(sum, position_sum(traj), 1e-12, "position sum");
            }
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn lagrangebench_arrays_and_metadata_follow_its_layout() {
    let dir = temp_dir("export-lagrangebench");
    let data = dir.join("data");
    let written = write_sample_dataset(&data, &[("train", 3)], 6, 2);
    let dataset = Dataset::open(&data).unwrap();
    let file = dir.join("train-arrays.npz");
    let count = export_lagrangebench_arrays(&dataset, "train", &file, &mut || {}).unwrap();
    assert_eq!(count, 3);
    let arrays = read_npz(&file).unwrap();
    assert_eq!(arrays.len(), 6);
    for (i, traj) in written[0].iter().enumerate() {
        let (name, position) = &arrays[2 * i];
        assert_eq!(name, &format!("{i:05}/position"));
        assert_eq!(position.shape, [6, traj.particles, 2]);
        assert_eq!(position.as_f32().unwrap(), traj.position);
        let (name, types) = &arrays[2 * i + 1];
        assert_eq!(name, &format!("{i:05}/particle_type"));
        let expected: Vec<i64> = traj
            .particle_type
            .iter()
            .map(|&t| if t == LIQUID { LB_FLUID } else { LB_SOLID_WALL })
            .collect();
        assert_eq!(types.as_i64().unwrap(), expected);
    }

    let m = lagrangebench_metadata(&dataset).unwrap();
    let most = written[0].iter().map(|t| t.particles).max().unwrap();
    assert_eq!(m["num_particles_max"], most);
    assert_eq!(
        m["periodic_boundary_conditions"],
        serde_json::json!([false, false])
    );
    assert_eq!(m["write_every"], 1);
    assert_eq!(m["sequence_length_train"], 5);
    assert_eq!(m["num_trajs_train"], 3);
    // No particles_per_cell in this generator: dx is the cell size.
    assert_eq!(m["dx"], dataset.metadata().position_scale);
    assert_eq!(m["acc_std"], serde_json::json!(dataset.metadata().acc_std));
    let _ = std::fs::remove_dir_all(&dir);
}
