//! The fixed regular background grid (DESIGN §2): square cells of side `h`,
//! bilinear 4-node cells, node numbering, cell lookup.

use crate::shape;

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
}

/// Where a point sits in the grid: its cell, the cell's four global node
/// indices (local order of [`shape::NODE_SIGNS`]) and the shape function
/// values and gradients there.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ShapeAt {
    /// Cell index.
    pub cell: u32,
    /// Global node indices of the cell's corners.
    pub nodes: [u32; 4],
    /// N_a(x).
    pub n: [f64; 4],
    /// ∇N_a(x), 1/m.
    pub dn: [[f64; 2]; 4],
}

impl Grid {
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
    /// (DESIGN §2). Returns `None` when `x` is outside the grid.
    pub fn locate(&self, x: [f64; 2]) -> Option<(usize, usize)> {
        if !self.contains(x) || !x[0].is_finite() || !x[1].is_finite() {
            return None;
        }
        let fx = ((x[0] - self.origin[0]) / self.cell_size).floor() as isize;
        let fy = ((x[1] - self.origin[1]) / self.cell_size).floor() as isize;
        let ci = fx.clamp(0, self.cells[0] as isize - 1) as usize;
        let cj = fy.clamp(0, self.cells[1] as isize - 1) as usize;
        Some((ci, cj))
    }

    /// Shape functions of the cell `(ci, cj)` evaluated at `x` (DESIGN D9).
    pub fn shape_in_cell(&self, ci: usize, cj: usize, x: [f64; 2]) -> ShapeAt {
        let h = self.cell_size;
        let xc = self.origin[0] + (ci as f64 + 0.5) * h;
        let yc = self.origin[1] + (cj as f64 + 0.5) * h;
        let xi = 2.0 * (x[0] - xc) / h;
        let eta = 2.0 * (x[1] - yc) / h;
        ShapeAt {
            cell: (cj * self.cells[0] + ci) as u32,
            nodes: self.cell_nodes(ci, cj),
            n: shape::values(xi, eta),
            dn: shape::gradients(xi, eta, h),
        }
    }

    /// Shape functions at `x` in the cell that contains it; `None` outside the grid.
    pub fn shape_at(&self, x: [f64; 2]) -> Option<ShapeAt> {
        self.locate(x).map(|(ci, cj)| self.shape_in_cell(ci, cj, x))
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
        Grid {
            origin: [1.0, -2.0],
            cell_size: 0.5,
            cells: [4, 3],
        }
    }

    /// Interpolating node coordinates reproduces the point (linear completeness).
    #[test]
    fn shape_interpolates_position() {
        let g = grid();
        for &x in &[[1.1, -1.9], [2.74, -0.6], [3.0, -0.5], [1.0, -2.0]] {
            let s = g.shape_at(x).expect("inside");
            let mut y = [0.0; 2];
            for a in 0..4 {
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
