//! The training noise and the one-step loss: the noise's statistics and its target adjustment,
//! the loss against host arithmetic, its mask, and its gradient in the decoder's last bias
//! against the closed form.

use phi_core::{AutodiffBackend, Tensor};
use phi_gns::data::LIQUID;
use phi_gns::data::OBSTACLE;
use phi_gns::model::{Gns, GnsKernels, GraphBatch};
use phi_gns::train::{
    ErrorNorm, non_kinematic_mask, obstacle_weights, one_step_loss, random_walk_noise,
};
use rand::SeedableRng;
use rand::rngs::StdRng;

use super::common::{Rng, config, liquid_over_obstacles, perturbed, spec};

phi_core::backend_tests!(
    loss_is_the_masked_mean_of_squared_errors,
    huber_loss_is_quadratic_inside_delta_and_linear_outside,
    relative_loss_divides_each_error_by_its_target_size,
    a_weighted_mask_makes_the_loss_the_weighted_mean
);
mod gradient {
    use super::{
        loss_gradient_in_the_decoder_bias_is_the_mean_error,
        relative_loss_gradient_is_the_weighted_mean_error,
    };
    phi_core::autodiff_backend_tests!(
        loss_gradient_in_the_decoder_bias_is_the_mean_error,
        relative_loss_gradient_is_the_weighted_mean_error
    );
}

#[test]
fn noise_is_a_random_walk_of_the_stated_std_at_the_last_velocity() {
    let (n, window, dim, sigma) = (20_000, 6, 2, 6.7e-4);
    let kinematic: Vec<bool> = (0..n).map(|i| i % 10 == 0).collect();
    let noise = random_walk_noise(
        &kinematic,
        window,
        dim,
        sigma,
        &mut StdRng::seed_from_u64(3),
    );
    let offsets = noise.offsets();
    let at = |i: usize, t: usize, k: usize| f64::from(offsets[(i * window + t) * dim + k]);
    let mut last = Vec::new();
    let mut first = Vec::new();
    for (i, &fixed) in kinematic.iter().enumerate() {
        for k in 0..dim {
            assert_eq!(at(i, 0, k), 0.0, "the first position is not moved");
            if fixed {
                for t in 0..window {
                    assert_eq!(at(i, t, k), 0.0, "kinematic particle {i} got noise");
                }
            } else {
                last.push(at(i, window - 1, k) - at(i, window - 2, k));
                first.push(at(i, 1, k) - at(i, 0, k));
            }
        }
    }
    let std = |v: &[f64]| {
        let mean = v.iter().sum::<f64>() / v.len() as f64;
        (v.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / v.len() as f64).sqrt()
    };
    // 36,000 samples: the sample std is within ~0.4 % of the true one (1σ), so 3 % cannot fail
    // by chance; a walk that did not accumulate would give σ/√5 at the last velocity.
    let (last_std, first_std) = (std(&last), std(&first));
    assert!(
        (last_std / sigma - 1.0).abs() < 0.03,
        "last velocity std {last_std}"
    );
    let per_step = sigma / 5f64.sqrt();
    assert!(
        (first_std / per_step - 1.0).abs() < 0.03,
        "first velocity std {first_std}"
    );
    // The same seed draws the same noise; another seed other noise.
    let again = random_walk_noise(
        &kinematic,
        window,
        dim,
        sigma,
        &mut StdRng::seed_from_u64(3),
    );
    assert_eq!(again, noise);
    let other = random_walk_noise(
        &kinematic,
        window,
        dim,
        sigma,
        &mut StdRng::seed_from_u64(4),
    );
    assert_ne!(other, noise);
    // No noise at σ = 0.
    let none = random_walk_noise(&kinematic, window, dim, 0.0, &mut StdRng::seed_from_u64(3));
    assert!(none.offsets().iter().all(|&x| x == 0.0));
}

