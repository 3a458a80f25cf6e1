//! Step setup, shared by both integrators and by the checks before a run:
//! shape functions at the start-of-step positions (DESIGN §2), the particles
//! binned by cell, and the shape functions of the boundary points (traction
//! points, rigid bodies' contact points).

use crate::error::{BoundaryPointKind, StepError};
use crate::grid::ShapeAt;
use crate::model::Model;
use crate::transfer::{self, ParticleBins};

/// The start-of-step interpolation of one (sub-)step.
pub struct StepSetup {
    /// N_ip, ∇N_ip at every material point.
    pub shapes: Vec<ShapeAt>,
    /// Points per cell, active cells and nodes.
    pub bins: ParticleBins,
    /// Shape functions of the traction points.
    pub traction_shapes: Vec<ShapeAt>,
    /// Shape functions of the rigid bodies' tied points.
    pub driven_shapes: Vec<ShapeAt>,
}

impl StepSetup {
    /// Shape functions and bins for the model as it is now; a material or
    /// boundary point outside the grid is an error naming it.
    pub fn new(model: &Model) -> Result<Self, StepError> {
        let grid = &model.grid;
        let shapes = transfer::shapes_at(grid, &model.particles.position).map_err(|o| {
            StepError::ParticleLeftGrid {
                particle: o.particle,
                position: o.position,
            }
        })?;
        let bins = ParticleBins::new(grid, &shapes);
        let min_points = model.traction_min_points();
        let boundary = |kind: BoundaryPointKind| {
            move |o: transfer::OutsideGrid| StepError::BoundaryPointLeftGrid {
                kind,
                point: o.particle,
                position: o.position,
            }
        };
        let traction_shapes = model
            .traction
            .shapes(grid, &bins, min_points)
            .map_err(boundary(BoundaryPointKind::Traction))?;
        let driven_shapes = model
            .driven
            .shapes(grid, &bins, min_points, &shapes)
            .map_err(boundary(BoundaryPointKind::Contact))?;
        Ok(Self {
            shapes,
            bins,
            traction_shapes,
            driven_shapes,
        })
    }
}
