//! Gradients of every differentiable operation on the autodiff backends: against central finite
//! differences, and Burn against tch.
//!
//! Finite differences use the backend's own `f32` forward pass with step `h = 5·10⁻³`. The
//! truncation error is `h²/6 · f'''` (below 10⁻⁵ for these inputs) and the round-off error is
//! about `ε_f32 · |loss| / h` (≈ 10⁻⁴ for losses of order 10), so gradients are held to
//! `2·10⁻³ + 10⁻²·|g|`; an actual gradient bug (a wrong sign, a missing term, a wrong axis)
//! shows up as an error of order 1.

use phi_core::{AutodiffBackend, Tensor, TensorError};

use super::cases::Case;
use super::{assert_values, tensor, values};

phi_core::autodiff_backend_tests!(
    unary_gradients,
    binary_gradients,
    reduction_gradients,
    matmul_gradients,
    shape_gradients,
    gather_scatter_gradients,
    composite_gradient,
    detached_and_unused_inputs,
    gradient_errors,
);

const STEP: f32 = 5e-3;

/// `Σ out · w` for fixed weights `w`, so that every output element reaches the loss with its own
/// weight.
fn weighted_loss<B: AutodiffBackend>(out: &Tensor<B>) -> Tensor<B> {
    let weights = tensor::<B>(&out.shape(), &values(out.numel(), 0.5, 1.5, 99));
    (out * &weights).sum()
}

/// The gradients of the weighted loss of `case` with respect to each input, by backpropagation.
pub fn case_gradients<B: AutodiffBackend>(case: Case) -> Vec<Tensor<B>> {
    let leaves: Vec<Tensor<B>> = case
        .inputs()
        .iter()
        .map(|(s, v)| tensor::<B>(s, v).require_grad())
        .collect();
    let loss = weighted_loss(&case.apply(&leaves));
    let wrt: Vec<&Tensor<B>> = leaves.iter().collect();
    loss.gradients(&wrt)
        .expect("the loss is a scalar of tracked inputs")
}

/// Checks backpropagated gradients of `case` against central differences.
fn check_case<B: AutodiffBackend>(case: Case) {
    let inputs = case.inputs();
    let gradients = case_gradients::<B>(case);
    let loss_at = |perturbed: &[(Vec<usize>, Vec<f32>)]| -> f32 {
        let tensors: Vec<Tensor<B>> = perturbed.iter().map(|(s, v)| tensor::<B>(s, v)).collect();
        weighted_loss(&case.apply(&tensors)).to_scalar().unwrap()
    };
    for (k, (shape, input)) in inputs.iter().enumerate() {
        let mut numeric = Vec::with_capacity(input.len());
        for e in 0..input.len() {
            let mut plus = inputs.clone();
            plus[k].1[e] += STEP;
            let mut minus = inputs.clone();
            minus[k].1[e] -= STEP;
            numeric.push((loss_at(&plus) - loss_at(&minus)) / (2.0 * STEP));
        }
        let g = &gradients[k];
        assert_values(
            &format!("{case:?} ∂/∂input{k}"),
            &g.shape(),
            &g.to_vec(),
            shape,
            &numeric,
            1e-2,
            2e-3,
        );
        assert!(!g.is_tracked(), "{case:?}: gradients come back untracked");
    }
}

fn check_cases<B: AutodiffBackend>(keep: impl Fn(&Case) -> bool) {
    let cases: Vec<Case> = Case::all().into_iter().filter(|c| keep(c)).collect();
    assert!(!cases.is_empty());
    for case in cases {
        check_case::<B>(case);
    }
}

fn unary_gradients<B: AutodiffBackend>() {
    check_cases::<B>(|c| matches!(c, Case::Unary(_) | Case::Clamp));
}

fn binary_gradients<B: AutodiffBackend>() {
    check_cases::<B>(|c| matches!(c, Case::Binary(_) | Case::BinaryScalar(..) | Case::Where));
}

fn reduction_gradients<B: AutodiffBackend>() {
    check_cases::<B>(|c| matches!(c, Case::Reduce(_) | Case::ReduceAxis(..)));
}

fn matmul_gradients<B: AutodiffBackend>() {
    check_cases::<B>(|c| matches!(c, Case::Matmul | Case::MatmulBroadcast));
}

fn shape_gradients<B: AutodiffBackend>() {
    check_cases::<B>(|c| {
        matches!(
            c,
            Case::Reshape
                | Case::Permute
                | Case::Slice
                | Case::Concat
                | Case::Stack
                | Case::BroadcastTo
                | Case::Pad(_)
                | Case::ToDevice
        )
    });
}

fn gather_scatter_gradients<B: AutodiffBackend>() {
    check_cases::<B>(|c| {
        matches!(
            c,
            Case::GatherRows | Case::ScatterAddRows | Case::GatherNd | Case::ScatterAddNd
        )
    });
}