#[test]
fn the_target_moves_by_the_latest_positions_noise() {
    let kinematic = [false, true, false];
    let noise = random_walk_noise(&kinematic, 3, 2, 1e-2, &mut StdRng::seed_from_u64(9));
    let next = [1.0f32, 2.0, 3.0, 4.0, 5.0, 6.0];
    let adjusted = noise.adjust_target(&next);
    let offsets = noise.offsets();
    for i in 0..3 {
        for k in 0..2 {
            let last = offsets[(i * 3 + 2) * 2 + k];
            assert_eq!(adjusted[i * 2 + k], next[i * 2 + k] + last);
        }
    }
    assert_eq!(
        &adjusted[2..4],
        &next[2..4],
        "the kinematic particle's target stays"
    );
    let window = vec![0.5f32; 3 * 3 * 2];
    let noisy = noise.apply(&window);
    assert!(noisy.iter().zip(offsets).all(|(p, o)| *p == 0.5 + o));
}

/// A small model on a block of liquid over obstacles, and a target window one frame on.
struct Problem<B: GnsKernels> {
    model: Gns<B>,
    batch: GraphBatch<B>,
    next: Vec<f32>,
    types: Vec<i64>,
}

fn problem<B: GnsKernels>() -> Problem<B> {
    let device = B::default_device();
    let spec = spec(config(12, 10, 2, 2), 5);
    let model = Gns::<B>::init(spec, &device).expect("a valid spec");
    let params = perturbed(model.params(), 6);
    let model = model.with_params(params).expect("the same layout");
    let mut rng = Rng::new(21);
    let scene = liquid_over_obstacles(&mut rng, 4, 3, 4, [0.4, 0.4], 6);
    let batch = GraphBatch::<B>::from_host(&scene.window, &scene.types, model.spec(), &device)
        .expect("a valid window");
    let n = scene.particles();
    let next: Vec<f32> = (0..n * 2)
        .map(|i| {
            let last = scene.window[(i / 2 * 6 + 5) * 2 + i % 2];
            last + 1e-3 * (rng.uniform() as f32 - 0.5)
        })
        .collect();
    Problem {
        model,
        batch,
        next,
        types: scene.types,
    }
}

fn loss_is_the_masked_mean_of_squared_errors<B: GnsKernels>() {
    let p = problem::<B>();
    let device = B::default_device();
    let n = p.types.len();
    let next = Tensor::<B>::from_vec(p.next.clone(), &[n, 2], &device).unwrap();
    let mask = non_kinematic_mask::<B>(&p.types, &[OBSTACLE], &device).unwrap();
    let loss = one_step_loss(&p.model, &p.batch, &next, &mask, ErrorNorm::Squared).unwrap();
    let predicted = p.model.normalised_acceleration(&p.batch).unwrap().to_vec();
    let target = p
        .model
        .target_acceleration(&p.batch, &next)
        .unwrap()
        .to_vec();
    let (mut sum, mut count) = (0.0f64, 0usize);
    for i in (0..n).filter(|&i| p.types[i] != OBSTACLE) {
        count += 1;
        for k in 0..2 {
            let d = f64::from(predicted[i * 2 + k]) - f64::from(target[i * 2 + k]);
            sum += d * d;
        }
    }
    let expected = sum / count as f64;
    let got = f64::from(loss.to_scalar().unwrap());
    assert!(
        (got - expected).abs() <= 1e-5 * expected,
        "{}: loss {got}, host {expected}",
        B::name()
    );
    // Kinematic particles count for nothing: moving their targets leaves the loss as it is.
    let mut moved = p.next.clone();
    for i in (0..n).filter(|&i| p.types[i] == OBSTACLE) {
        moved[i * 2] += 0.5;
    }
    let moved = Tensor::<B>::from_vec(moved, &[n, 2], &device).unwrap();
    let same = one_step_loss(&p.model, &p.batch, &moved, &mask, ErrorNorm::Squared).unwrap();
    assert_eq!(same.to_scalar().unwrap(), loss.to_scalar().unwrap());
    // A prediction that is its own target has no loss (to the rounding of the round trip
    // through positions).
    let own = p.model.next_positions(&p.batch).unwrap();
    let zero = f64::from(
        one_step_loss(&p.model, &p.batch, &own, &mask, ErrorNorm::Squared)
            .unwrap()
            .to_scalar()
            .unwrap(),
    );
    assert!(
        zero < 1e-3 * expected,
        "{}: own prediction loss {zero} vs {expected}",
        B::name()
    );
    // A batch of only kinematic particles has no loss to average.
    let none = Tensor::<B>::zeros(&[n], &device);
    assert!(one_step_loss(&p.model, &p.batch, &next, &none, ErrorNorm::Squared).is_err());
}

