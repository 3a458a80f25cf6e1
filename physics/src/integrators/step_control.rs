//! Error-controlled steps of the implicit dynamic integrator (theory
//! "Error-controlled steps"): the local error estimate of a Newmark or
//! generalised-α step, the controller that turns it into the next step, and
//! the record of what the control did (written to `run.json`, kept in
//! checkpoints).

use super::step_system::{Newmark, StepSystem};
use crate::settings::Settings;
use crate::transfer::NONE;

/// The local error of a converged step and the size of its motion, both as
/// mass-weighted root mean squares over the free dofs, m.
#[derive(Clone, Copy, Debug)]
pub struct LocalError {
    /// The Zienkiewicz–Xie estimate of the displacement's truncation error
    /// (theory eq. AS1): e = (β − 1/6) Δt² (a_{n+1} − a_n) per dof.
    pub error: f64,
    /// The step's displacement increment Δu.
    pub increment: f64,
}

impl LocalError {
    /// The estimate of a converged step with increment `du` and new nodal
    /// accelerations `acceleration_next`.
    pub fn of(
        system: &StepSystem,
        newmark: &Newmark,
        du: &[[f64; 2]],
        acceleration_next: &[[f64; 2]],
    ) -> Self {
        let factor = (newmark.beta - 1.0 / 6.0) * system.dt * system.dt;
        let (mut mass, mut error2, mut increment2) = (0.0, 0.0, 0.0);
        for (d, &index) in system.dofs.index.iter().enumerate() {
            if index == NONE {
                continue;
            }
            let (node, c) = (d / 2, d % 2);
            let m = system.nodal.mass[node];
            let e = factor * (acceleration_next[node][c] - system.nodal.acceleration[node][c]);
            mass += m;
            error2 += m * e * e;
            increment2 += m * du[node][c] * du[node][c];
        }
        if mass == 0.0 {
            return Self {
                error: 0.0,
                increment: 0.0,
            };
        }
        Self {
            error: (error2 / mass).sqrt(),
            increment: (increment2 / mass).sqrt(),
        }
    }

    /// The relative error η = e / (Δt V) of a step `dt` (theory eq. AS2),
    /// against the velocity scale V, the largest mean speed Δu/Δt of the
    /// run's steps so far including this one (`velocity_scale`: before it).
    /// The step's own increment alone would vanish where a vibration turns
    /// (every point at rest at once) and stall the steps there. Zero when
    /// nothing has moved.
    pub fn relative(&self, dt: f64, velocity_scale: f64) -> f64 {
        let scale = velocity_scale.max(self.increment / dt);
        if self.error == 0.0 || scale == 0.0 {
            return 0.0;
        }
        self.error / (dt * scale)
    }
}

/// The step-size controller of `[solver] time_step = "adaptive"`.
#[derive(Clone, Copy, Debug)]
pub struct StepController {
    /// Largest accepted η.
    pub tolerance: f64,
    /// Smallest step, s.
    pub dt_min: f64,
    /// Largest step, s.
    pub dt_max: f64,
}

impl StepController {
    /// Safety factor on the step the estimate asks for.
    const SAFETY: f64 = 0.9;
    /// Largest growth of the step from one step to the next.
    const MAX_GROWTH: f64 = 2.0;
    /// Largest reduction of the step after one estimate.
    const MAX_SHRINK: f64 = 0.2;

    /// The controller of an adaptive run (`None` for fixed steps).
    pub fn of(settings: &Settings) -> Option<Self> {
        if !settings.solver.adaptive() {
            return None;
        }
        let (dt_min, dt_max) = settings.solver.step_bounds(settings.run.dt.unwrap_or(1.0));
        Some(Self {
            tolerance: settings.solver.error_tolerance,
            dt_min,
            dt_max,
        })
    }

    /// Whether a step with relative error `estimate` is kept.
    pub fn accepts(&self, estimate: f64) -> bool {
        estimate <= self.tolerance
    }

