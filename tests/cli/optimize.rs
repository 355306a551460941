//! `phi optimize` end to end: a short optimisation writes its loss curve, plot, frames and
//! summary with a decreasing loss; a bad configuration is an error naming file and key. Through
//! a GNS: the gradient of the learned rollout against finite differences, a short run, and a
//! model that does not fit the scene refused.

use phi::gns::inverse::GnsForward;
use phi::phi_core::Backend;
use phi::phi_core::backend::burn::Burn;
use phi::phi_core::tensor::Tensor;
use phi::phi_flip::optimize::Forward;
use phi::phi_flip::{OptimizeConfig, OptimizeProblem};
use phi::phi_gns::data::Variant;

use super::rollout::{failed, init, tiny_dataset_with};
use super::{ok, phi, scratch};

const CONFIG: &str = r#"
description = "A short test optimisation"

[scene.domain]
resolution = [12, 12]

[scene.simulation]
dt = 0.05
steps = 5
particles_per_cell = 2
placement = "centered"

[[scene.liquid]]
geometry = { type = "box", lower = [2, 2], upper = [6, 6] }

[target]
liquid = [{ type = "sphere", center = [6.5, 6.5], radius = 2.6 }]
particles_per_cell = 4

[optimize]
iterations = 10
"#;

#[test]
fn optimize_writes_loss_curve_plot_and_frames() {
    let dir = scratch("optimize");
    let config = dir.join("tiny.toml");
    std::fs::write(&config, CONFIG).unwrap();
    let out = dir.join("run");
    let optimize = |out: &std::path::Path, global: &[&str]| {
        phi()
            .args(global)
            .arg("optimize")
            .arg(&config)
            .arg("--out")
            .arg(out)
            .args([
                "--backend",
                "burn",
                "--iterations",
                "4",
                "--frame-every",
                "2",
            ])
            .output()
            .unwrap()
    };
    let output = optimize(&out, &[]);
    // A line per iteration on stderr, none with -q.
    let stderr = String::from_utf8_lossy(&output.stderr).into_owned();
    assert!(stderr.contains("iteration   4: loss"), "{stderr}");
    let stdout = ok(output);
    let quiet = optimize(&dir.join("quiet"), &["-q"]);
    let quiet_stderr = String::from_utf8_lossy(&quiet.stderr).into_owned();
    assert!(!quiet_stderr.contains("iteration"), "{quiet_stderr}");
    let quiet_stdout = ok(quiet);
    assert!(
        quiet_stdout.contains("5 iterations of 32 particles"),
        "-q keeps the results: {quiet_stdout}"
    );
    assert!(
        stdout.contains("5 iterations of 32 particles through flip on burn"),
        "{stdout}"
    );
    let csv = std::fs::read_to_string(out.join("loss.csv")).unwrap();
    let mut lines = csv.lines();
    assert_eq!(
        lines.next(),
        Some("iteration,loss,gradient_norm,rms_distance,chamfer")
    );
    let losses: Vec<f32> = lines
        .map(|l| l.split(',').nth(1).unwrap().parse().unwrap())
        .collect();
    assert_eq!(losses.len(), 5);
    assert!(
        losses[4] < 0.01 * losses[0],
        "the loss must fall by 100x: {losses:?}"
    );
    for file in [
        "loss.png",
        "summary.json",
        "frames/iteration_000_initial.png",
        "frames/iteration_000_final.png",
        "frames/iteration_002_final.png",
        "frames/iteration_004_final.png",
    ] {
        assert!(out.join(file).is_file(), "missing {file}");
    }
    let png = std::fs::read(out.join("loss.png")).unwrap();
    assert_eq!(&png[1..4], b"PNG");
    // The IHDR chunk: the labelled 640 × 400 plot.
    let size = |at: usize| u32::from_be_bytes(png[at..at + 4].try_into().unwrap());
    assert_eq!((size(16), size(20)), (640, 400));
}

#[test]
fn optimize_reports_configuration_errors_with_file_and_key() {
    let dir = scratch("optimize-bad");
    let config = dir.join("bad.toml");
    std::fs::write(
        &config,
        CONFIG.replace("radius = 2.6", "radius = 2.6, colour = 3"),
    )
    .unwrap();
    let output = phi()
        .arg("optimize")
        .arg(&config)
        .arg("--out")
        .arg(dir.join("run"))
        .output()
        .unwrap();
    assert!(!output.status.success());
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        stderr.contains("bad.toml") && stderr.contains("target.liquid[0]"),
        "{stderr}"
    );
}

