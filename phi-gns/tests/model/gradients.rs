//! Gradients of a one-step loss on the autodiff backends (Burn and libtorch) with respect to
//! every parameter and to the input positions, against central finite differences, against
//! exact maths where there is some, and Burn against libtorch.
//!
//! The loss is DeepMind's one-step training loss: `L = Σ_i w_i Σ_a (â_ia − t_ia)²`, the squared
//! error of the normalised acceleration against a fixed target, summed over the axes and
//! averaged over the non-kinematic particles (`w_i = 1 / #liquid` for liquid particles and 0 for
//! obstacles, the kinematic type). The model is tiny (latent 12, hidden 10, so that a
//! transposed hidden/latent pair shows, 2 hidden layers, 2 message-passing steps) on 16
//! particles with every LayerNorm moved off ones and zeros.
//!
//! # Tolerances
//! - **Against the f64 host reference** (`reference.rs`): for each parameter tensor, the
//!   directional derivative `g · d` along a seeded random direction `d` (entries in `[−1, 1)`)
//!   against the central difference of the *f64* reference with step `h = 1e-6`. In f64 that
//!   difference is accurate to ~1e-9 (truncation `h² L‴ ~ 1e-12`, round-off `1e-16 / h`), and
//!   a step that moves the O(0.1–1) pre-activations by ~1e-6 almost never crosses a ReLU kink,
//!   so the comparison measures the f32 autodiff gradient itself. Its error is f32 rounding
//!   through a few dozen layers: measured at most 4e-7 of `Σ_k |g_k d_k|`; the bound is `1e-5`
//!   of it, which still catches a single wrong element in a tensor of a hundred.
//! - **Against finite differences of the backend itself** (f32, all parameters at once along
//!   three random directions): the loss is O(1) with f32 round-off ~1e-7, so the quotient's
//!   round-off is ~`1e-7 / h` of it; a larger step moves every pre-activation by ~`h · fan_in`
//!   and crosses ReLU kinks, where the piecewise-linear network's difference quotient stops
//!   being its derivative (measured: 1–3% error at `h = 1e-3`, 0.5–2.4% at `3e-4`, 2–3e-4 at
//!   `1e-4`). `h = 1e-4`; the bound is `5e-3` of `|g · d|`.
//! - **Positions**: along three random directions of the whole window `[N, C + 1, dim]`,
//!   against the f64 host's central difference with `h = 1e-8` in position units (the features
//!   scale positions by `1 / vel_std ~ 1e3` and `1 / R ~ 33`, so the step is ~1e-5 in feature
//!   units, far from any clip or kink); measured at most 4e-8 of `Σ_k |g_k d_k|`, bound `1e-5`
//!   of it.
//! - **Burn against libtorch**: the same f32 graph with different kernels and summation orders:
//!   every gradient tensor within `1e-5` of its largest entry (measured at most ~1e-6).

use phi_core::backend::Host;
use phi_core::{AutodiffBackend, Backend, Tensor};
use phi_gns::model::{Gns, GnsKernels, GraphBatch, ModelSpec, Parameters};

use crate::common::{self, Rng, Scene, liquid_over_obstacles, perturbed};
use crate::reference::{self, Edges, HostGns};

phi_core::autodiff_backend_tests!(
    parameter_gradients_match_finite_differences_of_the_host_reference,
    parameter_gradients_match_finite_differences_of_the_backend,
    position_gradients_are_finite_and_match_finite_differences,
);

/// The loss's inputs.
struct Problem {
    spec: ModelSpec,
    scene: Scene,
    /// `[N, dim]`.
    target: Vec<f32>,
    /// `[N]`: `1 / #non-kinematic` or 0.
    weights: Vec<f32>,
    /// The radius graph of the scene.
    senders: Vec<i64>,
    receivers: Vec<i64>,
}

const SEED: u64 = 21;
const PERTURBATION_SEED: u64 = 2;

