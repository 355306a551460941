//! The native (host, `f64`) solvers: the choice of method, preconditioned conjugate gradients,
//! and the direct solves through the factorizations a [`SparseMatrix`] caches.

use std::sync::Arc;

use super::factor::IncompleteCholesky;
use super::mic::ModifiedIncompleteCholesky;
use super::sparse::SparseMatrix;
use super::{Preconditioner, SolveError, SolveMethod, SolveOptions, SolveStats};

/// Solves `A X = B` for `columns` right-hand sides stored row-major in `rhs` (`[n, columns]`),
/// returning `X` in the same layout.
///
/// # Errors
/// [`SolveError::DimensionMismatch`] for a matrix that is not square or a right-hand side of the
/// wrong length; [`SolveError::NonFinite`] for NaN or infinity in `rhs` (or, after a breakdown,
/// in the solution); [`SolveError::NotConverged`] when the residual misses the tolerance;
/// [`SolveError::Invalid`] / [`SolveError::Factorization`] when the method does not apply.
pub fn solve(
    matrix: &SparseMatrix,
    rhs: &[f64],
    columns: usize,
    options: &SolveOptions,
) -> Result<(Vec<f64>, SolveStats), SolveError> {
    solve_impl(matrix, rhs, columns, options, false)
}

/// Solves `Aᵀ X = B` (the adjoint system of a backward pass), like [`solve`]. For a symmetric
/// matrix this is the same solve, reusing the same cached factorization.
///
/// # Errors
/// As [`solve`].
pub fn solve_transpose(
    matrix: &SparseMatrix,
    rhs: &[f64],
    columns: usize,
    options: &SolveOptions,
) -> Result<(Vec<f64>, SolveStats), SolveError> {
    solve_impl(matrix, rhs, columns, options, true)
}

/// [`solve`] with `f32` right-hand sides and solutions (the tensors' type); the solve runs in
/// `f64`.
///
/// # Errors
/// As [`solve`], and [`SolveError::NonFinite`] when the solution overflows `f32`.
pub fn solve_f32(
    matrix: &SparseMatrix,
    rhs: &[f32],
    columns: usize,
    options: &SolveOptions,
) -> Result<(Vec<f32>, SolveStats), SolveError> {
    let rhs: Vec<f64> = rhs.iter().map(|&v| f64::from(v)).collect();
    let (x, stats) = solve(matrix, &rhs, columns, options)?;
    Ok((to_f32(&x)?, stats))
}

/// [`solve_transpose`] with `f32` right-hand sides and solutions.
///
/// # Errors
/// As [`solve_f32`].
pub fn solve_transpose_f32(
    matrix: &SparseMatrix,
    rhs: &[f32],
    columns: usize,
    options: &SolveOptions,
) -> Result<(Vec<f32>, SolveStats), SolveError> {
    let rhs: Vec<f64> = rhs.iter().map(|&v| f64::from(v)).collect();
    let (x, stats) = solve_transpose(matrix, &rhs, columns, options)?;
    Ok((to_f32(&x)?, stats))
}

fn to_f32(x: &[f64]) -> Result<Vec<f32>, SolveError> {
    let out: Vec<f32> = x.iter().map(|&v| v as f32).collect();
    if out.iter().all(|v| v.is_finite()) {
        Ok(out)
    } else {
        Err(SolveError::NonFinite {
            what: "the solution (as f32)".into(),
        })
    }
}

