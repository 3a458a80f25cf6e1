//! The points binned by cell ([`ParticleBins`]): the fixed order in which every
//! nodal sum is formed.

use std::ops::Range;

use super::NONE;

use crate::grid::{Grid, ShapeAt, Support};

/// Largest node patch of a cell (4 × 4 for GIMP).
pub const MAX_PATCH: usize = 16;

/// Particles binned by cell, the active cells and the active nodes (theory §2:
/// a cell is active if it holds ≥ 1 point; a node is active if some point's
/// shape functions reach it: the nodes of the active cells, and for GIMP also
/// those of the cells that a point's domain overlaps across a cell edge).
/// One `ParticleBins` serves one grid: a rebuild on a bilinear grid keeps the
/// bins of the last one when no point changed cell.
#[derive(Clone, Debug, Default)]
pub struct ParticleBins {
    /// `order[cell_start[c]..cell_start[c+1]]` are the particles of cell `c`, in index order.
    pub cell_start: Vec<u32>,
    /// Particle indices sorted by cell.
    pub order: Vec<u32>,
    /// Indices of the active cells, increasing.
    pub active_cells: Vec<u32>,
    /// Cells that hold no point but that some point's GIMP domain overlaps,
    /// increasing (always empty for bilinear shape functions).
    pub reached_cells: Vec<u32>,
    /// For every cell, its slot in `active_cells`, or [`NONE`].
    pub cell_slot: Vec<u32>,
    /// For every grid node, whether it is active.
    pub node_active: Vec<bool>,
    /// Indices of the active nodes, increasing.
    pub active_nodes: Vec<u32>,
    /// The holding cell of every point at the last rebuild on a bilinear grid
    /// (empty after one on a GIMP grid): while no point leaves its cell, the
    /// bins stay.
    holding_cells: Vec<u32>,
    /// The cells (in index order) outside which the arrays hold the values
    /// of cells without points: `cell_start` 0 before and the point count
    /// after, no slot, no active node. A rebuild visits these cells and
    /// those of the new points, not the whole grid (on the vertical cut's
    /// 40 m grid, the rows of the body: a third of the cells at the start).
    span: Range<usize>,
    /// Per cell, whether some GIMP support reaches it (a rebuild's buffer,
    /// all false between rebuilds).
    reached: Vec<bool>,
}

impl ParticleBins {
    /// Bin the particles whose shapes are `shapes`.
    pub fn new(grid: &Grid, shapes: &[ShapeAt]) -> Self {
        let mut bins = Self::default();
        bins.rebuild(grid, shapes);
        bins
    }

    /// Bin the particles whose shapes are `shapes` again, reusing the
    /// arrays: what [`Self::new`] gives, without allocating once the arrays
    /// have grown, and with work in proportion to the cells from the lowest
    /// to the highest the points hold or reach (at this rebuild and the
    /// last), not to the grid. On a bilinear grid
    /// the bins are those of the points' holding cells and are kept while
    /// no point leaves its cell ([`Self::rebuild_bilinear`]).
    pub fn rebuild<S: Support>(&mut self, grid: &Grid, shapes: &[S]) {
        let cell_of = |p: usize| shapes[p].holding_cell();
        if grid.patch_side() == 2 {
            self.keep_or_rebin_bilinear(grid, shapes.len(), cell_of);
            return;
        }
        self.holding_cells.clear();
        if self.reached.len() != grid.cell_count() {
            self.reached.clear();
            self.reached.resize(grid.cell_count(), false);
        }
        let mut span = holding_span(shapes.len(), cell_of);
        for s in shapes {
            span = union(span, mark_cells_reached(grid, s, &mut self.reached));
        }
        self.bin(grid, shapes.len(), cell_of, span);
    }

    /// [`Self::rebuild`] for bilinear shape functions (whose support never
    /// leaves the holding cell) from the holding cell of every point. The
    /// bins depend on nothing else: when every point is in the cell it was
    /// in at the last call (the common case of an explicit step, whose points
    /// move a fraction of a cell), they are kept as they are.
    pub fn rebuild_bilinear(&mut self, grid: &Grid, cells: &[u32]) {
        debug_assert_eq!(grid.patch_side(), 2, "a bilinear grid");
        self.keep_or_rebin_bilinear(grid, cells.len(), |p| cells[p]);
    }

    /// The bilinear rebuild, point `p` held by cell `cell_of(p)`: the bins
    /// are kept when every point is in the cell it was in at the last
    /// rebuild, else sorted and numbered afresh (no cell is reached without
    /// holding a point).
    fn keep_or_rebin_bilinear(
        &mut self,
        grid: &Grid,
        n_points: usize,
        cell_of: impl Fn(usize) -> u32,
    ) {
        let unmoved = self.cell_start.len() == grid.cell_count() + 1
            && self.holding_cells.len() == n_points
            && (self.holding_cells.iter().enumerate()).all(|(p, &c)| cell_of(p) == c);
        if unmoved {
            return;
        }
        self.holding_cells.clear();
        self.holding_cells.extend((0..n_points).map(&cell_of));
        let span = holding_span(n_points, &cell_of);
        self.bin(grid, n_points, &cell_of, span);
    }

