//! The sparse linear solve on every backend: forward results against the host solver, errors as
//! values, and on the autodiff backends implicit gradients (against central finite differences,
//! Burn against tch, and the backward pass being exactly one adjoint solve).

use std::sync::Arc;

use phi_core::fields::{Boundary, Domain, all_faces_open, poisson_matrix};
use phi_core::solve::{
    PoissonSystem, Preconditioner, SolveError, SolveMethod, SolveOptions, SparseMatrix, solve_f32,
};
use phi_core::{AutodiffBackend, Backend, Tensor, TensorError};

/// Forward solves on every backend.
mod forward {
    use super::*;
    phi_core::backend_tests!(forward_matches_the_host_solver, errors_are_values);
}

/// Implicit gradients on the autodiff backends.
mod gradients {
    use super::*;
    phi_core::autodiff_backend_tests!(
        gradient_matches_finite_differences,
        gradient_of_several_right_hand_sides,
        backward_is_one_adjoint_solve,
        tracking_follows_the_right_hand_side,
    );
}

/// A 6×5 tank with an open top, an air pocket and an obstacle face: 29 unknowns.
fn tank() -> PoissonSystem {
    let domain = Domain::new(
        &[6, 5],
        &[0.0, 0.0],
        &[3.0, 5.0],
        &[[Boundary::Closed; 2], [Boundary::Closed, Boundary::Open]],
    )
    .unwrap();
    let mut liquid = vec![true; 30];
    liquid[2 * 5 + 3] = false;
    let mut faces = all_faces_open(&domain);
    faces[0][4 * 5 + 1] = false;
    poisson_matrix(&domain, &liquid, &faces).unwrap()
}

fn values(n: usize, seed: u64) -> Vec<f32> {
    // A cheap deterministic spread of values in [-1, 1].
    (0..n)
        .map(|i| {
            let x = ((i as u64 + 1) * 2654435761 + seed * 40503) % 10007;
            x as f32 / 5003.0 - 1.0
        })
        .collect()
}

fn tensor<B: Backend>(data: &[f32], shape: &[usize]) -> Tensor<B> {
    Tensor::from_slice(data, shape, &B::default_device()).unwrap()
}

fn tight() -> SolveOptions {
    SolveOptions {
        relative_tolerance: 1e-7,
        ..SolveOptions::default()
    }
}

fn forward_matches_the_host_solver<B: Backend>() {
    let system = tank();
    let n = system.unknowns();
    for method in [
        SolveMethod::Auto,
        SolveMethod::Cholesky,
        SolveMethod::ConjugateGradient(Preconditioner::IncompleteCholesky),
    ] {
        let options = SolveOptions::with_method(method);
        let b = values(n, 1);
        let (x, stats) = tensor::<B>(&b, &[n])
            .linear_solve(&system.matrix, &options)
            .unwrap();
        assert_eq!(x.shape(), vec![n]);
        let (want, _) = solve_f32(&system.matrix, &b, 1, &options).unwrap();
        assert_eq!(x.to_vec(), want, "{method:?}");
        let bnorm = b.iter().map(|v| f64::from(*v).powi(2)).sum::<f64>().sqrt();
        assert!(stats.residual <= 1e-5 * bnorm);
        // The residual of the f32 result, recomputed here.
        let x64: Vec<f64> = x.to_vec().iter().map(|&v| f64::from(v)).collect();
        let ax = system.matrix.mul_vec(&x64);
        let r = ax
            .iter()
            .zip(&b)
            .map(|(p, q)| (p - f64::from(*q)).powi(2))
            .sum::<f64>()
            .sqrt();
        assert!(r <= 1e-5 * bnorm, "{method:?}: residual {r}");
    }
    // Two right-hand sides as the columns of [n, 2].
    let b1 = values(n, 2);
    let b2 = values(n, 3);
    let both: Vec<f32> = (0..n).flat_map(|i| [b1[i], b2[i]]).collect();
    let (x, _) = tensor::<B>(&both, &[n, 2])
        .linear_solve(&system.matrix, &tight())
        .unwrap();
    assert_eq!(x.shape(), vec![n, 2]);
    let x = x.to_vec();
    let (x1, _) = solve_f32(&system.matrix, &b1, 1, &tight()).unwrap();
    let (x2, _) = solve_f32(&system.matrix, &b2, 1, &tight()).unwrap();
    for i in 0..n {
        assert!((x[2 * i] - x1[i]).abs() <= 1e-6 * (1.0 + x1[i].abs()));
        assert!((x[2 * i + 1] - x2[i]).abs() <= 1e-6 * (1.0 + x2[i].abs()));
    }
}

