//! Times GNS training steps on a batch of dataset windows, for side-by-side runs with other GNS
//! implementations (criterion's `benches/gns.rs` is the reference measurement).
//!
//! ```sh
//! cargo run --release --example gns_train_step -- --data DATASET --backend burn \
//!     --example 40:100 --example 41:100
//! ```
//!
//! One step is DeepMind's: random-walk noise (σ = 6.7e-4, seeded) on each window, the radius
//! graph of the noisy latest positions, the one-step loss against the noise-adjusted next
//! positions with kinematic particles masked, its gradients, and an Adam update. The model has
//! the thesis's sizes (10 × 128, 2 hidden layers, embedding 16) with seeded random weights. The
//! steps after the warm-up are timed; the peak resident memory of the process is printed at the
//! end. `--write-input FILE.npz` writes the clean windows, types, next positions, the first
//! step's noise and its loss, and `--write-model DIR` the initial model directory, so that
//! another implementation can train from the same weights on the same batch.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result, bail, ensure};
use clap::Parser;
use phi::backends::BackendKind;
use phi_core::AutodiffBackend;
use phi_core::tensor::Tensor;
use phi_gns::data::{Dataset, Trajectory, read_trajectory};
use phi_gns::model::{Gns, GnsConfig, GnsKernels, GraphBatch, ModelSpec, save_model};
use phi_gns::rollout::input_window;
use phi_gns::train::{
    Adam, AdamConfig, RandomWalkNoise, non_kinematic_mask, random_walk_noise, train_step,
};
use phi_io::npz::{NpyArray, write_npz};
use rand::SeedableRng;
use rand::rngs::StdRng;

#[derive(Parser)]
struct Args {
    /// The dataset directory.
    #[arg(long)]
    data: PathBuf,
    /// The split.
    #[arg(long, default_value = "train")]
    split: String,
    /// An example of the batch, `TRAJECTORY:FRAME` (the latest frame of its input window);
    /// repeat for a batch of several.
    #[arg(long = "example", default_values = ["40:100", "41:100"])]
    examples: Vec<String>,
    /// The backend (one with autodiff).
    #[arg(long, default_value = "burn")]
    backend: BackendKind,
    /// Steps to time.
    #[arg(long, default_value_t = 5)]
    repeats: usize,
    /// Untimed steps first.
    #[arg(long, default_value_t = 1)]
    warmup: usize,
    /// The seed of the weights.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// The seed of the training noise.
    #[arg(long, default_value_t = 0)]
    noise_seed: u64,
    /// The noise's standard deviation at the last input velocity.
    #[arg(long, default_value_t = 6.7e-4)]
    noise_std: f64,
    /// Write the batch, the first step's noise and its loss here (.npz).
    #[arg(long)]
    write_input: Option<PathBuf>,
    /// Write the initial model directory here.
    #[arg(long)]
    write_model: Option<PathBuf>,
}

/// One example of the batch: its clean input window, next positions and particle types.
struct Example {
    window: Vec<f32>,
    next: Vec<f32>,
    types: Vec<i64>,
}

/// Peak resident set size of this process in MiB (Linux `VmHWM`).
fn peak_rss_mib() -> Option<f64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kib: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib / 1024.0)
}

/// `TRAJECTORY:FRAME` of the dataset's split as an example with `c` input velocities.
fn read_example(args: &Args, text: &str, c: usize) -> Result<Example> {
    let (index, frame) = text
        .split_once(':')
        .and_then(|(i, f)| Some((i.parse::<usize>().ok()?, f.parse::<usize>().ok()?)))
        .with_context(|| format!("example '{text}' is not TRAJECTORY:FRAME"))?;
    let path = Dataset::trajectory_path(&args.data, &args.split, index);
    let trajectory: Trajectory = read_trajectory(&path)?;
    ensure!(
        frame >= c && frame + 1 < trajectory.frames,
        "frame {frame} of trajectory {index} has no window of {c} velocities and a next frame \
         (frames {c}..{})",
        trajectory.frames - 1
    );
    Ok(Example {
        window: input_window(&trajectory, frame, c),
        next: trajectory.frame(frame + 1).to_vec(),
        types: trajectory.particle_type.clone(),
    })
}