/// [`problem`] with its target as a tensor, the loss mask, the host's predicted and target
/// normalised accelerations and the indices of the particles that count.
struct Scored<B: GnsKernels> {
    p: Problem<B>,
    next: Tensor<B>,
    mask: Tensor<B>,
    predicted: Vec<f32>,
    target: Vec<f32>,
    counted: Vec<usize>,
}

fn scored<B: GnsKernels>() -> Scored<B> {
    let p = problem::<B>();
    let device = B::default_device();
    let n = p.types.len();
    let next = Tensor::<B>::from_vec(p.next.clone(), &[n, 2], &device).unwrap();
    let mask = non_kinematic_mask::<B>(&p.types, &[OBSTACLE], &device).unwrap();
    let predicted = p.model.normalised_acceleration(&p.batch).unwrap().to_vec();
    let target = p
        .model
        .target_acceleration(&p.batch, &next)
        .unwrap()
        .to_vec();
    let counted: Vec<usize> = (0..n).filter(|&i| p.types[i] != OBSTACLE).collect();
    Scored {
        p,
        next,
        mask,
        predicted,
        target,
        counted,
    }
}

impl<B: GnsKernels> Scored<B> {
    /// The one-step loss of the problem under `norm`.
    fn loss(&self, norm: ErrorNorm) -> f64 {
        f64::from(
            one_step_loss(&self.p.model, &self.p.batch, &self.next, &self.mask, norm)
                .unwrap()
                .to_scalar()
                .unwrap(),
        )
    }
}

fn huber_loss_is_quadratic_inside_delta_and_linear_outside<B: GnsKernels>() {
    let s = scored::<B>();
    let mut sizes: Vec<f64> = s
        .counted
        .iter()
        .flat_map(|&i| (0..2).map(move |k| i * 2 + k))
        .map(|j| (f64::from(s.predicted[j]) - f64::from(s.target[j])).abs())
        .collect();
    sizes.sort_by(f64::total_cmp);
    // δ at the median error: half the components on each branch.
    let delta = sizes[sizes.len() / 2];
    let expected = sizes
        .iter()
        .map(|&r| {
            if r <= delta {
                r * r
            } else {
                2.0 * delta * r - delta * delta
            }
        })
        .sum::<f64>()
        / s.counted.len() as f64;
    let huber = ErrorNorm::Huber {
        delta: delta as f32,
    };
    let got = s.loss(huber);
    assert!(
        (got - expected).abs() <= 1e-5 * expected,
        "{}: Huber loss {got}, host {expected}",
        B::name()
    );
    let squared = s.loss(ErrorNorm::Squared);
    assert!(
        got < squared,
        "{}: outliers cost less than squared",
        B::name()
    );
    // A δ above every error is the squared error.
    let wide = ErrorNorm::Huber {
        delta: (sizes[sizes.len() - 1] * 2.0) as f32,
    };
    let same = s.loss(wide);
    assert!((same - squared).abs() <= 1e-6 * squared, "{}", B::name());
}