fn problem() -> Problem {
    let mut config = common::config(12, 10, 2, 2);
    config.embedding_size = 3;
    let spec = common::spec(config, SEED);
    let scene = liquid_over_obstacles(&mut Rng::new(6), 4, 3, 4, [0.105, 0.125], 6);
    let mut rng = Rng::new(7);
    let target = (0..scene.particles() * 2)
        .map(|_| (2.0 * rng.uniform() - 1.0) as f32)
        .collect();
    let kinematic: Vec<bool> = scene
        .types
        .iter()
        .map(|t| spec.kinematic_types.contains(t))
        .collect();
    let free = kinematic.iter().filter(|k| !**k).count();
    assert!(
        free > 0 && free < scene.particles(),
        "both kinds of particle"
    );
    let weights = kinematic
        .iter()
        .map(|&k| if k { 0.0 } else { 1.0 / free as f32 })
        .collect();
    let batch =
        GraphBatch::<Host>::from_host(&scene.window, &scene.types, &spec, &Default::default())
            .unwrap();
    Problem {
        senders: batch.graph().senders().to_vec(),
        receivers: batch.graph().receivers().to_vec(),
        spec,
        scene,
        target,
        weights,
    }
}

impl Problem {
    /// The parameters of the problem on `B`: seeded, LayerNorms perturbed.
    fn params<B: Backend>(&self) -> Parameters<B> {
        let device = B::default_device();
        let init = Parameters::init(&self.spec.config, self.spec.seed, &device);
        perturbed(&init, PERTURBATION_SEED)
    }

    fn host(&self) -> HostGns {
        HostGns::new(&self.spec, &self.params::<Host>())
    }

    fn edges(&self) -> Edges<'_> {
        Edges {
            senders: &self.senders,
            receivers: &self.receivers,
        }
    }

    fn target_f64(&self) -> Vec<f64> {
        self.target.iter().map(|&x| f64::from(x)).collect()
    }

    fn weights_f64(&self) -> Vec<f64> {
        self.weights.iter().map(|&x| f64::from(x)).collect()
    }

    /// The host's loss for a window and parameters.
    fn host_loss(&self, host: &HostGns, window: &[f64]) -> f64 {
        let acceleration = host.normalised_acceleration(window, &self.scene.types, self.edges());
        reference::loss(&acceleration, &self.target_f64(), &self.weights_f64(), 2)
    }

    /// The backend's loss tensor for a model and a batch.
    fn loss<B: GnsKernels>(&self, model: &Gns<B>, batch: &GraphBatch<B>) -> Tensor<B> {
        let device = B::default_device();
        let n = self.scene.particles();
        let target = Tensor::<B>::from_vec(self.target.clone(), &[n, 2], &device).unwrap();
        let weights = Tensor::<B>::from_vec(self.weights.clone(), &[n, 1], &device).unwrap();
        let acceleration = model.normalised_acceleration(batch).unwrap();
        ((acceleration - target).square() * weights).sum()
    }

    /// The backend's loss (no gradients) with parameters `params`.
    fn loss_value<B: GnsKernels>(&self, params: Parameters<B>) -> f64 {
        let model = Gns::new(self.spec.clone(), params).unwrap();
        let batch = GraphBatch::from_host(
            &self.scene.window,
            &self.scene.types,
            &self.spec,
            &B::default_device(),
        )
        .unwrap();
        f64::from(self.loss(&model, &batch).to_scalar().unwrap())
    }
}

/// The gradients of the loss on one backend.
struct Gradients {
    /// Parameter names, in name order, with their gradients.
    params: Vec<(String, Vec<f32>)>,
    /// `∂L/∂positions`, `[N, C + 1, dim]`.
    positions: Vec<f32>,
    loss: f32,
    /// The normalised acceleration `[N, dim]` of the forward pass.
    acceleration: Vec<f32>,
}

