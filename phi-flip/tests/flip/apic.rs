//! APIC transfer (Jiang et al. 2015, "The affine particle-in-cell method"): the affine round trip
//! is exact where PIC's is not, a rotating disc keeps its angular momentum, the backends agree,
//! scenes select it, and gradients through APIC steps match finite differences.

use phi_core::backend::burn::Burn;
use phi_core::fields::LatticeKernels;
use phi_core::fields::{
    Domain, PointCloud, Transfer, extrapolate_valid, particles_to_staggered,
    particles_to_staggered_affine, sample_staggered, sample_staggered_gradient, valid_faces,
};
use phi_core::{AutodiffBackend, Tensor};
use phi_flip::{FlipParams, FlipSimulation, Particles, Placement, Scene};
use phi_geom::{Geometry, Obstacle, Rotation};

use super::{Nd, boxed, closed};

/// A named affine field `u₀ + A x`: `(name, u₀, A)`.
type AffineField = (&'static str, Vec<f32>, Vec<Vec<f32>>);

/// One step's particles on the host: positions, velocities, affine matrices.
type Frame = (Vec<f32>, Vec<f32>, Vec<f32>);

/// `u(x) = u₀ + A x` at `points` (host, `[N * d]`).
fn affine_field(points: &[f32], u0: &[f32], a: &[Vec<f32>]) -> Vec<f32> {
    let d = u0.len();
    points
        .chunks(d)
        .flat_map(|x| (0..d).map(move |i| u0[i] + (0..d).map(|j| a[i][j] * x[j]).sum::<f32>()))
        .collect()
}

/// Particles filling the cells of `region` (8 per cell, jittered) in a closed box of `res`.
fn filled<B: LatticeKernels>(res: &[usize], region: &Geometry) -> Vec<f32> {
    let d = res.len();
    let sim = FlipSimulation::<B>::new(
        closed(res),
        FlipParams::thesis(d, 0.05),
        vec![],
        vec![],
        0,
        &B::default_device(),
    )
    .unwrap();
    sim.seed(region, &vec![0.0; d], 8, Placement::Jittered, 11)
        .unwrap()
        .positions
        .to_vec()
}

/// One particle → grid → particle round trip as a step does it (the grid extrapolated one layer
/// beyond the faces that received weight): APIC when `affine` is given, PIC otherwise. Returns
/// the particle velocities `[N * d]` and the affine matrices `[N * d * d]` (APIC only).
fn round_trip<B: LatticeKernels>(
    domain: &Domain,
    points: &Tensor<B>,
    velocities: &Tensor<B>,
    affine: Option<&Tensor<B>>,
) -> (Vec<f32>, Option<Vec<f32>>) {
    round_trip_with(domain, points, velocities, affine, Transfer::Linear)
}

/// [`round_trip`] with the particle → grid transfer `transfer`.
fn round_trip_with<B: LatticeKernels>(
    domain: &Domain,
    points: &Tensor<B>,
    velocities: &Tensor<B>,
    affine: Option<&Tensor<B>>,
    transfer: Transfer,
) -> (Vec<f32>, Option<Vec<f32>>) {
    let cloud = PointCloud::new(points.clone(), velocities.clone()).unwrap();
    let (grid, weights) = match affine {
        Some(c) => particles_to_staggered_affine(&cloud, c, domain, transfer).unwrap(),
        None => particles_to_staggered(&cloud, domain, transfer).unwrap(),
    };
    let valid = valid_faces(&weights).unwrap();
    let (grid, _) = extrapolate_valid(&grid, &valid, 1).unwrap();
    let v = sample_staggered(&grid, points).unwrap().to_vec();
    let c = affine.map(|_| sample_staggered_gradient(&grid, points).unwrap().to_vec());
    (v, c)
}

/// A closed 16² box with the cells of the block `[4, 12]²` filled with jittered particles: the
/// domain, the positions on the host `[N * 2]` and as a tensor `[N, 2]`.
fn block_in_box() -> (Domain, Vec<f32>, Tensor<Nd>) {
    let res = [16, 16];
    let positions = filled::<Nd>(&res, &boxed(&[4.0, 4.0], &[12.0, 12.0]));
    let n = positions.len() / 2;
    let points = Tensor::from_vec(positions.clone(), &[n, 2], &Default::default()).unwrap();
    (closed(&res), positions, points)
}

fn max_abs_difference(a: &[f32], b: &[f32]) -> f32 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0f32, f32::max)
}

