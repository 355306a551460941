//! `phi model init` and `phi rollout` end to end, on tiny datasets and models.

use std::path::Path;
use std::process::{Command, Output};

use phi::output::{NpyArray, read_npz};
use phi::phi_core::backend::ndarray::NdArray;
use phi::phi_core::tensor::Tensor;
use phi::phi_gns::data::{
    Dataset, LIQUID, Metadata, OBSTACLE, Trajectory, TrajectoryStats, Variant, read_metadata,
    write_metadata, write_trajectory,
};
use phi::phi_gns::model::{load_model, read_spec, save_model};

use super::{ok, phi, scratch};

/// The options of a tiny model.
const TINY: [&str; 6] = [
    "--latent",
    "16",
    "--hidden",
    "16",
    "--message-passing-steps",
    "2",
];

/// A hand-made dataset in `dir`: two test trajectories of 10 frames, 12 liquid particles
/// falling with some jitter beside 4 static obstacle particles, in `dim` dimensions, every axis
/// within `bounds`.
fn tiny_dataset(dir: &Path, dim: usize, bounds: [f64; 2], variant: Variant) {
    tiny_dataset_with(dir, dim, bounds, variant, &[("test", 2)], 10);
}

/// A hand-made dataset in `dir` with `splits` (name, trajectories) of `frames` frames each: 12
/// liquid particles falling with some jitter beside 4 static obstacle particles, in `dim`
/// dimensions, every axis within `bounds`; the statistics are those of all trajectories.
pub(super) fn tiny_dataset_with(
    dir: &Path,
    dim: usize,
    bounds: [f64; 2],
    variant: Variant,
    splits: &[(&str, usize)],
    frames: usize,
) {
    let mut metadata = Metadata::new(dim);
    metadata.bounds = vec![bounds; dim];
    metadata.sequence_length = frames - 1;
    metadata.variant = variant;
    let mut state = 0x2545_f491_4f6c_dd1du64;
    let mut jitter = move || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((state >> 40) as f64 / (1u64 << 24) as f64 - 0.5) as f32 * 2e-3
    };
    let (lo, width) = (bounds[0] as f32, (bounds[1] - bounds[0]) as f32);
    let mut total = TrajectoryStats::new(dim);
    for &(split, count) in splits {
        metadata.splits.insert(split.into(), count);
        std::fs::create_dir_all(dir.join(split)).unwrap();
        for index in 0..count {
            let (liquid, obstacles) = (12, 4);
            let mut types = vec![LIQUID; liquid];
            types.extend([OBSTACLE; 4]);
            let mut position = Vec::new();
            for t in 0..frames {
                let fall = 0.5e-3 * (t * t) as f32;
                for i in 0..liquid {
                    for a in 0..dim {
                        let grid = 0.01 * ((i >> (2 * a)) % 4) as f32;
                        let down = if a == 1 { fall } else { 0.0 };
                        position.push(lo + 0.5 * width + grid - down + jitter());
                    }
                }
                for j in 0..obstacles {
                    for a in 0..dim {
                        let row = if a == 0 { 0.01 * j as f32 } else { 0.0 };
                        position.push(lo + 0.2 * width + row);
                    }
                }
            }
            let trajectory =
                Trajectory::new(dim, position, types, 100 + index as u64, index).unwrap();
            let stats = TrajectoryStats::of(&trajectory);
            total.merge(&stats).unwrap();
            let path = Dataset::trajectory_path(dir, split, index);
            write_trajectory(&path, &trajectory, &stats).unwrap();
        }
    }
    metadata.set_statistics(&total).unwrap();
    write_metadata(dir, &metadata).unwrap();
}

pub(super) fn init(data: &Path, out: &Path, extra: &[&str]) -> Output {
    phi()
        .args(["model", "init", "--data"])
        .arg(data)
        .arg("--out")
        .arg(out)
        .args(TINY)
        .args(extra)
        .output()
        .unwrap()
}

fn rollout(model: &Path, data: &Path, out: &Path, extra: &[&str]) -> Output {
    let mut command: Command = phi();
    command
        .arg("rollout")
        .arg("--model")
        .arg(model)
        .arg("--data")
        .arg(data)
        .arg("--out")
        .arg(out)
        .args(extra);
    command.output().unwrap()
}

