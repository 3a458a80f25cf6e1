//! Quasi-static path following by dissipation control (theory §3.7,
//! eqs. PF1–PF6).
//!
//! A displacement-driven quasi-static run moves its rigid bodies by a fixed
//! travel per step; where the load–travel curve turns back (a snap-back
//! after a brittle peak) no equilibrium exists at the next travel and Newton
//! fails. Here the anchors' time parameter τ (the rigid bodies' travel per
//! unit velocity) is an unknown of each step beside the nodal increments,
//! and one linear constraint in the plane of travel and driven load fixes
//! the step (PF2):
//!
//! g(Δu, Δτ) = c_τ Δτ + c_F (F(Δu, Δτ) − F_n) − s = 0.
//!
//! In the elastic range the travel is prescribed, (c_τ, c_F) = (1/Δt, 0),
//! s = 1, Δt the scene's nominal step. Once a step's travel is mostly
//! plastic, the constraint prescribes the plastic travel instead,
//! Δτ/Δt − ΔF/F_ref = s, with F_ref the load change of the first (elastic)
//! step: τ − F/K_e (K_e = F_ref/Δt the elastic stiffness of the loading) is
//! the travel left when the load is taken off elastically, and F times its
//! increment is the energy the step dissipates (PF3; Gutiérrez's energy
//! release control with elastic unloading). Elastic unloading keeps the
//! plastic travel fixed, so this constraint cannot follow the elastic
//! unloading branch that a constraint on the increment's length finds after
//! a brittle peak (measured: an arc length in the plane of travel and load
//! unloaded the local footing at h = 0.25 m elastically from its peak to a
//! tensile load). The driven load F is linear in (Δu, Δτ) (PF1), so every
//! full Newton correction meets the constraint exactly. A step that jumps
//! onto an elastic branch measures the body's present unloading stiffness,
//! which replaces K_e from then on (PF6).

use super::step_system::StepSystem;
use super::tangent::Border;
use crate::bc::TravelDerivatives;

/// A step whose plastic travel is at least this share of its travel (or
/// whose travel is not positive) hands the next step to the plastic-travel
/// constraint (PF5).
pub const PLASTIC_SHARE: f64 = 0.5;

/// A plastic-travel step longer than this many times its predicted length is
/// redone with half the plastic travel (PF5).
pub const MAX_JUMP: f64 = 4.0;

/// A jump whose plastic travel is at most this share of its travel is an
/// elastic branch: its load change over its travel is the body's present
/// unloading stiffness (PF6).
pub const ELASTIC_SHARE: f64 = 0.1;

/// The most times one step re-measures the unloading stiffness (PF6).
pub const MAX_RELEARNED: usize = 3;

/// A step taken in at most this many Newton iterations lets the next
/// plastic travel double (PF5).
const EASY_ITERATIONS: usize = 8;

/// The linear constraint of one path-following step (theory PF2).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PathConstraint {
    /// c_τ, per unit time.
    pub travel_weight: f64,
    /// c_F, per kN/m.
    pub load_weight: f64,
    /// s, scaled.
    pub arc: f64,
    /// F_n, the driven load at the start of the step, kN/m.
    pub start_load: f64,
    /// Newton's start: the last step's nodal increment times this factor
    /// (0: from Δu = 0), with the travel `start_travel`. A plastic-travel step must
    /// start off the elastic state: at Δu = 0 every point's tangent is
    /// elastic, and along the elastic tangent the plastic travel cannot
    /// change (the bordered system is singular there).
    pub predictor: f64,
    /// The start's travel Δτ: the prescribed travel under displacement
    /// control, else the last step's times `predictor`.
    pub start_travel: f64,
    /// The longest step (Δτ/Δt, ΔF/F_ref) accepted, scaled (∞: any).
    pub max_step: f64,
    /// F_ref, kN/m.
    pub load_scale: f64,
}