    /// The step after (or instead of) a step `dt` whose relative error was
    /// `estimate` (theory eq. AS3): η ∝ Δt², so
    /// Δt_new = Δt · S (tol/η)^½, its change limited to [0.2, 2] and the
    /// result to [dt_min, dt_max].
    pub fn next(&self, dt: f64, estimate: f64) -> f64 {
        let change = if estimate > 0.0 {
            Self::SAFETY * (self.tolerance / estimate).sqrt()
        } else {
            Self::MAX_GROWTH
        };
        (dt * change.clamp(Self::MAX_SHRINK, Self::MAX_GROWTH)).clamp(self.dt_min, self.dt_max)
    }
}

/// What the step control did so far (`run.json` → `usage.step_control`).
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct StepControlRecord {
    /// The step the controller proposes next, s.
    pub next_dt: f64,
    /// Steps taken.
    pub accepted: usize,
    /// Attempts redone because their error estimate exceeded the tolerance.
    pub rejected_error: usize,
    /// Attempts redone with half the step because Newton failed.
    pub rejected_newton: usize,
    /// Steps kept although their estimate exceeded the tolerance (the
    /// first step of the run, or a step at `dt_min`).
    pub accepted_at_min: usize,
    /// Smallest and largest step taken, s.
    pub dt_range: Option<(f64, f64)>,
    /// The largest mean speed Δu/Δt of a step so far, m/s: the velocity
    /// scale of the relative error ([`LocalError::relative`]).
    pub velocity_scale: f64,
}

impl StepControlRecord {
    /// Count a step of `dt` taken, whose error estimate was `local`.
    pub fn accept(&mut self, dt: f64, local: Option<LocalError>) {
        self.accepted += 1;
        if let Some(local) = local {
            self.velocity_scale = self.velocity_scale.max(local.increment / dt);
        }
        self.dt_range = Some(match self.dt_range {
            Some((lo, hi)) => (lo.min(dt), hi.max(dt)),
            None => (dt, dt),
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn controller() -> StepController {
        StepController {
            tolerance: 1e-3,
            dt_min: 1e-6,
            dt_max: 1e-2,
        }
    }

    /// η ∝ Δt²: the step that would just meet the tolerance is Δt (tol/η)^½;
    /// the controller asks for 0.9 of it, grows at most 2× and shrinks at
    /// most 5× per estimate, within [dt_min, dt_max].
    #[test]
    fn next_step_follows_the_square_root_law_within_limits() {
        let c = controller();
        let dt = 1e-3;
        assert!((c.next(dt, 4e-3) / (0.9 * 0.5 * dt) - 1.0).abs() < 1e-12);
        assert!((c.next(dt, 1e-3) / (0.9 * dt) - 1.0).abs() < 1e-12);
        assert_eq!(c.next(dt, 1e-9), 2.0 * dt);
        assert_eq!(c.next(dt, 0.0), 2.0 * dt);
        assert_eq!(c.next(dt, 1.0), 0.2 * dt);
        assert_eq!(c.next(2e-6, 1.0), 1e-6);
        assert_eq!(c.next(8e-3, 1e-9), 1e-2);
        assert!(c.accepts(1e-3) && !c.accepts(1.0001e-3));
    }

    #[test]
    fn record_keeps_the_range_of_steps() {
        let mut r = StepControlRecord::default();
        let local = |increment| LocalError {
            error: 1e-9,
            increment,
        };
        for (dt, increment) in [(2e-3, 2e-3), (5e-4, 1e-3), (1e-3, 1e-4)] {
            r.accept(dt, Some(local(increment)));
        }
        assert_eq!((r.accepted, r.dt_range), (3, Some((5e-4, 2e-3))));
        assert_eq!(r.velocity_scale, 2.0, "the largest Δu/Δt");
        // at a turning point (no increment) the scale still holds the error
        assert_eq!(local(0.0).relative(1e-3, 2.0), 1e-9 / (1e-3 * 2.0));
        assert_eq!(local(4e-3).relative(1e-3, 2.0), 1e-9 / (1e-3 * 4.0));
    }
}
