//! Times GNS inference steps (radius graph, forward pass, integration) on one frame of a dataset
//! trajectory, and optionally a rollout, for side-by-side runs with other GNS implementations
//! (criterion's `benches/gns.rs` is the reference measurement).
//!
//! ```sh
//! cargo run --release --example gns_step -- --data DATASET --split train --index 7 --frame 100
//! ```
//!
//! The model has the thesis's sizes (10 × 128, 2 hidden layers, embedding 16) with seeded random
//! weights; `--write-input FILE.npz` writes the window, particle types, edges and normalisation
//! (the input format of the PyTorch anchor scripts) and `--write-model DIR` the model directory,
//! so that another implementation can run the same network on the same input. `--rollout K`
//! times a K-step rollout from that frame and prints the peak resident memory.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result, ensure};
use clap::Parser;
use phi::backends::BackendKind;
use phi_gns::data::{Dataset, read_trajectory};
use phi_gns::graph::{ExamplePositions, RadiusGraph};
use phi_gns::model::{Gns, GnsConfig, GnsKernels, GraphBatch, ModelSpec, save_model};
use phi_gns::rollout::{RolloutRange, input_window, rollout};
use phi_io::npz::{NpyArray, write_npz};

#[derive(Parser)]
struct Args {
    /// The dataset directory.
    #[arg(long)]
    data: PathBuf,
    /// The split.
    #[arg(long, default_value = "train")]
    split: String,
    /// The trajectory.
    #[arg(long, default_value_t = 0)]
    index: usize,
    /// The latest frame of the input window.
    #[arg(long, default_value_t = 100)]
    frame: usize,
    /// The backend.
    #[arg(long, default_value = "ndarray")]
    backend: BackendKind,
    /// Steps to time (after two warm-up steps).
    #[arg(long, default_value_t = 10)]
    repeats: usize,
    /// The seed of the weights.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Write the input of the step here (.npz).
    #[arg(long)]
    write_input: Option<PathBuf>,
    /// Write the model directory here.
    #[arg(long)]
    write_model: Option<PathBuf>,
    /// Write the normalised accelerations of the step here (.npy via .npz member `acc`).
    #[arg(long)]
    write_acc: Option<PathBuf>,
    /// Then time a rollout of this many steps from the frame.
    #[arg(long, default_value_t = 0)]
    rollout: usize,
}

/// Median and minimum of `times` (milliseconds), sorting them.
fn summary(times: &mut [f64]) -> (f64, f64) {
    times.sort_by(f64::total_cmp);
    (times[times.len() / 2], times[0])
}

/// Peak resident set size of this process in MiB (Linux `VmHWM`).
fn peak_rss_mib() -> Option<f64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kib: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib / 1024.0)
}

