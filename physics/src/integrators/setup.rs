//! Step setup, shared by both integrators and by the checks before a run:
//! shape functions at the start-of-step positions (theory §2), the particles
//! binned by cell, and the shape functions of the boundary points (traction
//! points, rigid bodies' contact points).

use crate::error::{BoundaryPointKind, StepError};
use crate::grid::{BilinearShape, ShapeAt, ShapeFunctions};
use crate::model::Model;
use crate::scene::DoubleMapping;
use crate::transfer::{self, ParticleBins, ShapeScratch};

/// The start-of-step interpolation of one (sub-)step.
#[derive(Default)]
pub struct StepSetup {
    /// N_ip, ∇N_ip at every material point.
    pub shapes: Vec<ShapeAt>,
    /// Points per cell, active cells and nodes.
    pub bins: ParticleBins,
    /// Shape functions of the traction points.
    pub traction_shapes: Vec<ShapeAt>,
    /// Shape functions of the rigid bodies' tied points.
    pub driven_shapes: Vec<ShapeAt>,
    /// Buffers of the shape functions and the binning, kept for [`Self::refresh`].
    scratch: ShapeScratch,
    /// The cell of every point (binning buffer, compact shapes).
    cells: Vec<u32>,
}

impl StepSetup {
    /// Shape functions and bins for the model as it is now; a material or
    /// boundary point outside the grid is an error naming it.
    pub fn new(model: &Model) -> Result<Self, StepError> {
        let mut setup = Self::default();
        setup.refresh(model)?;
        Ok(setup)
    }

    /// The setup of the model as it is now, in place: what [`Self::new`]
    /// gives, reusing the arrays of an earlier step (no allocation for the
    /// material points' shape functions and bins once they have grown).
    pub fn refresh(&mut self, model: &Model) -> Result<(), StepError> {
        let grid = &model.grid;
        let positions = &model.state.particles.position;
        transfer::shapes_into(grid, positions, &mut self.scratch, &mut self.shapes)
            .map_err(point_left_grid)?;
        self.bins.rebuild(grid, &self.shapes);
        self.boundary_shapes(model)
    }

    /// Whether the points of `model` may take the compact form of their
    /// shape functions ([`Self::refresh_compact`]): bilinear shape functions,
    /// no rigid body (its tied points take the points' full shapes) and no
    /// double mapping (it reads them).
    pub fn compact_applies(model: &Model) -> bool {
        model.grid.shape_functions == ShapeFunctions::Bilinear
            && model.state.driven.is_empty()
            && model.double_mapping() == DoubleMapping::Off
    }

    /// [`Self::refresh`] with the material points' shape functions in
    /// compact form, into `shapes` (when [`Self::compact_applies`]): the
    /// bins and the boundary points' shapes, `self.shapes` left empty.
    pub fn refresh_compact(
        &mut self,
        model: &Model,
        shapes: &mut Vec<BilinearShape>,
    ) -> Result<(), StepError> {
        debug_assert!(Self::compact_applies(model));
        let grid = &model.grid;
        let cells = &mut self.cells;
        transfer::bilinear_shapes_into(grid, &model.state.particles.position, shapes, cells)
            .map_err(point_left_grid)?;
        self.shapes.clear();
        self.bins.rebuild_bilinear(grid, cells);
        self.boundary_shapes(model)
    }

    /// Shape functions of the traction points and the rigid bodies' tied
    /// points, with the bins of the material points.
    fn boundary_shapes(&mut self, model: &Model) -> Result<(), StepError> {
        let grid = &model.grid;
        let min_points = model.traction_min_points();
        let boundary = |kind: BoundaryPointKind| {
            move |o: transfer::OutsideGrid| StepError::BoundaryPointLeftGrid {
                kind,
                point: o.particle,
                position: o.position,
            }
        };
        self.traction_shapes = model
            .state
            .traction
            .shapes(grid, &self.bins, min_points)
            .map_err(boundary(BoundaryPointKind::Traction))?;
        self.driven_shapes = model
            .state
            .driven
            .shapes(grid, &self.bins, min_points, &self.shapes)
            .map_err(boundary(BoundaryPointKind::Contact))?;
        Ok(())
    }
}

/// The error of a material point outside the grid.
fn point_left_grid(o: transfer::OutsideGrid) -> StepError {
    StepError::ParticleLeftGrid {
        particle: o.particle,
        position: o.position,
    }
}
