//! Does training learn? The cheapest signal, end to end through the command line: FLIP data of
//! falling blocks and pools (`phi dataset generate`), a small model trained briefly on it
//! (`phi train`), and its one-step predictions for a block in free fall and a pool at rest
//! (`phi model probe`), whose truths are gravity and zero.

use std::path::Path;

use super::{ok, phi, scratch};

/// Table 5.1 cut down to blocks falling from rest, half of them above a pool, no obstacles:
/// 30 frames, so most particle-frames are free fall or rest, with some impacts.
const GENERATOR: &str = r#"steps = 30
pool_probability = 0.5
pool_height = [3, 5]
block_size = [4, 8]
multiple_blocks_probability = 0.0
obstacle_probability = 0.0
velocity_probability = 0.0
"#;

/// The CPU preset's recipe (clipping, warm-up) on a small network: 16 wide, two
/// message-passing steps, a moving average of the weights.
const PRESET: &str = r#"description = "a small model that must learn free fall and rest"

[model]
input_velocities = 5
latent_size = 16
hidden_size = 16
hidden_layers = 2
message_passing_steps = 2
embedding_size = 16
boundary_features = true
noise_std = 0.0
seed = 0

[training]
steps = 800
batch_size = 2
seed = 0
extra_steps = 0
log_every = 100
ema_decay = 0.99

[optimizer]
beta1 = 0.9
beta2 = 0.999
eps = 1e-8
clip_norm = 1.0

[optimizer.learning_rate]
initial = 1e-3
final_rate = 1e-5
decay_steps = 1e4
warmup_steps = 200

[checkpoints]
every = 800
keep = 1

[screening]
every = 0
split = "valid"
trajectories = 1
window_stride = 20
rollout_steps = 20
select_by = "rollout_mse"

[data]
split = "train"
cache_mib = 64
read_ahead = 2
"#;

fn generate(dir: &Path, split: &str, count: &str) {
    ok(phi()
        .args(["-q", "dataset", "generate", "--out"])
        .arg(dir.join("data"))
        .args([
            "--split",
            split,
            "--trajectories",
            count,
            "--threads",
            "1",
            "--config",
        ])
        .arg(dir.join("generator.toml"))
        .output()
        .unwrap());
}

/// `(along gravity, across gravity, resting mean, resting rms)` of the probe of `model`, as
/// fractions of `|g|`, and the same of the mean-acceleration floor.
fn probe(dir: &Path, model: &Path) -> ([f64; 4], [f64; 4]) {
    let report = dir.join("probe.json");
    ok(phi()
        .args(["-q", "model", "probe", "--data"])
        .arg(dir.join("data"))
        .arg("--model")
        .arg(model)
        .arg("--json")
        .arg(&report)
        .output()
        .unwrap());
    let rows: serde_json::Value = serde_json::from_slice(&std::fs::read(&report).unwrap()).unwrap();
    let rows = rows.as_array().unwrap();
    let read = |label: Option<&str>| {
        let row = rows
            .iter()
            .find(|r| label.is_none_or(|l| r["label"] == l))
            .unwrap();
        let r = &row["result"];
        let g = r["gravity"]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap().powi(2))
            .sum::<f64>()
            .sqrt();
        [
            r["falling_along_gravity"].as_f64().unwrap(),
            r["falling_across_gravity"].as_f64().unwrap(),
            r["resting_over_gravity"].as_f64().unwrap(),
            r["resting_rms"].as_f64().unwrap() / g,
        ]
    };
    (read(None), read(Some("mean-acceleration")))
}

#[test]
fn a_small_model_trained_briefly_on_flip_data_learns_free_fall_and_rest() {
    let dir = scratch("learning");
    std::fs::write(dir.join("generator.toml"), GENERATOR).unwrap();
    std::fs::write(dir.join("preset.toml"), PRESET).unwrap();
    generate(&dir, "train", "24");
    generate(&dir, "valid", "1");
    let run = dir.join("run");
    ok(phi()
        .args(["-q", "train", "--data"])
        .arg(dir.join("data"))
        .arg("--config")
        .arg(dir.join("preset.toml"))
        .arg("--out")
        .arg(&run)
        .output()
        .unwrap());
    let averaged = run.join("checkpoints/step-0000000800/average");
    let ([along, across, resting, resting_rms], floor) = probe(&dir, &averaged);
    // Gravity within 5 %, no sideways push beyond 5 % of it, the pool still within 5 %.
    assert!((along - 1.0).abs() < 0.05, "free fall along g: {along}");
    assert!(across < 0.05, "free fall across g: {across}");
    assert!(resting < 0.05, "the pool's mean: {resting}");
    assert!(resting_rms < 0.1, "the pool's jitter: {resting_rms}");
    // The data's mean acceleration (a floor that does not look at the scene) reads neither.
    assert!(floor[0] < 0.5 && floor[2] > 0.1, "the floor: {floor:?}");
}
