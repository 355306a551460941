//! Blown-up runs stop, naming the step and the CFL number; `simulation.cfl` sub-steps them
//! into runs that stay finite; sub-steps converge to small fixed steps.

use phi_core::backend::ndarray::NdArray;
use phi_flip::{FlipError, Scene};

type Nd = NdArray;

/// A block of liquid over a pool in a closed 16 × 16 box, with `simulation` lines added.
fn scene(simulation: &str) -> Scene {
    let text = format!(
        "[domain]\nresolution = [16, 16]\n[simulation]\n{simulation}\nparticles_per_cell = 4\n\
         placement = \"centered\"\n\
         [[liquid]]\ngeometry = {{ type = \"box\", lower = [0, 0], upper = [16, 4] }}\n\
         [[liquid]]\ngeometry = {{ type = \"box\", lower = [5, 8], upper = [11, 13] }}\n"
    );
    Scene::from_toml(&text, "blowup.toml").unwrap()
}

/// Runs the scene; returns the positions of each frame or the error with the steps done.
fn run(scene: &Scene) -> (Vec<Vec<f32>>, Option<FlipError>, Vec<phi_flip::StepStats>) {
    let setup = scene
        .build::<Nd>("blowup.toml", &Default::default())
        .unwrap();
    let mut p = setup.particles;
    let mut frames = vec![p.positions.to_vec()];
    let mut stats = Vec::new();
    for step in 0..setup.steps {
        match setup.simulation.step(&p, step) {
            Ok((next, s)) => {
                p = next;
                frames.push(p.positions.to_vec());
                stats.push(s);
            }
            Err(e) => return (frames, Some(e), stats),
        }
    }
    (frames, None, stats)
}

/// Far past the CFL limit (`dt = 50`, gravity 10⁹, a velocity of 10³⁰), the first step fails
/// with the step and a CFL number far above the limit, instead of running on with every
/// particle piled in a corner.
#[test]
fn blown_up_runs_stop_naming_the_step_and_the_cfl_number() {
    let cases = [
        "dt = 50\nsteps = 3".to_string(),
        "dt = 0.1\nsteps = 3\ngravity = [0, -1e9]".to_string(),
    ];
    for case in &cases {
        let (frames, error, _) = run(&scene(case));
        let error = error.unwrap_or_else(|| panic!("{case}: the run did not fail"));
        match &error {
            FlipError::Unstable { step, cfl, .. } => {
                assert_eq!(*step, 0, "{case}");
                assert!(*cfl > 1e3, "{case}: CFL number {cfl}");
            }
            other => panic!("{case}: {other}"),
        }
        let message = error.to_string();
        assert!(
            message.contains("step 0") && message.contains("CFL number"),
            "{message}"
        );
        assert_eq!(frames.len(), 1, "{case}");
    }
    let fast = "[domain]\nresolution = [16, 16]\n[simulation]\ndt = 0.1\nsteps = 3\n\
                [[liquid]]\ngeometry = { type = \"box\", lower = [4, 4], upper = [8, 8] }\n\
                velocity = [1e30, 0]\n";
    let (_, error, _) = run(&Scene::from_toml(fast, "fast.toml").unwrap());
    let message = error.expect("a velocity of 1e30 must fail").to_string();
    assert!(message.contains("step 0"), "{message}");
}

/// The scene that blows up at `dt = 50` completes with `cfl = 1`: every sub-step stays near the
/// target, the state stays finite and inside the box, and the block has fallen into the pool.
#[test]
fn the_cfl_key_sub_steps_a_blown_up_scene_into_a_finite_run() {
    let (frames, error, stats) = run(&scene("dt = 5\nsteps = 2\ncfl = 1.0"));
    assert!(error.is_none(), "{}", error.unwrap());
    let last = frames.last().unwrap();
    assert!(
        last.iter()
            .all(|x| x.is_finite() && (0.0..=16.0).contains(x))
    );
    for s in &stats {
        println!("sub-steps {} CFL {:.3}", s.substeps, s.cfl);
        assert!(s.substeps > 10, "{} sub-steps", s.substeps);
        // The estimate reads the particles before a sub-step; the projection may speed the
        // liquid up a little beyond it.
        assert!(s.cfl < 2.0, "CFL number {}", s.cfl);
    }
    // After 10 s the block has fallen into the pool (it started at heights 8 to 13).
    let top = last.chunks(2).map(|p| p[1]).fold(0.0f32, f32::max);
    assert!(top < 11.0, "liquid up to {top}");
    // Without sub-steps the same scene fails.
    let (_, error, _) = run(&scene("dt = 5\nsteps = 2"));
    assert!(matches!(error, Some(FlipError::Unstable { step: 0, .. })));
}

