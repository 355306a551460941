//! The evaluation metrics: hand-computed kinetic energies and neighbour counts, and the
//! bookkeeping of a trajectory's evaluation checked against independent rollouts (MSE 20 from
//! rollouts started at the stated frames, MSE 400 the mean of its curve, the EMD bounded by the
//! identity assignment), the summary of a blown-up rollout, and the bands over trajectories.

use phi_core::backend::ndarray::NdArray;
use phi_core::{Backend, Tensor};
use phi_gns::data::{LIQUID, OBSTACLE, Trajectory};
use phi_gns::eval::metrics::{kinetic_energy, liquid_positions, mean_neighbour_count};
use phi_gns::eval::{
    Band, EvalOptions, ModelSummary, evaluate_trajectory, mse_acc1, mse_acc1_in, one_step_errors,
};
use phi_gns::model::{Gns, Normalisation, Parameters};
use phi_gns::rollout::{RolloutRange, position_mse, rollout_positions};

use crate::common::{self, Rng, perturbed};

/// `C` of the models here (the thesis' 5).
const C: usize = 5;

/// 3 obstacle particles sliding along x, then 8 liquid particles falling with a little noise,
/// `frames` frames in 2D inside the bounds.
fn trajectory(frames: usize) -> Trajectory {
    let mut rng = Rng::new(11);
    let mut start: Vec<([f64; 2], i64)> = (0..3)
        .map(|k| ([0.3 + 0.01 * k as f64, 0.3], OBSTACLE))
        .collect();
    for i in 0..8 {
        start.push((
            [0.3 + 0.01 * (i % 4) as f64, 0.315 + 0.01 * (i / 4) as f64],
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
                    p[1] - 0.2e-4 * t * t,
                )
            };
            position.extend([x as f32, y as f32]);
        }
    }
    let types = start.iter().map(|(_, t)| *t).collect();
    Trajectory::new(2, position, types, 0, 0).unwrap()
}

fn small_model() -> Gns<NdArray> {
    let spec = common::spec(common::config(16, 16, 2, 2), 3);
    let params = Parameters::init(&spec.config, spec.seed, &NdArray::default_device());
    Gns::new(spec, perturbed(&params, 6)).unwrap()
}

#[test]
fn kinetic_energy_of_a_uniform_motion_is_half_the_squared_speed() {
    // Three particles moving by (3, 4)·1e-3 per frame, one kinematic one standing still.
    let previous = [0.1f32, 0.2, 0.5, 0.5, 0.3, 0.4, 0.7, 0.7];
    let current: Vec<f32> = previous
        .chunks(2)
        .enumerate()
        .flat_map(|(i, p)| {
            if i == 3 {
                [p[0], p[1]]
            } else {
                [p[0] + 3e-3, p[1] + 4e-3]
            }
        })
        .collect();
    let liquid = [true, true, true, false];
    let ke = kinetic_energy(&previous, &current, &liquid, 2);
    approx::assert_relative_eq!(ke, 0.5 * 25e-6, max_relative = 1e-4);
    // Only kinematic particles: no liquid, no energy.
    assert_eq!(kinetic_energy(&previous, &current, &[false; 4], 2), 0.0);
}

#[test]
fn neighbour_counts_of_a_lattice_are_those_counted_by_hand() {
    // A 3×3 lattice of spacing h with a radius between h and √2 h: corners have 2 neighbours,
    // edges 3, the centre 4; a far kinematic particle does not count.
    let h = 0.01f32;
    let mut frame = Vec::new();
    for j in 0..3 {
        for i in 0..3 {
            frame.extend([0.2 + h * i as f32, 0.2 + h * j as f32]);
        }
    }
    frame.extend([0.2 + h, 0.2 + h]);
    let mut liquid = vec![true; 9];
    liquid.push(false);
    let count = mean_neighbour_count(&frame, &liquid, 2, 1.2 * f64::from(h)).unwrap();
    approx::assert_relative_eq!(
        count,
        (4.0 * 2.0 + 4.0 * 3.0 + 4.0) / 9.0,
        max_relative = 1e-12
    );
    // Within √2 h < R < 2h the diagonals join: corners 3, edges 5, centre 8.
    let count = mean_neighbour_count(&frame, &liquid, 2, 1.5 * f64::from(h)).unwrap();
    approx::assert_relative_eq!(
        count,
        (4.0 * 3.0 + 4.0 * 5.0 + 8.0) / 9.0,
        max_relative = 1e-12
    );
    assert_eq!(liquid_positions(&frame, &liquid, 2).len(), 18);
}