fn errors_are_values<B: Backend>() {
    let system = tank();
    let n = system.unknowns();
    let mut b = values(n, 4);
    b[3] = f32::NAN;
    let err = tensor::<B>(&b, &[n])
        .linear_solve(&system.matrix, &SolveOptions::default())
        .unwrap_err();
    assert!(matches!(err, SolveError::NonFinite { .. }), "{err}");

    let options = SolveOptions {
        max_iterations: 2,
        ..SolveOptions::with_method(SolveMethod::ConjugateGradient(Preconditioner::Jacobi))
    };
    let err = tensor::<B>(&values(n, 5), &[n])
        .linear_solve(&system.matrix, &options)
        .unwrap_err();
    match err {
        SolveError::NotConverged {
            iterations,
            residual,
            tolerance,
        } => assert!(iterations == 2 && residual > tolerance),
        other => panic!("expected NotConverged, got {other}"),
    }

    let err = tensor::<B>(&values(n + 1, 6), &[n + 1])
        .linear_solve(&system.matrix, &SolveOptions::default())
        .unwrap_err();
    assert!(matches!(
        err,
        SolveError::DimensionMismatch { expected, got, .. } if expected == n && got == n + 1
    ));
    let err = tensor::<B>(&values(2 * n, 6), &[n, 1, 2])
        .linear_solve(&system.matrix, &SolveOptions::default())
        .unwrap_err();
    assert!(matches!(
        err,
        SolveError::Tensor(TensorError::InvalidArgument { .. })
    ));
    let rectangular = Arc::new(SparseMatrix::from_triplets(2, 3, &[(0, 0, 1.0)]).unwrap());
    let err = tensor::<B>(&[1.0, 2.0], &[2])
        .linear_solve(&rectangular, &SolveOptions::default())
        .unwrap_err();
    assert!(matches!(err, SolveError::DimensionMismatch { .. }));
}

/// `L(b) = Σ w·x² + Σ sin x` with `x = A⁻¹ (2 b + sin b)`: non-linear on both sides of the solve.
fn loss<B: AutodiffBackend>(
    matrix: &Arc<SparseMatrix>,
    b: &Tensor<B>,
    options: &SolveOptions,
) -> Tensor<B> {
    let rhs = b * 2.0 + b.sin();
    let (x, _) = rhs.linear_solve(matrix, options).unwrap();
    let w = tensor::<B>(&values(x.numel(), 7), &x.shape());
    (&x * &x * &w).sum() + x.sin().sum()
}

/// The gradient of [`loss`] by backpropagation.
fn backprop<B: AutodiffBackend>(
    matrix: &Arc<SparseMatrix>,
    b: &[f32],
    shape: &[usize],
    options: &SolveOptions,
) -> Vec<f32> {
    let leaf = tensor::<B>(b, shape).require_grad();
    let l = loss(matrix, &leaf, options);
    l.gradients(&[&leaf]).unwrap()[0].to_vec()
}

/// Central differences of [`loss`] with the backend's own `f32` forward pass. The step `h =
/// 10⁻²` gives a truncation error of about `h²/6 · |L'''|` (≈ 10⁻⁴ here) and a round-off error of
/// about `ε_f32 · |L| / h` (≈ 10⁻⁵); the tolerance below, `10⁻³ + 10⁻² |g|`, is far below the
/// error of a wrong gradient (a missing transpose, an unrolled solve cut short: order 1).
fn finite_differences<B: AutodiffBackend>(
    matrix: &Arc<SparseMatrix>,
    b: &[f32],
    shape: &[usize],
    options: &SolveOptions,
) -> Vec<f32> {
    let h = 1e-2f32;
    (0..b.len())
        .map(|k| {
            let mut plus = b.to_vec();
            let mut minus = b.to_vec();
            plus[k] += h;
            minus[k] -= h;
            let at = |v: &[f32]| {
                loss(matrix, &tensor::<B>(v, shape), options)
                    .to_scalar()
                    .unwrap()
            };
            (at(&plus) - at(&minus)) / (2.0 * h)
        })
        .collect()
}

fn assert_gradients_close(what: &str, got: &[f32], want: &[f32]) {
    assert_eq!(got.len(), want.len());
    let scale = want.iter().fold(0.0f32, |m, v| m.max(v.abs()));
    assert!(
        scale > 1e-2,
        "{what}: the gradient is too small to test ({scale})"
    );
    for (k, (g, w)) in got.iter().zip(want).enumerate() {
        assert!(
            (g - w).abs() <= 1e-3 + 1e-2 * w.abs(),
            "{what}: component {k}: {g} against {w}"
        );
    }
}