/// A block falling freely, sub-stepped with a small CFL target, agrees with a run of small
/// fixed steps far better than with the unsub-stepped coarse run.
#[test]
fn small_cfl_sub_steps_agree_with_small_fixed_steps() {
    let block = |simulation: &str| {
        let text = format!(
            "[domain]\nresolution = [16, 32]\n[simulation]\n{simulation}\n\
             particles_per_cell = 4\nplacement = \"centered\"\n\
             [[liquid]]\ngeometry = {{ type = \"box\", lower = [6, 20], upper = [10, 24] }}\n"
        );
        Scene::from_toml(&text, "fall.toml").unwrap()
    };
    let (coarse, e1, _) = run(&block("dt = 0.4\nsteps = 3"));
    let (sub, e2, stats) = run(&block("dt = 0.4\nsteps = 3\ncfl = 0.05"));
    let (fine, e3, _) = run(&block("dt = 0.01\nsteps = 120"));
    assert!(e1.is_none() && e2.is_none() && e3.is_none());
    let total: usize = stats.iter().map(|s| s.substeps).sum();
    println!(
        "sub-steps per step: {:?}",
        stats.iter().map(|s| s.substeps).collect::<Vec<_>>()
    );
    assert!(total > 30, "{total} sub-steps");
    let mean_y = |p: &[f32]| p.chunks(2).map(|q| q[1]).sum::<f32>() / (p.len() / 2) as f32;
    let (c, s, f) = (
        mean_y(coarse.last().unwrap()),
        mean_y(sub.last().unwrap()),
        mean_y(fine.last().unwrap()),
    );
    // Free fall over 1.2 s: 22 − ½ 9.81 1.2² = 14.94 for the centre of mass.
    println!("centre of mass: coarse {c:.3}, sub-stepped {s:.3}, fine {f:.3}, exact 14.937");
    assert!((s - f).abs() < 0.1, "sub-stepped {s} vs fine {f}");
    assert!(
        (c - f).abs() > 5.0 * (s - f).abs(),
        "coarse {c} sub {s} fine {f}"
    );
    assert!((f - 14.937).abs() < 0.15, "fine {f}");
}

/// The keys are checked.
#[test]
fn cfl_keys_are_validated() {
    let base = "[domain]\nresolution = [8, 8]\n[simulation]\ndt = 0.1\nsteps = 1\n";
    let liquid = "[[liquid]]\ngeometry = { type = \"box\", lower = [0, 0], upper = [8, 2] }\n";
    for (line, key) in [
        ("cfl = 0", "simulation.cfl"),
        ("cfl = -1", "simulation.cfl"),
        ("max_cfl = 0", "simulation.max_cfl"),
        ("cfl = 30", "simulation.cfl"),
        ("max_substeps = 0", "simulation.max_substeps"),
    ] {
        let text = format!("{base}{line}\n{liquid}");
        let e = Scene::from_toml(&text, "k.toml").unwrap_err().to_string();
        assert!(e.contains("k.toml") && e.contains(key), "{line}: {e}");
    }
    let text = format!("{base}cfl = 1\nmax_cfl = inf\nmax_substeps = 5\n{liquid}");
    assert!(Scene::from_toml(&text, "k.toml").is_ok());
}

/// A step that would need more sub-steps than allowed fails up front, naming the step.
#[test]
fn too_many_sub_steps_fail_naming_the_step() {
    let text = "[domain]\nresolution = [16, 16]\n[simulation]\ndt = 0.1\nsteps = 3\ncfl = 1\n\
                [[liquid]]\ngeometry = { type = \"box\", lower = [4, 4], upper = [8, 8] }\n\
                velocity = [1e30, 0]\n";
    let (_, error, _) = run(&Scene::from_toml(text, "fast.toml").unwrap());
    let message = error.expect("must fail").to_string();
    assert!(
        message.contains("step 0") && message.contains("max_substeps"),
        "{message}"
    );
}

/// Keys that would make a scene do nothing or throw its particles away are refused:
/// a push offset across the domain, an inflow that stops before its first emission and one
/// that lies entirely inside an obstacle.
#[test]
fn scenes_that_cannot_do_what_they_say_are_refused() {
    let base = "[domain]\nresolution = [16, 16]\n[simulation]\ndt = 0.1\nsteps = 4\n";
    let liquid = "[[liquid]]\ngeometry = { type = \"box\", lower = [0, 0], upper = [16, 2] }\n";
    let text = format!("{base}push_offset = 1e30\n{liquid}");
    let e = Scene::from_toml(&text, "s.toml").unwrap_err().to_string();
    assert!(
        e.contains("s.toml") && e.contains("simulation.push_offset") && e.contains("1000000"),
        "{e}"
    );
    let text = format!(
        "{base}{liquid}[[inflow]]\ngeometry = {{ type = \"box\", lower = [2, 10], upper = [4, 12] }}\n\
         velocity = [1, 0]\nuntil_step = 0\n"
    );
    let e = Scene::from_toml(&text, "s.toml").unwrap_err().to_string();
    assert!(e.contains("inflow[0].until_step"), "{e}");
    let text = format!(
        "{base}{liquid}[[obstacle]]\ngeometry = {{ type = \"box\", lower = [1, 8], upper = [6, 14] }}\n\
         [[inflow]]\ngeometry = {{ type = \"box\", lower = [2, 10], upper = [4, 12] }}\n\
         velocity = [1, 0]\n"
    );
    let scene = Scene::from_toml(&text, "s.toml").unwrap();
    let e = scene
        .build::<Nd>("s.toml", &Default::default())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("inflow[0].geometry") && e.contains("emit no particle"),
        "{e}"
    );
    // A small offset and an inflow beside the obstacle are fine.
    let text = format!(
        "{base}push_offset = 0.5\n{liquid}[[obstacle]]\n\
         geometry = {{ type = \"box\", lower = [1, 8], upper = [6, 14] }}\n\
         [[inflow]]\ngeometry = {{ type = \"box\", lower = [8, 10], upper = [10, 12] }}\n\
         velocity = [1, 0]\nuntil_step = 1\n"
    );
    let setup = Scene::from_toml(&text, "s.toml")
        .unwrap()
        .build::<Nd>("s.toml", &Default::default())
        .unwrap();
    let (after, _) = setup.simulation.step(&setup.particles, 0).unwrap();
    assert_eq!(after.len(), setup.particles.len() + 4 * 8);
}