/// Angular momentum (per unit mass) about `centre` of 2D particles: `Σ (x − c) × v`.
fn angular_momentum(positions: &[f32], velocities: &[f32], centre: [f32; 2]) -> f32 {
    positions
        .chunks(2)
        .zip(velocities.chunks(2))
        .map(|(x, v)| (x[0] - centre[0]) * v[1] - (x[1] - centre[1]) * v[0])
        .sum()
}

/// An affine velocity field `u₀ + A x` (a rigid rotation plus a shear and a uniform motion) on
/// particles that fill the cells of a block: APIC (particles carrying `C = A`) gives back every
/// velocity and `C = A` to float precision, also after ten round trips. PIC, which has no `C`,
/// loses part of the rotation on every trip: its particle velocities are off by a measurable
/// amount and the block's angular momentum shrinks trip after trip.
#[test]
fn affine_round_trip_is_exact_with_apic_and_lossy_with_pic() {
    let (domain, positions, points) = block_in_box();
    let n = positions.len() / 2;
    let device = points.device();
    let centre = [8.0, 8.0];
    let fields: [AffineField; 2] = [
        // A rigid rotation about the block's centre, ω = 1.5 rad/s.
        (
            "rotation",
            vec![1.5 * 8.0, -1.5 * 8.0],
            vec![vec![0.0, -1.5], vec![1.5, 0.0]],
        ),
        // A general affine field: rotation, shear, stretch and a uniform motion.
        (
            "affine",
            vec![0.7, -0.4],
            vec![vec![0.3, -1.1], vec![0.6, -0.2]],
        ),
    ];
    for (name, u0, a) in fields {
        let exact = affine_field(&positions, &u0, &a);
        let c_exact: Vec<f32> = (0..n).flat_map(|_| a.iter().flatten().copied()).collect();
        let l0 = angular_momentum(&positions, &exact, centre);

        // APIC, ten trips: velocities and C come back each time.
        let mut v = Tensor::<Nd>::from_vec(exact.clone(), &[n, 2], &device).unwrap();
        let mut c = Tensor::<Nd>::from_vec(c_exact.clone(), &[n, 2, 2], &device).unwrap();
        let (mut apic_v_error, mut apic_c_error) = (0.0f32, 0.0f32);
        for _ in 0..10 {
            let (vv, cc) = round_trip(&domain, &points, &v, Some(&c));
            let cc = cc.unwrap();
            apic_v_error = apic_v_error.max(max_abs_difference(&vv, &exact));
            apic_c_error = apic_c_error.max(max_abs_difference(&cc, &c_exact));
            v = Tensor::from_vec(vv, &[n, 2], &device).unwrap();
            c = Tensor::from_vec(cc, &[n, 2, 2], &device).unwrap();
        }
        let apic_l = angular_momentum(&positions, &v.to_vec(), centre);

        // PIC, the same ten trips.
        let mut v = Tensor::<Nd>::from_vec(exact.clone(), &[n, 2], &device).unwrap();
        let mut pic_first_error = 0.0f32;
        for trip in 0..10 {
            let (vv, _) = round_trip(&domain, &points, &v, None);
            if trip == 0 {
                pic_first_error = max_abs_difference(&vv, &exact);
            }
            v = Tensor::from_vec(vv, &[n, 2], &device).unwrap();
        }
        let pic_error = max_abs_difference(&v.to_vec(), &exact);
        let pic_l = angular_momentum(&positions, &v.to_vec(), centre);
        println!(
            "{name} ({n} particles): APIC velocity error {apic_v_error:.1e} cells/s, C error \
             {apic_c_error:.1e} /s over 10 trips; PIC velocity error {pic_first_error:.3} after \
             1 trip, {pic_error:.3} after 10; angular momentum about the centre kept: APIC \
             {:.6}, PIC {:.4}",
            apic_l / l0,
            pic_l / l0
        );
        let scale = exact.iter().fold(0.0f32, |m, x| m.max(x.abs()));
        // Float rounding of values of size `scale`, accumulated over ten trips.
        let tolerance = 3e-6 * scale.max(1.0);
        assert!(
            apic_v_error < tolerance,
            "{name}: APIC velocity error {apic_v_error}"
        );
        assert!(
            apic_c_error < tolerance,
            "{name}: APIC C error {apic_c_error}"
        );
        assert!(
            (apic_l / l0 - 1.0).abs() < 1e-5,
            "{name}: APIC L {apic_l} against {l0}"
        );
        assert!(
            pic_first_error > 100.0 * apic_v_error.max(1e-6) && pic_first_error > 0.05,
            "{name}: PIC's first trip is as good as APIC's ({pic_first_error})"
        );
        assert!(
            pic_error > pic_first_error,
            "{name}: PIC error does not grow"
        );
        if name == "rotation" {
            assert!(pic_l / l0 < 0.97, "{name}: PIC keeps {} of L", pic_l / l0);
        }
    }
}

