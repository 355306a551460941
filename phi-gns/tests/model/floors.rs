//! The floors and the free-fall probe: a floor predicts its constant acceleration for every
//! particle of any window (a constant-velocity rollout is a straight line), the probe scene's
//! block falls with exactly gravity and its pool is at rest, and the probe reads the floors'
//! predictions back as the fractions of gravity they are.

use phi_core::Backend;
use phi_core::backend::ndarray::NdArray;
use phi_gns::data::LIQUID;
use phi_gns::eval::{probe, probe_scene};
use phi_gns::model::{Floor, GraphBatch};

use crate::common;

/// The random scenes' gravity, cells per second².
const G: [f64; 2] = [0.0, -9.81];

#[test]
fn a_floor_predicts_its_constant_acceleration_everywhere() {
    let metadata = common::metadata();
    let device = NdArray::default_device();
    let scene = probe_scene(&metadata, 5, &G, 0.0, 8, 4, 1).unwrap();
    let n = scene.particle_type.len();
    for floor in Floor::ALL {
        let model = floor.model::<NdArray>(&metadata, 5, &device).unwrap();
        let batch =
            GraphBatch::from_host(&scene.window, &scene.particle_type, model.spec(), &device)
                .unwrap();
        let predicted = model.acceleration(&batch).unwrap().to_vec();
        let want = floor.acceleration(&metadata);
        for i in 0..n {
            for a in 0..2 {
                let got = f64::from(predicted[i * 2 + a]);
                assert!(
                    (got - want[a]).abs() <= 1e-6 * metadata.acc_std[a],
                    "{}: particle {i} axis {a}: {got} for {}",
                    floor.name(),
                    want[a]
                );
            }
        }
        // Constant velocity: the next position continues the last step.
        if floor == Floor::ConstantVelocity {
            let next = model.next_positions(&batch).unwrap().to_vec();
            let w = &scene.window;
            for i in 0..n {
                for a in 0..2 {
                    let last = f64::from(w[(i * 6 + 5) * 2 + a]);
                    let before = f64::from(w[(i * 6 + 4) * 2 + a]);
                    let got = f64::from(next[i * 2 + a]);
                    assert!((got - (2.0 * last - before)).abs() < 1e-6, "particle {i}");
                }
            }
        }
    }
    assert_eq!(
        Floor::from_name("mean-acceleration"),
        Some(Floor::MeanAcceleration)
    );
    assert_eq!(Floor::from_name("gravity"), None);
}

#[test]
fn the_probe_scene_falls_with_gravity_above_a_pool_at_rest() {
    let metadata = common::metadata();
    let c = 5;
    let scene = probe_scene(&metadata, c, &G, 0.0, 8, 4, 3).unwrap();
    let n = scene.particle_type.len();
    assert!(scene.particle_type.iter().all(|&t| t == LIQUID));
    let falling = scene.falling.iter().filter(|f| **f).count();
    // 32 × 4 pool cells and a 6 × 6 block, 8 particles each.
    assert_eq!((n - falling, falling), (32 * 4 * 8, 36 * 8));
    let g = 9.81 * metadata.position_scale * metadata.dt * metadata.dt;
    assert!((scene.gravity[1] + g).abs() < 1e-15 && scene.gravity[0] == 0.0);
    let (lo, hi) = (metadata.bounds[1][0], metadata.bounds[1][1]);
    let mut pool_top = f64::MIN;
    let mut block_bottom = f64::MAX;
    for i in 0..n {
        let at = |k: usize, a: usize| f64::from(scene.window[(i * (c + 1) + k) * 2 + a]);
        for k in 0..=c {
            assert!((lo..=hi).contains(&at(k, 1)) && (0.1..=0.9).contains(&at(k, 0)));
        }
        for k in 1..c {
            for a in 0..2 {
                let second = at(k + 1, a) - 2.0 * at(k, a) + at(k - 1, a);
                let want = if scene.falling[i] {
                    scene.gravity[a]
                } else {
                    0.0
                };
                // f32 positions of ~0.5: second differences good to a few 1e-8.
                assert!(
                    (second - want).abs() < 2e-7,
                    "particle {i} frame {k} axis {a}"
                );
            }
        }
        if scene.falling[i] {
            block_bottom = block_bottom.min(at(c, 1));
        } else {
            pool_top = pool_top.max(at(c, 1));
        }
    }
    // The pool fills the bottom 4 rows; the block is beyond the model's reach above it.
    assert!(pool_top <= lo + 4.0 * metadata.position_scale);
    assert!(block_bottom - pool_top > 10.0 * metadata.position_scale);
    // Another seed jitters the particles, not the layout.
    let other = probe_scene(&metadata, c, &G, 0.0, 8, 4, 4).unwrap();
    assert_eq!(other.falling, scene.falling);
    assert_ne!(other.window, scene.window);
}

