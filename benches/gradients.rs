//! Gradients through FLIP: forward (20 steps) and forward plus backward (20 steps and the
//! gradient of a loss of the final positions with respect to the initial positions) of
//! `scenes/small32.toml` (32², 1,024 particles, dt 0.05) on the autodiff backends.
//!
//! Before the timings, it prints the growth of the process' peak resident memory (`VmHWM`) over
//! one forward pass and over one forward-plus-backward pass (the first measurement of each
//! backend, so the peak is the pass' own).
//!
//! `cargo bench --bench gradients --features tch -- --noplot`.

// Shared with the other benches; this one runs on the autodiff backends only and does not use
// `on_every_backend`.
#[allow(unused_macros, unused_imports)]
mod common;

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use phi_core::{AutodiffBackend, Backend, Tensor};
use phi_flip::{FlipSimulation, Particles, Scene};

const STEPS: usize = 20;

fn forward<B: Backend>(sim: &FlipSimulation<B>, start: &Particles<B>) -> Tensor<B> {
    let mut p = start.clone();
    for step in 0..STEPS {
        p = sim.step(&p, step).expect("a step").0;
    }
    p.positions
}

fn forward_backward<B: AutodiffBackend>(
    sim: &FlipSimulation<B>,
    start: &Particles<B>,
) -> Tensor<B> {
    let x0 = start.positions.require_grad();
    let p = Particles {
        positions: x0.clone(),
        velocities: start.velocities.clone(),
        affine: start.affine.clone(),
    };
    let end = forward(sim, &p);
    let loss = end.square().sum();
    loss.gradients(&[&x0]).expect("gradients").remove(0)
}

/// The peak resident set size of this process in KiB (Linux `VmHWM`; 0 elsewhere).
fn peak_rss_kib() -> u64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmHWM:"))
                .and_then(|l| l.split_whitespace().nth(1)?.parse().ok())
        })
        .unwrap_or(0)
}

fn bench_backend<B: AutodiffBackend>(c: &mut Criterion) {
    let device = B::default_device();
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/small32.toml");
    let scene = Scene::from_file(&path).expect("a shipped scene");
    let setup = scene
        .build::<B>("small32", &device)
        .expect("the scene builds");
    let (sim, start) = (setup.simulation, setup.particles);

    let before = peak_rss_kib();
    common::force(&forward(&sim, &start));
    let after_forward = peak_rss_kib();
    common::force(&forward_backward(&sim, &start));
    let after_backward = peak_rss_kib();
    println!(
        "{}: peak memory +{} MiB over the forward pass, +{} MiB more over forward + backward \
         (peak {} MiB)",
        B::name(),
        (after_forward - before) / 1024,
        (after_backward - after_forward) / 1024,
        after_backward / 1024
    );

    let mut group = c.benchmark_group("gradients small32 20 steps");
    group.sample_size(10);
    group.bench_with_input(BenchmarkId::new("forward", B::name()), &(), |b, _| {
        b.iter(|| common::force(&forward(&sim, &start)))
    });
    group.bench_with_input(
        BenchmarkId::new("forward+backward", B::name()),
        &(),
        |b, _| b.iter(|| common::force(&forward_backward(&sim, &start))),
    );
    group.finish();
}

fn benches(c: &mut Criterion) {
    let _ = &c; // no autodiff backend compiled in: nothing to measure
    #[cfg(feature = "burn")]
    bench_backend::<phi_core::backend::burn::Burn>(c);
    #[cfg(feature = "tch")]
    bench_backend::<phi_core::backend::tch::Tch>(c);
}

criterion_group!(benches_group, benches);
criterion_main!(benches_group);
