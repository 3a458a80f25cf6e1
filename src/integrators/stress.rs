//! The stress-update stage shared by both integrators: for each material
//! point, Δε and ω from the nodal displacement increment (DESIGN D12), Jaumann
//! rotation of the stored stress (D13), and the constitutive update (§5).

use std::sync::Arc;

use rayon::prelude::*;

use super::regularisation::NonlocalStrength;
use crate::constitutive::{
    mat4_mul_vec, ConstitutiveError, ConstitutiveModel, Mat4, PointState, StrengthVariable, Voigt,
};
use crate::grid::ShapeAt;
use crate::particles::Particles;
use crate::transfer;

/// Trial stresses, states and tangents of all material points for a given
/// displacement increment (not yet committed).
#[derive(Clone, Debug, Default)]
pub struct TrialStresses {
    /// σ_{n+1}, kPa.
    pub stress: Vec<Voigt>,
    /// State after the update.
    pub state: Vec<PointState>,
    /// Algorithmic tangents dσ/dΔε.
    pub tangent: Vec<Mat4>,
    /// Displacement-increment gradient L per point (row-major 2×2).
    pub gradient: Vec<[f64; 4]>,
    /// σ^R(n): the committed stress rotated by the step's spin (D13).
    pub rotated: Vec<Voigt>,
    /// dσ_{n+1}/dω = D_alg C g (see `stiffness::add_spin_stiffness`); filled only
    /// when compliances are passed (unsymmetric tangents).
    pub spin_sensitivity: Vec<Voigt>,
}

/// Evaluate the stress update at every material point for the nodal
/// increment `du`. `strength` (nonlocal runs) gives the variable each point's
/// strength is evaluated at (D36); local runs pass `None`. On failure returns the lowest-index
/// failing point (deterministic whatever the thread count).
pub fn evaluate_stresses(
    particles: &Particles,
    materials: &[Arc<dyn ConstitutiveModel>],
    shapes: &[ShapeAt],
    du: &[[f64; 2]],
    strength: Option<NonlocalStrength<'_>>,
    compliances: Option<&[Mat4]>,
    trial: &mut TrialStresses,
) -> Result<(), (usize, ConstitutiveError)> {
    let n = particles.len();
    trial.stress.resize(n, [0.0; 4]);
    trial.state.resize(n, PointState::default());
    trial.gradient.resize(n, [0.0; 4]);
    trial.tangent.resize(n, [[0.0; 4]; 4]);
    trial.rotated.resize(n, [0.0; 4]);
    let failures: Vec<(usize, ConstitutiveError)> = trial
        .stress
        .par_iter_mut()
        .zip(trial.state.par_iter_mut())
        .zip(
            trial
                .gradient
                .par_iter_mut()
                .zip(trial.tangent.par_iter_mut()),
        )
        .zip(trial.rotated.par_iter_mut())
        .enumerate()
        .filter_map(|(p, (((stress, state), (grad, tangent)), rotated_out))| {
            let l = transfer::gradient(&shapes[p], du);
            *grad = l;
            let (strain_increment, spin) = transfer::strain_and_spin(&l);
            let rotated = transfer::rotate_stress(&particles.stress[p], spin);
            *rotated_out = rotated;
            let material = &materials[particles.material[p] as usize];
            let strength = strength.map_or(StrengthVariable::Local, |s| s.at(p));
            match material.update(&rotated, &strain_increment, &particles.state[p], strength) {
                Ok(update) => {
                    *stress = update.stress;
                    *state = update.state;
                    *tangent = update.tangent;
                    None
                }
                Err(e) => Some((p, e)),
            }
        })
        .collect();
    if let Some(compliances) = compliances {
        trial.spin_sensitivity.resize(n, [0.0; 4]);
        trial
            .spin_sensitivity
            .par_iter_mut()
            .enumerate()
            .for_each(|(p, out)| {
                let s = &particles.stress[p];
                let g = [2.0 * s[3], -2.0 * s[3], 0.0, s[1] - s[0]];
                let cg = mat4_mul_vec(&compliances[particles.material[p] as usize], &g);
                *out = mat4_mul_vec(&trial.tangent[p], &cg);
            });
    } else {
        trial.spin_sensitivity.clear();
    }
    match failures.into_iter().min_by_key(|(p, _)| *p) {
        Some(first) => Err(first),
        None => Ok(()),
    }
}