/// A model with seeded random weights for the 12 × 12 scene of [`CONFIG`]: its dataset's bounds
/// [0.1, 0.9] are the scene's grid in stored units (0.8 / 12 per cell).
fn tiny_model(dir: &std::path::Path, bounds: [f64; 2]) -> std::path::PathBuf {
    let data = dir.join("data");
    tiny_dataset_with(&data, 2, bounds, Variant::Obstacles, &[("train", 1)], 10);
    let model = dir.join("model");
    ok(init(&data, &model, &[]));
    model
}

#[test]
fn gns_rollout_gradients_match_finite_differences() {
    let dir = scratch("optimize-gns-gradient");
    let model = tiny_model(&dir, [0.1, 0.9]);
    let config = OptimizeConfig::from_toml(CONFIG, "tiny.toml").unwrap();
    let device = <Burn as Backend>::default_device();
    let problem: OptimizeProblem<Burn> = config.build("tiny.toml", &device).unwrap();
    let forward = GnsForward::new(&model, &problem, "tiny.toml").unwrap();
    let x0 = problem.initial.positions.detach();
    let host = x0.to_vec();
    let n = host.len() / 2;
    // A fixed linear functional of the final positions: its gradient is the rollout's
    // vector-Jacobian product with `w`.
    let w: Vec<f32> = (0..2 * n)
        .map(|i| ((i * 7919) % 13) as f32 / 13.0 - 0.5)
        .collect();
    let weights = Tensor::<Burn>::from_vec(w.clone(), &[n, 2], &device).unwrap();
    let objective = |x: &[f32]| -> f64 {
        let x = Tensor::<Burn>::from_vec(x.to_vec(), &[n, 2], &device).unwrap();
        let end = forward.run(&x).unwrap().to_vec();
        end.iter()
            .zip(&w)
            .map(|(e, w)| f64::from(*e) * f64::from(*w))
            .sum()
    };
    let x = x0.require_grad();
    let end = forward.run(&x).unwrap();
    let value = (&end * &weights).sum();
    let gradient = value.gradients(&[&x]).unwrap().remove(0).to_vec();
    assert!(gradient.iter().all(|g| g.is_finite()));
    assert!(
        gradient.iter().any(|g| g.abs() > 1e-3),
        "a rollout whose output does not depend on its input: {gradient:?}"
    );
    let eps = 2e-3f32;
    for k in [0, 7, 2 * n / 2 + 1, 2 * n - 1] {
        let (mut plus, mut minus) = (host.clone(), host.clone());
        plus[k] += eps;
        minus[k] -= eps;
        let numeric = (objective(&plus) - objective(&minus)) / (2.0 * f64::from(eps));
        let analytic = f64::from(gradient[k]);
        assert!(
            (numeric - analytic).abs() <= 2e-2 * numeric.abs().max(analytic.abs()) + 2e-3,
            "coordinate {k}: autodiff {analytic}, central difference {numeric}"
        );
    }
}

