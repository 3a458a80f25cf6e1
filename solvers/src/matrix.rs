//! Square CSC matrices sharing an immutable, reference-counted sparsity pattern.

use std::sync::Arc;

use faer::sparse::{SparseColMatRef, SymbolicSparseColMat};

use crate::SolverError;

/// Immutable CSC pattern (sorted, duplicate-free row indices in every column) of a square matrix.
#[derive(Debug)]
pub(crate) struct Pattern {
    pub(crate) symbolic: SymbolicSparseColMat<usize>,
}

impl Pattern {
    /// Builds a pattern from a column pointer and sorted, unique row indices per column.
    pub(crate) fn new(n: usize, col_ptr: Vec<usize>, row_idx: Vec<usize>) -> Self {
        // new_checked verifies the invariants once (monotone col_ptr, sorted in-range rows).
        Self {
            symbolic: SymbolicSparseColMat::new_checked(n, n, col_ptr, None, row_idx),
        }
    }

    pub(crate) fn n(&self) -> usize {
        self.symbolic.ncols()
    }

    pub(crate) fn col_ptr(&self) -> &[usize] {
        self.symbolic.col_ptr()
    }

    pub(crate) fn row_idx(&self) -> &[usize] {
        self.symbolic.row_idx()
    }

    /// Same structure (used to decide whether a symbolic factorisation can be reused).
    pub(crate) fn same_as(self: &Arc<Self>, other: &Arc<Self>) -> bool {
        Arc::ptr_eq(self, other)
            || (self.n() == other.n()
                && self.col_ptr() == other.col_ptr()
                && self.row_idx() == other.row_idx())
    }

    /// Value position of entry (row, col), if it is in the pattern.
    pub(crate) fn position(&self, row: usize, col: usize) -> Option<usize> {
        if row >= self.n() || col >= self.n() {
            return None;
        }
        let (a, b) = (self.col_ptr()[col], self.col_ptr()[col + 1]);
        self.row_idx()[a..b].binary_search(&row).ok().map(|k| a + k)
    }
}

/// A square sparse matrix in compressed sparse column (CSC) form, full storage (both triangles).
///
/// The pattern is shared through an [`Arc`] with the [`crate::Assembler`] that built it, so that
/// [`crate::DirectSolver`] can recognise an unchanged pattern cheaply and reuse its symbolic
/// factorisation (theory §3 "Linear system", \[D17\]).
#[derive(Debug, Clone)]
pub struct SparseMatrix {
    pub(crate) pattern: Arc<Pattern>,
    pub(crate) values: Vec<f64>,
}

impl SparseMatrix {
    pub(crate) fn from_parts(pattern: Arc<Pattern>, values: Vec<f64>) -> Self {
        debug_assert_eq!(pattern.row_idx().len(), values.len());
        Self { pattern, values }
    }

    /// Builds an `n x n` matrix from `(row, col, value)` triplets; duplicates are summed in the
    /// order given. Intended for tests and benchmarks; the engine uses [`crate::Assembler`].
    ///
    /// Errors: [`SolverError::EmptySystem`] if `n == 0`, [`SolverError::IndexOutOfRange`] for a
    /// triplet outside the matrix.
    pub fn from_triplets(n: usize, triplets: &[(usize, usize, f64)]) -> Result<Self, SolverError> {
        if n == 0 {
            return Err(SolverError::EmptySystem);
        }
        let mut count = vec![0usize; n + 1];
        for &(row, col, _) in triplets {
            if row >= n || col >= n {
                return Err(SolverError::IndexOutOfRange { row, col, n });
            }
            count[col + 1] += 1;
        }
        for j in 0..n {
            count[j + 1] += count[j];
        }
        // Bucket by column, keeping input order (so duplicates are summed in input order).
        let mut next = count.clone();
        let mut bucket = vec![(0usize, 0.0f64); triplets.len()];
        for &(row, col, v) in triplets {
            bucket[next[col]] = (row, v);
            next[col] += 1;
        }
        let mut col_ptr = Vec::with_capacity(n + 1);
        let mut row_idx = Vec::with_capacity(triplets.len());
        let mut values = Vec::with_capacity(triplets.len());
        col_ptr.push(0);
        for j in 0..n {
            let col = &mut bucket[count[j]..count[j + 1]];
            col.sort_by_key(|&(r, _)| r); // stable: equal rows keep input order
            let mut k = 0;
            while k < col.len() {
                let r = col[k].0;
                let mut s = 0.0;
                while k < col.len() && col[k].0 == r {
                    s += col[k].1;
                    k += 1;
                }
                row_idx.push(r);
                values.push(s);
            }
            col_ptr.push(row_idx.len());
        }
        Ok(Self::from_parts(
            Arc::new(Pattern::new(n, col_ptr, row_idx)),
            values,
        ))
    }

    /// Dimension n of the (square) matrix.
    pub fn n(&self) -> usize {
        self.pattern.n()
    }

    /// Number of stored entries (structural non-zeros, explicit zeros included).
    pub fn nnz(&self) -> usize {
        self.values.len()
    }

    /// Column pointer of the CSC storage (length n + 1).
    pub fn col_ptr(&self) -> &[usize] {
        self.pattern.col_ptr()
    }

    /// Row indices of the CSC storage, sorted and unique within each column (length nnz).
    pub fn row_idx(&self) -> &[usize] {
        self.pattern.row_idx()
    }

