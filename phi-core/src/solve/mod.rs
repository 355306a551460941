//! Sparse linear solves: the pressure projection's Poisson equation and any other sparse system.
//!
//! - [`SparseMatrix`]: a host-side CSR matrix in `f64`.
//! - [`solve`] / [`solve_transpose`]: native solvers (preconditioned conjugate gradients,
//!   faer's sparse Cholesky and LU) with [`SolveOptions`] and [`SolveStats`]; failures, including
//!   non-convergence, are [`SolveError`] values, never a silently wrong result.
//! - [`PoissonSystem::assemble`]: the masked negative Laplacian of FLIP's pressure projection on
//!   a [`PoissonGrid`] (plain numbers: resolution, cell sizes, open sides).
//! - [`crate::backend::Backend::float_linear_solve`] and [`crate::tensor::Tensor::linear_solve`]:
//!   the same solves on backend tensors. On the autodiff backends the solve is differentiated
//!   implicitly with respect to the right-hand side: `∂L/∂b = A⁻ᵀ ∂L/∂x`, one adjoint solve, not
//!   unrolled iterations. The matrix is a constant (masks are not differentiated, as in Φ_Flow).
//!
//! # Why `f64`
//! Tensors are `f32`, but the matrix, the iterations and the factorizations are `f64`: the
//! condition number of the Poisson matrix grows like `n²` (about 10⁴ at 128², 2·10³ at 64³), so an
//! `f32` conjugate-gradient loop stagnates near relative residuals of 10⁻⁴–10⁻⁵ — just where the
//! default tolerance sits — and an `f32` Cholesky factor loses most of its digits. On the host the
//! wider type costs little (the matrix is memory-bound either way), and it makes the implicit
//! gradients accurate enough to check against finite differences. Right-hand sides are converted
//! on the way in and solutions rounded to `f32` on the way out.
//!
//! # Which method
//! [`SolveMethod::Auto`] (the default) uses conjugate gradients with a modified incomplete
//! Cholesky preconditioner, MIC(0), for stencil M-matrices (Poisson matrices on grids of any
//! dimension, [`SparseMatrix::is_stencil_m_matrix`]); for other symmetric matrices, faer's sparse
//! Cholesky where the factor stays small (up to 5.5 entries per row) and IC(0) conjugate
//! gradients otherwise; LU for matrices that are not symmetric. Factorizations and
//! preconditioners are cached in the matrix, so the adjoint solve of a backward pass (and any
//! later solve with the same matrix) reuses them. `benches/fields.rs` (projection with each
//! method, a new liquid mask each call) supports the choice: MIC(0) CG is 1.7×, 1.2–1.4× and 3×
//! faster than the sparse Cholesky factorization at 32², 64² and 128², and 1.6× faster than
//! IC(0) CG at 64³. The factorization stays the method for an exact solve (to rounding) and for
//! many solves with one matrix, which reuse the factor.
//!
//! # Files
//! Each file imports only from those listed before it:
//! - `csr`: a borrowed view of a CSR matrix, what the factorizations read;
//! - `up_looking` (our sparse Cholesky), `mic` (MIC(0) and the product's layout) and `factor`
//!   (faer's Cholesky and LU, IC(0); it picks `up_looking` for small matrices): factorizations
//!   of that view;
//! - `sparse`: [`SparseMatrix`], which owns the arrays and caches those factorizations;
//! - `native` (the solves: the choice of method, conjugate gradients, the direct solves) and
//!   `poisson` (the pressure projection's matrix on a [`PoissonGrid`]).
//!
//! This file holds the options and errors they share. The module knows nothing of `fields`: the
//! fields layer uses it, translating its domains into [`PoissonGrid`]s.

mod csr;
mod factor;
mod mic;
mod native;
mod poisson;
mod sparse;
mod up_looking;

pub use native::{adjoint_solve_f32, solve, solve_f32, solve_transpose, solve_transpose_f32};
pub use poisson::{PoissonGrid, PoissonSystem, Weight, grid_elimination_order};
pub use sparse::SparseMatrix;

use thiserror::Error;

use crate::error::TensorError;

