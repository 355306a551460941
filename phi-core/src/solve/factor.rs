//! Factorizations of a CSR matrix, computed once per matrix and cached by
//! [`super::SparseMatrix`]: sparse Cholesky (faer's, or our up-looking one for small matrices of a
//! new pattern), faer's sparse LU, and zero-fill incomplete Cholesky, IC(0).

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

use super::SolveError;
use super::csr::CsrRef;
use super::up_looking::UpLookingCholesky;

/// A sparse Cholesky factorization `A = L Lᵀ` of a symmetric positive definite matrix.
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

/// A sparse LU factorization with partial pivoting.
#[derive(Debug)]
pub(crate) struct LuFactor(Lu<usize, f64>);

/// A zero-fill incomplete Cholesky factor `L` (lower triangle with the diagonal, CSR).
#[derive(Debug)]
pub(crate) struct IncompleteCholesky {
    row_ptr: Vec<usize>,
    cols: Vec<usize>,
    values: Vec<f64>,
}

/// The lower triangle (with the diagonal) of a symmetric matrix as faer triplets, or every entry.
fn lower_triplets(matrix: CsrRef<'_>, lower_only: bool) -> Vec<Triplet<usize, usize, f64>> {
    (0..matrix.nrows())
        .flat_map(|i| {
            matrix
                .row(i)
                .filter(move |&(j, _)| !lower_only || j <= i)
                .map(move |(j, v)| Triplet::new(i, j, v))
        })
        .collect()
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
fn seen_recently(matrix: CsrRef<'_>, order: &[usize]) -> bool {
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
/// [`super::SparseMatrix::with_ordering`]): the upper triangle of the permuted matrix is assembled
/// column by column (each column's rows sorted), then factorised by faer without a further
/// ordering.
pub(super) fn ordered_cholesky(
    matrix: CsrRef<'_>,
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
fn permuted_upper(matrix: CsrRef<'_>, order: &[usize]) -> (Vec<usize>, Vec<usize>, Vec<f64>) {
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
pub(super) fn amd_factor_entries(matrix: CsrRef<'_>) -> usize {
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
    /// The Cholesky factorization of the symmetric `matrix`: in its elimination order
    /// `ordering` where it has one (ours up-looking for a small matrix of a pattern not seen
    /// recently, faer's otherwise), else faer's with an AMD ordering.
    ///
    /// # Errors
    /// [`SolveError::Factorization`] when the matrix is not positive definite.
    pub(crate) fn factorize(
        matrix: CsrRef<'_>,
        ordering: Option<&Arc<[usize]>>,
    ) -> Result<Self, SolveError> {
        let failed = |reason: String| SolveError::Factorization {
            method: "Cholesky",
            reason,
        };
        if let Some(order) = ordering {
            if matrix.nrows() <= UP_LOOKING_MAX_UNKNOWNS && !seen_recently(matrix, order) {
                return UpLookingCholesky::factorize(matrix, order).map(CholeskyFactor::UpLooking);
            }
            return ordered_cholesky(matrix, order.clone());
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
        Ok(CholeskyFactor::Amd(llt))
    }

    /// Stored entries of the factor `L` (its fill), for a factor in the matrix's own order.
    #[cfg(test)]
    pub(super) fn factor_entries(&self) -> Option<usize> {
        match self {
            CholeskyFactor::Amd(_) => None,
            CholeskyFactor::UpLooking(factor) => Some(factor.entries()),
            CholeskyFactor::Ordered { symbolic, .. } => Some(symbolic.len_val()),
        }
    }

    /// `x = A⁻¹ b`.
    pub(crate) fn solve(&self, b: &[f64]) -> Vec<f64> {
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
    /// faer's sparse LU factorization of the square `matrix`.
    ///
    /// # Errors
    /// [`SolveError::Factorization`] when the matrix is singular.
    pub(crate) fn factorize(matrix: CsrRef<'_>) -> Result<Self, SolveError> {
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
        Ok(LuFactor(lu))
    }

    /// `x = A⁻¹ b`, or `x = A⁻ᵀ b` with `transpose`.
    pub(crate) fn solve(&self, b: &[f64], transpose: bool) -> Vec<f64> {
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
    pub(crate) fn new(matrix: CsrRef<'_>) -> Option<Self> {
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
    pub(crate) fn apply(&self, r: &[f64], z: &mut [f64]) {
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
