//! `Gns::with_bounds`, the walls of a larger domain: moving the particles and the walls together
//! leaves the predicted accelerations unchanged (the network sees only displacements and
//! clipped wall distances), while moving the particles alone changes them.
//!
//! The scene sits 0.005–0.04 above the lower wall, inside the radius (0.03) where the boundary
//! features are not clipped. Moved up by 0.8 it sits just above the training domain's upper
//! wall, where the model's own bounds see it outside the domain. The moved positions round
//! differently in f32 (their ulp grows from 1.5e-8 to 1.2e-7), so the displacements the
//! network sees differ by up to ~1e-7 of the 0.01 spacing; the tolerance is 1e-3 of the largest
//! normalised acceleration, and the controls must differ by more than 10 times that (measured:
//! the model's walls by 1.5 % of the largest).

use phi_gns::model::{Gns, GnsKernels, GraphBatch, Parameters};

use crate::common::{self, Rng, liquid_over_obstacles, max_abs, perturbed};

phi_core::backend_tests!(walls_moved_with_the_particles_leave_the_accelerations_unchanged);

fn walls_moved_with_the_particles_leave_the_accelerations_unchanged<B: GnsKernels>() {
    let device = B::default_device();
    let spec = common::spec(common::config(16, 16, 2, 3), 17);
    assert!(spec.config.boundary_features);
    let model = Gns::new(
        spec.clone(),
        perturbed(&Parameters::<B>::init(&spec.config, spec.seed, &device), 4),
    )
    .unwrap();
    let scene = liquid_over_obstacles(&mut Rng::new(9), 4, 3, 0, [0.13, 0.105], 6);
    let shift = 0.8_f32;
    let moved: Vec<f32> = scene
        .window
        .iter()
        .enumerate()
        .map(|(i, &x)| if i % 2 == 1 { x + shift } else { x })
        .collect();
    let accelerations = |model: &Gns<B>, window: &[f32]| -> Vec<f64> {
        let batch = GraphBatch::from_host(window, &scene.types, model.spec(), &device).unwrap();
        let a = model.normalised_acceleration(&batch).unwrap().to_vec();
        a.into_iter().map(f64::from).collect()
    };

    let here = accelerations(&model, &scene.window);
    let taller = model
        .with_bounds(vec![[0.1, 0.9], [0.1, 0.9 + f64::from(shift)]])
        .unwrap();
    let moved_walls = model
        .with_bounds(vec![
            [0.1, 0.9],
            [0.1 + f64::from(shift), 0.9 + f64::from(shift)],
        ])
        .unwrap();
    let with_walls = accelerations(&moved_walls, &moved);
    let without_walls = accelerations(&model, &moved);
    let in_taller = accelerations(&taller, &moved);

    let scale = max_abs(&here);
    let diff = |a: &[f64], b: &[f64]| {
        a.iter()
            .zip(b)
            .map(|(x, y)| (x - y).abs())
            .fold(0.0, f64::max)
    };
    assert!(
        diff(&with_walls, &here) <= 1e-3 * scale,
        "walls moved with the particles: the accelerations moved by {:.3e} (scale {scale:.3e})",
        diff(&with_walls, &here)
    );
    for (what, other) in [
        ("the model's walls", &without_walls),
        ("a taller domain", &in_taller),
    ] {
        assert!(
            diff(other, &here) > 0.01 * scale,
            "particles moved away from the lower wall ({what}): the accelerations changed by \
             only {:.3e} (scale {scale:.3e})",
            diff(other, &here)
        );
    }
    // The recorded bounds are the new ones; a reversed pair is refused.
    assert_eq!(taller.spec().bounds[1], [0.1, 0.9 + f64::from(shift)]);
    assert!(model.with_bounds(vec![[0.1, 0.9], [0.9, 0.1]]).is_err());
}