#[test]
fn the_probe_reads_the_floors_as_fractions_of_gravity() {
    let mut metadata = common::metadata();
    let device = NdArray::default_device();
    let scene = probe_scene(&metadata, 5, &G, 0.0, 8, 4, 0).unwrap();
    // A dataset whose mean acceleration is gravity: the mean-acceleration floor is exact for
    // the falling block and wrong by |g| for the pool.
    metadata.acc_mean = scene.gravity.clone();
    let exact = Floor::MeanAcceleration
        .model::<NdArray>(&metadata, 5, &device)
        .unwrap();
    let r = probe(&exact, &scene, &device).unwrap();
    assert!((r.falling_along_gravity - 1.0).abs() < 1e-4, "{r:?}");
    assert!(r.falling_across_gravity < 1e-4, "{r:?}");
    assert!((r.resting_over_gravity - 1.0).abs() < 1e-4, "{r:?}");
    assert!(
        (r.resting_rms / scene.gravity[1].abs() - 1.0).abs() < 1e-4,
        "{r:?}"
    );
    let still = Floor::ConstantVelocity
        .model::<NdArray>(&metadata, 5, &device)
        .unwrap();
    let r = probe(&still, &scene, &device).unwrap();
    assert!(
        r.falling_along_gravity.abs() < 1e-4 && r.resting_over_gravity < 1e-4,
        "{r:?}"
    );
}

#[test]
fn a_thrown_block_keeps_its_sideways_velocity_and_the_probe_reads_drag_with_its_sign() {
    let mut metadata = common::metadata();
    let device = NdArray::default_device();
    let c = 5;
    let throw = 5.0; // cells per second
    let scene = probe_scene(&metadata, c, &G, throw, 8, 4, 2).unwrap();
    let u = throw * metadata.dt * metadata.position_scale;
    assert_eq!(scene.throw, vec![u, 0.0]);
    let dropped = probe_scene(&metadata, c, &G, 0.0, 8, 4, 2).unwrap();
    assert_eq!(dropped.throw, vec![0.0, 0.0]);
    let centre = 0.5 * (metadata.bounds[0][0] + metadata.bounds[0][1]);
    let (mut sum, mut count) = (0.0, 0usize);
    for i in 0..scene.falling.len() {
        let at = |w: &[f32], k: usize, a: usize| f64::from(w[(i * (c + 1) + k) * 2 + a]);
        for k in 1..=c {
            let first = at(&scene.window, k, 0) - at(&scene.window, k - 1, 0);
            let want = if scene.falling[i] { u } else { 0.0 };
            assert!((first - want).abs() < 2e-7, "particle {i} frame {k}");
            // The vertical motion is the dropped block's.
            let dy = at(&scene.window, k, 1) - at(&dropped.window, k, 1);
            assert!(dy.abs() < 1e-7, "particle {i} frame {k}");
        }
        if scene.falling[i] {
            // Extrapolated to the frame after the window, where the block is centred across.
            sum += at(&scene.window, c, 0) + u;
            count += 1;
        }
    }
    // The mean of the jitter (uniform in each cell, 288 particles) is within a tenth of a cell.
    let mean = sum / count as f64;
    assert!(
        (mean - centre).abs() < 0.1 * metadata.position_scale,
        "{mean} vs {centre}"
    );
    // A model whose prediction is gravity plus a tenth of |g| against the +x axis reads as drag
    // for a block thrown along +x and as a push for one thrown along −x.
    let g = scene.gravity[1].abs();
    metadata.acc_mean = vec![-0.1 * g, scene.gravity[1]];
    let braking = Floor::MeanAcceleration
        .model::<NdArray>(&metadata, c, &device)
        .unwrap();
    let r = probe(&braking, &scene, &device).unwrap();
    assert!((r.falling_along_throw + 0.1).abs() < 1e-4, "{r:?}");
    assert!((r.falling_across_gravity - 0.1).abs() < 1e-4, "{r:?}");
    let back = probe_scene(&metadata, c, &G, -throw, 8, 4, 2).unwrap();
    let r = probe(&braking, &back, &device).unwrap();
    assert!((r.falling_along_throw - 0.1).abs() < 1e-4, "{r:?}");
    let r = probe(&braking, &dropped, &device).unwrap();
    assert_eq!(r.falling_along_throw, 0.0);
}

#[test]
fn a_probe_scene_that_does_not_fit_is_refused() {
    let metadata = common::metadata();
    let error = probe_scene(&metadata, 5, &[0.0], 0.0, 8, 4, 0)
        .unwrap_err()
        .to_string();
    assert!(error.contains("gravity has 1 components"), "{error}");
    let error = probe_scene(&metadata, 5, &[0.0, 0.0], 0.0, 8, 4, 0)
        .unwrap_err()
        .to_string();
    assert!(error.contains("not zero"), "{error}");
    let error = probe_scene(&metadata, 5, &G, 0.0, 8, 60, 0)
        .unwrap_err()
        .to_string();
    assert!(error.contains("fewer fallen frames"), "{error}");
    let error = probe_scene(&metadata, 5, &G, 400.0, 8, 4, 0)
        .unwrap_err()
        .to_string();
    assert!(error.contains("between it and the walls"), "{error}");
    let error = probe_scene(&metadata, 5, &G, f64::NAN, 8, 4, 0)
        .unwrap_err()
        .to_string();
    assert!(error.contains("finite"), "{error}");
}
