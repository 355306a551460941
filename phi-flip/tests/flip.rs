//! Physical validation of the FLIP simulator: tests that fail when the physics breaks.
//!
//! Units are cells (cell size 1) and seconds; gravity is −9.81 cells/s² along the last axis.

use phi_core::backend::ndarray::NdArray;
use phi_core::fields::LatticeKernels;
use phi_core::fields::{Boundary, Domain};
use phi_flip::{FlipParams, FlipSimulation, Particles, Placement, Scene};
use phi_geom::{Geometry, Obstacle, Rotation};

#[path = "flip/apic.rs"]
mod apic;
#[path = "flip/gradients.rs"]
mod gradients;
#[path = "flip/optimize.rs"]
mod optimize;
#[path = "flip/random.rs"]
mod random;
#[path = "flip/sloshing.rs"]
mod sloshing;
#[path = "flip/stability.rs"]
mod stability;

type Nd = NdArray;

fn closed(res: &[usize]) -> Domain {
    let upper: Vec<f32> = res.iter().map(|&n| n as f32).collect();
    Domain::new(
        res,
        &vec![0.0; res.len()],
        &upper,
        &vec![[Boundary::Closed; 2]; res.len()],
    )
    .unwrap()
}

fn boxed(lower: &[f32], upper: &[f32]) -> Geometry {
    Geometry::boxed(lower.to_vec(), upper.to_vec()).unwrap()
}

fn simulation<B: LatticeKernels>(
    res: &[usize],
    dt: f32,
    flip_ratio: f32,
    obstacles: Vec<Obstacle>,
) -> FlipSimulation<B> {
    let mut params = FlipParams::thesis(res.len(), dt);
    params.flip_ratio = flip_ratio;
    FlipSimulation::new(
        closed(res),
        params,
        obstacles,
        vec![],
        0,
        &B::default_device(),
    )
    .unwrap()
}

fn seed<B: LatticeKernels>(
    sim: &FlipSimulation<B>,
    regions: &[Geometry],
    placement: Placement,
) -> Particles<B> {
    let d = sim.domain().dim();
    let mut positions = Vec::new();
    for (i, g) in regions.iter().enumerate() {
        let p = sim
            .seed(g, &vec![0.0; d], 8, placement, 7 + i as u64)
            .unwrap();
        positions.extend(p.positions.to_vec());
    }
    let n = positions.len();
    Particles::from_host(positions, vec![0.0; n], d, &B::default_device()).unwrap()
}

fn run<B: LatticeKernels>(
    sim: &FlipSimulation<B>,
    mut p: Particles<B>,
    steps: usize,
) -> Vec<Particles<B>> {
    let mut frames = vec![p.clone()];
    for step in 0..steps {
        p = sim.step(&p, step).unwrap().0;
        frames.push(p.clone());
    }
    frames
}

/// Mean of each coordinate.
fn centre(positions: &[f32], d: usize) -> Vec<f32> {
    let n = positions.len() / d;
    (0..d)
        .map(|a| positions.chunks(d).map(|p| p[a]).sum::<f32>() / n as f32)
        .collect()
}

#[test]
fn still_pool_stays_at_rest() {
    let sim = simulation::<Nd>(&[24, 24], 0.05, 1.0, vec![]);
    let start = seed(
        &sim,
        &[boxed(&[0.0, 0.0], &[24.0, 8.0])],
        Placement::Jittered,
    );
    let frames = run(&sim, start.clone(), 100);
    let (a, b) = (start.positions.to_vec(), frames[100].positions.to_vec());
    let moved = a
        .iter()
        .zip(&b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0f32, f32::max);
    println!("largest displacement of a still pool over 100 steps: {moved:.2e} cells");
    assert!(moved < 1e-3, "the still pool moved {moved} cells");
}

