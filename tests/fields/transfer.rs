//! Sampling, particle ↔ grid transfers and extrapolation.

use phi_core::Tensor;
use phi_core::fields::LatticeKernels;
use phi_core::fields::{
    Boundary, CenteredGrid, Domain, Integrator, PointCloud, StaggeredGrid, Transfer, advect_points,
    count_particles, extrapolate_valid, occupied_cells, particles_to_centered,
    particles_to_staggered, sample_centered, sample_staggered, valid_faces,
};

use super::{domain, for_each_index, max_error, tensor};

phi_core::backend_tests!(
    sampling_is_exact_for_linear_fields,
    particle_grid_particle_reproduces_linear_fields,
    transfer_conserves_weights,
    particles_to_centered_density,
    occupied_cells_match_particle_counts,
    extrapolation_fills_exactly_the_requested_layers,
    point_advection_integrates_a_linear_field,
);

/// Two particles per cell and axis at `(i + ¼) Δx` and `(i + ¾) Δx` (the usual FLIP seeding),
/// `[N, d]` on the host.
fn regular_particles(domain: &Domain) -> Vec<f32> {
    let d = domain.dim();
    let shape: Vec<usize> = domain.resolution().iter().map(|&n| 2 * n).collect();
    let dx = domain.cell_size();
    let mut points = Vec::new();
    for_each_index(&shape, |index, _| {
        for j in 0..d {
            points.push(domain.lower()[j] + (index[j] as f32 * 0.5 + 0.25) * dx[j]);
        }
    });
    points
}

fn velocity(axis: usize, x: &[f32]) -> f32 {
    const A: [[f32; 3]; 3] = [[0.5, -1.0, 0.25], [2.0, -1.5, 0.75], [0.3, 0.6, 1.25]];
    const B: [f32; 3] = [0.2, -0.4, 1.0];
    B[axis]
        + x.iter()
            .enumerate()
            .map(|(j, &xj)| A[axis][j] * xj)
            .sum::<f32>()
}

fn sampling_is_exact_for_linear_fields<B: LatticeKernels>() {
    let domain = domain(&[5, 4], &[-1.0, 0.0], &[1.5, 1.0], Boundary::Closed);
    let dev = B::default_device();
    let f = |x: &[f32]| 1.5 * x[0] - 2.0 * x[1] + 0.3;
    let grid = CenteredGrid::<B>::from_fn(&domain, 2, &dev, |x| vec![f(x), 2.0 * f(x)]).unwrap();
    // Inside the lattice of centres, x ∈ [−0.75, 1.25], y ∈ [0.125, 0.875].
    let points = [
        -0.75f32, 0.125, 1.25, 0.875, 0.1, 0.5, -0.3, 0.33, 0.99, 0.2,
    ];
    let sampled = sample_centered(&grid, &tensor::<B>(&[5, 2], &points)).unwrap();
    assert_eq!(sampled.shape(), vec![5, 2]);
    let error = max_error(
        &sampled,
        |_| true,
        |i| {
            let x = &points[2 * i[0]..2 * i[0] + 2];
            if i[1] == 0 { f(x) } else { 2.0 * f(x) }
        },
    );
    assert!(
        error < 1e-5,
        "centred sampling of a linear field off by {error}"
    );
    // Beyond the outermost centres: clamped to the edge sample.
    let outside = sample_centered(&grid, &tensor::<B>(&[1, 2], &[-5.0, 0.5])).unwrap();
    let want = f(&[-0.75, 0.5]);
    assert!(
        (outside.to_vec()[0] - want).abs() < 1e-5,
        "clamped sample {:?} vs {want}",
        outside.to_vec()
    );

    let u = StaggeredGrid::<B>::from_fn(&domain, &dev, velocity).unwrap();
    // Inside the sample lattices of both components (x ∈ [−0.75, 1.25] for the y-component,
    // y ∈ [0.125, 0.875] for the x-component); beyond them sampling clamps, as documented.
    let points = [
        -0.75f32, 0.125, 1.25, 0.875, 0.1, 0.5, -0.3, 0.33, 0.99, 0.2,
    ];
    let sampled = sample_staggered(&u, &tensor::<B>(&[5, 2], &points)).unwrap();
    assert_eq!(sampled.shape(), vec![5, 2]);
    let error = max_error(
        &sampled,
        |_| true,
        |i| velocity(i[1], &points[2 * i[0]..2 * i[0] + 2]),
    );
    assert!(
        error < 1e-5,
        "staggered sampling of a linear field off by {error}"
    );
}

