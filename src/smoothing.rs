//! Double mapping of stresses (DESIGN §7, paper §2.1: González Acosta et al.
//! 2020): the converged stress increment of a step is mapped mass-weighted to
//! the nodes and interpolated back, which removes the cell-crossing stress
//! oscillations of the MPM. Applied once per converged step, after the
//! constitutive update and before the points move; state variables (κ, κ̄)
//! are not smoothed.

use std::sync::Arc;

use serde::{Deserialize, Serialize};

use crate::constitutive::{ConstitutiveModel, PointState, Voigt};
use crate::grid::{Grid, ShapeAt};
use crate::transfer::{self, ParticleBins};

/// Which stress is smoothed.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum DoubleMapping {
    /// On for materials that can soften, off otherwise (the paper's use).
    #[default]
    Auto,
    /// No smoothing.
    Off,
    /// Smooth the step's stress increment σ(n+1) − σ^R(n) (DESIGN D37–D38).
    Increment,
    /// Smooth the total stress σ(n+1).
    Total,
}

/// Apply double mapping to `stress` (the converged σ(n+1) of every point, in
/// place), given the rotated start-of-step stresses `rotated` (σ^R(n)), then
/// return every smoothed stress that lies outside the yield surface to it at
/// fixed p and θ (DESIGN D39) through [`ConstitutiveModel::project_to_surface`].
#[allow(clippy::too_many_arguments)]
pub fn double_map(
    mode: DoubleMapping,
    grid: &Grid,
    bins: &ParticleBins,
    shapes: &[ShapeAt],
    mass: &[f64],
    rotated: &[Voigt],
    stress: &mut [Voigt],
    materials: &[Arc<dyn ConstitutiveModel>],
    material: &[u16],
    state: &[PointState],
    strength_kappa: Option<&[f64]>,
) {
    // `Auto` is resolved by the caller (`Simulation::double_mapping`).
    if matches!(mode, DoubleMapping::Off | DoubleMapping::Auto) {
        return;
    }
    let base = |p: usize| -> Voigt {
        match mode {
            DoubleMapping::Increment => rotated[p],
            _ => [0.0; 4],
        }
    };
    // D37: Δσ̂_i = Σ_p N_ip m_p Δσ_p / Σ_p N_ip m_p
    let weighted = transfer::scatter::<5, _>(grid, bins, |p| {
        let s = &shapes[p];
        let b = base(p);
        let m = mass[p];
        let mut c = [[0.0; 5]; 4];
        for a in 0..4 {
            let w = s.n[a] * m;
            for k in 0..4 {
                c[a][k] = w * (stress[p][k] - b[k]);
            }
            c[a][4] = w;
        }
        c
    });
    let nodal: Vec<Voigt> = weighted
        .iter()
        .map(|v| {
            if v[4] > 0.0 {
                [v[0] / v[4], v[1] / v[4], v[2] / v[4], v[3] / v[4]]
            } else {
                [0.0; 4]
            }
        })
        .collect();
    // D38: σ_p ← σ^R_p + Σ_i N_ip Δσ̂_i, then D39
    for p in 0..stress.len() {
        let s = &shapes[p];
        let mut smoothed = base(p);
        for a in 0..4 {
            let v = &nodal[s.nodes[a] as usize];
            for k in 0..4 {
                smoothed[k] += s.n[a] * v[k];
            }
        }
        let model = &materials[material[p] as usize];
        stress[p] = if model.is_elastic() {
            smoothed
        } else {
            model.project_to_surface(&smoothed, &state[p], strength_kappa.map(|k| k[p]))
        };
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::constitutive::LinearElastic;

    /// A uniform stress increment on top of a varying start stress is left
    /// unchanged to round-off (1e−12): the mass-weighted nodal projection
    /// reproduces uniform fields exactly.
    #[test]
    fn uniform_increment_is_unchanged_and_mass_weighting_is_exact() {
        let grid = Grid {
            origin: [0.0, 0.0],
            cell_size: 0.5,
            cells: [3, 3],
        };
        let positions: Vec<[f64; 2]> = (0..36)
            .map(|i| [0.1 + 0.04 * i as f64, 0.2 + 0.03 * i as f64])
            .collect();
        let shapes = transfer::shapes_at(&grid, &positions).unwrap();
        let bins = ParticleBins::new(&grid, &shapes);
        let mass: Vec<f64> = (0..36).map(|i| 1.0 + 0.1 * i as f64).collect();
        let rotated: Vec<Voigt> = (0..36)
            .map(|i| [-100.0 - i as f64, -50.0, -70.0, 3.0 * i as f64])
            .collect();
        let increment = [-5.0, 2.0, 1.0, -0.5];
        let mut stress: Vec<Voigt> = rotated
            .iter()
            .map(|r| {
                [
                    r[0] + increment[0],
                    r[1] + increment[1],
                    r[2] + increment[2],
                    r[3] + increment[3],
                ]
            })
            .collect();
        let expected = stress.clone();
        let materials: Vec<Arc<dyn ConstitutiveModel>> =
            vec![Arc::new(LinearElastic::new(1000.0, 0.3))];
        let state = vec![PointState::default(); 36];
        double_map(
            DoubleMapping::Increment,
            &grid,
            &bins,
            &shapes,
            &mass,
            &rotated,
            &mut stress,
            &materials,
            &[0; 36],
            &state,
            None,
        );
        for (s, e) in stress.iter().zip(&expected) {
            for k in 0..4 {
                assert!((s[k] - e[k]).abs() < 1e-12 * e[k].abs().max(1.0));
            }
        }
    }
}
