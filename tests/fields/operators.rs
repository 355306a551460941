//! Differential operators, conversions and advection against exact maths, and the errors of the
//! fields layer.

use phi_core::fields::LatticeKernels;
use phi_core::fields::{
    Boundary, CenteredGrid, Domain, PointCloud, StaggeredGrid, Transfer, advect_semi_lagrangian,
    apply_wall_boundaries, centered_to_staggered, curl, divergence, extrapolate_valid, gradient,
    laplace, particles_to_staggered, sample_centered, sample_staggered, staggered_to_centered,
};
use phi_core::{Backend, Tensor};

use super::{domain, max_error, tensor};

phi_core::backend_tests!(
    divergence_of_linear_fields,
    gradient_of_quadratic,
    laplace_converges_at_second_order,
    curl_of_solid_rotation,
    staggered_centered_conversions,
    wall_boundaries,
    semi_lagrangian_advection_of_linear_fields,
    errors_name_shapes_and_grids,
);

fn device<B: Backend>() -> B::Device {
    B::default_device()
}

/// A field linear in each coordinate: `u_i(x) = Σ_j A[i][j] x_j + b_i`.
fn linear(a: &[[f32; 3]; 3], b: &[f32; 3], axis: usize, x: &[f32]) -> f32 {
    b[axis]
        + x.iter()
            .enumerate()
            .map(|(j, &xj)| a[axis][j] * xj)
            .sum::<f32>()
}

const A: [[f32; 3]; 3] = [[0.5, -1.0, 0.25], [2.0, -1.5, 0.75], [0.3, 0.6, 1.25]];
const OFFSET: [f32; 3] = [0.2, -0.4, 1.0];

fn divergence_of_linear_fields<B: Backend>() {
    let cases = [
        domain(&[8, 6], &[0.0, -1.0], &[2.0, 1.0], Boundary::Closed),
        domain(
            &[4, 5, 3],
            &[0.0, 0.0, -1.0],
            &[1.0, 2.0, 0.5],
            Boundary::Open,
        ),
    ];
    for domain in cases {
        let d = domain.dim();
        let u =
            StaggeredGrid::<B>::from_fn(&domain, &device::<B>(), |i, x| linear(&A, &OFFSET, i, x))
                .unwrap();
        let div = divergence(&u).unwrap();
        let mut shape = domain.resolution().to_vec();
        shape.push(1);
        assert_eq!(div.values().shape(), shape);
        let trace: f32 = (0..d).map(|i| A[i][i]).sum();
        let error = max_error(div.values(), |_| true, |_| trace);
        assert!(
            error < 1e-4,
            "{d}-d: divergence of a linear field is off by {error}"
        );
    }
}

fn gradient_of_quadratic<B: Backend>() {
    let p = |x: &[f32]| x[0] * x[0] + 3.0 * x[0] * x[1] - x[1] * x[1] + 0.5 * x[1];
    let dp = |axis: usize, x: &[f32]| {
        if axis == 0 {
            2.0 * x[0] + 3.0 * x[1]
        } else {
            3.0 * x[0] - 2.0 * x[1] + 0.5
        }
    };
    for boundary in [Boundary::Closed, Boundary::Open] {
        let domain = domain(&[8, 10], &[0.0, 0.0], &[1.0, 2.0], boundary);
        let (n, dx) = (domain.resolution().to_vec(), domain.cell_size());
        let scalar =
            CenteredGrid::<B>::from_fn(&domain, 1, &device::<B>(), |x| vec![p(x)]).unwrap();
        let g = gradient(&scalar).unwrap();
        for axis in 0..2 {
            assert_eq!(g.component(axis).shape(), domain.staggered_shape(axis));
            let position = |index: &[usize]| -> Vec<f32> {
                (0..2)
                    .map(|j| (index[j] as f32 + if j == axis { 0.0 } else { 0.5 }) * dx[j])
                    .collect()
            };
            let interior = |index: &[usize]| index[axis] > 0 && index[axis] < n[axis];
            let error = max_error(g.component(axis), interior, |index| {
                dp(axis, &position(index))
            });
            assert!(
                error < 2e-4,
                "{boundary:?}: ∂p/∂x{axis} at interior faces off by {error}"
            );
            // Wall faces: 0 at closed walls; at open sides the ghost is 0: (p_0 − 0)/Δx, (0 − p_n)/Δx.
            let wall = |index: &[usize]| index[axis] == 0 || index[axis] == n[axis];
            let want_wall = |index: &[usize]| match boundary {
                Boundary::Closed => 0.0,
                Boundary::Open => {
                    let mut cell = position(index);
                    let sign = if index[axis] == 0 { 1.0 } else { -1.0 };
                    cell[axis] += (if index[axis] == 0 { 0.5 } else { -0.5 }) * dx[axis];
                    sign * p(&cell) / dx[axis]
                }
            };
            let error = max_error(g.component(axis), wall, want_wall);
            assert!(
                error < 1e-3,
                "{boundary:?}: wall faces of component {axis} off by {error}"
            );
        }
    }
}