fn solve_impl(
    matrix: &SparseMatrix,
    rhs: &[f64],
    columns: usize,
    options: &SolveOptions,
    transpose: bool,
) -> Result<(Vec<f64>, SolveStats), SolveError> {
    let n = matrix.nrows();
    if matrix.ncols() != n {
        return Err(SolveError::DimensionMismatch {
            what: "columns of the (square) matrix".into(),
            expected: n,
            got: matrix.ncols(),
        });
    }
    if rhs.len() != n * columns {
        return Err(SolveError::DimensionMismatch {
            what: format!("right-hand side values for {columns} column(s)"),
            expected: n * columns,
            got: rhs.len(),
        });
    }
    if let Some(k) = rhs.iter().position(|v| !v.is_finite()) {
        return Err(SolveError::NonFinite {
            what: format!("the right-hand side (value {k} is {})", rhs[k]),
        });
    }
    if !(options.relative_tolerance >= 0.0 && options.absolute_tolerance >= 0.0) {
        return Err(SolveError::Invalid {
            reason: format!(
                "tolerances must be non-negative (relative {}, absolute {})",
                options.relative_tolerance, options.absolute_tolerance
            ),
        });
    }
    if n == 0 {
        return Ok((Vec::new(), SolveStats::default()));
    }
    let symmetric = matrix.is_symmetric();
    // The system actually solved: for a transposed solve of a non-symmetric matrix, Aᵀ.
    let transposed;
    let system: &SparseMatrix = if transpose && !symmetric {
        transposed = matrix.transpose();
        &transposed
    } else {
        matrix
    };
    let method = resolve_method(matrix, options.method);
    if matches!(
        method,
        SolveMethod::Cholesky | SolveMethod::ConjugateGradient(_)
    ) && !symmetric
    {
        return Err(SolveError::Invalid {
            reason: format!("{method:?} needs a symmetric matrix; use SolveMethod::Lu"),
        });
    }
    matrix.count_solves(columns);

    let mut solution = vec![0.0; n * columns];
    let mut stats = SolveStats::default();
    let mut column = vec![0.0; n];
    for c in 0..columns {
        for i in 0..n {
            column[i] = rhs[i * columns + c];
        }
        // Conjugate gradients return the residual they confirmed from the solution; the direct
        // methods' is computed here.
        let (x, iterations, residual) = match method {
            SolveMethod::ConjugateGradient(pre) => pcg(system, matrix, &column, options, pre)?,
            SolveMethod::Cholesky => {
                let x = matrix.cholesky()?.solve(&column);
                let residual = residual_norm(system, &x, &column);
                (x, 0, residual)
            }
            SolveMethod::Lu => {
                let x = matrix.lu()?.solve(&column, transpose);
                let residual = residual_norm(system, &x, &column);
                (x, 0, residual)
            }
            SolveMethod::Auto => unreachable!("resolved above"),
        };
        if !residual.is_finite() || x.iter().any(|v| !v.is_finite()) {
            return Err(SolveError::NonFinite {
                what: "the solution".into(),
            });
        }
        let tolerance = threshold(options, norm(&column));
        if residual > tolerance {
            return Err(SolveError::NotConverged {
                iterations,
                residual,
                tolerance,
            });
        }
        stats.iterations = stats.iterations.max(iterations);
        stats.residual = stats.residual.max(residual);
        for i in 0..n {
            solution[i * columns + c] = x[i];
        }
    }
    Ok((solution, stats))
}

/// The concrete method for `requested` on `matrix`.
fn resolve_method(matrix: &SparseMatrix, requested: SolveMethod) -> SolveMethod {
    if requested != SolveMethod::Auto {
        return requested;
    }
    if !matrix.is_symmetric() {
        return SolveMethod::Lu;
    }
    // A stencil M-matrix (Poisson matrices in any dimension): MIC(0) conjugate gradients. The
    // projection bench puts it 1.7×, 1.2–1.4× and 3× ahead of the sparse Cholesky factorization
    // at 32², 64² and 128² (a new mask each call), and 1.6× ahead of IC(0) CG at 64³; on a 64²
    // FLIP step's systems it takes ~22 iterations.
    // (A row with more far entries than the layout takes would leave MIC(0) to Jacobi.)
    if matrix.is_stencil_m_matrix() && matrix.split().is_some() {
        return SolveMethod::ConjugateGradient(Preconditioner::ModifiedIncompleteCholesky);
    }
    // Up to 5.5 entries per row: a 1-d or 2-d pattern, whose sparse Cholesky factor stays small
    // (nested-dissection-like fill, n log n), and factorising beats iterating even for a matrix
    // used once. More: a 3-d pattern, whose factor fills in heavily; use IC(0) CG. The test is
    // structural, so choosing costs nothing (a symbolic analysis to measure the fill costs as
    // much as the factorization of a fresh matrix).
    if matrix.nnz() as f64 <= 5.5 * matrix.nrows().max(1) as f64 {
        SolveMethod::Cholesky
    } else {
        SolveMethod::ConjugateGradient(Preconditioner::IncompleteCholesky)
    }
}