/// APIC with Φ_Flow's nearest-face transfer: each face takes the mean of `v_p + C (x_face − x_p)`
/// over the particles nearest to it, which for an affine field is the exact face value whichever
/// particles those are. So the round trip is exact for particles whose interpolation stencil lies
/// inside the block (faces at the block's sides may have no nearest particle and are
/// extrapolated); PIC with the same transfer is not.
#[test]
fn affine_round_trip_is_exact_with_apic_and_nearest_transfer() {
    let (domain, positions, points) = block_in_box();
    let n = positions.len() / 2;
    let device = points.device();
    let (u0, a) = (vec![0.7, -0.4], vec![vec![0.3, -1.1], vec![0.6, -0.2]]);
    let exact = affine_field(&positions, &u0, &a);
    let c_exact: Vec<f32> = (0..n).flat_map(|_| a.iter().flatten().copied()).collect();
    let v = Tensor::<Nd>::from_vec(exact.clone(), &[n, 2], &device).unwrap();
    let c = Tensor::<Nd>::from_vec(c_exact.clone(), &[n, 2, 2], &device).unwrap();
    let interior: Vec<usize> = (0..n)
        .filter(|&p| {
            positions[2 * p..2 * p + 2]
                .iter()
                .all(|x| (6.0..10.0).contains(x))
        })
        .collect();
    assert!(
        interior.len() > 100,
        "{} interior particles",
        interior.len()
    );
    let on_interior = |values: &[f32], width: usize| -> Vec<f32> {
        interior
            .iter()
            .flat_map(|&p| values[p * width..(p + 1) * width].to_vec())
            .collect()
    };
    let (apic_v, apic_c) = round_trip_with(&domain, &points, &v, Some(&c), Transfer::NearestFace);
    let (pic_v, _) = round_trip_with(&domain, &points, &v, None, Transfer::NearestFace);
    let exact_inside = on_interior(&exact, 2);
    let v_error = max_abs_difference(&on_interior(&apic_v, 2), &exact_inside);
    let c_error = max_abs_difference(&on_interior(&apic_c.unwrap(), 4), &on_interior(&c_exact, 4));
    let pic_error = max_abs_difference(&on_interior(&pic_v, 2), &exact_inside);
    println!(
        "nearest-face transfer, {} interior particles: APIC velocity error {v_error:.1e}, C error \
         {c_error:.1e}; PIC velocity error {pic_error:.3}",
        interior.len()
    );
    assert!(v_error < 1e-5, "APIC velocity error {v_error}");
    assert!(c_error < 1e-5, "APIC C error {c_error}");
    assert!(
        pic_error > 0.05,
        "PIC with nearest faces is exact too ({pic_error})"
    );
}