/// The standard error of a run that must have failed.
pub(super) fn failed(output: Output) -> String {
    assert!(
        !output.status.success(),
        "the command succeeded: {}",
        String::from_utf8_lossy(&output.stdout)
    );
    String::from_utf8_lossy(&output.stderr).into_owned()
}

pub(super) fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

fn array(arrays: &[(String, NpyArray)], name: &str) -> NpyArray {
    arrays
        .iter()
        .find(|(n, _)| n == name)
        .map(|(_, a)| a.clone())
        .unwrap_or_else(|| panic!("no array '{name}'"))
}

/// The position MSE of each frame recomputed from `rollout.npz`: over the liquid particles and
/// the dimensions.
fn recomputed_mse(arrays: &[(String, NpyArray)]) -> Vec<f64> {
    let (predicted, truth) = (
        array(arrays, "predicted_position"),
        array(arrays, "true_position"),
    );
    let types = array(arrays, "particle_type");
    let types = types.as_i64().unwrap();
    let [steps, n, dim] = predicted.shape[..] else {
        panic!("predicted_position is not [steps, N, dim]")
    };
    let (p, t) = (predicted.as_f32().unwrap(), truth.as_f32().unwrap());
    (0..steps)
        .map(|s| {
            let mut sum = 0.0f64;
            let mut count = 0;
            for i in (0..n).filter(|&i| types[i] == LIQUID) {
                for a in 0..dim {
                    let k = (s * n + i) * dim + a;
                    sum += (f64::from(p[k]) - f64::from(t[k])).powi(2);
                    count += 1;
                }
            }
            sum / count as f64
        })
        .collect()
}