/// The noisy batch of one step: its graph batch, adjusted next positions and noises.
struct NoisyBatch<B: GnsKernels> {
    batch: GraphBatch<B>,
    next: Tensor<B>,
    noises: Vec<RandomWalkNoise>,
}

fn noisy_batch<B: GnsKernels>(
    examples: &[Example],
    spec: &ModelSpec,
    noise_std: f64,
    rng: &mut StdRng,
    device: &B::Device,
) -> Result<NoisyBatch<B>> {
    let (window, dim) = (spec.config.input_velocities + 1, spec.config.dim);
    let mut noisy = Vec::with_capacity(examples.len());
    let mut next = Vec::new();
    let mut noises = Vec::with_capacity(examples.len());
    for example in examples {
        let kinematic = spec.kinematic(&example.types);
        let noise = random_walk_noise(&kinematic, window, dim, noise_std, rng);
        noisy.push(noise.apply(&example.window));
        next.extend(noise.adjust_target(&example.next));
        noises.push(noise);
    }
    let views: Vec<(&[f32], &[i64])> = noisy
        .iter()
        .zip(examples)
        .map(|(w, e)| (&w[..], &e.types[..]))
        .collect();
    let batch = GraphBatch::from_host_batch(&views, spec, device)?;
    let n = next.len() / dim;
    Ok(NoisyBatch {
        batch,
        next: Tensor::from_vec(next, &[n, dim], device)?,
        noises,
    })
}

fn run<B: AutodiffBackend + GnsKernels>(args: &Args) -> Result<()> {
    let dataset = Dataset::open(&args.data)?;
    let metadata = dataset.metadata();
    let config = GnsConfig {
        noise_std: args.noise_std,
        ..GnsConfig::thesis(metadata.dim)
    };
    let spec = ModelSpec::for_dataset(metadata, config, args.seed);
    let c = spec.config.input_velocities;
    let examples = args
        .examples
        .iter()
        .map(|e| read_example(args, e, c))
        .collect::<Result<Vec<_>>>()?;
    let device = B::default_device();
    let mut model = Gns::<B>::init(spec, &device)?;
    if let Some(dir) = &args.write_model {
        save_model(dir, &model)?;
    }
    let spec = model.spec().clone();
    let types: Vec<i64> = examples.iter().flat_map(|e| e.types.clone()).collect();
    let mask = non_kinematic_mask::<B>(&types, &spec.kinematic_types, &device)?;
    let mut adam = Adam::new(AdamConfig::default(), model.params());
    let mut rng = StdRng::seed_from_u64(args.noise_seed);
    let mut times = Vec::with_capacity(args.repeats);
    let mut first: Option<(NoisyBatch<B>, f32)> = None;
    let mut edges = 0;
    for step in 0..args.warmup + args.repeats {
        let start = Instant::now();
        let noisy = noisy_batch::<B>(&examples, &spec, args.noise_std, &mut rng, &device)?;
        let (updated, loss) = train_step(&model, &mut adam, &noisy.batch, &noisy.next, &mask)?;
        model = updated;
        if step >= args.warmup {
            times.push(start.elapsed().as_secs_f64());
        }
        edges = noisy.batch.graph().edges();
        if first.is_none() {
            first = Some((noisy, loss));
        }
    }
    let Some((first, first_loss)) = first else {
        bail!("no step ran (--warmup 0 --repeats 0)");
    };
    times.sort_by(f64::total_cmp);
    let (median, best) = match times.as_slice() {
        [] => (f64::NAN, f64::NAN),
        t => (t[t.len() / 2], t[0]),
    };
    let counts: Vec<String> = examples.iter().map(|e| e.types.len().to_string()).collect();
    println!(
        "{}: batch of {} ({} particles), {edges} edges, {} threads: first loss {first_loss:.6}, \
         step median {median:.3} s, best {best:.3} s, peak RSS {:.0} MiB",
        B::name(),
        examples.len(),
        counts.join(" + "),
        rayon::current_num_threads(),
        peak_rss_mib().unwrap_or(f64::NAN)
    );
    if let Some(out) = &args.write_input {
        write_input(out, &examples, &spec, &first, first_loss)?;
    }
    Ok(())
}

