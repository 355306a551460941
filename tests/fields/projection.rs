//! The pressure projection on every backend: divergence-free results around a rotated obstacle
//! in 2D and 3D, the hydrostatic pressure of a pool at rest, divergence-free fields left alone,
//! errors as values, and (autodiff backends) gradients against finite differences and Burn
//! against libtorch.

use phi_core::fields::{
    Boundary, CenteredGrid, Domain, ProjectionMasks, StaggeredGrid, divergence, pressure_projection,
};
use phi_core::solve::{SolveError, SolveOptions};
use phi_core::{AutodiffBackend, Backend, Tensor};
use phi_geom::{Geometry, Rotation};

use super::gradients::{backprop, finite_differences};
use super::{domain, for_each_index, tensor};
use crate::conformance::{assert_values, values};

phi_core::backend_tests!(
    divergence_free_around_a_rotated_obstacle,
    pool_at_rest_is_hydrostatic,
    divergence_free_fields_are_unchanged,
    projection_errors_are_values,
);
/// Gradients on the autodiff backends.
mod gradients {
    use super::*;
    phi_core::autodiff_backend_tests!(projection_gradients);
}

/// A smooth velocity that is far from divergence-free.
fn swirl(axis: usize, x: &[f32]) -> f32 {
    let s: f32 = x
        .iter()
        .enumerate()
        .map(|(i, &v)| (0.3 + 0.1 * i as f32) * v)
        .sum();
    match axis {
        0 => (0.7 * s).sin() + 0.2 * x[0],
        1 => (0.4 * s).cos() - 1.0,
        _ => 0.5 * (0.5 * s).sin() * x[0] / 10.0,
    }
}

/// Cells of `res` (row-major) whose centre has `x_{last} < level`, outside `obstacle`.
fn liquid_below<B: Backend>(domain: &Domain, level: f32, obstacle: &Tensor<B>) -> CenteredGrid<B> {
    let inside = obstacle.to_vec();
    let d = domain.dim();
    let mut flags = Vec::with_capacity(domain.cell_count());
    for_each_index(domain.resolution(), |index, flat| {
        let height = index[d - 1] as f32 + 0.5;
        flags.push(if height < level && inside[flat] < 0.5 {
            1.0
        } else {
            0.0
        });
    });
    let mut shape = domain.resolution().to_vec();
    shape.push(1);
    CenteredGrid::new(tensor::<B>(&shape, &flags), domain.clone()).unwrap()
}

fn divergence_free_around_a_rotated_obstacle<B: Backend>() {
    let device = B::default_device();
    for res in [vec![32usize, 32], vec![12, 12, 12]] {
        let d = res.len();
        let upper: Vec<f32> = res.iter().map(|&n| n as f32).collect();
        let domain = domain(&res, &vec![0.0; d], &upper, Boundary::Closed);
        let centre: Vec<f32> = upper.iter().map(|u| u * 0.45).collect();
        let half: Vec<f32> = upper.iter().map(|u| u * 0.15).collect();
        let lower: Vec<f32> = centre.iter().zip(&half).map(|(c, h)| c - h * 1.5).collect();
        let high: Vec<f32> = centre.iter().zip(&half).map(|(c, h)| c + h).collect();
        let rotation = if d == 2 {
            Rotation::degrees(30.0)
        } else {
            Rotation::axis_angle([0.3, 0.5, 0.8], 35.0)
        };
        let obstacle = Geometry::boxed(lower, high)
            .unwrap()
            .rotated(rotation)
            .unwrap();
        let blocked = obstacle.cell_inside_mask::<B>(&domain, &device).unwrap();
        let liquid = liquid_below(&domain, upper[d - 1] * 0.7, &blocked);
        let open: Vec<Tensor<B>> = (0..d)
            .map(|axis| {
                1.0 - obstacle
                    .face_inside_mask::<B>(&domain, axis, &device)
                    .unwrap()
            })
            .collect();
        let open = StaggeredGrid::new(open, domain.clone()).unwrap();
        let velocity = StaggeredGrid::<B>::from_fn(&domain, &device, swirl).unwrap();
        let masks = ProjectionMasks {
            liquid: &liquid,
            face_open: Some(&open),
            obstacle_velocity: None,
        };
        let options = SolveOptions::default();
        let result = pressure_projection(&velocity, masks, &options).unwrap();

        let liquid_flags = liquid.values().to_vec();
        let before = divergence(&velocity).unwrap().values().to_vec();
        let after = divergence(&result.velocity).unwrap().values().to_vec();
        let rhs_norm = before
            .iter()
            .zip(&liquid_flags)
            .map(|(v, &l)| if l > 0.5 { v * v } else { 0.0 })
            .sum::<f32>()
            .sqrt();
        let worst = after
            .iter()
            .zip(&liquid_flags)
            .filter(|(_, l)| **l > 0.5)
            .map(|(v, _)| v.abs())
            .fold(0.0f32, f32::max);
        println!(
            "{res:?}: {} unknowns, {} iterations, max |div| on liquid {worst:.2e} (‖div₀‖ {rhs_norm:.2e})",
            result.unknowns, result.stats.iterations
        );
        // The solver's own tolerance, plus f32 rounding of the velocity update.
        assert!(
            worst <= options.relative_tolerance as f32 * rhs_norm + 2e-5,
            "{res:?}: divergence {worst} after projection"
        );
        assert!(result.unknowns > 0 && rhs_norm > 1.0);
        // Blocked faces carry the obstacle's velocity (at rest: zero).
        for (axis, (u, w)) in result
            .velocity
            .components()
            .iter()
            .zip(open.components())
            .enumerate()
        {
            let (u, w) = (u.to_vec(), w.to_vec());
            let leak = u
                .iter()
                .zip(&w)
                .filter(|(_, w)| **w < 0.5)
                .map(|(u, _)| u.abs())
                .fold(0.0f32, f32::max);
            assert!(
                leak == 0.0,
                "{res:?}: flow {leak} through blocked faces of axis {axis}"
            );
            assert!(w.iter().any(|&w| w < 0.5), "the obstacle blocks no face");
        }
    }
}

