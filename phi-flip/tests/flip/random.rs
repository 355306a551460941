//! The random scene generator of the dataset (thesis table 5.1): every drawn scene obeys the
//! table, obstacles keep off the liquid, draws are reproducible, and the choices are made with
//! the table's probabilities.

use phi_core::backend::Host;
use phi_flip::{
    RandomScene, RandomSceneParams, SceneVariant, generate_random_scene, record_trajectory,
};

const DRAWS: u64 = 300;

fn scenes(variant: SceneVariant) -> Vec<RandomScene> {
    let params = RandomSceneParams::default();
    (0..DRAWS)
        .map(|seed| generate_random_scene(&params, variant, seed).unwrap())
        .collect()
}

fn cells_inside(geometry: &phi_geom::Geometry, scene: &RandomScene) -> Vec<bool> {
    geometry
        .cell_inside_mask::<Host>(&scene.domain, &Default::default())
        .unwrap()
        .to_vec()
        .into_iter()
        .map(|v| v > 0.5)
        .collect()
}

/// Everything table 5.1 promises, for one scene.
fn check_table(scene: &RandomScene, params: &RandomSceneParams) {
    let seed = scene.seed;
    assert!(
        scene.particle_count() <= params.max_particles,
        "seed {seed}: {} particles",
        scene.particle_count()
    );
    assert_eq!(
        scene.liquid_count(),
        8 * scene.liquid_cells.iter().filter(|&&c| c).count()
    );
    assert_eq!(
        scene.obstacle_count(),
        scene.solid_cells.iter().filter(|&&c| c).count()
    );
    if let Some(h) = scene.pool_height {
        assert!((3..=8).contains(&h), "seed {seed}: pool height {h}");
    }
    let n = scene.blocks.len();
    assert!((1..=3).contains(&n), "seed {seed}: {n} blocks");
    for b in &scene.blocks {
        for axis in 0..2 {
            let size = b.upper[axis] - b.lower[axis];
            assert!((2..=20).contains(&size), "seed {seed}: block {b:?}");
            assert!(b.upper[axis] <= 32);
        }
    }
    assert!(scene.obstacle_draws.len() <= 5);
    for o in &scene.obstacle_draws {
        assert!((2.0..=20.0).contains(&o.length), "seed {seed}: {o:?}");
        assert!(
            (0.0..=90.0).contains(&o.rotation_degrees),
            "seed {seed}: {o:?}"
        );
        // Grown by one cell, no obstacle holds a liquid cell centre.
        let grown = cells_inside(&o.geometry(1.0).unwrap(), scene);
        assert!(
            !grown.iter().zip(&scene.liquid_cells).any(|(&g, &l)| g && l),
            "seed {seed}: obstacle {o:?} touches the liquid"
        );
        assert!(cells_inside(&o.geometry(0.0).unwrap(), scene).contains(&true));
    }
    if let Some(v) = scene.initial_velocity {
        assert!(v.iter().all(|c| (-5.0..=5.0).contains(c)), "{v:?}");
    }
    // Liquid particles lie in liquid cells; obstacle particles at solid cell centres.
    for p in scene.liquid_positions.chunks(2) {
        let (i, j) = (p[0].floor() as usize, p[1].floor() as usize);
        assert!(
            scene.liquid_cells[i * 32 + j],
            "seed {seed}: particle {p:?}"
        );
        assert!(!scene.solid_cells[i * 32 + j]);
    }
    for p in scene.obstacle_particles.chunks(2) {
        let (i, j) = (p[0] as usize, p[1] as usize);
        assert_eq!([p[0] % 1.0, p[1] % 1.0], [0.5, 0.5]);
        assert!(scene.solid_cells[i * 32 + j]);
    }
    // The simulation sees the same solid cells as the learner.
    let (simulation, particles) = scene.simulation(0.05).unwrap();
    assert_eq!(simulation.solid_cells(0.0).unwrap(), scene.solid_cells);
    assert_eq!(particles.len(), scene.liquid_count());
}

#[test]
fn every_scene_obeys_table_5_1() {
    let params = RandomSceneParams::default();
    for scene in scenes(SceneVariant::Obstacles) {
        check_table(&scene, &params);
    }
}

#[test]
fn choices_follow_the_table_probabilities() {
    let all = scenes(SceneVariant::Obstacles);
    let share = |f: &dyn Fn(&RandomScene) -> bool| all.iter().filter(|s| f(s)).count();
    // Binomial(300, p): four standard deviations either side.
    let check = |name: &str, count: usize, p: f64| {
        let n = DRAWS as f64;
        let sd = (n * p * (1.0 - p)).sqrt();
        assert!(
            (count as f64 - n * p).abs() <= 4.0 * sd,
            "{name}: {count} of {DRAWS}, expected about {}",
            n * p
        );
    };
    check("pool", share(&|s| s.pool_height.is_some()), 0.3);
    check("several blocks", share(&|s| s.blocks.len() > 1), 0.3);
    check("obstacles", share(&|s| !s.obstacle_draws.is_empty()), 0.8);
    check(
        "initial velocity",
        share(&|s| s.initial_velocity.is_some()),
        0.3,
    );
    // Every count of blocks and obstacles in the table's ranges occurs.
    for blocks in 1..=3 {
        assert!(
            all.iter().any(|s| s.blocks.len() == blocks),
            "{blocks} blocks"
        );
    }
    for obstacles in 0..=5 {
        assert!(
            all.iter().any(|s| s.obstacle_draws.len() == obstacles),
            "{obstacles} obstacles"
        );
    }
    // Rotations spread over [0, 90] degrees.
    let angles: Vec<f32> = all
        .iter()
        .flat_map(|s| s.obstacle_draws.iter().map(|o| o.rotation_degrees))
        .collect();
    assert!(angles.iter().any(|&a| a < 10.0) && angles.iter().any(|&a| a > 80.0));
}

