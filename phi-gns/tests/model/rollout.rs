//! Rollouts on small synthetic trajectories: kinematic particles follow the ground truth, the
//! predictions feed back into the window, ranges are checked, and a rollout that produces a
//! non-finite position stops there with the frames before it delivered; clamped walls stop a
//! particle at the wall and leave its motion along it, and so does an obstacle it is pushed out
//! of.

use phi_core::Tensor;
use phi_gns::data::{LIQUID, OBSTACLE, Trajectory};
use phi_gns::model::{
    Floor, Gns, GnsKernels, GraphBatch, ModelError, Obstacles, Parameters, Walls,
};
use phi_gns::rollout::{Rollout, RolloutRange, TrajectoryRollout, rollout, rollout_positions};

use crate::common::{self, Rng, bits, perturbed};

phi_core::backend_tests!(
    kinematic_particles_follow_the_truth_and_predictions_feed_back,
    a_nan_prediction_stops_the_rollout_at_step_one,
    an_overflow_stops_the_rollout_at_the_step_it_happens,
    the_device_stepper_equals_a_window_rebuilt_on_the_host_every_step,
    the_stepper_reads_each_frame_once_and_slides_it_in,
    clamped_walls_stop_a_particle_at_the_wall_and_keep_its_motion_along_it,
    pushing_out_of_obstacles_stops_a_particle_at_a_thin_wall_it_would_cross,
);

/// `C` of the models here (the thesis' 5).
const C: usize = 5;

/// 3 obstacle particles (first, so that a particle index shows whether the kinematic ones were
/// overwritten before the finiteness check) sliding along x, then 6 liquid particles falling,
/// `frames` frames in 2D inside the bounds.
fn trajectory(frames: usize) -> Trajectory {
    let mut rng = Rng::new(5);
    let mut start: Vec<([f64; 2], i64)> = (0..3)
        .map(|k| ([0.3 + 0.01 * k as f64, 0.3], OBSTACLE))
        .collect();
    for i in 0..6 {
        start.push((
            [0.3 + 0.01 * (i % 3) as f64, 0.315 + 0.01 * (i / 3) as f64],
            LIQUID,
        ));
    }
    let mut position = Vec::new();
    for t in 0..frames {
        for (p, kind) in &start {
            let t = t as f64;
            let (x, y) = if *kind == OBSTACLE {
                (p[0] + 3e-4 * t, p[1])
            } else {
                (
                    p[0] + 2e-4 * t + 1e-4 * (rng.uniform() - 0.5),
                    p[1] - 0.5e-4 * t * t,
                )
            };
            position.extend([x as f32, y as f32]);
        }
    }
    let types = start.iter().map(|(_, t)| *t).collect();
    Trajectory::new(2, position, types, 0, 0).unwrap()
}

fn small_model<B: GnsKernels>() -> Gns<B> {
    let spec = common::spec(common::config(16, 16, 2, 2), 3);
    let params = Parameters::init(&spec.config, spec.seed, &B::default_device());
    Gns::new(spec, perturbed(&params, 6)).unwrap()
}

/// The window `[N, C + 1, 2]` of frames `frames` (each `[N, 2]`), oldest first.
fn window(frames: &[&[f32]], n: usize) -> Vec<f32> {
    let mut window = Vec::new();
    for i in 0..n {
        for frame in frames {
            window.extend_from_slice(&frame[2 * i..2 * i + 2]);
        }
    }
    window
}

