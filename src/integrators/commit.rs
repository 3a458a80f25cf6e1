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
    check_finite_points(p)?;
    check_finite_nodes(&model.grid, &nodal)?;
    if model.scene.grid.lost_points == LostPointPolicy::Stop {
        if let Some(i) = (0..p.len()).find(|&i| !model.grid.contains(p.position[i])) {
            return Err(StepError::ParticleLeftGrid {
                particle: i,
                position: p.position[i],
            });
        }
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

/// The one pass over the committed point state: the first point with a NaN
/// or infinite variable stops the run, naming it.
fn check_finite_points(p: &Particles) -> Result<(), StepError> {
    let finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
    for i in 0..p.len() {
        if !finite(&p.stress[i]) {
            return Err(StepError::NonFiniteStress { particle: i });
        }
        let quantity = if !finite(&p.position[i]) {
            "position"
        } else if !finite(&p.velocity[i]) {
            "velocity"
        } else if !finite(&p.acceleration[i]) {
            "acceleration"
        } else if !(p.volume[i].is_finite() && p.volume[i] > 0.0) {
            "volume (non-finite or not positive)"
        } else if !finite(&p.def_grad[i]) {
            "deformation gradient"
        } else if !finite(&p.strain[i]) {
            "strain"
        } else if !(p.state[i].plastic_strain_eq.is_finite()
            && p.state[i].plastic_strain_eq_nonlocal.is_finite()
            && finite(&p.state[i].plastic_strain))
        {
            "plastic strain"
        } else {
            continue;
        };
        let position = if finite(&p.position[i]) {
            p.position[i]
        } else {
            p.position0[i]
        };
        return Err(StepError::NonFinitePoint {
            particle: i,
            quantity,
            position,
        });
    }
    Ok(())
}

/// The nodal results the model keeps must be finite.
fn check_finite_nodes(grid: &crate::grid::Grid, nodal: &NodalResults) -> Result<(), StepError> {
    for (quantity, values) in [
        ("reaction", nodal.reaction),
        ("displacement increment", nodal.increment),
    ] {
        if let Some(node) = values
            .iter()
            .position(|v| !(v[0].is_finite() && v[1].is_finite()))
        {
            return Err(StepError::NonFiniteNode {
                node,
                quantity,
                position: grid.node_position(node),
            });
        }
    }
    Ok(())
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
