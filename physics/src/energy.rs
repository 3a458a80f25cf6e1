//! The energy budget of a run (theory §9 M5, issue 39 item 5), kJ per metre
//! run, closed per step by its remainder:
//!
//! W = W_int + (K − K0) + B + R,                                    (E1)
//!
//! W the work of the external loads (gravity, follower pressures, rigid
//! bodies; `State::external_work`), W_int the work of the stresses on the
//! strain increments, K the kinetic energy of the points (with the points
//! removed after leaving the grid, which take theirs with them), B the
//! energy taken at the boundary (the kinetic energy the fixed dofs removed,
//! [`crate::integrators::boundary_work`] B1; the friction work, theory FR5;
//! the points' velocity into a wall, [`crate::walls`] B2), and R what remains: the
//! integrator's numerical dissipation (Newmark γ > ½, the P2G/G2P
//! projections, MUSL's re-map); R < 0 is energy the run created.
//! The internal work splits as
//!
//! W_int = U + D + G,                                               (E2)
//!
//! U = Σ_p ½ V_p σ_p·Cσ_p the stored elastic energy, D the plastic
//! dissipation (theory D43), and G the gap of the hypoelastic update: U is
//! weighted with the current volumes while each step's work uses V_p(n), so
//! G = −Σ_steps Σ_p ½ σ·Cσ ΔV_p (a point compressed under load stores less
//! than the work put in, one dilating under load more), plus what the
//! volume bound `grid.max_point_volume` and the removed points take.

use serde::Serialize;

use crate::model::Model;

/// The terms of (E1) and (E2) at one instant, kJ/m.
#[derive(Clone, Copy, Debug, Serialize, PartialEq)]
pub struct EnergyBudget {
    /// W.
    pub external_work: f64,
    /// W_int.
    pub internal_work: f64,
    /// U.
    pub stored_elastic: f64,
    /// D.
    pub dissipation: f64,
    /// K of the points in the run.
    pub kinetic_energy: f64,
    /// K0.
    pub initial_kinetic_energy: f64,
    /// Kinetic energy the removed points carried off the grid.
    pub removed_kinetic_energy: f64,
    /// B.
    pub boundary_work: f64,
    /// R of (E1).
    pub remainder: f64,
    /// G of (E2), W_int − U − D.
    pub internal_work_gap: f64,
}

impl EnergyBudget {
    /// The budget of `model` now.
    pub fn of(model: &Model) -> Self {
        let removed_kinetic_energy = removed_kinetic_energy(model);
        let kinetic_energy = model.kinetic_energy();
        let stored_elastic = model.strain_energy();
        let (external_work, internal_work) = (model.state.external_work, model.state.internal_work);
        Self {
            external_work,
            internal_work,
            stored_elastic,
            dissipation: model.state.dissipated_energy,
            kinetic_energy,
            initial_kinetic_energy: model.state.initial_kinetic_energy,
            removed_kinetic_energy,
            boundary_work: model.state.boundary_work,
            remainder: remainder(model),
            internal_work_gap: internal_work - stored_elastic - model.state.dissipated_energy,
        }
    }

    /// |R| as a share of the energy put in, max(|W|, K0) (the scale of a run
    /// driven by its loads or by its initial motion); zero when nothing was
    /// put in.
    pub fn remainder_share(&self) -> f64 {
        let scale = self.external_work.abs().max(self.initial_kinetic_energy);
        if scale > 0.0 {
            self.remainder.abs() / scale
        } else {
            0.0
        }
    }

    /// The warning of a remainder beyond `bound` (a share of the energy put
    /// in, `[output] energy_remainder_warning`), if any.
    pub fn warning(&self, bound: Option<f64>) -> Option<String> {
        let bound = bound?;
        let share = self.remainder_share();
        (share > bound).then(|| {
            format!(
                "energy budget: the remainder W - W_int - (K - K0) - B = {:.4e} kJ/m is {:.3} of the energy put in (bound output.energy_remainder_warning = {bound}): the time integration {} that much (W = {:.4e}, W_int = {:.4e}, K = {:.4e}, K0 = {:.4e}, B = {:.4e} kJ/m)",
                self.remainder,
                share,
                if self.remainder >= 0.0 { "dissipated" } else { "created" },
                self.external_work,
                self.internal_work,
                self.kinetic_energy + self.removed_kinetic_energy,
                self.initial_kinetic_energy,
                self.boundary_work,
            )
        })
    }
}

/// Σ ½ m |v|² of the points removed after leaving the grid (their velocity
/// when removed), kJ/m.
pub fn removed_kinetic_energy(model: &Model) -> f64 {
    model
        .state
        .lost_points
        .iter()
        .map(|p| 0.5 * p.mass * (p.velocity[0].powi(2) + p.velocity[1].powi(2)))
        .sum()
}

/// R of (E1), kJ/m: W − W_int − (K + K_removed − K0) − B.
pub fn remainder(model: &Model) -> f64 {
    let kinetic = model.kinetic_energy() + removed_kinetic_energy(model);
    model.state.external_work
        - model.state.internal_work
        - (kinetic - model.state.initial_kinetic_energy)
        - model.state.boundary_work
}