/// The gradient sampling generically in 3D: an affine field's round trip through APIC is exact
/// (a block of particles in an 8³ box).
#[test]
fn affine_round_trip_is_exact_in_3d() {
    let res = [8, 8, 8];
    let domain = closed(&res);
    let device = Default::default();
    let positions = filled::<Nd>(&res, &boxed(&[2.0, 2.0, 1.0], &[6.0, 7.0, 5.0]));
    let n = positions.len() / 3;
    let points = Tensor::<Nd>::from_vec(positions.clone(), &[n, 3], &device).unwrap();
    let u0 = vec![0.3, -0.5, 0.8];
    let a = vec![
        vec![0.2, -0.9, 0.4],
        vec![0.9, -0.1, -0.3],
        vec![-0.4, 0.5, 0.05],
    ];
    let exact = affine_field(&positions, &u0, &a);
    let c_exact: Vec<f32> = (0..n).flat_map(|_| a.iter().flatten().copied()).collect();
    let v = Tensor::<Nd>::from_vec(exact.clone(), &[n, 3], &device).unwrap();
    let c = Tensor::<Nd>::from_vec(c_exact.clone(), &[n, 3, 3], &device).unwrap();
    let (vv, cc) = round_trip(&domain, &points, &v, Some(&c));
    let (v_error, c_error) = (
        max_abs_difference(&vv, &exact),
        max_abs_difference(&cc.unwrap(), &c_exact),
    );
    let (pic, _) = round_trip(&domain, &points, &v, None);
    let pic_error = max_abs_difference(&pic, &exact);
    println!(
        "3D ({n} particles): APIC velocity error {v_error:.1e}, C error {c_error:.1e}; PIC \
         velocity error {pic_error:.3}"
    );
    assert!(v_error < 2e-5 && c_error < 1e-5);
    assert!(pic_error > 0.05);
}

/// A rigid rotation to start from: velocities `ω × (x − c)` and, for APIC, `C` its gradient.
fn spinning(positions: &[f32], centre: [f32; 2], omega: f32, apic: bool) -> Particles<Nd> {
    let n = positions.len() / 2;
    let velocities = positions
        .chunks(2)
        .flat_map(|x| [-omega * (x[1] - centre[1]), omega * (x[0] - centre[0])])
        .collect();
    let device = Default::default();
    let mut p = Particles::from_host(positions.to_vec(), velocities, 2, &device).unwrap();
    if apic {
        let c = [0.0, -omega, omega, 0.0].repeat(n);
        p.affine = Some(Tensor::from_vec(c, &[n, 2, 2], &device).unwrap());
    }
    p
}

/// A disc of liquid spinning rigidly without gravity in the middle of a closed box: APIC keeps
/// almost all of its angular momentum over 100 steps (2 s, a third of a turn), PIC damps it.
/// FLIP's value is printed for comparison.
///
/// Every scheme loses some to the time stepping itself: a particle's velocity is not turned
/// while it moves along the circle, and the projection removes the outward part, so the speed
/// shrinks by `cos(ω Δt)` per step, `exp(−ω² Δt t / 2) ≈ 0.98` over the run.
#[test]
fn spinning_disc_keeps_its_angular_momentum_with_apic() {
    let (res, dt, omega, steps) = ([32usize, 32], 0.02f32, 1.0f32, 100);
    let centre = [16.0, 16.0];
    let disc = Geometry::sphere([16.0, 16.0], 8.0).unwrap();
    let positions = filled::<Nd>(&res, &disc);
    let kept = |flip_ratio: f32, apic: bool| -> Vec<f32> {
        let mut params = FlipParams::thesis(2, dt);
        params.gravity = vec![0.0, 0.0];
        params.flip_ratio = flip_ratio;
        params.apic = apic;
        let sim =
            FlipSimulation::<Nd>::new(closed(&res), params, vec![], vec![], 0, &Default::default())
                .unwrap();
        let mut p = spinning(&positions, centre, omega, apic);
        let l0 = angular_momentum(&p.positions.to_vec(), &p.velocities.to_vec(), centre);
        let mut history = vec![1.0];
        for step in 0..steps {
            p = sim.step(&p, step).unwrap().0;
            let l = angular_momentum(&p.positions.to_vec(), &p.velocities.to_vec(), centre);
            history.push(l / l0);
        }
        history
    };
    let (apic, pic, flip) = (kept(0.0, true), kept(0.0, false), kept(1.0, false));
    println!("angular momentum kept (L/L0) by a spinning disc without gravity:");
    println!(" step   APIC     PIC      FLIP");
    for k in (0..=steps).step_by(20) {
        println!("{k:>5} {:>7.4} {:>7.4} {:>7.4}", apic[k], pic[k], flip[k]);
    }
    let (a, p) = (apic[steps], pic[steps]);
    assert!(a > 0.95, "APIC keeps only {a} of the angular momentum");
    assert!(p < 0.8, "PIC keeps {p} of the angular momentum");
    assert!(
        1.0 - a < 0.25 * (1.0 - p),
        "APIC loses {} of the angular momentum, PIC {}: not much less",
        1.0 - a,
        1.0 - p
    );
}

