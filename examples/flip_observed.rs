//! What FLIP does next from what a GNS sees of it.
//!
//! A GNS reads positions only, and takes a particle's velocity as the difference of its last two
//! positions. FLIP's particles carry a velocity of their own, which the grid updates by
//! increments and which drifts away from that difference once the liquid has hit something; the
//! next frame depends on it through the transfer to the grid. This restarts FLIP at chosen
//! frames of a dataset trajectory from the recorded positions with either velocity:
//!
//! - FLIP's own: the next frame must be the dataset's, bit for bit (checked: otherwise the scene
//!   is not the trajectory's, or the step is not deterministic);
//! - the backward difference of the positions, what the GNS's latest input velocity says.
//!
//! The second's next frame is written as a `phi rollout --steps 1` folder (`OUT/sS/SPLIT_I/
//! rollout.npz`), so that `scripts/contact_response.py` reads it as it reads a model's: a
//! deterministic simulator that knows the physics exactly and sees what a GNS sees.
//!
//! ```sh
//! cargo run --release --example flip_observed -- scenes/test/05_funnel.toml data/flip \
//!     --split test --trajectory 4 --starts 18,20,22 --out observed
//! python3 scripts/contact_response.py data/flip test 4 observed/s*
//! ```

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail, ensure};
use clap::Parser;
use phi_core::Backend;
use phi_core::backend::ndarray::NdArray;
use phi_flip::{Particles, Scene};
use phi_gns::data::{Dataset, LIQUID};
use phi_io::npy::{ArrayData, NpyArray};

#[derive(Parser)]
struct Args {
    /// The scene file the trajectory was generated from.
    scene: PathBuf,
    /// The dataset.
    data: PathBuf,
    /// The split.
    #[arg(long, default_value = "test")]
    split: String,
    /// The trajectory's index in the split.
    #[arg(long)]
    trajectory: usize,
    /// The frames to restart from (comma-separated, each at least 1).
    #[arg(long, value_delimiter = ',', required = true)]
    starts: Vec<usize>,
    /// The output folder (one `sS` folder per start).
    #[arg(long)]
    out: PathBuf,
}

fn main() -> Result<()> {
    let args = Args::parse();
    let scene = Scene::from_file(&args.scene)
        .with_context(|| format!("reading {}", args.scene.display()))?;
    let device = NdArray::default_device();
    let setup = scene.build::<NdArray>(&args.scene.display().to_string(), &device)?;
    let sim = setup.simulation;
    let dim = sim.domain().dim();
    let dt = sim.params().dt;

    let dataset = Dataset::open(&args.data)?;
    let (truth, _) = dataset.read_with_stats(&args.split, args.trajectory)?;
    let meta = dataset.metadata();
    let (scale, offset) = (meta.position_scale as f32, meta.position_offset as f32);
    let liquid: Vec<usize> = (0..truth.particles)
        .filter(|&i| truth.particle_type[i] == LIQUID)
        .collect();
    let last = *args.starts.iter().max().unwrap_or(&0) + 1;
    ensure!(
        args.starts.iter().all(|&s| s >= 1) && last < truth.frames,
        "--starts: every start must be at least 1 and leave a frame after it (the trajectory has {})",
        truth.frames
    );

    // FLIP's own states up to the last frame needed, checked against the dataset.
    let mut states = vec![host_state(&setup.particles)];
    let mut particles = setup.particles;
    for step in 0..last {
        particles = sim.step(&particles, step)?.0;
        states.push(host_state(&particles));
    }
    ensure!(
        states[0].0.len() == liquid.len() * dim,
        "{}: {} liquid particles, the scene starts with {}",
        args.data.display(),
        liquid.len(),
        states[0].0.len() / dim
    );
    let stored = |x: &[f32]| -> Vec<f32> { x.iter().map(|v| offset + scale * v).collect() };
    for (t, (x, _)) in states.iter().enumerate() {
        let frame = liquid_frame(truth.frame(t), &liquid, dim);
        if stored(x) != frame {
            bail!(
                "{}: frame {t} of trajectory {} is not what {} simulates (not the same scene)",
                args.data.display(),
                args.trajectory,
                args.scene.display()
            );
        }
    }

    println!(
        "start\tFLIP from its own velocities: largest difference\tfrom observed velocities: RMS difference (cells)"
    );
    for &s in &args.starts {
        let (x, v) = &states[s];
        let own = Particles::<NdArray>::from_host(x.clone(), v.clone(), dim, &device)?;
        let again = host_state(&sim.step(&own, s)?.0).0;
        let (next, _) = &states[s + 1];
        let exact = largest_difference(&again, next);

        let previous = &states[s - 1].0;
        let observed: Vec<f32> = x.iter().zip(previous).map(|(a, b)| (a - b) / dt).collect();
        let seen = Particles::<NdArray>::from_host(x.clone(), observed, dim, &device)?;
        let predicted = host_state(&sim.step(&seen, s)?.0).0;
        let rms = (predicted
            .iter()
            .zip(next)
            .map(|(a, b)| f64::from(a - b).powi(2))
            .sum::<f64>()
            / liquid.len() as f64)
            .sqrt();
        println!("{s}\t{exact:e}\t{rms:.4}");

        // The dataset's frame s + 1 with the liquid where the restart put it.
        let mut frame = truth.frame(s + 1).to_vec();
        for (k, &i) in liquid.iter().enumerate() {
            frame[i * dim..(i + 1) * dim]
                .copy_from_slice(&stored(&predicted[k * dim..(k + 1) * dim]));
        }
        write_rollout(&args, s, frame, truth.particles, dim)?;
    }
    Ok(())
}

/// Positions and velocities on the host, `[N·d]` each.
fn host_state(particles: &Particles<NdArray>) -> (Vec<f32>, Vec<f32>) {
    (
        particles.positions.host_values().into_owned(),
        particles.velocities.host_values().into_owned(),
    )
}

/// The liquid particles' coordinates of a dataset frame, in order.
fn liquid_frame(frame: &[f32], liquid: &[usize], dim: usize) -> Vec<f32> {
    liquid
        .iter()
        .flat_map(|&i| frame[i * dim..(i + 1) * dim].iter().copied())
        .collect()
}

fn largest_difference(a: &[f32], b: &[f32]) -> f32 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f32::max)
}

/// `OUT/sS/SPLIT_I/rollout.npz` with the one predicted frame and its start, as `phi rollout`
/// writes them.
fn write_rollout(args: &Args, start: usize, frame: Vec<f32>, n: usize, dim: usize) -> Result<()> {
    let dir: PathBuf = args
        .out
        .join(format!("s{start}"))
        .join(format!("{}_{}", args.split, args.trajectory));
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    let predicted = NpyArray {
        shape: vec![1, n, dim],
        data: ArrayData::F32(frame),
    };
    let start = NpyArray {
        shape: vec![1],
        data: ArrayData::I64(vec![start as i64]),
    };
    let path: &Path = &dir.join("rollout.npz");
    phi_io::npz::write_npz(
        path,
        &[("predicted_position", &predicted), ("start", &start)],
    )?;
    Ok(())
}
