//! `phi train` end to end on a tiny dataset and model: the files of a run, exact resume after a
//! stop, a SIGINT and a SIGKILL, the refusals, and divergence.

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

use phi::phi_core::backend::Host;
use phi::phi_gns::data::Variant;

use super::rollout::tiny_dataset_with;
use super::{ok, phi, scratch};

/// A preset of a tiny model: 8 wide, one message-passing step; `steps`, a log row every 2 steps,
/// a checkpoint every 6, screening every 8 on one validation trajectory.
fn tiny_preset(dir: &Path, name: &str, extra: &str, steps: u64) -> PathBuf {
    let text = format!(
        r#"description = "a tiny test model"

[model]
input_velocities = 3
latent_size = 8
hidden_size = 8
hidden_layers = 1
message_passing_steps = 1
embedding_size = 4
boundary_features = true
noise_std = {noise}
seed = 3

[training]
steps = {steps}
batch_size = 2
seed = 11
extra_steps = {extra_steps}
log_every = 2{ema}{parallel}

[optimizer]
beta1 = 0.9
beta2 = 0.999
eps = 1e-8

[optimizer.learning_rate]
initial = {lr}
final_rate = 1e-5
decay_steps = 100

[checkpoints]
every = 6
keep = 2

[screening]
every = 8
split = "valid"
trajectories = 1
window_stride = 5
rollout_steps = 6
select_by = "rollout_mse"

[data]
split = "train"
cache_mib = 1
read_ahead = 2
"#,
        noise = if extra.contains("noise") {
            "1e-3"
        } else {
            "0.0"
        },
        extra_steps = if extra.contains("two-step") { 1 } else { 0 },
        ema = if extra.contains("ema") {
            "\nema_decay = 0.9"
        } else {
            ""
        },
        parallel = if extra.contains("parallel") {
            "\nparallel_graphs = true"
        } else {
            ""
        },
        lr = if extra.contains("diverge") {
            "1e9"
        } else {
            "1e-3"
        },
    );
    let path = dir.join(format!("{name}.toml"));
    std::fs::write(&path, text).unwrap();
    path
}

fn dataset(dir: &Path) -> PathBuf {
    let data = dir.join("data");
    tiny_dataset_with(
        &data,
        2,
        [0.1, 0.9],
        Variant::Obstacles,
        &[("train", 3), ("valid", 1)],
        20,
    );
    data
}

fn train(data: &Path, preset: &Path, out: &Path, extra: &[&str]) -> Output {
    phi()
        .args(["train", "--data"])
        .arg(data)
        .arg("--config")
        .arg(preset)
        .arg("--out")
        .arg(out)
        .args(extra)
        .output()
        .unwrap()
}

fn resume(out: &Path, extra: &[&str]) -> Output {
    phi()
        .args(["train", "--resume", "--out"])
        .arg(out)
        .args(extra)
        .output()
        .unwrap()
}

fn stderr(output: &Output) -> String {
    String::from_utf8_lossy(&output.stderr).into_owned()
}

/// The step and loss columns of `train.csv` (the timing column differs between runs).
fn losses(out: &Path) -> Vec<(String, String, String, String)> {
    let text = std::fs::read_to_string(out.join("train.csv")).unwrap();
    let mut lines = text.lines();
    assert_eq!(
        lines.next().unwrap(),
        "step,loss,learning_rate,steps_per_second,valid_mse_acc1,valid_rollout_mse,valid_emd"
    );
    lines
        .map(|l| {
            let c: Vec<&str> = l.split(',').collect();
            assert_eq!(c.len(), 7, "{l}");
            (c[0].into(), c[1].into(), c[4].into(), c[5].into())
        })
        .collect()
}

fn final_weights(out: &Path, step: u64) -> Vec<u8> {
    std::fs::read(
        out.join("checkpoints")
            .join(format!("step-{step:010}"))
            .join("model.safetensors"),
    )
    .unwrap()
}

