//! Pattern construction and deterministic scatter of per-element dense blocks (DESIGN §3
//! "Linear system": constrained dofs eliminated, blocks summed into CSC). An element is any
//! dof list: the 8 dofs of a bilinear cell, or the 32 dofs of the 4x4-node patch that the
//! GIMP supports of a cell's points reach.

use std::sync::Arc;

use crate::matrix::{Pattern, SparseMatrix};
use crate::{SolverError, NO_DOF};

/// Marker for a skipped entry (constrained row or column) in the scatter map.
const SKIP: u32 = u32::MAX;

/// Sparsity pattern of K (full storage, both triangles, CSC) built once from the element dof
/// lists, plus, for each element of `d` dofs, the `d²` value positions its block scatters into.
///
/// The pattern always contains the whole diagonal (so that [`Assembler::assemble_with_diagonal`]
/// can add the Newmark mass term `4M/dt^2` of \[D17\] to any dof). It is fixed while the set of
/// active cells does not change; build a new `Assembler` when it does. Matrices built by one
/// `Assembler` share its pattern through an [`Arc`], which lets [`crate::DirectSolver`] reuse the
/// symbolic factorisation.
#[derive(Debug, Clone)]
pub struct Assembler {
    pattern: Arc<Pattern>,
    /// For element e of `d` dofs, `scatter[start[e] + d·a + b]` is the value position of
    /// (dof_a, dof_b), or `SKIP`.
    scatter: Vec<u32>,
    /// Offsets of the elements' blocks in `scatter` (length elements + 1).
    start: Vec<usize>,
    /// Value position of K_ii.
    diag_pos: Vec<usize>,
}

impl Assembler {
    /// Builds the pattern from the element dof lists. Entry `element_dofs[e][a]` is the global dof
    /// of local dof `a` (node `a / 2`, direction `a % 2` in the engine's convention) or
    /// [`NO_DOF`] for an eliminated (constrained) dof.
    ///
    /// Errors: [`SolverError::EmptySystem`] if `n_dofs == 0`, [`SolverError::DofOutOfRange`],
    /// [`SolverError::TooManyNonZeros`] above `u32::MAX - 1` non-zeros.
    pub fn new<E: AsRef<[u32]>>(n_dofs: usize, element_dofs: &[E]) -> Result<Self, SolverError> {
        Self::with_couplings(n_dofs, element_dofs, |_, _, _| true)
    }

    /// Like [`Assembler::new`], keeping only the couplings of local dofs `a`, `b` of an element
    /// of `d` dofs with `coupled(d, a, b)` (symmetric in `a`, `b`). Use it when some
    /// entries of every block are zero by construction, e.g. the nodes three apart in a GIMP
    /// cell patch that no single material point reaches together: the pattern, and the fill of
    /// the factors, shrink. Block entries outside the couplings are ignored when assembling.
    pub fn with_couplings<E: AsRef<[u32]>>(
        n_dofs: usize,
        element_dofs: &[E],
        coupled: impl Fn(usize, usize, usize) -> bool,
    ) -> Result<Self, SolverError> {
        if n_dofs == 0 {
            return Err(SolverError::EmptySystem);
        }
        let element_dofs: Vec<&[u32]> = element_dofs.iter().map(|e| e.as_ref()).collect();
        for (e, dofs) in element_dofs.iter().enumerate() {
            if let Some(&d) = dofs.iter().find(|&&d| d != NO_DOF && d as usize >= n_dofs) {
                return Err(SolverError::DofOutOfRange {
                    element: e,
                    dof: d,
                    n_dofs,
                });
            }
        }
        // Candidate rows per column (with duplicates): diagonal + element couplings.
        let mut start = vec![0usize; n_dofs + 1];
        for j in 0..n_dofs {
            start[j + 1] = 1;
        }
        // (local a, local b) pairs of an element that enter the pattern
        let pairs = |dofs: &[u32]| {
            let valid: Vec<usize> = (0..dofs.len()).filter(|&a| dofs[a] != NO_DOF).collect();
            let mut out = Vec::with_capacity(valid.len() * valid.len());
            for &a in &valid {
                for &b in &valid {
                    if coupled(dofs.len(), a, b) {
                        out.push((a, b));
                    }
                }
            }
            out
        };
        for dofs in &element_dofs {
            for (_, b) in pairs(dofs) {
                start[dofs[b] as usize + 1] += 1;
            }
        }
        for j in 0..n_dofs {
            start[j + 1] += start[j];
        }
        let mut fill = start.clone();
        let mut rows = vec![0u32; start[n_dofs]];
        for (j, f) in fill.iter_mut().take(n_dofs).enumerate() {
            rows[*f] = j as u32;
            *f += 1;
        }
        for dofs in &element_dofs {
            for (a, b) in pairs(dofs) {
                let f = &mut fill[dofs[b] as usize];
                rows[*f] = dofs[a];
                *f += 1;
            }
        }
        // Sort and deduplicate each column.
        let mut col_ptr = Vec::with_capacity(n_dofs + 1);
        let mut row_idx = Vec::new();
        col_ptr.push(0usize);
        for j in 0..n_dofs {
            let col = &mut rows[start[j]..start[j + 1]];
            col.sort_unstable();
            let mut last = None;
            for &r in col.iter() {
                if last != Some(r) {
                    row_idx.push(r as usize);
                    last = Some(r);
                }
            }
            col_ptr.push(row_idx.len());
        }
        drop(rows);
        let nnz = row_idx.len();
        if nnz >= SKIP as usize {
            return Err(SolverError::TooManyNonZeros { nnz });
        }
        let pattern = Pattern::new(n_dofs, col_ptr, row_idx);
        let pos = |r: u32, c: u32| -> u32 {
            // every coupling was inserted above, so the search always succeeds
            pattern
                .position(r as usize, c as usize)
                .map_or(SKIP, |p| p as u32)
        };
        let mut start = Vec::with_capacity(element_dofs.len() + 1);
        start.push(0usize);
        let mut scatter = Vec::new();
        for dofs in &element_dofs {
            for (la, &a) in dofs.iter().enumerate() {
                for (lb, &b) in dofs.iter().enumerate() {
                    let kept = a != NO_DOF && b != NO_DOF && coupled(dofs.len(), la, lb);
                    scatter.push(if kept { pos(a, b) } else { SKIP });
                }
            }
            start.push(scatter.len());
        }
        let diag_pos = (0..n_dofs)
            .map(|i| pattern.position(i, i).unwrap_or(usize::MAX))
            .collect();
        Ok(Self {
            pattern: Arc::new(pattern),
            scatter,
            start,
            diag_pos,
        })
    }

