//! The nonlocal variable within a step (DESIGN §6, D35–D36), shared by both
//! integrators: weights from the start-of-step positions and volumes, the
//! strength variable κ̄ each Newton iteration sees, its convergence (third
//! criterion of D18), and the value committed at the end of the step.

use crate::nonlocal::{NonlocalAverager, NonlocalParameters};
use crate::particles::Particles;
use crate::scene::{NonlocalSpec, NonlocalUpdate};

/// Nonlocal bookkeeping of one step.
pub struct NonlocalStep {
    averager: NonlocalAverager,
    /// κ̄(n), committed at the start of the step.
    start: Vec<f64>,
    /// κ̄ the current iteration's strengths are evaluated at.
    current: Vec<f64>,
    update: NonlocalUpdate,
    tolerance: f64,
    scratch_increment: Vec<f64>,
    scratch_average: Vec<f64>,
    /// Increments `scratch_average` was computed from (valid if `memo_valid`): the commit
    /// after convergence repeats the last iteration's increments and reuses its result.
    memo_increment: Vec<f64>,
    memo_valid: bool,
}

impl NonlocalStep {
    /// Weights (D34) for the start-of-step configuration; MPs of different
    /// materials never average together.
    pub fn new(
        spec: &NonlocalSpec,
        particles: &Particles,
        force_step_update: bool,
    ) -> Result<Self, String> {
        let params = NonlocalParameters {
            length_scale: spec.length_scale,
            cutoff_factor: spec.cutoff_factor,
        };
        let averager = NonlocalAverager::new(
            &params,
            &particles.position,
            &particles.volume,
            &particles.material,
        )
        .map_err(|e| e.to_string())?;
        let start: Vec<f64> = particles
            .state
            .iter()
            .map(|s| s.plastic_strain_eq_nonlocal)
            .collect();
        let n = start.len();
        Ok(Self {
            averager,
            current: start.clone(),
            start,
            update: if force_step_update {
                NonlocalUpdate::Step
            } else {
                spec.update
            },
            tolerance: spec.tolerance,
            scratch_increment: vec![0.0; n],
            scratch_average: vec![0.0; n],
            memo_increment: vec![0.0; n],
            memo_valid: false,
        })
    }

    /// κ̄ at which the strengths of the current iteration are evaluated.
    pub fn strength_kappa(&self) -> &[f64] {
        &self.current
    }

    /// κ̄(n) + Σ_q W_pq Δκ_q for the local increments Δκ = κ(trial) − κ(n) (D35).
    ///
    /// In `iteration` mode (D36: one average per Newton iteration, weights fixed within the
    /// step) the weights of the plastic sources are cached at their first appearance in the
    /// step and reused by later iterations; a call with the same increments as the previous
    /// one (the commit after convergence) reuses its result.
    fn averaged(
        &mut self,
        particles: &Particles,
        trial_kappa: impl Fn(usize) -> f64,
    ) -> Result<&[f64], String> {
        for (p, inc) in self.scratch_increment.iter_mut().enumerate() {
            *inc = trial_kappa(p) - particles.state[p].plastic_strain_eq;
        }
        let same = self.memo_valid
            && self
                .scratch_increment
                .iter()
                .zip(&self.memo_increment)
                .all(|(a, b)| a.to_bits() == b.to_bits());
        if same {
            return Ok(&self.scratch_average);
        }
        if self.update == NonlocalUpdate::Iteration {
            self.averager
                .cache_sources(&self.scratch_increment)
                .map_err(|e| e.to_string())?;
        }
        self.averager
            .average(&self.scratch_increment, &mut self.scratch_average)
            .map_err(|e| e.to_string())?;
        for (avg, start) in self.scratch_average.iter_mut().zip(&self.start) {
            *avg += start;
        }
        self.memo_increment.copy_from_slice(&self.scratch_increment);
        self.memo_valid = true;
        Ok(&self.scratch_average)
    }

    /// After an iteration's stress update: lag κ̄ by one iteration (D36) and
    /// report whether it has converged (max change ≤ ε_κ · max(max Δκ̄, 1e−8)).
    /// In `step` mode the strength stays frozen at κ̄(n) and this is always true.
    pub fn iterate(
        &mut self,
        particles: &Particles,
        trial_kappa: impl Fn(usize) -> f64,
    ) -> Result<bool, String> {
        if self.update == NonlocalUpdate::Step {
            return Ok(true);
        }
        let next = self.averaged(particles, trial_kappa)?.to_vec();
        let mut change = 0.0f64;
        let mut largest = 0.0f64;
        for p in 0..next.len() {
            change = change.max((next[p] - self.current[p]).abs());
            largest = largest.max(next[p] - self.start[p]);
        }
        self.current = next;
        Ok(change <= self.tolerance * largest.max(1e-8))
    }

    /// κ̄(n+1) of the converged step (D35).
    pub fn committed(
        &mut self,
        particles: &Particles,
        trial_kappa: impl Fn(usize) -> f64,
    ) -> Result<Vec<f64>, String> {
        Ok(self.averaged(particles, trial_kappa)?.to_vec())
    }
}