/// Max error of the discrete Laplacian of `f = Π sin(k_i x_i)` against `−Σ k_i² f` over cells at
/// least one cell away from the sides, on the unit box at `n` cells per axis.
fn laplace_error<B: Backend>(d: usize, n: usize, k: &[f32]) -> f32 {
    let domain = domain(&vec![n; d], &vec![0.0; d], &vec![1.0; d], Boundary::Open);
    let f = |x: &[f32]| -> f64 {
        x.iter()
            .zip(k)
            .map(|(&xi, &ki)| (ki as f64 * xi as f64).sin())
            .product()
    };
    let grid =
        CenteredGrid::<B>::from_fn(&domain, 1, &device::<B>(), |x| vec![f(x) as f32]).unwrap();
    let lap = laplace(&grid).unwrap();
    let k2: f64 = k.iter().map(|&ki| (ki as f64).powi(2)).sum();
    let h = 1.0 / n as f64;
    let interior = |index: &[usize]| index[..d].iter().all(|&i| i >= 1 && i + 1 < n);
    max_error(lap.values(), interior, |index| {
        let x: Vec<f32> = index[..d]
            .iter()
            .map(|&i| ((i as f64 + 0.5) * h) as f32)
            .collect();
        (-k2 * f(&x)) as f32
    }) / k2 as f32
}

fn laplace_converges_at_second_order<B: Backend>() {
    let pi = std::f32::consts::PI;
    for (d, resolutions, k) in [
        (2, vec![16, 32, 64], vec![2.0 * pi, 4.0 * pi]),
        (3, vec![8, 16, 32], vec![2.0 * pi, pi, 2.0 * pi]),
    ] {
        let errors: Vec<f32> = resolutions
            .iter()
            .map(|&n| laplace_error::<B>(d, n, &k))
            .collect();
        let orders: Vec<f32> = errors.windows(2).map(|e| (e[0] / e[1]).log2()).collect();
        println!(
            "{} laplace {d}-d: resolutions {resolutions:?}, relative errors {errors:?}, observed orders {orders:?}",
            B::name()
        );
        // The coarsest pair (8³ in 3-D) is not yet asymptotic: the finest pair must show second
        // order, every pair at least 1.7.
        let finest = *orders.last().expect("three resolutions give two orders");
        assert!(
            finest >= 1.8,
            "{d}-d Laplacian converges at order {finest} < 1.8 on the finest pair: {errors:?}"
        );
        for order in orders {
            assert!(
                order >= 1.7,
                "{d}-d Laplacian converges at order {order} < 1.7: {errors:?}"
            );
        }
    }
    // Zero-gradient walls are exact mirrors for cos(kπx): second order up to the walls.
    let mut errors = Vec::new();
    for n in [16, 32, 64] {
        let domain = domain(&[n, n], &[0.0, 0.0], &[1.0, 1.0], Boundary::Closed);
        let (kx, ky) = (2.0 * pi, pi);
        let f = |x: &[f32]| (kx * x[0]).cos() * (ky * x[1]).cos();
        let grid = CenteredGrid::<B>::from_fn(&domain, 1, &device::<B>(), |x| vec![f(x)]).unwrap();
        let lap = laplace(&grid).unwrap();
        let h = 1.0 / n as f32;
        let k2 = kx * kx + ky * ky;
        let error = max_error(
            lap.values(),
            |_| true,
            |i| -k2 * f(&[(i[0] as f32 + 0.5) * h, (i[1] as f32 + 0.5) * h]),
        );
        errors.push(error / k2);
    }
    let orders: Vec<f32> = errors.windows(2).map(|e| (e[0] / e[1]).log2()).collect();
    println!(
        "{} laplace closed walls (cos): errors {errors:?}, orders {orders:?}",
        B::name()
    );
    assert!(
        orders.iter().all(|&o| o >= 1.8),
        "closed-wall Laplacian orders {orders:?}"
    );
}