/// Free fall: the step is semi-implicit Euler (velocity first, then positions with the new
/// velocity), so after `n` steps the block's centre is at `y₀ − g Δt² n(n+1)/2` exactly, which is
/// `g Δt t / 2` below the analytic `y₀ − g t²/2`. The block moves as one: its spread is unchanged.
#[test]
fn falling_block_follows_free_fall_and_keeps_its_shape() {
    let (dt, g) = (0.05f32, 9.81f32);
    let sim = simulation::<Nd>(&[32, 48], dt, 1.0, vec![]);
    let start = seed(
        &sim,
        &[boxed(&[10.0, 30.0], &[22.0, 40.0])],
        Placement::Jittered,
    );
    let steps = 25;
    let frames = run(&sim, start, steps);
    let c0 = centre(&frames[0].positions.to_vec(), 2);
    let spread = |p: &[f32], c: &[f32]| -> f32 {
        p.chunks(2)
            .map(|q| (q[0] - c[0]).powi(2) + (q[1] - c[1]).powi(2))
            .sum::<f32>()
    };
    let s0 = spread(&frames[0].positions.to_vec(), &c0);
    println!("step   t      centre y   discrete   analytic");
    for (n, frame) in frames.iter().enumerate() {
        let p = frame.positions.to_vec();
        let c = centre(&p, 2);
        let t = n as f32 * dt;
        let discrete = c0[1] - g * dt * dt * (n * (n + 1)) as f32 / 2.0;
        let analytic = c0[1] - g * t * t / 2.0;
        if n % 5 == 0 {
            println!(
                "{n:>4} {t:>5.2} {:>10.4} {discrete:>10.4} {analytic:>10.4}",
                c[1]
            );
        }
        assert!(
            (c[1] - discrete).abs() < 2e-3,
            "step {n}: centre {} against {discrete}",
            c[1]
        );
        assert!((c[1] - analytic).abs() <= g * dt * t / 2.0 + 2e-3);
        assert!(
            (c[0] - c0[0]).abs() < 1e-3,
            "step {n}: the block drifts sideways"
        );
        let s = spread(&p, &c);
        assert!(
            (s - s0).abs() < 1e-4 * s0,
            "step {n}: the block deforms ({s} against {s0})"
        );
    }
    // It has not touched anything yet: the lowest particle is still well above the floor.
    let lowest = frames[steps]
        .positions
        .to_vec()
        .chunks(2)
        .map(|q| q[1])
        .fold(f32::MAX, f32::min);
    assert!(lowest > 1.0);
}

fn obstacle_scene() -> (FlipSimulation<Nd>, Particles<Nd>, Vec<Geometry>) {
    let ramp = boxed(&[6.0, 16.0], &[22.0, 19.0])
        .rotated(Rotation::degrees(-20.0))
        .unwrap();
    let post = Geometry::union(vec![
        boxed(&[24.0, 8.0], &[26.0, 14.0]),
        Geometry::sphere([25.0, 14.0], 2.0).unwrap(),
    ])
    .unwrap();
    let obstacles = vec![
        Obstacle::at_rest(ramp.clone()).unwrap(),
        Obstacle::at_rest(post.clone()).unwrap(),
    ];
    let sim = simulation::<Nd>(&[32, 32], 0.05, 1.0, obstacles);
    let p = seed(
        &sim,
        &[
            boxed(&[4.0, 22.0], &[14.0, 30.0]),
            boxed(&[0.0, 0.0], &[32.0, 4.0]),
        ],
        Placement::Jittered,
    );
    (sim, p, vec![ramp, post])
}

#[test]
fn particles_stay_out_of_obstacles_and_inside_the_domain() {
    let (sim, start, geometries) = obstacle_scene();
    let n = start.len();
    let mut p = start;
    for step in 0..80 {
        p = sim.step(&p, step).unwrap().0;
        assert_eq!(p.len(), n, "step {step}: particles appeared or vanished");
        for (k, g) in geometries.iter().enumerate() {
            let inside = g.lies_inside(&p.positions).unwrap().to_vec();
            let count = inside.iter().filter(|&&v| v > 0.5).count();
            assert_eq!(
                count, 0,
                "step {step}: {count} particles inside obstacle {k}"
            );
        }
        let host = p.positions.to_vec();
        assert!(
            host.iter().all(|&x| (0.0..=32.0).contains(&x)),
            "step {step}: a particle left the domain"
        );
    }
}

