//! Pattern construction and deterministic scatter of per-element dense blocks (theory §3
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
        let (pattern, scatter, start) = column_pattern(n_dofs, &element_dofs, &coupled)?;
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

/// The pattern, the scatter map and the elements' offsets in it.
type ColumnPattern = (Pattern, Vec<u32>, Vec<usize>);

/// The coupling mask of an element of `d` dofs: `mask[d·a + b]` = coupled(d, a, b).
fn coupling_mask(d: usize, coupled: &impl Fn(usize, usize, usize) -> bool) -> Vec<bool> {
    (0..d * d).map(|k| coupled(d, k / d, k % d)).collect()
}

/// The pattern (sorted distinct rows of every column, the diagonal
/// included) and the scatter map of the elements, built column by column:
/// the elements that touch column j list their coupled rows once into it
/// (a marker array drops repeats), the short list is sorted, and a slot
/// array of the rows' positions in the column fills the elements' scatter
/// entries of that column without a search. The same pattern and map as
/// sorting every column's candidate rows and binary-searching each entry
/// (the test below compares the two).
fn column_pattern(
    n_dofs: usize,
    element_dofs: &[&[u32]],
    coupled: &impl Fn(usize, usize, usize) -> bool,
) -> Result<ColumnPattern, SolverError> {
    // the coupling masks, one per element size (the elements of a grid share one)
    let mut masks: Vec<(usize, Vec<bool>)> = Vec::new();
    let mut mask_of = Vec::with_capacity(element_dofs.len());
    for dofs in element_dofs {
        let d = dofs.len();
        let m = match masks.iter().position(|(size, _)| *size == d) {
            Some(m) => m,
            None => {
                masks.push((d, coupling_mask(d, coupled)));
                masks.len() - 1
            }
        };
        mask_of.push(m as u32);
    }
    // the (element, local dof) entries of every column, in element order
    let mut column_start = vec![0usize; n_dofs + 1];
    for dofs in element_dofs {
        for &b in dofs.iter().filter(|&&b| b != NO_DOF) {
            column_start[b as usize + 1] += 1;
        }
    }
    for j in 0..n_dofs {
        column_start[j + 1] += column_start[j];
    }
    let mut next = column_start.clone();
    let mut column_entries = vec![(0u32, 0u32); column_start[n_dofs]];
    for (e, dofs) in element_dofs.iter().enumerate() {
        for (lb, &b) in dofs.iter().enumerate() {
            if b != NO_DOF {
                column_entries[next[b as usize]] = (e as u32, lb as u32);
                next[b as usize] += 1;
            }
        }
    }
    drop(next);
    let mut start = Vec::with_capacity(element_dofs.len() + 1);
    start.push(0usize);
    for dofs in element_dofs {
        start.push(start.last().unwrap() + dofs.len() * dofs.len());
    }
    let mut scatter = vec![SKIP; *start.last().unwrap()];
    let mut col_ptr = Vec::with_capacity(n_dofs + 1);
    col_ptr.push(0usize);
    let mut row_idx: Vec<usize> = Vec::new();
    // marker[r] = j + 1 once row r is listed in column j; slot[r] = its position
    let mut marker = vec![0usize; n_dofs];
    let mut slot = vec![0u32; n_dofs];
    for j in 0..n_dofs {
        let first = row_idx.len();
        marker[j] = j + 1;
        row_idx.push(j);
        let entries = &column_entries[column_start[j]..column_start[j + 1]];
        for &(e, lb) in entries {
            let dofs = element_dofs[e as usize];
            let (d, mask) = (dofs.len(), &masks[mask_of[e as usize] as usize].1);
            for (la, &a) in dofs.iter().enumerate() {
                if a != NO_DOF && mask[d * la + lb as usize] && marker[a as usize] != j + 1 {
                    marker[a as usize] = j + 1;
                    row_idx.push(a as usize);
                }
            }
        }
        row_idx[first..].sort_unstable();
        if row_idx.len() >= SKIP as usize {
            return Err(SolverError::TooManyNonZeros { nnz: row_idx.len() });
        }
        for (k, &r) in row_idx.iter().enumerate().skip(first) {
            slot[r] = k as u32;
        }
        for &(e, lb) in entries {
            let dofs = element_dofs[e as usize];
            let (d, mask) = (dofs.len(), &masks[mask_of[e as usize] as usize].1);
            let block = &mut scatter[start[e as usize]..start[e as usize + 1]];
            for (la, &a) in dofs.iter().enumerate() {
                if a != NO_DOF && mask[d * la + lb as usize] {
                    block[d * la + lb as usize] = slot[a as usize];
                }
            }
        }
        col_ptr.push(row_idx.len());
    }
    Ok((Pattern::new(n_dofs, col_ptr, row_idx), scatter, start))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The plain construction: every column's candidate rows (diagonal and
    /// element couplings, with repeats) sorted and deduplicated, then each
    /// block entry's position found by binary search.
    fn reference(
        n_dofs: usize,
        element_dofs: &[&[u32]],
        coupled: impl Fn(usize, usize, usize) -> bool,
    ) -> (Vec<usize>, Vec<usize>, Vec<u32>) {
        let mut columns: Vec<Vec<usize>> = (0..n_dofs).map(|j| vec![j]).collect();
        for dofs in element_dofs {
            for (la, &a) in dofs.iter().enumerate() {
                for (lb, &b) in dofs.iter().enumerate() {
                    if a != NO_DOF && b != NO_DOF && coupled(dofs.len(), la, lb) {
                        columns[b as usize].push(a as usize);
                    }
                }
            }
        }
        let mut col_ptr = vec![0];
        let mut row_idx = Vec::new();
        for c in &mut columns {
            c.sort_unstable();
            c.dedup();
            row_idx.extend_from_slice(c);
            col_ptr.push(row_idx.len());
        }
        let mut scatter = Vec::new();
        for dofs in element_dofs {
            for (la, &a) in dofs.iter().enumerate() {
                for (lb, &b) in dofs.iter().enumerate() {
                    let kept = a != NO_DOF && b != NO_DOF && coupled(dofs.len(), la, lb);
                    scatter.push(if kept {
                        let (lo, hi) = (col_ptr[b as usize], col_ptr[b as usize + 1]);
                        (lo + row_idx[lo..hi].binary_search(&(a as usize)).unwrap()) as u32
                    } else {
                        SKIP
                    });
                }
            }
        }
        (col_ptr, row_idx, scatter)
    }

    /// On grids of GIMP-like patches (4 × 4 nodes, 2 dofs each, couplings
    /// of nodes three apart dropped) and bilinear cells, with constrained
    /// dofs, repeated dofs and unused dofs, the column-wise construction
    /// gives exactly the reference pattern and scatter map.
    #[test]
    fn column_construction_equals_the_sorted_reference() {
        let mut seed = 12345u64;
        let mut draw = move |n: u64| {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 33) % n
        };
        let far = |d: usize, a: usize, b: usize| {
            let nodes = d / 2;
            let side = (nodes as f64).sqrt() as usize;
            let (na, nb) = (a / 2, b / 2);
            let dx = (na % side).abs_diff(nb % side);
            let dy = (na / side).abs_diff(nb / side);
            dx < 3 && dy < 3
        };
        for (side, cells) in [(4usize, [5usize, 4]), (2, [7, 3]), (4, [1, 1])] {
            let nodes = [cells[0] + side - 1, cells[1] + side - 1];
            let n_dofs = 2 * nodes[0] * nodes[1] + 3; // three dofs no element uses
            let mut elements: Vec<Vec<u32>> = Vec::new();
            for cy in 0..cells[1] {
                for cx in 0..cells[0] {
                    let mut dofs = Vec::new();
                    for j in 0..side {
                        for i in 0..side {
                            let node = (cy + j) * nodes[0] + cx + i;
                            for c in 0..2 {
                                dofs.push(if draw(7) == 0 {
                                    NO_DOF
                                } else {
                                    (2 * node + c) as u32
                                });
                            }
                        }
                    }
                    if draw(5) == 0 {
                        dofs[1] = dofs[0]; // a repeated dof
                    }
                    elements.push(dofs);
                }
            }
            let views: Vec<&[u32]> = elements.iter().map(|e| e.as_slice()).collect();
            let asm = Assembler::with_couplings(n_dofs, &views, far).unwrap();
            let (col_ptr, row_idx, scatter) = reference(n_dofs, &views, far);
            assert_eq!(asm.pattern.col_ptr(), col_ptr.as_slice());
            assert_eq!(asm.pattern.row_idx(), row_idx.as_slice());
            assert_eq!(asm.scatter, scatter);
            for i in 0..n_dofs {
                assert_eq!(row_idx[asm.diag_pos[i]], i);
            }
        }
    }
}
