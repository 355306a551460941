//! [`CsrRef`]: a borrowed view of a matrix in compressed sparse rows, what the factorizations and
//! preconditioners read.
//!
//! [`super::SparseMatrix`] owns the arrays and caches what the solvers compute from them (the
//! factorizations, the preconditioners, the product's layout). Those take this view rather than
//! the owner, so that the owner can name their types without the files depending on each other
//! in a circle.

/// A CSR matrix with `f64` values, borrowed: the entries of row `i` are `col_indices[row_ptr[i]..
/// row_ptr[i + 1]]` (sorted, no duplicates) with `values` alongside.
#[derive(Debug, Clone, Copy)]
pub(crate) struct CsrRef<'a> {
    nrows: usize,
    ncols: usize,
    row_ptr: &'a [usize],
    col_indices: &'a [usize],
    values: &'a [f64],
}

impl<'a> CsrRef<'a> {
    /// A view of arrays that form a valid CSR matrix, as a [`super::SparseMatrix`] holds them
    /// (checked when it was built; the lengths again in debug builds).
    #[inline]
    pub(crate) fn new(
        nrows: usize,
        ncols: usize,
        row_ptr: &'a [usize],
        col_indices: &'a [usize],
        values: &'a [f64],
    ) -> Self {
        debug_assert!(
            row_ptr.len() == nrows + 1
                && row_ptr[nrows] == col_indices.len()
                && col_indices.len() == values.len(),
            "inconsistent CSR arrays"
        );
        Self {
            nrows,
            ncols,
            row_ptr,
            col_indices,
            values,
        }
    }

    /// Number of rows.
    #[inline]
    pub(crate) fn nrows(self) -> usize {
        self.nrows
    }

    /// Number of columns.
    #[inline]
    pub(crate) fn ncols(self) -> usize {
        self.ncols
    }

    /// Number of stored entries.
    #[inline]
    pub(crate) fn nnz(self) -> usize {
        self.values.len()
    }

    /// Row start offsets (`nrows + 1` entries).
    #[inline]
    pub(crate) fn row_ptr(self) -> &'a [usize] {
        self.row_ptr
    }

    /// Column index of each stored entry.
    #[inline]
    pub(crate) fn col_indices(self) -> &'a [usize] {
        self.col_indices
    }

    /// Value of each stored entry.
    #[inline]
    pub(crate) fn values(self) -> &'a [f64] {
        self.values
    }

    /// The stored entries of row `i` as `(column, value)` pairs.
    #[inline]
    pub(crate) fn row(self, i: usize) -> impl Iterator<Item = (usize, f64)> + 'a {
        let range = self.row_ptr[i]..self.row_ptr[i + 1];
        self.col_indices[range.clone()]
            .iter()
            .copied()
            .zip(self.values[range].iter().copied())
    }
}
