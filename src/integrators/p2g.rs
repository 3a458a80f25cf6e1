//! Particle-to-grid stage pieces both integrators use (DESIGN D10–D11): the
//! external nodal forces. The nodal mass, momentum and internal force come
//! from the kernels in [`crate::transfer`].

use super::StepSetup;
use crate::model::Model;
use crate::transfer;

/// f_i^ext at time `t`: body force Σ_p N_ip m_p b(t) (when gravity is on) plus
/// the follower pressures of the traction points, per grid node (DESIGN D10).
pub fn external_force(model: &Model, setup: &StepSetup, t: f64) -> Vec<[f64; 2]> {
    let grid = &model.grid;
    let p = &model.particles;
    let g = model.scene.loads.gravity_at(t);
    let mut external = if g != 0.0 {
        transfer::body_force(grid, &setup.bins, &setup.shapes, &p.mass, [0.0, -g])
    } else {
        vec![[0.0; 2]; grid.node_count()]
    };
    model
        .traction
        .add_forces(&setup.traction_shapes, &mut external);
    external
}
