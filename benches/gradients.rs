//! Gradients through FLIP: forward (20 steps) and forward plus backward (20 steps and the
//! gradient of a loss of the final positions with respect to the initial positions) of
//! `scenes/small32.toml` (32², 1,024 particles, dt 0.05) on the autodiff backends.
//!
//! Before the timings, it prints each backend's memory: the peak resident memory (`VmHWM`) of
//! one forward pass and of one forward-plus-backward pass above the resident memory before it
//! (the peak is reset before each pass through `/proc/self/clear_refs`, so every number is the
//! pass' own whatever ran before), and the resident memory after each of five more
//! forward-plus-backward passes (memory that stays behind shows up as growth).
//!
//! `cargo bench --bench gradients --features tch -- --noplot`.

// Shared with the other benches; this one runs on the autodiff backends only and does not use
// `on_every_backend`.
#[allow(unused_macros, unused_imports)]
mod common;

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use phi_core::fields::LatticeKernels;
use phi_core::{AutodiffBackend, Tensor};
use phi_flip::{FlipSimulation, Particles, Scene};

const STEPS: usize = 20;

fn forward<B: LatticeKernels>(sim: &FlipSimulation<B>, start: &Particles<B>) -> Tensor<B> {
    let mut p = start.clone();
    for step in 0..STEPS {
        p = sim.step(&p, step).expect("a step").0;
    }
    p.positions
}

fn forward_backward<B: AutodiffBackend + LatticeKernels>(
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

/// A field of `/proc/self/status` in KiB (`VmHWM`: the peak resident set size, `VmRSS`: the
/// current one; 0 off Linux).
fn status_kib(field: &str) -> u64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with(field))
                .and_then(|l| l.split_whitespace().nth(1)?.parse().ok())
        })
        .unwrap_or(0)
}

/// Resets the peak resident set size to the current one (Linux); false where it cannot.
fn reset_peak() -> bool {
    std::fs::write("/proc/self/clear_refs", "5").is_ok()
}

/// The peak resident memory of `pass` above `baseline` (KiB of resident memory before the
/// backend's first pass), in MiB: the footprint of the pass, including memory the allocators
/// kept from earlier passes and reuse.
fn peak_of(baseline: u64, pass: impl FnOnce()) -> Option<f64> {
    if !reset_peak() {
        return None;
    }
    pass();
    Some(status_kib("VmHWM:").saturating_sub(baseline) as f64 / 1024.0)
}

fn memory_report<B: AutodiffBackend + LatticeKernels>(
    sim: &FlipSimulation<B>,
    start: &Particles<B>,
) {
    let baseline = status_kib("VmRSS:");
    let forward_peak = peak_of(baseline, || common::force(&forward(sim, start)));
    let backward_peak = peak_of(baseline, || common::force(&forward_backward(sim, start)));
    // Resident memory above the baseline after each of five runs of `pass`.
    let resident_after = |pass: &dyn Fn()| -> String {
        (0..5)
            .map(|_| {
                pass();
                format!(
                    "{:+.0}",
                    (status_kib("VmRSS:") as f64 - baseline as f64) / 1024.0
                )
            })
            .collect::<Vec<_>>()
            .join(", ")
    };
    println!(
        "{}: resident after five forward passes: {} MiB",
        B::name(),
        resident_after(&|| common::force(&forward(sim, start)))
    );
    let resident = resident_after(&|| common::force(&forward_backward(sim, start)));
    match (forward_peak, backward_peak) {
        (Some(f), Some(b)) => println!(
            "{}: peak memory of a forward pass +{f:.1} MiB, of forward + backward +{b:.1} MiB \
             (above the {:.0} MiB resident before); resident after five more forward + \
             backward passes: {} MiB",
            B::name(),
            baseline as f64 / 1024.0,
            resident
        ),
        _ => println!("{}: peak memory not measurable here", B::name()),
    }
}

fn bench_backend<B: AutodiffBackend + LatticeKernels>(c: &mut Criterion) {
    let device = B::default_device();
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/small32.toml");
    let scene = Scene::from_file(&path).expect("a shipped scene");
    let setup = scene
        .build::<B>("small32", &device)
        .expect("the scene builds");
    let (sim, start) = (setup.simulation, setup.particles);

    memory_report(&sim, &start);

    reset_peak();
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
    println!(
        "{}: peak resident memory over the timing loops {:.0} MiB",
        B::name(),
        status_kib("VmHWM:") as f64 / 1024.0
    );
}

fn benches(c: &mut Criterion) {
    let _ = &c; // no autodiff backend compiled in: nothing to measure
    phi_core::for_each_autodiff_backend!(B => bench_backend::<B>(c));
}

criterion_group!(benches_group, benches);
criterion_main!(benches_group);