fn gradients<B: AutodiffBackend + GnsKernels>(problem: &Problem) -> Gradients {
    let device = B::default_device();
    let leaves = problem.params::<B>().map(|_, t| t.require_grad());
    let model = Gns::new(problem.spec.clone(), leaves.clone()).unwrap();
    let batch = GraphBatch::from_host(
        &problem.scene.window,
        &problem.scene.types,
        &problem.spec,
        &device,
    )
    .unwrap();
    let positions = batch.positions().require_grad();
    let batch = batch.with_positions(positions.clone()).unwrap();
    let acceleration = model.normalised_acceleration(&batch).unwrap().to_vec();
    let loss = problem.loss(&model, &batch);
    let mut wrt: Vec<&Tensor<B>> = leaves.iter().map(|(_, t)| t).collect();
    wrt.push(&positions);
    let mut grads = loss.gradients(&wrt).unwrap();
    let positions = grads.pop().unwrap().to_vec();
    let params = leaves
        .iter()
        .zip(grads)
        .map(|((name, leaf), g)| {
            assert_eq!(g.shape(), leaf.shape(), "{name}");
            (name.to_string(), g.to_vec())
        })
        .collect();
    Gradients {
        params,
        positions,
        loss: loss.to_scalar().unwrap(),
        acceleration,
    }
}

/// `n` entries uniform in `[−1, 1)`.
fn direction(rng: &mut Rng, n: usize) -> Vec<f64> {
    (0..n).map(|_| 2.0 * rng.uniform() - 1.0).collect()
}

/// `(g · d, Σ |g_k d_k|)`.
fn directional(g: &[f32], d: &[f64]) -> (f64, f64) {
    g.iter().zip(d).fold((0.0, 0.0), |(s, a), (g, d)| {
        let t = f64::from(*g) * d;
        (s + t, a + t.abs())
    })
}

fn parameter_gradients_match_finite_differences_of_the_host_reference<
    B: AutodiffBackend + GnsKernels,
>() {
    let problem = problem();
    let grads = gradients::<B>(&problem);
    let host = problem.host();
    let window = problem.scene.window_f64();
    let loss = problem.host_loss(&host, &window);
    assert!(
        (f64::from(grads.loss) - loss).abs() <= 1e-5 * loss,
        "loss {} on {}, {loss} on the host",
        grads.loss,
        B::name()
    );
    assert_eq!(grads.params.len(), host.params.len());

    // The last bias of the decoder enters â linearly with slope one, so its gradient is
    // exactly ∂L/∂b_a = 2 Σ_i w_i (â_ia − t_ia): no finite differences needed.
    let last = format!("decoder.{}.bias", problem.spec.config.hidden_layers);
    let exact: Vec<f64> = (0..2)
        .map(|a| {
            (0..problem.scene.particles())
                .map(|i| {
                    let k = i * 2 + a;
                    2.0 * f64::from(problem.weights[i])
                        * f64::from(grads.acceleration[k] - problem.target[k])
                })
                .sum()
        })
        .collect();
    let (_, bias_grad) = grads.params.iter().find(|(n, _)| *n == last).unwrap();
    common::assert_close(bias_grad, &exact, 1e-5, &format!("{last} on {}", B::name()));

    let h = 1e-6;
    let mut rng = Rng::new(11);
    for (name, g) in &grads.params {
        assert!(g.iter().all(|x| x.is_finite()), "{name}: {g:?}");
        assert!(
            g.iter().any(|&x| x != 0.0),
            "{name}: the loss does not depend on it"
        );
        let d = direction(&mut rng, g.len());
        let (got, scale) = directional(g, &d);
        let shifted = |sign: f64| {
            let mut moved = host.clone();
            let values = moved.params.get_mut(name).unwrap();
            for (v, d) in values.iter_mut().zip(&d) {
                *v += sign * h * d;
            }
            problem.host_loss(&moved, &window)
        };
        let fd = (shifted(1.0) - shifted(-1.0)) / (2.0 * h);
        assert!(
            (got - fd).abs() <= 1e-5 * scale,
            "{name} on {}: g·d = {got}, central difference {fd} (Σ|g d| = {scale:.3e})",
            B::name()
        );
    }
}

