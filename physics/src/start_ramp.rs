//! Smooth start of a driven boundary (issue 39): a prescribed motion whose
//! velocity rises from zero to its full value over a ramp time T instead of
//! jumping to it at t = 0, so that an implicit Newmark run does not ring.
//!
//! With τ = t/T, the velocity factor is the cubic smoothstep
//! φ(τ) = 3τ² − 2τ³ (φ = 0 and φ' = 0 at τ = 0, φ = 1 and φ' = 0 at τ = 1:
//! no jump of velocity nor of acceleration at either end), and the
//! displacement factor, its integral in time, is
//! D(t) = T (τ³ − τ⁴/2) for t ≤ T and D(t) = T/2 + (t − T) after.
//! A driven motion u(t) = D(t) · v then has velocity φ(t/T) · v.
//! T = 0 gives D(t) = t, the impulsive start.

/// The start profile of one driven boundary (`ramp_time` of `[[bc.rigid]]`
/// and `[[bc.prescribed]]`).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StartRamp {
    /// Ramp time T ≥ 0 over which the velocity rises to its full value
    /// (0: full velocity from t = 0).
    pub time: f64,
}

impl StartRamp {
    /// The profile rising over `time` (s, or pseudo-time in a quasi-static run).
    pub fn new(time: f64) -> Self {
        Self { time }
    }

    /// Displacement factor D(t): T (τ³ − τ⁴/2), τ = t/T, for 0 ≤ t ≤ T,
    /// T/2 + (t − T) after, t itself for T = 0 (and for t ≤ 0, where nothing
    /// has moved yet: D = t = 0 at t = 0).
    pub fn displacement(&self, t: f64) -> f64 {
        let ramp = self.time;
        if ramp <= 0.0 || t <= 0.0 {
            return t;
        }
        if t >= ramp {
            return 0.5 * ramp + (t - ramp);
        }
        let tau = t / ramp;
        ramp * tau.powi(3) * (1.0 - 0.5 * tau)
    }

    /// Velocity factor φ(t/T) = 3τ² − 2τ³ = dD/dt, 1 for t ≥ T and for T = 0.
    pub fn velocity_factor(&self, t: f64) -> f64 {
        let ramp = self.time;
        if ramp <= 0.0 || t >= ramp {
            return 1.0;
        }
        if t <= 0.0 {
            return 0.0;
        }
        let tau = t / ramp;
        tau * tau * (3.0 - 2.0 * tau)
    }

    /// Mean velocity factor over the step [t0, t1], (D(t1) − D(t0)) / (t1 − t0):
    /// the constant velocity that moves a boundary exactly by its prescribed
    /// displacement over the step (φ(t0) for an empty step); exactly 1 once
    /// the ramp is over and for T = 0.
    pub fn mean_velocity_factor(&self, t0: f64, t1: f64) -> f64 {
        if self.time <= 0.0 || t0 >= self.time {
            1.0
        } else if t1 > t0 {
            (self.displacement(t1) - self.displacement(t0)) / (t1 - t0)
        } else {
            self.velocity_factor(t0)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Central difference of `f` at `t` with step `e`.
    fn derivative(f: impl Fn(f64) -> f64, t: f64, e: f64) -> f64 {
        (f(t + e) - f(t - e)) / (2.0 * e)
    }

    #[test]
    fn velocity_factor_is_the_time_derivative_of_the_displacement() {
        let ramp = StartRamp::new(0.2);
        for k in 1..40 {
            let t = 0.01 * k as f64 + 0.003; // off the ramp's end
            let fd = derivative(|t| ramp.displacement(t), t, 1e-6);
            // central differences of a quartic: error ~ e² D''' ≈ 1e-12 · 150
            assert!(
                (fd - ramp.velocity_factor(t)).abs() < 1e-8,
                "t = {t}: dD/dt = {fd}, φ = {}",
                ramp.velocity_factor(t)
            );
        }
    }

    #[test]
    fn displacement_and_its_first_two_derivatives_are_continuous_at_the_ramp_end() {
        let ramp = StartRamp::new(0.1);
        let (t, e) = (ramp.time, 1e-9);
        // D: the quartic reaches T/2 at τ = 1
        assert!((ramp.displacement(t - e) - 0.05).abs() < 1e-8);
        assert!((ramp.displacement(t + e) - 0.05).abs() < 1e-8);
        // D' = φ: 1 on both sides
        assert!((ramp.velocity_factor(t - e) - 1.0).abs() < 1e-8);
        assert!((ramp.velocity_factor(t + e) - 1.0).abs() < 1e-8);
        // D'' = φ' = 6τ(1 − τ)/T → 0 on both sides: its mean over the last
        // h = 1e-6 s is 3h/T² = 3e-4 1/s (against 6/(4T) = 15 1/s mid-ramp)
        let h = 1e-6;
        let before = (ramp.velocity_factor(t) - ramp.velocity_factor(t - h)) / h;
        let after = (ramp.velocity_factor(t + h) - ramp.velocity_factor(t)) / h;
        assert!(
            before.abs() < 1e-3 && after.abs() < 1e-12,
            "{before}, {after}"
        );
    }

    #[test]
    fn the_start_has_no_velocity_nor_acceleration() {
        let ramp = StartRamp::new(0.1);
        assert_eq!(ramp.displacement(0.0), 0.0);
        assert_eq!(ramp.velocity_factor(0.0), 0.0);
        let h = 1e-6;
        // φ'(0) = 0: φ(h) = 3 (h/T)² = 3e-10
        assert!(ramp.velocity_factor(h) / h < 1e-3);
    }

    #[test]
    fn zero_ramp_time_is_the_impulsive_start() {
        let ramp = StartRamp::default();
        for t in [0.0, 0.02, 0.7, 3.0] {
            assert_eq!(ramp.displacement(t), t);
            assert_eq!(ramp.velocity_factor(t), 1.0);
            assert_eq!(ramp.mean_velocity_factor(t, t + 0.02), 1.0);
        }
    }

    #[test]
    fn mean_velocity_factor_moves_the_boundary_by_the_displacement_of_the_step() {
        let ramp = StartRamp::new(0.1);
        let dt = 0.02;
        let moved: f64 = (0..10)
            .map(|n| dt * ramp.mean_velocity_factor(n as f64 * dt, (n + 1) as f64 * dt))
            .sum();
        // D(0.2) = T/2 + 0.1 = 0.15
        assert!((moved - 0.15).abs() < 1e-12, "{moved}");
    }
}
