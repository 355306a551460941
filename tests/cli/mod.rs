//! The `phi` command line end to end, and its errors: `phi simulate` here, the other commands
//! in the modules below.

use std::path::PathBuf;
use std::process::{Command, Output};

use phi::output::read_npz;

mod dataset;
mod dataset_faults;
mod eval;
mod faults;
mod learning;
mod optimize;
mod rollout;
mod train;

fn phi() -> Command {
    Command::new(env!("CARGO_BIN_EXE_phi"))
}

/// The standard output of a run that must have succeeded (otherwise both outputs are shown).
fn ok(output: Output) -> String {
    assert!(
        output.status.success(),
        "stdout: {}\nstderr: {}",
        String::from_utf8_lossy(&output.stdout),
        String::from_utf8_lossy(&output.stderr)
    );
    String::from_utf8_lossy(&output.stdout).into_owned()
}

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("phi-cli-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

#[test]
fn simulate_writes_trajectory_frames_and_gif() {
    let dir = scratch("simulate");
    let scene = concat!(env!("CARGO_MANIFEST_DIR"), "/scenes/small32.toml");
    let out = dir.join("run");
    let stdout = ok(phi()
        .args(["simulate", scene, "--out"])
        .arg(&out)
        .args([
            "--steps",
            "6",
            "--frame-every",
            "3",
            "--checkpoint-every",
            "2",
        ])
        .output()
        .unwrap());
    assert!(stdout.contains("6 steps of 1024 particles"), "{stdout}");
    let arrays = read_npz(out.join("trajectory.npz")).unwrap();
    let get = |k: &str| {
        arrays
            .iter()
            .find(|(n, _)| n == k)
            .map(|(_, a)| a.clone())
            .unwrap()
    };
    assert_eq!(get("positions").shape, vec![7, 1024, 2]);
    assert_eq!(get("velocities").shape, vec![7, 1024, 2]);
    assert_eq!(get("steps_completed").as_i64().unwrap(), &[6]);
    assert!(
        arrays.iter().all(|(k, _)| k != "affine"),
        "a FLIP run has no affine matrices"
    );
    let positions = get("positions");
    let p = positions.as_f32().unwrap();
    assert!(p.iter().all(|x| x.is_finite() && (0.0..=32.0).contains(x)));
    // Frames 0, 3 and 6.
    for step in [0, 3, 6] {
        assert!(out.join(format!("frames/frame_{step:05}.png")).is_file());
    }
    assert!(out.join("simulation.gif").is_file());
    let run: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("run.json")).unwrap()).unwrap();
    assert_eq!(run["complete"], true);
    assert_eq!(run["steps"], 6);
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn simulate_records_apic_affine_matrices() {
    let dir = scratch("apic");
    let scene = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/scenes/colliding_blocks_apic.toml"
    );
    let out = dir.join("run");
    ok(phi()
        .args(["simulate", scene, "--out"])
        .arg(&out)
        .args(["--steps", "30", "--frame-every", "0"])
        .output()
        .unwrap());
    let arrays = read_npz(out.join("trajectory.npz")).unwrap();
    let get = |k: &str| arrays.iter().find(|(n, _)| n == k).map(|(_, a)| a.clone());
    let n = get("positions").unwrap().shape[1];
    let affine = get("affine").expect("an APIC run records the affine matrices");
    assert_eq!(affine.shape, vec![31, n, 2, 2]);
    let c = affine.as_f32().unwrap();
    let largest = |t: usize| {
        c[t * n * 4..(t + 1) * n * 4]
            .iter()
            .fold(0.0f32, |m, x| m.max(x.abs()))
    };
    assert!(c.iter().all(|x| x.is_finite()));
    // Frame 0 is the seeded state (C = 0). In free flight the blocks translate uniformly
    // (gravity adds the same velocity everywhere) and the pool rests: no velocity gradient.
    assert_eq!(largest(0), 0.0);
    assert!(
        largest(3) < 1e-3,
        "largest |C| in free flight: {}",
        largest(3)
    );
    // By step 30 the blocks (24 cells apart, closing at 24 cells/s) have collided: shear.
    assert!(
        largest(30) > 1.0,
        "largest |C| after the collision: {}",
        largest(30)
    );
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn bad_scenes_exit_nonzero_naming_file_and_key() {
    let dir = scratch("bad");
    let scene = dir.join("bad.toml");
    std::fs::write(
        &scene,
        "[domain]\nresolution = [32, 32]\n[simulation]\ndt = 0.0\nsteps = 5\n\
         [[liquid]]\ngeometry = { type = \"box\", lower = [0, 0], upper = [32, 4] }\n",
    )
    .unwrap();
    let out = dir.join("out");
    let output = phi()
        .arg("simulate")
        .arg(&scene)
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert!(!output.status.success());
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        stderr.contains("bad.toml") && stderr.contains("simulation.dt"),
        "{stderr}"
    );
    assert!(!out.exists(), "a failed scene left output behind");

    let output = phi()
        .args([
            "simulate",
            concat!(env!("CARGO_MANIFEST_DIR"), "/scenes/small32.toml"),
            "--device",
            "cuda",
            "--out",
        ])
        .arg(&out)
        .output()
        .unwrap();
    assert!(!output.status.success());
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        stderr.contains("device `cuda`") && stderr.contains("on the CPU"),
        "{stderr}"
    );
    let _ = std::fs::remove_dir_all(dir);
}