impl PathConstraint {
    /// Displacement control: a step of travel `travel` (in time units).
    /// Newton starts with the anchors moved over the whole travel (g = 0,
    /// and with c_F = 0 every correction keeps it 0) and Δu = 0: the step of
    /// a quasi-static run without path following. From Δτ = 0 instead, the
    /// line search would weigh the unmet g by D18's reference force, which
    /// before the first load is tiny: every candidate that moves the anchors
    /// then looks worse than the start (the local footing at h = 0.1 m failed
    /// its first step at every one of 8 halvings).
    pub fn travel(dt: f64, travel: f64, start_load: f64) -> Self {
        Self {
            travel_weight: 1.0 / dt,
            load_weight: 0.0,
            arc: travel / dt,
            start_load,
            predictor: 0.0,
            start_travel: travel,
            max_step: f64::INFINITY,
            load_scale: 1.0,
        }
    }

    /// The constraint with F_n the driven load of `system` at the start of
    /// its step (Δu = 0, Δτ = 0, the step's bearing points).
    pub fn starting_from(self, system: &StepSystem) -> Self {
        let zero = vec![[0.0; 2]; system.model.grid.node_count()];
        Self {
            start_load: system.driven_load(&zero, 0.0),
            ..self
        }
    }

    /// g at a step of `travel` (Δτ) whose driven load is `load` (PF2).
    pub fn value(&self, travel: f64, load: f64) -> f64 {
        self.travel_weight * travel + self.load_weight * (load - self.start_load) - self.arc
    }

    /// The border of the Newton system at an iterate where the constraint
    /// has the value `g` (PF4): the column −∂f_pen/∂τ, the row
    /// ∂g/∂Δu = c_F ∂F/∂Δu, the corner ∂g/∂τ = c_τ + c_F ∂F/∂τ and the
    /// right-hand side −g.
    pub fn border(&self, derivatives: &TravelDerivatives, g: f64) -> Border {
        let nonzero = |values: &[f64], factor: f64| -> Vec<(usize, f64)> {
            values
                .iter()
                .enumerate()
                .filter(|(_, v)| **v != 0.0)
                .map(|(i, v)| (i, factor * v))
                .collect()
        };
        Border {
            column: nonzero(&derivatives.force_rate, -1.0),
            row: nonzero(&derivatives.load_gradient, self.load_weight),
            corner: self.travel_weight + self.load_weight * derivatives.load_rate,
            rhs: -g,
        }
    }

    /// Whether a converged step of travel `travel` and load change
    /// `load_change` stays on the path the predictor set out on (PF5): at
    /// most [`MAX_JUMP`] times the predicted step long. A longer one has
    /// jumped to another branch that meets the constraint: where the
    /// softened body unloads more softly than K_e, elastic unloading also
    /// gains plastic travel (measured on the local biaxial at h = 1/300 m: a
    /// step went back 103 nominal steps, unloading to 5 % of the peak).
    pub fn accepts(&self, dt: f64, travel: f64, load_change: f64) -> bool {
        (travel / dt).hypot(load_change / self.load_scale) <= self.max_step
    }

    /// Whether the constraint's value `g` (in nominal steps of travel) is
    /// met: to 1e-6 of a step, well above the round-off of the driven load
    /// (a sum of penalty forces k·gap with k ~ 1e3 E: on the biaxial at
    /// h = 2 mm it carried 1e-8 of a step).
    pub fn met(&self, g: f64) -> bool {
        g.abs() <= 1e-6
    }
}

/// Where the path following stands and what it did (`run.json` →
/// `usage.path`; checkpointed).
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PathRecord {
    /// The last step in the scaled plane: (Δτ/Δt, ΔF/F_ref).
    pub last_step: [f64; 2],
    /// The plastic travel of the next plastic-travel step, in nominal steps
    /// (at most 1).
    pub plastic_travel: f64,
    /// F_ref, the load change of one nominal step of the first step, kN/m
    /// (0 before the first step).
    pub load_scale: f64,
    /// Steps taken under the plastic-travel constraint.
    pub plastic_steps: usize,
    /// Attempts redone with half the step (Newton failed, or the step
    /// jumped off the path).
    pub cuts: usize,
    /// Attempts redone because the step jumped off the path
    /// ([`PathConstraint::accepts`]).
    pub jumps: usize,
    /// Steps whose travel went back (the path snapped back).
    pub reversals: usize,
}