fn parameter_gradients_match_finite_differences_of_the_backend<B: AutodiffBackend + GnsKernels>() {
    let problem = problem();
    let grads = gradients::<B>(&problem);
    let params = problem.params::<B>();
    let h = 1e-4;
    let mut rng = Rng::new(12);
    // Random directions along which the derivative is large enough to compare in f32 (a
    // direction nearly orthogonal to the gradient is drawn again); three of them are checked.
    let mut compared = 0;
    for round in 0..12 {
        if compared == 3 {
            break;
        }
        let directions: Vec<Vec<f64>> = grads
            .params
            .iter()
            .map(|(_, g)| direction(&mut rng, g.len()))
            .collect();
        let got: f64 = grads
            .params
            .iter()
            .zip(&directions)
            .map(|((_, g), d)| directional(g, d).0)
            .sum();
        let shifted = |sign: f64| {
            let mut k = 0;
            let moved = params.map(|_, t| {
                let d = &directions[k];
                k += 1;
                let values = t
                    .to_vec()
                    .iter()
                    .zip(d)
                    .map(|(v, d)| (f64::from(*v) + sign * h * d) as f32)
                    .collect();
                Tensor::from_vec(values, &t.shape(), &t.device()).unwrap()
            });
            problem.loss_value(moved)
        };
        let fd = (shifted(1.0) - shifted(-1.0)) / (2.0 * h);
        if fd.abs() <= 0.1 {
            continue;
        }
        assert!(
            (got - fd).abs() <= 5e-3 * fd.abs(),
            "direction {round} on {}: g·d = {got}, central difference {fd}",
            B::name()
        );
        compared += 1;
    }
    assert_eq!(
        compared, 3,
        "too few directions with a derivative large enough to compare"
    );
}

fn position_gradients_are_finite_and_match_finite_differences<B: AutodiffBackend + GnsKernels>() {
    let problem = problem();
    let grads = gradients::<B>(&problem);
    assert!(
        grads.positions.iter().all(|g| g.is_finite()),
        "non-finite position gradients on {}",
        B::name()
    );
    // The oldest frame enters only through the first velocity, v₀ = p₁ − p₀, so its gradient
    // is −∂L/∂v₀ / vel_scale: not zero.
    let frames = problem.spec.config.input_velocities + 1;
    assert!(
        grads
            .positions
            .chunks_exact(frames * 2)
            .any(|particle| particle[..2].iter().any(|&g| g != 0.0))
    );
    let host = problem.host();
    let window = problem.scene.window_f64();
    let h = 1e-8;
    let mut rng = Rng::new(13);
    for round in 0..3 {
        let d = direction(&mut rng, window.len());
        let (got, scale) = directional(&grads.positions, &d);
        let shifted = |sign: f64| {
            let moved: Vec<f64> = window
                .iter()
                .zip(&d)
                .map(|(p, d)| p + sign * h * d)
                .collect();
            problem.host_loss(&host, &moved)
        };
        let fd = (shifted(1.0) - shifted(-1.0)) / (2.0 * h);
        assert!(
            (got - fd).abs() <= 1e-5 * scale,
            "direction {round} on {}: g·d = {got}, central difference {fd} (Σ|g d| = \
             {scale:.3e})",
            B::name()
        );
    }
}

#[cfg(feature = "tch")]
#[test]
fn burn_and_tch_gradients_agree() {
    use phi_core::backend::burn::Burn;
    use phi_core::backend::tch::Tch;

    let problem = problem();
    let burn = gradients::<Burn>(&problem);
    let tch = gradients::<Tch>(&problem);
    let mut pairs: Vec<(&str, &[f32], &[f32])> = burn
        .params
        .iter()
        .zip(&tch.params)
        .map(|((n, b), (m, t))| {
            assert_eq!(n, m);
            (n.as_str(), b.as_slice(), t.as_slice())
        })
        .collect();
    pairs.push(("positions", &burn.positions, &tch.positions));
    for (name, b, t) in pairs {
        let t64: Vec<f64> = t.iter().map(|&x| f64::from(x)).collect();
        common::assert_close(b, &t64, 1e-5, &format!("∂L/∂{name}, Burn against tch"));
    }
}
