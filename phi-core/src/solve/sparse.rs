//! [`SparseMatrix`]: compressed sparse rows in `f64`, with cached factorizations.
//!
//! The factorizations and preconditioners ([`super::factor`], [`super::mic`]) read the matrix
//! through a borrowed view ([`CsrRef`]); this file owns the arrays and keeps what they compute,
//! so the imports point one way: the view, then the factorizations, then the matrix.

use std::fmt;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, OnceLock};

use super::SolveError;
use super::csr::CsrRef;
use super::factor::{CholeskyFactor, IncompleteCholesky, LuFactor};
use super::mic::{ModifiedIncompleteCholesky, SplitMatrix};

/// A sparse matrix in compressed sparse row (CSR) form with `f64` values.
///
/// Rows are stored one after the other: the entries of row `i` are `col_indices[row_ptr[i]..
/// row_ptr[i + 1]]` (sorted, no duplicates) with `values` alongside. The matrix is immutable once
/// built; factorizations, preconditioners and the transpose are computed on first use and cached,
/// so share it as an `Arc<SparseMatrix>` and every solve with it (forward and adjoint) reuses them.
pub struct SparseMatrix {
    nrows: usize,
    ncols: usize,
    row_ptr: Vec<usize>,
    col_indices: Vec<usize>,
    values: Vec<f64>,
    symmetric: OnceLock<bool>,
    stencil_m_matrix: OnceLock<bool>,
    transpose: OnceLock<Arc<SparseMatrix>>,
    cholesky: OnceLock<Result<Arc<CholeskyFactor>, SolveError>>,
    lu: OnceLock<Result<Arc<LuFactor>, SolveError>>,
    ic0: OnceLock<Option<Arc<IncompleteCholesky>>>,
    mic0: OnceLock<Option<Arc<ModifiedIncompleteCholesky>>>,
    /// The layout of the conjugate-gradient product, where the rows fit it.
    split: OnceLock<Option<Arc<SplitMatrix>>>,
    /// A fill-reducing elimination order for the Cholesky factorization (see
    /// [`SparseMatrix::with_ordering`]); `None`: faer computes an AMD ordering.
    ordering: Option<Arc<[usize]>>,
    solves: AtomicUsize,
    factorizations: AtomicUsize,
}

impl Clone for SparseMatrix {
    /// A copy of the entries and the elimination order; caches and counters start afresh.
    fn clone(&self) -> Self {
        let mut copy = Self::from_parts(
            self.nrows,
            self.ncols,
            self.row_ptr.clone(),
            self.col_indices.clone(),
            self.values.clone(),
        );
        copy.ordering = self.ordering.clone();
        copy
    }
}

impl fmt::Debug for SparseMatrix {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("SparseMatrix")
            .field("nrows", &self.nrows)
            .field("ncols", &self.ncols)
            .field("nnz", &self.nnz())
            .finish()
    }
}

impl PartialEq for SparseMatrix {
    /// Equal shapes and entries (caches are not compared).
    fn eq(&self, other: &Self) -> bool {
        self.nrows == other.nrows
            && self.ncols == other.ncols
            && self.row_ptr == other.row_ptr
            && self.col_indices == other.col_indices
            && self.values == other.values
    }
}

impl SparseMatrix {
    fn from_parts(
        nrows: usize,
        ncols: usize,
        row_ptr: Vec<usize>,
        col_indices: Vec<usize>,
        values: Vec<f64>,
    ) -> Self {
        Self {
            nrows,
            ncols,
            row_ptr,
            col_indices,
            values,
            symmetric: OnceLock::new(),
            stencil_m_matrix: OnceLock::new(),
            transpose: OnceLock::new(),
            cholesky: OnceLock::new(),
            lu: OnceLock::new(),
            ic0: OnceLock::new(),
            mic0: OnceLock::new(),
            split: OnceLock::new(),
            ordering: None,
            solves: AtomicUsize::new(0),
            factorizations: AtomicUsize::new(0),
        }
    }

