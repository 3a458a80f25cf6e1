//! What a converged step commits at the material points, shared by both
//! integrators: the nonlocal variable κ̄(n+1) (DESIGN D35) and the double-mapped
//! stresses (D37–D39).

use super::{NonlocalStep, TrialStresses};
use crate::bc::DofMap;
use crate::constitutive::{PointState, Voigt};
use crate::grid::ShapeAt;
use crate::simulation::Simulation;
use crate::smoothing::{double_map, DoubleMapping, Equilibrium, MappingFrame};
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

    /// Energies of the converged step (M5), kJ per metre run, from the
    /// constitutive stresses before double mapping (Voigt dot products,
    /// engineering shear), with one strain increment Δε per point:
    /// - internal work Σ_p V_p(n) · ½(σ_p(n+1) + σ_p^R(n)) · Δε_p (elastic
    ///   energy stored plus dissipation);
    /// - plastic dissipation (DESIGN D43) Σ_p V_p(n) · ½(σ_p(n+1) + σ_p^R(n)) · Δε^p_p
    ///   with Δε^p = Δε − C(σ(n+1) − σ^R(n)); elastic materials contribute nothing.
    pub(crate) fn step_energies(&self, trial: &TrialStresses) -> (f64, f64) {
        let p = &self.particles;
        let strain: Vec<Voigt> = trial
            .gradient
            .iter()
            .map(|l| crate::transfer::strain_and_spin(l).0)
            .collect();
        let internal_work = (0..p.len())
            .map(|i| {
                let (now, before) = (&trial.stress[i], &trial.rotated[i]);
                let work: f64 = (0..4)
                    .map(|k| 0.5 * (now[k] + before[k]) * strain[i][k])
                    .sum();
                p.volume[i] * work
            })
            .sum();
        if self.materials.iter().all(|m| m.is_elastic()) {
            return (internal_work, 0.0);
        }
        // elastic points dissipate nothing: give them zero weight
        let volumes: Vec<f64> = (0..p.len())
            .map(|i| {
                if self.materials[p.material[i] as usize].is_elastic() {
                    0.0
                } else {
                    p.volume[i]
                }
            })
            .collect();
        let compliance: Vec<crate::constitutive::Mat4> = p
            .material
            .iter()
            .map(|&m| self.compliances[m as usize])
            .collect();
        let dissipation = crate::metrics::dissipation_increment(
            &volumes,
            &trial.stress,
            &trial.rotated,
            &strain,
            crate::metrics::ComplianceSource::PerPoint(&compliance),
        )
        .unwrap_or(f64::NAN);
        (internal_work, dissipation)
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
        let start = std::time::Instant::now();
        if mode != DoubleMapping::Off {
            let frame = MappingFrame {
                grid: &self.grid,
                bins,
                shapes,
                mass: &self.particles.mass,
            };
            let dofs = self
                .scene
                .smoothing
                .restore_forces
                .then(|| DofMap::new(bins, &self.constraints));
            let equilibrium = dofs.as_ref().map(|dofs| Equilibrium {
                volume: &self.particles.volume,
                dofs,
            });
            double_map(
                mode,
                &frame,
                equilibrium,
                &trial.rotated,
                &mut stress,
                &self.materials,
                &self.particles.material,
                &state,
                kappa_bar.as_deref(),
            )
            .map_err(|e| format!("double mapping: {e}"))?;
        }
        if mode != DoubleMapping::Off {
            self.profile.add(
                crate::profile::Stage::Smoothing,
                start.elapsed().as_secs_f64(),
            );
        }
        Ok((stress, state))
    }
}
