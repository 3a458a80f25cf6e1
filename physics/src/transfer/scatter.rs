//! P2G scatter: per-cell patch sums in particle order, then node sums over the
//! neighbouring cells in a fixed order (theory D10–D11).

use super::NONE;
use rayon::prelude::*;

use super::bins::ParticleBins;
use super::nodal_field::NodalField;
use crate::grid::{Grid, ShapeAt, Support, MAX_SUPPORT};

/// Contributions of one particle to the nodes of its support, in the order of
/// [`ShapeAt::nodes`] (the first `count` entries are used).
pub type Contribution<const K: usize> = [[f64; K]; MAX_SUPPORT];

/// Sum particle contributions into grid nodes: `contribution(p)` returns the
/// contributions of particle `p` to the nodes of its support.
/// Returns one `[f64; K]` per grid node (zero at inactive nodes). Deterministic:
/// particles are summed per cell in index order into the cell's node patch,
/// then each node sums the patches that hold it in a fixed cell order.
pub fn scatter<const K: usize, F>(
    grid: &Grid,
    bins: &ParticleBins,
    shapes: &[ShapeAt],
    contribution: F,
) -> Vec<[f64; K]>
where
    F: Fn(usize) -> Contribution<K> + Sync,
{
    let mut nodal = NodalField::default();
    let add = |p: usize, s: &ShapeAt, patch: &mut [[f64; K]]| {
        let contrib = contribution(p);
        for a in s.support() {
            let place = s.local[a] as usize;
            for k in 0..K {
                patch[place][k] += contrib[a][k];
            }
        }
    };
    scatter_into_field(grid, bins, shapes, add, &mut Vec::new(), &mut nodal);
    nodal.into_vec()
}

/// Cells handed to one rayon task at least, in the per-cell loops.
const CELLS_PER_TASK: usize = 64;

/// [`scatter`] into `nodal`, with `cell_sums` as the buffer of the active
/// cells' patch sums: no allocation once both have grown to the run's size,
/// and work in proportion to the active nodes (of this call and the one
/// before), not to the grid. `add(p, shape_p, patch)` adds the contributions
/// of particle `p` to the places of its support in its cell's node patch
/// (`patch[shape_p.place(a)]`), once per place, so that every nodal sum is
/// formed in the order [`scatter`] documents.
pub fn scatter_into_field<const K: usize, S: Support, F>(
    grid: &Grid,
    bins: &ParticleBins,
    shapes: &[S],
    add: F,
    cell_sums: &mut Vec<[f64; K]>,
    nodal: &mut NodalField<[f64; K]>,
) where
    F: Fn(usize, &S, &mut [[f64; K]]) + Sync,
{
    sum_cell_patches(bins, grid.patch_side().pow(2), shapes, add, cell_sums);
    let gather = CellGather::new(grid, bins, cell_sums);
    nodal.refill(grid.node_count(), &bins.active_nodes, |node| {
        gather.node(node)
    });
}

/// The patch sums of the active cells (`patch` places each, in the order of
/// `bins.active_cells`): every point's contributions added by `add` into
/// its cell's patch, points in index order.
fn sum_cell_patches<const K: usize, S: Support, F>(
    bins: &ParticleBins,
    patch: usize,
    shapes: &[S],
    add: F,
    cell_sums: &mut Vec<[f64; K]>,
) where
    F: Fn(usize, &S, &mut [[f64; K]]) + Sync,
{
    // each patch is zeroed by the task that sums it (not all in one serial pass)
    cell_sums.resize(bins.active_cells.len() * patch, [0.0; K]);
    cell_sums
        .par_chunks_mut(patch)
        .zip(bins.active_cells.par_iter())
        .with_min_len(CELLS_PER_TASK)
        .for_each(|(sum, &c)| {
            sum.fill([0.0; K]);
            for &p in bins.particles_in(c as usize) {
                let p = p as usize;
                add(p, &shapes[p], sum);
            }
        });
}

/// The sum at one node of the patch sums of the active cells that hold it.
struct CellGather<'a, const K: usize> {
    bins: &'a ParticleBins,
    cell_sums: &'a [[f64; K]],
    /// Cells along x and y.
    cells: [isize; 2],
    /// Nodes along x.
    nodes_x: usize,
    /// Nodes along a patch side.
    side: isize,
    /// How far a cell's patch starts before its own lower-left node.
    offset: isize,
}

impl<'a, const K: usize> CellGather<'a, K> {
    fn new(grid: &Grid, bins: &'a ParticleBins, cell_sums: &'a [[f64; K]]) -> Self {
        let (offset, _) = grid.patch_origin(0, 0);
        Self {
            bins,
            cell_sums,
            cells: [grid.cells[0] as isize, grid.cells[1] as isize],
            nodes_x: grid.cells[0] + 1,
            side: grid.patch_side() as isize,
            offset: -offset,
        }
    }

    /// The value at `node`: the patches that hold it, cells in increasing
    /// (row-major) order.
    #[inline]
    fn node(&self, node: usize) -> [f64; K] {
        let [ncx, ncy] = self.cells;
        let (side, offset) = (self.side, self.offset);
        let patch = (side * side) as usize;
        let (i, j) = (
            (node % self.nodes_x) as isize,
            (node / self.nodes_x) as isize,
        );
        let mut value = [0.0; K];
        // the patch of cell c starts at node c − offset and spans `side` nodes
        for cj in (j + offset - side + 1)..=(j + offset) {
            for ci in (i + offset - side + 1)..=(i + offset) {
                if ci < 0 || cj < 0 || ci >= ncx || cj >= ncy {
                    continue;
                }
                let slot = self.bins.cell_slot[(cj * ncx + ci) as usize];
                if slot == NONE {
                    continue;
                }
                let place = ((j - (cj - offset)) * side + (i - (ci - offset))) as usize;
                let contrib = &self.cell_sums[slot as usize * patch + place];
                for k in 0..K {
                    value[k] += contrib[k];
                }
            }
        }
        value
    }
}