    /// A matrix from `(row, column, value)` entries; repeated positions are summed.
    ///
    /// # Errors
    /// [`SolveError::Invalid`] for an index out of range, [`SolveError::NonFinite`] for a NaN or
    /// infinite value.
    pub fn from_triplets(
        nrows: usize,
        ncols: usize,
        triplets: &[(usize, usize, f64)],
    ) -> Result<Self, SolveError> {
        let mut counts = vec![0usize; nrows + 1];
        for &(row, col, value) in triplets {
            if row >= nrows || col >= ncols {
                return Err(SolveError::Invalid {
                    reason: format!("entry ({row}, {col}) lies outside a {nrows}×{ncols} matrix"),
                });
            }
            if !value.is_finite() {
                return Err(SolveError::NonFinite {
                    what: format!("matrix entry ({row}, {col})"),
                });
            }
            counts[row + 1] += 1;
        }
        for i in 0..nrows {
            counts[i + 1] += counts[i];
        }
        let mut next = counts.clone();
        let mut entries = vec![(0usize, 0.0f64); triplets.len()];
        for &(row, col, value) in triplets {
            entries[next[row]] = (col, value);
            next[row] += 1;
        }
        let mut row_ptr = Vec::with_capacity(nrows + 1);
        let mut col_indices = Vec::with_capacity(triplets.len());
        let mut values = Vec::with_capacity(triplets.len());
        row_ptr.push(0);
        for i in 0..nrows {
            let row = &mut entries[counts[i]..counts[i + 1]];
            row.sort_unstable_by_key(|&(col, _)| col);
            for &(col, value) in row.iter() {
                if col_indices.len() > row_ptr[i] && col_indices.last() == Some(&col) {
                    *values.last_mut().expect("an entry was pushed") += value;
                } else {
                    col_indices.push(col);
                    values.push(value);
                }
            }
            row_ptr.push(col_indices.len());
        }
        Ok(Self::from_parts(nrows, ncols, row_ptr, col_indices, values))
    }

    /// A matrix from CSR arrays (see the type's docs); within a row, column indices must be
    /// strictly increasing.
    ///
    /// # Errors
    /// [`SolveError::Invalid`] for inconsistent arrays, [`SolveError::NonFinite`] for a NaN or
    /// infinite value.
    pub fn from_csr(
        nrows: usize,
        ncols: usize,
        row_ptr: Vec<usize>,
        col_indices: Vec<usize>,
        values: Vec<f64>,
    ) -> Result<Self, SolveError> {
        let invalid = |reason: String| Err(SolveError::Invalid { reason });
        if row_ptr.len() != nrows + 1 || row_ptr[0] != 0 {
            return invalid(format!(
                "row_ptr must have {} entries starting at 0",
                nrows + 1
            ));
        }
        if row_ptr[nrows] != col_indices.len() || col_indices.len() != values.len() {
            return invalid(format!(
                "row_ptr ends at {}, with {} column indices and {} values",
                row_ptr[nrows],
                col_indices.len(),
                values.len()
            ));
        }
        for i in 0..nrows {
            if row_ptr[i] > row_ptr[i + 1] {
                return invalid(format!("row_ptr decreases at row {i}"));
            }
            let row = &col_indices[row_ptr[i]..row_ptr[i + 1]];
            if row.windows(2).any(|w| w[0] >= w[1]) || row.last().is_some_and(|&c| c >= ncols) {
                return invalid(format!(
                    "row {i}: column indices must increase strictly and stay below {ncols}"
                ));
            }
        }
        check_finite(&values)?;
        Ok(Self::from_parts(nrows, ncols, row_ptr, col_indices, values))
    }

    /// [`from_csr`](Self::from_csr) for rows assembled by this crate, whose structure is right by
    /// construction (checked in debug builds): only the values are checked.
    ///
    /// # Errors
    /// [`SolveError::NonFinite`] for a NaN or infinite value.
    pub(crate) fn from_assembled_csr(
        nrows: usize,
        ncols: usize,
        row_ptr: Vec<usize>,
        col_indices: Vec<usize>,
        values: Vec<f64>,
    ) -> Result<Self, SolveError> {
        if cfg!(debug_assertions) {
            return Self::from_csr(nrows, ncols, row_ptr, col_indices, values);
        }
        check_finite(&values)?;
        Ok(Self::from_parts(nrows, ncols, row_ptr, col_indices, values))
    }

