//! A simplicial up-looking sparse Cholesky factorization in a given elimination order, for the
//! small and medium matrices of 2D pressure solves.
//!
//! faer's sparse Cholesky runs a symbolic analysis (elimination tree, column counts, the factor's
//! structure) before the numeric factorization. For a pressure solve on a moving liquid every
//! matrix has a new pattern, so that analysis is paid on every step, and at 32² (about 500
//! unknowns) it and faer's generic set-up cost more than the arithmetic. This factorization needs
//! no separate analysis: it computes `L` one row at a time (`L[k, ..k]` from a sparse triangular
//! solve with the rows above), finds each row's pattern by walking the elimination tree from the
//! entries of `A`'s row (the row subtree), and builds the elimination tree itself along the way
//! (a node's parent is the first later row whose pattern reaches it). Rows of `L` are stored as
//! they are computed (compressed rows, entries in the order the solve visits them), so no column
//! counts are needed in advance either.
//!
//! The work is the factor's flops plus `O(|L|)` integer operations; nothing is sorted.

use super::SolveError;
use super::csr::CsrRef;

/// Marks an absent parent in the elimination tree and an unvisited node.
const NONE: u32 = u32::MAX;

/// `P A Pᵀ = L Lᵀ` for a symmetric positive definite `A` and the elimination order `P`
/// (`order[k]`: the row of `A` eliminated `k`-th). `L` is stored by rows without its diagonal
/// (`cols` / `values` between `row_ptr[k]` and `row_ptr[k + 1]`, in no particular order), the
/// diagonal separately.
#[derive(Debug)]
pub(crate) struct UpLookingCholesky {
    order: Vec<u32>,
    row_ptr: Vec<usize>,
    cols: Vec<u32>,
    values: Vec<f64>,
    diagonal: Vec<f64>,
}

impl UpLookingCholesky {
    /// The largest matrix this factorization indexes (`u32` indices).
    pub(crate) const MAX_ROWS: usize = u32::MAX as usize - 1;

    /// Factorises the symmetric `matrix` in the elimination order `order` (a permutation of
    /// `0..n`; [`super::SparseMatrix::with_ordering`] checks it). Only the entries of `matrix` on and
    /// below the diagonal of the permuted matrix are read.
    ///
    /// # Errors
    /// [`SolveError::Factorization`] when a pivot is not positive (the matrix is not positive
    /// definite) or the matrix has more than [`Self::MAX_ROWS`] rows.
    pub(crate) fn factorize(matrix: CsrRef<'_>, order: &[usize]) -> Result<Self, SolveError> {
        let failed = |reason: String| SolveError::Factorization {
            method: "Cholesky",
            reason,
        };
        let n = matrix.nrows();
        if n > Self::MAX_ROWS || order.len() != n {
            return Err(failed(format!(
                "the up-looking factorization takes at most {} rows and one order entry per \
                 row, got {n} rows and {} entries",
                Self::MAX_ROWS,
                order.len()
            )));
        }
        // position[row of A] = its index in the elimination order.
        let mut position = vec![0u32; n];
        for (k, &row) in order.iter().enumerate() {
            position[row] = k as u32;
        }
        // The elimination tree, built as rows are factorised.
        let mut parent = vec![NONE; n];
        // mark[i] == k: node i is in the pattern of row k (visited while factorising row k).
        let mut mark = vec![NONE; n];
        // The row being solved for, dense; zero outside the current row's pattern.
        let mut x = vec![0.0f64; n];
        // stack[..len]: the path being walked; stack[top..]: the row's pattern, in an order in
        // which every node comes after its descendants (those its value depends on).
        let mut stack = vec![0u32; n];

        let mut row_ptr = Vec::with_capacity(n + 1);
        row_ptr.push(0);
        // 2D grid factors under a nested-dissection-like order hold a few times A's entries.
        let mut cols: Vec<u32> = Vec::with_capacity(2 * matrix.nnz());
        let mut values: Vec<f64> = Vec::with_capacity(2 * matrix.nnz());
        let mut diagonal = vec![0.0f64; n];
        // 1 / L[j, j]: a multiplication instead of a division on the solve's dependency chain.
        let mut inverse = vec![0.0f64; n];

        for (k, &row) in order.iter().enumerate() {
            let k32 = k as u32;
            mark[k] = k32;
            let mut top = n;
            let mut pivot = 0.0;
            for (column, a) in matrix.row(row) {
                let p = position[column] as usize;
                if p > k {
                    continue;
                }
                if p == k {
                    pivot += a;
                    continue;
                }
                x[p] = a;
                // Walk up the elimination tree from p until a node already in the pattern; a
                // node without a parent yet gets k (no earlier row reached it).
                let mut len = 0;
                let mut i = p;
                while mark[i] != k32 {
                    stack[len] = i as u32;
                    len += 1;
                    mark[i] = k32;
                    if parent[i] == NONE {
                        parent[i] = k32;
                        break;
                    }
                    i = parent[i] as usize;
                }
                // Prepend the path (leaf first) to the pattern.
                while len > 0 {
                    len -= 1;
                    top -= 1;
                    stack[top] = stack[len];
                }
            }
            // Solve L[..k, ..k] L[k, ..k]ᵀ = A[..k, k] over the pattern, descendants first:
            // L[k, j] = (A[k, j] − Σ_i L[j, i] L[k, i]) / L[j, j].
            for &j in &stack[top..n] {
                let j = j as usize;
                let range = row_ptr[j]..row_ptr[j + 1];
                // SAFETY: row j of L holds columns below j, and j < k < n = x.len().
                let dot = unsafe { sparse_dot(&cols[range.clone()], &values[range], &x) };
                let v = (x[j] - dot) * inverse[j];
                x[j] = v;
                cols.push(j as u32);
                values.push(v);
            }
            // Kept out of the loop above, whose values depend on one another.
            pivot -= sparse_norm_squared(&values[row_ptr[k]..]);
            for &j in &cols[row_ptr[k]..] {
                x[j as usize] = 0.0;
            }
            if !(pivot > 0.0 && pivot.is_finite()) {
                return Err(failed(format!(
                    "pivot {k} (row {row}) is {pivot:e}: the matrix is not positive definite"
                )));
            }
            diagonal[k] = pivot.sqrt();
            inverse[k] = 1.0 / diagonal[k];
            row_ptr.push(cols.len());
        }
        Ok(Self {
            order: order.iter().map(|&r| r as u32).collect(),
            row_ptr,
            cols,
            values,
            diagonal,
        })
    }

