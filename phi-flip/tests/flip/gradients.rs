//! Gradients through FLIP steps on the autodiff backends: with respect to the initial particle
//! positions and velocities, the gravity, an obstacle's position and an inflow's velocity,
//! against central finite differences, and Burn against libtorch. (The losses' gradients are
//! tested with them, in `phi_core::point_sets`.)
//!
//! # Tolerances
//! The loss `L = Σ w ⊙ x_N + Σ w' ⊙ v_N` (fixed pseudo-random weights) is piecewise smooth: the
//! forward pass holds constant which cells are liquid, which faces are valid or blocked, the
//! cell and the grid samples each particle falls between and the number of extrapolation layers,
//! and the gradient is that of the smooth piece. Central differences in `f32` with `h = 10⁻²`
//! have truncation error `~h²·|L'''|` and round-off `~ε·|L|/h ≈ 10⁻⁷·30/10⁻² = 3·10⁻⁴`; the
//! 2D pressure solve is a direct (Cholesky) solve, so it adds no iteration error. An element is
//! compared only when its stencil lies on one smooth piece, which shows as `FD(h)` and `FD(h/2)`
//! agreeing (a particle crossing a face line or a cell boundary inside the stencil changes the
//! masks and makes them disagree); at least 80% of the elements must qualify. Gradients are then
//! held to `2·10⁻² + 2·10⁻²·|g|`, a few times the round-off of the difference quotient after
//! several steps of amplification.

use phi_core::fields::LatticeKernels;
use phi_core::fields::{Boundary, Domain};
use phi_core::{AutodiffBackend, Backend, Tensor};
use phi_flip::{FlipParams, FlipSimulation, Inflow, Particles, SceneParameters};
use phi_geom::{Geometry, Obstacle};

phi_core::autodiff_backend_tests!(
    gradients_of_a_falling_block_match_finite_differences,
    gradients_with_an_obstacle_match_finite_differences,
    gradients_with_an_inflow_match_finite_differences,
);

const H: f32 = 1e-2;
const STEPS: usize = 4;

/// A tiny scene: its simulation, the initial particles (host) and the number of obstacles and
/// inflows.
struct Tiny {
    domain: Domain,
    obstacles: Vec<Obstacle>,
    inflows: Vec<Inflow>,
    positions: Vec<f32>,
    velocities: Vec<f32>,
}

fn closed(n: usize) -> Domain {
    Domain::new(
        &[n, n],
        &[0.0, 0.0],
        &[n as f32, n as f32],
        &[[Boundary::Closed; 2]; 2],
    )
    .unwrap()
}

/// Particles on a 3×3-per-cell lattice of the cells `[x0, x0 + w) × [y0, y0 + h)`, offset from
/// the face and centre lines (multiples of ½) by at least 0.1, with a smooth velocity field.
fn block(x0: usize, y0: usize, w: usize, h: usize, vy: f32) -> (Vec<f32>, Vec<f32>) {
    let (mut p, mut v) = (Vec::new(), Vec::new());
    for i in 0..w {
        for j in 0..h {
            for (a, b) in [(0.2, 0.3), (0.7, 0.15), (0.35, 0.8)] {
                let (x, y) = (x0 as f32 + i as f32 + a, y0 as f32 + j as f32 + b);
                p.extend([x, y]);
                v.extend([0.8 * (0.7 * y).sin(), vy + 0.5 * (0.9 * x).cos()]);
            }
        }
    }
    (p, v)
}

fn falling_block() -> Tiny {
    let (positions, velocities) = block(3, 3, 2, 2, -1.0);
    Tiny {
        domain: closed(8),
        obstacles: vec![],
        inflows: vec![],
        positions,
        velocities,
    }
}

/// A block falling fast onto a box obstacle: particles that end a step inside it are pushed out,
/// and the gradient with respect to the obstacle's offset comes from those pushes.
fn block_over_obstacle() -> Tiny {
    let (positions, velocities) = block(3, 4, 2, 1, -12.0);
    // Thinner than a cell and between cell centres: it blocks no face, so the liquid falls into
    // it and is pushed out (to the nearer of its top and bottom sides).
    let obstacle = Obstacle::at_rest(Geometry::boxed(vec![2.6, 2.6], vec![5.4, 3.4]).unwrap());
    Tiny {
        domain: closed(8),
        obstacles: vec![obstacle.unwrap()],
        inflows: vec![],
        positions,
        velocities,
    }
}

fn block_with_inflow() -> Tiny {
    let (positions, velocities) = block(2, 2, 2, 1, 0.0);
    Tiny {
        domain: closed(8),
        obstacles: vec![],
        inflows: vec![Inflow {
            geometry: Geometry::boxed(vec![5.0, 5.0], vec![6.0, 6.0]).unwrap(),
            velocity: vec![1.5, -2.0],
            every: 2,
            until_step: None,
            particles_per_cell: 2,
        }],
        positions,
        velocities,
    }
}

