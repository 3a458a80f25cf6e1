//! The nonlocal variable within a step (theory §6, D35–D36), shared by both
//! integrators: weights from the start-of-step positions and volumes, the
//! strength variable κ̄ each Newton iteration sees, its convergence (third
//! criterion of D18), and the value committed at the end of the step.

use crate::constitutive::StrengthVariable;
use crate::model::Model;
use crate::nonlocal::{GridAverager, NonlocalAverager, NonlocalAveraging, NonlocalError};
use crate::particles::Particles;
use crate::profile::{Profile, Stage, Work};
use crate::scene::{NonlocalSpec, NonlocalUpdate};

/// The strength variable of every point for one iteration's stress updates.
#[derive(Clone, Copy)]
pub struct NonlocalStrength<'a> {
    neighbours: &'a [f64],
    own_weight: f64,
}

impl NonlocalStrength<'_> {
    /// κ_s of point `p`: κ̄_n + m Σ W Δκ (lagged) + (1 − m) Δκ_p (solved with the update).
    pub fn at(&self, p: usize) -> StrengthVariable {
        StrengthVariable::Nonlocal {
            neighbours: self.neighbours[p],
            own_weight: self.own_weight,
        }
    }
}

/// The step's averaging operator: over point pairs (D34) or on a grid (NG1–NG3).
enum Operator {
    Points(Box<NonlocalAverager>),
    Grid(GridAverager),
}

/// Nonlocal bookkeeping of one step.
pub struct NonlocalStep {
    averager: Operator,
    /// κ̄(n), committed at the start of the step.
    start: Vec<f64>,
    /// κ̄(n) + m Σ_q W_pq Δκ_q of the previous iteration (D36; for m = 1 the κ̄
    /// the current iteration's strengths are evaluated at).
    neighbours: Vec<f64>,
    /// Over-nonlocal factor m: the own increment enters κ̄ with weight 1 − m.
    over_nonlocal: f64,
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
    /// The step's nonlocal bookkeeping for a nonlocal scene (`None` for a
    /// local one, which does no averaging): weights (D34) from the
    /// start-of-step configuration, timed as the nonlocal stage and counted
    /// as a neighbour list. κ̄ is updated per the scene's `nonlocal.update`
    /// (D36), or once per step when `step_update` (explicit runs, theory §4).
    pub fn start(
        model: &Model,
        step_update: bool,
        profile: &Profile,
    ) -> Result<Option<Self>, NonlocalError> {
        let Some(spec) = &model.settings.nonlocal else {
            return Ok(None);
        };
        let step = profile.time(Stage::Nonlocal, || {
            Self::new(spec, &model.state.particles, step_update)
        })?;
        profile.count(Work::NeighbourLists, 1);
        Ok(Some(step))
    }