impl PathRecord {
    /// Whether the last step hands the next to the plastic-travel
    /// constraint (PF5).
    fn plastic(&self) -> bool {
        let [travel, load] = self.last_step;
        self.load_scale > 0.0 && (travel <= 0.0 || travel - load >= PLASTIC_SHARE * travel)
    }

    /// The constraint of a step from time parameter `t`, nominal step `dt`,
    /// path end `end`, shrunk by `shrink` (½ per Newton failure) (PF5): the
    /// travel of one nominal step in the elastic range, the plastic travel
    /// of [`Self::plastic_travel`] once the last step was mostly plastic, and
    /// the travel to the end where the step would reach it (predicted from
    /// the last step's ratio of travel to plastic travel). Its start load is
    /// set by [`PathConstraint::starting_from`].
    pub fn constraint(&self, t: f64, dt: f64, end: f64, shrink: f64) -> PathConstraint {
        let remaining = end - t;
        if !self.plastic() {
            return PathConstraint::travel(dt, shrink * dt.min(remaining), 0.0);
        }
        let [travel, load] = self.last_step;
        let plastic = shrink * self.plastic_travel;
        let predicted = plastic * travel / (travel - load);
        if t + predicted * dt >= end {
            return PathConstraint::travel(dt, shrink * remaining, 0.0);
        }
        PathConstraint {
            travel_weight: 1.0 / dt,
            load_weight: -1.0 / self.load_scale,
            arc: plastic,
            start_load: 0.0,
            predictor: plastic / (travel - load),
            start_travel: plastic / (travel - load) * travel * dt,
            max_step: MAX_JUMP * plastic / (travel - load) * travel.hypot(load),
            load_scale: self.load_scale,
        }
    }

    /// After an attempt that jumped off the path with travel `travel` and
    /// load change `load_change` (PF6): where the jump followed an elastic
    /// branch (load and travel change together, its plastic travel at most
    /// [`ELASTIC_SHARE`] of its travel), its slope ΔF/Δτ is the body's
    /// present unloading stiffness, and F_ref = (ΔF/Δτ) Δt from now on, so
    /// that elastic unloading keeps the plastic travel fixed at the present
    /// stiffness too (the footing's softened body unloads up to a few per
    /// cent stiffer than its first step). Returns whether F_ref changed
    /// (by more than 0.1 %).
    pub fn relearn(&mut self, dt: f64, travel: f64, load_change: f64) -> bool {
        if self.load_scale <= 0.0 || travel * load_change <= 0.0 {
            return false;
        }
        let scaled = [travel / dt, load_change / self.load_scale];
        if (scaled[0] - scaled[1]).abs() > ELASTIC_SHARE * scaled[0].abs() {
            return false;
        }
        let scale = load_change * dt / travel;
        if (scale - self.load_scale).abs() <= 1e-3 * self.load_scale {
            return false;
        }
        self.last_step[1] *= self.load_scale / scale;
        self.load_scale = scale;
        true
    }