fn kinematic_particles_follow_the_truth_and_predictions_feed_back<B: GnsKernels>() {
    let device = B::default_device();
    let model = small_model::<B>();
    let trajectory = trajectory(10);
    let n = trajectory.particles;
    let range = RolloutRange { start: C, steps: 4 };
    let mut frames: Vec<Vec<f32>> = Vec::new();
    rollout(&model, &trajectory, range, &device, |step, positions| {
        assert_eq!(step, frames.len() + 1, "steps count from 1, in order");
        assert_eq!(positions.len(), n * 2);
        frames.push(positions.to_vec());
        Ok(())
    })
    .unwrap();
    assert_eq!(frames.len(), 4);
    let collected = rollout_positions(&model, &trajectory, range, &device).unwrap();
    assert_eq!(bits(&collected), bits(&frames.concat()));

    for (k, frame) in frames.iter().enumerate() {
        let truth = trajectory.frame(C + 1 + k);
        for i in 0..n {
            let (got, expected) = (&frame[2 * i..2 * i + 2], &truth[2 * i..2 * i + 2]);
            if trajectory.particle_type[i] == OBSTACLE {
                assert_eq!(bits(got), bits(expected), "step {}: obstacle {i}", k + 1);
            } else {
                // The untrained model does not reproduce the truth (so that the equality of
                // the obstacles above means something).
                assert_ne!(got, expected, "step {}: liquid particle {i}", k + 1);
            }
        }
    }

    // Step 1 is the model's next positions of frames 0..=C; step 2 that of frames 1..=C and
    // the prediction of step 1 (its obstacles from the truth).
    let next = |frames: &[&[f32]]| {
        let batch = GraphBatch::from_host(
            &window(frames, n),
            &trajectory.particle_type,
            model.spec(),
            &device,
        )
        .unwrap();
        model.next_positions(&batch).unwrap().to_vec()
    };
    let truth: Vec<&[f32]> = (0..=C + 1).map(|t| trajectory.frame(t)).collect();
    let first = next(&truth[..=C]);
    let mut second_window = truth[1..=C].to_vec();
    second_window.push(&frames[0]);
    let second = next(&second_window);
    for (step, expected) in [(0, &first), (1, &second)] {
        for i in (0..n).filter(|&i| trajectory.particle_type[i] == LIQUID) {
            assert_eq!(
                bits(&frames[step][2 * i..2 * i + 2]),
                bits(&expected[2 * i..2 * i + 2]),
                "step {}: particle {i}",
                step + 1
            );
        }
    }
}

#[test]
fn a_range_is_checked_against_the_window_and_the_trajectory() {
    let frames = 10;
    // The first possible start is frame C, the last possible end the last frame.
    assert_eq!(
        RolloutRange::full(C, frames),
        RolloutRange { start: C, steps: 4 }
    );
    RolloutRange { start: C, steps: 4 }
        .check(C, frames)
        .unwrap();
    RolloutRange { start: 8, steps: 1 }
        .check(C, frames)
        .unwrap();
    RolloutRange { start: 9, steps: 0 }
        .check(C, frames)
        .unwrap();

    let error = RolloutRange { start: 4, steps: 1 }
        .check(C, frames)
        .unwrap_err();
    assert!(
        matches!(&error, ModelError::Input { what: "rollout start", reason }
            if reason.contains("frame 4") && reason.contains("5 frames")),
        "{error:?}"
    );
    let error = RolloutRange { start: C, steps: 5 }
        .check(C, frames)
        .unwrap_err();
    assert!(
        matches!(&error, ModelError::Input { what: "rollout steps", reason }
            if reason.contains("5 steps") && reason.contains("frame 5")
                && reason.contains("last frame 9")),
        "{error:?}"
    );
    // A huge step count does not overflow.
    RolloutRange {
        start: C,
        steps: usize::MAX - 2,
    }
    .check(C, frames)
    .unwrap_err();

    // rollout checks the range before predicting anything.
    let model = small_model::<phi_core::backend::Host>();
    let trajectory = trajectory(frames);
    for range in [
        RolloutRange { start: 4, steps: 1 },
        RolloutRange { start: C, steps: 5 },
    ] {
        let mut called = false;
        let error = rollout(&model, &trajectory, range, &Default::default(), |_, _| {
            called = true;
            Ok(())
        })
        .unwrap_err();
        assert!(matches!(error, ModelError::Input { .. }), "{error:?}");
        assert!(!called);
    }
}

fn a_nan_prediction_stops_the_rollout_at_step_one<B: GnsKernels>() {
    let device = B::default_device();
    let model = small_model::<B>();
    let last = format!("decoder.{}.bias", model.spec().config.hidden_layers);
    let broken = model
        .with_params(model.params().map(|name, t| {
            if name == last {
                Tensor::full(&t.shape(), f32::NAN, &t.device())
            } else {
                t.clone()
            }
        }))
        .unwrap();
    let trajectory = trajectory(10);
    let mut delivered = Vec::new();
    let range = RolloutRange { start: C, steps: 4 };
    let error = rollout(&broken, &trajectory, range, &device, |step, _| {
        delivered.push(step);
        Ok(())
    })
    .unwrap_err();
    // Particles 0..3 are obstacles, whose positions come from the truth: the first
    // non-finite one is the first liquid particle.
    assert!(
        matches!(
            error,
            ModelError::NonFinitePrediction {
                step: 1,
                frame: 6,
                particle: 3
            }
        ),
        "{error:?}"
    );
    assert!(delivered.is_empty(), "{delivered:?}");
    let message = error.to_string();
    assert!(
        message.contains("step 1") && message.contains("frame 6") && message.contains("particle 3")
    );
}