    /// Sort the points into their cells and number the cells and nodes,
    /// point `p` in cell `cell_of(p)`, every cell that holds a point or
    /// that `reached` marks within `span`. Visits `span` and the span of
    /// the last rebuild (the whole grid at the first, or when the number of
    /// points changed), then clears the marks.
    fn bin(
        &mut self,
        grid: &Grid,
        n_points: usize,
        cell_of: impl Fn(usize) -> u32,
        span: Range<usize>,
    ) {
        let n_cells = grid.cell_count();
        let kept = self.cell_start.len() == n_cells + 1
            && self.cell_start[n_cells] as usize == n_points
            && self.cell_slot.len() == n_cells
            && self.node_active.len() == grid.node_count();
        let visit = if kept {
            union(self.span.clone(), span.clone())
        } else {
            self.cell_start.clear();
            self.cell_start.resize(n_cells + 1, 0);
            self.cell_slot.clear();
            self.cell_slot.resize(n_cells, NONE);
            self.node_active.clear();
            self.node_active.resize(grid.node_count(), false);
            0..n_cells
        };
        self.sort_points(visit.clone(), n_points, cell_of);
        self.number_cells(grid, visit);
        if let Some(marks) = self.reached.get_mut(span.clone()) {
            marks.fill(false);
        }
        self.span = span;
    }

    /// `cell_start` and `order`: the points of every cell in index order
    /// (a stable counting sort), point `p` in cell `cell_of(p)`, every cell
    /// in `cells`; `cell_start` is 0 before them and `n_points` after.
    fn sort_points(
        &mut self,
        cells: Range<usize>,
        n_points: usize,
        cell_of: impl Fn(usize) -> u32,
    ) {
        let cell_start = &mut self.cell_start;
        cell_start[cells.start..=cells.end].fill(0);
        for p in 0..n_points {
            cell_start[cell_of(p) as usize + 1] += 1;
        }
        for c in cells.clone() {
            cell_start[c + 1] += cell_start[c];
        }
        self.order.clear();
        self.order.resize(n_points, 0);
        // `next[c]` is kept in `cell_slot` until the slots are numbered
        let next = &mut self.cell_slot;
        next[cells.clone()].copy_from_slice(&cell_start[cells]);
        for p in 0..n_points {
            let c = cell_of(p) as usize;
            self.order[next[c] as usize] = p as u32;
            next[c] += 1;
        }
    }

    /// The active and reached cells among `cells` (`self.reached[c]`: some
    /// support reaches cell `c`), their slots and the active nodes; every
    /// other cell and its nodes are inactive.
    fn number_cells(&mut self, grid: &Grid, cells: Range<usize>) {
        self.active_cells.clear();
        self.reached_cells.clear();
        self.active_nodes.clear();
        if cells.is_empty() {
            return;
        }
        // the nodes of `cells`: from the first one's lower left to the last
        // one's upper right
        let lower_left = |c: usize| grid.cell_nodes(c % grid.cells[0], c / grid.cells[0])[0];
        let nodes = lower_left(cells.start) as usize
            ..lower_left(cells.end - 1) as usize + grid.cells[0] + 3;
        self.node_active[nodes.clone()].fill(false);
        for c in cells {
            let holds_points = self.cell_start[c + 1] > self.cell_start[c];
            let is_reached = self.reached.get(c).copied().unwrap_or(false);
            self.cell_slot[c] = NONE;
            if holds_points {
                self.cell_slot[c] = self.active_cells.len() as u32;
                self.active_cells.push(c as u32);
            } else if is_reached {
                self.reached_cells.push(c as u32);
            }
            if holds_points || is_reached {
                let (ci, cj) = grid.cell_ij(c);
                for n in grid.cell_nodes(ci, cj) {
                    self.node_active[n as usize] = true;
                }
            }
        }
        let active = |&n: &u32| self.node_active[n as usize];
        let nodes = nodes.start as u32..nodes.end as u32;
        self.active_nodes.extend(nodes.filter(active));
    }

    /// Particles in cell `cell`, in index order.
    pub fn particles_in(&self, cell: usize) -> &[u32] {
        &self.order[self.cell_start[cell] as usize..self.cell_start[cell + 1] as usize]
    }
}

/// Mark the cells spanned by the support of `s` (the cells between its lowest
/// and highest node indices along each direction); returns the cells from
/// the first to the last marked (in index order).
fn mark_cells_reached<S: Support>(grid: &Grid, s: &S, reached: &mut [bool]) -> Range<usize> {
    let (mut lo, mut hi) = ([usize::MAX; 2], [0usize; 2]);
    for a in 0..s.support_size() {
        let (i, j) = grid.node_ij(s.node(a));
        lo = [lo[0].min(i), lo[1].min(j)];
        hi = [hi[0].max(i), hi[1].max(j)];
    }
    if lo[0] >= hi[0] || lo[1] >= hi[1] {
        return 0..0;
    }
    for cj in lo[1]..hi[1] {
        for ci in lo[0]..hi[0] {
            reached[cj * grid.cells[0] + ci] = true;
        }
    }
    lo[1] * grid.cells[0] + lo[0]..(hi[1] - 1) * grid.cells[0] + hi[0]
}

/// The cells from the lowest to the highest holding cell of `n_points`
/// points, point `p` in cell `cell_of(p)` (empty without points).
fn holding_span(n_points: usize, cell_of: impl Fn(usize) -> u32) -> Range<usize> {
    let (lo, hi) = (0..n_points)
        .map(|p| cell_of(p) as usize)
        .fold((usize::MAX, 0), |(lo, hi), c| (lo.min(c), hi.max(c + 1)));
    match lo < hi {
        true => lo..hi,
        false => 0..0,
    }
}

/// The smallest range that holds both (an empty range holds nothing).
fn union(a: Range<usize>, b: Range<usize>) -> Range<usize> {
    match (a.is_empty(), b.is_empty()) {
        (true, _) => b,
        (_, true) => a,
        _ => a.start.min(b.start)..a.end.max(b.end),
    }
}
