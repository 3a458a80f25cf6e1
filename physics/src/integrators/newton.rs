//! Newton–Raphson on the nodal equilibrium of one implicit (sub-)step
//! (theory D16–D18): the convergence criteria and the line search
//! ([`Convergence`]), and the loop ([`solve`]) that joins them to the step's
//! nonlinear system R(Δu) = 0 ([`StepSystem`], in [`super::step_system`]).

use super::path::PathConstraint;
use super::step_system::{
    singular_placed, NewtonError, Residual, ResidualScratch, StepSystem, CONTACT_HOLD_ITERATION,
};
use super::tangent::Tangent;
use super::{NonlocalStep, SolverUsage, TrialStresses};
use crate::bc::TravelDerivatives;
use crate::dofs::gather_free_into;
use crate::error::{Criterion, NewtonFailure, StepError};
use crate::profile::{Profile, Stage};
use crate::scene::SolverSpec;
use crate::transfer::NONE;

/// A converged (sub-)step.
pub struct Solution {
    /// Nodal displacement increment Δu, per grid node.
    pub du: Vec<[f64; 2]>,
    /// The step of the anchors' time parameter: `dt`, or under path
    /// following the Δτ the constraint chose.
    pub travel: f64,
    /// Stresses, states and tangents at Δu.
    pub trial: TrialStresses,
    /// Residual at Δu (its negative is the support reaction).
    pub residual: Residual,
    /// Newton iterations taken.
    pub iterations: usize,
    /// ‖R‖ per iteration, kN/m.
    pub history: Vec<f64>,
}

/// What the convergence check says of an iterate.
enum Verdict {
    /// All D18 criteria hold; `stagnated`: accepted on the force criterion
    /// alone because the residual had stagnated.
    Converged { stagnated: bool },
    /// Iterate again.
    Iterate,
}

/// One Newton iterate or line-search candidate: increment, its stresses and
/// residual, step length α. The loop keeps three (current, best candidate,
/// candidate being evaluated) and swaps them, so that their buffers serve
/// every iteration of the solve ([`NewtonBuffers`] keeps them between solves).
#[derive(Default)]
struct Candidate {
    du: Vec<[f64; 2]>,
    /// The anchors' step (`dt`, or Δτ under path following).
    travel: f64,
    trial: TrialStresses,
    residual: Residual,
    alpha: f64,
}

/// The three candidates of a Newton solve and its residual scratch, kept by
/// the integrator from one (sub-)step to the next: a step's stress updates
/// and residuals then write into buffers that have already grown, instead of
/// allocating and mapping fresh memory each step (at 40,000 points, 56 % of
/// the page faults of an implicit run were the first writes into new trial
/// arrays).
#[derive(Default)]
pub struct NewtonBuffers {
    current: Candidate,
    best: Candidate,
    spare: Candidate,
    scratch: ResidualScratch,
}

impl NewtonBuffers {
    /// Take back a converged step's trial stresses (moved out in its
    /// [`Solution`]) as the next solve's iterate buffers.
    pub fn recycle(&mut self, trial: TrialStresses) {
        self.current.trial = trial;
    }
}

/// The D18 convergence criteria of a (sub-)step and the line search.
pub struct Convergence {
    tolerance_force: f64,
    tolerance_energy: f64,
    max_iterations: usize,
    /// ‖R‖ per iteration.
    history: Vec<f64>,
    /// |δu⁰ · R⁰|, the energy norm's reference.
    energy0: f64,
    /// The correction last applied (α δu).
    last_correction: Vec<f64>,
    /// Consecutive iterations in which ‖R‖ grew.
    growth: usize,
}

impl Convergence {
    /// The criteria of the scene's `[solver]` table.
    pub fn new(settings: &SolverSpec, max_iterations: usize) -> Self {
        Self {
            tolerance_force: settings.tolerance_force,
            tolerance_energy: settings.tolerance_energy,
            max_iterations,
            history: Vec::new(),
            energy0: 0.0,
            last_correction: Vec::new(),
            growth: 0,
        }
    }