fn curl_of_solid_rotation<B: Backend>() {
    // 2D: u = Ω × (x − c) = (−Ω (y − c_y), Ω (x − c_x)), curl 2Ω.
    let omega = 0.7;
    let domain2 = domain(&[7, 9], &[0.0, 0.0], &[1.4, 1.8], Boundary::Closed);
    let u = StaggeredGrid::<B>::from_fn(&domain2, &device::<B>(), |i, x| {
        if i == 0 {
            -omega * (x[1] - 0.9)
        } else {
            omega * (x[0] - 0.6)
        }
    })
    .unwrap();
    let w = curl(&u).unwrap();
    assert_eq!(w.values().shape(), vec![7, 9, 1]);
    let interior = |i: &[usize]| i[0] >= 1 && i[0] <= 5 && i[1] >= 1 && i[1] <= 7;
    let error = max_error(w.values(), interior, |_| 2.0 * omega);
    assert!(error < 1e-4, "2-d curl of a solid rotation off by {error}");
    // 3D: u = w × (x − c), curl 2w.
    let axis = [0.3f32, -0.5, 0.8];
    let c = [0.5f32, 0.4, 0.6];
    let domain3 = domain(&[5, 6, 4], &[0.0; 3], &[1.0, 1.2, 0.8], Boundary::Open);
    let u = StaggeredGrid::<B>::from_fn(&domain3, &device::<B>(), |i, x| {
        let r = [x[0] - c[0], x[1] - c[1], x[2] - c[2]];
        let cross = [
            axis[1] * r[2] - axis[2] * r[1],
            axis[2] * r[0] - axis[0] * r[2],
            axis[0] * r[1] - axis[1] * r[0],
        ];
        cross[i]
    })
    .unwrap();
    let w = curl(&u).unwrap();
    assert_eq!(w.values().shape(), vec![5, 6, 4, 3]);
    let res = [5, 6, 4];
    let interior = |i: &[usize]| (0..3).all(|a| i[a] >= 1 && i[a] + 1 < res[a]);
    let error = max_error(w.values(), interior, |i| 2.0 * axis[i[3]]);
    assert!(error < 1e-4, "3-d curl of a solid rotation off by {error}");
    // 1D has no curl.
    let line = domain(&[4], &[0.0], &[1.0], Boundary::Closed);
    assert!(curl(&StaggeredGrid::<B>::zeros(&line, &device::<B>())).is_err());
}

