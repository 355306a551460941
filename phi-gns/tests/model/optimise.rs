//! Adam and the training step: Adam against a host f64 implementation, DeepMind's schedule,
//! Burn and tch agreeing on a training step, a small model overfitting a window, and a
//! non-finite gradient refused.

use phi_core::{AutodiffBackend, Backend, Tensor};
use phi_gns::data::OBSTACLE;
use phi_gns::model::{Gns, GnsKernels, GraphBatch, Parameters};
use phi_gns::train::{Adam, AdamConfig, LearningRate, non_kinematic_mask, train_step};

use super::common::{Rng, config, host_params, liquid_over_obstacles, spec};

phi_core::backend_tests!(adam_matches_the_host_update);
mod training {
    use super::a_small_model_overfits_a_window;
    phi_core::autodiff_backend_tests!(a_small_model_overfits_a_window);
}

#[test]
fn deepmind_schedule() {
    let lr = LearningRate::default();
    assert_eq!(lr.at(0), 1e-4);
    assert!((lr.at(5_000_000) - (0.99e-4 * 0.1 + 1e-6)).abs() < 1e-15);
    assert!((lr.at(20_000_000) - (0.99e-4 * 1e-4 + 1e-6)).abs() < 1e-15);
    assert_eq!(LearningRate::constant(3e-3).at(123_456), 3e-3);
}

fn adam_matches_the_host_update<B: GnsKernels>() {
    let device = B::default_device();
    let model = Gns::<B>::init(spec(config(4, 3, 1, 1), 2), &device).unwrap();
    let params = model.params().clone();
    let config = AdamConfig {
        learning_rate: LearningRate {
            initial: 1e-2,
            final_rate: 1e-3,
            decay_steps: 2.0,
        },
        ..AdamConfig::default()
    };
    let mut adam = Adam::new(config, &params);
    let mut host = host_params(&params);
    let mut m: Vec<Vec<f64>> = host.values().map(|v| vec![0.0; v.len()]).collect();
    let mut v = m.clone();
    let mut rng = Rng::new(8);
    let mut current = params;
    for step in 0..3u64 {
        let gradients: Vec<Tensor<B>> = current
            .iter()
            .map(|(_, t)| {
                let values: Vec<f32> = (0..t.numel())
                    .map(|_| (rng.uniform() - 0.5) as f32)
                    .collect();
                Tensor::from_vec(values, &t.shape(), &device).unwrap()
            })
            .collect();
        let lr = config.learning_rate.at(step);
        let t = (step + 1) as f64;
        for (i, (values, g)) in host.values_mut().zip(&gradients).enumerate() {
            let g = g.to_vec();
            for j in 0..values.len() {
                let gj = f64::from(g[j]);
                m[i][j] = 0.9 * m[i][j] + 0.1 * gj;
                v[i][j] = 0.999 * v[i][j] + 0.001 * gj * gj;
                let m_hat = m[i][j] / (1.0 - 0.9f64.powf(t));
                let v_hat = v[i][j] / (1.0 - 0.999f64.powf(t));
                values[j] -= lr * m_hat / (v_hat.sqrt() + 1e-8);
            }
        }
        current = adam.update(&current, &gradients).unwrap();
        for ((name, got), expected) in host_params(&current).iter().zip(host.values()) {
            for (a, b) in got.iter().zip(expected) {
                // f32 arithmetic on values ~0.5 with steps ~1e-2: a few ulps of 0.5.
                assert!(
                    (a - b).abs() < 1e-6,
                    "{}: step {step}, '{name}': {a} vs {b}",
                    B::name()
                );
            }
        }
    }
    assert_eq!(adam.step(), 3);
    // A non-finite gradient is refused and changes nothing.
    let mut bad: Vec<Tensor<B>> = current.iter().map(|(_, t)| t.zeros_like()).collect();
    bad[0] = Tensor::full(&bad[0].shape(), f32::NAN, &device);
    let before = host_params(adam.moments().0);
    let error = adam.update(&current, &bad).unwrap_err().to_string();
    assert!(error.contains("non-finite"), "{error}");
    assert_eq!(adam.step(), 3);
    assert_eq!(host_params(adam.moments().0), before);
}