    /// A dense row-major matrix's non-zero entries as a sparse matrix (for tests and small
    /// systems).
    ///
    /// # Errors
    /// As [`SparseMatrix::from_triplets`], and [`SolveError::DimensionMismatch`] when `dense`
    /// does not hold `nrows · ncols` values.
    pub fn from_dense(nrows: usize, ncols: usize, dense: &[f64]) -> Result<Self, SolveError> {
        if dense.len() != nrows * ncols {
            return Err(SolveError::DimensionMismatch {
                what: "dense matrix values".into(),
                expected: nrows * ncols,
                got: dense.len(),
            });
        }
        let triplets: Vec<(usize, usize, f64)> = (0..nrows)
            .flat_map(|i| (0..ncols).map(move |j| (i, j)))
            .filter(|&(i, j)| dense[i * ncols + j] != 0.0)
            .map(|(i, j)| (i, j, dense[i * ncols + j]))
            .collect();
        Self::from_triplets(nrows, ncols, &triplets)
    }

    /// Number of rows.
    pub fn nrows(&self) -> usize {
        self.nrows
    }

    /// Number of columns.
    pub fn ncols(&self) -> usize {
        self.ncols
    }

    /// Number of stored entries.
    pub(crate) fn nnz(&self) -> usize {
        self.values.len()
    }

    /// Row start offsets (`nrows + 1` entries).
    pub fn row_ptr(&self) -> &[usize] {
        &self.row_ptr
    }

    /// Column index of each stored entry.
    pub fn col_indices(&self) -> &[usize] {
        &self.col_indices
    }

    /// Value of each stored entry.
    pub fn values(&self) -> &[f64] {
        &self.values
    }