fn run<B: GnsKernels>(args: &Args) -> Result<()> {
    let dataset = Dataset::open(&args.data)?;
    let metadata = dataset.metadata();
    let path = Dataset::trajectory_path(&args.data, &args.split, args.index);
    let trajectory = read_trajectory(&path)?;
    let spec = ModelSpec::for_dataset(metadata, GnsConfig::thesis(metadata.dim), args.seed);
    let c = spec.config.input_velocities;
    ensure!(
        args.frame >= c && args.frame < trajectory.frames,
        "frame {} is not in {c}..{}",
        args.frame,
        trajectory.frames
    );
    let device = B::default_device();
    let model = Gns::<B>::init(spec, &device)?;
    let (n, dim) = (trajectory.particles, trajectory.dim);
    let window = input_window(&trajectory, args.frame, c);
    let types = &trajectory.particle_type;
    let step = || -> Result<(usize, Vec<f32>)> {
        let batch = GraphBatch::<B>::from_host(&window, types, model.spec(), &device)?;
        let next = model.next_positions(&batch)?.to_vec();
        Ok((batch.graph().edges(), next))
    };
    let (edges, _) = step()?;
    step()?;
    let mut times = Vec::with_capacity(args.repeats);
    for _ in 0..args.repeats {
        let start = Instant::now();
        std::hint::black_box(step()?);
        times.push(start.elapsed().as_secs_f64() * 1e3);
    }
    let (median, best) = summary(&mut times);
    let liquid = types
        .iter()
        .filter(|&&t| t == phi_gns::data::LIQUID)
        .count();
    println!(
        "{}: {n} particles ({liquid} liquid), {edges} edges, {} threads: step median {median:.1} ms, best {best:.1} ms",
        B::name(),
        rayon::current_num_threads()
    );
    if let Some(out) = &args.write_input {
        let batch = GraphBatch::<B>::from_host(&window, types, model.spec(), &device)?;
        let graph = batch.graph();
        let f64s = |v: &[f64]| NpyArray::new(vec![v.len()], v.to_vec());
        let n_ = &model.spec().normalisation;
        let bounds: Vec<f64> = model
            .spec()
            .bounds
            .iter()
            .flat_map(|b| [b[0], b[1]])
            .collect();
        let arrays = [
            (
                "position",
                NpyArray::new(vec![n, c + 1, dim], window.clone())?,
            ),
            ("particle_type", NpyArray::new(vec![n], types.clone())?),
            (
                "senders",
                NpyArray::new(vec![edges], graph.senders().to_vec())?,
            ),
            (
                "receivers",
                NpyArray::new(vec![edges], graph.receivers().to_vec())?,
            ),
            ("bounds", NpyArray::new(vec![dim, 2], bounds)?),
            (
                "radius",
                NpyArray::new(vec![], vec![model.spec().config.connectivity_radius])?,
            ),
            ("vel_mean", f64s(&n_.vel_mean)?),
            ("vel_std", f64s(&n_.vel_std)?),
            ("acc_mean", f64s(&n_.acc_mean)?),
            ("acc_std", f64s(&n_.acc_std)?),
        ];
        let refs: Vec<(&str, &NpyArray)> = arrays.iter().map(|(k, a)| (*k, a)).collect();
        write_npz(out, &refs).with_context(|| format!("writing {}", out.display()))?;
    }
    if let Some(out) = &args.write_acc {
        let batch = GraphBatch::<B>::from_host(&window, types, model.spec(), &device)?;
        let acc = model.normalised_acceleration(&batch)?.to_vec();
        let array = NpyArray::new(vec![n, dim], acc)?;
        write_npz(out, &[("acc", &array)]).with_context(|| format!("writing {}", out.display()))?;
    }
    if let Some(dir) = &args.write_model {
        save_model(dir, &model)?;
    }
    if args.rollout > 0 {
        let range = RolloutRange {
            start: args.frame,
            steps: args.rollout,
        };
        let start = Instant::now();
        let mut latest = vec![trajectory.frame(args.frame).to_vec()];
        rollout(&model, &trajectory, range, &device, |_, positions| {
            latest.push(positions.to_vec());
            Ok(())
        })?;
        let seconds = start.elapsed().as_secs_f64();
        let frames = latest.len() - 1;
        // Step k reads the graph of frame k − 1: the rollout's graphs grow or shrink as the
        // predicted liquid gathers or spreads, so the time is per edge as well as per step.
        let edges = latest[..frames]
            .iter()
            .map(|p| {
                let example = ExamplePositions::new(p, trajectory.particles);
                RadiusGraph::for_batch(&[example], dim, model.spec().config.connectivity_radius)
                    .map(|g| g.edges())
            })
            .sum::<Result<usize, _>>()? as f64
            / frames as f64;
        println!(
            "rollout: {frames} steps in {seconds:.2} s ({:.1} ms per step; {edges:.0} edges a \
             step, {:.2} µs per edge), peak RSS {:.0} MiB",
            seconds * 1e3 / frames as f64,
            seconds * 1e6 / frames as f64 / edges,
            peak_rss_mib().unwrap_or(f64::NAN)
        );
    }
    Ok(())
}

#[global_allocator]
static ALLOCATOR: phi::allocator::Allocator = phi::allocator::Allocator;

fn main() -> Result<()> {
    phi::allocator::configure();
    let args = Args::parse();
    phi::with_backend!(args.backend, B => run::<B>(&args))
}
