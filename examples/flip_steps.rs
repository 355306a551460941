//! Times FLIP steps of a scene on the ndarray backend, for quick before/after comparisons of the
//! step's kernels (criterion's `benches/flip.rs` is the reference measurement).
//!
//! `cargo run --release --example flip_steps -- scenes/block_pool.toml 300`
//!
//! Runs 20 steps, then times `N` steps that all start from that state (what the bench measures)
//! and `N` steps of the run going on (the liquid moves, so every pressure matrix is new). Prints
//! the median and the best step time of each. Run it with `RAYON_NUM_THREADS=1` for
//! single-threaded numbers, and under `valgrind --tool=cachegrind` for instruction counts, which
//! vary far less than times on a shared machine.

use std::time::Instant;

use anyhow::{Context, Result};
use clap::Parser;
use phi_core::Backend;
use phi_core::backend::ndarray::NdArray;
use phi_flip::Scene;

#[derive(Parser)]
struct Args {
    /// The scene file.
    scene: std::path::PathBuf,
    /// Steps to time in each of the two runs.
    #[arg(default_value_t = 300)]
    steps: usize,
}

/// Median and minimum of `times` (milliseconds), sorting them.
fn summary(times: &mut [f64]) -> (f64, f64) {
    times.sort_by(f64::total_cmp);
    (times[times.len() / 2], times[0])
}

#[global_allocator]
static ALLOCATOR: phi::allocator::Allocator = phi::allocator::Allocator;

fn main() -> Result<()> {
    phi::allocator::configure();
    let args = Args::parse();
    anyhow::ensure!(args.steps > 0, "time at least one step");
    let scene = Scene::from_file(&args.scene)
        .with_context(|| format!("reading {}", args.scene.display()))?;
    let device = NdArray::default_device();
    let setup = scene.build::<NdArray>("timing", &device)?;
    let sim = setup.simulation;
    let mut particles = setup.particles;
    for step in 0..20 {
        particles = sim.step(&particles, step)?.0;
    }
    let time_ms = |start: Instant| start.elapsed().as_secs_f64() * 1e3;

    let mut same = Vec::with_capacity(args.steps);
    for _ in 0..args.steps {
        let start = Instant::now();
        let next = sim.step(&particles, 20)?;
        same.push(time_ms(start));
        std::hint::black_box(next);
    }
    let mut moving = Vec::with_capacity(args.steps);
    for step in 20..20 + args.steps {
        let start = Instant::now();
        particles = sim.step(&particles, step)?.0;
        moving.push(time_ms(start));
    }
    let (median, best) = summary(&mut same);
    println!("from one state: median {median:.3} ms, best {best:.3} ms");
    let (median, best) = summary(&mut moving);
    println!("moving run:     median {median:.3} ms, best {best:.3} ms");
    Ok(())
}
