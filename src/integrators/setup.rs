//! Step setup, shared by both integrators and by the checks before a run:
//! shape functions at the start-of-step positions (DESIGN §2), the particles
//! binned by cell, and the shape functions of the boundary points (traction
//! points, rigid bodies' contact points).

use crate::error::{BoundaryPointKind, StepError};
use crate::grid::ShapeAt;
use crate::model::Model;
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
    /// Cells some GIMP domain reaches (binning buffer).
    reached: Vec<bool>,
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
        let positions = &model.particles.position;
        transfer::shapes_into(grid, positions, &mut self.scratch, &mut self.shapes).map_err(
            |o| StepError::ParticleLeftGrid {
                particle: o.particle,
                position: o.position,
            },
        )?;
        self.bins.rebuild(grid, &self.shapes, &mut self.reached);
        let min_points = model.traction_min_points();
        let boundary = |kind: BoundaryPointKind| {
            move |o: transfer::OutsideGrid| StepError::BoundaryPointLeftGrid {
                kind,
                point: o.particle,
                position: o.position,
            }
        };
        self.traction_shapes = model
            .traction
            .shapes(grid, &self.bins, min_points)
            .map_err(boundary(BoundaryPointKind::Traction))?;
        self.driven_shapes = model
            .driven
            .shapes(grid, &self.bins, min_points, &self.shapes)
            .map_err(boundary(BoundaryPointKind::Contact))?;
        Ok(())
    }
}