/// The batch for the anchor scripts: clean windows, next positions, types, particles per
/// example, the first step's noise and loss, and the normalisation and bounds of `spec`.
fn write_input<B: GnsKernels>(
    out: &std::path::Path,
    examples: &[Example],
    spec: &ModelSpec,
    first: &NoisyBatch<B>,
    loss: f32,
) -> Result<()> {
    let (window, dim) = (spec.config.input_velocities + 1, spec.config.dim);
    let n: usize = examples.iter().map(|e| e.types.len()).sum();
    let cat = |f: &dyn Fn(&Example) -> &[f32]| -> Vec<f32> {
        examples.iter().flat_map(|e| f(e).iter().copied()).collect()
    };
    let noise: Vec<f32> = first
        .noises
        .iter()
        .flat_map(|z| z.offsets().iter().copied())
        .collect();
    let f64s = |v: &[f64]| NpyArray::new(vec![v.len()], v.to_vec());
    let norm = &spec.normalisation;
    let bounds: Vec<f64> = spec.bounds.iter().flat_map(|b| [b[0], b[1]]).collect();
    let counts: Vec<i64> = examples.iter().map(|e| e.types.len() as i64).collect();
    let (senders, receivers) = (
        first.batch.graph().senders(),
        first.batch.graph().receivers(),
    );
    let arrays = [
        (
            "position",
            NpyArray::new(vec![n, window, dim], cat(&|e| &e.window))?,
        ),
        (
            "next_position",
            NpyArray::new(vec![n, dim], cat(&|e| &e.next))?,
        ),
        ("noise", NpyArray::new(vec![n, window, dim], noise)?),
        (
            "particle_type",
            NpyArray::new(
                vec![n],
                examples
                    .iter()
                    .flat_map(|e| e.types.clone())
                    .collect::<Vec<i64>>(),
            )?,
        ),
        (
            "n_particles_per_example",
            NpyArray::new(vec![counts.len()], counts)?,
        ),
        (
            "kinematic_types",
            NpyArray::new(
                vec![spec.kinematic_types.len()],
                spec.kinematic_types.clone(),
            )?,
        ),
        (
            "senders",
            NpyArray::new(vec![senders.len()], senders.to_vec())?,
        ),
        (
            "receivers",
            NpyArray::new(vec![receivers.len()], receivers.to_vec())?,
        ),
        ("bounds", NpyArray::new(vec![dim, 2], bounds)?),
        (
            "radius",
            NpyArray::new(vec![], vec![spec.config.connectivity_radius])?,
        ),
        (
            "noise_std",
            NpyArray::new(vec![], vec![spec.config.noise_std])?,
        ),
        ("vel_mean", f64s(&norm.vel_mean)?),
        ("vel_std", f64s(&norm.vel_std)?),
        ("acc_mean", f64s(&norm.acc_mean)?),
        ("acc_std", f64s(&norm.acc_std)?),
        ("loss", NpyArray::new(vec![], vec![loss])?),
    ];
    let refs: Vec<(&str, &NpyArray)> = arrays.iter().map(|(k, a)| (*k, a)).collect();
    write_npz(out, &refs).with_context(|| format!("writing {}", out.display()))?;
    Ok(())
}

#[global_allocator]
static ALLOCATOR: phi::allocator::Allocator = phi::allocator::Allocator;

fn main() -> Result<()> {
    phi::allocator::configure();
    let args = Args::parse();
    phi::with_autodiff_backend!(args.backend, B => run::<B>(&args), otherwise => {
        bail!("--backend {} has no autodiff; use burn or tch", args.backend)
    })
}