    /// Stored values, aligned with [`Self::row_idx`].
    pub fn values(&self) -> &[f64] {
        &self.values
    }

    /// Mutable stored values (the pattern cannot change), e.g. to add a penalty term in place.
    pub fn values_mut(&mut self) -> &mut [f64] {
        &mut self.values
    }

    /// Value position of entry `(row, col)` in [`Self::values`], or `None` if it is not stored.
    pub fn position(&self, row: usize, col: usize) -> Option<usize> {
        self.pattern.position(row, col)
    }

    /// Entry `(row, col)`; `0.0` if it is not stored (or out of range).
    pub fn get(&self, row: usize, col: usize) -> f64 {
        self.position(row, col).map_or(0.0, |p| self.values[p])
    }

    /// Borrowed faer view of the matrix (e.g. for faer's sparse products).
    pub fn as_faer(&self) -> SparseColMatRef<'_, usize, f64> {
        SparseColMatRef::new(self.pattern.symbolic.as_ref(), &self.values)
    }

    /// The (n + 1) × (n + 1) bordered matrix [K c; rᵀ d]: this matrix with the
    /// column `column` and the row `row` (sparse, `(index, value)` pairs
    /// with indices below n, increasing) and the corner `corner` appended,
    /// e.g. the system of a Newton step with one extra unknown and one
    /// extra equation (arc-length and path-following methods). The pattern
    /// depends only on K's pattern and the border's indices.
    ///
    /// Errors: [`SolverError::IndexOutOfRange`] for a border index not below
    /// n or not increasing.
    pub fn bordered(
        &self,
        column: &[(usize, f64)],
        row: &[(usize, f64)],
        corner: f64,
    ) -> Result<SparseMatrix, SolverError> {
        let n = self.n();
        for border in [column, row] {
            let increasing = border.windows(2).all(|w| w[0].0 < w[1].0);
            if let Some(&(i, _)) = border
                .iter()
                .find(|&&(i, _)| i >= n)
                .or(border.first().filter(|_| !increasing))
            {
                return Err(SolverError::IndexOutOfRange {
                    row: i,
                    col: n,
                    n: n + 1,
                });
            }
        }
        let (cp, ri) = (self.col_ptr(), self.row_idx());
        let nnz = self.nnz() + column.len() + row.len() + 1;
        let (mut col_ptr, mut row_idx, mut values) = (
            Vec::with_capacity(n + 2),
            Vec::with_capacity(nnz),
            Vec::with_capacity(nnz),
        );
        col_ptr.push(0);
        let mut next_row = row.iter().peekable();
        for j in 0..n {
            row_idx.extend_from_slice(&ri[cp[j]..cp[j + 1]]);
            values.extend_from_slice(&self.values[cp[j]..cp[j + 1]]);
            if let Some(&(_, value)) = next_row.next_if(|&&(i, _)| i == j) {
                row_idx.push(n);
                values.push(value);
            }
            col_ptr.push(row_idx.len());
        }
        for &(i, value) in column {
            row_idx.push(i);
            values.push(value);
        }
        row_idx.push(n);
        values.push(corner);
        col_ptr.push(row_idx.len());
        Ok(Self::from_parts(
            Arc::new(Pattern::new(n + 1, col_ptr, row_idx)),
            values,
        ))
    }

    /// `true` if both matrices share the same pattern object (not just an equal one).
    pub fn shares_pattern_with(&self, other: &SparseMatrix) -> bool {
        Arc::ptr_eq(&self.pattern, &other.pattern)
    }

    /// `y = K x` (sequential, fixed summation order).
    ///
    /// # Panics
    /// If `x.len()` or `y.len()` differs from [`Self::n`] (a programming error, not numeric input).
    pub fn mul_vec(&self, x: &[f64], y: &mut [f64]) {
        let n = self.n();
        assert_eq!(x.len(), n, "mul_vec: x has the wrong length");
        assert_eq!(y.len(), n, "mul_vec: y has the wrong length");
        y.fill(0.0);
        let (cp, ri) = (self.col_ptr(), self.row_idx());
        for j in 0..n {
            let xj = x[j];
            for p in cp[j]..cp[j + 1] {
                y[ri[p]] += self.values[p] * xj;
            }
        }
    }

    /// Numerical symmetry check: for every stored `a_ij` (and the matching `a_ji`, 0 if absent),
    /// `|a_ij - a_ji| <= rel_tol * max(|a_ij|, |a_ji|, sqrt(|a_ii| |a_jj|))`.
    ///
    /// The `sqrt(|a_ii a_jj|)` term keeps the test scale-invariant and insensitive to
    /// round-off in entries that almost cancel. A matrix containing NaN or inf is not symmetric.
    pub fn is_symmetric(&self, rel_tol: f64) -> bool {
        let n = self.n();
        let (cp, ri) = (self.col_ptr(), self.row_idx());
        let diag: Vec<f64> = (0..n).map(|i| self.get(i, i).abs()).collect();
        for j in 0..n {
            for (&i, &aij) in ri[cp[j]..cp[j + 1]]
                .iter()
                .zip(&self.values[cp[j]..cp[j + 1]])
            {
                if !aij.is_finite() {
                    return false;
                }
                if i == j {
                    continue;
                }
                let aji = self.get(j, i);
                let scale = aij.abs().max(aji.abs()).max((diag[i] * diag[j]).sqrt());
                if aji.is_nan() || (aij - aji).abs() > rel_tol * scale {
                    return false;
                }
            }
        }
        true
    }
}