    /// The stored entries of row `i` as `(column, value)` pairs.
    #[inline]
    pub fn row(&self, i: usize) -> impl Iterator<Item = (usize, f64)> + '_ {
        self.csr().row(i)
    }

    /// The matrix as a borrowed view, what the factorizations read.
    #[inline]
    pub(crate) fn csr(&self) -> CsrRef<'_> {
        CsrRef::new(
            self.nrows,
            self.ncols,
            &self.row_ptr,
            &self.col_indices,
            &self.values,
        )
    }

    /// Entry `(i, j)`, zero where nothing is stored.
    pub fn get(&self, i: usize, j: usize) -> f64 {
        let range = self.row_ptr[i]..self.row_ptr[i + 1];
        match self.col_indices[range.clone()].binary_search(&j) {
            Ok(k) => self.values[range.start + k],
            Err(_) => 0.0,
        }
    }

    /// The diagonal (`min(nrows, ncols)` entries).
    pub fn diagonal(&self) -> Vec<f64> {
        (0..self.nrows.min(self.ncols))
            .map(|i| self.get(i, i))
            .collect()
    }

    /// `y = A x`.
    ///
    /// # Panics
    /// When `x` does not have `ncols` entries or `y` not `nrows`.
    pub(crate) fn mul_vec_into(&self, x: &[f64], y: &mut [f64]) {
        assert_eq!(x.len(), self.ncols, "mul_vec: x has the wrong length");
        assert_eq!(y.len(), self.nrows, "mul_vec: y has the wrong length");
        for (i, out) in y.iter_mut().enumerate() {
            let mut sum = 0.0;
            for k in self.row_ptr[i]..self.row_ptr[i + 1] {
                sum += self.values[k] * x[self.col_indices[k]];
            }
            *out = sum;
        }
    }

    /// `A x` as a new vector.
    ///
    /// # Panics
    /// When `x` does not have `ncols` entries.
    pub fn mul_vec(&self, x: &[f64]) -> Vec<f64> {
        let mut y = vec![0.0; self.nrows];
        self.mul_vec_into(x, &mut y);
        y
    }

    /// `Aᵀ`, computed once and cached.
    pub fn transpose(&self) -> Arc<SparseMatrix> {
        self.transpose
            .get_or_init(|| {
                let triplets: Vec<(usize, usize, f64)> = (0..self.nrows)
                    .flat_map(|i| self.row(i).map(move |(j, v)| (j, i, v)))
                    .collect();
                Arc::new(
                    Self::from_triplets(self.ncols, self.nrows, &triplets)
                        .expect("the transpose of a valid matrix is valid"),
                )
            })
            .clone()
    }

    /// Whether the matrix is a weakly diagonally dominant M-matrix with short rows: positive
    /// diagonal entries, no positive entry off the diagonal, each diagonal entry at least its
    /// row's off-diagonal magnitudes, and at most 11 entries per row. Poisson matrices on grids
    /// of any dimension are; [`super::SolveMethod::Auto`] solves them with MIC(0) conjugate
    /// gradients. Computed once and cached.
    pub fn is_stencil_m_matrix(&self) -> bool {
        *self.stencil_m_matrix.get_or_init(|| {
            (0..self.nrows).all(|i| {
                let (start, end) = (self.row_ptr[i], self.row_ptr[i + 1]);
                if end - start > 11 {
                    return false;
                }
                let (mut diagonal, mut off) = (0.0, 0.0);
                for k in start..end {
                    let v = self.values[k];
                    if self.col_indices[k] == i {
                        diagonal = v;
                    } else if v > 0.0 {
                        return false;
                    } else {
                        off -= v;
                    }
                }
                diagonal > 0.0 && diagonal >= off * (1.0 - 1e-12)
            })
        })
    }

    /// Whether the matrix is square and exactly symmetric (`A[i, j] == A[j, i]` bit for bit,
    /// the same stored pattern). Computed once and cached.
    pub fn is_symmetric(&self) -> bool {
        *self.symmetric.get_or_init(|| {
            self.nrows == self.ncols
                && (0..self.nrows).all(|i| self.row(i).all(|(j, v)| self.get(j, i) == v))
        })
    }

    /// How many single right-hand-side solves (forward or transposed, any method) this matrix
    /// has done. A diagnostic: the tests use it to check that a backward pass is one adjoint
    /// solve.
    pub fn solve_count(&self) -> usize {
        self.solves.load(Ordering::Relaxed)
    }

    /// How many numeric factorizations (Cholesky, LU, incomplete Cholesky) this matrix has
    /// computed; each is cached, so at most one of each kind.
    pub fn factorization_count(&self) -> usize {
        self.factorizations.load(Ordering::Relaxed)
    }

    /// The matrix with a fill-reducing elimination order for its Cholesky factorization:
    /// `order[k]` is the row eliminated `k`-th. Without one, the factorization computes an
    /// approximate minimum degree (AMD) ordering, which for a matrix used once costs as much as
    /// the factorization itself; a caller that knows its structure (a grid: nested dissection)
    /// can supply a good order for almost nothing. The order affects speed only, never the
    /// solution beyond rounding.
    ///
    /// # Errors
    /// [`SolveError::Invalid`] when `order` is not a permutation of `0..nrows` or the matrix is
    /// not square.
    pub fn with_ordering(mut self, order: Vec<usize>) -> Result<Self, SolveError> {
        let n = self.nrows;
        let invalid = |reason: String| Err(SolveError::Invalid { reason });
        if self.ncols != n {
            return invalid(format!(
                "an elimination order needs a square matrix, got {n}×{}",
                self.ncols
            ));
        }
        if order.len() != n {
            return invalid(format!(
                "the elimination order has {} entries for {n} rows",
                order.len()
            ));
        }
        let mut seen = vec![false; n];
        for &row in &order {
            if row >= n || std::mem::replace(&mut seen[row], true) {
                return invalid(format!(
                    "the elimination order is not a permutation of 0..{n} (entry {row})"
                ));
            }
        }
        self.ordering = Some(order.into());
        Ok(self)
    }

    /// The elimination order given by [`SparseMatrix::with_ordering`], if any.
    pub fn ordering(&self) -> Option<&[usize]> {
        self.ordering.as_deref()
    }

    /// Records that the matrix is symmetric, for a builder that guarantees it by construction
    /// (skips the check of [`SparseMatrix::is_symmetric`]).
    pub(crate) fn assume_symmetric(self) -> Self {
        debug_assert!(
            self.nrows == self.ncols
                && (0..self.nrows).all(|i| self.row(i).all(|(j, v)| self.get(j, i) == v)),
            "assume_symmetric on a matrix that is not symmetric"
        );
        let _ = self.symmetric.set(true);
        self
    }

    pub(super) fn count_solves(&self, n: usize) {
        self.solves.fetch_add(n, Ordering::Relaxed);
    }

    fn count_factorization(&self) {
        self.factorizations.fetch_add(1, Ordering::Relaxed);
    }

    /// The sparse Cholesky factorization ([`CholeskyFactor::factorize`], in the elimination
    /// order where the matrix has one), computed once and cached, failure included.
    pub(super) fn cholesky(&self) -> Result<Arc<CholeskyFactor>, SolveError> {
        self.cholesky
            .get_or_init(|| {
                self.count_factorization();
                CholeskyFactor::factorize(self.csr(), self.ordering.as_ref()).map(Arc::new)
            })
            .clone()
    }

    /// The sparse LU factorization, computed once and cached, failure included.
    pub(super) fn lu(&self) -> Result<Arc<LuFactor>, SolveError> {
        self.lu
            .get_or_init(|| {
                self.count_factorization();
                LuFactor::factorize(self.csr()).map(Arc::new)
            })
            .clone()
    }

    /// IC(0) of the symmetric matrix, computed once and cached; `None` where a pivot breaks
    /// down.
    pub(super) fn incomplete_cholesky(&self) -> Option<Arc<IncompleteCholesky>> {
        self.ic0
            .get_or_init(|| {
                self.count_factorization();
                IncompleteCholesky::new(self.csr()).map(Arc::new)
            })
            .clone()
    }

    /// MIC(0) of the symmetric matrix on its product layout ([`Self::split`]), computed once and
    /// cached; `None` where the rows do not fit the layout or a pivot breaks down.
    pub(super) fn modified_incomplete_cholesky(&self) -> Option<Arc<ModifiedIncompleteCholesky>> {
        self.mic0
            .get_or_init(|| {
                self.count_factorization();
                self.split()
                    .and_then(|split| ModifiedIncompleteCholesky::new(&split).map(Arc::new))
            })
            .clone()
    }

    /// The product layout of the symmetric matrix ([`SplitMatrix`]), built once and cached;
    /// `None` where its rows do not fit.
    pub(super) fn split(&self) -> Option<Arc<SplitMatrix>> {
        self.split
            .get_or_init(|| SplitMatrix::new(self.csr()).map(Arc::new))
            .clone()
    }
}