    /// The D18 criteria at `iteration`: force ‖R‖ ≤ ε_R F_ref; energy (work of
    /// the new residual on the last correction); and, through `kappa_settled`,
    /// the nonlocal κ̄ (called every iteration: it lags κ̄ by one). Fails on a
    /// non-finite residual, at the iteration limit, or when ‖R‖ grew in three
    /// consecutive iterations.
    fn judge(
        &mut self,
        iteration: usize,
        res: &Residual,
        free_residual: &[f64],
        constraint_met: bool,
        kappa_settled: impl FnOnce() -> Result<bool, StepError>,
    ) -> Result<Verdict, NewtonError> {
        if !res.norm.is_finite() {
            return Err(NewtonError::failed(
                NewtonFailure::NonFinite("residual"),
                &self.history,
            ));
        }
        self.history.push(res.norm);
        let force_ok = res.norm <= self.tolerance_force * res.reference;
        // The energy check confirms a small residual is not hiding a large
        // remaining correction; a residual 100× below the force tolerance
        // is accepted without it (soft modes of nearly empty cells make the
        // energy ratio stall near round-off).
        let energy_converged = iteration == 0
            || dot(&self.last_correction, free_residual).abs()
                <= self.tolerance_energy * self.energy0
            || res.norm <= 1e-2 * self.tolerance_force * res.reference;
        // Stagnation: with the force criterion met, three corrections in a
        // row that each change the residual by under 1 % act along a mode
        // the residual does not see (a soft mode held only by the background
        // stiffness D19); iterating cannot meet the energy criterion there.
        let stagnated = !energy_converged && force_ok && stagnating(&self.history);
        let energy_ok = energy_converged || stagnated;
        let kappa_ok = kappa_settled()?;
        if force_ok && energy_ok && kappa_ok && constraint_met {
            return Ok(Verdict::Converged { stagnated });
        }
        if iteration == self.max_iterations {
            let unmet = [
                (!force_ok).then_some(Criterion::Force),
                (!energy_ok).then_some(Criterion::Energy),
                (!kappa_ok).then_some(Criterion::NonlocalKappa),
                (!constraint_met).then_some(Criterion::PathConstraint),
            ];
            let cause = NewtonFailure::IterationLimit {
                iterations: self.max_iterations,
                unmet: unmet.into_iter().flatten().collect(),
                reference: res.reference,
            };
            return Err(NewtonError::failed(cause, &self.history));
        }
        let n = self.history.len();
        if n >= 2 && self.history[n - 1] > self.history[n - 2] {
            self.growth += 1;
            if self.growth >= 3 {
                return Err(NewtonError::failed(NewtonFailure::Diverged, &self.history));
            }
        } else {
            self.growth = 0;
        }
        Ok(Verdict::Iterate)
    }

    /// The first correction sets the energy norm's reference |δu⁰ · R⁰|.
    fn first_correction(&mut self, iteration: usize, correction: &[f64], free_residual: &[f64]) {
        if iteration == 0 {
            self.energy0 = dot(correction, free_residual).abs().max(f64::MIN_POSITIVE);
        }
    }

    /// Backtracking on ‖R(Δu + α δu)‖ < (1 − 10⁻⁴ α) ‖R(Δu)‖ for α = 1, ½, … ⅟₆₄:
    /// the first length that reduces the residual is taken, else the one with
    /// the smallest residual (softening makes the tangent indefinite and full
    /// Newton steps can overshoot), into `best`. `evaluate(α, slot)` fills
    /// `slot` and gives `false` where the stress update fails at that length
    /// (it is then shortened); `slot` is `spare`, swapped with `best` when
    /// better. Records the correction applied for the energy criterion.
    fn line_search(
        &mut self,
        correction: &[f64],
        reference_norm: f64,
        (best, spare): (&mut Candidate, &mut Candidate),
        mut evaluate: impl FnMut(f64, &mut Candidate) -> Result<bool, NewtonError>,
    ) -> Result<(), NewtonError> {
        let mut found = false;
        let mut alpha = 1.0;
        for _ in 0..7 {
            if !evaluate(alpha, spare)? {
                alpha *= 0.5;
                continue;
            }
            let norm = spare.residual.norm;
            let accepted = norm < (1.0 - 1e-4 * alpha) * reference_norm;
            if accepted || !found || norm < best.residual.norm {
                std::mem::swap(best, spare);
                found = true;
            }
            if accepted {
                break;
            }
            alpha *= 0.5;
        }
        if !found {
            return Err(NewtonError::failed(
                NewtonFailure::NonFinite("stress update at every line-search step"),
                &[],
            ));
        }
        // the energy norm uses the correction actually applied
        self.last_correction.clear();
        let alpha = best.alpha;
        self.last_correction
            .extend(correction.iter().map(|c| alpha * c));
        Ok(())
    }
}