fn an_overflow_stops_the_rollout_at_the_step_it_happens<B: GnsKernels>() {
    // One liquid particle moving along x by 5e37 per frame, ending the window at 1.5e38, and
    // two resting obstacles. With vel_std 1e38 its velocity features stay O(1) (and its
    // boundary features clip), the network's acceleration is ~1e-4, so the predictions are
    // 2e38, 2.5e38, 3e38 and then 3.5e38, beyond f32::MAX (3.4e38): step 4 overflows.
    let device = B::default_device();
    let mut metadata = common::metadata();
    metadata.vel_std = vec![1e38, 1e38];
    let spec = phi_gns::model::ModelSpec::for_dataset(&metadata, common::config(8, 8, 1, 1), 2);
    let model = Gns::<B>::init(spec, &device).unwrap();
    let frames = 12;
    let mut position = Vec::new();
    for t in 0..frames {
        let x = (-1e38 + 5e37 * t.min(C) as f64) as f32;
        position.extend([0.5, 0.5, 0.52, 0.5, x, 0.5]);
    }
    let trajectory = Trajectory::new(2, position, vec![OBSTACLE, OBSTACLE, LIQUID], 0, 0).unwrap();
    let mut delivered: Vec<Vec<f32>> = Vec::new();
    let range = RolloutRange { start: C, steps: 6 };
    let error = rollout(&model, &trajectory, range, &device, |_, positions| {
        delivered.push(positions.to_vec());
        Ok(())
    })
    .unwrap_err();
    assert!(
        matches!(
            error,
            ModelError::NonFinitePrediction {
                step: 4,
                frame: 9,
                particle: 2
            }
        ),
        "{error:?}"
    );
    assert_eq!(delivered.len(), 3);
    for (k, frame) in delivered.iter().enumerate() {
        assert!(frame.iter().all(|x| x.is_finite()));
        let expected = 1.5e38 + 5e37 * (k + 1) as f64;
        assert!(
            (f64::from(frame[4]) - expected).abs() < 1e-6 * expected,
            "step {}: {}",
            k + 1,
            frame[4]
        );
        assert_eq!(&frame[..4], &[0.5, 0.5, 0.52, 0.5]);
    }
}

/// The rollout as it was written before the device stepper: the window rebuilt on the host
/// from the kept frames every step, uploaded, the kinematic rows overwritten on the host.
fn host_window_rollout<B: GnsKernels>(
    model: &Gns<B>,
    trajectory: &Trajectory,
    range: RolloutRange,
) -> Vec<Vec<f32>> {
    let device = B::default_device();
    let n = trajectory.particles;
    let mut history: Vec<Vec<f32>> = (range.start - C..=range.start)
        .map(|t| trajectory.frame(t).to_vec())
        .collect();
    let mut frames = Vec::new();
    for step in 1..=range.steps {
        let refs: Vec<&[f32]> = history.iter().map(Vec::as_slice).collect();
        let batch = GraphBatch::from_host(
            &window(&refs, n),
            &trajectory.particle_type,
            model.spec(),
            &device,
        )
        .unwrap();
        let mut next = model.next_positions(&batch).unwrap().to_vec();
        let truth = trajectory.frame(range.start + step);
        for i in (0..n).filter(|&i| trajectory.particle_type[i] == OBSTACLE) {
            next[2 * i..2 * i + 2].copy_from_slice(&truth[2 * i..2 * i + 2]);
        }
        frames.push(next.clone());
        history.remove(0);
        history.push(next);
    }
    frames
}

fn the_device_stepper_equals_a_window_rebuilt_on_the_host_every_step<B: GnsKernels>() {
    let device = B::default_device();
    let model = small_model::<B>();
    let trajectory = trajectory(30);
    let range = RolloutRange::full(C, trajectory.frames);
    let expected = host_window_rollout(&model, &trajectory, range);
    let frames: Vec<_> = TrajectoryRollout::new(&model, &trajectory, range, &device)
        .unwrap()
        .collect::<Result<_, _>>()
        .unwrap();
    assert_eq!(frames.len(), range.steps);
    for (k, (frame, expected)) in frames.iter().zip(&expected).enumerate() {
        assert_eq!((frame.step, frame.frame), (k + 1, C + k + 1));
        assert_eq!(bits(&frame.positions), bits(expected), "step {}", k + 1);
        assert_eq!(
            bits(&frame.tensor.to_vec()),
            bits(expected),
            "step {}",
            k + 1
        );
    }
}