/// [`SolveError::NonFinite`] naming the first NaN or infinite value of a matrix's `values`.
fn check_finite(values: &[f64]) -> Result<(), SolveError> {
    match values.iter().position(|v| !v.is_finite()) {
        Some(k) => Err(SolveError::NonFinite {
            what: format!("matrix value {k}"),
        }),
        None => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn triplets_sum_duplicates_and_sort() {
        let a = SparseMatrix::from_triplets(
            2,
            3,
            &[(1, 2, 1.0), (0, 1, 2.0), (1, 0, 3.0), (1, 2, 4.0)],
        )
        .unwrap();
        assert_eq!(a.row_ptr(), &[0, 1, 3]);
        assert_eq!(a.col_indices(), &[1, 0, 2]);
        assert_eq!(a.values(), &[2.0, 3.0, 5.0]);
        assert_eq!(a.get(1, 2), 5.0);
        assert_eq!(a.get(0, 0), 0.0);
        assert_eq!(a.mul_vec(&[1.0, 1.0, 2.0]), vec![2.0, 13.0]);
        let t = a.transpose();
        assert_eq!((t.nrows(), t.ncols()), (3, 2));
        assert_eq!(t.get(2, 1), 5.0);
        assert!(!a.is_symmetric());
    }

    #[test]
    fn invalid_inputs_are_errors() {
        assert!(matches!(
            SparseMatrix::from_triplets(2, 2, &[(2, 0, 1.0)]),
            Err(SolveError::Invalid { .. })
        ));
        assert!(matches!(
            SparseMatrix::from_triplets(2, 2, &[(0, 0, f64::NAN)]),
            Err(SolveError::NonFinite { .. })
        ));
        assert!(matches!(
            SparseMatrix::from_csr(2, 2, vec![0, 2, 1], vec![0, 1], vec![1.0, 1.0]),
            Err(SolveError::Invalid { .. })
        ));
        assert!(matches!(
            SparseMatrix::from_csr(1, 2, vec![0, 2], vec![1, 0], vec![1.0, 1.0]),
            Err(SolveError::Invalid { .. })
        ));
        let ok = SparseMatrix::from_csr(2, 2, vec![0, 1, 2], vec![0, 1], vec![1.0, 2.0]).unwrap();
        assert!(ok.is_symmetric());
        assert_eq!(ok.diagonal(), vec![1.0, 2.0]);
    }
}
