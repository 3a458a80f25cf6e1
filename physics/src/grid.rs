//! The fixed regular background grid (theory §2): square cells of side `h`,
//! node numbering, cell lookup, and the shape functions of a point: bilinear
//! (theory D9, the paper's) or uGIMP (particle-domain averaged, an option that
//! removes the cell-crossing error of D9).

use crate::shape;

/// Largest number of grid nodes a point's shape functions reach (3 × 3 for GIMP).
pub const MAX_SUPPORT: usize = 9;

/// Which shape functions connect points and nodes.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub enum ShapeFunctions {
    /// Bilinear N_a of the cell that holds the point (theory D9); the support
    /// is the cell's 4 nodes and ∇N jumps when a point crosses a cell edge.
    #[default]
    Bilinear,
    /// uGIMP (Bardenhagen & Kober 2004): N and ∇N averaged over a square
    /// particle domain of half-width `half_width` (m), clipped to the grid
    /// ([`shape::gimp_1d`]). Continuous gradients across cell edges; a point
    /// within `half_width` of a grid line also reaches the nodes beyond it.
    Gimp {
        /// Half-width l_p of the particle domain, m (h/(2·points per cell)).
        half_width: f64,
    },
}

/// A regular grid of `cells[0] × cells[1]` square cells of side `cell_size` (m),
/// lower-left corner at `origin`. Node `(i, j)` has index `j·(cells[0]+1) + i`;
/// cell `(ci, cj)` has index `cj·cells[0] + ci`.
#[derive(Clone, Debug, PartialEq)]
pub struct Grid {
    /// Lower-left corner of the grid, m.
    pub origin: [f64; 2],
    /// Cell side h, m (the paper's l_ele).
    pub cell_size: f64,
    /// Number of cells along x and y.
    pub cells: [usize; 2],
    /// Shape functions of the material points.
    pub shape_functions: ShapeFunctions,
}

/// Where a point sits in the grid: its cell, the nodes its shape functions
/// reach (the first `count` entries), their places in the cell's node patch
/// ([`Grid::patch_nodes`]), and the values and gradients there.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ShapeAt {
    /// Index of the cell that holds the point.
    pub cell: u32,
    /// Number of nodes in the support.
    pub count: u8,
    /// Global node indices.
    pub nodes: [u32; MAX_SUPPORT],
    /// Place of each node in the patch of `cell`, row-major (`j·side + i`).
    pub local: [u8; MAX_SUPPORT],
    /// N_a(x).
    pub n: [f64; MAX_SUPPORT],
    /// ∇N_a(x), 1/m.
    pub dn: [[f64; 2]; MAX_SUPPORT],
}

impl ShapeAt {
    /// Indices `0..count` of the support.
    #[inline]
    pub fn support(&self) -> std::ops::Range<usize> {
        0..self.count as usize
    }
}

/// The shape functions of one point as the transfer kernels read them: the
/// nodes of its support in order, their places in the holding cell's node
/// patch, N_a and ∇N_a. Implemented by [`ShapeAt`] and by the compact
/// [`BilinearShape`]; a kernel generic over it gives the same numbers with
/// either (same nodes, values and order).
pub trait Support: Sync {
    /// Index of the cell that holds the point.
    fn holding_cell(&self) -> u32;
    /// Number of nodes in the support.
    fn support_size(&self) -> usize;
    /// Global index of support node `a`.
    fn node(&self, a: usize) -> usize;
    /// Place of support node `a` in the patch of the holding cell.
    fn place(&self, a: usize) -> usize;
    /// N_a.
    fn value(&self, a: usize) -> f64;
    /// ∇N_a, 1/m.
    fn gradient(&self, a: usize) -> [f64; 2];
}

impl Support for ShapeAt {
    #[inline]
    fn holding_cell(&self) -> u32 {
        self.cell
    }
    #[inline]
    fn support_size(&self) -> usize {
        self.count as usize
    }
    #[inline]
    fn node(&self, a: usize) -> usize {
        self.nodes[a] as usize
    }
    #[inline]
    fn place(&self, a: usize) -> usize {
        self.local[a] as usize
    }
    #[inline]
    fn value(&self, a: usize) -> f64 {
        self.n[a]
    }
    #[inline]
    fn gradient(&self, a: usize) -> [f64; 2] {
        self.dn[a]
    }
}