#[test]
fn a_run_writes_its_log_checkpoints_and_best_model() {
    let dir = scratch("train-files");
    let data = dataset(&dir);
    let preset = tiny_preset(&dir, "tiny", "noise", 16);
    let out = dir.join("run");
    let stdout = ok(train(&data, &preset, &out, &[]));
    assert!(stdout.contains("16 steps"), "{stdout}");
    let record: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("train.json")).unwrap()).unwrap();
    assert_eq!(
        record["backend"],
        phi::backends::BackendKind::default_autodiff()
            .unwrap()
            .name(),
        "the default backend"
    );
    let rows = losses(&out);
    let steps: Vec<&str> = rows.iter().map(|r| r.0.as_str()).collect();
    assert_eq!(steps, ["2", "4", "6", "8", "10", "12", "14", "16"]);
    for (step, loss, acc, rollout) in &rows {
        let loss: f64 = loss.parse().unwrap();
        assert!(loss.is_finite() && loss > 0.0, "step {step}: loss {loss}");
        let screened = step == "8" || step == "16";
        assert_eq!(!acc.is_empty(), screened, "step {step}");
        assert_eq!(!rollout.is_empty(), screened, "step {step}");
    }
    // keep = 2: the checkpoints of steps 12 and 16 (the end) remain.
    let mut kept: Vec<String> = std::fs::read_dir(out.join("checkpoints"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    kept.sort();
    assert_eq!(kept, ["step-0000000012", "step-0000000016"]);
    for file in [
        "model.json",
        "model.safetensors",
        "optimizer.safetensors",
        "state.json",
    ] {
        assert!(
            out.join("checkpoints/step-0000000016").join(file).is_file(),
            "{file}"
        );
    }
    let best: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("best/best.json")).unwrap()).unwrap();
    assert_eq!(best["metric"], "valid_rollout_mse");
    let best_step = best["step"].as_u64().unwrap();
    assert!(best_step == 8 || best_step == 16, "{best}");
    assert!(out.join("best/model.safetensors").is_file());
    // The model directories are models `phi rollout` reads.
    let spec: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("best/model.json")).unwrap()).unwrap();
    assert_eq!(spec["provenance"]["made_by"], "phi train");
    assert_eq!(spec["config"]["noise_std"], 1e-3);
}

#[test]
fn a_stopped_and_resumed_run_has_the_uninterrupted_loss_curve_bit_for_bit() {
    let dir = scratch("train-resume");
    let data = dataset(&dir);
    for (variant, backend) in [
        ("noise", "burn"),
        ("two-step", "burn"),
        ("noise-ema", "burn"),
        ("two-step-noise-parallel", "burn"),
        ("noise", "tch"),
    ] {
        if !phi::backends::BackendKind::available()
            .iter()
            .any(|k| k.name() == backend)
        {
            continue;
        }
        let preset = tiny_preset(&dir, variant, variant, 20);
        let whole = dir.join(format!("{variant}-{backend}-whole"));
        ok(train(&data, &preset, &whole, &["--backend", backend]));
        let parts = dir.join(format!("{variant}-{backend}-parts"));
        // Stopped at step 9 (between checkpoints and between screenings), then resumed.
        ok(train(
            &data,
            &preset,
            &parts,
            &["--backend", backend, "--steps", "9"],
        ));
        ok(resume(&parts, &["--backend", backend, "--steps", "20"]));
        assert_eq!(losses(&parts), losses(&whole), "{variant} on {backend}");
        assert_eq!(
            final_weights(&parts, 20),
            final_weights(&whole, 20),
            "{variant} on {backend}"
        );
        if variant.contains("ema") {
            let average = |out: &Path| {
                std::fs::read(out.join("checkpoints/step-0000000020/average/model.safetensors"))
                    .unwrap()
            };
            assert_eq!(average(&parts), average(&whole), "the weight average");
            assert_ne!(
                average(&whole),
                final_weights(&whole, 20),
                "the average is not the last step's weights"
            );
            assert_eq!(
                std::fs::read(parts.join("best/model.safetensors")).unwrap(),
                std::fs::read(whole.join("best/model.safetensors")).unwrap(),
                "best/ holds the same average"
            );
        }
        // A total the run has reached trains nothing and changes nothing.
        let done = ok(resume(&parts, &["--backend", backend, "--steps", "12"]));
        assert!(done.contains("nothing to train"), "{done}");
        assert_eq!(losses(&parts), losses(&whole), "{variant} on {backend}");
    }
}