#[test]
fn a_trajectory_evaluation_agrees_with_independent_rollouts() {
    let device = NdArray::default_device();
    let model = small_model();
    let frames = 32;
    let trajectory = trajectory(frames);
    let kinematic: Vec<bool> = trajectory
        .particle_type
        .iter()
        .map(|t| *t == OBSTACLE)
        .collect();
    let mut options = EvalOptions::new(0.015);
    options.short_rollout = 10;
    options.sinkhorn_every = 13;
    options.container = Some(phi_gns::eval::metrics::Container {
        bounds: vec![[0.1, 0.9], [0.1, 0.9]],
        cell_size: 0.025,
    });
    let eval = evaluate_trajectory(&model, &trajectory, &options, &device).unwrap();

    let steps = frames - 1 - C;
    assert_eq!(eval.failed_step, None);
    assert_eq!(eval.liquid_particles, 8);
    assert_eq!(eval.acc_windows, frames - 1 - C);
    assert_eq!(eval.curves.frame, (C + 1..frames).collect::<Vec<_>>());
    for curve in [
        &eval.curves.mse,
        &eval.curves.emd,
        &eval.curves.kinetic_energy_predicted,
        &eval.curves.kinetic_energy_true,
        &eval.curves.density_predicted,
        &eval.curves.density_true,
    ] {
        assert_eq!(curve.len(), steps);
    }

    // MSE 400 is the mean of the per-frame curve, which is the MSE of an independent rollout.
    let full =
        rollout_positions(&model, &trajectory, RolloutRange::full(C, frames), &device).unwrap();
    let per_frame = trajectory.particles * 2;
    for (k, mse) in eval.curves.mse.iter().enumerate() {
        let predicted = &full[k * per_frame..(k + 1) * per_frame];
        let expected = position_mse(predicted, trajectory.frame(C + 1 + k), &kinematic, 2);
        assert_eq!(mse.to_bits(), expected.to_bits(), "frame {}", C + 1 + k);
        // The identity assignment is one transport plan: EMD ≤ Σ|p − t|² / L = dim · MSE.
        assert!(
            eval.curves.emd[k] <= 2.0 * mse * (1.0 + 1e-9),
            "frame {}",
            C + 1 + k
        );
    }
    let mean = eval.curves.mse.iter().sum::<f64>() / steps as f64;
    approx::assert_relative_eq!(eval.mse400.unwrap(), mean, max_relative = 1e-15);

    // MSE 20 (here 10): rollouts from frames C and C + 10 (C + 20 + 10 is past the end).
    assert_eq!(eval.short_windows, 2);
    let short = |start: usize| {
        let range = RolloutRange { start, steps: 10 };
        let predicted = rollout_positions(&model, &trajectory, range, &device).unwrap();
        (0..10)
            .map(|k| {
                position_mse(
                    &predicted[k * per_frame..(k + 1) * per_frame],
                    trajectory.frame(start + 1 + k),
                    &kinematic,
                    2,
                )
            })
            .sum::<f64>()
            / 10.0
    };
    let expected = 0.5 * (short(C) + short(C + 10));
    approx::assert_relative_eq!(eval.mse20.unwrap(), expected, max_relative = 1e-12);

    // MSE-acc 1 over every window equals the mean over strided windows combined.
    let (acc, windows) = mse_acc1(&model, &trajectory, 1, &device).unwrap();
    assert_eq!(
        (acc.to_bits(), windows),
        (eval.mse_acc1.to_bits(), eval.acc_windows)
    );

    // The Sinkhorn divergence at steps 13, 26 and the last one.
    let computed: Vec<usize> = eval
        .curves
        .sinkhorn
        .iter()
        .enumerate()
        .filter(|(_, s)| s.is_some())
        .map(|(k, _)| k + 1)
        .collect();
    assert_eq!(computed, vec![13, 26]);
    assert!(eval.sinkhorn.unwrap() >= 0.0);

    // The kinetic energies of the truth are those of its frames.
    let truth_ke = kinetic_energy(
        trajectory.frame(C),
        trajectory.frame(C + 1),
        &kinematic.iter().map(|k| !k).collect::<Vec<_>>(),
        2,
    );
    assert_eq!(
        eval.curves.kinetic_energy_true[0].to_bits(),
        truth_ke.to_bits()
    );
    assert!(eval.kinetic_energy_error.unwrap() >= 0.0);
    assert!(eval.density_ratio.unwrap() > 0.0);

    // The plausibility figures come from the curves and the final frames.
    let p = eval.plausibility.clone().expect("a container was given");
    assert_eq!(eval.curves.outside.len(), steps);
    let misplaced: usize = eval.curves.outside.iter().sum::<usize>()
        + eval.curves.inside_obstacles.iter().sum::<usize>();
    approx::assert_relative_eq!(
        p.outside + p.inside_obstacles,
        misplaced as f64 / (8 * steps) as f64,
        max_relative = 1e-12
    );
    let most_inside = eval.curves.inside_obstacles.iter().max().copied().unwrap();
    assert_eq!(p.peak_inside_obstacles, most_inside as f64 / 8.0);
    approx::assert_relative_eq!(
        p.final_density_ratio,
        eval.curves.density_predicted[steps - 1] / eval.curves.density_true[steps - 1],
        max_relative = 1e-12
    );
    let late = |v: &[f64]| v.iter().sum::<f64>();
    approx::assert_relative_eq!(
        p.late_kinetic_energy_ratio,
        late(&eval.curves.kinetic_energy_predicted) / late(&eval.curves.kinetic_energy_true),
        max_relative = 1e-12
    );
    let liquid: Vec<bool> = kinematic.iter().map(|k| !k).collect();
    let last = &full[(steps - 1) * per_frame..steps * per_frame];
    let (a, b) = (
        phi_gns::eval::metrics::centre_of_mass(last, &liquid, 2),
        phi_gns::eval::metrics::centre_of_mass(trajectory.frame(frames - 1), &liquid, 2),
    );
    let distance = ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)).sqrt() / 0.025;
    approx::assert_relative_eq!(
        p.final_centre_distance_cells,
        distance,
        max_relative = 1e-12
    );

    // One trajectory: the summary is its evaluation, the band its curve with zero width.
    let summary = ModelSummary::of(
        std::slice::from_ref(&eval),
        &model.spec().normalisation.acc_std,
    );
    assert_eq!(summary.mse400, eval.mse400);
    assert_eq!(summary.blown_up, 0);
    let band = Band::of(std::slice::from_ref(&eval), |e| &e.curves.mse);
    assert_eq!(band.mean, eval.curves.mse);
    assert_eq!(band.min, band.max);
}