/// Bilinear shape functions of a point (theory D9) in compact form: what
/// they are evaluated from (the holding cell, its first node, the natural
/// coordinates ξ, η), in 40 bytes instead of the 272 of a [`ShapeAt`]. N_a
/// and ∇N_a are formed where a kernel reads them, by the expressions of
/// [`shape::values`] and [`shape::gradients`]: the same numbers, nodes and
/// order as the point's [`ShapeAt`]. For the kernels that stream every
/// point's shape functions several times a step, the few operations cost
/// less than the memory traffic they save.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct BilinearShape {
    /// Index of the cell that holds the point.
    pub cell: u32,
    /// Global index of the cell's lower-left node.
    pub first_node: u32,
    /// Nodes per grid row (the upper nodes are one row above).
    pub row: u32,
    /// Natural coordinates (ξ, η) ∈ [−1, 1]² in the cell.
    pub xi_eta: [f64; 2],
    /// (2/h)·¼: ∇N_a = this × (ξ_a(1 + η_a η), η_a(1 + ξ_a ξ)).
    pub quarter_scale: f64,
}

impl BilinearShape {
    /// Places in the cell's 2 × 2 node patch of the nodes in the order of
    /// [`shape::NODE_SIGNS`].
    const PLACES: [usize; 4] = [0, 1, 3, 2];
}

impl Support for BilinearShape {
    #[inline]
    fn holding_cell(&self) -> u32 {
        self.cell
    }
    #[inline]
    fn support_size(&self) -> usize {
        4
    }
    #[inline]
    fn node(&self, a: usize) -> usize {
        let (first, row) = (self.first_node as usize, self.row as usize);
        [first, first + 1, first + 1 + row, first + row][a]
    }
    #[inline]
    fn place(&self, a: usize) -> usize {
        Self::PLACES[a]
    }
    #[inline]
    fn value(&self, a: usize) -> f64 {
        let [xi, eta] = self.xi_eta;
        let sign = shape::NODE_SIGNS[a];
        0.25 * (1.0 + sign[0] * xi) * (1.0 + sign[1] * eta)
    }
    #[inline]
    fn gradient(&self, a: usize) -> [f64; 2] {
        let [xi, eta] = self.xi_eta;
        let sign = shape::NODE_SIGNS[a];
        [
            self.quarter_scale * sign[0] * (1.0 + sign[1] * eta),
            self.quarter_scale * sign[1] * (1.0 + sign[0] * xi),
        ]
    }
}

impl Grid {
    /// A grid with bilinear shape functions.
    pub fn bilinear(origin: [f64; 2], cell_size: f64, cells: [usize; 2]) -> Self {
        Self {
            origin,
            cell_size,
            cells,
            shape_functions: ShapeFunctions::Bilinear,
        }
    }

    /// Number of grid nodes.
    pub fn node_count(&self) -> usize {
        (self.cells[0] + 1) * (self.cells[1] + 1)
    }

    /// Number of cells.
    pub fn cell_count(&self) -> usize {
        self.cells[0] * self.cells[1]
    }

    /// Upper-right corner of the grid, m.
    pub fn extent_max(&self) -> [f64; 2] {
        [
            self.origin[0] + self.cells[0] as f64 * self.cell_size,
            self.origin[1] + self.cells[1] as f64 * self.cell_size,
        ]
    }

    /// Coordinates of node `node`, m.
    pub fn node_position(&self, node: usize) -> [f64; 2] {
        let nx = self.cells[0] + 1;
        let (i, j) = (node % nx, node / nx);
        [
            self.origin[0] + i as f64 * self.cell_size,
            self.origin[1] + j as f64 * self.cell_size,
        ]
    }

    /// Grid indices `(i, j)` of node `node`.
    pub fn node_ij(&self, node: usize) -> (usize, usize) {
        let nx = self.cells[0] + 1;
        (node % nx, node / nx)
    }

    /// The four global node indices of cell `(ci, cj)`, local order of [`shape::NODE_SIGNS`].
    pub fn cell_nodes(&self, ci: usize, cj: usize) -> [u32; 4] {
        let nx = self.cells[0] + 1;
        let n0 = cj * nx + ci;
        [
            n0 as u32,
            (n0 + 1) as u32,
            (n0 + 1 + nx) as u32,
            (n0 + nx) as u32,
        ]
    }

    /// The four global node indices of cell `(ci, cj)` in row-major order
    /// (lower-left, lower-right, upper-left, upper-right), the order of the
    /// 8×8 cell blocks of `stiffness::system_blocks`.
    pub fn cell_nodes_row_major(&self, ci: usize, cj: usize) -> [u32; 4] {
        let [ll, lr, ur, ul] = self.cell_nodes(ci, cj);
        [ll, lr, ul, ur]
    }