/// A batch of one window of liquid over obstacles and random next positions.
fn window<B: GnsKernels>(model: &Gns<B>, seed: u64) -> (GraphBatch<B>, Tensor<B>, Tensor<B>) {
    let device = B::default_device();
    let mut rng = Rng::new(seed);
    let scene = liquid_over_obstacles(&mut rng, 4, 4, 4, [0.4, 0.4], 6);
    let batch =
        GraphBatch::<B>::from_host(&scene.window, &scene.types, model.spec(), &device).unwrap();
    let n = scene.particles();
    let next: Vec<f32> = (0..n * 2)
        .map(|i| scene.window[(i / 2 * 6 + 5) * 2 + i % 2] + 3e-4 * (rng.uniform() as f32 - 0.5))
        .collect();
    let next = Tensor::from_vec(next, &[n, 2], &device).unwrap();
    let mask = non_kinematic_mask::<B>(&scene.types, &[OBSTACLE], &device).unwrap();
    (batch, next, mask)
}

fn a_small_model_overfits_a_window<B: AutodiffBackend + GnsKernels>() {
    let device = B::default_device();
    let mut model = Gns::<B>::init(spec(config(16, 16, 2, 1), 4), &device).unwrap();
    let (batch, next, mask) = window(&model, 12);
    let config = AdamConfig {
        learning_rate: LearningRate::constant(3e-3),
        ..AdamConfig::default()
    };
    let mut adam = Adam::new(config, model.params());
    let mut losses = Vec::new();
    for _ in 0..300 {
        let (updated, loss) = train_step(&model, &mut adam, &batch, &next, &mask).unwrap();
        model = updated;
        losses.push(loss);
    }
    let (first, last) = (losses[0], *losses.last().unwrap());
    assert!(
        last * 100.0 < first,
        "{}: the loss fell from {first} to {last} in 300 steps",
        B::name()
    );
}

/// One training step from the same weights and batch gives the same parameters on Burn and tch.
#[cfg(feature = "tch")]
#[test]
fn burn_and_tch_take_the_same_training_step() {
    use phi_core::backend::burn::Burn;
    use phi_core::backend::tch::Tch;
    let burn = Gns::<Burn>::init(
        spec(config(12, 10, 2, 2), 9),
        &<Burn as Backend>::default_device(),
    )
    .unwrap();
    let tch = Gns::<Tch>::init(spec(config(12, 10, 2, 2), 9), &Tch::default_device()).unwrap();
    let (b_batch, b_next, b_mask) = window(&burn, 13);
    let (t_batch, t_next, t_mask) = window(&tch, 13);
    let mut b_adam = Adam::new(AdamConfig::default(), burn.params());
    let mut t_adam = Adam::new(AdamConfig::default(), tch.params());
    let (burn, b_loss) = train_step(&burn, &mut b_adam, &b_batch, &b_next, &b_mask).unwrap();
    let (tch, t_loss) = train_step(&tch, &mut t_adam, &t_batch, &t_next, &t_mask).unwrap();
    assert!(
        (b_loss - t_loss).abs() <= 1e-5 * b_loss.abs(),
        "{b_loss} vs {t_loss}"
    );
    let (b, t): (Parameters<Burn>, Parameters<Tch>) = (burn.params().clone(), tch.params().clone());
    for ((name, x), (_, y)) in host_params(&b).iter().zip(host_params(&t).iter()) {
        for (a, c) in x.iter().zip(y) {
            // The first Adam step moves each parameter by ~lr·sign(g) = 1e-4; the gradients
            // agree to ~1e-6 relative, so the updated values agree far below 1e-4 relative.
            assert!(
                (a - c).abs() <= 1e-4 * a.abs().max(1e-3),
                "'{name}': {a} vs {c}"
            );
        }
    }
}