/// A small network layer, `mean(tanh(x W + b)²)`, whose gradients are known in closed form.
fn composite_gradient<B: AutodiffBackend>() {
    let x = tensor::<B>(&[4, 3], &values(12, -1.0, 1.0, 1));
    let w = tensor::<B>(&[3, 2], &values(6, -1.0, 1.0, 2)).require_grad();
    let b = tensor::<B>(&[2], &[0.1, -0.2]).require_grad();
    let h = (x.matmul(&w).unwrap() + &b).tanh();
    let loss = h.square().mean();
    let grads = loss.gradients(&[&w, &b]).unwrap();
    // ∂loss/∂z = 2 h (1 - h²) / n with z = x W + b; ∂/∂W = xᵀ ∂z, ∂/∂b = Σ_rows ∂z.
    let (xv, hv) = (x.to_vec(), h.to_vec());
    let dz: Vec<f32> = hv.iter().map(|&h| 2.0 * h * (1.0 - h * h) / 8.0).collect();
    let mut dw = vec![0.0f32; 6];
    let mut db = vec![0.0f32; 2];
    for row in 0..4 {
        for j in 0..2 {
            db[j] += dz[row * 2 + j];
            for i in 0..3 {
                dw[i * 2 + j] += xv[row * 3 + i] * dz[row * 2 + j];
            }
        }
    }
    assert_values(
        "∂/∂W",
        &grads[0].shape(),
        &grads[0].to_vec(),
        &[3, 2],
        &dw,
        1e-4,
        1e-6,
    );
    assert_values(
        "∂/∂b",
        &grads[1].shape(),
        &grads[1].to_vec(),
        &[2],
        &db,
        1e-4,
        1e-6,
    );
    // d/dx Σ x² = 2x exactly.
    let x = tensor::<B>(&[3], &[1.0, -2.0, 0.5]).require_grad();
    let g = x.square().sum().gradients(&[&x]).unwrap();
    assert_values(
        "∂Σx²/∂x",
        &g[0].shape(),
        &g[0].to_vec(),
        &[3],
        &[2.0, -4.0, 1.0],
        0.0,
        0.0,
    );
}

fn detached_and_unused_inputs<B: AutodiffBackend>() {
    let x = tensor::<B>(&[2], &[1.0, 2.0]).require_grad();
    let unused = tensor::<B>(&[3], &[1.0, 2.0, 3.0]).require_grad();
    assert!(x.is_tracked() && unused.is_tracked());
    assert!(!tensor::<B>(&[1], &[1.0]).is_tracked());
    // Gradient through the first factor only: the detached copy is a constant.
    let loss = (&x * &x.detach()).sum();
    let g = loss.gradients(&[&x, &unused]).unwrap();
    assert_values(
        "through x only",
        &g[0].shape(),
        &g[0].to_vec(),
        &[2],
        &[1.0, 2.0],
        0.0,
        0.0,
    );
    assert_values(
        "unused input",
        &g[1].shape(),
        &g[1].to_vec(),
        &[3],
        &[0.0; 3],
        0.0,
        0.0,
    );
    // Comparisons are constants too.
    let masked = (&x * &x.compare_scalar(phi_core::backend::CompareOp::Greater, 1.5)).sum();
    let g = masked.gradients(&[&x]).unwrap();
    assert_values(
        "mask",
        &g[0].shape(),
        &g[0].to_vec(),
        &[2],
        &[0.0, 1.0],
        0.0,
        0.0,
    );
    // A parameter made from a computed tensor is a fresh leaf.
    let y = (&x * 3.0).require_grad();
    let g = (&y * 2.0).sum().gradients(&[&y, &x]).unwrap();
    assert_values(
        "fresh leaf",
        &g[0].shape(),
        &g[0].to_vec(),
        &[2],
        &[2.0, 2.0],
        0.0,
        0.0,
    );
    assert_values(
        "history cut",
        &g[1].shape(),
        &g[1].to_vec(),
        &[2],
        &[0.0, 0.0],
        0.0,
        0.0,
    );
}

fn gradient_errors<B: AutodiffBackend>() {
    let x = tensor::<B>(&[2], &[1.0, 2.0]).require_grad();
    let not_scalar = &x * 2.0;
    assert!(matches!(
        not_scalar.gradients(&[&x]),
        Err(TensorError::NotScalar { .. })
    ));
    // Gradients are for leaves made by require_grad: not for constants, not for intermediates.
    let constant = tensor::<B>(&[2], &[3.0, 4.0]);
    let loss = (&x * &constant).sum();
    assert!(matches!(
        loss.gradients(&[&constant]),
        Err(TensorError::Backend { .. })
    ));
    let intermediate = &x * 2.0;
    let loss = intermediate.square().sum();
    assert!(matches!(
        loss.gradients(&[&intermediate]),
        Err(TensorError::Backend { .. })
    ));
}

/// Burn and libtorch differentiate every case to the same gradients.
#[cfg(all(feature = "burn", feature = "tch"))]
#[test]
fn burn_and_tch_gradients_agree() {
    use phi_core::backend::{burn::Burn, tch::Tch};
    for case in Case::all() {
        let from_burn = case_gradients::<Burn>(case);
        let from_tch = case_gradients::<Tch>(case);
        for (k, (b, t)) in from_burn.iter().zip(&from_tch).enumerate() {
            assert_values(
                &format!("{case:?} ∂/∂input{k}"),
                &b.shape(),
                &b.to_vec(),
                &t.shape(),
                &t.to_vec(),
                1e-5,
                1e-6,
            );
        }
    }
}
