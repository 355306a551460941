//! The fields layer per backend: pressure projection of a random velocity on a tank about half
//! full of liquid (32², 64², 128², 64³), and particle → grid / grid → particle transfers with 10k
//! and 100k particles on a 64² grid.
//!
//! The projections cycle through eight liquid levels (the upper half of the tank less 0–7
//! layers), so that, as in a FLIP step where the liquid moves, every call assembles, analyses and
//! factorises a matrix of a new pattern. `… same mask` repeats one level: a liquid at rest, where
//! the symbolic analysis of the previous call is reused.
//!
//! `cargo bench --bench fields --features tch -- --noplot` (add a filter such as `projection`).

mod common;

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use phi_core::Tensor;
use phi_core::fields::LatticeKernels;
use phi_core::fields::{
    Boundary, CenteredGrid, Domain, PointCloud, ProjectionMasks, StaggeredGrid, Transfer,
    particles_to_staggered, pressure_projection, sample_staggered,
};
use phi_core::solve::{Preconditioner, SolveMethod, SolveOptions};

fn domain(res: &[usize]) -> Domain {
    let upper: Vec<f32> = res.iter().map(|&n| n as f32).collect();
    Domain::new(
        res,
        &vec![0.0; res.len()],
        &upper,
        &vec![[Boundary::Closed; 2]; res.len()],
    )
    .expect("a valid domain")
}

fn bench_backend<B: LatticeKernels>(c: &mut Criterion) {
    let device = B::default_device();
    let name = B::name();
    for res in [
        vec![32usize, 32],
        vec![64, 64],
        vec![128, 128],
        vec![64, 64, 64],
    ] {
        let domain = domain(&res);
        let d = res.len();
        let top = res[d - 1] as f32 / 2.0;
        let liquids: Vec<CenteredGrid<B>> = (0..8)
            .map(|k| {
                CenteredGrid::<B>::from_fn(&domain, 1, &device, |x| {
                    vec![if x[d - 1] < top - k as f32 { 1.0 } else { 0.0 }]
                })
                .expect("a mask")
            })
            .collect();
        let velocity = StaggeredGrid::<B>::from_fn(&domain, &device, |axis, x| {
            ((axis as f32 + 1.0) * 0.37 * x.iter().sum::<f32>()).sin()
        })
        .expect("a field");
        let label = res
            .iter()
            .map(|n| n.to_string())
            .collect::<Vec<_>>()
            .join("x");
        // The solve is the same host code on every backend: compare its methods on ndarray.
        let mut methods = vec![("", SolveMethod::Auto)];
        if name == "ndarray" {
            methods.push((
                " cg-ic0",
                SolveMethod::ConjugateGradient(Preconditioner::IncompleteCholesky),
            ));
            methods.push((
                " cg-mic0",
                SolveMethod::ConjugateGradient(Preconditioner::ModifiedIncompleteCholesky),
            ));
            if d == 2 {
                methods.push((" cholesky", SolveMethod::Cholesky));
            }
        }
        if d == 2 {
            methods.push((" same mask", SolveMethod::Auto));
        }
        for (suffix, method) in methods {
            let options = SolveOptions::with_method(method);
            let id = BenchmarkId::new(format!("projection {label}{suffix}"), name);
            let cycle = if suffix == " same mask" {
                1
            } else {
                liquids.len()
            };
            let mut call = 0usize;
            c.bench_with_input(id, &(), |b, _| {
                b.iter(|| {
                    call += 1;
                    let liquid = &liquids[call % cycle];
                    let p =
                        pressure_projection(&velocity, ProjectionMasks::liquid(liquid), &options)
                            .expect("the solve converges");
                    common::force(p.velocity.component(0))
                })
            });
        }
    }

    let domain = domain(&[64, 64]);
    for n in [10_000usize, 100_000] {
        let positions = Tensor::<B>::random_uniform(&[n, 2], 0.0, 64.0, 1, &device);
        let velocities = Tensor::<B>::random_uniform(&[n, 2], -1.0, 1.0, 2, &device);
        let cloud = PointCloud::new(positions.clone(), velocities).expect("a cloud");
        let (grid, _) = particles_to_staggered(&cloud, &domain, Transfer::Linear).expect("p2g");
        c.bench_with_input(
            BenchmarkId::new(format!("particles to grid {n}"), name),
            &(),
            |b, _| {
                b.iter(|| {
                    let (g, _) =
                        particles_to_staggered(&cloud, &domain, Transfer::Linear).expect("p2g");
                    common::force(g.component(0))
                })
            },
        );
        c.bench_with_input(
            BenchmarkId::new(format!("grid to particles {n}"), name),
            &(),
            |b, _| {
                b.iter(|| {
                    let v = sample_staggered(&grid, &positions).expect("g2p");
                    common::force(&v)
                })
            },
        );
    }
}

fn benches(c: &mut Criterion) {
    phi_core::for_each_backend!(B => bench_backend::<B>(c));
}

criterion_group! {
    name = fields;
    config = Criterion::default().sample_size(10).measurement_time(std::time::Duration::from_secs(3));
    targets = benches
}
criterion_main!(fields);