/// Runs `phi train` in the background until its log has a row of step ≥ `after`, then sends
/// `signal`; returns its output.
fn interrupt(data: &Path, preset: &Path, out: &Path, after: u64, signal: &str) -> Output {
    let child = phi()
        .args(["train", "--data"])
        .arg(data)
        .arg("--config")
        .arg(preset)
        .arg("--out")
        .arg(out)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let started = Instant::now();
    loop {
        let logged = std::fs::read_to_string(out.join("train.csv"))
            .ok()
            .and_then(|t| {
                t.lines()
                    .last()
                    .and_then(|l| l.split(',').next()?.parse::<u64>().ok())
            })
            .unwrap_or(0);
        if logged >= after {
            break;
        }
        assert!(
            started.elapsed() < Duration::from_secs(120),
            "the run did not reach step {after}"
        );
        std::thread::sleep(Duration::from_millis(5));
    }
    let status = Command::new("kill")
        .args([signal, &child.id().to_string()])
        .status()
        .unwrap();
    assert!(status.success());
    child.wait_with_output().unwrap()
}

#[test]
fn a_run_interrupted_by_sigint_or_killed_resumes_to_the_same_curve() {
    let dir = scratch("train-signal");
    let data = dataset(&dir);
    let steps = 400;
    let preset = tiny_preset(&dir, "long", "noise", steps);
    let whole = dir.join("whole");
    ok(train(&data, &preset, &whole, &[]));
    // A run killed before its first periodic checkpoint resumes from the one of step 0.
    let rare = dir.join("rare.toml");
    let text = std::fs::read_to_string(&preset).unwrap();
    std::fs::write(&rare, text.replace("every = 6", "every = 100000")).unwrap();
    for (signal, preset, name) in [
        ("-INT", &preset, "int"),
        ("-TERM", &preset, "term"),
        ("-KILL", &preset, "kill"),
        ("-KILL", &rare, "kill-early"),
    ] {
        let out = dir.join(format!("signal-{name}"));
        let stopped = interrupt(&data, preset, &out, 30, signal);
        assert!(
            !stopped.status.success(),
            "{signal}: the run was not stopped"
        );
        if signal != "-KILL" {
            let message = stderr(&stopped);
            assert!(
                message.contains("interrupted at step") && message.contains("--resume"),
                "{signal}: {message}"
            );
        }
        let lock = out.join("train.lock");
        if signal != "-KILL" {
            assert!(
                !lock.exists(),
                "{signal}: a stopped run frees its directory"
            );
        }
        if name == "int" && cfg!(target_os = "linux") {
            // A directory held by a running process (pid 1 runs on every Linux system) is
            // refused, and its lock left as it is.
            std::fs::write(&lock, "1\n").unwrap();
            let refused = resume(&out, &[]);
            assert!(!refused.status.success(), "a held directory was resumed");
            let message = stderr(&refused);
            assert!(
                message.contains("in use by another `phi train` (process 1)"),
                "{message}"
            );
            assert_eq!(std::fs::read_to_string(&lock).unwrap(), "1\n");
            std::fs::remove_file(&lock).unwrap();
        }
        // A killed run's lock names a process that is gone: the resume takes it over.
        let done = ok(resume(&out, &[]));
        assert!(done.contains("steps in"), "{done}");
        assert!(!lock.exists(), "a finished run frees its directory");
        assert_eq!(losses(&out), losses(&whole), "{name}");
        assert_eq!(final_weights(&out, steps), final_weights(&whole, steps));
    }
}