/// How to solve a system.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum SolveMethod {
    /// MIC(0) conjugate gradients for a stencil M-matrix (Poisson matrices); for other
    /// symmetric matrices, sparse Cholesky with at most 5.5 entries per row and IC(0) conjugate
    /// gradients with more; LU for a matrix that is not symmetric.
    #[default]
    Auto,
    /// Conjugate gradients with a preconditioner; the matrix must be symmetric positive
    /// definite. Obeys `max_iterations`.
    ConjugateGradient(Preconditioner),
    /// Sparse Cholesky (`LLᵀ`): faer's supernodal/simplicial factorization with an AMD ordering,
    /// or, for a matrix with its own elimination order ([`SparseMatrix::with_ordering`]), our
    /// up-looking factorization (small matrices of a new pattern) or faer's in that order. The
    /// matrix must be symmetric positive definite. Direct: `max_iterations` does not apply.
    Cholesky,
    /// faer's sparse LU with partial pivoting, for any square non-singular matrix. Direct.
    Lu,
}

/// The preconditioner of [`SolveMethod::ConjugateGradient`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum Preconditioner {
    /// Plain conjugate gradients.
    None,
    /// Division by the diagonal.
    Jacobi,
    /// Zero-fill incomplete Cholesky, IC(0), on the matrix's own sparsity pattern. Exists for
    /// M-matrices such as the Poisson matrix; where a pivot breaks down, the solve falls back to
    /// Jacobi.
    #[default]
    IncompleteCholesky,
    /// Modified incomplete Cholesky, MIC(0): IC(0) whose dropped fill goes to the diagonal, so
    /// that the preconditioner keeps the matrix's row sums. On Poisson matrices it needs about
    /// half IC(0)'s iterations (their count grows like the square root of the grid's side
    /// instead of like the side). Where it cannot be built, the solve falls back to Jacobi.
    ModifiedIncompleteCholesky,
}

/// Options of a linear solve. The solve has converged when `‖b − A x‖₂ ≤ max(relative_tolerance ·
/// ‖b‖₂, absolute_tolerance)` for every right-hand side; direct methods are held to the same test.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SolveOptions {
    /// Residual bound relative to `‖b‖₂` (default `1e-5`).
    pub relative_tolerance: f64,
    /// Absolute residual bound (default `0`).
    pub absolute_tolerance: f64,
    /// Iteration limit of iterative methods (default `1000`).
    pub max_iterations: usize,
    /// The method (default [`SolveMethod::Auto`]).
    pub method: SolveMethod,
}

impl Default for SolveOptions {
    fn default() -> Self {
        Self {
            relative_tolerance: 1e-5,
            absolute_tolerance: 0.0,
            max_iterations: 1000,
            method: SolveMethod::Auto,
        }
    }
}

impl SolveOptions {
    /// The default options with `method`.
    pub fn with_method(method: SolveMethod) -> Self {
        Self {
            method,
            ..Self::default()
        }
    }
}

/// What a successful solve did. With several right-hand sides, the largest over them.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SolveStats {
    /// Iterations of an iterative method; `0` for a direct one.
    pub iterations: usize,
    /// The final residual `‖b − A x‖₂`, recomputed from the solution.
    pub residual: f64,
}

/// Why a solve failed.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum SolveError {
    /// The residual did not reach the tolerance.
    #[error(
        "the linear solve did not converge: residual {residual:e} after {iterations} iterations, \
         tolerance {tolerance:e}"
    )]
    NotConverged {
        iterations: usize,
        residual: f64,
        tolerance: f64,
    },
    /// A NaN or an infinity in an input or in the result.
    #[error("non-finite values in {what}")]
    NonFinite { what: String },
    /// Sizes that do not fit together.
    #[error("{what}: expected {expected}, got {got}")]
    DimensionMismatch {
        what: String,
        expected: usize,
        got: usize,
    },
    /// An invalid matrix or a method that does not apply to it (an index out of range, CG or
    /// Cholesky on a matrix that is not symmetric, ...).
    #[error("invalid linear system: {reason}")]
    Invalid { reason: String },
    /// A factorization failed (the matrix is singular or not positive definite).
    #[error("the {method} factorization failed: {reason}")]
    Factorization {
        method: &'static str,
        reason: String,
    },
    /// An error of the tensor layer (shapes of backend tensors, the engine underneath).
    #[error(transparent)]
    Tensor(#[from] TensorError),
}

/// Also the home of helpers that the tests of the layers above share.
#[cfg(test)]
pub(crate) mod tests;
