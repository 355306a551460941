//! The native (host, `f64`) solvers: preconditioned conjugate gradients, sparse Cholesky (faer's,
//! and our up-looking one for small matrices of a new pattern) and faer's sparse LU.

use std::sync::Arc;

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt::factor::LltRegularization;
use faer::linalg::solvers::Solve;
use faer::sparse::linalg::cholesky::{
    CholeskySymbolicParams, LltRef, SymbolicCholesky, SymmetricOrdering,
    factorize_symbolic_cholesky,
};
use faer::sparse::linalg::solvers::{Llt, Lu};
use faer::sparse::{SparseColMat, SparseColMatRef, SymbolicSparseColMatRef, Triplet};
use faer::{Conj, Mat, Par, Side};

use super::mic::{ModifiedIncompleteCholesky, SplitMatrix};
use super::sparse::SparseMatrix;
use super::up_looking::UpLookingCholesky;
use super::{Preconditioner, SolveError, SolveMethod, SolveOptions, SolveStats};

/// A cached sparse Cholesky factorization.
#[derive(Debug)]
pub(crate) enum CholeskyFactor {
    /// faer's, with its AMD ordering.
    Amd(Llt<usize, f64>),
    /// Our own simplicial up-looking factorization in the matrix's elimination order, without a
    /// symbolic analysis (see [`UpLookingCholesky`]): matrices of up to
    /// [`UP_LOOKING_MAX_UNKNOWNS`] rows.
    UpLooking(UpLookingCholesky),
    /// `P A Pᵀ = L Lᵀ` in the matrix's own elimination order (`order[k]`: the row eliminated
    /// `k`-th), through faer's symbolic and numeric factorizations with the identity ordering.
    Ordered {
        symbolic: Arc<SymbolicCholesky<usize>>,
        values: Vec<f64>,
        order: Arc<[usize]>,
    },
}

/// A cached sparse LU factorization.
#[derive(Debug)]
pub(crate) struct LuFactor(Lu<usize, f64>);

