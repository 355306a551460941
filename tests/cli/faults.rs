//! `phi simulate` under faults: blown-up runs stop and keep what they made, output directories
//! are not overwritten, and requests beyond the memory limit are refused before allocating.

use super::{ok, phi, scratch};
use phi::output::read_npz;

/// A block falling freely in a 16 × 32 box: the CFL number of step `k` (0-based) is
/// `9.81 · 0.1² · (k + 1) = 0.0981 (k + 1)`.
fn falling_block(dir: &std::path::Path, extra: &str) -> std::path::PathBuf {
    let path = dir.join("fall.toml");
    std::fs::write(
        &path,
        format!(
            "[domain]\nresolution = [16, 32]\n[simulation]\ndt = 0.1\nsteps = 8\n\
             particles_per_cell = 2\n{extra}\n\
             [[liquid]]\ngeometry = {{ type = \"box\", lower = [6, 20], upper = [10, 24] }}\n"
        ),
    )
    .unwrap();
    path
}

fn run_json(out: &std::path::Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(out.join("run.json")).unwrap()).unwrap()
}

/// A run that goes unstable at step 2 (CFL 0.29 > max_cfl = 0.25), before its first
/// checkpoint, fails naming the step and the CFL number, and keeps its three frames: the
/// trajectory, `run.json` (incomplete, with the reason) and a closed GIF.
#[test]
fn a_failing_run_keeps_what_it_made() {
    let dir = scratch("unstable");
    let scene = falling_block(&dir, "max_cfl = 0.25");
    let out = dir.join("run");
    let output = phi()
        .arg("simulate")
        .arg(&scene)
        .arg("--out")
        .arg(&out)
        .args(["--frame-every", "1", "--checkpoint-every", "25"])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(!output.status.success(), "{stderr}");
    assert!(
        stderr.contains("step 2") && stderr.contains("CFL number 0.29"),
        "{stderr}"
    );
    let arrays = read_npz(out.join("trajectory.npz")).unwrap();
    let get = |k: &str| arrays.iter().find(|(n, _)| n == k).unwrap().1.clone();
    assert_eq!(get("positions").shape[0], 3);
    assert_eq!(get("steps_completed").as_i64().unwrap(), &[2]);
    let run = run_json(&out);
    assert_eq!(run["complete"], false);
    assert_eq!(run["steps"], 2);
    assert_eq!(run["frames"], 3);
    assert_eq!(run["trajectory_frames"], 3);
    let failure = run["failure"].as_str().unwrap();
    assert!(
        failure.contains("step 2") && failure.contains("CFL"),
        "{failure}"
    );
    let gif = std::fs::read(out.join("simulation.gif")).unwrap();
    assert_eq!(gif.last(), Some(&0x3B), "the GIF has no trailer");
    let _ = std::fs::remove_dir_all(dir);
}

/// `dt = 50` fails at step 0; the same scene with `cfl = 1` completes, sub-stepped.
#[test]
fn blown_up_scenes_fail_and_sub_step_with_the_cfl_key() {
    let dir = scratch("blowup");
    let out = dir.join("run");
    let blown = dir.join("blown.toml");
    let scene = |extra: &str| {
        format!(
            "[domain]\nresolution = [16, 16]\n[simulation]\ndt = 50\nsteps = 2\n\
             particles_per_cell = 2\n{extra}\n\
             [[liquid]]\ngeometry = {{ type = \"box\", lower = [0, 0], upper = [16, 4] }}\n\
             [[liquid]]\ngeometry = {{ type = \"box\", lower = [5, 8], upper = [11, 12] }}\n"
        )
    };
    std::fs::write(&blown, scene("")).unwrap();
    let output = phi()
        .arg("simulate")
        .arg(&blown)
        .arg("--out")
        .arg(&out)
        .args(["--frame-every", "0"])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(!output.status.success(), "{stderr}");
    assert!(
        stderr.contains("step 0") && stderr.contains("CFL number"),
        "{stderr}"
    );
    assert_eq!(run_json(&out)["complete"], false);

    std::fs::write(&blown, scene("cfl = 1.0")).unwrap();
    let stdout = ok(phi()
        .arg("simulate")
        .arg(&blown)
        .arg("--out")
        .arg(&out)
        .args(["--frame-every", "0", "--force"])
        .output()
        .unwrap());
    let run = run_json(&out);
    assert_eq!(run["complete"], true, "{stdout}");
    assert!(run["substeps"].as_u64().unwrap() > 100, "{run}");
    assert!(run["cfl_max"].as_f64().unwrap() < 2.0, "{run}");
    let arrays = read_npz(out.join("trajectory.npz")).unwrap();
    let p = arrays
        .iter()
        .find(|(n, _)| n == "positions")
        .unwrap()
        .1
        .clone();
    assert!(p.as_f32().unwrap().iter().all(|x| x.is_finite()));
    let _ = std::fs::remove_dir_all(dir);
}