/// An APIC scene (a block thrown with a spin onto a rotated obstacle over a pool): its first
/// steps on every backend.
fn apic_run<B: LatticeKernels>(steps: usize) -> Vec<Frame> {
    let obstacle = boxed(&[9.0, 6.0], &[13.0, 8.0])
        .rotated(Rotation::degrees(30.0))
        .unwrap();
    let mut params = FlipParams::thesis(2, 0.05);
    params.flip_ratio = 0.0;
    params.apic = true;
    let sim = FlipSimulation::<B>::new(
        closed(&[16, 16]),
        params,
        vec![Obstacle::at_rest(obstacle).unwrap()],
        vec![],
        0,
        &B::default_device(),
    )
    .unwrap();
    let mut positions = Vec::new();
    for (i, g) in [
        boxed(&[4.0, 9.0], &[10.0, 14.0]),
        boxed(&[0.0, 0.0], &[16.0, 3.0]),
    ]
    .iter()
    .enumerate()
    {
        let p = sim
            .seed(g, &[0.0, 0.0], 8, Placement::Jittered, 7 + i as u64)
            .unwrap();
        positions.extend(p.positions.to_vec());
    }
    // The block spins at 2 rad/s about its centre and moves right; the pool is at rest.
    let velocities: Vec<f32> = positions
        .chunks(2)
        .flat_map(|x| {
            if x[1] > 5.0 {
                [2.0 - 2.0 * (x[1] - 11.5), 2.0 * (x[0] - 7.0)]
            } else {
                [0.0, 0.0]
            }
        })
        .collect();
    let mut p = Particles::<B>::from_host(positions, velocities, 2, &B::default_device()).unwrap();
    let mut frames = Vec::new();
    for step in 0..steps {
        p = sim.step(&p, step).unwrap().0;
        frames.push((
            p.positions.to_vec(),
            p.velocities.to_vec(),
            p.affine.as_ref().expect("APIC writes C").to_vec(),
        ));
    }
    frames
}

/// ndarray, Burn and libtorch give the same APIC particles (positions to 1e-4 cells) over the
/// first 10 steps.
#[test]
fn apic_backends_agree_over_ten_steps() {
    let reference = apic_run::<Nd>(10);
    // Not vacuous: the liquid moves and the matrices are far from zero.
    let moved = max_abs_difference(&reference[0].0, &reference[9].0);
    let largest_c = reference[9].2.iter().fold(0.0f32, |m, c| m.max(c.abs()));
    println!("ndarray: particles moved up to {moved:.2} cells, |C| up to {largest_c:.2} /s");
    assert!(moved > 1.0 && largest_c > 1.0);
    let others: Vec<(&str, Vec<Frame>)> = vec![
        ("burn", apic_run::<Burn>(10)),
        #[cfg(feature = "tch")]
        ("tch", apic_run::<phi_core::backend::tch::Tch>(10)),
    ];
    for (name, frames) in others {
        let mut worst = [0.0f32; 3];
        for (step, (a, b)) in reference.iter().zip(&frames).enumerate() {
            let d = [
                max_abs_difference(&a.0, &b.0),
                max_abs_difference(&a.1, &b.1),
                max_abs_difference(&a.2, &b.2),
            ];
            assert!(
                d[0] < 1e-4,
                "{name}, step {step}: positions {} cells apart",
                d[0]
            );
            assert!(
                d[1] < 1e-3,
                "{name}, step {step}: velocities {} apart",
                d[1]
            );
            assert!(d[2] < 1e-3, "{name}, step {step}: C {} apart", d[2]);
            for k in 0..3 {
                worst[k] = worst[k].max(d[k]);
            }
        }
        println!(
            "{name}: agrees with ndarray over 10 APIC steps: positions {:.1e} cells, velocities \
             {:.1e} cells/s, C {:.1e} /s",
            worst[0], worst[1], worst[2]
        );
    }
}