fn a_weighted_mask_makes_the_loss_the_weighted_mean<B: GnsKernels>() {
    let s = scored::<B>();
    let device = B::default_device();
    let n = s.p.types.len();
    // Weights 1, 2, 3 in turn for the counted particles, 0 for the obstacles.
    let weights: Vec<f32> = (0..n)
        .map(|i| {
            if s.p.types[i] == OBSTACLE {
                0.0
            } else {
                (1 + i % 3) as f32
            }
        })
        .collect();
    let mask = Tensor::<B>::from_vec(weights.clone(), &[n], &device).unwrap();
    let got = f64::from(
        one_step_loss(&s.p.model, &s.p.batch, &s.next, &mask, ErrorNorm::Squared)
            .unwrap()
            .to_scalar()
            .unwrap(),
    );
    let (mut sum, mut total) = (0.0f64, 0.0f64);
    for &i in &s.counted {
        let w = f64::from(weights[i]);
        for k in 0..2 {
            let d = f64::from(s.predicted[i * 2 + k]) - f64::from(s.target[i * 2 + k]);
            sum += w * d * d;
        }
        total += w;
    }
    let expected = sum / total;
    assert!(
        (got - expected).abs() <= 1e-5 * expected,
        "{}: weighted loss {got}, host {expected}",
        B::name()
    );
    assert!(
        (got - s.loss(ErrorNorm::Squared)).abs() > 1e-4 * expected,
        "{}: the weights change the mean",
        B::name()
    );
}

#[test]
fn obstacle_weights_pick_the_counted_particles_within_the_radius_of_an_obstacle() {
    // Along x: an obstacle at 0.5, liquid at 0.5 ± 0.029 (within R = 0.03), at 0.5 + 0.031
    // (beyond), and a second obstacle at 0.7 with liquid 0.02 above it (2D distance).
    let latest = [
        0.5, 0.2, // obstacle
        0.471, 0.2, // liquid, 0.029 away
        0.529, 0.2, // liquid, 0.029 away
        0.531, 0.2, // liquid, 0.031 away
        0.7, 0.2, // obstacle
        0.7, 0.22, // liquid, 0.02 away
        0.9, 0.9, // liquid, far from both
    ];
    let types = [OBSTACLE, LIQUID, LIQUID, LIQUID, OBSTACLE, LIQUID, LIQUID];
    let weights = obstacle_weights(&latest, 2, &types, &[OBSTACLE], 0.03, 4.0);
    assert_eq!(weights, vec![0.0, 4.0, 4.0, 1.0, 0.0, 4.0, 1.0]);
    // Weight 1 is the plain mask of the counted particles.
    let plain = obstacle_weights(&latest, 2, &types, &[OBSTACLE], 0.03, 1.0);
    assert_eq!(plain, vec![0.0, 1.0, 1.0, 1.0, 0.0, 1.0, 1.0]);
    // No kinematic type: nothing is near an obstacle and every particle counts once.
    let none = obstacle_weights(&latest, 2, &types, &[], 0.03, 4.0);
    assert_eq!(none, vec![1.0; 7]);
}

/// The host's relative loss: `Σ_i s² |r_i|² / (|t_i|² + s²)` over the counted particles,
/// divided by their number, and each particle's weight `s² / (|t_i|² + s²)`.
fn host_relative(
    predicted: &[f32],
    target: &[f32],
    counted: &[usize],
    scale: f64,
) -> (f64, Vec<f64>) {
    let floor = scale * scale;
    let mut weights = vec![0.0; predicted.len() / 2];
    let mut sum = 0.0;
    for &i in counted {
        let (mut error, mut size) = (0.0, 0.0);
        for k in 0..2 {
            let t = f64::from(target[i * 2 + k]);
            let r = f64::from(predicted[i * 2 + k]) - t;
            error += r * r;
            size += t * t;
        }
        weights[i] = floor / (size + floor);
        sum += weights[i] * error;
    }
    (sum / counted.len() as f64, weights)
}

