//! Gradients through the fields layer on the autodiff backends: particle → grid → particle
//! transfers and semi-Lagrangian advection against central finite differences, and Burn against
//! libtorch.
//!
//! The losses are piecewise smooth: the multilinear weights have kinks where a point crosses a
//! line of samples. The test points stay at least `0.1 Δx` from every such line, and the finite
//! differences use `h = 10⁻²` (truncation ≈ `h²`, `f32` round-off ≈ `ε |loss| / h` ≈ 10⁻⁴), so
//! gradients are held to `3·10⁻³ + 10⁻²·|g|`.

use phi_core::fields::LatticeKernels;
use phi_core::fields::{
    Boundary, CenteredGrid, PointCloud, StaggeredGrid, Transfer, advect_semi_lagrangian,
    particles_to_centered, particles_to_staggered, sample_staggered,
};
use phi_core::{AutodiffBackend, Tensor};

use super::{domain, tensor};
use crate::conformance::{assert_values, values};

phi_core::autodiff_backend_tests!(particle_grid_particle_gradients, semi_lagrangian_gradients,);

const STEP: f32 = 1e-2;

/// Positions with every coordinate at least 0.1 from the lines of faces and centres (multiples
/// of ½) of a unit-cell 4×4 domain, and inside the lattices (no clamping).
const POSITIONS: [f32; 10] = [0.62, 1.37, 1.15, 2.83, 2.38, 0.71, 3.21, 3.12, 1.88, 1.64];

/// `Σ W ⊙ PIC(positions, values) + Σ W' ⊙ density`, where PIC is particle → staggered grid
/// (linear) → particles and the density is the centred transfer weight of the particles.
fn transfer_loss<B: AutodiffBackend + LatticeKernels>(
    positions: &Tensor<B>,
    values: &Tensor<B>,
) -> Tensor<B> {
    let domain = domain(&[4, 4], &[0.0, 0.0], &[4.0, 4.0], Boundary::Open);
    let cloud = PointCloud::new(positions.clone(), values.clone()).unwrap();
    let (grid, _) = particles_to_staggered(&cloud, &domain, Transfer::Linear).unwrap();
    let back = sample_staggered(&grid, positions).unwrap();
    let w = tensor::<B>(&back.shape(), &values_of(back.numel(), 11));
    let scalar = PointCloud::new(positions.clone(), values.narrow(1, 0..1).unwrap()).unwrap();
    let (_, density) = particles_to_centered(&scalar, &domain, Transfer::Linear).unwrap();
    let w2 = tensor::<B>(&density.values().shape(), &values_of(16, 12));
    (back * w).sum() + (density.values() * &w2).sum()
}

fn values_of(n: usize, seed: u64) -> Vec<f32> {
    values(n, 0.5, 1.5, seed)
}

/// Central differences of `loss` with respect to each element of each input.
pub fn finite_differences<B: AutodiffBackend>(
    inputs: &[(Vec<usize>, Vec<f32>)],
    loss: impl Fn(&[Tensor<B>]) -> Tensor<B>,
) -> Vec<Vec<f32>> {
    let at = |data: &[(Vec<usize>, Vec<f32>)]| -> f32 {
        let tensors: Vec<Tensor<B>> = data.iter().map(|(s, v)| tensor::<B>(s, v)).collect();
        loss(&tensors).to_scalar().unwrap()
    };
    (0..inputs.len())
        .map(|k| {
            (0..inputs[k].1.len())
                .map(|e| {
                    let (mut plus, mut minus) = (inputs.to_vec(), inputs.to_vec());
                    plus[k].1[e] += STEP;
                    minus[k].1[e] -= STEP;
                    (at(&plus) - at(&minus)) / (2.0 * STEP)
                })
                .collect()
        })
        .collect()
}

/// Backpropagated gradients of `loss` with respect to each input.
pub fn backprop<B: AutodiffBackend>(
    inputs: &[(Vec<usize>, Vec<f32>)],
    loss: impl Fn(&[Tensor<B>]) -> Tensor<B>,
) -> Vec<Vec<f32>> {
    let leaves: Vec<Tensor<B>> = inputs
        .iter()
        .map(|(s, v)| tensor::<B>(s, v).require_grad())
        .collect();
    let wrt: Vec<&Tensor<B>> = leaves.iter().collect();
    loss(&leaves)
        .gradients(&wrt)
        .unwrap()
        .iter()
        .map(|g| g.to_vec())
        .collect()
}