#[test]
fn train_refuses_what_it_cannot_run_and_names_why() {
    let dir = scratch("train-refuse");
    let data = dataset(&dir);
    let preset = tiny_preset(&dir, "tiny", "", 4);
    // A directory that holds something else.
    let foreign = dir.join("foreign");
    std::fs::create_dir_all(&foreign).unwrap();
    std::fs::write(foreign.join("notes.txt"), "mine").unwrap();
    let e = stderr(&train(&data, &preset, &foreign, &[]));
    assert!(e.contains("refusing") && e.contains("'notes.txt'"), "{e}");
    assert_eq!(
        std::fs::read_to_string(foreign.join("notes.txt")).unwrap(),
        "mine"
    );
    // A finished run is not started again.
    let out = dir.join("run");
    ok(train(&data, &preset, &out, &[]));
    let e = stderr(&train(&data, &preset, &out, &[]));
    assert!(e.contains("--resume"), "{e}");
    // An unknown key and a value out of range name the key.
    let bad = dir.join("bad.toml");
    let text = std::fs::read_to_string(&preset).unwrap();
    std::fs::write(
        &bad,
        text.replace("log_every = 2", "log_every = 2\nlog_evry = 3"),
    )
    .unwrap();
    let e = stderr(&train(&data, &bad, &dir.join("bad"), &[]));
    assert!(e.contains("log_evry"), "{e}");
    std::fs::write(&bad, text.replace("batch_size = 2", "batch_size = 0")).unwrap();
    let e = stderr(&train(&data, &bad, &dir.join("bad"), &[]));
    assert!(e.contains("training.batch_size"), "{e}");
    std::fs::write(
        &bad,
        text.replace(
            "boundary_features = true",
            "boundary_features = true\nboundary_horizon = -1.0",
        ),
    )
    .unwrap();
    let e = stderr(&train(&data, &bad, &dir.join("bad"), &[]));
    assert!(
        e.contains("model.boundary_horizon") && e.contains("-1"),
        "{e}"
    );
    // Boundary features on a dataset whose walls are particles.
    let walls = dir.join("walls");
    tiny_dataset_with(
        &walls,
        2,
        [0.1, 0.9],
        Variant::WallsAsParticles,
        &[("train", 1), ("valid", 1)],
        20,
    );
    let e = stderr(&train(&walls, &preset, &dir.join("walls-run"), &[]));
    assert!(e.contains("model.boundary_features"), "{e}");
    // A backend without autodiff, a device that is not there.
    let e = stderr(&train(
        &data,
        &preset,
        &dir.join("nd"),
        &["--backend", "ndarray"],
    ));
    assert!(
        e.contains("no autodiff") && e.contains("use --backend burn"),
        "{e}"
    );
    let e = stderr(&train(
        &data,
        &preset,
        &dir.join("gpu"),
        &["--device", "cuda:7"],
    ));
    assert!(e.contains("--device cuda:7"), "{e}");
    // tch without the `cuda` feature cannot see a GPU; the message names the feature that can.
    if cfg!(not(feature = "cuda"))
        && phi::backends::BackendKind::available()
            .iter()
            .any(|k| k.name() == "tch")
    {
        let e = stderr(&train(
            &data,
            &preset,
            &dir.join("tch-gpu"),
            &["--backend", "tch", "--device", "cuda"],
        ));
        assert!(e.contains("--features tch,cuda"), "{e}");
    }
    // A resumed run with another configuration.
    let other = dir.join("other.toml");
    std::fs::write(&other, text.replace("seed = 11", "seed = 12")).unwrap();
    let e = stderr(&resume(
        &out,
        &["--config", other.to_str().unwrap(), "--steps", "8"],
    ));
    assert!(e.contains("another configuration"), "{e}");
    assert!(e.contains("training.ema_decay"), "{e}");
}

/// The `valid_*` columns of `train.csv`'s screening rows: `(step, rollout MSE, EMD)`.
fn screenings(out: &Path) -> Vec<(u64, f64, Option<f64>)> {
    let text = std::fs::read_to_string(out.join("train.csv")).unwrap();
    text.lines()
        .skip(1)
        .map(|l| l.split(',').collect::<Vec<_>>())
        .filter(|c| !c[5].is_empty())
        .map(|c| {
            (
                c[0].parse().unwrap(),
                c[5].parse().unwrap(),
                c[6].parse().ok(),
            )
        })
        .collect()
}