#[test]
fn one_step_errors_in_stored_units_give_mse_acc1_in_any_normalisation() {
    // A model trained with noise σ divides its accelerations by sqrt(acc_std² + σ²): the
    // stored-unit errors divided by that scale are its own MSE-acc 1, and divided by the
    // dataset's acc_std the larger value that a model without noise would report.
    let device = NdArray::default_device();
    let mut config = common::config(16, 16, 2, 2);
    config.noise_std = 1.5e-4;
    let spec = common::spec(config, 3);
    let params = Parameters::<NdArray>::init(&spec.config, spec.seed, &device);
    let model = Gns::new(spec, perturbed(&params, 6)).unwrap();
    let trajectory = trajectory(12);
    let errors = one_step_errors(&model, &trajectory, 1, &device).unwrap();
    assert_eq!(
        (errors.mse_acc1, errors.windows),
        mse_acc1(&model, &trajectory, 1, &device).unwrap()
    );
    let plain = &model.spec().normalisation.acc_std;
    let widened = Normalisation::scale(plain, model.spec().config.noise_std);
    approx::assert_relative_eq!(
        mse_acc1_in(&errors.acc_error, &widened),
        errors.mse_acc1,
        max_relative = 1e-5
    );
    // acc_std = (1.1, 0.8)·1e-4 and σ = 1.5e-4: per dimension the plain normalisation reads
    // (1.1² + 1.5²) / 1.1² = 2.86 and (0.8² + 1.5²) / 0.8² = 4.52 times more, so the whole
    // between the two.
    let ratio = mse_acc1_in(&errors.acc_error, plain) / errors.mse_acc1;
    assert!((2.859..4.516).contains(&ratio), "{ratio}");
}