fn transfer_inputs() -> Vec<(Vec<usize>, Vec<f32>)> {
    vec![
        (vec![5, 2], POSITIONS.to_vec()),
        (vec![5, 2], values(10, -1.0, 1.0, 5)),
    ]
}

fn particle_grid_particle_gradients<B: AutodiffBackend + LatticeKernels>() {
    let inputs = transfer_inputs();
    let loss = |t: &[Tensor<B>]| transfer_loss(&t[0], &t[1]);
    let numeric = finite_differences::<B>(&inputs, loss);
    let analytic = backprop::<B>(&inputs, loss);
    for (k, name) in ["positions", "values"].iter().enumerate() {
        assert_values(
            &format!("∂loss/∂{name}"),
            &inputs[k].0,
            &analytic[k],
            &inputs[k].0,
            &numeric[k],
            1e-2,
            3e-3,
        );
        assert!(
            analytic[k].iter().any(|g| g.abs() > 1e-2),
            "the gradient w.r.t. {name} vanishes"
        );
    }
}

fn advection_inputs() -> Vec<(Vec<usize>, Vec<f32>)> {
    vec![
        (vec![5, 4, 1], values(20, -1.0, 1.0, 6)),
        (vec![6, 4], values(24, 0.1, 0.4, 7)),
        (vec![5, 5], values(25, 0.1, 0.4, 8)),
    ]
}

fn advection_loss<B: AutodiffBackend + LatticeKernels>(t: &[Tensor<B>]) -> Tensor<B> {
    let domain = domain(&[5, 4], &[0.0, 0.0], &[5.0, 4.0], Boundary::Closed);
    let field = CenteredGrid::new(t[0].clone(), domain.clone()).unwrap();
    let velocity = StaggeredGrid::new(vec![t[1].clone(), t[2].clone()], domain).unwrap();
    let advected = advect_semi_lagrangian(&field, &velocity, 0.8).unwrap();
    (advected.values() * tensor::<B>(&[5, 4, 1], &values_of(20, 13))).sum()
}

fn semi_lagrangian_gradients<B: AutodiffBackend + LatticeKernels>() {
    let inputs = advection_inputs();
    let numeric = finite_differences::<B>(&inputs, advection_loss::<B>);
    let analytic = backprop::<B>(&inputs, advection_loss::<B>);
    for (k, name) in ["field", "u", "v"].iter().enumerate() {
        assert_values(
            &format!("∂loss/∂{name}"),
            &inputs[k].0,
            &analytic[k],
            &inputs[k].0,
            &numeric[k],
            1e-2,
            3e-3,
        );
        assert!(
            analytic[k].iter().any(|g| g.abs() > 1e-2),
            "the gradient w.r.t. {name} vanishes"
        );
    }
}

/// Burn's and libtorch's gradients of the same losses agree.
#[cfg(all(feature = "burn", feature = "tch"))]
#[test]
fn burn_matches_tch() {
    use phi_core::backend::burn::Burn;
    use phi_core::backend::tch::Tch;
    let compare = |what: &str, burn: Vec<Vec<f32>>, tch: Vec<Vec<f32>>| {
        for (k, (b, t)) in burn.iter().zip(&tch).enumerate() {
            assert_values(
                &format!("{what} input {k}: burn vs tch"),
                &[b.len()],
                b,
                &[t.len()],
                t,
                1e-4,
                1e-5,
            );
        }
    };
    let inputs = transfer_inputs();
    compare(
        "transfer",
        backprop::<Burn>(&inputs, |t| transfer_loss(&t[0], &t[1])),
        backprop::<Tch>(&inputs, |t| transfer_loss(&t[0], &t[1])),
    );
    let inputs = advection_inputs();
    compare(
        "advection",
        backprop::<Burn>(&inputs, advection_loss::<Burn>),
        backprop::<Tch>(&inputs, advection_loss::<Tch>),
    );
}