/// The decoded bytes of the inline binary data array `name` of a `.vtu` document (a UInt64
/// byte count, then the data).
fn vtu_array(vtu: &str, name: &str) -> Vec<u8> {
    use base64::Engine;
    let tag = format!("Name=\"{name}\"");
    let at = vtu.find(&tag).unwrap_or_else(|| panic!("no array {name}"));
    let start = at + vtu[at..].find('>').unwrap() + 1;
    let end = start + vtu[start..].find("</DataArray>").unwrap();
    let block = base64::engine::general_purpose::STANDARD
        .decode(&vtu[start..end])
        .unwrap();
    let (count, data) = block.split_at(8);
    assert_eq!(
        u64::from_le_bytes(count.try_into().unwrap()) as usize,
        data.len()
    );
    data.to_vec()
}

/// `phi --help` states the rule for the default backend once, and each command's help states
/// the default the rule gives it.
#[test]
fn help_states_each_commands_default_backend() {
    let help = |args: &[&str]| ok(phi().args(args).arg("--help").output().unwrap());
    let top = help(&[]);
    assert!(
        top.contains("Default backend: a command runs on ndarray"),
        "{top}"
    );
    let autodiff = phi::backends::BackendKind::default_autodiff().unwrap();
    for (command, default) in [
        ("simulate", "ndarray"),
        ("rollout", "ndarray"),
        ("eval", "ndarray"),
        ("train", autodiff.name()),
        ("optimize", autodiff.name()),
    ] {
        let text = help(&[command]);
        // The option's description: the lines after its name, indented deeper than options.
        let backend: String = text
            .lines()
            .skip_while(|line| !line.contains("--backend <BACKEND>"))
            .skip(1)
            .take_while(|line| line.starts_with("          "))
            .collect();
        assert!(
            backend.contains(&format!("[default: {default}"))
                || backend.contains(&format!("else {default}, as")),
            "phi {command} --help: {backend}"
        );
    }
}

#[test]
fn simulate_writes_a_vtk_series() {
    let dir = scratch("simulate-vtk");
    let scene = concat!(env!("CARGO_MANIFEST_DIR"), "/scenes/small32.toml");
    let out = dir.join("run");
    ok(phi()
        .args(["simulate", scene, "--out"])
        .arg(&out)
        .args(["--steps", "4", "--frame-every", "0", "--vtk-every", "2"])
        .output()
        .unwrap());
    // The collection lists frames 0, 2 and 4 at their times (dt = 0.05 in small32.toml).
    let pvd = std::fs::read_to_string(out.join("simulation.pvd")).unwrap();
    let files: Vec<&str> = pvd
        .lines()
        .filter(|l| l.contains("<DataSet"))
        .map(|l| {
            let at = l.find("file=\"").unwrap() + 6;
            &l[at..at + l[at..].find('"').unwrap()]
        })
        .collect();
    assert_eq!(
        files,
        [
            "vtk/frame_00000.vtu",
            "vtk/frame_00002.vtu",
            "vtk/frame_00004.vtu"
        ],
        "{pvd}"
    );
    let arrays = read_npz(out.join("trajectory.npz")).unwrap();
    let positions = &arrays.iter().find(|(k, _)| k == "positions").unwrap().1;
    let (n, d) = (positions.shape[1], positions.shape[2]);
    let values = positions.as_f32().unwrap();
    for (k, file) in files.iter().enumerate() {
        let vtu = std::fs::read_to_string(out.join(file)).unwrap();
        assert!(vtu.contains(&format!("NumberOfPoints=\"{n}\"")), "{file}");
        // The points are the trajectory's positions, padded with z = 0.
        let points: Vec<f32> = vtu_array(&vtu, "Points")
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes(b.try_into().unwrap()))
            .collect();
        let frame = &values[2 * k * n * d..(2 * k + 1) * n * d];
        let padded: Vec<f32> = frame.chunks(d).flat_map(|p| [p[0], p[1], 0.0]).collect();
        assert_eq!(points, padded, "{file}");
        // Speed is |velocity|, per particle.
        let floats = |name: &str| -> Vec<f32> {
            vtu_array(&vtu, name)
                .chunks_exact(4)
                .map(|b| f32::from_le_bytes(b.try_into().unwrap()))
                .collect()
        };
        let (velocity, speed) = (floats("velocity"), floats("speed"));
        assert_eq!(speed.len(), n);
        for (v, s) in velocity.chunks(3).zip(&speed) {
            let norm = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
            assert!((norm - s).abs() <= 1e-6 * norm.max(1.0), "{norm} {s}");
        }
    }
    let _ = std::fs::remove_dir_all(dir);
}