#[test]
fn a_blown_up_rollout_makes_the_rollout_metrics_infinite() {
    let device = NdArray::default_device();
    let model = small_model();
    // A model whose decoder biases are NaN: the first prediction is not finite.
    let params = model.params().map(|name, t| {
        if name.starts_with("decoder.") && name.ends_with(".bias") {
            Tensor::from_vec(vec![f32::NAN; t.numel()], &t.shape(), &t.device()).unwrap()
        } else {
            t.clone()
        }
    });
    let blowing = Gns::new(model.spec().clone(), params).unwrap();
    let trajectory = trajectory(30);
    let eval =
        evaluate_trajectory(&blowing, &trajectory, &EvalOptions::new(0.015), &device).unwrap();
    assert_eq!(eval.failed_step, Some(1));
    assert_eq!((eval.mse400, eval.emd, eval.mse20), (None, None, None));
    assert!(eval.curves.mse.is_empty());

    let fine = evaluate_trajectory(&model, &trajectory, &EvalOptions::new(0.015), &device).unwrap();
    let summary = ModelSummary::of(
        &[fine.clone(), eval.clone()],
        &model.spec().normalisation.acc_std,
    );
    assert_eq!(
        (summary.blown_up, summary.mse400, summary.emd),
        (1, None, None)
    );
    // The band covers the frames of the rollout that ran on, from it alone.
    let band = Band::of(&[fine.clone(), eval], |e| &e.curves.mse);
    assert_eq!(band.frame, fine.curves.frame);
    assert!(band.count.iter().all(|&c| c == 1));
    assert_eq!(band.mean, fine.curves.mse);
}

#[test]
fn misplaced_liquid_is_counted_outside_the_bounds_and_in_obstacle_cells() {
    use phi_gns::eval::metrics::{Container, centre_of_mass};
    let container = Container {
        bounds: vec![[0.1, 0.9], [0.1, 0.9]],
        cell_size: 0.025,
    };
    // Two obstacle particles at the centres of cells (4, 4) and (5, 4); liquid in cell (4, 4),
    // next to it in (6, 4), below the domain, and right of it.
    let centre = |i: usize, j: usize| {
        [
            0.1 + 0.025 * (i as f32 + 0.5),
            0.1 + 0.025 * (j as f32 + 0.5),
        ]
    };
    let mut frame = Vec::new();
    for p in [centre(4, 4), centre(5, 4)] {
        frame.extend(p);
    }
    let [x, y] = centre(4, 4);
    frame.extend([x + 0.01, y - 0.01]); // inside cell (4, 4)
    frame.extend(centre(6, 4)); // beside the obstacle
    frame.extend([0.5, 0.09]); // below the floor
    frame.extend([0.95, 0.5]); // right of the right wall
    let liquid = [false, false, true, true, true, true];
    let obstacles = container.obstacle_cells(&frame, &liquid, 2);
    assert_eq!(obstacles.len(), 2);
    assert_eq!(container.misplaced(&frame, &liquid, 2, &obstacles), (2, 1));
    let com = centre_of_mass(&frame, &liquid, 2);
    let want_x = (f64::from(x) + 0.01 + f64::from(centre(6, 4)[0]) + 0.5 + 0.95) / 4.0;
    assert!((com[0] - want_x).abs() < 1e-6, "{com:?}");
}