    /// Weights (D34) for the start-of-step configuration; MPs of different
    /// materials never average together.
    pub fn new(
        spec: &NonlocalSpec,
        particles: &Particles,
        force_step_update: bool,
    ) -> Result<Self, NonlocalError> {
        let (x, v, g) = (&particles.position, &particles.volume, &particles.material);
        let averager = match spec.averaging {
            NonlocalAveraging::Points => {
                let mut averager = NonlocalAverager::new(spec, x, v, g)?;
                averager.set_pair_budget(spec.weight_budget());
                Operator::Points(Box::new(averager))
            }
            NonlocalAveraging::Grid => Operator::Grid(GridAverager::new(spec, x, v, g)?),
        };
        let start: Vec<f64> = particles
            .state
            .iter()
            .map(|s| s.plastic_strain_eq_nonlocal)
            .collect();
        let n = start.len();
        Ok(Self {
            averager,
            neighbours: start.clone(),
            start,
            over_nonlocal: spec.over_nonlocal,
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

    /// The strength variables of the current iteration's stress updates.
    pub fn strength(&self) -> NonlocalStrength<'_> {
        NonlocalStrength {
            neighbours: &self.neighbours,
            own_weight: 1.0 - self.over_nonlocal,
        }
    }

    /// Σ_q W_pq Δκ_q for the local increments Δκ = κ(trial) − κ(n) (D35); the
    /// increments are left in `scratch_increment`.
    ///
    /// In `iteration` mode (D36: one average per Newton iteration, weights fixed within the
    /// step) the weights of the plastic sources are cached at their first appearance in the
    /// step and reused by later iterations; a call with the same increments as the previous
    /// one (the commit after convergence) reuses its result. Weight caches built, averages
    /// and the first computation of the denominators are counted in `profile`.
    fn averaged(
        &mut self,
        particles: &Particles,
        trial_kappa: impl Fn(usize) -> f64,
        profile: &Profile,
    ) -> Result<&[f64], NonlocalError> {
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
        match &mut self.averager {
            Operator::Points(averager) => {
                let had_weights = averager.has_weights();
                if self.update == NonlocalUpdate::Iteration {
                    let cached = averager.cache_sources(&self.scratch_increment)?;
                    profile.count(Work::WeightCaches, u64::from(cached > 0));
                }
                averager.average(&self.scratch_increment, &mut self.scratch_average)?;
                profile.count(
                    Work::NonlocalWeights,
                    u64::from(!had_weights && averager.has_weights()),
                );
            }
            Operator::Grid(averager) => {
                averager.average(&self.scratch_increment, &mut self.scratch_average)?;
            }
        }
        profile.count(Work::NonlocalAverages, 1);
        self.memo_increment.copy_from_slice(&self.scratch_increment);
        self.memo_valid = true;
        Ok(&self.scratch_average)
    }

    /// After an iteration's stress update: lag the neighbour part of κ̄ by one
    /// iteration (D36) and report whether it has converged (max change ≤
    /// ε_κ · max(max Δκ̄, 1e−8)). In `step` mode the strength stays frozen at
    /// κ̄(n) and this is always true (no average).
    pub fn iterate(
        &mut self,
        particles: &Particles,
        trial_kappa: impl Fn(usize) -> f64,
        profile: &Profile,
    ) -> Result<bool, NonlocalError> {
        if self.update == NonlocalUpdate::Step {
            return Ok(true);
        }
        let m = self.over_nonlocal;
        self.averaged(particles, trial_kappa, profile)?;
        let mut change = 0.0f64;
        let mut largest = 0.0f64;
        for ((neighbours, start), avg) in self
            .neighbours
            .iter_mut()
            .zip(&self.start)
            .zip(&self.scratch_average)
        {
            let next = start + m * avg;
            change = change.max((next - *neighbours).abs());
            largest = largest.max(next - start);
            *neighbours = next;
        }
        Ok(change <= self.tolerance * largest.max(1e-8))
    }

    /// κ̄(n+1) = κ̄(n) + m Σ_q W_pq Δκ_q + (1 − m) Δκ_p of the converged step
    /// (D35; m = 1 by default).
    pub fn committed(
        &mut self,
        particles: &Particles,
        trial_kappa: impl Fn(usize) -> f64,
        profile: &Profile,
    ) -> Result<Vec<f64>, NonlocalError> {
        let m = self.over_nonlocal;
        self.averaged(particles, trial_kappa, profile)?;
        Ok(self
            .start
            .iter()
            .zip(&self.scratch_average)
            .zip(&self.scratch_increment)
            .map(|((start, avg), own)| start + m * avg + (1.0 - m) * own)
            .collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// 5 × 5 points at spacing l_s/2, each of volume (l_s/2)², all κ̄(n) = 0.2.
    fn grid_of_points() -> Particles {
        let mut particles = Particles::default();
        for i in 0..5 {
            for j in 0..5 {
                let x = [0.005 * i as f64, 0.005 * j as f64];
                particles.push(x, 1.0, 2.5e-5, [0.0; 4], 0, 0);
            }
        }
        for state in &mut particles.state {
            state.plastic_strain_eq = 0.1;
            state.plastic_strain_eq_nonlocal = 0.2;
        }
        particles
    }

    fn spec(over_nonlocal: f64) -> NonlocalSpec {
        NonlocalSpec {
            length_scale: 0.01,
            cutoff_factor: 3.0,
            update: NonlocalUpdate::Iteration,
            tolerance: 1e-3,
            over_nonlocal,
            weight_cache_mb: 512.0,
            averaging: NonlocalAveraging::Points,
            grid_spacing_factor: 0.1,
        }
    }

    /// κ̄(n+1) − κ̄(n) = m Σ W Δκ + (1 − m) Δκ_p (D35 with the over-nonlocal
    /// factor): a uniform increment gives the same κ̄ increment for every m
    /// (weights normalised), and a non-uniform one is the m-weighted blend of
    /// the plain average (m = 1) and the point's own increment.
    #[test]
    fn over_nonlocal_commit_blends_average_and_own_increment() {
        let particles = grid_of_points();
        let profile = Profile::default();
        let uniform = |_: usize| 0.1 + 0.03;
        let peaked = |p: usize| 0.1 + if p == 12 { 0.05 } else { 0.01 * (p % 3) as f64 };
        let plain = NonlocalStep::new(&spec(1.0), &particles, false)
            .unwrap()
            .committed(&particles, peaked, &profile)
            .unwrap();
        for m in [1.0, 1.1, 2.0] {
            let mut step = NonlocalStep::new(&spec(m), &particles, false).unwrap();
            for k in step.committed(&particles, uniform, &profile).unwrap() {
                assert!((k - 0.23).abs() < 1e-12, "m = {m}: {k}");
            }
            let committed = step.committed(&particles, peaked, &profile).unwrap();
            for p in 0..particles.len() {
                let own = peaked(p) - 0.1;
                let expected = 0.2 + m * (plain[p] - 0.2) + (1.0 - m) * own;
                assert!(
                    (committed[p] - expected).abs() < 1e-12,
                    "m = {m}, point {p}"
                );
            }
        }
    }

    /// The strength variable of an iteration carries the lagged neighbour part
    /// κ̄(n) + m Σ W Δκ and the own weight 1 − m; `step` mode keeps κ̄(n).
    #[test]
    fn strength_variable_carries_lagged_neighbours_and_own_weight() {
        let particles = grid_of_points();
        let profile = Profile::default();
        let increments = |p: usize| 0.1 + 0.002 * p as f64;
        let plain = NonlocalStep::new(&spec(1.0), &particles, false)
            .unwrap()
            .committed(&particles, increments, &profile)
            .unwrap();
        let m = 1.1;
        let mut step = NonlocalStep::new(&spec(m), &particles, false).unwrap();
        step.iterate(&particles, increments, &profile).unwrap();
        for (p, plain_p) in plain.iter().enumerate() {
            match step.strength().at(p) {
                StrengthVariable::Nonlocal {
                    neighbours,
                    own_weight,
                } => {
                    assert!((neighbours - (0.2 + m * (plain_p - 0.2))).abs() < 1e-12);
                    assert!((own_weight - (1.0 - m)).abs() < 1e-15);
                }
                StrengthVariable::Local => panic!("local strength in a nonlocal step"),
            }
        }
        let mut frozen = NonlocalStep::new(&spec(m), &particles, true).unwrap();
        assert!(frozen.iterate(&particles, increments, &profile).unwrap());
        assert!(matches!(
            frozen.strength().at(7),
            StrengthVariable::Nonlocal { neighbours, .. } if neighbours == 0.2
        ));
    }

    /// The averaging work is counted where it is done: the commit that
    /// repeats the last iteration's increments reuses its average (one
    /// average counted, not two), the denominators are computed once, and
    /// `step` mode (explicit runs) averages only at the commit.
    #[test]
    fn averages_are_counted_once_per_application() {
        let particles = grid_of_points();
        let increments = |p: usize| 0.1 + 0.002 * p as f64;
        let profile = Profile::default();
        let mut step = NonlocalStep::new(&spec(1.0), &particles, false).unwrap();
        step.iterate(&particles, increments, &profile).unwrap();
        step.committed(&particles, increments, &profile).unwrap();
        assert_eq!(profile.work_count(Work::NonlocalAverages), 1);
        assert_eq!(profile.work_count(Work::NonlocalWeights), 1);
        // 25 new sources (≥ 16): one cache block
        assert_eq!(profile.work_count(Work::WeightCaches), 1);
        let frozen_profile = Profile::default();
        let mut frozen = NonlocalStep::new(&spec(1.0), &particles, true).unwrap();
        frozen
            .iterate(&particles, increments, &frozen_profile)
            .unwrap();
        assert_eq!(frozen_profile.work_count(Work::NonlocalAverages), 0);
        frozen
            .committed(&particles, increments, &frozen_profile)
            .unwrap();
        assert_eq!(frozen_profile.work_count(Work::NonlocalAverages), 1);
        assert_eq!(frozen_profile.work_count(Work::WeightCaches), 0);
    }
}
