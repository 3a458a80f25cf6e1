//! Shape functions at the points: the located cells, the GIMP domains clipped
//! to the filled cells, and the bilinear fast path (theory D10).

use rayon::prelude::*;

use crate::grid::{BilinearShape, Grid, ShapeAt};

/// A particle that is not inside the grid.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OutsideGrid {
    /// Particle index.
    pub particle: usize,
    /// Its position, m.
    pub position: [f64; 2],
}

/// Shape functions at every particle position (evaluated once per step at
/// start-of-step positions, theory §2).
///
/// GIMP domains are clipped, along each direction, to the cells that hold
/// points: a domain reaches the neighbouring cell only if that cell holds
/// points too. Inside the body nothing changes (the domains move smoothly
/// across cell edges); at a free surface a domain does not reach into the
/// empty cell beyond. Without this, a node that a surface point's domain
/// barely overlaps (by ε) would get a stiffness of order (ε/h)² but a force
/// of order ε/h from the surface stress, and move by O(h/ε): measured, a
/// local biaxial run throws corner points off the grid.
pub fn shapes_at(grid: &Grid, positions: &[[f64; 2]]) -> Result<Vec<ShapeAt>, OutsideGrid> {
    let mut shapes = Vec::new();
    shapes_into(grid, positions, &mut ShapeScratch::default(), &mut shapes)?;
    Ok(shapes)
}

/// Reusable buffers of [`shapes_into`]: the cell of every point and which
/// cells hold points.
#[derive(Clone, Debug, Default)]
pub struct ShapeScratch {
    /// Cell `(ci, cj)` of every point, `None` outside the grid.
    located: Vec<Option<(usize, usize)>>,
    /// Whether each cell holds points (GIMP only: it clips the domains; all
    /// false between calls).
    pub(super) holds_points: Vec<bool>,
}

/// [`shapes_at`] into `shapes` (resized to one entry per point), with the
/// buffers of `scratch`: no allocation once they have grown to the run's size.
pub fn shapes_into(
    grid: &Grid,
    positions: &[[f64; 2]],
    scratch: &mut ShapeScratch,
    shapes: &mut Vec<ShapeAt>,
) -> Result<(), OutsideGrid> {
    let ShapeScratch {
        located,
        holds_points,
    } = scratch;
    located.clear();
    located.par_extend(positions.par_iter().map(|&x| grid.locate(x)));
    if let Some(p) = located.iter().position(Option::is_none) {
        return Err(OutsideGrid {
            particle: p,
            position: positions[p],
        });
    }
    // which cells hold points (needed only to clip GIMP domains): the
    // flags are all false between calls, so that marking and clearing them
    // costs the points, not the grid
    let gimp = grid.patch_side() > 2;
    let mark = |holds_points: &mut Vec<bool>, value: bool| {
        for &(ci, cj) in located.iter().flatten() {
            holds_points[cj * grid.cells[0] + ci] = value;
        }
    };
    if gimp {
        if holds_points.len() != grid.cell_count() {
            holds_points.clear();
            holds_points.resize(grid.cell_count(), false);
        }
        mark(holds_points, true);
    }
    let filled_cells = &*holds_points;
    let bounds = |ci: usize, cj: usize| {
        let h = grid.cell_size;
        let filled = |i: isize, j: isize| {
            i >= 0
                && j >= 0
                && (i as usize) < grid.cells[0]
                && (j as usize) < grid.cells[1]
                && filled_cells[j as usize * grid.cells[0] + i as usize]
        };
        let (i, j) = (ci as isize, cj as isize);
        let extent = |d: usize, k: isize, low: bool, high: bool| {
            let lo = k - low as isize;
            let hi = k + 1 + high as isize;
            [
                grid.origin[d] + lo as f64 * h,
                grid.origin[d] + hi as f64 * h,
            ]
        };
        [
            extent(0, i, filled(i - 1, j), filled(i + 1, j)),
            extent(1, j, filled(i, j - 1), filled(i, j + 1)),
        ]
    };
    shapes.resize(positions.len(), ShapeAt::default());
    shapes
        .par_iter_mut()
        .zip(positions)
        .zip(located.par_iter())
        .for_each(|((shape, &x), cell)| {
            // every point is located (checked above)
            if let Some(cell) = *cell {
                *shape = grid.shape_in(cell, x, bounds);
            }
        });
    if gimp {
        mark(holds_points, false);
    }
    Ok(())
}

/// The compact bilinear shape functions ([`BilinearShape`]) of every point
/// of a bilinear grid into `shapes`, and its holding cell into `cells`: the
/// values [`shapes_into`] gives, from 40 rather than 272 bytes a point.
pub fn bilinear_shapes_into(
    grid: &Grid,
    positions: &[[f64; 2]],
    shapes: &mut Vec<BilinearShape>,
    cells: &mut Vec<u32>,
) -> Result<(), OutsideGrid> {
    debug_assert_eq!(grid.patch_side(), 2, "a bilinear grid");
    shapes.resize(positions.len(), BilinearShape::default());
    cells.resize(positions.len(), 0);
    // runs of points in a plain loop (no early exit: a point outside the
    // grid is rare, and is found again below)
    const RUN: usize = 1024;
    let outside = shapes
        .par_chunks_mut(RUN)
        .zip(cells.par_chunks_mut(RUN))
        .zip(positions.par_chunks(RUN))
        .map(|((shapes, cells), positions)| {
            let mut outside = false;
            for ((shape, cell), &x) in shapes.iter_mut().zip(cells).zip(positions) {
                match grid.locate(x) {
                    Some((ci, cj)) => {
                        *shape = grid.bilinear_shape(ci, cj, x);
                        *cell = shape.cell;
                    }
                    None => outside = true,
                }
            }
            outside
        })
        .reduce(|| false, |a, b| a || b);
    match outside {
        true => {
            let p = positions
                .iter()
                .position(|&x| grid.locate(x).is_none())
                .unwrap_or_default();
            Err(OutsideGrid {
                particle: p,
                position: positions[p],
            })
        }
        false => Ok(()),
    }
}