/// Thesis fig. 4.4: a block sampled at the cell centres in the middle of the domain stays
/// mirror-symmetric about the vertical centre line.
#[test]
fn centred_block_stays_mirror_symmetric() {
    let sim = simulation::<Nd>(&[64, 64], 0.1, 1.0, vec![]);
    let start = seed(
        &sim,
        &[boxed(&[26.0, 40.0], &[38.0, 50.0])],
        Placement::Centered,
    );
    let p0 = start.positions.to_vec();
    let n = p0.len() / 2;
    // The partner of each particle: the one at the mirrored position (x → 64 − x).
    let partner: Vec<usize> = (0..n)
        .map(|i| {
            (0..n)
                .find(|&j| {
                    (p0[2 * j] - (64.0 - p0[2 * i])).abs() < 1e-4
                        && (p0[2 * j + 1] - p0[2 * i + 1]).abs() < 1e-4
                })
                .expect("a centred block has a mirror partner for every particle")
        })
        .collect();
    let frames = run(&sim, start, 30);
    for (step, frame) in frames.iter().enumerate() {
        let p = frame.positions.to_vec();
        let mse = (0..n)
            .map(|i| {
                let j = partner[i];
                (p[2 * i] - (64.0 - p[2 * j])).powi(2) + (p[2 * i + 1] - p[2 * j + 1]).powi(2)
            })
            .sum::<f32>()
            / n as f32;
        assert!(mse < 1e-6, "step {step}: mirror MSE {mse}");
    }
    // And it did fall and splash (the test is not vacuous).
    let last = frames[30].positions.to_vec();
    let spread_x = last.chunks(2).map(|q| q[0]).fold(0.0f32, f32::max)
        - last.chunks(2).map(|q| q[0]).fold(f32::MAX, f32::min);
    assert!(
        spread_x > 14.0,
        "the block did not spread on impact ({spread_x} cells wide)"
    );
}

/// Thesis fig. 4.3: PIC damps the motion, FLIP keeps more kinetic energy.
#[test]
fn flip_keeps_more_kinetic_energy_than_pic() {
    let energy = |ratio: f32| -> f32 {
        let sim = simulation::<Nd>(&[32, 32], 0.05, ratio, vec![]);
        let start = seed(
            &sim,
            &[
                boxed(&[12.0, 16.0], &[20.0, 24.0]),
                boxed(&[0.0, 0.0], &[32.0, 4.0]),
            ],
            Placement::Jittered,
        );
        let frames = run(&sim, start, 50);
        // Mean kinetic energy per particle over the last 20 steps (after the impact).
        frames[30..]
            .iter()
            .map(|f| {
                let v = f.velocities.to_vec();
                v.iter().map(|x| x * x).sum::<f32>() / (2.0 * (v.len() / 2) as f32)
            })
            .sum::<f32>()
            / 21.0
    };
    let (flip, pic) = (energy(1.0), energy(0.0));
    println!("mean kinetic energy per particle, steps 30-50: FLIP {flip:.3}, PIC {pic:.3}");
    assert!(flip > 1.2 * pic, "FLIP {flip} against PIC {pic}");
}

/// Martin & Moyce (1952), dam break, surge front `Z = x/a` against `T = t √(2g/a)`.
const MARTIN_MOYCE: [(f32, f32); 15] = [
    (0.41, 1.11),
    (0.84, 1.22),
    (1.19, 1.44),
    (1.43, 1.67),
    (1.63, 1.89),
    (1.83, 2.11),
    (1.98, 2.33),
    (2.20, 2.56),
    (2.32, 2.78),
    (2.51, 3.00),
    (2.65, 3.22),
    (2.83, 3.44),
    (2.98, 3.67),
    (3.11, 3.89),
    (3.33, 4.11),
];