#[test]
fn plausibility_needs_every_figure_within_its_bounds() {
    use phi_gns::eval::Plausibility;
    let good = Plausibility {
        outside: 0.004,
        inside_obstacles: 0.005,
        inside_obstacles_true: 0.003,
        peak_inside_obstacles: 0.02,
        peak_inside_obstacles_true: 0.01,
        final_density_ratio: 1.1,
        late_kinetic_energy_ratio: 1.8,
        final_centre_distance_cells: 1.5,
    };
    assert!(good.is_plausible());
    let fails = [
        Plausibility {
            outside: 0.006,
            ..good.clone()
        },
        Plausibility {
            final_density_ratio: 1.3,
            ..good.clone()
        },
        Plausibility {
            final_density_ratio: 0.7,
            ..good.clone()
        },
        Plausibility {
            late_kinetic_energy_ratio: 2.1,
            ..good.clone()
        },
        Plausibility {
            late_kinetic_energy_ratio: 0.4,
            ..good.clone()
        },
        Plausibility {
            final_centre_distance_cells: 2.5,
            ..good.clone()
        },
    ];
    for p in fails {
        assert!(!p.is_plausible(), "{p:?}");
    }
    // The peak share inside obstacles is reported beside the bounds, not one of them.
    let passing = Plausibility {
        peak_inside_obstacles: 0.9,
        ..good
    };
    assert!(passing.is_plausible());
}

/// A row of four liquid particles falling one cell a frame through a thin obstacle (one row of
/// obstacle cells) is inside it in one frame of many: a small fraction of the particle-frames,
/// and all of the liquid in that frame. Stopped on the obstacle's top face, it is never inside.
#[test]
fn a_block_passing_through_a_thin_obstacle_peaks_at_all_of_the_liquid() {
    use phi_gns::eval::compare_trajectories;
    let cell = 0.025f32;
    let centre = |i: usize, j: f32| [0.1 + cell * (i as f32 + 0.5), 0.1 + cell * (j + 0.5)];
    let frames = 20;
    // Cells (10..16, 10) hold the obstacle; the liquid falls in columns 11..15 from row 19.
    let scene = |stop: Option<f32>| {
        let mut position = Vec::new();
        for t in 0..frames {
            for i in 10..16 {
                position.extend(centre(i, 10.0));
            }
            let row = (19.0 - t as f32).max(stop.unwrap_or(f32::MIN));
            for i in 11..15 {
                position.extend(centre(i, row));
            }
        }
        let types = [vec![OBSTACLE; 6], vec![LIQUID; 4]].concat();
        Trajectory::new(2, position, types, 0, 0).unwrap()
    };
    let (through, stopped) = (scene(None), scene(Some(11.0)));
    let comparison =
        compare_trajectories(&through, &stopped, C, &[OBSTACLE], &comparison_options()).unwrap();
    let p = comparison.plausibility.unwrap();
    let steps = frames - 1 - C;
    // Frame 9 puts the liquid in row 10, the obstacle's.
    assert_eq!(p.inside_obstacles, 1.0 / steps as f64);
    assert_eq!(p.peak_inside_obstacles, 1.0);
    assert_eq!(
        (p.inside_obstacles_true, p.peak_inside_obstacles_true),
        (0.0, 0.0)
    );
    assert_eq!(p.outside, 0.0);
}

/// `trajectory`'s liquid moved by `shift` in every frame (its obstacle particles stay).
fn shifted(trajectory: &Trajectory, shift: [f32; 2]) -> Trajectory {
    let mut position = trajectory.position.clone();
    for (p, kind) in position
        .chunks_exact_mut(2)
        .zip(trajectory.particle_type.iter().cycle())
    {
        if *kind == LIQUID {
            p[0] += shift[0];
            p[1] += shift[1];
        }
    }
    Trajectory::new(2, position, trajectory.particle_type.clone(), 0, 0).unwrap()
}

fn comparison_options() -> EvalOptions {
    let mut options = EvalOptions::new(0.015);
    options.sinkhorn_every = 0;
    options.container = Some(phi_gns::eval::metrics::Container {
        bounds: vec![[0.1, 0.9], [0.1, 0.9]],
        cell_size: 0.025,
    });
    options
}