    /// Stored entries of `L`, the diagonal included (the fill).
    #[cfg(test)]
    pub(crate) fn entries(&self) -> usize {
        self.values.len() + self.diagonal.len()
    }

    /// `x = A⁻¹ b`: `L y = P b`, `Lᵀ z = y`, `x = Pᵀ z`.
    pub(crate) fn solve(&self, b: &[f64]) -> Vec<f64> {
        let n = self.diagonal.len();
        let mut y: Vec<f64> = self.order.iter().map(|&row| b[row as usize]).collect();
        // L y = P b, by rows.
        for k in 0..n {
            let range = self.row_ptr[k]..self.row_ptr[k + 1];
            // SAFETY: row k of L holds columns below k < n = y.len().
            let dot = unsafe { sparse_dot(&self.cols[range.clone()], &self.values[range], &y) };
            y[k] = (y[k] - dot) / self.diagonal[k];
        }
        // Lᵀ z = y: the rows of L are the columns of Lᵀ, from the last.
        for k in (0..n).rev() {
            let v = y[k] / self.diagonal[k];
            y[k] = v;
            for q in self.row_ptr[k]..self.row_ptr[k + 1] {
                y[self.cols[q] as usize] -= self.values[q] * v;
            }
        }
        let mut x = vec![0.0; n];
        for (&row, &v) in self.order.iter().zip(&y) {
            x[row as usize] = v;
        }
        x
    }
}

/// `Σ values[q] · x[cols[q]]`, in four independent partial sums: a single running sum would wait
/// on the latency of each addition, and these rows are short dot products on the critical path.
///
/// # Safety
/// Every entry of `cols` must index `x` (asserted in debug builds). This is the factorization's
/// inner loop, and the bounds check on each gather was about a fifth of its instructions.
unsafe fn sparse_dot(cols: &[u32], values: &[f64], x: &[f64]) -> f64 {
    debug_assert!(cols.iter().all(|&c| (c as usize) < x.len()));
    // SAFETY: the function's contract: every column indexes `x`.
    let gather = |c: u32| unsafe { *x.get_unchecked(c as usize) };
    let mut sums = [0.0f64; 4];
    let mut col_chunks = cols.chunks_exact(4);
    let mut value_chunks = values.chunks_exact(4);
    for (c, v) in (&mut col_chunks).zip(&mut value_chunks) {
        for lane in 0..4 {
            sums[lane] += v[lane] * gather(c[lane]);
        }
    }
    let mut tail = 0.0;
    for (&c, &v) in col_chunks.remainder().iter().zip(value_chunks.remainder()) {
        tail += v * gather(c);
    }
    (sums[0] + sums[1]) + (sums[2] + sums[3]) + tail
}

/// `Σ v²` in four partial sums.
fn sparse_norm_squared(values: &[f64]) -> f64 {
    let mut sums = [0.0f64; 4];
    let mut chunks = values.chunks_exact(4);
    for v in &mut chunks {
        for lane in 0..4 {
            sums[lane] += v[lane] * v[lane];
        }
    }
    let tail: f64 = chunks.remainder().iter().map(|v| v * v).sum();
    (sums[0] + sums[1]) + (sums[2] + sums[3]) + tail
}