    /// After a step of travel `travel` and load change `load_change` that
    /// converged in `iterations` (PF5): the first step sets F_ref; the next
    /// plastic travel is this step's, doubled after an easy step, at most
    /// one nominal step.
    pub fn advance(&mut self, dt: f64, travel: f64, load_change: f64, iterations: usize) {
        if self.load_scale == 0.0 {
            self.load_scale = (load_change.abs() * dt / travel.abs()).max(f64::MIN_POSITIVE);
        }
        self.plastic_steps += usize::from(self.plastic());
        self.last_step = [travel / dt, load_change / self.load_scale];
        self.reversals += usize::from(travel < 0.0);
        let plastic = self.last_step[0] - self.last_step[1];
        let growth = if iterations <= EASY_ITERATIONS {
            2.0
        } else {
            1.0
        };
        if plastic > 0.0 {
            self.plastic_travel = (growth * plastic).min(1.0);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The first step is displacement controlled and sets F_ref = K_e Δt;
    /// elastic steps keep the nominal travel; a mostly plastic step hands
    /// the next to the plastic travel τ − F/K_e, which an elastic unloading
    /// does not change; a step that would pass the end is cut to end there.
    #[test]
    fn steps_switch_from_travel_to_plastic_travel() {
        let (dt, end, stiffness) = (0.5, 20.0, 40.0);
        let mut record = PathRecord::default();
        let first = record.constraint(0.0, dt, end, 1.0);
        assert_eq!(first, PathConstraint::travel(dt, dt, 0.0));
        record.advance(dt, dt, stiffness * dt, 3);
        assert!((record.load_scale - stiffness * dt).abs() < 1e-12);
        assert_eq!(record.constraint(dt, dt, end, 1.0), first);
        // a step with a third of its load increment: two thirds plastic
        record.advance(dt, dt, stiffness * dt / 3.0, 3);
        let plastic = record.constraint(2.0 * dt, dt, end, 1.0);
        assert_eq!(plastic.arc, 1.0);
        // elastic unloading (ΔF = K_e Δτ) leaves the plastic travel unchanged
        let unloading = -0.3;
        assert!((plastic.value(unloading, stiffness * unloading) + plastic.arc).abs() < 1e-12);
        let last = record.constraint(end - 0.1, dt, end, 1.0);
        assert!(last.value(0.1, 123.0).abs() < 1e-12);
        assert_eq!(last.load_weight, 0.0);
    }

    /// A step that went back counts as a reversal and keeps the plastic
    /// constraint; the next plastic travel is the step's after a hard step,
    /// twice that after an easy one, never above one nominal step.
    #[test]
    fn plastic_travel_follows_the_iterations_and_reversals_are_counted() {
        let mut record = PathRecord {
            load_scale: 10.0,
            last_step: [1.0, 0.0],
            plastic_travel: 1.0,
            ..Default::default()
        };
        record.advance(1.0, -0.1, -2.0, 20);
        assert_eq!(record.reversals, 1);
        assert!(record.plastic());
        assert!((record.plastic_travel - 0.1).abs() < 1e-12);
        record.advance(1.0, -0.1, -2.0, 2);
        assert!((record.plastic_travel - 0.2).abs() < 1e-12);
        record.advance(1.0, 2.0, -30.0, 2);
        assert_eq!(record.plastic_travel, 1.0);
    }

    /// A jump along an elastic branch (load and travel falling together,
    /// plastic travel within a tenth of the travel) re-measures F_ref, after
    /// which unloading at that stiffness keeps the plastic travel fixed; the
    /// last step keeps its load change in kN/m. A plastic jump, one whose
    /// load and travel part ways, or one at the present stiffness changes
    /// nothing.
    #[test]
    fn an_elastic_jump_measures_the_unloading_stiffness() {
        let dt = 0.5;
        let mut record = PathRecord {
            load_scale: 10.0,
            last_step: [1.0, 0.2],
            plastic_travel: 0.5,
            ..Default::default()
        };
        let before = record.clone();
        for (travel, load) in [(-0.2, -2.0), (-0.2, -8.0), (-0.2, 3.0), (-0.2, -4.0001)] {
            assert!(!record.relearn(dt, travel, load), "{travel}, {load}");
            assert_eq!(record, before);
        }
        // 5 % stiffer than F_ref = 10 per nominal step
        assert!(record.relearn(dt, -0.2, -4.2));
        assert!((record.load_scale - 10.5).abs() < 1e-12);
        assert!((record.last_step[1] * record.load_scale - 2.0).abs() < 1e-12);
        let plastic = record.constraint(1.0, dt, 20.0, 1.0);
        let unloading = -0.3;
        let load = 10.5 / dt * unloading;
        assert!((plastic.value(unloading, load) + plastic.arc).abs() < 1e-12);
    }
}