    /// Whether `k` was built by this assembler (shares its pattern), so that
    /// [`Assembler::reassemble`] may overwrite it.
    pub fn built(&self, k: &SparseMatrix) -> bool {
        Arc::ptr_eq(&k.pattern, &self.pattern)
    }

    /// Number of unknowns (dimension of K).
    pub fn n_dofs(&self) -> usize {
        self.pattern.n()
    }

    /// Number of elements (cells) the pattern was built from.
    pub fn n_elements(&self) -> usize {
        self.start.len() - 1
    }

    /// Number of stored entries of K: the distinct (row, col) couplings plus the diagonal.
    pub fn nnz(&self) -> usize {
        self.pattern.row_idx().len()
    }

    /// Values of K = sum over elements of the blocks. `element_blocks[e]` is row-major d×d for an
    /// element of d dofs: `block[d·a + b]` couples local dof `a` (row) with `b` (column). Entries
    /// whose row or column is [`NO_DOF`] are skipped.
    ///
    /// Contributions are summed sequentially in element order, so the result is bit-identical
    /// whatever the thread count of the caller. Errors: [`SolverError::DimensionMismatch`] if the
    /// number of blocks differs from the number of elements, or a block's size from its
    /// element's d².
    pub fn assemble<B: AsRef<[f64]>>(
        &self,
        element_blocks: &[B],
    ) -> Result<SparseMatrix, SolverError> {
        self.assemble_with_diagonal(element_blocks, None)
    }

    /// Same as [`Assembler::assemble`], then adds `diagonal[i]` to `K_ii` (used for the Newmark
    /// mass term `4M/dt^2` of \[D17\], or any other diagonal shift).
    ///
    /// Errors: [`SolverError::DimensionMismatch`] for a wrong number of blocks or a diagonal whose
    /// length is not [`Assembler::n_dofs`].
    pub fn assemble_with_diagonal<B: AsRef<[f64]>>(
        &self,
        element_blocks: &[B],
        diagonal: Option<&[f64]>,
    ) -> Result<SparseMatrix, SolverError> {
        let mut k = SparseMatrix::from_parts(self.pattern.clone(), vec![0.0; self.nnz()]);
        self.reassemble(&mut k, element_blocks, diagonal)?;
        Ok(k)
    }

    /// Overwrites the values of `k` (which must have been built by this `Assembler`, i.e. share
    /// its pattern) with a new assembly; avoids reallocating the value array every Newton
    /// iteration. Same summation order and errors as [`Assembler::assemble_with_diagonal`], plus
    /// [`SolverError::DimensionMismatch`] if `k` does not share this assembler's pattern.
    pub fn reassemble<B: AsRef<[f64]>>(
        &self,
        k: &mut SparseMatrix,
        element_blocks: &[B],
        diagonal: Option<&[f64]>,
    ) -> Result<(), SolverError> {
        if !Arc::ptr_eq(&k.pattern, &self.pattern) {
            return Err(SolverError::DimensionMismatch {
                context: "reassemble: matrix does not share the assembler's pattern (nnz)",
                expected: self.nnz(),
                found: k.nnz(),
            });
        }
        if element_blocks.len() != self.n_elements() {
            return Err(SolverError::DimensionMismatch {
                context: "element blocks (one per element)",
                expected: self.n_elements(),
                found: element_blocks.len(),
            });
        }
        for (e, block) in element_blocks.iter().enumerate() {
            let expected = self.start[e + 1] - self.start[e];
            if block.as_ref().len() != expected {
                return Err(SolverError::DimensionMismatch {
                    context: "element block (d² values for an element of d dofs)",
                    expected,
                    found: block.as_ref().len(),
                });
            }
        }
        if let Some(d) = diagonal {
            if d.len() != self.n_dofs() {
                return Err(SolverError::DimensionMismatch {
                    context: "diagonal",
                    expected: self.n_dofs(),
                    found: d.len(),
                });
            }
        }
        let values = &mut k.values;
        values.fill(0.0);
        for (e, block) in element_blocks.iter().enumerate() {
            let map = &self.scatter[self.start[e]..self.start[e + 1]];
            for (&p, &v) in map.iter().zip(block.as_ref()) {
                if p != SKIP {
                    values[p as usize] += v;
                }
            }
        }
        if let Some(d) = diagonal {
            for (&p, &v) in self.diag_pos.iter().zip(d) {
                values[p] += v;
            }
        }
        Ok(())
    }
}