/// Newton–Raphson for one (sub-)step (theory D17): from Δu⁰ (prescribed
/// nodal increments), assemble and factorise the tangent, solve for the
/// correction, line-search it, until the D18 criteria hold; then check the
/// motion limit. κ̄ is lagged one iteration (D36) through `nonlocal`. The
/// iterates live in `buffers` (every value is written before it is read).
pub fn solve(
    system: &StepSystem,
    tangent: &mut Tangent,
    mut nonlocal: Option<&mut NonlocalStep>,
    usage: &mut SolverUsage,
    profile: &Profile,
    buffers: &mut NewtonBuffers,
) -> Result<Solution, NewtonError> {
    let model = system.model;
    let mut convergence = Convergence::new(&model.settings.solver, model.settings.max_iterations);
    tangent.begin_newton(system);
    // the iterate, the line search's best candidate and its spare slot
    let NewtonBuffers {
        current,
        best,
        spare,
        scratch,
    } = buffers;
    start_iterate(system, current);
    let path = system.path.map(|c| (c, system.travel_derivatives()));
    let Candidate {
        du,
        trial,
        residual,
        travel,
        ..
    } = &mut *current;
    let at = (&du[..], *travel);
    system.evaluate_into(at, nonlocal.as_deref(), trial, scratch, residual, profile)?;
    let mut free_residual = Vec::new();
    // `judge` ends the loop: at convergence, or with an error at the iteration limit
    let mut iteration = 0;
    loop {
        let Candidate {
            du,
            trial,
            residual: res,
            travel,
            ..
        } = &*current;
        let travel = *travel;
        gather_free_into(&system.dofs, &res.residual, &mut free_residual);
        let constraint = res.constraint;
        let kappa_settled = || match nonlocal.as_deref_mut() {
            Some(nl) => Ok(profile.time(Stage::Nonlocal, || {
                nl.iterate(
                    &model.state.particles,
                    |p| trial.state[p].plastic_strain_eq,
                    profile,
                )
            })?),
            None => Ok(true),
        };
        let constraint_met = path
            .as_ref()
            .zip(constraint)
            .is_none_or(|((c, _), g)| c.met(g));
        let verdict = convergence
            .judge(
                iteration,
                res,
                &free_residual,
                constraint_met,
                kappa_settled,
            )
            .map_err(|e| e.located(&system.dofs, &model.grid, &free_residual))?;
        if let Verdict::Converged { stagnated } = verdict {
            usage.stagnated_steps += usize::from(stagnated);
            return converged(system, current, iteration, convergence.history);
        }
        if iteration >= CONTACT_HOLD_ITERATION && !system.model.friction.is_empty() {
            system.hold_sticks(du);
        }
        // path following solves the bordered system (PF4); the energy
        // norm's reference is then the work of the load R + (∂f_pen/∂τ) δτ
        let bordered = path.as_ref().zip(constraint);
        let (mut correction, travel_correction) = newton_correction(
            system,
            tangent,
            trial,
            &free_residual,
            bordered,
            usage,
            profile,
        )?;
        if let Some(cells) = model.settings.solver.max_correction {
            let longest = cells * model.grid.cell_size;
            limit_nodal_corrections(&system.dofs.index, &mut correction, longest);
        }
        let loaded = loaded_residual(&free_residual, path.as_ref(), travel_correction);
        if correction.iter().any(|v| !v.is_finite()) || !travel_correction.is_finite() {
            let cause = NewtonFailure::NonFinite("solution of the linear system");
            return Err(NewtonError::failed(cause, &convergence.history));
        }
        convergence.first_correction(iteration, &correction, &loaded);
        // κ̄ changed since `res` was evaluated: the line search compares against
        // the residual at the current κ̄, so re-evaluate the reference first.
        let reference_norm = match nonlocal.as_deref() {
            Some(nl) if iteration > 0 => {
                let at = (&du[..], travel);
                norm_at_new_kappa(system, at, nl, (spare, scratch), profile)?
            }
            _ => res.norm,
        };
        let slots = (&mut *best, &mut *spare);
        convergence.line_search(&correction, reference_norm, slots, |alpha, slot| {
            let step = (alpha, &correction[..], travel_correction);
            corrected_increment(slot, system, (&du[..], travel), step);
            evaluate_candidate(system, slot, nonlocal.as_deref(), scratch, profile)
        })?;
        std::mem::swap(current, best);
        iteration += 1;
    }
}

