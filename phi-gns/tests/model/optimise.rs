//! Adam and the training step: Adam against a host f64 implementation, DeepMind's schedule,
//! Burn and tch agreeing on a training step, a small model overfitting a few windows with the
//! one-step and the two-step loss, and a non-finite gradient or loss refused.

use phi_core::{AutodiffBackend, Backend, Tensor};
use phi_gns::data::OBSTACLE;
use phi_gns::model::{Gns, GnsKernels, GraphBatch};
use phi_gns::train::{
    Adam, AdamConfig, ErrorNorm, LearningRate, multi_step_loss, non_kinematic_mask,
    random_walk_noise, train_step, train_step_with,
};
use rand::SeedableRng;
use rand::rngs::StdRng;

use super::common::{Rng, config, frame_of, host_params, liquid_over_obstacles, spec};

phi_core::backend_tests!(adam_matches_the_host_update);
mod training {
    use super::a_step_refuses_a_loss_that_is_not_one_finite_value;
    phi_core::autodiff_backend_tests!(a_step_refuses_a_loss_that_is_not_one_finite_value);
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
            warmup_steps: 0.0,
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
    let first = current.iter().next().unwrap().0.to_string();
    assert!(
        error.contains("non-finite") && error.contains(&format!("'{first}'")),
        "{error}"
    );
    assert_eq!(adam.step(), 3);
    assert_eq!(host_params(adam.moments().0), before);
    // An infinity in the last parameter's gradient is refused and names that parameter.
    let mut bad: Vec<Tensor<B>> = current.iter().map(|(_, t)| t.zeros_like()).collect();
    let last = bad.len() - 1;
    bad[last] = Tensor::full(&bad[last].shape(), f32::INFINITY, &device);
    let error = adam.update(&current, &bad).unwrap_err().to_string();
    let name = current.iter().last().unwrap().0.to_string();
    assert!(error.contains(&format!("'{name}'")), "{error}");
    assert_eq!(adam.step(), 3);
    // Finite gradients whose squares overflow f32 are not refused: the norm is summed in f64,
    // and clipping brings them to norm 1, so Adam's first step moves each weight by ~lr.
    let clipped = AdamConfig {
        clip_norm: Some(1.0),
        ..config
    };
    let mut adam = Adam::new(clipped, &current);
    let huge: Vec<Tensor<B>> = current
        .iter()
        .map(|(_, t)| Tensor::full(&t.shape(), 1e20, &device))
        .collect();
    let updated = adam.update(&current, &huge).unwrap();
    for ((name, after), before) in host_params(&updated)
        .iter()
        .zip(host_params(&current).values())
    {
        for (a, b) in after.iter().zip(before) {
            let moved = b - a;
            assert!(
                (moved - 1e-2).abs() < 1e-4,
                "{}: '{name}' moved by {moved}, not the learning rate 1e-2",
                B::name()
            );
        }
    }
}

/// A batch of windows of liquid over obstacles, one per seed, with random-walk noise of
/// `noise_std` drawn from `noise_seed`, their targets and true frames.
struct Windows<B: GnsKernels> {
    batch: GraphBatch<B>,
    /// The noise-adjusted next positions `[N, 2]`.
    next: Tensor<B>,
    /// The true frames `t ..= t + 2`, `[N, 3, 2]`.
    truth: Tensor<B>,
    mask: Tensor<B>,
}

fn windows<B: GnsKernels>(
    model: &Gns<B>,
    seeds: &[u64],
    noise_std: f64,
    noise_seed: u64,
) -> Windows<B> {
    let device = B::default_device();
    let mut noise_rng = StdRng::seed_from_u64(noise_seed);
    let (mut noisy, mut next, mut truth, mut types) = (vec![], vec![], vec![], vec![]);
    for (k, &seed) in seeds.iter().enumerate() {
        let mut rng = Rng::new(seed);
        let origin = [0.2 + 0.15 * k as f64, 0.4];
        let scene = liquid_over_obstacles(&mut rng, 4, 4, 4, origin, 6);
        let future = scene.future(3);
        let kinematic: Vec<bool> = scene
            .types
            .iter()
            .map(|t| model.spec().kinematic_types.contains(t))
            .collect();
        let noise = random_walk_noise(&kinematic, 6, 2, noise_std, &mut noise_rng);
        noisy.push(noise.apply(&scene.window));
        next.extend(noise.adjust_target(&frame_of(&future, scene.particles(), 1)));
        truth.extend(future);
        types.push(scene.types);
    }
    let examples: Vec<(&[f32], &[i64])> = noisy
        .iter()
        .zip(&types)
        .map(|(w, t)| (w.as_slice(), t.as_slice()))
        .collect();
    let batch = GraphBatch::<B>::from_host_batch(&examples, model.spec(), &device).unwrap();
    let types: Vec<i64> = types.concat();
    let n = types.len();
    Windows {
        batch,
        next: Tensor::from_vec(next, &[n, 2], &device).unwrap(),
        truth: Tensor::from_vec(truth, &[n, 3, 2], &device).unwrap(),
        mask: non_kinematic_mask::<B>(&types, &[OBSTACLE], &device).unwrap(),
    }
}

/// The losses a training step can take.
#[derive(Debug, Clone, Copy)]
enum Loss {
    /// Equation 5.1.
    OneStep,
    /// Equation 5.2 with one extra step.
    TwoStep,
}

const LOSSES: [Loss; 2] = [Loss::OneStep, Loss::TwoStep];

