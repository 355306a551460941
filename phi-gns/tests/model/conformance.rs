//! Every backend against the f64 host reference (`reference.rs`): the seeded initial weights,
//! the normalised accelerations of the thesis' model size (latent 128, 10 message-passing steps)
//! on a realistic particle arrangement, and the integration around the network.
//!
//! # Tolerance
//! The backends compute in f32. LayerNorm after every MLP keeps the latents O(1), and the
//! residual steps add errors rather than multiply them, so after ten steps the outputs differ
//! from the f64 reference by ~1e-6 of their largest value (measured: 6e-7 to 7e-7 on the three
//! backends); the assertion is `1e-4` of the largest value, which a wrong layout, a missing
//! residual or a transposed weight exceeds by orders of magnitude.

use std::sync::OnceLock;

use phi_core::backend::Host;
use phi_gns::model::{Gns, GnsKernels, GraphBatch, Init, Parameters, parameter_layout};

use crate::common::{self, Rng, Scene, assert_close, bits, liquid_over_obstacles, perturbed};
use crate::reference::{Edges, HostGns};

phi_core::backend_tests!(
    initial_parameters_are_the_same_on_every_backend,
    ten_message_passing_steps_match_the_host_reference,
    next_positions_and_targets_follow_the_acceleration,
    a_longer_boundary_horizon_scales_the_wall_distances,
);

/// The model of the conformance test: the thesis' sizes, LayerNorms moved off ones and zeros.
fn thesis_model<B: GnsKernels>() -> Gns<B> {
    let mut config = common::config(128, 128, 2, 10);
    // Training noise widens the velocity normalisation: √(vel_std² + σ²).
    config.noise_std = 4e-4;
    let spec = common::spec(config, 11);
    let device = B::default_device();
    let params = perturbed(&Parameters::init(&spec.config, spec.seed, &device), 5);
    Gns::new(spec, params).unwrap()
}

/// 42 liquid particles (7 × 6 at spacing 0.01) above a row of 10 obstacle particles near the
/// lower-left corner of the domain, so that some boundary features lie inside `(−1, 1)`.
fn thesis_scene() -> Scene {
    liquid_over_obstacles(&mut Rng::new(3), 7, 6, 10, [0.105, 0.13], 6)
}

fn initial_parameters_are_the_same_on_every_backend<B: GnsKernels>() {
    let config = common::config(16, 12, 2, 2);
    let params = Parameters::<B>::init(&config, 42, &B::default_device());
    let host = Parameters::<Host>::init(&config, 42, &Default::default());
    let layout = parameter_layout(&config);
    assert_eq!(params.len(), layout.len());
    for spec in &layout {
        let values = params.get(&spec.name).to_vec();
        assert_eq!(params.get(&spec.name).shape(), spec.shape, "{}", spec.name);
        assert_eq!(
            bits(&values),
            bits(&host.get(&spec.name).to_vec()),
            "{} on {}",
            spec.name,
            B::name()
        );
        match spec.init {
            Init::Uniform(bound) => {
                // PyTorch's nn.Linear: weight and bias both U(±1/√fan_in).
                let weight = format!("{}.weight", spec.name.rsplit_once('.').unwrap().0);
                let fan_in = params.get(&weight).shape()[1];
                assert_eq!(bound, 1.0 / (fan_in as f32).sqrt(), "{}", spec.name);
                assert!(values.iter().all(|v| v.abs() <= bound), "{}", spec.name);
                // Large enough tensors fill the interval around zero: a mean within 3.5
                // standard deviations (bound / √(3n)) of 0, a largest entry above bound / 2.
                if values.len() >= 64 {
                    let (mean, _) = moments(&values);
                    let largest = values.iter().fold(0f32, |m, v| m.max(v.abs()));
                    assert!(mean.abs() < 3.5 * bound / (3.0 * values.len() as f32).sqrt());
                    assert!(largest > bound / 2.0, "{}", spec.name);
                }
            }
            Init::Normal => {
                // Standard normal: the 32 entries' mean within 4 / √32 of 0, their standard
                // deviation within 40% of 1.
                let (mean, std) = moments(&values);
                assert!(
                    mean.abs() < 4.0 / (values.len() as f32).sqrt(),
                    "{}",
                    spec.name
                );
                assert!((std - 1.0).abs() < 0.4, "{}: std {std}", spec.name);
            }
            Init::Ones => assert!(values.iter().all(|&v| v == 1.0), "{}", spec.name),
            Init::Zeros => assert!(values.iter().all(|&v| v == 0.0), "{}", spec.name),
        }
    }
    // Another seed gives other weights.
    let other = Parameters::<B>::init(&config, 43, &B::default_device());
    assert_ne!(
        other.get("decoder.0.weight").to_vec(),
        params.get("decoder.0.weight").to_vec()
    );
}