/// The converged iterate `current` as the step's solution, after the motion
/// limit of theory §3 is checked.
fn converged(
    system: &StepSystem,
    current: &mut Candidate,
    iteration: usize,
    history: Vec<f64>,
) -> Result<Solution, NewtonError> {
    system
        .check_motion(&current.du)
        .map_err(|cause| NewtonError::failed(cause, &history))?;
    Ok(Solution {
        du: std::mem::take(&mut current.du),
        travel: current.travel,
        trial: std::mem::take(&mut current.trial),
        residual: std::mem::take(&mut current.residual),
        iterations: iteration,
        history,
    })
}

/// Stress update and residual at the line search's candidate `slot`: whether
/// its ‖R‖ is finite; a failed stress update (at a too-long step) counts as
/// not finite, so that the line search shortens the step.
fn evaluate_candidate(
    system: &StepSystem,
    slot: &mut Candidate,
    nonlocal: Option<&NonlocalStep>,
    scratch: &mut ResidualScratch,
    profile: &Profile,
) -> Result<bool, NewtonError> {
    let Candidate {
        du,
        trial,
        residual,
        travel,
        ..
    } = slot;
    match system.evaluate_into((du, *travel), nonlocal, trial, scratch, residual, profile) {
        Ok(()) => Ok(residual.norm.is_finite()),
        Err(NewtonError::Constitutive(..)) => Ok(false),
        Err(e) => Err(e),
    }
}

/// Newton's first iterate in `current`: the prescribed nodal increments and
/// the predictor (theory D17), or under path following the last step scaled
/// (PF4).
fn start_iterate(system: &StepSystem, current: &mut Candidate) {
    current.travel = system.dt;
    current.du = match system.path {
        // path following starts from the last step scaled (PF4)
        Some(c) => {
            current.travel = c.start_travel;
            system.initial_increment(&system.scaled_last_increment(c.predictor))
        }
        None => system.initial_increment(&system.predictor()),
    };
}

/// The Newton correction of the free dofs and of the anchors' step: the
/// tangent's solution for `free_residual`, or under path following
/// (`bordered`: the constraint, its derivatives and its value g) that of the
/// bordered system (PF4).
fn newton_correction(
    system: &StepSystem,
    tangent: &mut Tangent,
    trial: &TrialStresses,
    free_residual: &[f64],
    bordered: Option<(&(PathConstraint, TravelDerivatives), f64)>,
    usage: &mut SolverUsage,
    profile: &Profile,
) -> Result<(Vec<f64>, f64), NewtonError> {
    let place = |e| singular_placed(e, &system.dofs, &system.model.grid);
    Ok(match bordered {
        Some(((c, derivatives), g)) => tangent
            .solve_bordered(
                system,
                trial,
                (free_residual, &c.border(derivatives, g)),
                usage,
                profile,
            )
            .map_err(place)?,
        None => (
            tangent
                .solve(system, trial, free_residual, usage, profile)
                .map_err(place)?,
            0.0,
        ),
    })
}

/// The load whose work is the energy norm's reference: the free residual,
/// under path following R + (∂f_pen/∂τ) δτ (PF4).
fn loaded_residual<'a>(
    free_residual: &'a [f64],
    path: Option<&(PathConstraint, TravelDerivatives)>,
    travel_correction: f64,
) -> std::borrow::Cow<'a, [f64]> {
    match path {
        Some((_, derivatives)) => (free_residual.iter())
            .zip(&derivatives.force_rate)
            .map(|(r, q)| r + q * travel_correction)
            .collect(),
        None => free_residual.into(),
    }
}

/// ‖R‖ at the iterate `(du, travel)` with the current κ̄ (D36: κ̄ changed
/// since the iterate's residual was evaluated), evaluated in the spare slot,
/// whose contents are not kept; no tangent is assembled from this residual,
/// so none is formed.
fn norm_at_new_kappa(
    system: &StepSystem,
    (du, travel): (&[[f64; 2]], f64),
    nonlocal: &NonlocalStep,
    (spare, scratch): (&mut Candidate, &mut ResidualScratch),
    profile: &Profile,
) -> Result<f64, NewtonError> {
    let Candidate {
        trial, residual, ..
    } = spare;
    let tangents = false;
    system.evaluate_with(
        (du, travel),
        Some(nonlocal),
        trial,
        (scratch, residual),
        profile,
        tangents,
    )?;
    Ok(residual.norm)
}