/// A square column of side `a = 12` cells at the left wall of a closed tank 6a wide. The
/// simulation is inviscid and frictionless while the experiment had a real floor and a gate,
/// so the simulated front may run ahead, as inviscid solvers' fronts do in the literature; held
/// to 10 % of the measured `Z` (0.15 absolute at the start, where the lifting of the gate in the
/// experiment dominates). Measured here: within 7 % at every tabulated time.
#[test]
fn dam_break_front_follows_martin_and_moyce() {
    let a = 12.0f32;
    let (dt, g) = (0.02f32, 9.81f32);
    let sim = simulation::<Nd>(&[72, 24], dt, 1.0, vec![]);
    let start = seed(&sim, &[boxed(&[0.0, 0.0], &[a, a])], Placement::Jittered);
    let scale = (2.0 * g / a).sqrt();
    let steps = (3.4 / scale / dt).ceil() as usize;
    let frames = run(&sim, start, steps);
    // The front: the 99.5th percentile of x, so that a lone splashed particle does not count.
    let front = |p: &[f32]| -> f32 {
        let mut xs: Vec<f32> = p.chunks(2).map(|q| q[0]).collect();
        xs.sort_by(f32::total_cmp);
        xs[(xs.len() as f32 * 0.995) as usize]
    };
    println!("    T   Z (Martin & Moyce)   Z (phi)");
    let mut worst = 0.0f32;
    for (t_ref, z_ref) in MARTIN_MOYCE {
        let step = ((t_ref / scale) / dt).round() as usize;
        let z = front(&frames[step].positions.to_vec()) / a;
        println!("{t_ref:>5.2} {z_ref:>12.2} {z:>14.2}");
        let tolerance = (0.1 * z_ref).max(0.15);
        worst = worst.max((z - z_ref).abs() / tolerance);
        assert!(
            (z - z_ref).abs() <= tolerance,
            "T = {t_ref}: Z = {z}, measured {z_ref}"
        );
    }
    println!("worst deviation: {:.0} % of the tolerance", worst * 100.0);
}

/// The scene files shipped in `scenes/` parse, validate and build.
#[test]
fn shipped_scenes_build() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes");
    let mut count = 0;
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().and_then(|e| e.to_str()) != Some("toml") {
            continue;
        }
        let scene = Scene::from_file(&path).unwrap_or_else(|e| panic!("{e}"));
        if scene.simulation.steps == 0 {
            continue;
        }
        let setup = scene
            .build::<Nd>(&path.display().to_string(), &Default::default())
            .unwrap();
        assert!(!setup.particles.is_empty() || !scene.inflows.is_empty());
        count += 1;
    }
    assert!(count >= 5, "only {count} scenes in {}", dir.display());
}

#[test]
fn bad_scenes_are_errors_naming_file_key_and_problem() {
    let good = r#"
[domain]
resolution = [16, 16]
[simulation]
dt = 0.05
steps = 10
[[liquid]]
geometry = { type = "box", lower = [0, 0], upper = [16, 4] }
"#;
    assert!(Scene::from_toml(good, "good.toml").is_ok());
    // `[run] backend` takes every spelling of `--backend`, and nothing else.
    for backend in ["ndarray", "burn", "burn-wgpu", "tch"] {
        let text = format!("[run]\nbackend = \"{backend}\"\n{good}");
        assert!(Scene::from_toml(&text, "run.toml").is_ok(), "{backend}");
    }
    let cases = [
        (
            format!("[run]\nbackend = \"wgpu\"\n{good}"),
            "run.backend",
            "unknown backend",
        ),
        (
            good.replace("[16, 16]", "[16, 0]"),
            "domain.resolution[1]",
            "at least 1",
        ),
        (
            good.replace("dt = 0.05", "dt = -0.05"),
            "simulation.dt",
            "positive",
        ),
        (
            good.replace("dt = 0.05", "dt = nan"),
            "simulation.dt",
            "positive",
        ),
        (
            good.replace("steps = 10", "steps = 10\nsteps_per_frame = 2"),
            "simulation",
            "steps_per_frame",
        ),
        (
            good.replace("upper = [16, 4]", "upper = [16, 4, 2]"),
            "liquid[0].geometry",
            "3 entries",
        ),
        (
            good.replace(
                "lower = [0, 0], upper = [16, 4]",
                "lower = [20, 20], upper = [30, 30]",
            ),
            "liquid[0].geometry",
            "outside the domain",
        ),
        (
            good.replace("[simulation]", "[simulation]\ngravity = [0, -9.81, 0]"),
            "simulation.gravity",
            "2 finite",
        ),
        (
            good.replace("dt = 0.05", "dt = \"fast\""),
            "simulation.dt",
            "invalid type",
        ),
    ];
    for (text, key, problem) in cases {
        let message = Scene::from_toml(&text, "scene.toml")
            .unwrap_err()
            .to_string();
        assert!(message.starts_with("scene.toml: "), "{message}");
        assert!(message.contains(key), "{message} (should name {key})");
        assert!(
            message.contains(problem),
            "{message} (should say {problem})"
        );
    }
}

