//! `phi model init` end to end, on tiny datasets.

use std::path::Path;
use std::process::Output;

use phi::phi_core::backend::ndarray::NdArray;
use phi::phi_gns::data::{
    Dataset, LIQUID, Metadata, OBSTACLE, Trajectory, TrajectoryStats, Variant, read_metadata,
    write_metadata, write_trajectory,
};
use phi::phi_gns::model::{load_model, read_spec};

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
    let mut metadata = Metadata::new(dim);
    metadata.bounds = vec![bounds; dim];
    metadata.sequence_length = 9;
    metadata.variant = variant;
    metadata.splits.insert("test".into(), 2);
    let mut state = 0x2545_f491_4f6c_dd1du64;
    let mut jitter = move || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((state >> 40) as f64 / (1u64 << 24) as f64 - 0.5) as f32 * 2e-3
    };
    let (lo, width) = (bounds[0] as f32, (bounds[1] - bounds[0]) as f32);
    let mut total = TrajectoryStats::new(dim);
    std::fs::create_dir_all(dir.join("test")).unwrap();
    for index in 0..2 {
        let (liquid, obstacles) = (12, 4);
        let mut types = vec![LIQUID; liquid];
        types.extend([OBSTACLE; 4]);
        let mut position = Vec::new();
        for t in 0..10 {
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
        let trajectory = Trajectory::new(dim, position, types, 100 + index as u64, index).unwrap();
        let stats = TrajectoryStats::of(&trajectory);
        total.merge(&stats).unwrap();
        let path = Dataset::trajectory_path(dir, "test", index);
        write_trajectory(&path, &trajectory, &stats).unwrap();
    }
    metadata.set_statistics(&total).unwrap();
    write_metadata(dir, &metadata).unwrap();
}

fn init(data: &Path, out: &Path, extra: &[&str]) -> Output {
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

/// The standard error of a run that must have failed.
fn failed(output: Output) -> String {
    assert!(
        !output.status.success(),
        "the command succeeded: {}",
        String::from_utf8_lossy(&output.stdout)
    );
    String::from_utf8_lossy(&output.stderr).into_owned()
}

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
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
    // Its own output is rewritten, to the same bytes.
    let weights = std::fs::read(model.join("model.safetensors")).unwrap();
    ok(init(&data, &model, &["--seed", "3"]));
    assert_eq!(
        std::fs::read(model.join("model.safetensors")).unwrap(),
        weights
    );
    ok(init(&data, &model, &["--seed", "4"]));
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
    ok(init(&walls, &m, &["--boundary-features"]));
    assert!(read_spec(&m).unwrap().config.boundary_features);

    // A bad size names the option.
    let stderr = failed(init(&data, &dir.join("bad"), &["--hidden", "0"]));
    assert!(stderr.contains("--hidden"), "{stderr}");
    // Directories it did not write are refused, and left as they were.
    let foreign = dir.join("foreign");
    std::fs::create_dir_all(&foreign).unwrap();
    std::fs::write(foreign.join("notes.txt"), "mine").unwrap();
    let stderr = failed(init(&data, &foreign, &[]));
    assert!(
        stderr.contains("notes.txt") && stderr.contains("did not write"),
        "{stderr}"
    );
    let mut trained = json(&model.join("model.json"));
    trained["provenance"] = serde_json::json!({"made_by": "a training run"});
    std::fs::write(model.join("model.json"), trained.to_string()).unwrap();
    let stderr = failed(init(&data, &model, &[]));
    assert!(
        stderr.contains("model.json") && stderr.contains("a training run"),
        "{stderr}"
    );
    assert_eq!(json(&model.join("model.json")), trained);
    let _ = std::fs::remove_dir_all(dir);
}