impl Tiny {
    fn simulation<B: LatticeKernels>(&self) -> FlipSimulation<B> {
        FlipSimulation::new(
            self.domain.clone(),
            FlipParams::thesis(2, 0.05),
            self.obstacles.clone(),
            self.inflows.clone(),
            3,
            &B::default_device(),
        )
        .unwrap()
    }

    /// The inputs: positions, velocities, gravity, then each obstacle offset and each inflow
    /// velocity, as (shape, values).
    fn inputs(&self) -> Vec<(Vec<usize>, Vec<f32>)> {
        let n = self.positions.len() / 2;
        let mut inputs = vec![
            (vec![n, 2], self.positions.clone()),
            (vec![n, 2], self.velocities.clone()),
            (vec![2], vec![0.0, -9.81]),
        ];
        for _ in &self.obstacles {
            inputs.push((vec![1, 2], vec![0.0, 0.0]));
        }
        for f in &self.inflows {
            inputs.push((vec![1, 2], f.velocity.clone()));
        }
        inputs
    }
}

/// `Σ w ⊙ x_N + Σ w' ⊙ v_N` after [`STEPS`] steps from the inputs of [`Tiny::inputs`].
fn loss<B: LatticeKernels>(
    sim: &FlipSimulation<B>,
    t: &[Tensor<B>],
    obstacles: usize,
) -> Tensor<B> {
    let scene = SceneParameters {
        gravity: t[2].clone(),
        obstacle_offsets: t[3..3 + obstacles].to_vec(),
        inflow_velocities: t[3 + obstacles..].to_vec(),
    };
    let mut p = Particles {
        positions: t[0].clone(),
        velocities: t[1].clone(),
        affine: None,
    };
    for step in 0..STEPS {
        p = sim.step_with(&p, step, &scene).unwrap().0;
    }
    let weights = |shape: &[usize], phase: f32| {
        let n: usize = shape.iter().product();
        let w: Vec<f32> = (0..n)
            .map(|k| 1.0 + 0.5 * (1.3 * k as f32 + phase).sin())
            .collect();
        Tensor::<B>::from_vec(w, shape, &B::default_device()).unwrap()
    };
    (&p.positions * &weights(&p.positions.shape(), 0.4)).sum()
        + (&p.velocities * &weights(&p.velocities.shape(), 1.1)).sum() * 0.1
}

fn tensors<B: Backend>(inputs: &[(Vec<usize>, Vec<f32>)]) -> Vec<Tensor<B>> {
    inputs
        .iter()
        .map(|(s, v)| Tensor::from_vec(v.clone(), s, &B::default_device()).unwrap())
        .collect()
}

/// Backpropagated gradients of the loss with respect to every input.
fn backprop<B: AutodiffBackend + LatticeKernels>(tiny: &Tiny) -> Vec<Vec<f32>> {
    let sim = tiny.simulation::<B>();
    let leaves: Vec<Tensor<B>> = tensors::<B>(&tiny.inputs())
        .iter()
        .map(Tensor::require_grad)
        .collect();
    let wrt: Vec<&Tensor<B>> = leaves.iter().collect();
    loss(&sim, &leaves, tiny.obstacles.len())
        .gradients(&wrt)
        .unwrap()
        .iter()
        .map(Tensor::to_vec)
        .collect()
}

/// Central differences with step `h` of every input element.
fn finite_differences<B: LatticeKernels>(tiny: &Tiny, h: f32) -> Vec<Vec<f32>> {
    let sim = tiny.simulation::<B>();
    let inputs = tiny.inputs();
    let at = |data: &[(Vec<usize>, Vec<f32>)]| {
        loss(&sim, &tensors::<B>(data), tiny.obstacles.len())
            .to_scalar()
            .unwrap()
    };
    (0..inputs.len())
        .map(|k| {
            (0..inputs[k].1.len())
                .map(|e| {
                    let (mut plus, mut minus) = (inputs.clone(), inputs.clone());
                    plus[k].1[e] += h;
                    minus[k].1[e] -= h;
                    (at(&plus) - at(&minus)) / (2.0 * h)
                })
                .collect()
        })
        .collect()
}

const NAMES: [&str; 5] = [
    "positions",
    "velocities",
    "gravity",
    "obstacle offset",
    "inflow velocity",
];

