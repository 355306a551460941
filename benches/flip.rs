//! FLIP steps per backend on the shipped scenes: `small32` (32², 1,024 particles, dt 0.05, the
//! dataset scale) and `block_pool` (64², 11,520 particles, dt 0.1), from the state after 20 steps
//! (the block in flight). Compare with Φ_Flow 2.1.4 on the same scenes (docs/benchmarks.md).
//!
//! `cargo bench --bench flip --features tch -- --noplot`; single-threaded numbers with
//! `RAYON_NUM_THREADS=1`.

mod common;

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use phi_core::fields::LatticeKernels;
use phi_flip::Scene;

fn bench_backend<B: LatticeKernels>(c: &mut Criterion) {
    let device = B::default_device();
    for name in ["small32", "block_pool"] {
        let path =
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("scenes/{name}.toml"));
        let scene = Scene::from_file(&path).expect("a shipped scene");
        let setup = scene.build::<B>(name, &device).expect("the scene builds");
        let sim = setup.simulation;
        let mut particles = setup.particles;
        for step in 0..20 {
            particles = sim.step(&particles, step).expect("a step").0;
        }
        c.bench_with_input(
            BenchmarkId::new(format!("flip step {name}"), B::name()),
            &(),
            |b, _| {
                b.iter(|| {
                    let (next, _) = sim.step(&particles, 20).expect("a step");
                    common::force(&next.positions)
                })
            },
        );
    }
}

fn benches(c: &mut Criterion) {
    phi_core::for_each_backend!(B => bench_backend::<B>(c));
}

criterion_group! {
    name = flip;
    config = Criterion::default().sample_size(10).measurement_time(std::time::Duration::from_secs(3));
    targets = benches
}
criterion_main!(flip);