/// The mean and the standard deviation of `values`.
fn moments(values: &[f32]) -> (f32, f32) {
    let n = values.len() as f32;
    let mean = values.iter().sum::<f32>() / n;
    let var = values.iter().map(|v| (v - mean) * (v - mean)).sum::<f32>() / n;
    (mean, var.sqrt())
}

/// The host reference's normalised accelerations of the thesis model on the thesis scene,
/// computed once for all backends (the weights are the same on every backend, tested above).
fn thesis_reference() -> &'static (Vec<i64>, Vec<i64>, Vec<f64>) {
    static REFERENCE: OnceLock<(Vec<i64>, Vec<i64>, Vec<f64>)> = OnceLock::new();
    REFERENCE.get_or_init(|| {
        let model = thesis_model::<Host>();
        let scene = thesis_scene();
        let batch = GraphBatch::<Host>::from_host(
            &scene.window,
            &scene.types,
            model.spec(),
            &Default::default(),
        )
        .unwrap();
        let graph = batch.graph();
        let host = HostGns::new(model.spec(), model.params());
        let edges = Edges {
            senders: graph.senders(),
            receivers: graph.receivers(),
        };
        let expected = host.normalised_acceleration(&scene.window_f64(), &scene.types, edges);
        (
            graph.senders().to_vec(),
            graph.receivers().to_vec(),
            expected,
        )
    })
}

fn ten_message_passing_steps_match_the_host_reference<B: GnsKernels>() {
    let model = thesis_model::<B>();
    let scene = thesis_scene();
    let batch = GraphBatch::from_host(
        &scene.window,
        &scene.types,
        model.spec(),
        &B::default_device(),
    )
    .unwrap();
    let (senders, receivers, expected) = thesis_reference();
    assert_eq!(batch.graph().senders(), senders.as_slice());
    assert_eq!(batch.graph().receivers(), receivers.as_slice());

    // The arrangement exercises what it should: both types, a dense neighbourhood, boundary
    // features that are not clipped.
    let n = scene.particles();
    assert!(scene.types.contains(&0) && scene.types.contains(&1));
    assert!(
        senders.len() > 10 * n,
        "{} edges for {n} particles",
        senders.len()
    );
    let host = HostGns::new(model.spec(), model.params());
    let features = host.node_features(&scene.window_f64(), &scene.types);
    let width = model.spec().config.node_features();
    let boundary: Vec<f64> = features
        .chunks_exact(width)
        .flat_map(|row| row[10..14].to_vec())
        .collect();
    assert!(
        boundary.iter().any(|d| d.abs() < 0.9),
        "no unclipped boundary feature"
    );

    let got = model.normalised_acceleration(&batch).unwrap();
    assert_eq!(got.shape(), vec![n, 2]);
    assert_close(
        &got.to_vec(),
        expected,
        1e-4,
        &format!("normalised acceleration on {}", B::name()),
    );
}