fn particle_grid_particle_reproduces_linear_fields<B: LatticeKernels>() {
    let dev = B::default_device();
    for domain in [
        domain(&[8, 6], &[0.0, -1.0], &[2.0, 1.0], Boundary::Closed),
        domain(&[5, 4, 6], &[0.0; 3], &[1.0, 0.8, 1.5], Boundary::Open),
    ] {
        let d = domain.dim();
        let dx = domain.cell_size();
        let res = domain.resolution().to_vec();
        let host = regular_particles(&domain);
        let n = host.len() / d;
        let positions = tensor::<B>(&[n, d], &host);
        // A constant field is reproduced everywhere particles reach, from random particles too.
        let random = Tensor::<B>::random_uniform(&[n, d], 0.0, 1.0, 7, &dev);
        let random = &(random
            * tensor::<B>(
                &[1, d],
                &(0..d)
                    .map(|j| domain.upper()[j] - domain.lower()[j])
                    .collect::<Vec<_>>(),
            ))
            + &tensor::<B>(&[1, d], domain.lower());
        let constant: Vec<f32> = (0..n)
            .flat_map(|_| (0..d).map(|j| 0.5 - j as f32))
            .collect();
        let cloud = PointCloud::new(random.clone(), tensor::<B>(&[n, d], &constant)).unwrap();
        let (grid, weights) = particles_to_staggered(&cloud, &domain, Transfer::Linear).unwrap();
        for axis in 0..d {
            let w = weights.component(axis).to_vec();
            let g = grid.component(axis).to_vec();
            for (wi, gi) in w.iter().zip(&g) {
                let want = if *wi > 0.0 { 0.5 - axis as f32 } else { 0.0 };
                assert!(
                    (gi - want).abs() < 1e-5,
                    "constant field: face value {gi}, expected {want}"
                );
            }
        }
        let back = sample_staggered(&grid, &random).unwrap();
        let error = max_error(&back, |_| true, |i| 0.5 - i[1] as f32);
        assert!(
            error < 1e-5,
            "{d}-d constant field through P2G2P off by {error}"
        );

        // A linear field from regularly seeded particles: exact at the interior faces.
        let values: Vec<f32> = host
            .chunks(d)
            .flat_map(|x| (0..d).map(|j| velocity(j, x)))
            .collect();
        let cloud = PointCloud::new(positions.clone(), tensor::<B>(&[n, d], &values)).unwrap();
        let (grid, _) = particles_to_staggered(&cloud, &domain, Transfer::Linear).unwrap();
        for axis in 0..d {
            let face = |i: &[usize]| -> Vec<f32> {
                (0..d)
                    .map(|j| {
                        domain.lower()[j]
                            + (i[j] as f32 + if j == axis { 0.0 } else { 0.5 }) * dx[j]
                    })
                    .collect()
            };
            let interior = |i: &[usize]| {
                (0..d).all(|j| {
                    if j == axis {
                        i[j] >= 1 && i[j] < res[j]
                    } else {
                        i[j] >= 1 && i[j] + 2 <= res[j]
                    }
                })
            };
            let error = max_error(grid.component(axis), interior, |i| velocity(axis, &face(i)));
            assert!(
                error < 1e-4,
                "{d}-d linear field: interior faces of component {axis} off by {error}"
            );
        }
        // ... and back at the particles whose stencils use interior faces only.
        let back = sample_staggered(&grid, &positions).unwrap();
        let inner = |i: &[usize]| {
            let x = &host[i[0] * d..i[0] * d + d];
            (0..d).all(|j| {
                let cells = (x[j] - domain.lower()[j]) / dx[j];
                cells >= 1.5 && cells <= res[j] as f32 - 1.5
            })
        };
        let error = max_error(&back, inner, |i| {
            velocity(i[1], &host[i[0] * d..i[0] * d + d])
        });
        assert!(
            error < 1e-4,
            "{d}-d linear field through P2G2P off by {error}"
        );
    }
}