/// Checks backprop against finite differences (see the module docs for the tolerance); returns
/// the analytic gradients.
fn check_against_finite_differences<B: AutodiffBackend + LatticeKernels>(
    tiny: &Tiny,
) -> Vec<Vec<f32>> {
    let analytic = backprop::<B>(tiny);
    let fd = finite_differences::<B>(tiny, H);
    let fd_half = finite_differences::<B>(tiny, H / 2.0);
    let names: Vec<&str> = (0..analytic.len())
        .map(|k| match k {
            0..=2 => NAMES[k],
            _ if k < 3 + tiny.obstacles.len() => NAMES[3],
            _ => NAMES[4],
        })
        .collect();
    compare_with_finite_differences("", &analytic, &fd, &fd_half, &names);
    analytic
}

fn gradients_of_a_falling_block_match_finite_differences<B: AutodiffBackend + LatticeKernels>() {
    let tiny = falling_block();
    let g = check_against_finite_differences::<B>(&tiny);
    // Free fall: after k steps a particle has fallen `g Δt² k(k+1)/2` (symplectic Euler on the
    // grid) and gained `g Δt k` of velocity, so `∂L/∂g_y` is the y weights times those factors.
    let n = tiny.positions.len() / 2;
    let weight_sum = |phase: f32| -> f32 {
        (0..n)
            .map(|i| 1.0 + 0.5 * (1.3 * (2 * i + 1) as f32 + phase).sin())
            .sum()
    };
    let (dt, k) = (0.05f32, STEPS as f32);
    let free_fall =
        weight_sum(0.4) * dt * dt * k * (k + 1.0) / 2.0 + 0.1 * weight_sum(1.1) * dt * k;
    assert!(
        (g[2][1] - free_fall).abs() < 0.1 * free_fall,
        "∂L/∂g_y = {}, free fall {free_fall}",
        g[2][1]
    );
}

fn gradients_with_an_obstacle_match_finite_differences<B: AutodiffBackend + LatticeKernels>() {
    check_against_finite_differences::<B>(&block_over_obstacle());
}

fn gradients_with_an_inflow_match_finite_differences<B: AutodiffBackend + LatticeKernels>() {
    check_against_finite_differences::<B>(&block_with_inflow());
}

/// Burn and libtorch give the same gradients for every input of every scene.
#[cfg(feature = "tch")]
#[test]
fn burn_and_tch_gradients_agree() {
    use phi_core::backend::burn::Burn;
    use phi_core::backend::tch::Tch;
    for (name, tiny) in [
        ("falling block", falling_block()),
        ("obstacle", block_over_obstacle()),
        ("inflow", block_with_inflow()),
    ] {
        let burn = backprop::<Burn>(&tiny);
        let tch = backprop::<Tch>(&tiny);
        for (k, (a, b)) in burn.iter().zip(&tch).enumerate() {
            assert_eq!(a.len(), b.len());
            let worst = a
                .iter()
                .zip(b)
                .map(|(x, y)| (x - y).abs() / (1.0 + y.abs()))
                .fold(0.0f32, f32::max);
            println!("{name}: input {k}: largest difference {worst:.2e}");
            // Both are f32 with different operation orders; four steps amplify round-off.
            assert!(worst <= 1e-3, "{name}: input {k}: burn {a:?} vs tch {b:?}");
        }
    }
}

/// Backprop gradients `analytic[k]` (one list per input, named `names[k]`) against central
/// finite differences with steps `h` (`fd`) and `h/2` (`fd_half`): an element is compared only
/// where the two difference quotients agree (no kink inside the stencil), to 2e-2 absolute plus
/// 2e-2 relative; at least 80 % of the elements must qualify, and no gradient may vanish.
pub(crate) fn compare_with_finite_differences<S: AsRef<str>>(
    label: &str,
    analytic: &[Vec<f32>],
    fd: &[Vec<f32>],
    fd_half: &[Vec<f32>],
    names: &[S],
) {
    let (mut compared, mut total) = (0, 0);
    for k in 0..analytic.len() {
        for e in 0..analytic[k].len() {
            total += 1;
            let (a, f, f2) = (analytic[k][e], fd[k][e], fd_half[k][e]);
            // A kink inside the stencil: the two difference quotients disagree.
            if (f - f2).abs() > 1e-2 + 1e-2 * f.abs() {
                continue;
            }
            compared += 1;
            assert!(
                (a - f).abs() <= 2e-2 + 2e-2 * f.abs(),
                "{label}∂L/∂{}[{e}]: backprop {a}, finite differences {f} (h/2: {f2})",
                names[k].as_ref()
            );
        }
    }
    println!("{label}{compared} of {total} gradient elements compared with finite differences");
    assert!(
        compared * 5 >= total * 4,
        "{label}only {compared} of {total} elements lie on a smooth piece"
    );
    for (k, g) in analytic.iter().enumerate() {
        assert!(
            g.iter().any(|v| v.abs() > 1e-2),
            "{label}the gradient with respect to {} vanishes: {g:?}",
            names[k].as_ref()
        );
    }
}