/// The same scene on every backend gives the same particles over the first 10 steps.
fn conformance_run<B: LatticeKernels>() -> Vec<Vec<f32>> {
    let obstacle = boxed(&[9.0, 6.0], &[13.0, 8.0])
        .rotated(Rotation::degrees(30.0))
        .unwrap();
    let sim = simulation::<B>(
        &[16, 16],
        0.05,
        1.0,
        vec![Obstacle::at_rest(obstacle).unwrap()],
    );
    let start = seed(
        &sim,
        &[
            boxed(&[4.0, 9.0], &[10.0, 14.0]),
            boxed(&[0.0, 0.0], &[16.0, 3.0]),
        ],
        Placement::Jittered,
    );
    run(&sim, start, 10)
        .iter()
        .map(|f| f.positions.to_vec())
        .collect()
}

#[test]
fn backends_agree_over_ten_steps() {
    let reference = conformance_run::<Nd>();
    let mut others: Vec<(&str, Vec<Vec<f32>>)> = Vec::new();
    others.push(("burn", conformance_run::<phi_core::backend::burn::Burn>()));
    #[cfg(feature = "tch")]
    others.push(("tch", conformance_run::<phi_core::backend::tch::Tch>()));
    for (name, frames) in others {
        for (step, (a, b)) in reference.iter().zip(&frames).enumerate() {
            assert_eq!(a.len(), b.len());
            let worst = a
                .iter()
                .zip(b)
                .map(|(x, y)| (x - y).abs())
                .fold(0.0f32, f32::max);
            assert!(
                worst < 1e-4,
                "{name}, step {step}: {worst} cells from ndarray"
            );
        }
        println!("{name}: agrees with ndarray to 1e-4 cells over 10 steps");
    }
}

/// 3D: a cube falls freely (the centre follows the discrete free fall, the shape is kept) and a
/// pool under it stays at rest.
#[test]
fn three_dimensional_free_fall_over_a_still_pool() {
    let (dt, g) = (0.05f32, 9.81f32);
    let sim = simulation::<Nd>(&[10, 10, 20], dt, 1.0, vec![]);
    let cube = boxed(&[3.0, 3.0, 12.0], &[7.0, 7.0, 16.0]);
    let pool = boxed(&[0.0, 0.0, 0.0], &[10.0, 10.0, 3.0]);
    let start = seed(&sim, &[cube, pool], Placement::Jittered);
    let p0 = start.positions.to_vec();
    let in_cube: Vec<bool> = p0.chunks(3).map(|q| q[2] > 6.0).collect();
    let frames = run(&sim, start, 12);
    let stats = |p: &[f32]| {
        let (mut c, mut n, mut pool_moved) = ([0.0f32; 3], 0.0f32, 0.0f32);
        for ((q, q0), &cube) in p.chunks(3).zip(p0.chunks(3)).zip(&in_cube) {
            if cube {
                for a in 0..3 {
                    c[a] += q[a];
                }
                n += 1.0;
            } else {
                let moved = q
                    .iter()
                    .zip(q0)
                    .map(|(x, y)| (x - y).abs())
                    .fold(0.0f32, f32::max);
                pool_moved = pool_moved.max(moved);
            }
        }
        (c.map(|v| v / n), pool_moved)
    };
    let (c0, _) = stats(&p0);
    for (n, frame) in frames.iter().enumerate() {
        let (c, pool_moved) = stats(&frame.positions.to_vec());
        let discrete = c0[2] - g * dt * dt * (n * (n + 1)) as f32 / 2.0;
        assert!(
            (c[2] - discrete).abs() < 2e-3,
            "step {n}: centre z {} against {discrete}",
            c[2]
        );
        assert!(
            (c[0] - c0[0]).abs() < 1e-3 && (c[1] - c0[1]).abs() < 1e-3,
            "step {n}: drift"
        );
        assert!(
            pool_moved < 1e-3,
            "step {n}: the pool moved {pool_moved} cells"
        );
    }
}
