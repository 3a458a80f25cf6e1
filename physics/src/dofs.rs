//! Numbering of the unknowns of one step (theory §3 "Linear system"): the
//! free degrees of freedom of the active nodes, and the system indices of
//! every element of the tangent.

use crate::bc::{Constraints, DofConstraint};
use crate::grid::Grid;
use crate::transfer::{ParticleBins, NONE};

/// Numbering of the free dofs of the active nodes for one step.
#[derive(Debug, Default)]
pub struct DofMap {
    /// For every grid dof, its index in the system, or [`NONE`].
    pub index: Vec<u32>,
    /// Number of unknowns.
    pub n_free: usize,
}

/// `clone_from` refills the index array in place (a derived one would
/// allocate anew): the implicit step copies the numbering into its system
/// each contact pass.
impl Clone for DofMap {
    fn clone(&self) -> Self {
        Self {
            index: self.index.clone(),
            n_free: self.n_free,
        }
    }

    fn clone_from(&mut self, source: &Self) {
        self.index.clone_from(&source.index);
        self.n_free = source.n_free;
    }
}

impl DofMap {
    /// Number the free dofs of active nodes in grid-dof order (deterministic).
    pub fn new(bins: &ParticleBins, constraints: &Constraints) -> Self {
        let mut dofs = Self::default();
        dofs.renumber(bins, constraints);
        dofs
    }

    /// [`Self::new`] in place, reusing the index array.
    pub fn renumber(&mut self, bins: &ParticleBins, constraints: &Constraints) {
        self.index.clear();
        self.index.resize(constraints.dof.len(), NONE);
        self.n_free = 0;
        for (node, &active) in bins.node_active.iter().enumerate() {
            if !active {
                continue;
            }
            for c in 0..2 {
                let d = 2 * node + c;
                if constraints.dof[d] == DofConstraint::Free {
                    self.index[d] = self.n_free as u32;
                    self.n_free += 1;
                }
            }
        }
    }

    /// Make the constrained grid dof `d` an unknown, numbered after the
    /// others (a frictional node's normal dof in a step it may leave the
    /// edge, theory eq. FR7). A dof that is an unknown already keeps its
    /// number.
    pub fn release(&mut self, d: usize) {
        if self.index[d] == NONE {
            self.index[d] = self.n_free as u32;
            self.n_free += 1;
        }
    }

    /// Whether grid dof `d` is an unknown of the system.
    #[inline]
    pub fn is_free(&self, d: usize) -> bool {
        self.index[d] != NONE
    }

    /// The system indices of every element's dofs ([`NONE`] where constrained
    /// or outside the grid), in the order of `stiffness::system_blocks`: each
    /// active cell's node patch (row-major), then each GIMP-reached cell's four
    /// nodes (row-major).
    pub fn element_dofs(&self, grid: &Grid, bins: &ParticleBins) -> Vec<Vec<u32>> {
        let dofs_of = |nodes: &[Option<u32>]| -> Vec<u32> {
            nodes
                .iter()
                .flat_map(|node| {
                    (0..2).map(move |k| node.map_or(NONE, |n| self.index[2 * n as usize + k]))
                })
                .collect()
        };
        let patches = bins.active_cells.iter().map(|&c| {
            let (ci, cj) = grid.cell_ij(c as usize);
            dofs_of(&grid.patch_nodes(ci, cj))
        });
        let reached = bins.reached_cells.iter().map(|&c| {
            let (ci, cj) = grid.cell_ij(c as usize);
            dofs_of(&grid.cell_nodes_row_major(ci, cj).map(Some))
        });
        patches.chain(reached).collect()
    }
}

/// The free-dof entries of a nodal field, in system order, into `out`
/// (resized to the unknowns; no allocation once it has grown).
pub fn gather_free_into(dofs: &DofMap, nodal: &[[f64; 2]], out: &mut Vec<f64>) {
    out.clear();
    out.resize(dofs.n_free, 0.0);
    for (d, &index) in dofs.index.iter().enumerate() {
        if index != NONE {
            out[index as usize] = nodal[d / 2][d % 2];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A copy into a numbering of the same size keeps its index array (the
    /// contact passes of an implicit step refill it, they do not allocate).
    #[test]
    fn clone_from_refills_the_index_in_place() {
        let source = DofMap {
            index: (0..10).collect(),
            n_free: 10,
        };
        let mut copy = DofMap {
            index: vec![NONE; 10],
            n_free: 0,
        };
        let array = copy.index.as_ptr();
        copy.clone_from(&source);
        assert_eq!(copy.index, source.index);
        assert_eq!(copy.n_free, 10);
        assert_eq!(copy.index.as_ptr(), array);
    }
}