fn transfer_conserves_weights<B: LatticeKernels>() {
    let dev = B::default_device();
    for domain in [
        domain(&[6, 5], &[0.0, 0.0], &[3.0, 2.5], Boundary::Closed),
        domain(&[4, 3, 5], &[-1.0; 3], &[1.0, 0.5, 1.5], Boundary::Open),
    ] {
        let d = domain.dim();
        let n = 137;
        let lower = tensor::<B>(&[1, d], domain.lower());
        let size: Vec<f32> = (0..d)
            .map(|j| domain.upper()[j] - domain.lower()[j])
            .collect();
        let positions = Tensor::<B>::random_uniform(&[n, d], 0.0, 1.0, 3, &dev)
            * tensor::<B>(&[1, d], &size)
            + &lower;
        let values = Tensor::<B>::random_normal(&[n, d], 0.0, 1.0, 4, &dev);
        let cloud = PointCloud::new(positions, values.clone()).unwrap();
        for transfer in [Transfer::Linear, Transfer::NearestFace] {
            let (grid, weights) = particles_to_staggered(&cloud, &domain, transfer).unwrap();
            for axis in 0..d {
                let total = weights.component(axis).sum().to_scalar().unwrap();
                assert!(
                    (total - n as f32).abs() < 1e-3,
                    "{transfer:?} component {axis}: Σ weights = {total}, expected {n}"
                );
                // Σ w·v over the faces is the sum of the particles' values (momentum).
                let momentum = (grid.component(axis) * weights.component(axis))
                    .sum()
                    .to_scalar()
                    .unwrap();
                let want = values
                    .narrow(1, axis..axis + 1)
                    .unwrap()
                    .sum()
                    .to_scalar()
                    .unwrap();
                assert!(
                    (momentum - want).abs() < 1e-3,
                    "{transfer:?} component {axis}: momentum {momentum} vs {want}"
                );
            }
            // The valid faces are exactly those with weight.
            let valid = valid_faces(&weights).unwrap();
            for axis in 0..d {
                let w = weights.component(axis).to_vec();
                let m = valid.component(axis).to_vec();
                assert!(w.iter().zip(&m).all(|(w, m)| (*w > 0.0) == (*m == 1.0)));
            }
        }
    }
}

fn particles_to_centered_density<B: LatticeKernels>() {
    let domain = domain(&[4, 3], &[0.0, 0.0], &[4.0, 3.0], Boundary::Closed);
    // Two particles in cell (1, 1) at its centre and one at the centre of cell (3, 0).
    let positions = tensor::<B>(&[3, 2], &[1.5, 1.5, 1.5, 1.5, 3.5, 0.5]);
    let values = tensor::<B>(&[3, 1], &[2.0, 4.0, 7.0]);
    let cloud = PointCloud::new(positions.clone(), values).unwrap();
    let (grid, weights) = particles_to_centered(&cloud, &domain, Transfer::Linear).unwrap();
    let mut want_w = vec![0.0; 12];
    want_w[4] = 2.0;
    want_w[9] = 1.0;
    let mut want_v = vec![0.0; 12];
    want_v[4] = 3.0;
    want_v[9] = 7.0;
    assert_eq!(weights.values().shape(), vec![4, 3, 1]);
    assert_eq!(weights.values().to_vec(), want_w);
    assert_eq!(grid.values().to_vec(), want_v);
    let occupied = occupied_cells(&positions, &domain).unwrap();
    let want: Vec<f32> = want_w
        .iter()
        .map(|&w| if w > 0.0 { 1.0 } else { 0.0 })
        .collect();
    assert_eq!(occupied.values().to_vec(), want);
    // Off-centre: the tent weights split one particle over four cells and sum to 1.
    let cloud = PointCloud::new(
        tensor::<B>(&[1, 2], &[1.75, 1.0]),
        tensor::<B>(&[1, 1], &[1.0]),
    )
    .unwrap();
    let (_, weights) = particles_to_centered(&cloud, &domain, Transfer::Linear).unwrap();
    let w = weights.values().to_vec();
    // cells (1,0), (1,1), (2,0), (2,1) with weights 0.75·0.5, 0.75·0.5, 0.25·0.5, 0.25·0.5
    let mut want = vec![0.0; 12];
    want[3] = 0.375;
    want[4] = 0.375;
    want[6] = 0.125;
    want[7] = 0.125;
    for (g, w) in w.iter().zip(&want) {
        assert!((g - w).abs() < 1e-6, "{w:?} vs {want:?}");
    }
}