#[test]
fn optimize_through_a_gns_runs_and_refuses_a_model_of_other_bounds() {
    let dir = scratch("optimize-gns");
    let config = dir.join("tiny.toml");
    std::fs::write(&config, CONFIG).unwrap();
    let model = tiny_model(&dir.join("fits"), [0.1, 0.9]);
    let out = dir.join("run");
    let stdout = ok(phi()
        .arg("optimize")
        .arg(&config)
        .arg("--out")
        .arg(&out)
        .args([
            "--backend",
            "burn",
            "--iterations",
            "2",
            "--simulator",
            "gns",
            "--model",
        ])
        .arg(&model)
        .output()
        .unwrap());
    assert!(
        stdout.contains("3 iterations of 32 particles through gns"),
        "{stdout}"
    );
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    let losses = summary["summary"]["losses"].as_array().unwrap();
    assert_eq!(losses.len(), 3);
    assert!(losses.iter().all(|l| l.as_f64().unwrap().is_finite()));
    assert!(
        summary["summary"]["simulator"]
            .as_str()
            .unwrap()
            .starts_with("gns ")
    );
    // The optimum found through the model is simulated with FLIP: its first iteration's initial
    // positions are the initial guess, whose FLIP end state a FLIP run measures the same.
    assert!(stdout.contains("simulated with FLIP"), "{stdout}");
    let check = &summary["summary"]["flip_check"];
    let flip_out = dir.join("flip");
    ok(phi()
        .arg("optimize")
        .arg(&config)
        .arg("--out")
        .arg(&flip_out)
        .args(["--backend", "burn", "--iterations", "1"])
        .output()
        .unwrap());
    let flip: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(flip_out.join("summary.json")).unwrap())
            .unwrap();
    assert!(flip["summary"]["flip_check"].is_null());
    for key in ["chamfer", "wasserstein"] {
        assert_eq!(check[key][0], flip["summary"][key][0], "{key}");
        assert!(check[key][1].as_f64().unwrap().is_finite(), "{key}");
    }

    let other = tiny_model(&dir.join("other"), [0.0, 1.0]);
    let message = failed(
        phi()
            .arg("optimize")
            .arg(&config)
            .arg("--out")
            .arg(dir.join("refused"))
            .args(["--backend", "burn", "--simulator", "gns", "--model"])
            .arg(&other)
            .output()
            .unwrap(),
    );
    assert!(
        message.contains("tiny.toml")
            && message.contains("scene.domain.resolution")
            && message.contains("bounds [0, 1]"),
        "{message}"
    );
    let missing = failed(
        phi()
            .arg("optimize")
            .arg(&config)
            .arg("--out")
            .arg(dir.join("no-model"))
            .args(["--simulator", "gns"])
            .output()
            .unwrap(),
    );
    assert!(missing.contains("--model"), "{missing}");
}

/// One rule for the output folder: a new one is written; a previous run is refused unless
/// `--force`, which replaces it whole (no frame of the old run remains); a folder holding
/// anything `phi optimize` does not write is refused even with `--force`, and left as it was.
#[test]
fn optimize_replaces_a_previous_run_only_with_force() {
    let dir = scratch("optimize-force");
    let config = dir.join("tiny.toml");
    std::fs::write(&config, CONFIG).unwrap();
    let optimize = |out: &std::path::Path, iterations: &str, force: bool| {
        let mut command = phi();
        command
            .args(["-q", "optimize"])
            .arg(&config)
            .arg("--out")
            .arg(out)
            .args(["--backend", "burn", "--iterations", iterations]);
        command.args(["--frame-every", "1"]);
        if force {
            command.arg("--force");
        }
        command.output().unwrap()
    };
    let out = dir.join("run");
    ok(optimize(&out, "2", false));
    assert!(out.join("frames/iteration_002_final.png").is_file());
    let summary = std::fs::read(out.join("summary.json")).unwrap();
    let refused = optimize(&out, "1", false);
    let stderr = String::from_utf8_lossy(&refused.stderr);
    assert!(!refused.status.success(), "a previous run was overwritten");
    assert!(
        stderr.contains(&*out.to_string_lossy())
            && stderr.contains("previous `phi optimize` output")
            && stderr.contains("--force"),
        "{stderr}"
    );
    assert_eq!(std::fs::read(out.join("summary.json")).unwrap(), summary);
    ok(optimize(&out, "1", true));
    assert!(out.join("frames/iteration_001_final.png").is_file());
    assert!(
        !out.join("frames/iteration_002_final.png").exists(),
        "a frame of the old run is left"
    );

    for foreign in ["notes.txt", "frames/notes.txt"] {
        let other = dir.join(format!("other-{}", foreign.replace('/', "-")));
        std::fs::create_dir_all(other.join("frames")).unwrap();
        std::fs::write(other.join(foreign), "mine").unwrap();
        for force in [false, true] {
            let refused = optimize(&other, "1", force);
            let stderr = String::from_utf8_lossy(&refused.stderr);
            assert!(!refused.status.success(), "{foreign} was overwritten");
            assert!(
                stderr.contains(&format!("'{foreign}'")) && stderr.contains("does not write"),
                "{stderr}"
            );
        }
        assert_eq!(std::fs::read(other.join(foreign)).unwrap(), b"mine");
        assert!(!other.join("loss.csv").exists());
    }
    let file = dir.join("file");
    std::fs::write(&file, "mine").unwrap();
    let stderr = String::from_utf8_lossy(&optimize(&file, "1", true).stderr).into_owned();
    assert!(stderr.contains("is not a directory"), "{stderr}");
    let _ = std::fs::remove_dir_all(dir);
}