/// A second run into the same directory is refused unless `--force`, which replaces the
/// previous run whole (no frames of the old run remain); datasets and other files are refused
/// even with `--force`, and left as they were.
#[test]
fn simulate_does_not_overwrite_silently() {
    let dir = scratch("overwrite");
    let scene = falling_block(&dir, "");
    let out = dir.join("run");
    let simulate = |steps: &str, force: bool| {
        let mut c = phi();
        c.arg("simulate")
            .arg(&scene)
            .arg("--out")
            .arg(&out)
            .args(["--steps", steps]);
        if force {
            c.arg("--force");
        }
        c.output().unwrap()
    };
    ok(simulate("4", false));
    assert!(out.join("frames/frame_00004.png").is_file());
    let output = simulate("2", false);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(!output.status.success());
    assert!(
        stderr.contains("not empty") && stderr.contains("--force"),
        "{stderr}"
    );
    assert_eq!(
        run_json(&out)["steps"],
        4,
        "the refused run touched the old one"
    );
    ok(simulate("2", true));
    assert_eq!(run_json(&out)["steps"], 2);
    assert!(out.join("frames/frame_00002.png").is_file());
    assert!(
        !out.join("frames/frame_00004.png").exists(),
        "a frame of the old run is left"
    );

    for (name, expected) in [
        ("metadata.json", "dataset"),
        ("notes.txt", "does not write"),
    ] {
        let foreign = dir.join(format!("foreign-{name}"));
        std::fs::create_dir_all(&foreign).unwrap();
        std::fs::write(foreign.join(name), "{}").unwrap();
        let output = phi()
            .arg("simulate")
            .arg(&scene)
            .arg("--out")
            .arg(&foreign)
            .arg("--force")
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert!(!output.status.success());
        assert!(stderr.contains(expected), "{stderr}");
        let left: Vec<_> = std::fs::read_dir(&foreign).unwrap().collect();
        assert_eq!(
            left.len(),
            1,
            "phi simulate wrote into {}",
            foreign.display()
        );
    }
    let _ = std::fs::remove_dir_all(dir);
}

/// A run with a VTK series (`simulation.pvd`, `vtk/`) is replaced whole by `--force`: no VTK frame
/// of the old run remains. A file `phi simulate` does not write, beside the series or inside
/// `vtk/`, is refused even with `--force`, and left as it was.
#[test]
fn force_replaces_a_run_with_a_vtk_series() {
    let dir = scratch("overwrite-vtk");
    let scene = falling_block(&dir, "");
    let simulate = |out: &std::path::Path, steps: &str, force: bool| {
        let mut c = phi();
        c.arg("simulate").arg(&scene).arg("--out").arg(out).args([
            "--steps",
            steps,
            "--vtk-every",
            "2",
        ]);
        if force {
            c.arg("--force");
        }
        c.output().unwrap()
    };
    let out = dir.join("run");
    ok(simulate(&out, "4", false));
    assert!(out.join("simulation.pvd").is_file());
    assert!(out.join("vtk/frame_00004.vtu").is_file());
    ok(simulate(&out, "2", true));
    assert_eq!(run_json(&out)["steps"], 2);
    assert!(out.join("vtk/frame_00002.vtu").is_file());
    assert!(
        !out.join("vtk/frame_00004.vtu").exists(),
        "a VTK frame of the old run is left"
    );
    let pvd = std::fs::read_to_string(out.join("simulation.pvd")).unwrap();
    assert!(!pvd.contains("frame_00004"), "{pvd}");

    for foreign in ["notes.txt", "vtk/notes.txt"] {
        let other = dir.join(format!("other-{}", foreign.replace('/', "-")));
        ok(simulate(&other, "2", false));
        let path = other.join(foreign);
        std::fs::write(&path, "mine").unwrap();
        let output = simulate(&other, "2", true);
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert!(!output.status.success(), "{foreign} was overwritten");
        assert!(
            stderr.contains("does not write") && stderr.contains(foreign),
            "{stderr}"
        );
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "mine");
        assert!(other.join("vtk/frame_00002.vtu").is_file());
    }
    let _ = std::fs::remove_dir_all(dir);
}

/// Requests beyond the memory limit are refused before anything is allocated or written,
/// naming the key, the estimate and the limit.
#[test]
fn sizes_beyond_the_memory_limit_are_refused() {
    let dir = scratch("memory");
    let out = dir.join("run");
    let cases = [
        (
            "resolution = [100000, 100000]",
            "particles_per_cell = 8",
            "domain.resolution",
            None,
        ),
        (
            "resolution = [32, 32]",
            "particles_per_cell = 1000000000",
            "simulation.particles_per_cell",
            None,
        ),
        (
            "resolution = [32, 32]",
            "particles_per_cell = 8",
            "simulation.steps",
            Some("1MiB"),
        ),
    ];
    for (resolution, ppc, key, limit) in cases {
        let scene = dir.join("big.toml");
        std::fs::write(
            &scene,
            format!(
                "[domain]\n{resolution}\n[simulation]\ndt = 0.05\nsteps = 100\n{ppc}\n\
                 [[liquid]]\ngeometry = {{ type = \"box\", lower = [0, 0], upper = [32, 8] }}\n"
            ),
        )
        .unwrap();
        let mut c = phi();
        c.arg("simulate").arg(&scene).arg("--out").arg(&out);
        if let Some(limit) = limit {
            c.args(["--memory-limit", limit]);
        }
        let output = c.output().unwrap();
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert!(!output.status.success(), "{key}");
        assert!(
            stderr.contains("big.toml") && stderr.contains(key) && stderr.contains("limit"),
            "{stderr}"
        );
        assert!(!out.exists(), "{key}: a refused run left output behind");
    }
    let _ = std::fs::remove_dir_all(dir);
}