#[test]
fn the_screening_may_switch_to_emd_on_resume_and_then_picks_best_by_it() {
    let dir = scratch("train-emd-screening");
    let data = dataset(&dir);
    let preset = tiny_preset(&dir, "tiny", "noise", 16);
    let e = stderr(&train(
        &data,
        &preset,
        &dir.join("refused"),
        &["--select-by", "emd"],
    ));
    assert!(e.contains("screening.emd_every"), "{e}");
    let whole = dir.join("whole");
    ok(train(&data, &preset, &whole, &["--steps", "24"]));
    let out = dir.join("run");
    ok(train(&data, &preset, &out, &[]));
    // Made as by a phi from before the EMD: a log without its column, a best without its metric.
    let log = out.join("train.csv");
    let old: String = std::fs::read_to_string(&log)
        .unwrap()
        .lines()
        .map(|l| format!("{}\n", l.rsplit_once(',').unwrap().0))
        .collect();
    std::fs::write(&log, old).unwrap();
    let state_path = out.join("checkpoints/step-0000000016/state.json");
    let mut state: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&state_path).unwrap()).unwrap();
    assert_eq!(state["best"]["metric"], "rollout_mse", "{state}");
    state["best"].as_object_mut().unwrap().remove("metric");
    std::fs::write(&state_path, serde_json::to_vec(&state).unwrap()).unwrap();
    ok(resume(
        &out,
        &["--steps", "24", "--emd-every", "1", "--select-by", "emd"],
    ));
    // The screening changes no weight: the losses and the other screening columns are the
    // uninterrupted run's.
    assert_eq!(losses(&out), losses(&whole));
    let rows = screenings(&out);
    assert_eq!(
        rows.iter()
            .map(|r| (r.0, r.2.is_some()))
            .collect::<Vec<_>>(),
        [(8, false), (16, false), (24, true)]
    );
    // Every frame's EMD is at most the squared distance of the identity pairing: EMD ≤ d × MSE.
    let (_, mse, emd) = rows[2];
    let emd = emd.unwrap();
    assert!(
        emd > 0.0 && emd <= 2.0 * mse * (1.0 + 1e-9),
        "{emd} vs {mse}"
    );
    // The best by rollout MSE was forgotten: step 24 is the first chosen by EMD.
    let best: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("best/best.json")).unwrap()).unwrap();
    assert_eq!(best["metric"], "valid_emd");
    assert_eq!(best["step"], 24);
    assert_eq!(best["value"].as_f64().unwrap(), emd);
    let stored = std::fs::read_to_string(out.join("config.toml")).unwrap();
    assert!(stored.contains("select_by = \"emd\""), "{stored}");
}

#[test]
fn a_weight_average_switched_on_at_resume_starts_from_the_checkpoint() {
    let dir = scratch("train-ema-resume");
    let data = dataset(&dir);
    let preset = tiny_preset(&dir, "plain", "noise", 12);
    let out = dir.join("run");
    ok(train(&data, &preset, &out, &[]));
    let state = |step: u64| -> serde_json::Value {
        let path = out.join(format!("checkpoints/step-{step:010}/state.json"));
        serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap()
    };
    assert!(state(12).get("average_updates").is_none());
    assert!(!out.join("checkpoints/step-0000000012/average").exists());
    ok(resume(&out, &["--steps", "18", "--ema-decay", "0.5"]));
    assert_eq!(state(18)["average_updates"], 6, "{}", state(18));
    let stored = std::fs::read_to_string(out.join("config.toml")).unwrap();
    assert!(stored.contains("ema_decay = 0.5"), "{stored}");
    // The average of six steps from the weights of step 12 lies between those and step 18's.
    let weights = |path: &Path| -> Vec<f32> {
        let model = phi::phi_gns::model::load_model::<Host>(path, &Default::default()).unwrap();
        model
            .params()
            .iter()
            .flat_map(|(_, t)| t.to_vec())
            .collect()
    };
    let last = weights(&out.join("checkpoints/step-0000000018"));
    let average = weights(&out.join("checkpoints/step-0000000018/average"));
    let start = weights(&out.join("checkpoints/step-0000000012"));
    let moved =
        |a: &[f32], b: &[f32]| -> f32 { a.iter().zip(b).map(|(x, y)| (x - y).abs()).sum::<f32>() };
    assert!(moved(&average, &last) > 0.0, "the average lags the weights");
    assert!(
        moved(&average, &start) < moved(&last, &start),
        "the average has moved less than the weights since it started"
    );
    // A later resume continues the stored average.
    ok(resume(&out, &["--steps", "20"]));
    assert_eq!(state(20)["average_updates"], 8);
}

#[test]
fn a_diverging_run_stops_naming_the_step_and_keeps_the_last_good_checkpoint() {
    let dir = scratch("train-diverge");
    let data = dataset(&dir);
    let preset = tiny_preset(&dir, "diverge", "diverge", 50);
    let out = dir.join("run");
    let failed = train(&data, &preset, &out, &[]);
    assert!(!failed.status.success());
    let e = stderr(&failed);
    assert!(e.contains("diverged at step"), "{e}");
    let step: u64 = e
        .split("diverged at step ")
        .nth(1)
        .and_then(|r| r.split(':').next())
        .and_then(|s| s.trim().parse().ok())
        .unwrap_or_else(|| panic!("{e}"));
    assert!(step < 50, "{e}");
    let kept = out
        .join("checkpoints")
        .join(format!("step-{:010}", step - 1));
    assert!(kept.join("state.json").is_file(), "{e}");
}