fn staggered_centered_conversions<B: Backend>() {
    for domain in [
        domain(&[6, 5], &[-1.0, 0.0], &[2.0, 1.0], Boundary::Closed),
        domain(&[3, 4, 5], &[0.0; 3], &[1.0, 1.0, 2.0], Boundary::Open),
    ] {
        let d = domain.dim();
        let dx = domain.cell_size();
        let res = domain.resolution().to_vec();
        let staggered =
            StaggeredGrid::<B>::from_fn(&domain, &device::<B>(), |i, x| linear(&A, &OFFSET, i, x))
                .unwrap();
        let centred = staggered_to_centered(&staggered).unwrap();
        let mut shape = res.clone();
        shape.push(d);
        assert_eq!(centred.values().shape(), shape);
        let centre = |index: &[usize]| -> Vec<f32> {
            (0..d)
                .map(|j| domain.lower()[j] + (index[j] as f32 + 0.5) * dx[j])
                .collect()
        };
        let error = max_error(
            centred.values(),
            |_| true,
            |i| linear(&A, &OFFSET, i[d], &centre(i)),
        );
        assert!(
            error < 1e-5 * 8.0,
            "{d}-d staggered → centred off by {error}"
        );

        let back = centered_to_staggered(&centred).unwrap();
        for axis in 0..d {
            let face = |index: &[usize]| -> Vec<f32> {
                (0..d)
                    .map(|j| {
                        let offset = if j == axis { 0.0 } else { 0.5 };
                        domain.lower()[j] + (index[j] as f32 + offset) * dx[j]
                    })
                    .collect()
            };
            let interior = |i: &[usize]| i[axis] > 0 && i[axis] < res[axis];
            let error = max_error(back.component(axis), interior, |i| {
                linear(&A, &OFFSET, axis, &face(i))
            });
            assert!(
                error < 1e-4,
                "{d}-d centred → staggered off by {error} at interior faces"
            );
            let wall = |i: &[usize]| i[axis] == 0 || i[axis] == res[axis];
            let want = |i: &[usize]| match domain.boundaries()[axis][0] {
                Boundary::Closed => 0.0,
                // zero gradient: the value of the edge cell
                Boundary::Open => {
                    let mut cell = i.to_vec();
                    cell[axis] = if i[axis] == 0 { 0 } else { res[axis] - 1 };
                    let mut x = centre(&cell);
                    x.truncate(d);
                    linear(&A, &OFFSET, axis, &x)
                }
            };
            let error = max_error(back.component(axis), wall, want);
            assert!(
                error < 1e-4,
                "{d}-d centred → staggered wall faces off by {error}"
            );
        }
    }
}

fn wall_boundaries<B: Backend>() {
    let boundaries = [
        [Boundary::Closed, Boundary::Open],
        [Boundary::Open, Boundary::Closed],
    ];
    let domain = Domain::new(&[3, 2], &[0.0, 0.0], &[3.0, 2.0], &boundaries).unwrap();
    let ones = StaggeredGrid::<B>::from_fn(&domain, &device::<B>(), |_, _| 1.0).unwrap();
    let walled = apply_wall_boundaries(&ones).unwrap();
    // component x [4, 2]: the lower x side is closed; component y [3, 3]: the upper y side.
    assert_eq!(
        walled.component(0).to_vec(),
        vec![0.0, 0.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0]
    );
    assert_eq!(
        walled.component(1).to_vec(),
        vec![1.0, 1.0, 0.0, 1.0, 1.0, 0.0, 1.0, 1.0, 0.0]
    );
    // The divergence sees the wall faces: a uniform flow into a closed wall piles up there.
    let div = divergence(&walled).unwrap();
    assert_eq!(div.values().to_vec(), vec![1.0, 0.0, 0.0, -1.0, 0.0, -1.0]);
}

fn semi_lagrangian_advection_of_linear_fields<B: LatticeKernels>() {
    let domain = domain(&[8, 7], &[0.0, 0.0], &[4.0, 3.5], Boundary::Closed);
    let dx = domain.cell_size();
    let (velocity, dt) = ([0.3f32, -0.2], 0.5f32);
    let u = StaggeredGrid::<B>::from_fn(&domain, &device::<B>(), |i, _| velocity[i]).unwrap();
    let f = |x: &[f32]| 2.0 * x[0] - x[1] + 1.0;
    let field =
        CenteredGrid::<B>::from_fn(&domain, 2, &device::<B>(), |x| vec![f(x), -f(x)]).unwrap();
    let advected = advect_semi_lagrangian(&field, &u, dt).unwrap();
    assert_eq!(advected.values().shape(), vec![8, 7, 2]);
    // Traced back by (−0.15, +0.1): inside the centre lattice except at the low-x and high-y edge.
    let inside = |i: &[usize]| i[0] >= 1 && i[1] + 1 < 7;
    let error = max_error(advected.values(), inside, |i| {
        let x = [
            (i[0] as f32 + 0.5) * dx[0] - dt * velocity[0],
            (i[1] as f32 + 0.5) * dx[1] - dt * velocity[1],
        ];
        if i[2] == 0 { f(&x) } else { -f(&x) }
    });
    assert!(error < 1e-4, "advected centred linear field off by {error}");

    let staggered =
        StaggeredGrid::<B>::from_fn(&domain, &device::<B>(), |i, x| linear(&A, &OFFSET, i, x))
            .unwrap();
    let advected = advect_semi_lagrangian(&staggered, &u, dt).unwrap();
    for axis in 0..2 {
        let face = |i: &[usize]| -> [f32; 2] {
            let pos = |j: usize| (i[j] as f32 + if j == axis { 0.0 } else { 0.5 }) * dx[j];
            [pos(0) - dt * velocity[0], pos(1) - dt * velocity[1]]
        };
        let shape = domain.staggered_shape(axis);
        let inside = |i: &[usize]| i[0] >= 1 && i[1] + 1 < shape[1];
        let error = max_error(advected.component(axis), inside, |i| {
            linear(&A, &OFFSET, axis, &face(i))
        });
        assert!(
            error < 1e-4,
            "advected staggered component {axis} off by {error}"
        );
    }
}