#[test]
fn scenes_select_apic_and_reject_a_flip_ratio_with_it() {
    let scene = |extra: &str| {
        format!(
            r#"
[domain]
resolution = [16, 16]
[simulation]
dt = 0.05
steps = 10
scheme = "apic"
{extra}
[[liquid]]
geometry = {{ type = "box", lower = [0, 0], upper = [16, 4] }}
"#
        )
    };
    let parsed = Scene::from_toml(&scene(""), "apic.toml").unwrap();
    let params = parsed.params("apic.toml").unwrap();
    assert!(params.apic);
    assert_eq!(params.flip_ratio, 0.0);
    let setup = parsed
        .build::<Nd>("apic.toml", &Default::default())
        .unwrap();
    let (after, _) = setup.simulation.step(&setup.particles, 0).unwrap();
    assert_eq!(after.affine.unwrap().shape(), [setup.particles.len(), 2, 2]);

    let message = Scene::from_toml(&scene("flip_ratio = 0.5"), "apic.toml")
        .unwrap_err()
        .to_string();
    println!("{message}");
    assert!(message.starts_with("apic.toml: "), "{message}");
    assert!(message.contains("simulation.flip_ratio"), "{message}");
    assert!(message.contains("apic"), "{message}");

    // The parameters themselves: APIC is a PIC update.
    let mut params = FlipParams::thesis(2, 0.05);
    params.apic = true;
    let error = FlipSimulation::<Nd>::new(
        closed(&[8, 8]),
        params,
        vec![],
        vec![],
        0,
        &Default::default(),
    )
    .unwrap_err()
    .to_string();
    assert!(error.contains("flip_ratio"), "{error}");
}

/// FLIP and PIC steps ignore an affine matrix the particles carry and write none: the step is
/// the one without APIC, bit for bit.
#[test]
fn flip_and_pic_ignore_affine_matrices() {
    let positions = filled::<Nd>(&[16, 16], &boxed(&[4.0, 4.0], &[10.0, 9.0]));
    for ratio in [1.0, 0.0] {
        let mut params = FlipParams::thesis(2, 0.05);
        params.flip_ratio = ratio;
        let sim = FlipSimulation::<Nd>::new(
            closed(&[16, 16]),
            params,
            vec![],
            vec![],
            0,
            &Default::default(),
        )
        .unwrap();
        let plain = spinning(&positions, [7.0, 6.5], 1.0, false);
        let with_c = spinning(&positions, [7.0, 6.5], 1.0, true);
        let (a, _) = sim.step(&plain, 0).unwrap();
        let (b, _) = sim.step(&with_c, 0).unwrap();
        assert_eq!(a.positions.to_vec(), b.positions.to_vec());
        assert_eq!(a.velocities.to_vec(), b.velocities.to_vec());
        assert!(a.affine.is_none() && b.affine.is_none());
    }
}

// ---------------------------------------------------------------------------------------------
// Gradients through APIC steps (Burn and libtorch) against central finite differences, with the
// protocol and tolerances of `gradients.rs`: only elements whose stencils `h` and `h/2` agree (on
// one smooth piece) are compared, at least 80 % of them must be, held to `2e-2 + 2e-2 |g|`.

const H: f32 = 1e-2;
const STEPS: usize = 3;

mod gradients_burn {
    #[test]
    fn apic_gradients_match_finite_differences() {
        super::apic_gradients_match_finite_differences::<phi_core::backend::burn::Burn>();
    }
}

#[cfg(feature = "tch")]
mod gradients_tch {
    #[test]
    fn apic_gradients_match_finite_differences() {
        super::apic_gradients_match_finite_differences::<phi_core::backend::tch::Tch>();
    }
}