fn gradient_matches_finite_differences<B: AutodiffBackend>() {
    let system = tank();
    let n = system.unknowns();
    let b = values(n, 8);
    for method in [
        SolveMethod::Auto,
        SolveMethod::ConjugateGradient(Preconditioner::IncompleteCholesky),
        SolveMethod::Lu,
    ] {
        let options = SolveOptions {
            relative_tolerance: 1e-7,
            ..SolveOptions::with_method(method)
        };
        let got = backprop::<B>(&system.matrix, &b, &[n], &options);
        let want = finite_differences::<B>(&system.matrix, &b, &[n], &options);
        assert_gradients_close(&format!("{} {method:?}", B::name()), &got, &want);
    }

    // A matrix that is not symmetric: the backward must solve with Aᵀ, not A.
    let m = 12;
    let mut triplets = Vec::new();
    for i in 0..m {
        triplets.push((i, i, 4.0));
        if i + 1 < m {
            triplets.push((i, i + 1, -2.0));
            triplets.push((i + 1, i, -0.5));
        }
    }
    triplets.push((0, m - 1, 1.0));
    let a = Arc::new(SparseMatrix::from_triplets(m, m, &triplets).unwrap());
    assert!(!a.is_symmetric());
    let b = values(m, 9);
    let got = backprop::<B>(&a, &b, &[m], &tight());
    let want = finite_differences::<B>(&a, &b, &[m], &tight());
    assert_gradients_close(&format!("{} non-symmetric", B::name()), &got, &want);
}

fn gradient_of_several_right_hand_sides<B: AutodiffBackend>() {
    let system = tank();
    let n = system.unknowns();
    let b = values(2 * n, 10);
    let got = backprop::<B>(&system.matrix, &b, &[n, 2], &tight());
    let want = finite_differences::<B>(&system.matrix, &b, &[n, 2], &tight());
    assert_gradients_close(&format!("{} [n, 2]", B::name()), &got, &want);
}

fn backward_is_one_adjoint_solve<B: AutodiffBackend>() {
    for method in [
        SolveMethod::Cholesky,
        SolveMethod::ConjugateGradient(Preconditioner::Jacobi),
    ] {
        // A fresh matrix, so its counters start at zero.
        let matrix = tank().matrix;
        let options = SolveOptions::with_method(method);
        let n = matrix.nrows();
        let leaf = tensor::<B>(&values(n, 11), &[n]).require_grad();
        let (x, stats) = leaf.linear_solve(&matrix, &options).unwrap();
        assert_eq!(matrix.solve_count(), 1, "{method:?}: forward");
        let loss = x.square().sum();
        let grad = loss.gradients(&[&leaf]).unwrap()[0].to_vec();
        assert_eq!(
            matrix.solve_count(),
            2,
            "{method:?}: backward is one more solve"
        );
        // Cholesky: the backward reuses the forward's factorization.
        if method == SolveMethod::Cholesky {
            assert_eq!(matrix.factorization_count(), 1);
            assert_eq!(stats.iterations, 0);
        } else {
            assert!(stats.iterations > 1);
        }
        // ∂(Σx²)/∂b = A⁻ᵀ 2x: the gradient solves A g = 2x.
        let (want, _) = solve_f32(
            &matrix,
            &x.to_vec().iter().map(|v| 2.0 * v).collect::<Vec<_>>(),
            1,
            &tight(),
        )
        .unwrap();
        for (g, w) in grad.iter().zip(&want) {
            assert!((g - w).abs() <= 1e-4 * (1.0 + w.abs()), "{g} against {w}");
        }
    }
}

fn tracking_follows_the_right_hand_side<B: AutodiffBackend>() {
    let system = tank();
    let n = system.unknowns();
    let plain = tensor::<B>(&values(n, 12), &[n]);
    let (x, _) = plain.linear_solve(&system.matrix, &tight()).unwrap();
    assert!(!x.is_tracked());
    let (x, _) = plain
        .require_grad()
        .linear_solve(&system.matrix, &tight())
        .unwrap();
    assert!(x.is_tracked());
}

/// Burn's and libtorch's implicit gradients agree.
#[cfg(all(feature = "burn", feature = "tch"))]
#[test]
fn burn_and_tch_gradients_agree() {
    use phi_core::backend::burn::Burn;
    use phi_core::backend::tch::Tch;
    let system = tank();
    let n = system.unknowns();
    let b = values(2 * n, 13);
    for shape in [vec![2 * n], vec![n, 2]] {
        let (matrix, shape) = if shape.len() == 1 {
            // A block-diagonal doubling of the tank for the one-column case.
            let m = &system.matrix;
            let mut triplets = Vec::new();
            for block in 0..2 {
                for i in 0..n {
                    for (j, v) in m.row(i) {
                        triplets.push((block * n + i, block * n + j, v));
                    }
                }
            }
            (
                Arc::new(SparseMatrix::from_triplets(2 * n, 2 * n, &triplets).unwrap()),
                shape,
            )
        } else {
            (system.matrix.clone(), shape)
        };
        let burn = backprop::<Burn>(&matrix, &b, &shape, &tight());
        let tch = backprop::<Tch>(&matrix, &b, &shape, &tight());
        for (k, (x, y)) in burn.iter().zip(&tch).enumerate() {
            assert!(
                (x - y).abs() <= 1e-5 * (1.0 + y.abs()),
                "{shape:?}: component {k}: burn {x}, tch {y}"
            );
        }
    }
}