#[test]
fn the_same_seed_gives_the_same_scene() {
    let params = RandomSceneParams::default();
    for seed in [0, 1, 12345] {
        let a = generate_random_scene(&params, SceneVariant::Obstacles, seed).unwrap();
        let b = generate_random_scene(&params, SceneVariant::Obstacles, seed).unwrap();
        assert_eq!(a.liquid_positions, b.liquid_positions);
        assert_eq!(a.obstacle_particles, b.obstacle_particles);
        assert_eq!(a.obstacle_draws, b.obstacle_draws);
        assert_eq!(a.initial_velocity, b.initial_velocity);
    }
    let a = generate_random_scene(&params, SceneVariant::Obstacles, 5).unwrap();
    let b = generate_random_scene(&params, SceneVariant::Obstacles, 6).unwrap();
    assert_ne!(a.liquid_positions, b.liquid_positions);
}

#[test]
fn walls_variant_adds_a_solid_ring_of_particles() {
    let params = RandomSceneParams::default();
    for scene in scenes(SceneVariant::Walls).iter().take(60) {
        check_table(scene, &params);
        for k in 0..32 * 32 {
            let (i, j) = (k / 32, k % 32);
            if i == 0 || j == 0 || i == 31 || j == 31 {
                assert!(
                    scene.solid_cells[k],
                    "seed {}: wall cell {i},{j}",
                    scene.seed
                );
                assert!(!scene.liquid_cells[k]);
            }
        }
        assert!(scene.obstacle_count() >= 124);
        assert_eq!(scene.obstacles.len(), scene.obstacle_draws.len() + 4);
    }
}

#[test]
fn a_recorded_trajectory_keeps_obstacle_particles_and_stays_in_the_domain() {
    let params = RandomSceneParams::default();
    // A scene with obstacles and an initial velocity.
    let scene = (0..)
        .map(|seed| generate_random_scene(&params, SceneVariant::Walls, seed).unwrap())
        .find(|s| !s.obstacle_draws.is_empty() && s.initial_velocity.is_some())
        .unwrap();
    let (simulation, particles) = scene.simulation(params.dt).unwrap();
    let steps = 8;
    let t = record_trajectory(&simulation, particles, &scene.obstacle_particles, steps).unwrap();
    assert_eq!(t.frames, steps + 1);
    assert_eq!(t.liquid, scene.liquid_count());
    assert_eq!(t.obstacle, scene.obstacle_count());
    let frame = t.particles() * 2;
    assert_eq!(t.positions.len(), t.frames * frame);
    assert_eq!(
        &t.positions[..scene.liquid_positions.len()],
        &scene.liquid_positions[..]
    );
    for f in 0..t.frames {
        let rows = &t.positions[f * frame..(f + 1) * frame];
        assert_eq!(&rows[t.liquid * 2..], &scene.obstacle_particles[..]);
        assert!(rows.iter().all(|x| (0.0..=32.0).contains(x)));
    }
    // The liquid moved.
    assert_ne!(
        &t.positions[..t.liquid * 2],
        &t.positions[steps * frame..steps * frame + t.liquid * 2]
    );
}

#[test]
fn parameters_default_to_the_table_and_reject_unknown_keys() {
    let p = RandomSceneParams::from_toml("", "gen.toml").unwrap();
    assert_eq!(p, RandomSceneParams::default());
    assert_eq!(
        (p.steps, p.dt, p.max_particles, p.resolution),
        (400, 0.05, 1300, [32, 32])
    );
    assert_eq!((p.pool_probability, p.pool_height), (0.3, [3, 8]));
    assert_eq!(p.block_size, [2, 20]);
    assert_eq!(
        (p.multiple_blocks_probability, p.multiple_blocks),
        (0.3, [2, 3])
    );
    assert_eq!((p.obstacle_probability, p.obstacle_count), (0.8, [1, 5]));
    assert_eq!(
        (p.obstacle_length, p.obstacle_rotation),
        ([2.0, 20.0], [0.0, 90.0])
    );
    assert_eq!(
        (p.velocity_probability, p.velocity_range),
        (0.3, [-5.0, 5.0])
    );

    let p =
        RandomSceneParams::from_toml("steps = 10\npool_probability = 1.0\n", "gen.toml").unwrap();
    assert_eq!((p.steps, p.pool_probability), (10, 1.0));

    let e = RandomSceneParams::from_toml("pool_probabilty = 0.5\n", "gen.toml")
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("gen.toml") && e.contains("pool_probabilty"),
        "{e}"
    );
    let e = RandomSceneParams::from_toml("pool_probability = 1.5\n", "gen.toml")
        .unwrap_err()
        .to_string();
    assert!(e.contains("gen.toml: pool_probability"), "{e}");
    let e = RandomSceneParams::from_toml("block_size = [5, 2]\n", "gen.toml")
        .unwrap_err()
        .to_string();
    assert!(e.contains("block_size"), "{e}");
}

#[test]
fn a_pool_every_time_still_fits_the_particle_limit() {
    let params = RandomSceneParams {
        pool_probability: 1.0,
        ..RandomSceneParams::default()
    };
    for seed in 0..40 {
        let scene = generate_random_scene(&params, SceneVariant::Obstacles, seed).unwrap();
        let h = scene.pool_height.unwrap();
        assert!((3..=8).contains(&h));
        check_table(&scene, &params);
    }
}
