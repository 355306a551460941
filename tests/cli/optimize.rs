//! `phi optimize` end to end: a short optimisation writes its loss curve, plot, frames and
//! summary with a decreasing loss; a bad configuration is an error naming file and key.

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
    let stdout = ok(phi()
        .arg("optimize")
        .arg(&config)
        .arg("--out")
        .arg(&out)
        .args([
            "--backend",
            "burn",
            "--iterations",
            "4",
            "--frame-every",
            "2",
        ])
        .output()
        .unwrap());
    assert!(
        stdout.contains("5 iterations of 32 particles on burn"),
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