fn errors_name_shapes_and_grids<B: LatticeKernels>() {
    let dev = device::<B>();
    let a = domain(&[4, 4], &[0.0, 0.0], &[1.0, 1.0], Boundary::Closed);
    let b = domain(&[4, 8], &[0.0, 0.0], &[1.0, 1.0], Boundary::Closed);
    let c = domain(&[4, 4], &[0.0, 0.0], &[2.0, 1.0], Boundary::Closed);
    let message = |e: phi_core::TensorError| e.to_string();
    // Wrong shapes name expected and actual.
    let m =
        message(CenteredGrid::new(Tensor::<B>::zeros(&[4, 5, 1], &dev), a.clone()).unwrap_err());
    assert!(m.contains("[4, 5, 1]") && m.contains("[4, 4]"), "{m}");
    let comps = vec![
        Tensor::<B>::zeros(&[5, 4], &dev),
        Tensor::<B>::zeros(&[5, 4], &dev),
    ];
    let m = message(StaggeredGrid::new(comps, a.clone()).unwrap_err());
    assert!(m.contains("[5, 4]") && m.contains("[4, 5]"), "{m}");
    // Mismatched resolutions and bounds name both grids.
    let ua = StaggeredGrid::<B>::zeros(&a, &dev);
    for other in [&b, &c] {
        let m = message(ua.add(&StaggeredGrid::<B>::zeros(other, &dev)).unwrap_err());
        assert!(
            m.contains(&format!("{:?}", other.resolution()))
                && m.contains(&format!("{:?}", other.upper())),
            "{m}"
        );
        let field = CenteredGrid::<B>::zeros(other, 1, &dev);
        let m = message(advect_semi_lagrangian(&field, &ua, 0.1).unwrap_err());
        assert!(
            m.contains("[4, 4]") && m.contains(&format!("{:?}", other.resolution())),
            "{m}"
        );
        let mask = CenteredGrid::<B>::zeros(other, 1, &dev);
        assert!(extrapolate_valid(&CenteredGrid::<B>::zeros(&a, 1, &dev), &mask, 1).is_err());
    }
    // Channel counts.
    let two = CenteredGrid::<B>::zeros(&a, 2, &dev);
    let m = message(gradient(&two).unwrap_err());
    assert!(m.contains("2 channels"), "{m}");
    let three = CenteredGrid::<B>::zeros(&a, 3, &dev);
    assert!(centered_to_staggered(&three).is_err());
    // Points of the wrong dimension.
    let points = Tensor::<B>::zeros(&[5, 3], &dev);
    let m = message(sample_staggered(&ua, &points).unwrap_err());
    assert!(m.contains("[5, 3]") && m.contains("[N, 2]"), "{m}");
    assert!(sample_centered(&CenteredGrid::<B>::zeros(&a, 1, &dev), &points).is_err());
    let cloud = PointCloud::new(points.clone(), Tensor::<B>::zeros(&[5, 3], &dev)).unwrap();
    assert!(particles_to_staggered(&cloud, &a, Transfer::Linear).is_err());
    let cloud = PointCloud::new(
        tensor::<B>(&[1, 2], &[0.5, 0.5]),
        tensor::<B>(&[1, 1], &[1.0]),
    )
    .unwrap();
    let m = message(particles_to_staggered(&cloud, &a, Transfer::Linear).unwrap_err());
    assert!(m.contains("[1, 1]"), "{m}");
}