/// Host reference of one extrapolation step on a 2-d array (`3×3` box).
/// The host-side occupancy mask marks exactly the cells that `count_particles` (tensor operations)
/// counts, also for points on cell sides, on the domain's sides and outside it, in 2D and 3D.
fn occupied_cells_match_particle_counts<B: LatticeKernels>() {
    let cases = [
        domain(&[7, 5], &[-1.0, 0.5], &[2.5, 3.0], Boundary::Closed),
        domain(
            &[4, 3, 5],
            &[0.0, -2.0, 1.0],
            &[1.0, 1.0, 3.5],
            Boundary::Closed,
        ),
    ];
    for domain in cases {
        let d = domain.dim();
        let dx = domain.cell_size();
        let mut points = Vec::new();
        // Cell sides and centres on a half-cell lattice reaching one cell beyond the domain.
        let shape: Vec<usize> = domain.resolution().iter().map(|&n| 2 * n + 5).collect();
        for_each_index(&shape, |index, _| {
            for j in 0..d {
                points.push(domain.lower()[j] + (index[j] as f32 - 2.0) * 0.5 * dx[j]);
            }
        });
        // And scattered ones.
        let mut state = 0x2545_f491_u32;
        for _ in 0..500 {
            for j in 0..d {
                state ^= state << 13;
                state ^= state >> 17;
                state ^= state << 5;
                let u = state as f32 / u32::MAX as f32;
                let span = domain.upper()[j] - domain.lower()[j];
                points.push(domain.lower()[j] - 0.1 * span + 1.2 * span * u);
            }
        }
        // A few points at a time, so that most cells stay empty and every point's cell counts.
        for group in points.chunks(5 * d) {
            let group = tensor::<B>(&[group.len() / d, d], group);
            let counts = count_particles(&group, &domain).unwrap().values().clone();
            let occupied = occupied_cells(&group, &domain).unwrap().values().clone();
            assert_eq!(occupied.shape(), counts.shape());
            let want: Vec<f32> = counts
                .to_vec()
                .iter()
                .map(|&c| f32::from(c > 0.0))
                .collect();
            assert_eq!(occupied.to_vec(), want, "points {:?}", group.to_vec());
        }
    }
}

fn host_extrapolate(values: &[f32], valid: &[f32], shape: [usize; 2]) -> (Vec<f32>, Vec<f32>) {
    let (mut out, mut mask) = (values.to_vec(), valid.to_vec());
    for i in 0..shape[0] {
        for j in 0..shape[1] {
            let flat = i * shape[1] + j;
            if valid[flat] != 0.0 {
                continue;
            }
            let (mut sum, mut count) = (0.0, 0.0);
            for a in i.saturating_sub(1)..(i + 2).min(shape[0]) {
                for b in j.saturating_sub(1)..(j + 2).min(shape[1]) {
                    let k = a * shape[1] + b;
                    if valid[k] != 0.0 {
                        sum += values[k];
                        count += 1.0;
                    }
                }
            }
            if count > 0.0 {
                out[flat] = sum / count;
                mask[flat] = 1.0;
            }
        }
    }
    (out, mask)
}