fn threshold(options: &SolveOptions, rhs_norm: f64) -> f64 {
    (options.relative_tolerance * rhs_norm).max(options.absolute_tolerance)
}

/// Independent partial sums of [`dot`]: a single running sum would chain every addition on
/// the previous one.
const LANES: usize = 8;

/// `aᵀ b`, summed in [`LANES`] interleaved partial sums.
fn dot(a: &[f64], b: &[f64]) -> f64 {
    let mut sums = [0.0; LANES];
    let (a_chunks, b_chunks) = (a.chunks_exact(LANES), b.chunks_exact(LANES));
    for (&a, &b) in a_chunks.remainder().iter().zip(b_chunks.remainder()) {
        sums[0] += a * b;
    }
    for (a, b) in a_chunks.zip(b_chunks) {
        for k in 0..LANES {
            sums[k] += a[k] * b[k];
        }
    }
    sums.iter().sum()
}

fn norm(a: &[f64]) -> f64 {
    dot(a, a).sqrt()
}

fn residual_norm(matrix: &SparseMatrix, x: &[f64], b: &[f64]) -> f64 {
    let ax = matrix.mul_vec(x);
    ax.iter()
        .zip(b)
        .map(|(y, b)| (b - y) * (b - y))
        .sum::<f64>()
        .sqrt()
}

/// The preconditioner actually used.
enum Precond {
    Identity,
    Jacobi(Vec<f64>),
    Ic(Arc<IncompleteCholesky>),
    Mic(Arc<ModifiedIncompleteCholesky>),
}

impl Precond {
    /// `z = M⁻¹ r`; returns `rᵀ z`.
    fn apply(&self, r: &[f64], z: &mut [f64]) -> f64 {
        match self {
            Precond::Identity => z.copy_from_slice(r),
            Precond::Jacobi(inverse) => {
                for ((z, r), d) in z.iter_mut().zip(r).zip(inverse) {
                    *z = r * d;
                }
            }
            Precond::Ic(ic) => ic.apply(r, z),
            Precond::Mic(mic) => return mic.apply(r, z),
        }
        dot(r, z)
    }
}

fn jacobi(matrix: &SparseMatrix) -> Result<Precond, SolveError> {
    let diagonal = matrix.diagonal();
    if let Some(i) = diagonal.iter().position(|&d| d <= 0.0) {
        return Err(SolveError::Invalid {
            reason: format!(
                "diagonal entry {i} is {}, so the matrix is not positive definite",
                diagonal[i]
            ),
        });
    }
    Ok(Precond::Jacobi(diagonal.iter().map(|d| 1.0 / d).collect()))
}

fn preconditioner(matrix: &SparseMatrix, kind: Preconditioner) -> Result<Precond, SolveError> {
    match kind {
        Preconditioner::None => Ok(Precond::Identity),
        Preconditioner::Jacobi => jacobi(matrix),
        Preconditioner::IncompleteCholesky => match matrix.incomplete_cholesky() {
            Some(ic) => Ok(Precond::Ic(ic)),
            None => jacobi(matrix),
        },
        Preconditioner::ModifiedIncompleteCholesky => match matrix.modified_incomplete_cholesky() {
            Some(mic) => Ok(Precond::Mic(mic)),
            None => jacobi(matrix),
        },
    }
}