/// A pool `h` cells deep in a closed tank, after one step of gravity (`u_y = −g Δt = −1`
/// everywhere): the projection must stop the liquid (every face inside and on the surface at
/// rest) with the hydrostatic pressure `p_j = (h − j) g Δt` (exact, the discrete system is
/// solved to tolerance).
fn pool_at_rest_is_hydrostatic<B: Backend>() {
    let device = B::default_device();
    let (nx, ny, h) = (8usize, 12usize, 6usize);
    let domain = domain(
        &[nx, ny],
        &[0.0, 0.0],
        &[nx as f32, ny as f32],
        Boundary::Closed,
    );
    let velocity =
        StaggeredGrid::<B>::from_fn(
            &domain,
            &device,
            |axis, _| {
                if axis == 1 { -1.0 } else { 0.0 }
            },
        )
        .unwrap();
    let nothing = Tensor::<B>::zeros(&[nx, ny], &device);
    let liquid = liquid_below(&domain, h as f32, &nothing);
    let options = SolveOptions {
        relative_tolerance: 1e-7,
        ..SolveOptions::default()
    };
    let result =
        pressure_projection(&velocity, ProjectionMasks::liquid(&liquid), &options).unwrap();
    let p = result.pressure.values().to_vec();
    for i in 0..nx {
        for j in 0..ny {
            let want = if j < h { (h - j) as f32 } else { 0.0 };
            assert!(
                (p[i * ny + j] - want).abs() < 1e-4,
                "p[{i},{j}] = {}, want {want}",
                p[i * ny + j]
            );
        }
    }
    let v = result.velocity.component(1).to_vec();
    for i in 0..nx {
        for j in 0..=h {
            let face = v[i * (ny + 1) + j];
            assert!(
                face.abs() < 1e-4,
                "v at face [{i},{j}] = {face}: the pool moves"
            );
        }
    }
}

/// A solid rotation plus a translation (exactly divergence-free on the MAC grid) in a liquid
/// disc surrounded by air, in an open domain: the pressure is zero and nothing changes.
fn divergence_free_fields_are_unchanged<B: Backend>() {
    let device = B::default_device();
    let domain = domain(&[16, 16], &[-8.0, -8.0], &[8.0, 8.0], Boundary::Open);
    let velocity = StaggeredGrid::<B>::from_fn(&domain, &device, |axis, x| match axis {
        0 => 1.0 - 0.5 * x[1],
        _ => 0.3 + 0.5 * x[0],
    })
    .unwrap();
    let liquid = CenteredGrid::<B>::from_fn(&domain, 1, &device, |x| {
        vec![if x[0] * x[0] + x[1] * x[1] < 36.0 {
            1.0
        } else {
            0.0
        }]
    })
    .unwrap();
    let result = pressure_projection(
        &velocity,
        ProjectionMasks::liquid(&liquid),
        &SolveOptions::default(),
    )
    .unwrap();
    assert!(result.unknowns > 100);
    let p = result.pressure.values().to_vec();
    assert!(
        p.iter().all(|v| v.abs() < 1e-5),
        "pressure of a divergence-free field"
    );
    for axis in 0..2 {
        let (a, b) = (
            velocity.component(axis).to_vec(),
            result.velocity.component(axis).to_vec(),
        );
        let change = a
            .iter()
            .zip(&b)
            .map(|(x, y)| (x - y).abs())
            .fold(0.0f32, f32::max);
        assert!(change < 1e-5, "component {axis} changed by {change}");
    }
}