#[test]
fn a_trajectory_compared_with_itself_and_with_its_translate_gives_the_analytic_metrics() {
    use phi_gns::eval::compare_trajectories;
    let truth = trajectory(30);
    let options = comparison_options();
    let same = compare_trajectories(&truth, &truth, C, &[OBSTACLE], &options).unwrap();
    assert_eq!(same.curves.frame, (C + 1..30).collect::<Vec<_>>());
    assert_eq!((same.mse400, same.emd), (0.0, 0.0));
    assert_eq!(same.kinetic_energy_error, Some(0.0));
    assert_eq!(same.density_ratio, Some(1.0));
    let p = same.plausibility.unwrap();
    assert_eq!(p.outside, 0.0);
    assert_eq!(p.inside_obstacles, p.inside_obstacles_true);
    assert_eq!(p.final_density_ratio, 1.0);
    assert_eq!(p.late_kinetic_energy_ratio, 1.0);
    assert_eq!(p.final_centre_distance_cells, 0.0);

    // A translation by d: every particle is |d| away from its twin, so the per-component MSE
    // is |d|²/2; the EMD (squared Euclidean) is |d|² (the translation is an optimal transport
    // map, and no plan costs less than the squared distance of the means); the centres of
    // mass are |d| apart; the motion is the same.
    let d = [0.003f32, -0.004];
    let moved = shifted(&truth, d);
    let cmp = compare_trajectories(&moved, &truth, C, &[OBSTACLE], &options).unwrap();
    let d2 = f64::from(d[0]).powi(2) + f64::from(d[1]).powi(2);
    assert!((cmp.mse400 - d2 / 2.0).abs() < 1e-3 * d2, "{}", cmp.mse400);
    assert!((cmp.emd - d2).abs() < 1e-3 * d2, "{} against {d2}", cmp.emd);
    let p = cmp.plausibility.unwrap();
    assert!((p.final_centre_distance_cells - d2.sqrt() / 0.025).abs() < 1e-3);
    assert!((p.late_kinetic_energy_ratio - 1.0).abs() < 1e-3, "{p:?}");
    assert!(cmp.kinetic_energy_error.unwrap() < 1e-3);
}

#[test]
fn comparing_a_model_rollout_as_a_trajectory_gives_the_evaluation_curves() {
    use phi_gns::eval::compare_trajectories;
    let device = NdArray::default_device();
    let model = small_model();
    let frames = 24;
    let truth = trajectory(frames);
    let range = RolloutRange::full(C, frames);
    // The rollout's frames after the truth's first C + 1: what the evaluation compares.
    let mut position = truth.position[..(C + 1) * truth.particles * 2].to_vec();
    position.extend(rollout_positions(&model, &truth, range, &device).unwrap());
    let rolled = Trajectory::new(2, position, truth.particle_type.clone(), 0, 0).unwrap();
    let mut options = comparison_options();
    options.sinkhorn_every = 7;
    let eval = evaluate_trajectory(&model, &truth, &options, &device).unwrap();
    let cmp = compare_trajectories(&rolled, &truth, C, &[OBSTACLE], &options).unwrap();
    assert_eq!(cmp.curves, eval.curves);
    assert_eq!(Some(cmp.mse400), eval.mse400);
    assert_eq!(Some(cmp.emd), eval.emd);
    assert_eq!(cmp.sinkhorn, eval.sinkhorn);
    assert_eq!(cmp.plausibility, eval.plausibility);
    assert_eq!(
        (cmp.kinetic_energy_error, cmp.density_ratio),
        (eval.kinetic_energy_error, eval.density_ratio)
    );
}

#[test]
fn trajectories_of_different_scenes_are_not_compared() {
    use phi_gns::eval::compare_trajectories;
    let options = comparison_options();
    let err = compare_trajectories(&trajectory(30), &trajectory(31), C, &[OBSTACLE], &options)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("over 30 frames against 11 in 2D over 31"),
        "{err}"
    );
    let truth = trajectory(30);
    let mut other = truth.clone();
    other.particle_type[0] = LIQUID;
    let err = compare_trajectories(&other, &truth, C, &[OBSTACLE], &options)
        .unwrap_err()
        .to_string();
    assert!(err.contains("particle types differ"), "{err}");
    let err = compare_trajectories(&truth, &truth, 29, &[OBSTACLE], &options)
        .unwrap_err()
        .to_string();
    assert!(err.contains("none after frame 29"), "{err}");
}