/// A 2×2-cell block with 3 particles per cell, offset from the face and centre lines, a smooth
/// velocity field and affine matrices: `(positions, velocities, affine)`.
fn tiny_block() -> [(Vec<usize>, Vec<f32>); 3] {
    let (mut p, mut v, mut c) = (Vec::new(), Vec::new(), Vec::new());
    for i in 0..2 {
        for j in 0..2 {
            for (a, b) in [(0.2, 0.3), (0.7, 0.15), (0.35, 0.8)] {
                let (x, y) = (3.0 + i as f32 + a, 3.0 + j as f32 + b);
                p.extend([x, y]);
                v.extend([0.8 * (0.7 * y).sin() - 0.5, -1.0 + 0.5 * (0.9 * x).cos()]);
                c.extend([0.1 * (x - y).sin(), -0.6 + 0.1 * x, 0.7 - 0.1 * y, 0.2]);
            }
        }
    }
    let n = p.len() / 2;
    [(vec![n, 2], p), (vec![n, 2], v), (vec![n, 2, 2], c)]
}

fn apic_loss<B: LatticeKernels>(sim: &FlipSimulation<B>, inputs: &[(Vec<usize>, Vec<f32>)]) -> f32 {
    let t: Vec<Tensor<B>> = inputs
        .iter()
        .map(|(s, v)| Tensor::from_vec(v.clone(), s, &B::default_device()).unwrap())
        .collect();
    apic_loss_of(sim, &t).to_scalar().unwrap()
}

/// `Σ w ⊙ x_N + 0.1 Σ w' ⊙ v_N + 0.1 Σ w'' ⊙ C_N`, fixed pseudo-random weights.
fn apic_loss_of<B: LatticeKernels>(sim: &FlipSimulation<B>, t: &[Tensor<B>]) -> Tensor<B> {
    let mut p = Particles {
        positions: t[0].clone(),
        velocities: t[1].clone(),
        affine: Some(t[2].clone()),
    };
    for step in 0..STEPS {
        p = sim.step(&p, step).unwrap().0;
    }
    let weights = |shape: &[usize], phase: f32| {
        let n: usize = shape.iter().product();
        let w: Vec<f32> = (0..n)
            .map(|k| 1.0 + 0.5 * (1.3 * k as f32 + phase).sin())
            .collect();
        Tensor::<B>::from_vec(w, shape, &B::default_device()).unwrap()
    };
    let c = p.affine.expect("APIC writes C");
    (&p.positions * &weights(&p.positions.shape(), 0.4)).sum()
        + (&p.velocities * &weights(&p.velocities.shape(), 1.1)).sum() * 0.1
        + (&c * &weights(&c.shape(), 2.3)).sum() * 0.1
}

fn apic_gradients_match_finite_differences<B: AutodiffBackend + LatticeKernels>() {
    let mut params = FlipParams::thesis(2, 0.05);
    params.flip_ratio = 0.0;
    params.apic = true;
    let sim = FlipSimulation::<B>::new(
        closed(&[8, 8]),
        params,
        vec![],
        vec![],
        0,
        &B::default_device(),
    )
    .unwrap();
    let inputs = tiny_block();
    let leaves: Vec<Tensor<B>> = inputs
        .iter()
        .map(|(s, v)| {
            Tensor::from_vec(v.clone(), s, &B::default_device())
                .unwrap()
                .require_grad()
        })
        .collect();
    let wrt: Vec<&Tensor<B>> = leaves.iter().collect();
    let analytic: Vec<Vec<f32>> = apic_loss_of(&sim, &leaves)
        .gradients(&wrt)
        .unwrap()
        .iter()
        .map(Tensor::to_vec)
        .collect();
    let fd = |h: f32| -> Vec<Vec<f32>> {
        (0..inputs.len())
            .map(|k| {
                (0..inputs[k].1.len())
                    .map(|e| {
                        let (mut plus, mut minus) = (inputs.clone(), inputs.clone());
                        plus[k].1[e] += h;
                        minus[k].1[e] -= h;
                        (apic_loss(&sim, &plus) - apic_loss(&sim, &minus)) / (2.0 * h)
                    })
                    .collect()
            })
            .collect()
    };
    let (fd, fd_half) = (fd(H), fd(H / 2.0));
    let names = ["positions", "velocities", "affine"];
    super::gradients::compare_with_finite_differences("APIC: ", &analytic, &fd, &fd_half, &names);
}
