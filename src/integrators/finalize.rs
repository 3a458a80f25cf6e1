//! What a converged step commits at the material points, shared by both
//! integrators: the nonlocal variable κ̄(n+1) (DESIGN D35) and the double-mapped
//! stresses (D37–D39).

use super::{NonlocalStep, TrialStresses};
use crate::constitutive::{PointState, Voigt};
use crate::grid::ShapeAt;
use crate::simulation::Simulation;
use crate::smoothing::{double_map, DoubleMapping};
use crate::transfer::ParticleBins;

impl Simulation {
    /// The double-mapping mode in force: `auto` means `increment` when some
    /// material can soften (the paper's use), else `off`.
    pub fn double_mapping(&self) -> DoubleMapping {
        match self.scene.smoothing.double_mapping {
            DoubleMapping::Auto if self.materials.iter().any(|m| m.can_soften()) => {
                DoubleMapping::Increment
            }
            DoubleMapping::Auto => DoubleMapping::Off,
            mode => mode,
        }
    }

    /// Stresses and states to commit for the converged trial state.
    pub(crate) fn finalize_stresses(
        &self,
        bins: &ParticleBins,
        shapes: &[ShapeAt],
        trial: &TrialStresses,
        nonlocal: Option<&mut NonlocalStep>,
    ) -> Result<(Vec<Voigt>, Vec<PointState>), String> {
        let mut state = trial.state.clone();
        let kappa_bar = match nonlocal {
            Some(nl) => {
                let committed =
                    nl.committed(&self.particles, |p| trial.state[p].plastic_strain_eq)?;
                for (s, k) in state.iter_mut().zip(&committed) {
                    s.plastic_strain_eq_nonlocal = *k;
                }
                Some(committed)
            }
            None => None,
        };
        let mut stress = trial.stress.clone();
        let mode = self.double_mapping();
        if mode != DoubleMapping::Off {
            double_map(
                mode,
                &self.grid,
                bins,
                shapes,
                &self.particles.mass,
                &trial.rotated,
                &mut stress,
                &self.materials,
                &self.particles.material,
                &state,
                kappa_bar.as_deref(),
            );
        }
        Ok((stress, state))
    }
}