fn relative_loss_divides_each_error_by_its_target_size<B: GnsKernels>() {
    let s = scored::<B>();
    // The median target size as the scale: the weights span both sides of ½.
    let mut sizes: Vec<f64> = s
        .counted
        .iter()
        .map(|&i| f64::from(s.target[i * 2]).hypot(f64::from(s.target[i * 2 + 1])))
        .collect();
    sizes.sort_by(f64::total_cmp);
    let scale = sizes[sizes.len() / 2];
    let (expected, weights) = host_relative(&s.predicted, &s.target, &s.counted, scale);
    let lightest = s.counted.iter().map(|&i| weights[i]).fold(1.0, f64::min);
    assert!(lightest < 0.5, "{}: weights down to {lightest}", B::name());
    let got = s.loss(ErrorNorm::Relative {
        scale: scale as f32,
    });
    assert!(
        (got - expected).abs() <= 1e-5 * expected,
        "{}: relative loss {got}, host {expected}",
        B::name()
    );
    // Every weight is below 1: the relative loss is below the squared error, and a scale far
    // above every target is the squared error.
    let squared = s.loss(ErrorNorm::Squared);
    assert!(got < squared, "{}: {got} against {squared}", B::name());
    let wide = s.loss(ErrorNorm::Relative {
        scale: (sizes[sizes.len() - 1] * 1e3) as f32,
    });
    assert!(
        (wide - squared).abs() <= 1e-5 * squared,
        "{}: {wide} against {squared}",
        B::name()
    );
}

fn relative_loss_gradient_is_the_weighted_mean_error<B: GnsKernels + AutodiffBackend>() {
    let scale = 0.5;
    let norm = ErrorNorm::Relative {
        scale: scale as f32,
    };
    decoder_bias_gradient_is_the_weighted_mean_error::<B>(norm, |predicted, target, counted| {
        host_relative(predicted, target, counted, scale).1
    });
}

fn loss_gradient_in_the_decoder_bias_is_the_mean_error<B: GnsKernels + AutodiffBackend>() {
    decoder_bias_gradient_is_the_weighted_mean_error::<B>(ErrorNorm::Squared, |predicted, _, _| {
        vec![1.0; predicted.len() / 2]
    });
}

/// The decoder's last bias adds to every particle's output, so for a loss whose particle `i`
/// scores `w_i |r_i|²` (`w_i` data, from `weights(predicted, target, counted)`), ∂L/∂b_k is
/// (2 / counted) Σ_i w_i (predicted_ik − target_ik) over the counted particles.
fn decoder_bias_gradient_is_the_weighted_mean_error<B: GnsKernels + AutodiffBackend>(
    norm: ErrorNorm,
    weights: impl Fn(&[f32], &[f32], &[usize]) -> Vec<f64>,
) {
    let p = problem::<B>();
    let device = B::default_device();
    let n = p.types.len();
    let leaves = p.model.params().map(|_, t| t.require_grad());
    let model = p.model.with_params(leaves.clone()).unwrap();
    let next = Tensor::<B>::from_vec(p.next.clone(), &[n, 2], &device).unwrap();
    let mask = non_kinematic_mask::<B>(&p.types, &[OBSTACLE], &device).unwrap();
    let predicted = model
        .normalised_acceleration(&p.batch)
        .unwrap()
        .detach()
        .to_vec();
    let target = model.target_acceleration(&p.batch, &next).unwrap().to_vec();
    let counted: Vec<usize> = (0..n).filter(|&i| p.types[i] != OBSTACLE).collect();
    let weights = weights(&predicted, &target, &counted);
    let loss = one_step_loss(&model, &p.batch, &next, &mask, norm).unwrap();
    let bias = leaves.get("decoder.2.bias");
    let gradient = loss.gradients(&[bias]).unwrap()[0].to_vec();
    for k in 0..2 {
        let expected: f64 = counted
            .iter()
            .map(|&i| {
                2.0 * weights[i] * (f64::from(predicted[i * 2 + k]) - f64::from(target[i * 2 + k]))
            })
            .sum::<f64>()
            / counted.len() as f64;
        let got = f64::from(gradient[k]);
        assert!(
            (got - expected).abs() <= 1e-5 * expected.abs().max(1e-3),
            "{}, {norm:?}: ∂L/∂b_{k} = {got}, closed form {expected}",
            B::name()
        );
    }
}