    /// Side of the node patch of a cell: the nodes any point of the cell can
    /// reach (2 bilinear, 4 GIMP).
    pub fn patch_side(&self) -> usize {
        match self.shape_functions {
            ShapeFunctions::Bilinear => 2,
            ShapeFunctions::Gimp { .. } => 4,
        }
    }

    /// Grid indices of the lower-left node of the patch of cell `(ci, cj)`
    /// (may lie outside the grid for GIMP boundary cells).
    pub fn patch_origin(&self, ci: usize, cj: usize) -> (isize, isize) {
        let offset = (self.patch_side() / 2 - 1) as isize;
        (ci as isize - offset, cj as isize - offset)
    }

    /// Global node indices of the patch of cell `(ci, cj)`, row-major, with
    /// `None` for places outside the grid.
    pub fn patch_nodes(&self, ci: usize, cj: usize) -> Vec<Option<u32>> {
        let side = self.patch_side() as isize;
        let (i0, j0) = self.patch_origin(ci, cj);
        let (nx, ny) = (self.cells[0] as isize + 1, self.cells[1] as isize + 1);
        let mut nodes = Vec::with_capacity((side * side) as usize);
        for j in j0..j0 + side {
            for i in i0..i0 + side {
                let inside = (0..nx).contains(&i) && (0..ny).contains(&j);
                nodes.push(inside.then_some((j * nx + i) as u32));
            }
        }
        nodes
    }

    /// Place of node `(i, j)` in the patch of cell `(ci, cj)`.
    fn patch_place(&self, ci: usize, cj: usize, i: usize, j: usize) -> u8 {
        let (i0, j0) = self.patch_origin(ci, cj);
        let side = self.patch_side() as isize;
        ((j as isize - j0) * side + (i as isize - i0)) as u8
    }

    /// Whether `x` lies inside the grid (boundary included).
    pub fn contains(&self, x: [f64; 2]) -> bool {
        let max = self.extent_max();
        let tol = 1e-12 * self.cell_size;
        x[0] >= self.origin[0] - tol
            && x[1] >= self.origin[1] - tol
            && x[0] <= max[0] + tol
            && x[1] <= max[1] + tol
    }

    /// Cell `(ci, cj)` containing `x`, by floor((x − x0)/h) clamped to the grid
    /// (theory §2). Returns `None` when `x` is outside the grid.
    #[inline]
    pub fn locate(&self, x: [f64; 2]) -> Option<(usize, usize)> {
        if !self.contains(x) || !x[0].is_finite() || !x[1].is_finite() {
            return None;
        }
        let fx = shape::floor_int((x[0] - self.origin[0]) / self.cell_size) as isize;
        let fy = shape::floor_int((x[1] - self.origin[1]) / self.cell_size) as isize;
        let ci = fx.clamp(0, self.cells[0] as isize - 1) as usize;
        let cj = fy.clamp(0, self.cells[1] as isize - 1) as usize;
        Some((ci, cj))
    }

    /// Bilinear shape functions of the cell `(ci, cj)` evaluated at `x`
    /// (theory D9), whatever the grid's point shape functions (traction
    /// points use these: they are boundary quadrature points, not volumes).
    pub fn shape_in_cell(&self, ci: usize, cj: usize, x: [f64; 2]) -> ShapeAt {
        let h = self.cell_size;
        let [xi, eta] = self.bilinear_shape(ci, cj, x).xi_eta;
        let n = shape::values(xi, eta);
        let dn = shape::gradients(xi, eta, h);
        let nodes = self.cell_nodes(ci, cj);
        let mut s = ShapeAt {
            cell: (cj * self.cells[0] + ci) as u32,
            count: 4,
            ..ShapeAt::default()
        };
        for (a, sign) in shape::NODE_SIGNS.iter().enumerate() {
            let (i, j) = (ci + (sign[0] > 0.0) as usize, cj + (sign[1] > 0.0) as usize);
            s.nodes[a] = nodes[a];
            s.local[a] = self.patch_place(ci, cj, i, j);
            s.n[a] = n[a];
            s.dn[a] = dn[a];
        }
        s
    }