/// The line search's candidate in `slot`: the iterate `(du, travel)` plus
/// `alpha` times the correction (free dofs and anchors' step).
fn corrected_increment(
    slot: &mut Candidate,
    system: &StepSystem,
    (du, travel): (&[[f64; 2]], f64),
    (alpha, correction, travel_correction): (f64, &[f64], f64),
) {
    slot.alpha = alpha;
    slot.travel = travel + alpha * travel_correction;
    slot.du.clear();
    slot.du.extend_from_slice(du);
    for (d, &index) in system.dofs.index.iter().enumerate() {
        if index != NONE {
            slot.du[d / 2][d % 2] += alpha * correction[index as usize];
        }
    }
}

/// The correction limit of theory §3.3: every node whose correction
/// (its free components, `index` mapping dof 2 node + c to the unknown or
/// [`NONE`]) is longer than `longest` has it scaled to that length, keeping
/// its direction; the other nodes' corrections are left as they are. Returns
/// the number of nodes scaled.
fn limit_nodal_corrections(index: &[u32], correction: &mut [f64], longest: f64) -> usize {
    let mut scaled = 0;
    for dofs in index.chunks_exact(2) {
        let free = |d: u32| (d != NONE).then_some(d as usize);
        let (x, y) = (free(dofs[0]), free(dofs[1]));
        let component = |i: Option<usize>| i.map_or(0.0, |i| correction[i]);
        let length = component(x).hypot(component(y));
        if length > longest {
            let factor = longest / length;
            for i in [x, y].into_iter().flatten() {
                correction[i] *= factor;
            }
            scaled += 1;
        }
    }
    scaled
}

/// True when each of the last three iterations changed the residual norm by
/// less than 1 %.
fn stagnating(history: &[f64]) -> bool {
    history.len() >= 4
        && history[history.len() - 4..]
            .windows(2)
            .all(|w| (w[1] - w[0]).abs() < 0.01 * w[0])
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

#[cfg(test)]
mod tests {
    use super::{limit_nodal_corrections, stagnating, NONE};

    /// A node whose correction is longer than the limit is scaled to it along
    /// its own direction, with one held dof or both free; the other nodes'
    /// corrections keep their bits.
    #[test]
    fn only_long_nodal_corrections_are_scaled() {
        // node 0: both free, length 5; node 1: y held, |x| = 2; node 2: short
        let index = [0, 1, 2, NONE, 3, 4];
        let mut correction = [3.0, -4.0, -2.0, 0.1, 0.2];
        let short = correction[3..].to_vec();
        let scaled = limit_nodal_corrections(&index, &mut correction, 1.0);
        assert_eq!(scaled, 2);
        assert!((correction[0] - 0.6).abs() < 1e-15 && (correction[1] + 0.8).abs() < 1e-15);
        assert_eq!(correction[2], -1.0);
        assert_eq!(correction[3..], short[..]);
    }

    /// The residual histories of the local h = 1/700 biaxial run with 3×3
    /// points per cell (step 114, stagnating at 8.6e-7 after a 1.8e8 reduction)
    /// and of a quadratically converging softening step (tests/element_path.rs)
    /// are told apart; too short a history never counts as stagnation.
    #[test]
    fn stagnation_is_told_from_convergence() {
        let stalled = [
            154.45, 4.37e-5, 9.24e-7, 8.5996e-7, 8.5977e-7, 8.5959e-7, 8.5941e-7,
        ];
        let quadratic = [1.0, 2.0e-3, 3.6e-5, 1.2e-8, 8.4e-13];
        assert!(stagnating(&stalled));
        assert!(!stagnating(&quadratic));
        assert!(!stagnating(&stalled[..3]));
        // one iteration with a real (> 1 %) reduction breaks the stagnation
        let recovering = [154.45, 9.24e-7, 8.5996e-7, 8.0e-7, 7.99e-7];
        assert!(!stagnating(&recovering));
    }
}