fn the_stepper_reads_each_frame_once_and_slides_it_in<B: GnsKernels>() {
    let device = B::default_device();
    let model = small_model::<B>();
    let trajectory = trajectory(12);
    let n = trajectory.particles;
    let start = GraphBatch::from_host(
        &phi_gns::rollout::input_window(&trajectory, C, C),
        &trajectory.particle_type,
        model.spec(),
        &device,
    )
    .unwrap();
    let mut read = Rollout::new(&model, start.clone()).unwrap();
    let mut unread = Rollout::new(&model, start).unwrap();
    assert!(
        read.read().is_empty(),
        "nothing to read before the first step"
    );
    for step in 1..=4 {
        let truth = Tensor::from_slice(trajectory.frame(C + step), &[n, 2], &device).unwrap();
        let a = read.step(&truth).unwrap().to_vec();
        let b = unread.step(&truth).unwrap().to_vec();
        // Whether the caller reads a frame does not change the next step.
        assert_eq!(bits(&a), bits(&b), "step {step}");
        assert_eq!(bits(read.read()), bits(&a));
        // The window the next step reads ends with this step's positions.
        let window = read.window().unwrap().positions().to_vec();
        for i in 0..n {
            let latest = &window[(i * (C + 1) + C) * 2..(i * (C + 1) + C) * 2 + 2];
            assert_eq!(
                bits(latest),
                bits(&a[2 * i..2 * i + 2]),
                "step {step}: particle {i}"
            );
        }
    }
    let wrong = Tensor::<B>::zeros(&[n + 1, 2], &device);
    assert!(matches!(
        read.step(&wrong),
        Err(ModelError::Input {
            what: "kinematic positions",
            ..
        })
    ));
}

/// The constant-velocity floor rolled out on two liquid particles moving in straight lines: one
/// towards the right wall (x = 0.9) and up, one in the middle of the domain. With open walls
/// both go on in straight lines; with clamped walls the first stops on the wall after the step
/// that would cross it (x = 0.9 from then on, so its velocity across the wall, read from the
/// window, drops to 0 two steps later), keeps moving up at its velocity, and the second moves
/// exactly as with open walls.
fn clamped_walls_stop_a_particle_at_the_wall_and_keep_its_motion_along_it<B: GnsKernels>() {
    let device = B::default_device();
    let metadata = common::metadata();
    let open = Floor::ConstantVelocity
        .model::<B>(&metadata, C, &device)
        .unwrap();
    assert_eq!(open.spec().config.walls, Walls::Open);
    let clamped = open.with_walls(Walls::Clamp);
    let (start, velocity) = (
        [[0.80f32, 0.40], [0.50, 0.50]],
        [[0.02f32, 0.01], [0.01, -0.01]],
    );
    let frames: Vec<Vec<f32>> = (0..=C)
        .map(|t| {
            let t = t as f32 - C as f32;
            (0..2)
                .flat_map(|i| (0..2).map(move |a| start[i][a] + velocity[i][a] * t))
                .collect()
        })
        .collect();
    let refs: Vec<&[f32]> = frames.iter().map(Vec::as_slice).collect();
    let types = [LIQUID, LIQUID];
    let steps = 12;
    let run = |model: &Gns<B>| -> Vec<Vec<f32>> {
        let batch =
            GraphBatch::from_host(&window(&refs, 2), &types, model.spec(), &device).unwrap();
        let mut stepper = Rollout::new(model, batch).unwrap();
        let unused = Tensor::zeros(&[2, 2], &device);
        (0..steps)
            .map(|_| {
                stepper.step(&unused).unwrap();
                stepper.read().to_vec()
            })
            .collect()
    };
    let (free, walled) = (run(&open), run(&clamped));
    for k in 1..=steps {
        let (f, w) = (&free[k - 1], &walled[k - 1]);
        let straight = |i: usize, a: usize| start[i][a] + velocity[i][a] * k as f32;
        for a in 0..2 {
            assert!(
                (f[a] - straight(0, a)).abs() < 1e-5,
                "open, step {k}: {f:?}"
            );
            assert!(
                (f[2 + a] - straight(1, a)).abs() < 1e-5,
                "open, step {k}: {f:?}"
            );
            assert_eq!(
                w[2 + a].to_bits(),
                f[2 + a].to_bits(),
                "clamped, middle, step {k}"
            );
        }
        // Along the wall: the straight line, clamped or not.
        assert!(
            (w[1] - straight(0, 1)).abs() < 1e-5,
            "clamped, step {k}: {w:?}"
        );
        // Across it: the straight line until it would cross 0.9 (after step 5), the wall after.
        let across = straight(0, 0).min(0.9);
        assert!((w[0] - across).abs() < 1e-5, "clamped, step {k}: {w:?}");
        assert!(w[0] <= 0.9, "clamped, step {k}: {} beyond the wall", w[0]);
    }
    assert!(
        free[steps - 1][0] > 1.0,
        "the open rollout leaves the domain"
    );
}