/// The lever and GPU presets parse and read back, and their names say what they hold: `mirror`
/// mirror augmentation, `average` the weight average, `two-step` the two-step loss, `noise` the
/// random-walk input noise, `walls` no boundary features.
#[test]
fn every_lever_and_gpu_preset_parses_and_holds_what_its_name_says() {
    use phi::phi_gns::train::TrainConfig;
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/gns");
    let mut seen = 0;
    for folder in ["levers", "gpu"] {
        for entry in std::fs::read_dir(root.join(folder)).unwrap() {
            let path = entry.unwrap().path();
            if path.extension().is_none_or(|e| e != "toml") {
                continue;
            }
            let c = TrainConfig::from_file(&path).unwrap_or_else(|e| panic!("{e}"));
            let name = path.file_stem().unwrap().to_string_lossy().into_owned();
            let at = path.display();
            if name.contains("mirror") {
                assert!(c.training.mirror, "{at}");
            }
            if name.contains("average") {
                assert!(c.training.ema_decay.is_some(), "{at}");
            }
            if name.contains("two-step") || name.starts_with("2s") {
                assert_eq!(c.training.extra_steps, 1, "{at}");
            }
            if name.contains("noise") {
                assert!(c.model.noise_std > 0.0, "{at}");
            }
            if name.contains("walls") {
                assert!(!c.model.boundary_features, "{at}");
            }
            if name.contains("horizon") {
                assert!(c.model.boundary_features, "{at}");
                assert!(c.model.boundary_horizon.is_some_and(|h| h > 1.0), "{at}");
            }
            assert_eq!(
                TrainConfig::from_toml(&c.to_toml(), "stored").unwrap(),
                c,
                "{at}"
            );
            seen += 1;
        }
    }
    assert!(
        seen >= 10,
        "only {seen} presets in configs/gns/levers and gpu"
    );
}

#[test]
fn every_preset_parses_and_the_full_scale_ones_are_the_thesis_recipe() {
    use phi::phi_gns::train::TrainConfig;
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/gns");
    for (folder, full) in [(root.clone(), true), (root.join("cpu"), false)] {
        for name in ["1s", "1sn", "1snb", "2ss", "2si"] {
            let path = folder.join(format!("{name}.toml"));
            let c = TrainConfig::from_file(&path).unwrap_or_else(|e| panic!("{e}"));
            let noisy = name.contains('n');
            assert_eq!(c.model.noise_std > 0.0, noisy, "{}", path.display());
            assert_eq!(c.model.noise_std, if noisy { 6.7e-4 } else { 0.0 });
            assert_eq!(
                c.model.boundary_features,
                name != "1snb",
                "{}",
                path.display()
            );
            assert_eq!(c.training.extra_steps, usize::from(name.starts_with('2')));
            assert_eq!(c.training.batch_size, 2);
            // The CPU presets differentiate each graph of a batch on its own thread.
            assert_eq!(c.training.parallel_graphs, !full, "{}", path.display());
            assert!(c.training.pushforward.is_none());
            assert_eq!(
                c.screening.select_by,
                phi::phi_gns::train::config::SelectBy::RolloutMse
            );
            if full {
                // Sanchez-Gonzalez et al. and the thesis: 10 × 128, 2 hidden layers, 2e7 steps,
                // Adam with the learning rate decaying from 1e-4 to 1e-6 over 5e6-step decades.
                let m = &c.model;
                assert_eq!(
                    (
                        m.latent_size,
                        m.hidden_size,
                        m.hidden_layers,
                        m.message_passing_steps
                    ),
                    (128, 128, 2, 10)
                );
                assert_eq!((m.input_velocities, m.embedding_size), (5, 16));
                assert_eq!(c.training.steps, 20_000_000);
                let lr = &c.optimizer.learning_rate;
                assert_eq!(
                    (lr.initial, lr.final_rate, lr.decay_steps),
                    (1e-4, 1e-6, 5e6)
                );
                assert_eq!(
                    (c.optimizer.beta1, c.optimizer.beta2, c.optimizer.eps),
                    (0.9, 0.999, 1e-8)
                );
            }
            // The stored form reads back as the same configuration.
            assert_eq!(TrainConfig::from_toml(&c.to_toml(), "stored").unwrap(), c);
        }
    }
}
