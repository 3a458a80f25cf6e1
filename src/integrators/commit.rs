//! The commit stage, shared by both integrators: the converged step becomes
//! the state of the material points (DESIGN D14: F, V, accumulated strain;
//! stresses and states), the boundary points follow the grid motion, and
//! points that left the grid stop the run or are removed.

use super::stresses::ConvergedStresses;
use super::{StepSetup, TrialStresses};
use crate::error::StepError;
use crate::model::{Model, PointRemap};
use crate::particles::Particles;
use crate::scene::LostPointPolicy;
use crate::transfer::strain_and_spin;

/// The nodal results of the step the model keeps.
pub struct NodalResults<'a> {
    /// Support reactions per grid node, kN/m.
    pub reaction: &'a [[f64; 2]],
    /// Displacement increment Δu per grid node (moves the traction points).
    pub increment: &'a [[f64; 2]],
    /// Nodal motion that moves the rigid bodies' surface contact points: the
    /// one that moved the material points.
    pub contact_motion: &'a [[f64; 2]],
}

/// Commit the step: deformation and stresses at the points, the step's
/// energies, boundary points advected, lost points checked. Returns the
/// index remap when points were removed.
pub fn commit(
    model: &mut Model,
    setup: &StepSetup,
    trial: &TrialStresses,
    converged: ConvergedStresses,
    nodal: NodalResults,
) -> Result<Option<PointRemap>, StepError> {
    model.internal_work += converged.internal_work;
    model.dissipated_energy += converged.dissipation;
    let p = &mut model.particles;
    for i in 0..p.len() {
        deform(p, i, &trial.gradient[i]);
    }
    p.stress = converged.stress;
    p.state = converged.state;
    if model.scene.grid.lost_points == LostPointPolicy::Stop {
        if let Some(i) = (0..p.len()).find(|&i| !model.grid.contains(p.position[i])) {
            return Err(StepError::ParticleLeftGrid {
                particle: i,
                position: p.position[i],
            });
        }
    }
    if let Some(i) = (0..p.len()).find(|&i| p.stress[i].iter().any(|s| !s.is_finite())) {
        return Err(StepError::NonFiniteStress { particle: i });
    }
    model.external_work += model
        .traction
        .advect(&setup.traction_shapes, nodal.increment);
    model
        .driven
        .advect(&setup.driven_shapes, nodal.contact_motion);
    model.reaction = nodal.reaction.to_vec();
    model.last_increment = nodal.increment.to_vec();
    model.drop_lost_points()
}

/// F_p ← (I + L) F_p; V_p ← det(I + L) V_p; accumulate Δε (DESIGN D14).
fn deform(p: &mut Particles, i: usize, l: &[f64; 4]) {
    let df = [1.0 + l[0], l[1], l[2], 1.0 + l[3]];
    let f = p.def_grad[i];
    p.def_grad[i] = [
        df[0] * f[0] + df[1] * f[2],
        df[0] * f[1] + df[1] * f[3],
        df[2] * f[0] + df[3] * f[2],
        df[2] * f[1] + df[3] * f[3],
    ];
    p.volume[i] *= df[0] * df[3] - df[1] * df[2];
    let (de, _) = strain_and_spin(l);
    for k in 0..4 {
        p.strain[i][k] += de[k];
    }
}