/// Preconditioned conjugate gradients from `x = 0` on `system` (symmetric: `system` is
/// `matrix`, whose caches hold the preconditioner and the product's layout). Returns the solution,
/// the iterations and the residual `‖b − A x‖₂` computed from the solution.
fn pcg(
    system: &SparseMatrix,
    matrix: &SparseMatrix,
    b: &[f64],
    options: &SolveOptions,
    kind: Preconditioner,
) -> Result<(Vec<f64>, usize, f64), SolveError> {
    let n = b.len();
    let mut x = vec![0.0; n];
    let tolerance = threshold(options, norm(b));
    let mut r = b.to_vec();
    let mut residual = norm(&r);
    if residual <= tolerance {
        return Ok((x, 0, residual));
    }
    let precond = preconditioner(matrix, kind)?;
    let split = if std::ptr::eq(system, matrix) {
        matrix.split()
    } else {
        None
    };
    let product = |x: &[f64], y: &mut [f64]| match &split {
        Some(split) => split.mul_vec_into(x, y),
        None => system.mul_vec_into(x, y),
    };
    let mut z = vec![0.0; n];
    let mut q = vec![0.0; n];
    let mut rz = precond.apply(&r, &mut z);
    let mut p = z.clone();
    let mut iterations = 0;
    while iterations < options.max_iterations {
        iterations += 1;
        product(&p, &mut q);
        let pq = dot(&p, &q);
        if !pq.is_finite() || !rz.is_finite() {
            return Err(SolveError::NonFinite {
                what: "the conjugate-gradient iteration".into(),
            });
        }
        if pq <= 0.0 {
            return Err(SolveError::Invalid {
                reason: format!(
                    "conjugate gradients broke down (pᵀAp = {pq:e}): the matrix is not \
                     positive definite"
                ),
            });
        }
        let alpha = rz / pq;
        residual = update_and_norm(alpha, &p, &q, &mut x, &mut r);
        if residual <= tolerance {
            // The recursive residual drifts from the true one; confirm, else restart from it.
            product(&x, &mut q);
            for i in 0..n {
                r[i] = b[i] - q[i];
            }
            let true_residual = norm(&r);
            if true_residual <= tolerance {
                return Ok((x, iterations, true_residual));
            }
            residual = true_residual;
            rz = precond.apply(&r, &mut z);
            p.copy_from_slice(&z);
            continue;
        }
        let rz_next = precond.apply(&r, &mut z);
        let beta = rz_next / rz;
        rz = rz_next;
        for (p, z) in p.iter_mut().zip(&z) {
            *p = z + beta * *p;
        }
    }
    Err(SolveError::NotConverged {
        iterations,
        residual,
        tolerance,
    })
}

/// `x += α p`, `r −= α q`; returns `‖r‖₂`, summed in the same pass and in the same order as
/// [`dot`] sums (the remainder into the first lane, then whole blocks lane by lane).
fn update_and_norm(alpha: f64, p: &[f64], q: &[f64], x: &mut [f64], r: &mut [f64]) -> f64 {
    let n = r.len();
    assert!(p.len() == n && q.len() == n && x.len() == n);
    let whole = n - n % LANES;
    let mut sums = [0.0; LANES];
    for i in whole..n {
        x[i] += alpha * p[i];
        r[i] -= alpha * q[i];
        sums[0] += r[i] * r[i];
    }
    let blocks = x[..whole]
        .chunks_exact_mut(LANES)
        .zip(r[..whole].chunks_exact_mut(LANES))
        .zip(p.chunks_exact(LANES).zip(q.chunks_exact(LANES)));
    for ((x, r), (p, q)) in blocks {
        for k in 0..LANES {
            x[k] += alpha * p[k];
            r[k] -= alpha * q[k];
            sums[k] += r[k] * r[k];
        }
    }
    sums.iter().sum::<f64>().sqrt()
}

/// The adjoint solve of a backward pass, `Aᵀ y = g`, for `f32` gradients: first with `options`;
/// if that fails (an iterative method that does not converge on the adjoint right-hand side), once
/// more with a direct method (Cholesky for a symmetric matrix, LU otherwise).
///
/// # Errors
/// The direct solve's error when both fail.
pub fn adjoint_solve_f32(
    matrix: &SparseMatrix,
    grad: &[f32],
    columns: usize,
    options: &SolveOptions,
) -> Result<Vec<f32>, SolveError> {
    match solve_transpose_f32(matrix, grad, columns, options) {
        Ok((y, _)) => Ok(y),
        Err(SolveError::NotConverged { .. } | SolveError::Invalid { .. })
            if !matches!(options.method, SolveMethod::Cholesky | SolveMethod::Lu) =>
        {
            let method = if matrix.is_symmetric() {
                SolveMethod::Cholesky
            } else {
                SolveMethod::Lu
            };
            let direct = SolveOptions { method, ..*options };
            solve_transpose_f32(matrix, grad, columns, &direct).map(|(y, _)| y)
        }
        Err(err) => Err(err),
    }
}