#[test]
fn model_init_writes_a_seeded_model_for_the_dataset() {
    let dir = scratch("model-init");
    let data = dir.join("data");
    tiny_dataset(&data, 2, [0.1, 0.9], Variant::Obstacles);
    let model = dir.join("model");
    let stdout = ok(init(&data, &model, &["--seed", "3"]));
    let loaded = load_model::<NdArray>(&model, &Default::default()).unwrap();
    let count = loaded.params().scalar_count();
    assert!(
        stdout.contains(&format!("model: {count} parameters")),
        "{stdout}"
    );
    let spec = read_spec(&model).unwrap();
    let metadata = read_metadata(&data).unwrap();
    let c = &spec.config;
    assert_eq!(
        (c.latent_size, c.hidden_size, c.message_passing_steps),
        (16, 16, 2)
    );
    // The rest are the thesis' sizes and the dataset's facts.
    assert_eq!(
        (c.hidden_layers, c.input_velocities, c.embedding_size),
        (2, 5, 16)
    );
    assert_eq!(c.connectivity_radius, metadata.default_connectivity_radius);
    assert!(c.boundary_features);
    assert_eq!((c.dim, c.particle_types, spec.seed), (2, 2, 3));
    assert_eq!(spec.bounds, metadata.bounds);
    assert_eq!(spec.normalisation.acc_std, metadata.acc_std);
    assert_eq!(spec.provenance["made_by"], "phi model init");
    // Its own output is refused without --force and rewritten with it, to the same bytes; a
    // temporary file of a killed write goes with it.
    let weights = std::fs::read(model.join("model.safetensors")).unwrap();
    let stderr = failed(init(&data, &model, &["--seed", "3"]));
    assert!(
        stderr.contains("previous `phi model init` output") && stderr.contains("--force"),
        "{stderr}"
    );
    std::fs::write(model.join(".model.safetensors.tmp-77"), "").unwrap();
    ok(init(&data, &model, &["--seed", "3", "--force"]));
    assert_eq!(
        std::fs::read(model.join("model.safetensors")).unwrap(),
        weights
    );
    assert!(!model.join(".model.safetensors.tmp-77").exists());
    ok(init(&data, &model, &["--seed", "4", "--force"]));
    assert_ne!(
        std::fs::read(model.join("model.safetensors")).unwrap(),
        weights
    );

    // Walls as particles: no boundary features unless asked for.
    let walls = dir.join("walls");
    tiny_dataset(&walls, 2, [0.1, 0.9], Variant::WallsAsParticles);
    let m = dir.join("walls-model");
    ok(init(&walls, &m, &["--radius", "0.05"]));
    let spec = read_spec(&m).unwrap();
    assert!(!spec.config.boundary_features);
    assert_eq!(spec.config.connectivity_radius, 0.05);
    ok(init(&walls, &m, &["--boundary-features", "--force"]));
    assert!(read_spec(&m).unwrap().config.boundary_features);

    // The boundary features' horizon: written only when it is not DeepMind's R.
    assert!(
        !json(&model.join("model.json"))["config"]
            .as_object()
            .unwrap()
            .contains_key("boundary_horizon")
    );
    let far = dir.join("far");
    let stdout = ok(init(&data, &far, &["--boundary-horizon", "4"]));
    assert!(stdout.contains("boundary features on to 4 R"), "{stdout}");
    assert_eq!(read_spec(&far).unwrap().config.boundary_horizon, 4.0);
    assert_eq!(
        json(&far.join("model.json"))["config"]["boundary_horizon"],
        4.0
    );

    // A bad size names the option.
    let stderr = failed(init(&data, &dir.join("bad"), &["--hidden", "0"]));
    assert!(stderr.contains("--hidden"), "{stderr}");
    let stderr = failed(init(&data, &dir.join("bad"), &["--boundary-horizon", "0"]));
    assert!(stderr.contains("--boundary-horizon"), "{stderr}");
    // Directories it did not write are refused, even with --force, and left as they were: other
    // files, a model another command wrote, weights without a model.json.
    let foreign = dir.join("foreign");
    std::fs::create_dir_all(&foreign).unwrap();
    std::fs::write(foreign.join("notes.txt"), "mine").unwrap();
    let mut trained = json(&model.join("model.json"));
    trained["provenance"] = serde_json::json!({"made_by": "a training run"});
    std::fs::write(model.join("model.json"), trained.to_string()).unwrap();
    let bare = dir.join("bare");
    std::fs::create_dir_all(&bare).unwrap();
    std::fs::write(bare.join("model.safetensors"), "weights").unwrap();
    for force in [&[][..], &["--force"][..]] {
        let stderr = failed(init(&data, &foreign, force));
        assert!(
            stderr.contains("notes.txt") && stderr.contains("does not write"),
            "{stderr}"
        );
        let stderr = failed(init(&data, &model, force));
        assert!(
            stderr.contains("model.json") && stderr.contains("'a training run'"),
            "{stderr}"
        );
        let stderr = failed(init(&data, &bare, force));
        assert!(stderr.contains("no model.json"), "{stderr}");
    }
    assert_eq!(std::fs::read(foreign.join("notes.txt")).unwrap(), b"mine");
    assert_eq!(json(&model.join("model.json")), trained);
    assert_eq!(
        std::fs::read(bare.join("model.safetensors")).unwrap(),
        b"weights"
    );
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn rollout_writes_predictions_truth_mse_and_gif() {
    let dir = scratch("rollout");
    let data = dir.join("data");
    ok(phi()
        .args(["dataset", "generate", "--split", "test"])
        .args(["--trajectories", "2", "--steps", "30", "--out"])
        .arg(&data)
        .output()
        .unwrap());
    let model = dir.join("model");
    ok(init(&data, &model, &[]));
    let out = dir.join("rollouts");
    // Test scene 1 (a narrow gap between obstacles): 8 steps from frame 5.
    let args = [
        "--trajectory",
        "1",
        "--steps",
        "8",
        "--checkpoint-every",
        "3",
        "--frame-every",
        "2",
    ];
    let stdout = ok(rollout(&model, &data, &out, &args));
    let folder = out.join("test_1");
    let arrays = read_npz(folder.join("rollout.npz")).unwrap();
    let dataset = Dataset::open(&data).unwrap();
    let (truth, _) = dataset.read_with_stats("test", 1).unwrap();
    let (n, dim) = (truth.particles, truth.dim);
    let predicted = array(&arrays, "predicted_position");
    assert_eq!(predicted.shape, vec![8, n, dim]);
    let true_position = array(&arrays, "true_position");
    assert_eq!(true_position.shape, vec![8, n, dim]);
    assert_eq!(
        true_position.as_f32().unwrap(),
        &truth.position[6 * n * dim..14 * n * dim],
        "true_position holds frames 6..=13"
    );
    assert_eq!(array(&arrays, "start").as_i64().unwrap(), &[5]);
    assert_eq!(
        array(&arrays, "frame").as_i64().unwrap(),
        &[6, 7, 8, 9, 10, 11, 12, 13]
    );
    let types = array(&arrays, "particle_type");
    assert_eq!(types.as_i64().unwrap(), &truth.particle_type[..]);
    let (p, t) = (predicted.as_f32().unwrap(), true_position.as_f32().unwrap());
    assert!(p.iter().all(|x| x.is_finite()));
    let obstacles: Vec<usize> = (0..n)
        .filter(|&i| truth.particle_type[i] == OBSTACLE)
        .collect();
    assert!(!obstacles.is_empty(), "test scene 1 has obstacles");
    for s in 0..8 {
        for &i in &obstacles {
            let k = (s * n + i) * dim;
            assert_eq!(
                &p[k..k + dim],
                &t[k..k + dim],
                "kinematic particle {i}, step {s}"
            );
        }
    }
    assert_ne!(p, t, "an untrained model predicts the truth");

    let record = json(&folder.join("rollout.json"));
    assert_eq!(record["complete"], true);
    assert_eq!(record["reason"], serde_json::Value::Null);
    assert_eq!(record["steps"], 8);
    assert_eq!(record["backend"], "ndarray", "the default backend");
    assert_eq!(
        (record["start"].clone(), record["index"].clone()),
        (5.into(), 1.into())
    );
    assert_eq!(record["kinematic_particles"], obstacles.len());
    let expected = recomputed_mse(&arrays);
    let mse: Vec<f64> = record["mse"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    assert_eq!(mse.len(), 8);
    for (a, b) in mse.iter().zip(&expected) {
        assert!((a - b).abs() <= 1e-12 * b.abs(), "MSE {a} recomputed {b}");
    }
    let mean = expected.iter().sum::<f64>() / 8.0;
    let recorded_mean = record["mse_mean"].as_f64().unwrap();
    assert!((recorded_mean - mean).abs() <= 1e-12 * mean);
    assert!(
        stdout.contains(&format!("mean         {mean:.6e}")),
        "{stdout}"
    );
    // The compact table: the first, quartile and last steps.
    assert!(
        stdout.contains(&format!("      8     13  {:.6e}", expected[7])),
        "{stdout}"
    );
    assert!(
        !stdout.contains(&format!("{:.6e}", expected[2])),
        "{stdout}"
    );
    // The start frame and steps 2, 4, 6, 8; the trailer closes the GIF.
    assert_eq!(record["gif_pictures"], 5);
    let gif = std::fs::read(folder.join("rollout.gif")).unwrap();
    assert_eq!(&gif[..6], b"GIF89a");
    assert_eq!(gif.last(), Some(&0x3B));

    // Its own outputs are rewritten with --force; --mse-every-step prints every step, and -v
    // is the global flag (backtraces), which rollout accepts like every command.
    let stdout = ok(rollout(
        &model,
        &data,
        &out,
        &[
            "--trajectory",
            "1",
            "--steps",
            "8",
            "--mse-every-step",
            "-v",
            "--force",
        ],
    ));
    for e in &expected {
        assert!(stdout.contains(&format!("{e:.6e}")), "{stdout}");
    }
    // Another backend gives the same predictions to float tolerance.
    let burn = dir.join("burn");
    ok(rollout(
        &model,
        &data,
        &burn,
        &[
            "--index",
            "1",
            "--steps",
            "2",
            "--backend",
            "burn",
            "--frame-every",
            "0",
        ],
    ));
    let other = read_npz(burn.join("test_1/rollout.npz")).unwrap();
    let q = array(&other, "predicted_position");
    assert_eq!(q.shape, vec![2, n, dim]);
    let largest = q
        .as_f32()
        .unwrap()
        .iter()
        .zip(p)
        .fold(0.0f32, |m, (a, b)| m.max((a - b).abs()));
    assert!(largest < 1e-5, "burn and ndarray differ by {largest}");
    assert!(!burn.join("test_1/rollout.gif").exists());

    // The VTK series: the start frame and every third step, the prediction's points those of
    // rollout.npz, its velocity the backward difference of the predicted frames over dt.
    let vtk = dir.join("vtk");
    ok(rollout(
        &model,
        &data,
        &vtk,
        &[
            "--trajectory",
            "1",
            "--steps",
            "8",
            "--frame-every",
            "0",
            "--vtk-every",
            "3",
        ],
    ));
    let folder = vtk.join("test_1");
    let listed = |pvd: &str| -> Vec<String> {
        std::fs::read_to_string(folder.join(pvd))
            .unwrap()
            .lines()
            .filter(|l| l.contains("<DataSet"))
            .map(|l| {
                let at = l.find("file=\"").unwrap() + 6;
                l[at..at + l[at..].find('"').unwrap()].to_string()
            })
            .collect()
    };
    let files = listed("rollout.pvd");
    assert_eq!(files.len(), 3, "frames 5, 8 and 11: {files:?}");
    assert_eq!(listed("truth.pvd").len(), 3);
    let dt = dataset.metadata().dt as f32;
    let floats = |vtu: &str, name: &str| -> Vec<f32> {
        super::vtu_array(vtu, name)
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes(b.try_into().unwrap()))
            .collect()
    };
    let frame = |step: usize| -> &[f32] {
        match step {
            0 => &truth.position[5 * n * dim..6 * n * dim],
            s => &p[(s - 1) * n * dim..s * n * dim],
        }
    };
    for (file, step) in files.iter().zip([0, 3, 6]) {
        assert!(file.contains(&format!("{:05}", 5 + step)), "{file}");
        let vtu = std::fs::read_to_string(folder.join(file)).unwrap();
        let points = floats(&vtu, "Points");
        let padded: Vec<f32> = frame(step)
            .chunks(dim)
            .flat_map(|q| [q[0], q[1], 0.0])
            .collect();
        assert_eq!(points, padded, "{file}");
        let velocity = floats(&vtu, "velocity");
        let before = frame(step.saturating_sub(1));
        for i in 0..n {
            for a in 0..dim {
                let expected = (frame(step)[i * dim + a] - before[i * dim + a]) / dt;
                let got = velocity[i * 3 + a];
                assert!(
                    (got - expected).abs() <= 1e-5 * expected.abs().max(1.0),
                    "{file}: particle {i}, axis {a}: {got} vs {expected}"
                );
            }
        }
    }
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn a_model_for_another_dimension_or_bounds_is_refused() {
    let dir = scratch("rollout-mismatch");
    let (plane, space, wide) = (dir.join("2d"), dir.join("3d"), dir.join("wide"));
    tiny_dataset(&plane, 2, [0.1, 0.9], Variant::Obstacles);
    tiny_dataset(&space, 3, [0.1, 0.9], Variant::Obstacles);
    tiny_dataset(&wide, 2, [0.0, 1.0], Variant::Obstacles);
    let (m2, m3) = (dir.join("m2"), dir.join("m3"));
    ok(init(&plane, &m2, &[]));
    ok(init(&space, &m3, &[]));
    let out = dir.join("out");
    let stderr = failed(rollout(&m3, &plane, &out, &[]));
    assert!(
        stderr.contains("metadata.json")
            && stderr.contains("key 'dim'")
            && stderr.contains("made for 3, the dataset has 2"),
        "{stderr}"
    );
    let stderr = failed(rollout(&m2, &wide, &out, &[]));
    assert!(
        stderr.contains("key 'bounds'")
            && stderr.contains("[0.0, 1.0]")
            && stderr.contains("--bounds data"),
        "{stderr}"
    );
    assert!(!out.exists(), "a refused rollout wrote {}", out.display());
    // On another domain by choice: the particles stay farther than R from both domains' walls,
    // so the dataset's walls and the model's give the same predictions, bit for bit.
    let predicted = |choice: &str| {
        let out = dir.join(format!("other-domain-{choice}"));
        ok(rollout(
            &m2,
            &wide,
            &out,
            &["--steps", "3", "--bounds", choice],
        ));
        let arrays = read_npz(out.join("test_0/rollout.npz")).unwrap();
        array(&arrays, "predicted_position").data
    };
    assert_eq!(predicted("data"), predicted("model"));
    let stderr = failed(rollout(&m3, &plane, &out, &["--bounds", "data"]));
    assert!(stderr.contains("key 'dim'"), "{stderr}");
    // A 3D model on its own dataset rolls out (without a GIF: rendering is 2D).
    let stdout = ok(rollout(&m3, &space, &out, &["--steps", "2"]));
    assert!(!stdout.contains("rollout.gif"), "{stdout}");
    assert_eq!(json(&out.join("test_0/rollout.json"))["complete"], true);
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn rollout_refuses_foreign_outputs_and_missing_trajectories() {
    let dir = scratch("rollout-refusals");
    let data = dir.join("data");
    tiny_dataset(&data, 2, [0.1, 0.9], Variant::Obstacles);
    let model = dir.join("model");
    ok(init(&data, &model, &[]));
    let out = dir.join("out");
    // --index, the name before --trajectory, still works.
    for flag in ["--trajectory", "--index"] {
        let stderr = failed(rollout(&model, &data, &out, &[flag, "2"]));
        assert!(
            stderr.contains("--trajectory 2") && stderr.contains("split 'test' has 2 trajectories"),
            "{stderr}"
        );
    }
    let stderr = failed(rollout(&model, &data, &out, &["--split", "train"]));
    assert!(
        stderr.contains("--split train") && stderr.contains("its metadata.json lists test"),
        "{stderr}"
    );
    let stderr = failed(rollout(&model, &data, &out, &["--split", "../test"]));
    assert!(
        stderr.contains("--split") && stderr.contains("not a split name"),
        "{stderr}"
    );
    // A device that is not there (this is not a CUDA build, or it has no eighth GPU).
    let stderr = failed(rollout(&model, &data, &out, &["--device", "cuda:7"]));
    assert!(
        stderr.contains("--device cuda:7") && stderr.contains("not available"),
        "{stderr}"
    );
    let stderr = failed(rollout(&model, &data, &out, &["--steps", "5"]));
    assert!(
        stderr.contains("--steps 5") && stderr.contains("frame 9"),
        "{stderr}"
    );
    let stderr = failed(rollout(&model, &data, &out, &["--start", "4"]));
    assert!(stderr.contains("--start 4"), "{stderr}");
    assert!(!out.exists());

    ok(rollout(&model, &data, &out, &["--all"]));
    for i in 0..2 {
        assert_eq!(
            json(&out.join(format!("test_{i}/rollout.json")))["complete"],
            true
        );
    }
    // An earlier rollout is refused without --force and replaced with it: its files go (no
    // GIF this time), the other trajectory's folder and the other files of --out stay.
    std::fs::write(out.join("notes.txt"), "mine").unwrap();
    let other = std::fs::read(out.join("test_0/rollout.npz")).unwrap();
    let stderr = failed(rollout(&model, &data, &out, &["--trajectory", "1"]));
    assert!(
        stderr.contains("test_1")
            && stderr.contains("previous `phi rollout` output")
            && stderr.contains("--force"),
        "{stderr}"
    );
    assert!(out.join("test_1/rollout.gif").is_file());
    ok(rollout(
        &model,
        &data,
        &out,
        &["--trajectory", "1", "--frame-every", "0", "--force"],
    ));
    assert!(!out.join("test_1/rollout.gif").exists());
    assert_eq!(json(&out.join("test_1/rollout.json"))["complete"], true);
    assert_eq!(
        std::fs::read(out.join("test_0/rollout.npz")).unwrap(),
        other
    );
    assert_eq!(std::fs::read(out.join("notes.txt")).unwrap(), b"mine");

    // Files it did not write, beside its own or in place of them, are refused even with
    // --force, and kept.
    std::fs::write(out.join("test_1/notes.txt"), "mine").unwrap();
    for force in [&["--all"][..], &["--all", "--force"][..]] {
        let stderr = failed(rollout(&model, &data, &out, force));
        assert!(
            stderr.contains("notes.txt") && stderr.contains("does not write"),
            "{stderr}"
        );
    }
    assert_eq!(
        std::fs::read(out.join("test_0/rollout.npz")).unwrap(),
        other
    );
    let foreign = dir.join("foreign");
    std::fs::create_dir_all(foreign.join("test_0")).unwrap();
    std::fs::write(foreign.join("test_0/rollout.npz"), "not ours").unwrap();
    let stderr = failed(rollout(&model, &data, &foreign, &["--force"]));
    assert!(stderr.contains("no rollout.json"), "{stderr}");
    assert_eq!(
        std::fs::read(foreign.join("test_0/rollout.npz")).unwrap(),
        b"not ours"
    );
    let _ = std::fs::remove_dir_all(dir);
}

/// The tiny 2D dataset in `dir/data` and a model in `dir/model` of single dense layers (so that
/// nothing between an overflow and the output is a ReLU, which may map NaN to 0 as f32::max
/// does) whose tensors `replace` returns replaced.
fn doctored_model(
    dir: &Path,
    replace: impl Fn(&str, &Tensor<NdArray>) -> Option<Tensor<NdArray>>,
) -> (std::path::PathBuf, std::path::PathBuf) {
    let (data, model) = (dir.join("data"), dir.join("model"));
    tiny_dataset(&data, 2, [0.1, 0.9], Variant::Obstacles);
    ok(init(&data, &model, &["--hidden-layers", "0"]));
    let gns = load_model::<NdArray>(&model, &Default::default()).unwrap();
    let params = gns
        .params()
        .map(|name, t| replace(name, t).unwrap_or_else(|| t.clone()));
    save_model(&model, &gns.with_params(params).unwrap()).unwrap();
    (data, model)
}

#[test]
fn a_diverging_model_stops_with_the_frames_before() {
    let dir = scratch("rollout-diverging");
    // A decoder bias near the largest f32 throws the liquid ~1e35 units in the first step (still
    // finite); the next step's velocities overflow the node encoder, whose weights are all 1e3.
    let (data, model) = doctored_model(&dir, |name, t| {
        let fill = |v: f32| Tensor::from_vec(vec![v; t.numel()], &t.shape(), &t.device()).unwrap();
        match name {
            "decoder.0.bias" => Some(fill(3e38)),
            "encoder.node.0.weight" => Some(fill(1e3)),
            _ => None,
        }
    });

    let out = dir.join("out");
    let stderr = failed(rollout(&model, &data, &out, &["--checkpoint-every", "1"]));
    assert!(
        stderr.contains("rollout step 2 (frame 7)") && stderr.contains("non-finite"),
        "{stderr}"
    );
    let folder = out.join("test_0");
    let record = json(&folder.join("rollout.json"));
    assert_eq!(record["complete"], false);
    assert_eq!(record["failed_step"], 2);
    assert_eq!(record["steps"], 1);
    assert!(
        record["reason"].as_str().unwrap().contains("step 2"),
        "{record}"
    );
    let arrays = read_npz(folder.join("rollout.npz")).unwrap();
    let predicted = array(&arrays, "predicted_position");
    assert_eq!(predicted.shape, vec![1, 16, 2]);
    assert!(predicted.as_f32().unwrap().iter().all(|x| x.is_finite()));
    assert_eq!(array(&arrays, "frame").as_i64().unwrap(), &[6]);
    assert_eq!(record["mse"].as_array().unwrap().len(), 1);
    let gif = std::fs::read(folder.join("rollout.gif")).unwrap();
    assert_eq!(gif.last(), Some(&0x3B), "the GIF is closed");
    assert_eq!(record["gif_pictures"], 2);
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn clamped_walls_keep_a_sinking_model_in_the_box() {
    let dir = scratch("rollout-walls");
    // A decoder bias of −200 standard deviations along the vertical axis: the liquid falls
    // through the floor (y = 0.1) within the trajectory's four predicted steps.
    let (data, model) = doctored_model(&dir, |name, t| {
        (name == "decoder.0.bias")
            .then(|| Tensor::from_vec(vec![0.0, -200.0], &t.shape(), &t.device()).unwrap())
    });
    let liquid_y = |out: &Path| -> Vec<f32> {
        let arrays = read_npz(out.join("test_0/rollout.npz")).unwrap();
        let (p, types) = (
            array(&arrays, "predicted_position"),
            array(&arrays, "particle_type"),
        );
        let (p, types) = (
            p.as_f32().unwrap().to_vec(),
            types.as_i64().unwrap().to_vec(),
        );
        let n = types.len();
        p.chunks(2)
            .enumerate()
            .filter(|(k, _)| types[k % n] == LIQUID)
            .map(|(_, xy)| xy[1])
            .collect()
    };

    let open = dir.join("open");
    ok(rollout(&model, &data, &open, &["--frame-every", "0"]));
    assert!(
        json(&open.join("test_0/rollout.json"))
            .get("walls")
            .is_none()
    );
    let y = liquid_y(&open);
    assert!(
        y.iter().any(|&y| y < 0.1),
        "the open rollout stays above the floor: {y:?}"
    );

    let clamped = dir.join("clamped");
    ok(rollout(
        &model,
        &data,
        &clamped,
        &["--frame-every", "0", "--walls", "clamp"],
    ));
    assert_eq!(json(&clamped.join("test_0/rollout.json"))["walls"], "clamp");
    let y = liquid_y(&clamped);
    assert!(y.iter().all(|&y| y >= 0.1), "below the floor: {y:?}");
    assert!(y.contains(&0.1f32), "nothing stopped on the floor: {y:?}");

    // Pushed out of the obstacles too: the record names the dataset's cells.
    let pushed = dir.join("pushed");
    ok(rollout(
        &model,
        &data,
        &pushed,
        &[
            "--frame-every",
            "0",
            "--walls",
            "clamp",
            "--obstacles",
            "push",
        ],
    ));
    let record = json(&pushed.join("test_0/rollout.json"));
    let metadata = json(&data.join("metadata.json"));
    assert_eq!(record["obstacles"]["kind"], "push", "{record}");
    assert_eq!(
        record["obstacles"]["cell_size"], metadata["position_scale"],
        "{record}"
    );
    assert!(liquid_y(&pushed).iter().all(|&y| y >= 0.1));
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn model_average_writes_the_mean_weights_and_refuses_mismatched_models() {
    let dir = scratch("model-average");
    let data = dir.join("data");
    tiny_dataset(&data, 2, [0.1, 0.9], Variant::Obstacles);
    let (a, b, out) = (dir.join("a"), dir.join("b"), dir.join("mean"));
    ok(init(&data, &a, &["--seed", "1"]));
    ok(init(&data, &b, &["--seed", "2"]));
    let average = |extra: &[&Path]| {
        let mut command = phi();
        command.args(["model", "average", "--out"]).arg(&out);
        for m in extra {
            command.arg(m);
        }
        command.output().unwrap()
    };
    ok(average(&[&a, &b]));
    let device = Default::default();
    let [ma, mb, mean] = [&a, &b, &out].map(|d| load_model::<NdArray>(d, &device).unwrap());
    for (name, t) in mean.params().iter() {
        let (x, y) = (
            ma.params().get(name).to_vec(),
            mb.params().get(name).to_vec(),
        );
        for (k, v) in t.to_vec().iter().enumerate() {
            let expected = ((f64::from(x[k]) + f64::from(y[k])) / 2.0) as f32;
            assert_eq!(*v, expected, "{name}[{k}]");
        }
    }
    let spec = json(&out.join("model.json"));
    assert_eq!(spec["provenance"]["made_by"], "phi model average");
    assert_eq!(spec["config"], json(&a.join("model.json"))["config"]);
    // Its own output is replaced only with --force; another model's directory never.
    assert!(failed(average(&[&a, &b])).contains("--force"));
    let wide = dir.join("wide");
    ok(init(&data, &wide, &["--hidden-layers", "1"]));
    let err = failed(average(&[&a, &wide]));
    assert!(err.contains("config.hidden_layers"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}