fn extrapolation_fills_exactly_the_requested_layers<B: LatticeKernels>() {
    let domain = domain(&[10, 9], &[0.0, 0.0], &[10.0, 9.0], Boundary::Closed);
    // A block of liquid in cells 2..5 × 3..6 with a non-uniform velocity.
    let host: Vec<f32> = regular_particles(&domain)
        .chunks(2)
        .filter(|x| x[0] > 2.0 && x[0] < 5.0 && x[1] > 3.0 && x[1] < 6.0)
        .flat_map(|x| x.to_vec())
        .collect();
    let n = host.len() / 2;
    let values: Vec<f32> = host
        .chunks(2)
        .flat_map(|x| [velocity(0, x), velocity(1, x)])
        .collect();
    let cloud =
        PointCloud::new(tensor::<B>(&[n, 2], &host), tensor::<B>(&[n, 2], &values)).unwrap();
    let (grid, weights) = particles_to_staggered(&cloud, &domain, Transfer::Linear).unwrap();
    let valid = valid_faces(&weights).unwrap();
    for cells in [0usize, 1, 2, 3] {
        let (extrapolated, grown) = extrapolate_valid(&grid, &valid, cells).unwrap();
        for axis in 0..2 {
            let shape = domain.staggered_shape(axis);
            let shape = [shape[0], shape[1]];
            let (mut want_v, mut want_m) = (
                grid.component(axis).to_vec(),
                valid.component(axis).to_vec(),
            );
            for _ in 0..cells {
                (want_v, want_m) = host_extrapolate(&want_v, &want_m, shape);
            }
            let (got_v, got_m) = (
                extrapolated.component(axis).to_vec(),
                grown.component(axis).to_vec(),
            );
            assert_eq!(
                got_m, want_m,
                "{cells} layers: valid mask of component {axis}"
            );
            // Originally valid samples are untouched, bit for bit.
            let original = grid.component(axis).to_vec();
            for (k, &m) in valid.component(axis).to_vec().iter().enumerate() {
                if m == 1.0 {
                    assert_eq!(
                        got_v[k], original[k],
                        "valid sample {k} of component {axis} changed"
                    );
                }
            }
            for (k, (g, w)) in got_v.iter().zip(&want_v).enumerate() {
                assert!(
                    (g - w).abs() < 1e-4,
                    "{cells} layers, component {axis}, sample {k}: {g} vs {w}"
                );
            }
            // Exactly `cells` layers: the grown region is the original dilated `cells` times by
            // the 3×3 box (Chebyshev distance ≤ cells).
            let m0 = valid.component(axis).to_vec();
            for i in 0..shape[0] {
                for j in 0..shape[1] {
                    let near = (0..shape[0]).any(|a| {
                        (0..shape[1]).any(|b| {
                            m0[a * shape[1] + b] == 1.0 && a.abs_diff(i).max(b.abs_diff(j)) <= cells
                        })
                    });
                    assert_eq!(
                        got_m[i * shape[1] + j] == 1.0,
                        near,
                        "layer membership at ({i}, {j})"
                    );
                }
            }
        }
    }
    // Centred grids take one mask for all channels.
    let field = CenteredGrid::<B>::new(
        tensor::<B>(&[3, 1, 2], &[0.0, 0.0, 1.0, 2.0, 0.0, 0.0]),
        Domain::closed_unit_cells(&[3, 1]).unwrap(),
    )
    .unwrap();
    let mask = CenteredGrid::<B>::new(
        tensor::<B>(&[3, 1, 1], &[0.0, 1.0, 0.0]),
        field.domain().clone(),
    )
    .unwrap();
    let (out, grown) = extrapolate_valid(&field, &mask, 1).unwrap();
    assert_eq!(out.values().to_vec(), vec![1.0, 2.0, 1.0, 2.0, 1.0, 2.0]);
    assert_eq!(grown.values().to_vec(), vec![1.0, 1.0, 1.0]);
}

/// Points in `u_i = a_i x_i`, which multilinear sampling reproduces exactly inside the faces:
/// one Euler step is `x (1 + z)` and one RK4 step `x (1 + z + z²/2 + z³/6 + z⁴/24)` with
/// `z = a_i Δt`, the Taylor polynomial of the exact `x e^{z}` to fourth order, in 2D and 3D.
fn point_advection_integrates_a_linear_field<B: LatticeKernels>() {
    const RATES: [f32; 3] = [0.8, -1.2, 0.5];
    let dev = B::default_device();
    for d in [2usize, 3] {
        let res = vec![8; d];
        let domain = domain(&res, &vec![-2.0; d], &vec![2.0; d], Boundary::Closed);
        let u =
            StaggeredGrid::<B>::from_fn(&domain, &dev, |axis, x| RATES[axis] * x[axis]).unwrap();
        // Start and all RK4 stages well inside every component's lattice.
        let points: Vec<f32> = (0..5 * d)
            .map(|k| -0.9 + 0.37 * (k % 5) as f32 + 0.05 * (k / 5) as f32)
            .collect();
        let n = points.len() / d;
        let dt = 0.4;
        for (integrator, order) in [(Integrator::Euler, 1), (Integrator::Rk4, 4)] {
            let moved = advect_points(&tensor::<B>(&[n, d], &points), &u, dt, integrator).unwrap();
            assert_eq!(moved.shape(), vec![n, d]);
            let taylor = |z: f64| {
                let mut term = 1.0;
                let mut sum = 1.0;
                for k in 1..=order {
                    term *= z / f64::from(k);
                    sum += term;
                }
                sum
            };
            for (i, (&got, &x)) in moved.to_vec().iter().zip(&points).enumerate() {
                let z = f64::from(RATES[i % d]) * f64::from(dt);
                let want = f64::from(x) * taylor(z);
                assert!(
                    (f64::from(got) - want).abs() < 2e-6,
                    "{d}D {integrator:?}: point {i} moved to {got}, want {want}"
                );
                // Euler and RK4 differ from the exact flow as their orders say.
                let exact = f64::from(x) * z.exp();
                let bound = 1.5 * f64::from(x).abs() * z.abs().powi(order + 1)
                    / (1..=order + 1).product::<i32>() as f64;
                assert!(
                    (f64::from(got) - exact).abs() <= bound + 2e-6,
                    "{d}D {integrator:?}: point {i} is {} from the exact flow (bound {bound})",
                    (f64::from(got) - exact).abs()
                );
            }
        }
    }
}