fn projection_errors_are_values<B: Backend>() {
    let device = B::default_device();
    let a = domain(&[4, 4], &[0.0, 0.0], &[4.0, 4.0], Boundary::Closed);
    let b = domain(&[4, 4], &[0.0, 0.0], &[8.0, 8.0], Boundary::Closed);
    let velocity = StaggeredGrid::<B>::zeros(&a, &device);
    let liquid = CenteredGrid::<B>::from_fn(&b, 1, &device, |_| vec![1.0]).unwrap();
    let message = pressure_projection(
        &velocity,
        ProjectionMasks::liquid(&liquid),
        &SolveOptions::default(),
    )
    .unwrap_err()
    .to_string();
    assert!(message.contains("liquid mask"), "{message}");

    let liquid = CenteredGrid::<B>::from_fn(&a, 1, &device, |_| vec![1.0]).unwrap();
    let bad = StaggeredGrid::<B>::from_fn(&a, &device, |axis, x| {
        if axis == 0 && x[1] > 2.0 {
            f32::NAN
        } else {
            0.0
        }
    })
    .unwrap();
    let error = pressure_projection(
        &bad,
        ProjectionMasks::liquid(&liquid),
        &SolveOptions::default(),
    )
    .unwrap_err();
    assert!(matches!(error, SolveError::NonFinite { .. }), "{error}");

    // No liquid: nothing to solve, the walls still apply.
    let empty = CenteredGrid::<B>::from_fn(&a, 1, &device, |_| vec![0.0]).unwrap();
    let ones = StaggeredGrid::<B>::from_fn(&a, &device, |_, _| 1.0).unwrap();
    let result = pressure_projection(
        &ones,
        ProjectionMasks::liquid(&empty),
        &SolveOptions::default(),
    )
    .unwrap();
    assert_eq!(result.unknowns, 0);
    assert_eq!(result.velocity.component(0).to_vec()[0], 0.0);
}

/// The 6×5 tank of the gradient tests: closed sides, open top, a liquid pocket with air above
/// and an obstacle face.
fn projection_loss<B: AutodiffBackend>(t: &[Tensor<B>]) -> Tensor<B> {
    let domain = Domain::new(
        &[6, 5],
        &[0.0, 0.0],
        &[6.0, 5.0],
        &[[Boundary::Closed; 2], [Boundary::Closed, Boundary::Open]],
    )
    .unwrap();
    let device = t[0].device();
    let liquid = CenteredGrid::<B>::from_fn(&domain, 1, &device, |x| {
        vec![if x[1] < 3.0 && !(x[0] > 2.0 && x[0] < 3.0 && x[1] > 1.0) {
            1.0
        } else {
            0.0
        }]
    })
    .unwrap();
    let open = StaggeredGrid::<B>::from_fn(&domain, &device, |axis, x| {
        if axis == 0 && (x[0] - 4.0).abs() < 0.1 && x[1] < 1.0 {
            0.0
        } else {
            1.0
        }
    })
    .unwrap();
    let velocity = StaggeredGrid::new(vec![t[0].clone(), t[1].clone()], domain).unwrap();
    let masks = ProjectionMasks {
        liquid: &liquid,
        face_open: Some(&open),
        obstacle_velocity: None,
    };
    let options = SolveOptions {
        relative_tolerance: 1e-7,
        ..SolveOptions::default()
    };
    let result = pressure_projection(&velocity, masks, &options).unwrap();
    let w0 = tensor::<B>(&[7, 5], &values(35, 0.5, 1.5, 21));
    let w1 = tensor::<B>(&[6, 6], &values(36, 0.5, 1.5, 22));
    let w2 = tensor::<B>(&[6, 5, 1], &values(30, 0.5, 1.5, 23));
    (result.velocity.component(0) * w0).sum()
        + (result.velocity.component(1) * w1).sum()
        + (result.pressure.values() * w2).sum()
}

fn projection_inputs() -> Vec<(Vec<usize>, Vec<f32>)> {
    vec![
        (vec![7, 5], values(35, -1.0, 1.0, 24)),
        (vec![6, 6], values(36, -1.0, 1.0, 25)),
    ]
}

/// The projection is linear in the velocity, so central differences are exact up to `f32`
/// rounding of the loss (`≈ 10⁻⁶ · |loss| / h ≈ 10⁻³`).
fn projection_gradients<B: AutodiffBackend>() {
    let inputs = projection_inputs();
    let numeric = finite_differences::<B>(&inputs, projection_loss::<B>);
    let analytic = backprop::<B>(&inputs, projection_loss::<B>);
    for (k, name) in ["u", "v"].iter().enumerate() {
        assert_values(
            &format!("∂loss/∂{name} through the projection"),
            &inputs[k].0,
            &analytic[k],
            &inputs[k].0,
            &numeric[k],
            1e-2,
            5e-3,
        );
        assert!(
            analytic[k].iter().any(|g| g.abs() > 0.1),
            "∂loss/∂{name} vanishes"
        );
    }
}

#[cfg(all(feature = "burn", feature = "tch"))]
#[test]
fn projection_burn_matches_tch() {
    use phi_core::backend::burn::Burn;
    use phi_core::backend::tch::Tch;
    let inputs = projection_inputs();
    let burn = backprop::<Burn>(&inputs, projection_loss::<Burn>);
    let tch = backprop::<Tch>(&inputs, projection_loss::<Tch>);
    for (k, (b, t)) in burn.iter().zip(&tch).enumerate() {
        assert_values(
            &format!("projection input {k}: burn vs tch"),
            &[b.len()],
            b,
            &[t.len()],
            t,
            1e-4,
            1e-5,
        );
    }
}
