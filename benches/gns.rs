//! GNS inference per backend on a dataset frame: one step (radius graph, forward pass,
//! integration) with the thesis's sizes (10 message-passing steps, latent and hidden 128,
//! embedding 16) and seeded random weights, the forward pass alone, and the radius graph alone;
//! and per autodiff backend one training step on a batch of two windows (the one-step loss, its
//! gradients and Adam's update).
//!
//! The frame is frame 100 of training trajectory 40 of the dataset with seed 0 (1,069 particles,
//! 1,008 of them liquid, ~27k edges at R = 0.03); the bench simulates that one trajectory first
//! (a few seconds). The training batch is the windows ending at frames 99 and 98 of the same
//! trajectory with frames 100 and 99 as targets (~54k edges), without noise so that every
//! iteration sees the same graphs. Compare with geoelements/gns on the same input
//! (docs/benchmarks.md).
//!
//! `cargo bench --bench gns --features tch -- --noplot`; single-threaded numbers with
//! `RAYON_NUM_THREADS=1 OMP_NUM_THREADS=1`.

mod common;

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use phi_dataset::{GenerateOptions, Shard, Split, generate};
use phi_flip::RandomSceneParams;
use phi_gns::data::{Metadata, Trajectory, TrajectoryStats, read_trajectory, trajectory_file_name};
use phi_gns::graph::RadiusGraph;
use phi_gns::model::{Gns, GnsConfig, GnsKernels, GraphBatch, ModelSpec};
use phi_gns::rollout::input_window;
use phi_gns::train::{Adam, AdamConfig, non_kinematic_mask, train_step};

const INDEX: usize = 40;
const FRAME: usize = 100;

/// Training trajectory [`INDEX`] of the seed-0 dataset, simulated to frame [`FRAME`].
fn trajectory() -> Trajectory {
    let out = std::env::temp_dir().join(format!("phi-bench-gns-{}", std::process::id()));
    let params = RandomSceneParams {
        steps: FRAME,
        ..RandomSceneParams::default()
    };
    let options = GenerateOptions {
        splits: vec![Split::Train],
        trajectories: Some(INDEX + 1),
        params,
        shard: Shard {
            index: INDEX,
            count: INDEX + 1,
        },
        ..GenerateOptions::new(&out)
    };
    generate(&options, |_| std::ops::ControlFlow::Continue(()))
        .expect("the bench trajectory simulates");
    let path = out.join("train").join(trajectory_file_name(INDEX));
    let trajectory = read_trajectory(&path).expect("the bench trajectory reads back");
    std::fs::remove_dir_all(&out).ok();
    trajectory
}

/// The model spec: the thesis's sizes and the trajectory's own statistics.
fn spec(trajectory: &Trajectory) -> ModelSpec {
    let mut metadata = Metadata::new(trajectory.dim);
    metadata
        .set_statistics(&TrajectoryStats::of(trajectory))
        .expect("statistics of the trajectory's dimension");
    ModelSpec::for_dataset(&metadata, GnsConfig::thesis(trajectory.dim), 0)
}

fn bench_backend<B: GnsKernels>(c: &mut Criterion, trajectory: &Trajectory) {
    let device = B::default_device();
    let model = Gns::<B>::init(spec(trajectory), &device).expect("a valid spec");
    let window = input_window(trajectory, FRAME, model.spec().config.input_velocities);
    let types = &trajectory.particle_type;
    c.bench_with_input(BenchmarkId::new("gns step", B::name()), &(), |b, _| {
        b.iter(|| {
            let batch = GraphBatch::<B>::from_host(&window, types, model.spec(), &device)
                .expect("a valid window");
            common::force(&model.next_positions(&batch).expect("a forward pass"))
        })
    });
    let batch =
        GraphBatch::<B>::from_host(&window, types, model.spec(), &device).expect("a valid window");
    c.bench_with_input(BenchmarkId::new("gns forward", B::name()), &(), |b, _| {
        b.iter(|| {
            common::force(
                &model
                    .normalised_acceleration(&batch)
                    .expect("a forward pass"),
            )
        })
    });
}

fn bench_training<B: phi_core::AutodiffBackend + GnsKernels>(
    c: &mut Criterion,
    trajectory: &Trajectory,
) {
    let device = B::default_device();
    let model = Gns::<B>::init(spec(trajectory), &device).expect("a valid spec");
    let inputs = model.spec().config.input_velocities;
    let windows = [FRAME - 1, FRAME - 2].map(|t| input_window(trajectory, t, inputs));
    let types = &trajectory.particle_type;
    let examples: Vec<(&[f32], &[i64])> = windows.iter().map(|w| (&w[..], &types[..])).collect();
    let batch =
        GraphBatch::<B>::from_host_batch(&examples, model.spec(), &device).expect("valid windows");
    let next: Vec<f32> = [FRAME, FRAME - 1]
        .iter()
        .flat_map(|&t| trajectory.frame(t).iter().copied())
        .collect();
    let n = next.len() / trajectory.dim;
    let next = phi_core::Tensor::from_vec(next, &[n, trajectory.dim], &device).expect("[N, dim]");
    let all_types: Vec<i64> = types.iter().chain(types).copied().collect();
    let mask = non_kinematic_mask::<B>(&all_types, &model.spec().kinematic_types, &device)
        .expect("a mask");
    let mut adam = Adam::new(AdamConfig::default(), model.params());
    c.bench_with_input(
        BenchmarkId::new("gns train step", B::name()),
        &(),
        |b, _| {
            b.iter(|| {
                let (updated, loss) =
                    train_step(&model, &mut adam, &batch, &next, &mask).expect("a training step");
                std::hint::black_box((updated, loss))
            })
        },
    );
}

fn benches(c: &mut Criterion) {
    let trajectory = trajectory();
    let latest = trajectory.frame(FRAME).to_vec();
    let liquid = trajectory.liquid_particles();
    let edges = RadiusGraph::for_positions(&latest, trajectory.dim, 0.03)
        .expect("finite positions")
        .edges();
    eprintln!(
        "frame {FRAME} of train/{INDEX}: {} particles ({liquid} liquid), {edges} edges",
        trajectory.particles
    );
    c.bench_function("radius graph", |b| {
        b.iter(|| {
            RadiusGraph::for_positions(&latest, trajectory.dim, 0.03)
                .expect("finite positions")
                .edges()
        })
    });
    phi_core::for_each_backend!(B => bench_backend::<B>(c, &trajectory));
    phi_core::for_each_autodiff_backend!(B => bench_training::<B>(c, &trajectory));
}

criterion_group! {
    name = gns;
    config = Criterion::default().sample_size(10).measurement_time(std::time::Duration::from_secs(5));
    targets = benches
}
criterion_main!(gns);