/// A zero-fill incomplete Cholesky factor `L` (lower triangle with the diagonal, CSR).
#[derive(Debug)]
pub(crate) struct IncompleteCholesky {
    row_ptr: Vec<usize>,
    cols: Vec<usize>,
    values: Vec<f64>,
}

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
                let x = cholesky(matrix)?.solve(&column);
                let residual = residual_norm(system, &x, &column);
                (x, 0, residual)
            }
            SolveMethod::Lu => {
                let x = lu(matrix)?.solve(&column, transpose);
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
    if matrix.is_stencil_m_matrix() && split_of(matrix).is_some() {
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

/// The lower triangle (with the diagonal) of a symmetric matrix as faer triplets, or every entry.
fn lower_triplets(matrix: &SparseMatrix, lower_only: bool) -> Vec<Triplet<usize, usize, f64>> {
    (0..matrix.nrows())
        .flat_map(|i| {
            matrix
                .row(i)
                .filter(move |&(j, _)| !lower_only || j <= i)
                .map(move |(j, v)| Triplet::new(i, j, v))
        })
        .collect()
}

pub(super) fn cholesky(matrix: &SparseMatrix) -> Result<Arc<CholeskyFactor>, SolveError> {
    matrix
        .cholesky
        .get_or_init(|| {
            matrix.count_factorization();
            let failed = |reason: String| SolveError::Factorization {
                method: "Cholesky",
                reason,
            };
            if let Some(order) = &matrix.ordering {
                if matrix.nrows() <= UP_LOOKING_MAX_UNKNOWNS && !seen_recently(matrix, order) {
                    return UpLookingCholesky::factorize(matrix, order)
                        .map(|f| Arc::new(CholeskyFactor::UpLooking(f)));
                }
                return ordered_cholesky(matrix, order.clone()).map(Arc::new);
            }
            let entries = lower_triplets(matrix, true);
            let a = SparseColMat::<usize, f64>::try_new_from_triplets(
                matrix.nrows(),
                matrix.ncols(),
                &entries,
            )
            .map_err(|e| failed(format!("{e:?}")))?;
            let llt = a
                .sp_cholesky(Side::Lower)
                .map_err(|e| failed(format!("{e} (is the matrix positive definite?)")))?;
            Ok(Arc::new(CholeskyFactor::Amd(llt)))
        })
        .clone()
}

fn lu(matrix: &SparseMatrix) -> Result<Arc<LuFactor>, SolveError> {
    matrix
        .lu
        .get_or_init(|| {
            matrix.count_factorization();
            let failed = |reason: String| SolveError::Factorization {
                method: "LU",
                reason,
            };
            let entries = lower_triplets(matrix, false);
            let a = SparseColMat::<usize, f64>::try_new_from_triplets(
                matrix.nrows(),
                matrix.ncols(),
                &entries,
            )
            .map_err(|e| failed(format!("{e:?}")))?;
            let lu = a.sp_lu().map_err(|e| failed(format!("{e:?}")))?;
            Ok(Arc::new(LuFactor(lu)))
        })
        .clone()
}

/// Up to this many unknowns, a matrix with an elimination order and a pattern not seen recently
/// is factorised by [`UpLookingCholesky`], which needs no symbolic analysis; larger ones, and
/// patterns that come again, by faer. Measured with `benches/fields.rs` (projection, a new
/// pattern each call): the up-looking factorization is faster at 32² (~500 unknowns, 17 %) and
/// level at 64² (~2000), faer's supernodal kernels win at 128² (~8000, 1.6×).
const UP_LOOKING_MAX_UNKNOWNS: usize = 3000;

/// Whether a matrix of the pattern and elimination order of `matrix` was factorised on this
/// thread recently; records it. A pattern that comes again (a liquid at rest) goes to faer,
/// whose symbolic analysis is then cached ([`cached_symbolic`]) and whose numeric factorization
/// is faster than the up-looking one; a new pattern (a moving liquid) is cheaper without the
/// analysis. The pattern is compared in full, so a hit is exact.
fn seen_recently(matrix: &SparseMatrix, order: &[usize]) -> bool {
    thread_local! {
        static SEEN: std::cell::RefCell<RecentPatterns<()>> =
            const { std::cell::RefCell::new(RecentPatterns::new()) };
    }
    let key: [&[usize]; 3] = [matrix.row_ptr(), matrix.col_indices(), order];
    SEEN.with_borrow_mut(|seen| {
        let hit = seen.get(&key).is_some();
        if !hit {
            seen.insert(&key, ());
        }
        hit
    })
}

/// The values of the [`RecentPatterns::KEPT`] most recently used keys (sparsity patterns, as
/// index arrays), most recent first: this thread's memory of the patterns it factorised. Keys
/// are compared in full, so a hit is exact.
struct RecentPatterns<V> {
    entries: Vec<(Vec<Vec<usize>>, V)>,
}

impl<V: Clone> RecentPatterns<V> {
    /// Patterns kept: a forward and an adjoint pattern, and a few regions in turn.
    const KEPT: usize = 4;

    const fn new() -> Self {
        Self {
            entries: Vec::new(),
        }
    }

    /// The value of `key`, which becomes the most recent.
    fn get(&mut self, key: &[&[usize]]) -> Option<V> {
        let same = |(k, _): &(Vec<Vec<usize>>, V)| {
            k.len() == key.len() && k.iter().zip(key).all(|(a, b)| a.as_slice() == *b)
        };
        let at = self.entries.iter().position(same)?;
        let entry = self.entries.remove(at);
        let value = entry.1.clone();
        self.entries.insert(0, entry);
        Some(value)
    }

    /// Remembers `value` for `key` as the most recent, forgetting the least recent beyond
    /// [`Self::KEPT`].
    fn insert(&mut self, key: &[&[usize]], value: V) {
        let key = key.iter().map(|k| k.to_vec()).collect();
        self.entries.insert(0, (key, value));
        self.entries.truncate(Self::KEPT);
    }
}

/// Below this many unknowns the factorization and solves run sequentially: spawning parallel
/// work costs more than it saves.
const PARALLEL_CHOLESKY_UNKNOWNS: usize = 20_000;

fn cholesky_parallelism(n: usize) -> Par {
    if n < PARALLEL_CHOLESKY_UNKNOWNS {
        Par::Seq
    } else {
        faer::get_global_parallelism()
    }
}

/// The Cholesky factorization of `P A Pᵀ` for the elimination order `order` (see
/// [`SparseMatrix::with_ordering`]): the upper triangle of the permuted matrix is assembled
/// column by column (each column's rows sorted), then factorised by faer without a further
/// ordering.
pub(super) fn ordered_cholesky(
    matrix: &SparseMatrix,
    order: Arc<[usize]>,
) -> Result<CholeskyFactor, SolveError> {
    let failed = |reason: String| SolveError::Factorization {
        method: "Cholesky",
        reason,
    };
    let n = matrix.nrows();
    let (col_ptr, row_idx, values) = permuted_upper(matrix, &order);
    let pattern = SymbolicSparseColMatRef::new_checked(n, n, &col_ptr, None, &row_idx);
    let upper = SparseColMatRef::new(pattern, &values);
    let symbolic = cached_symbolic(&col_ptr, &row_idx, || {
        factorize_symbolic_cholesky(
            pattern,
            Side::Upper,
            SymmetricOrdering::Identity,
            CholeskySymbolicParams::default(),
        )
        .map_err(|e| failed(format!("{e:?}")))
    })?;
    let par = cholesky_parallelism(n);
    let mut factor = vec![0.0; symbolic.len_val()];
    let mut scratch =
        MemBuffer::try_new(symbolic.factorize_numeric_llt_scratch::<f64>(par, Default::default()))
            .map_err(|e| failed(format!("{e:?}")))?;
    symbolic
        .factorize_numeric_llt(
            &mut factor,
            upper,
            Side::Upper,
            LltRegularization::default(),
            par,
            MemStack::new(&mut scratch),
            Default::default(),
        )
        .map_err(|e| failed(format!("{e} (is the matrix positive definite?)")))?;
    Ok(CholeskyFactor::Ordered {
        symbolic,
        values: factor,
        order,
    })
}

/// The symbolic factorization of the pattern `(col_ptr, row_idx)`, from this thread's cache of
/// the most recent patterns or through `analyse`. A pressure solve on an unchanged liquid region
/// (a pool at rest, a fixed domain) factorises matrices of one pattern again and again; for the
/// small matrices of 2D grids the analysis (elimination tree, column counts, the factor's
/// structure) costs about as much as the numeric factorization. The pattern is compared in full,
/// so a hit is exact. Patterns of more than `LARGEST` entries are not kept (their analysis is a
/// small part of the factorization, and the copies would be large).
fn cached_symbolic(
    col_ptr: &[usize],
    row_idx: &[usize],
    analyse: impl FnOnce() -> Result<SymbolicCholesky<usize>, SolveError>,
) -> Result<Arc<SymbolicCholesky<usize>>, SolveError> {
    const LARGEST: usize = 1 << 20;
    if row_idx.len() > LARGEST {
        return analyse().map(Arc::new);
    }
    thread_local! {
        static RECENT: std::cell::RefCell<RecentPatterns<Arc<SymbolicCholesky<usize>>>> =
            const { std::cell::RefCell::new(RecentPatterns::new()) };
    }
    let key: [&[usize]; 2] = [col_ptr, row_idx];
    if let Some(symbolic) = RECENT.with_borrow_mut(|recent| recent.get(&key)) {
        return Ok(symbolic);
    }
    let symbolic = Arc::new(analyse()?);
    RECENT.with_borrow_mut(|recent| recent.insert(&key, symbolic.clone()));
    Ok(symbolic)
}

/// The upper triangle of `P A Pᵀ` for a symmetric `A` as CSC arrays (column pointers, row
/// indices sorted within each column, values): column `k` holds the entries of row `order[k]`
/// of `A` whose new index is at most `k`.
fn permuted_upper(matrix: &SparseMatrix, order: &[usize]) -> (Vec<usize>, Vec<usize>, Vec<f64>) {
    let n = matrix.nrows();
    let mut position = vec![0usize; n];
    for (k, &row) in order.iter().enumerate() {
        position[row] = k;
    }
    let mut col_ptr = Vec::with_capacity(n + 1);
    let mut row_idx = Vec::with_capacity(matrix.nnz() / 2 + n);
    let mut values = Vec::with_capacity(matrix.nnz() / 2 + n);
    let mut column: Vec<(usize, f64)> = Vec::new();
    col_ptr.push(0);
    for (k, &row) in order.iter().enumerate() {
        column.clear();
        column.extend(
            matrix
                .row(row)
                .map(|(j, v)| (position[j], v))
                .filter(|&(i, _)| i <= k),
        );
        column.sort_unstable_by_key(|&(i, _)| i);
        for &(i, v) in &column {
            row_idx.push(i);
            values.push(v);
        }
        col_ptr.push(row_idx.len());
    }
    (col_ptr, row_idx, values)
}

/// Entries of the Cholesky factor of a symmetric `matrix` under faer's AMD ordering.
#[cfg(test)]
pub(super) fn amd_factor_entries(matrix: &SparseMatrix) -> usize {
    let n = matrix.nrows();
    let identity: Vec<usize> = (0..n).collect();
    let (col_ptr, row_idx, _) = permuted_upper(matrix, &identity);
    let pattern = SymbolicSparseColMatRef::new_checked(n, n, &col_ptr, None, &row_idx);
    factorize_symbolic_cholesky(
        pattern,
        Side::Upper,
        SymmetricOrdering::Amd,
        CholeskySymbolicParams::default(),
    )
    .expect("a valid pattern")
    .len_val()
}

impl CholeskyFactor {
    /// Stored entries of the factor `L` (its fill), for a factor in the matrix's own order.
    #[cfg(test)]
    pub(super) fn factor_entries(&self) -> Option<usize> {
        match self {
            CholeskyFactor::Amd(_) => None,
            CholeskyFactor::UpLooking(factor) => Some(factor.entries()),
            CholeskyFactor::Ordered { symbolic, .. } => Some(symbolic.len_val()),
        }
    }

    fn solve(&self, b: &[f64]) -> Vec<f64> {
        match self {
            CholeskyFactor::Amd(llt) => {
                let mut x = Mat::<f64>::from_fn(b.len(), 1, |i, _| b[i]);
                llt.solve_in_place(&mut x);
                (0..b.len()).map(|i| x[(i, 0)]).collect()
            }
            CholeskyFactor::UpLooking(factor) => factor.solve(b),
            CholeskyFactor::Ordered {
                symbolic,
                values,
                order,
            } => {
                // P A Pᵀ (P x) = P b.
                let n = b.len();
                let mut y = Mat::<f64>::from_fn(n, 1, |k, _| b[order[k]]);
                let par = cholesky_parallelism(n);
                let mut scratch = MemBuffer::new(symbolic.solve_in_place_scratch::<f64>(1, par));
                LltRef::new(symbolic, values).solve_in_place_with_conj(
                    Conj::No,
                    y.as_mut(),
                    par,
                    MemStack::new(&mut scratch),
                );
                let mut x = vec![0.0; n];
                for (k, &row) in order.iter().enumerate() {
                    x[row] = y[(k, 0)];
                }
                x
            }
        }
    }
}

impl LuFactor {
    fn solve(&self, b: &[f64], transpose: bool) -> Vec<f64> {
        let mut x = Mat::<f64>::from_fn(b.len(), 1, |i, _| b[i]);
        if transpose {
            self.0.solve_transpose_in_place(&mut x);
        } else {
            self.0.solve_in_place(&mut x);
        }
        (0..b.len()).map(|i| x[(i, 0)]).collect()
    }
}

impl IncompleteCholesky {
    /// IC(0) of a symmetric matrix, or `None` where a pivot is not positive.
    fn new(matrix: &SparseMatrix) -> Option<Self> {
        let n = matrix.nrows();
        let mut row_ptr = Vec::with_capacity(n + 1);
        let mut cols = Vec::new();
        let mut values = Vec::new();
        row_ptr.push(0);
        for i in 0..n {
            for (j, v) in matrix.row(i).filter(|&(j, _)| j <= i) {
                cols.push(j);
                values.push(v);
            }
            row_ptr.push(cols.len());
        }
        // Row-oriented IC(0): L[i,k] = (A[i,k] − Σ_{j<k} L[i,j] L[k,j]) / L[k,k], L[i,i] = √(A[i,i]
        // − Σ_{j<i} L[i,j]²), keeping only the pattern of the lower triangle of A.
        for i in 0..n {
            let (start, end) = (row_ptr[i], row_ptr[i + 1]);
            for p in start..end {
                let k = cols[p];
                // Sparse dot product of rows i and k over columns below k.
                let (mut a, mut b) = (start, row_ptr[k]);
                let (a_end, b_end) = (p, row_ptr[k + 1]);
                let mut sum = 0.0;
                while a < a_end && b < b_end {
                    let (ca, cb) = (cols[a], cols[b]);
                    if ca >= k || cb >= k {
                        break;
                    }
                    match ca.cmp(&cb) {
                        std::cmp::Ordering::Less => a += 1,
                        std::cmp::Ordering::Greater => b += 1,
                        std::cmp::Ordering::Equal => {
                            sum += values[a] * values[b];
                            a += 1;
                            b += 1;
                        }
                    }
                }
                if k == i {
                    let pivot = values[p] - sum;
                    if pivot <= 0.0 || !pivot.is_finite() {
                        return None;
                    }
                    values[p] = pivot.sqrt();
                } else {
                    let diag = values[row_ptr[k + 1] - 1];
                    values[p] = (values[p] - sum) / diag;
                }
            }
            if end == start || cols[end - 1] != i {
                return None; // no diagonal entry
            }
        }
        Some(Self {
            row_ptr,
            cols,
            values,
        })
    }

    /// `z = (L Lᵀ)⁻¹ r`.
    fn apply(&self, r: &[f64], z: &mut [f64]) {
        let n = r.len();
        // L y = r
        for i in 0..n {
            let (start, end) = (self.row_ptr[i], self.row_ptr[i + 1]);
            let mut sum = r[i];
            for p in start..end - 1 {
                sum -= self.values[p] * z[self.cols[p]];
            }
            z[i] = sum / self.values[end - 1];
        }
        // Lᵀ z = y, column-oriented over the rows of L.
        for i in (0..n).rev() {
            let (start, end) = (self.row_ptr[i], self.row_ptr[i + 1]);
            z[i] /= self.values[end - 1];
            let zi = z[i];
            for p in start..end - 1 {
                z[self.cols[p]] -= self.values[p] * zi;
            }
        }
    }
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
        Preconditioner::IncompleteCholesky => {
            let ic = matrix
                .ic0
                .get_or_init(|| {
                    matrix.count_factorization();
                    IncompleteCholesky::new(matrix).map(Arc::new)
                })
                .clone();
            match ic {
                Some(ic) => Ok(Precond::Ic(ic)),
                None => jacobi(matrix),
            }
        }
        Preconditioner::ModifiedIncompleteCholesky => {
            let mic = matrix
                .mic0
                .get_or_init(|| {
                    matrix.count_factorization();
                    split_of(matrix)
                        .and_then(|split| ModifiedIncompleteCholesky::new(&split).map(Arc::new))
                })
                .clone();
            match mic {
                Some(mic) => Ok(Precond::Mic(mic)),
                None => jacobi(matrix),
            }
        }
    }
}

/// The product layout of a symmetric `matrix` ([`SplitMatrix`]), built once and cached; `None`
/// where its rows do not fit.
fn split_of(matrix: &SparseMatrix) -> Option<Arc<SplitMatrix>> {
    matrix
        .split
        .get_or_init(|| SplitMatrix::new(matrix).map(Arc::new))
        .clone()
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
        split_of(matrix)
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