/// The constant-velocity floor rolled out beside a vertical wall one obstacle cell thick (cells
/// of side 0.025 from the lower bound 0.1: the column of cell 20, x from 0.6 to 0.625, centres
/// at x = 0.6125, rows 6 to 20). One liquid particle moves towards it at 0.01 a frame (less than
/// half a cell) and slowly up; another moves in the open. Open, the first runs through the
/// wall; pushed, it is never inside a wall cell, ends on the wall's near face (x = 0.6) after
/// the step that enters the cell, keeps its motion along the wall, and the second moves exactly
/// as in the open rollout.
fn pushing_out_of_obstacles_stops_a_particle_at_a_thin_wall_it_would_cross<B: GnsKernels>() {
    let device = B::default_device();
    let metadata = common::metadata();
    let open = Floor::ConstantVelocity
        .model::<B>(&metadata, C, &device)
        .unwrap();
    assert_eq!(open.spec().config.obstacles, Obstacles::Open);
    let cell = 0.025f32;
    let pushed = open
        .with_obstacles(Obstacles::Push {
            cell_size: f64::from(cell),
        })
        .unwrap();
    assert!(
        open.with_obstacles(Obstacles::Push { cell_size: 0.0 })
            .is_err(),
        "a zero cell is refused"
    );
    let wall: Vec<[f32; 2]> = (6..=20)
        .map(|j| [0.1 + cell * 20.5, 0.1 + cell * (j as f32 + 0.5)])
        .collect();
    let (start, velocity) = (
        [[0.553f32, 0.40], [0.30, 0.50]],
        [[0.01f32, 0.002], [-0.005, 0.0]],
    );
    let mut types = vec![OBSTACLE; wall.len()];
    types.extend([LIQUID, LIQUID]);
    let n = types.len();
    let frames: Vec<Vec<f32>> = (0..=C)
        .map(|t| {
            let t = t as f32 - C as f32;
            let mut frame: Vec<f32> = wall.iter().flatten().copied().collect();
            for i in 0..2 {
                frame.extend((0..2).map(|a| start[i][a] + velocity[i][a] * t));
            }
            frame
        })
        .collect();
    let refs: Vec<&[f32]> = frames.iter().map(Vec::as_slice).collect();
    let kinematic = Tensor::from_slice(&frames[C], &[n, 2], &device).unwrap();
    let steps = 12;
    let run = |model: &Gns<B>| -> Vec<Vec<f32>> {
        let batch =
            GraphBatch::from_host(&window(&refs, n), &types, model.spec(), &device).unwrap();
        let mut stepper = Rollout::new(model, batch).unwrap();
        (0..steps)
            .map(|_| {
                stepper.step(&kinematic).unwrap();
                stepper.read().to_vec()
            })
            .collect()
    };
    let (free, walled) = (run(&open), run(&pushed));
    let first = 2 * wall.len();
    let in_wall = |p: &[f32]| {
        wall.iter()
            .any(|q| (p[0] - q[0]).abs() < 0.5 * cell && (p[1] - q[1]).abs() < 0.5 * cell)
    };
    for k in 1..=steps {
        let (f, w) = (&free[k - 1], &walled[k - 1]);
        assert_eq!(&w[..first], &frames[C][..first], "the wall stays, step {k}");
        let mover = &w[first..first + 2];
        assert!(
            !in_wall(mover),
            "pushed, step {k}: {mover:?} inside the wall"
        );
        assert!(
            (mover[1] - (start[0][1] + velocity[0][1] * k as f32)).abs() < 1e-5,
            "pushed, step {k}: {mover:?} lost its motion along the wall"
        );
        if k >= 5 {
            // Step 5 would put it at 0.603, inside: it lands on the near face and stays there.
            assert!(
                (mover[0] - 0.6).abs() < 1e-4,
                "pushed, step {k}: {mover:?} not on the wall's face"
            );
        } else {
            assert_eq!(mover[0].to_bits(), f[first].to_bits(), "step {k}");
        }
        for a in 0..2 {
            assert_eq!(
                w[first + 2 + a].to_bits(),
                f[first + 2 + a].to_bits(),
                "pushed, the other particle, step {k}"
            );
        }
    }
    assert!(
        free[steps - 1][first] > 0.625,
        "the open rollout runs through the wall: {:?}",
        &free[steps - 1][first..first + 2]
    );
}