    /// [`Self::shape_in_cell`] in compact form.
    #[inline]
    pub fn bilinear_shape(&self, ci: usize, cj: usize, x: [f64; 2]) -> BilinearShape {
        let h = self.cell_size;
        let xc = self.origin[0] + (ci as f64 + 0.5) * h;
        let yc = self.origin[1] + (cj as f64 + 0.5) * h;
        let row = self.cells[0] + 1;
        BilinearShape {
            cell: (cj * self.cells[0] + ci) as u32,
            first_node: (cj * row + ci) as u32,
            row: row as u32,
            xi_eta: [2.0 * (x[0] - xc) / h, 2.0 * (x[1] - yc) / h],
            quarter_scale: 2.0 / h * 0.25,
        }
    }

    /// uGIMP shape functions at `x` of the cell `(ci, cj)` that holds it: the
    /// tensor product of [`shape::gimp_1d`] along x and y, the domain clipped
    /// to `bounds` (`[[x_lo, x_hi], [y_lo, y_hi]]`, grid lines).
    fn gimp_in_cell(
        &self,
        (ci, cj): (usize, usize),
        x: [f64; 2],
        half_width: f64,
        bounds: [[f64; 2]; 2],
    ) -> ShapeAt {
        let h = self.cell_size;
        let along = |d: usize| shape::gimp_1d(self.origin[d], h, x[d], half_width, bounds[d]);
        let (gx, gy) = (along(0), along(1));
        let nx = self.cells[0] + 1;
        let mut s = ShapeAt {
            cell: (cj * self.cells[0] + ci) as u32,
            ..ShapeAt::default()
        };
        let mut a = 0;
        for ky in 0..gy.count {
            for kx in 0..gx.count {
                let (i, j) = (gx.node[kx], gy.node[ky]);
                s.nodes[a] = (j * nx + i) as u32;
                s.local[a] = self.patch_place(ci, cj, i, j);
                s.n[a] = gx.weight[kx] * gy.weight[ky];
                s.dn[a] = [
                    gx.gradient[kx] * gy.weight[ky],
                    gx.weight[kx] * gy.gradient[ky],
                ];
                a += 1;
            }
        }
        s.count = a as u8;
        s
    }

    /// Shape functions of a material point at `x` (the grid's
    /// [`ShapeFunctions`]; a GIMP domain is clipped to the grid); `None`
    /// outside the grid.
    pub fn shape_at(&self, x: [f64; 2]) -> Option<ShapeAt> {
        let max = self.extent_max();
        let bounds = [[self.origin[0], max[0]], [self.origin[1], max[1]]];
        let cell = self.locate(x)?;
        Some(self.shape_in(cell, x, |_, _| bounds))
    }

    /// Shape functions at `x` of a point that cell `cell` holds; a GIMP
    /// domain is clipped to `bounds(ci, cj)` (ignored for bilinear).
    pub fn shape_in(
        &self,
        (ci, cj): (usize, usize),
        x: [f64; 2],
        bounds: impl Fn(usize, usize) -> [[f64; 2]; 2],
    ) -> ShapeAt {
        match self.shape_functions {
            ShapeFunctions::Bilinear => self.shape_in_cell(ci, cj, x),
            ShapeFunctions::Gimp { half_width } => {
                self.gimp_in_cell((ci, cj), x, half_width, bounds(ci, cj))
            }
        }
    }

    /// Cell `(ci, cj)` from a cell index.
    pub fn cell_ij(&self, cell: usize) -> (usize, usize) {
        (cell % self.cells[0], cell / self.cells[0])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid() -> Grid {
        Grid::bilinear([1.0, -2.0], 0.5, [4, 3])
    }

    /// Interpolating node coordinates reproduces the point (linear completeness).
    #[test]
    fn shape_interpolates_position() {
        let g = grid();
        for &x in &[[1.1, -1.9], [2.74, -0.6], [3.0, -0.5], [1.0, -2.0]] {
            let s = g.shape_at(x).expect("inside");
            let mut y = [0.0; 2];
            for a in s.support() {
                let xn = g.node_position(s.nodes[a] as usize);
                y[0] += s.n[a] * xn[0];
                y[1] += s.n[a] * xn[1];
            }
            assert!(
                (y[0] - x[0]).abs() < 1e-13 && (y[1] - x[1]).abs() < 1e-13,
                "{x:?} -> {y:?}"
            );
        }
    }

    /// The upper grid boundary belongs to the last cell; outside points are refused.
    #[test]
    fn lookup_clamps_upper_boundary_and_refuses_outside() {
        let g = grid();
        assert_eq!(g.locate([3.0, -0.5]), Some((3, 2)));
        assert_eq!(g.locate([3.01, 0.0]), None);
        assert_eq!(g.locate([f64::NAN, 0.0]), None);
    }
}