fn next_positions_and_targets_follow_the_acceleration<B: GnsKernels>() {
    let device = B::default_device();
    let mut config = common::config(16, 16, 2, 2);
    config.noise_std = 5e-5;
    let spec = common::spec(config, 9);
    let model = Gns::new(
        spec.clone(),
        perturbed(&Parameters::init(&spec.config, 9, &device), 1),
    )
    .unwrap();
    let scene = liquid_over_obstacles(&mut Rng::new(8), 3, 3, 3, [0.3, 0.4], 6);
    let n = scene.particles();
    let batch = GraphBatch::from_host(&scene.window, &scene.types, &spec, &device).unwrap();
    let normalised: Vec<f64> = model
        .normalised_acceleration(&batch)
        .unwrap()
        .to_vec()
        .into_iter()
        .map(f64::from)
        .collect();
    let norm = &spec.normalisation;
    // The acceleration's scale widened by the training noise: √(acc_std² + σ²).
    let acc_scale: Vec<f64> = norm
        .acc_std
        .iter()
        .map(|s| (s * s + 5e-5 * 5e-5_f64).sqrt())
        .collect();
    let window = scene.window_f64();
    let frame = |i: usize, t: usize, a: usize| window[(i * 6 + t) * 2 + a];

    // a = â · acc_scale + acc_mean, p_{t+1} = p_t + (p_t − p_{t−1}) + a.
    let acceleration: Vec<f64> = normalised
        .iter()
        .enumerate()
        .map(|(k, x)| x * acc_scale[k % 2] + norm.acc_mean[k % 2])
        .collect();
    let got = model.acceleration(&batch).unwrap().to_vec();
    assert_close(&got, &acceleration, 1e-6, "acceleration");
    let next: Vec<f64> = (0..n * 2)
        .map(|k| {
            let (i, a) = (k / 2, k % 2);
            2.0 * frame(i, 5, a) - frame(i, 4, a) + acceleration[k]
        })
        .collect();
    let got = model.next_positions(&batch).unwrap();
    assert_eq!(got.shape(), vec![n, 2]);
    // Three f32 roundings of values up to twice the largest position.
    let eps = f64::from(f32::EPSILON);
    assert_close(&got.to_vec(), &next, 4.0 * eps, "next positions");

    // The training target of the predicted positions is the prediction again, up to the
    // rounding of the f32 positions it is recovered from: p_{t+1} − 2 p_t + p_{t−1} of
    // positions up to ~0.4 (ulp 3e-8) carries about one ulp of the largest over the smallest
    // acc_std (0.8e-4), ~4e-4 in normalised units, all that f32 positions resolve of an
    // acceleration; the bound is two such ulps.
    let target = model.target_acceleration(&batch, &got).unwrap().to_vec();
    let roundoff = 2.0 * common::max_abs(&next) * eps / 0.8e-4;
    let tolerance = roundoff / common::max_abs(&normalised);
    assert_close(&target, &normalised, tolerance, "target of the prediction");
    // And of an arbitrary next frame, in f64: (p_{t+1} − 2 p_t + p_{t−1} − mean) / scale.
    let mut rng = Rng::new(4);
    let next: Vec<f32> = (0..n * 2)
        .map(|k| {
            (2.0 * frame(k / 2, 5, k % 2) - frame(k / 2, 4, k % 2) + 3e-4 * (rng.uniform() - 0.5))
                as f32
        })
        .collect();
    let expected: Vec<f64> = next
        .iter()
        .enumerate()
        .map(|(k, &x)| {
            let (i, a) = (k / 2, k % 2);
            (f64::from(x) - 2.0 * frame(i, 5, a) + frame(i, 4, a) - norm.acc_mean[a]) / acc_scale[a]
        })
        .collect();
    let next = phi_core::Tensor::<B>::from_vec(next, &[n, 2], &device).unwrap();
    let target = model.target_acceleration(&batch, &next).unwrap().to_vec();
    let tolerance = roundoff / common::max_abs(&expected);
    assert_close(&target, &expected, tolerance, "target of a given frame");
}

/// With `boundary_horizon = h` a node reads its distance to a wall divided by `h · R` and
/// clipped to `[−1, 1]`: the host reference with the same horizon agrees with every backend, the
/// features of particles between `R` and `h · R` from a wall lie inside `(−1, 1)` where the
/// default horizon clips them, and the same weights then predict something else.
fn a_longer_boundary_horizon_scales_the_wall_distances<B: GnsKernels>() {
    let device = B::default_device();
    let mut config = common::config(16, 12, 2, 2);
    let unit = common::spec(config.clone(), 5);
    config.boundary_horizon = 4.0;
    let spec = common::spec(config, 5);
    let params = perturbed(&Parameters::<B>::init(&spec.config, spec.seed, &device), 5);
    let model = Gns::new(spec, params.clone()).unwrap();
    let default = Gns::new(unit, params).unwrap();
    // A block from 1.5 R to about 3 R above the floor and right of the left wall.
    let scene = liquid_over_obstacles(&mut Rng::new(9), 6, 6, 4, [0.145, 0.145], 6);
    let batch = GraphBatch::from_host(&scene.window, &scene.types, model.spec(), &device).unwrap();

    let r = model.spec().config.connectivity_radius;
    let frames = model.spec().config.input_velocities + 1;
    let host = HostGns::new(model.spec(), model.params());
    let features = host.node_features(&scene.window_f64(), &scene.types);
    let width = model.spec().config.node_features();
    let mut inside = 0;
    for (i, row) in features.chunks_exact(width).enumerate() {
        for a in 0..2 {
            let latest = scene.window_f64()[(i * frames + frames - 1) * 2 + a];
            let expected = ((latest - 0.1) / (4.0 * r)).clamp(-1.0, 1.0);
            assert!(
                (row[10 + a] - expected).abs() < 1e-12,
                "particle {i} axis {a}"
            );
            if (latest - 0.1) > r && expected < 1.0 {
                inside += 1;
            }
        }
    }
    assert!(inside > 10, "only {inside} features between R and 4 R");

    let edges = Edges {
        senders: batch.graph().senders(),
        receivers: batch.graph().receivers(),
    };
    let expected = host.normalised_acceleration(&scene.window_f64(), &scene.types, edges);
    let got = model.normalised_acceleration(&batch).unwrap().to_vec();
    assert_close(
        &got,
        &expected,
        1e-4,
        &format!("horizon 4 on {}", B::name()),
    );
    let other = default.normalised_acceleration(&batch).unwrap().to_vec();
    let differs = got
        .iter()
        .zip(&other)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0f32, f32::max);
    assert!(differs > 1e-3, "horizon 4 and 1 predict alike ({differs})");
}