/// One training step on `loss`.
fn step<B: AutodiffBackend + GnsKernels>(
    model: &Gns<B>,
    adam: &mut Adam<B>,
    w: &Windows<B>,
    loss: Loss,
) -> (Gns<B>, f32) {
    match loss {
        Loss::OneStep => train_step(model, adam, &w.batch, &w.next, &w.mask).unwrap(),
        Loss::TwoStep => train_step_with(model, adam, |m| {
            multi_step_loss(m, &w.batch, &w.next, &w.truth, &w.mask, ErrorNorm::Squared)
        })
        .unwrap(),
    }
}

/// Three windows of 20 particles, whose targets follow from the velocities the model sees
/// (gravity and drag): measured falls of ~2000× (one-step) and ~1000× (two-step) in 150 steps;
/// the bound is 100×. On Burn only (~1.5 s): tch takes the same step (below).
#[test]
fn a_small_model_overfits_a_few_windows() {
    type B = phi_core::backend::burn::Burn;
    let device = <B as Backend>::default_device();
    for which in LOSSES {
        let mut model = Gns::<B>::init(spec(config(16, 16, 2, 1), 4), &device).unwrap();
        let w = windows(&model, &[12, 13, 14], 0.0, 0);
        let config = AdamConfig {
            learning_rate: LearningRate::constant(3e-3),
            ..AdamConfig::default()
        };
        let mut adam = Adam::new(config, model.params());
        let mut losses = Vec::new();
        for _ in 0..150 {
            let (updated, loss) = step(&model, &mut adam, &w, which);
            model = updated;
            losses.push(loss);
        }
        let (first, last) = (losses[0], *losses.last().unwrap());
        assert!(
            last * 100.0 < first,
            "{} ({which:?}): the loss fell from {first} to {last} in 150 steps",
            B::name()
        );
    }
}

/// One training step from the same weights, windows and noise gives the same parameters on
/// Burn and tch, with either loss.
#[cfg(feature = "tch")]
#[test]
fn burn_and_tch_take_the_same_training_step() {
    use phi_core::backend::burn::Burn;
    use phi_core::backend::tch::Tch;
    for which in LOSSES {
        let burn = Gns::<Burn>::init(
            spec(config(12, 10, 2, 2), 9),
            &<Burn as Backend>::default_device(),
        )
        .unwrap();
        let tch = Gns::<Tch>::init(spec(config(12, 10, 2, 2), 9), &Tch::default_device()).unwrap();
        let b_windows = windows(&burn, &[13, 14], 3e-4, 5);
        let t_windows = windows(&tch, &[13, 14], 3e-4, 5);
        let mut b_adam = Adam::new(AdamConfig::default(), burn.params());
        let mut t_adam = Adam::new(AdamConfig::default(), tch.params());
        let (burn, b_loss) = step(&burn, &mut b_adam, &b_windows, which);
        let (tch, t_loss) = step(&tch, &mut t_adam, &t_windows, which);
        assert!(
            (b_loss - t_loss).abs() <= 1e-5 * b_loss.abs(),
            "{which:?}: {b_loss} vs {t_loss}"
        );
        let (b, t): (
            phi_gns::model::Parameters<Burn>,
            phi_gns::model::Parameters<Tch>,
        ) = (burn.params().clone(), tch.params().clone());
        for ((name, x), (_, y)) in host_params(&b).iter().zip(host_params(&t).iter()) {
            for (a, c) in x.iter().zip(y) {
                // The first Adam step moves each parameter by ~lr·sign(g) = 1e-4; the gradients
                // agree to ~1e-6 relative, so the updated values agree far below 1e-4 relative.
                assert!(
                    (a - c).abs() <= 1e-4 * a.abs().max(1e-3),
                    "{which:?}, '{name}': {a} vs {c}"
                );
            }
        }
    }
}

fn a_step_refuses_a_loss_that_is_not_one_finite_value<B: AutodiffBackend + GnsKernels>() {
    let device = B::default_device();
    let model = Gns::<B>::init(spec(config(4, 3, 1, 1), 2), &device).unwrap();
    let mut adam = Adam::new(AdamConfig::default(), model.params());
    let nan = train_step_with(&model, &mut adam, |m| {
        Ok(m.params().get("decoder.1.bias").sum() * f32::NAN)
    });
    assert!(nan.unwrap_err().to_string().contains("NaN"));
    let two = train_step_with(&model, &mut adam, |m| {
        Ok(m.params().get("decoder.1.bias").clone())
    });
    assert!(two.unwrap_err().to_string().contains("one value"));
    assert_eq!(adam.step(), 0, "nothing was updated");
    // A loss of one parameter's sum moves that parameter by lr against its gradient's sign.
    let (updated, value) = train_step_with(&model, &mut adam, |m| {
        Ok(m.params().get("decoder.1.bias").sum())
    })
    .unwrap();
    let before = model.params().get("decoder.1.bias").to_vec();
    assert_eq!(value, before.iter().sum::<f32>());
    for (a, b) in updated
        .params()
        .get("decoder.1.bias")
        .to_vec()
        .iter()
        .zip(&before)
    {
        assert!((a - (b - 1e-4)).abs() < 1e-7, "{a} after {b}");
    }
    assert_eq!(
        updated.params().get("decoder.0.bias").to_vec(),
        model.params().get("decoder.0.bias").to_vec(),
        "a parameter the loss does not depend on stays"
    );
}
