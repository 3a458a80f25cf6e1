//! Implicit integrator (theory §3): full Newton–Raphson on the nodal
//! equilibrium of each step, quasi-static or dynamic with the Newmark
//! rule (paper eq. 2, theory D15–D17), consistent tangent assembled per cell
//! and factorised by the sparse direct solver; a step whose Newton loop
//! fails is halved, up to `solver.max_halvings` times.

use mpm_solvers::{SolverStats, SparseMatrix};

use super::boundary_work::fixed_dof_kinetic_energy;
use super::commit::{commit, NodalResults};
use super::converged_stresses::converged_stresses;
use super::g2p::{g2p, GridMotion, VelocityUpdate};
use super::newton::{self, NewtonBuffers, Solution};
use super::p2g::{external_force_into, nodal_kinematics, KinematicsBuffers};
use super::path::{PathConstraint, PathRecord, MAX_RELEARNED};
use super::step_control::{LocalError, StepControlRecord, StepController};
use super::step_system::{Newmark, NewtonError, NodalKinematics, StepSystem};
use super::tangent::{background_block, Tangent};
use super::{NonlocalStep, SolverUsage, StepReport, StepSetup, TrialStresses};
use crate::bc::DofConstraint;
use crate::dofs::{gather_free_into, DofMap};
use crate::error::StepError;
use crate::model::Model;
use crate::profile::{Profile, Stage, Work};
use crate::scene::AnalysisKind;

/// The implicit integrator and its caches.
pub struct ImplicitIntegrator {
    /// Time step Δt (quasi-static: pseudo-time, default 1).
    dt: f64,
    /// Newmark parameters; `None` in quasi-static runs.
    newmark: Option<Newmark>,
    /// Tangent pattern, assembler and sparse direct solver.
    tangent: Tangent,
    /// ε_bg · K_cell^el (theory D19).
    background_block: [f64; 64],
    /// What a (sub-)step builds, refilled in place by the next.
    buffers: StepBuffers,
    /// Factorisations, Newton iterations, halvings.
    pub usage: SolverUsage,
    /// ‖R‖ per Newton iteration of the last converged (sub-)step, kN/m, and the
    /// reference force of theory D18 it was compared with.
    pub last_residuals: (Vec<f64>, f64),
    /// The Newton iterates' buffers, kept from one (sub-)step to the next.
    newton_buffers: NewtonBuffers,
    /// The step-size controller (`[solver] time_step = "adaptive"`).
    control: Option<StepController>,
    /// Path following: the travel and load change of the last attempt
    /// rejected for jumping off the path (PF6).
    path_jump: Option<[f64; 2]>,
}

/// What an adaptive attempt needs to judge its error.
#[derive(Clone, Copy)]
struct ErrorControl {
    /// The controller.
    controller: StepController,
    /// The velocity scale of the relative error so far, m/s.
    velocity_scale: f64,
    /// Keep the step whatever its error (the first step, or one at `dt_min`).
    keep_any: bool,
}

/// What controls an attempt at a (sub-)step.
#[derive(Clone, Copy)]
enum Control {
    /// A step of the given `dt`.
    Fixed,
    /// Adaptive steps: the attempt's error is judged.
    Error(ErrorControl),
    /// Path following (theory §3.7): the constraint fixes the anchors' travel.
    Path(PathConstraint),
}

/// How an attempt at a (sub-)step ended.
enum Attempt {
    /// Converged and committed to the model, in this many Newton iterations;
    /// with adaptive steps, its local error.
    Committed(usize, Option<LocalError>),
    /// Converged, but its local error estimate exceeds the tolerance: the
    /// model is unchanged.
    Rejected(f64),
}

/// What a (sub-)step builds, kept by the integrator so that the next
/// (sub-)step refills the same arrays instead of allocating new ones.
#[derive(Default)]
struct StepBuffers {
    /// Shape functions and bins at the start-of-step positions.
    setup: StepSetup,
    /// The numbering of the unknowns, frictional nodes closed.
    free_dofs: DofMap,
    /// P2G's patch and nodal sums.
    p2g: KinematicsBuffers,
    /// P2G's nodal kinematics, as mapped.
    mapped: NodalKinematics,
    /// The step system's copies of `free_dofs` and `mapped` (a contact pass
    /// opens frictional nodes and zeroes the fixed dofs on them).
    system_dofs: DofMap,
    system_nodal: NodalKinematics,
    /// The converged step's nodal fields.
    fields: GridFields,
}

impl ImplicitIntegrator {
    /// The integrator for `model`'s scene.
    pub fn new(model: &Model) -> Result<Self, crate::scene::SceneError> {
        let dynamic = model.analysis() == AnalysisKind::ImplicitDynamic;
        Ok(Self {
            dt: model.settings.run.dt.unwrap_or(1.0),
            newmark: dynamic.then(|| Newmark::from_solver(&model.settings.solver)),
            tangent: Tangent::new(model)?,
            background_block: background_block(&model.settings, &model.grid),
            buffers: StepBuffers::default(),
            usage: SolverUsage::default(),
            last_residuals: (Vec::new(), 0.0),
            newton_buffers: NewtonBuffers::default(),
            control: StepController::of(&model.settings),
            path_jump: None,
        })
        .map(|mut integrator| {
            if integrator.control.is_some() {
                integrator.usage.step_control = Some(StepControlRecord {
                    next_dt: integrator.dt,
                    ..Default::default()
                });
            }
            if model.settings.solver.follows_path() {
                integrator.usage.path = Some(PathRecord::default());
            }
            integrator
        })
    }

    /// The time step, s.
    pub fn dt(&self) -> f64 {
        self.dt
    }

    /// Counters and timings of the tangent's linear solver.
    pub fn solver_stats(&self) -> SolverStats {
        self.tangent.solver_stats()
    }

    /// Fallbacks of the linear solver and skipped system exports.
    pub fn solver_warnings(&self) -> Vec<String> {
        self.tangent.warnings()
    }

    /// Write the systems of `[output] systems` (if any) into `dir`.
    pub fn export_systems(&mut self, dir: std::path::PathBuf, steps: Vec<usize>, max_mb: f64) {
        self.tangent.export_systems(dir, steps, max_mb);
    }

    /// Systems exported so far.
    pub fn systems_written(&self) -> usize {
        self.tangent.systems_written()
    }

    /// One implicit step: of Δt, halved on Newton failure (theory §3), or with
    /// adaptive steps of the controller's choice.
    pub fn step(&mut self, model: &mut Model, profile: &Profile) -> Result<StepReport, StepError> {
        if let Some(control) = self.control {
            return self.adaptive_step(model, profile, control);
        }
        if model.settings.solver.follows_path() {
            return self.path_step(model, profile);
        }
        let (t0, dt) = (model.state.time, self.dt);
        let mut report = StepReport {
            step: model.state.step + 1,
            dt,
            ..Default::default()
        };
        if model.settings.solver.remember_halvings {
            self.remembered_halvings(model, profile, t0, dt, &mut report)?;
        } else {
            self.advance(model, profile, t0, dt, 0, &mut report)?;
        }
        model.state.step += 1;
        model.state.time = t0 + dt;
        report.time = model.state.time;
        Ok(report)
    }

    /// One step whose size the error estimate controls (theory
    /// "Error-controlled steps"): the proposed step, cut to end at the next
    /// jump of the stepped gravity and at the end time, is tried; an attempt
    /// whose estimate exceeds the tolerance is redone with the step the
    /// controller derives from it, one whose Newton iteration fails with half
    /// the step. The first step of a run (its start acceleration is assumed,
    /// not computed) and a step at `dt_min` are kept whatever their estimate.
    fn adaptive_step(
        &mut self,
        model: &mut Model,
        profile: &Profile,
        control: StepController,
    ) -> Result<StepReport, StepError> {
        let t0 = model.state.time;
        restart_at_gravity_jump(model, self.newmark);
        let mut record = self.usage.step_control.take().unwrap_or_default();
        let mut report = StepReport {
            step: model.state.step + 1,
            ..Default::default()
        };
        let mut proposal = record.next_dt;
        let result = loop {
            let dt = self.step_within_loads(model, t0, proposal);
            let judge = ErrorControl {
                controller: control,
                velocity_scale: record.velocity_scale,
                keep_any: model.state.step == 0 || dt <= control.dt_min * (1.0 + 1e-9),
            };
            match self.substep(model, profile, (t0, dt), Control::Error(judge), &mut report) {
                Ok(Attempt::Committed(iterations, local)) => {
                    report.iterations += iterations;
                    report.substeps += 1;
                    report.dt = dt;
                    self.usage.newton_iterations += iterations;
                    record.accept(dt, local);
                    if report.error_estimate.is_some_and(|e| !control.accepts(e)) {
                        record.accepted_at_min += 1;
                    }
                    let estimate = report.error_estimate.unwrap_or(0.0);
                    // a step cut short by a load jump or the end tells
                    // nothing against the longer step proposed
                    record.next_dt = if dt < proposal && control.accepts(estimate) {
                        proposal
                    } else {
                        control.next(dt, estimate)
                    };
                    break Ok(());
                }
                Ok(Attempt::Rejected(estimate)) => {
                    report.rejected_error += 1;
                    record.rejected_error += 1;
                    proposal = control.next(dt, estimate);
                }
                Err(e) if e.retry() && dt > control.dt_min * (1.0 + 1e-9) => {
                    report.rejected_newton += 1;
                    record.rejected_newton += 1;
                    self.usage.halvings += 1;
                    proposal = (0.5 * dt).max(control.dt_min);
                }
                Err(e) => break Err(e.into_step_error(report.rejected_newton)),
            }
        };
        self.usage.step_control = Some(record);
        result?;
        model.state.step += 1;
        report.time = model.state.time;
        Ok(report)
    }

    /// One path-following step (theory §3.7, PF5): the path record's
    /// constraint fixes the anchors' travel; an attempt whose Newton
    /// iteration fails is redone with half the arc, up to
    /// `solver.max_halvings` times. The run stops with its step budget
    /// (`solver.path_max_steps`) spent.
    fn path_step(&mut self, model: &mut Model, profile: &Profile) -> Result<StepReport, StepError> {
        let settings = &model.settings;
        let end = settings.run.end_time_or_steps();
        let budget = settings.solver.path_step_budget(settings.run.steps);
        if model.state.step >= budget {
            return Err(StepError::PathBudget {
                steps: model.state.step,
                reached: model.state.time,
                end,
            });
        }
        let max_cuts = settings.solver.max_halvings;
        let (t, dt) = (model.state.time, self.dt);
        let mut record = self.usage.path.take().unwrap_or_default();
        let load_before = model.state.driven.committed_load(&model.state.particles, t);
        let mut report = StepReport {
            step: model.state.step + 1,
            ..Default::default()
        };
        let mut shrink = 1.0;
        let mut cuts = 0;
        let mut relearned = 0;
        let result = loop {
            let constraint = record.constraint(t, dt, end, shrink);
            match self.substep(
                model,
                profile,
                (t, dt),
                Control::Path(constraint),
                &mut report,
            ) {
                Ok(Attempt::Committed(iterations, _)) => {
                    report.iterations += iterations;
                    report.substeps += 1;
                    self.usage.newton_iterations += iterations;
                    let load = model
                        .state
                        .driven
                        .committed_load(&model.state.particles, model.state.time);
                    record.advance(dt, model.state.time - t, load - load_before, iterations);
                    break Ok(());
                }
                // a jump onto an elastic branch measures the body's present
                // unloading stiffness: the step is redone at the same plastic
                // travel, measured with it (PF6)
                Ok(Attempt::Rejected(_))
                    if relearned < MAX_RELEARNED
                        && self
                            .path_jump
                            .take()
                            .is_some_and(|[travel, load]| record.relearn(dt, travel, load)) =>
                {
                    relearned += 1;
                    record.jumps += 1;
                }
                Ok(Attempt::Rejected(_)) if cuts < max_cuts => {
                    cuts += 1;
                    shrink *= 0.5;
                    record.cuts += 1;
                    record.jumps += 1;
                }
                Ok(Attempt::Rejected(_)) => break Err(StepError::PathJump { travel: t, cuts }),
                Err(e) if e.retry() && cuts < max_cuts => {
                    cuts += 1;
                    shrink *= 0.5;
                    record.cuts += 1;
                    self.usage.halvings += 1;
                }
                Err(e) => break Err(e.into_step_error(cuts)),
            }
        };
        self.usage.path = Some(record);
        result?;
        model.state.step += 1;
        report.dt = model.state.time - t;
        report.time = model.state.time;
        Ok(report)
    }

    /// The step `proposal` cut to end at the next jump of the stepped gravity
    /// and at the end time.
    fn step_within_loads(&self, model: &Model, t: f64, proposal: f64) -> f64 {
        let end = model.settings.run.end_time_or_steps();
        let mut dt = proposal.min(end - t);
        if let Some(jump) = model.settings.loads.next_gravity_jump(t) {
            dt = dt.min(jump - t);
        }
        dt
    }

    /// Advance from `t` by `dt`; on a failure that halving may cure, two
    /// half steps instead (`depth` halvings so far).
    fn advance(
        &mut self,
        model: &mut Model,
        profile: &Profile,
        t: f64,
        dt: f64,
        depth: usize,
        report: &mut StepReport,
    ) -> Result<(), StepError> {
        match self.substep(model, profile, (t, dt), Control::Fixed, report) {
            // a fixed step is not judged for its error
            Ok(Attempt::Rejected(_)) => Err(StepError::NotAvailable(
                "a fixed step was rejected for its error",
            )),
            Ok(Attempt::Committed(iterations, _)) => {
                report.iterations += iterations;
                report.substeps += 1;
                self.usage.newton_iterations += iterations;
                Ok(())
            }
            Err(e) if e.retry() && depth < model.settings.solver.max_halvings => {
                self.usage.halvings += 1;
                self.advance(model, profile, t, 0.5 * dt, depth + 1, report)?;
                self.advance(model, profile, t + 0.5 * dt, 0.5 * dt, depth + 1, report)
            }
            Err(e) => Err(e.into_step_error(depth)),
        }
    }

    /// A fixed step with remembered halvings (theory §3.3, "Remembered
    /// halvings"): 2^d equal substeps at the depth d the last step left,
    /// each halved further on a Newton failure as in [`Self::advance`]. A
    /// step that needed no halving lets the next start one level coarser;
    /// one that did starts the next at the deepest level it reached.
    fn remembered_halvings(
        &mut self,
        model: &mut Model,
        profile: &Profile,
        t0: f64,
        dt: f64,
        report: &mut StepReport,
    ) -> Result<(), StepError> {
        let depth = self
            .usage
            .start_depth
            .min(model.settings.solver.max_halvings);
        let pieces = 1usize << depth;
        let piece = dt / pieces as f64;
        let halvings_before = self.usage.halvings;
        let mut deepest = depth;
        for k in 0..pieces {
            let substeps_before = report.substeps;
            let halvings = self.usage.halvings;
            self.advance(model, profile, t0 + k as f64 * piece, piece, depth, report)?;
            // a piece halved h times over s substeps went at least
            // ⌈log2 s⌉ levels deeper
            let extra = report.substeps - substeps_before;
            if self.usage.halvings > halvings {
                deepest = deepest.max(depth + extra.next_power_of_two().trailing_zeros() as usize);
            }
        }
        self.usage.remembered_substeps += if depth > 0 { pieces } else { 0 };
        self.usage.start_depth = if self.usage.halvings > halvings_before {
            deepest
        } else {
            depth.saturating_sub(1)
        };
        Ok(())
    }

    /// One (sub-)step from `t` to `t + dt`, the stages of paper Fig. 1. With
    /// error control (adaptive steps: whether to keep the step whatever its
    /// error) the converged step's error is estimated, and a step that fails
    /// the tolerance is rejected before anything is committed; with a path
    /// constraint the step ends at `t + Δτ`, Δτ chosen by the constraint.
    /// The step's arrays are the integrator's, refilled in place.
    fn substep(
        &mut self,
        model: &mut Model,
        profile: &Profile,
        (t, dt): (f64, f64),
        control: Control,
        report: &mut StepReport,
    ) -> Result<Attempt, NewtonError> {
        let StepBuffers {
            setup,
            free_dofs,
            p2g,
            mapped,
            system_dofs,
            system_nodal,
            fields,
        } = &mut self.buffers;
        profile.time(Stage::Setup, || refresh_setup(model, setup, free_dofs))?;
        let setup = &*setup;
        profile.time(Stage::P2G, || {
            map_to_grid(model, setup, self.newmark, t + dt, (p2g, mapped), profile)
        });
        let (system, solution, mut nonlocal) = ContactPasses {
            tangent: &mut self.tangent,
            usage: &mut self.usage,
            newton: &mut self.newton_buffers,
            newmark: self.newmark,
            background_block: self.background_block,
        }
        .solve(
            model,
            setup,
            (mapped, free_dofs),
            (system_dofs, system_nodal),
            (t, dt),
            control,
            profile,
        )?;
        let dt = solution.travel;
        if let Some(jump) = path_jump(&system, &solution) {
            self.path_jump = Some(jump);
            (*system_dofs, *system_nodal) = (system.dofs, system.nodal);
            self.newton_buffers.recycle(solution.trial);
            return Ok(Attempt::Rejected(f64::INFINITY));
        }
        let grid = ConvergedGrid::new(&system, solution, std::mem::take(fields));
        let boundary_work = system.nodal.removed_energy + system.friction_work(&grid.du);
        let local = local_error(&system, &grid, control, self.newmark, dt);
        (*system_dofs, *system_nodal) = (system.dofs, system.nodal);
        if let (Some((_, estimate)), Control::Error(judge)) = (&local, control) {
            report.error_estimate = Some(*estimate);
            if !judge.controller.accepts(*estimate) && !judge.keep_any {
                *fields = grid.fields;
                self.newton_buffers.recycle(grid.trial);
                return Ok(Attempt::Rejected(*estimate));
            }
        }
        self.last_residuals = (grid.history.clone(), grid.reference);
        let mut motion = grid.motion(dt, self.newmark);
        let removed_velocity = &system_nodal.removed_velocity;
        motion.velocity_removed = (!removed_velocity.is_empty()).then_some(&removed_velocity[..]);
        profile.time(Stage::G2P, || {
            g2p(&mut model.state.particles, &setup.shapes, &motion)
        });
        let converged = profile.time(Stage::Stresses, || {
            converged_stresses(model, setup, &grid.trial, nonlocal.as_mut(), profile)
        })?;
        let removed = profile.time(Stage::Commit, || {
            let nodal = NodalResults {
                reaction: &grid.fields.reaction,
                increment: &grid.du,
                contact_motion: &grid.du,
                gravity: model.settings.loads.gravity_at(t + dt),
                end_time: t + dt,
                nonzero_at: None,
                boundary_work,
            };
            commit(model, setup, &grid.trial, converged, nodal)
        })?;
        report.removed_points.extend(removed);
        model.state.time = t + dt;
        *fields = grid.fields;
        self.newton_buffers.recycle(grid.trial);
        Ok(Attempt::Committed(
            grid.iterations,
            local.map(|(error, _)| error),
        ))
    }

    /// The next step's linearisation at a given free-dof displacement increment
    /// (verification access, e.g. finite-difference checks of the tangent):
    /// the residual R = f_ext + f_pen − f_int − M a at the free dofs and the
    /// assembled tangent (theory D16–D17, incl. the \[D19\] term), without
    /// changing the model. `free_increment` has one entry per unknown (see
    /// [`Self::unknowns`]).
    pub fn linearize(
        &mut self,
        model: &Model,
        free_increment: &[f64],
    ) -> Result<(Vec<f64>, SparseMatrix), StepError> {
        let (t, dt) = (model.state.time, self.dt);
        let profile = Profile::default();
        let StepBuffers {
            setup,
            free_dofs,
            p2g,
            mapped,
            ..
        } = &mut StepBuffers::default();
        refresh_setup(model, setup, free_dofs)?;
        if free_increment.len() != free_dofs.n_free {
            return Err(StepError::WrongLength {
                what: "linearize",
                given: free_increment.len(),
                expected: free_dofs.n_free,
            });
        }
        map_to_grid(model, setup, self.newmark, t + dt, (p2g, mapped), &profile);
        let system = step_system(
            model,
            setup,
            (std::mem::take(free_dofs), std::mem::take(mapped)),
            (t, dt),
            (self.newmark, self.background_block),
        );
        let du = system.initial_increment(free_increment);
        let mut trial = TrialStresses::default();
        let res = system
            .evaluate(&du, None, &mut trial, &profile)
            .map_err(|e| e.into_step_error(0))?;
        self.tangent.begin_step();
        let matrix = self.tangent.assemble(&system, &trial, &profile)?;
        let mut free_residual = Vec::new();
        gather_free_into(&system.dofs, &res.residual, &mut free_residual);
        Ok((free_residual, matrix))
    }

    /// Number of unknowns of the next step.
    pub fn unknowns(model: &Model) -> Result<usize, StepError> {
        let (mut setup, mut dofs) = (StepSetup::default(), DofMap::default());
        refresh_setup(model, &mut setup, &mut dofs)?;
        Ok(dofs.n_free)
    }
}

/// The nonlinear system of a (sub-)step from `t` over `dt` on the numbering
/// `dofs` and the mapped kinematics `nodal`, with the integrator's Newmark
/// parameters and background block (theory D19).
fn step_system<'a>(
    model: &'a Model,
    setup: &'a StepSetup,
    (dofs, nodal): (DofMap, NodalKinematics),
    (t, dt): (f64, f64),
    (newmark, background_block): (Option<Newmark>, [f64; 64]),
) -> StepSystem<'a> {
    StepSystem {
        model,
        setup,
        dofs,
        nodal,
        t,
        dt,
        newmark,
        background_block,
        held_sticks: Default::default(),
        path: None,
    }
}

/// P2G into `nodal`: nodal mass, v_n and a_n (dynamic only, in one pass;
/// the mass counted in `profile`) and the external force at `t1` (theory
/// D10). The constrained dofs are held by [`hold_fixed_dofs`].
fn map_to_grid(
    model: &Model,
    setup: &StepSetup,
    newmark: Option<Newmark>,
    t1: f64,
    (sums, nodal): (&mut KinematicsBuffers, &mut NodalKinematics),
    profile: &Profile,
) {
    let Some(newmark) = newmark else {
        external_force_into(model, setup, t1, &mut nodal.external);
        return;
    };
    let carry_force = newmark.is_generalised_alpha();
    nodal_kinematics(model, setup, t1, carry_force, sums, nodal);
    profile.count(Work::MassMatrix, 1);
}

/// The Newton solves of one (sub-)step with the frictional nodes opened or
/// closed (FR7), with the integrator's solver state.
struct ContactPasses<'s> {
    tangent: &'s mut Tangent,
    usage: &'s mut SolverUsage,
    newton: &'s mut NewtonBuffers,
    newmark: Option<Newmark>,
    background_block: [f64; 64],
}

impl ContactPasses<'_> {
    /// Solve the step from the P2G kinematics `mapped` on the numbering
    /// `free_dofs`: the first pass with the start's guess of the open
    /// frictional nodes, then one per change of the contact set, up to
    /// [`MAX_CONTACT_PASSES`]. Each pass's system takes `dofs` and `nodal`
    /// as its copies of `free_dofs` and `mapped` (the last pass's are
    /// returned in its system; the others are put back).
    #[allow(clippy::too_many_arguments)]
    fn solve<'a>(
        &mut self,
        model: &'a Model,
        setup: &'a StepSetup,
        (mapped, free_dofs): (&NodalKinematics, &DofMap),
        (dofs, nodal): (&mut DofMap, &mut NodalKinematics),
        (t, dt): (f64, f64),
        control: Control,
        profile: &Profile,
    ) -> Result<(StepSystem<'a>, Solution, Option<NonlocalStep>), NewtonError> {
        let mut open = open_at_start(model, setup, mapped, dt);
        let mut pass = 1;
        loop {
            let (mut pass_dofs, mut pass_nodal) = (std::mem::take(dofs), std::mem::take(nodal));
            pass_dofs.clone_from(free_dofs);
            release_open(&mut pass_dofs, model, &open);
            pass_nodal.clone_from(mapped);
            hold_fixed_dofs(&mut pass_nodal, model, setup, &pass_dofs, self.newmark);
            let mut nonlocal =
                NonlocalStep::start(model, false, profile).map_err(StepError::from)?;
            let parameters = (self.newmark, self.background_block);
            let mut system =
                step_system(model, setup, (pass_dofs, pass_nodal), (t, dt), parameters);
            if let Control::Path(constraint) = control {
                system.path = Some(constraint.starting_from(&system));
            }
            let solution = profile.time(Stage::Newton, || {
                newton::solve(
                    &system,
                    self.tangent,
                    nonlocal.as_mut(),
                    self.usage,
                    profile,
                    self.newton,
                )
            })?;
            let changes = contact_changes(&system, &open, &solution);
            if changes.is_empty() || pass == MAX_CONTACT_PASSES {
                return Ok((system, solution, nonlocal));
            }
            pass += 1;
            self.usage.contact_resolves += 1;
            for k in changes {
                open[k] = !open[k];
            }
            self.newton.recycle(solution.trial);
            (*dofs, *nodal) = (system.dofs, system.nodal);
        }
    }
}

/// Path following: the travel and load change of a converged step that
/// jumped off the path (PF5), `None` where it stays on it or no path is
/// followed.
fn path_jump(system: &StepSystem, solution: &Solution) -> Option<[f64; 2]> {
    let path = system.path?;
    let travel = solution.travel;
    let load_change = system.driven_load(&solution.du, travel) - path.start_load;
    (!path.accepts(system.dt, travel, load_change)).then_some([travel, load_change])
}

/// With error control (adaptive steps, dynamic), the converged step's local
/// error and its estimate relative to the velocity scale.
fn local_error(
    system: &StepSystem,
    grid: &ConvergedGrid,
    control: Control,
    newmark: Option<Newmark>,
    dt: f64,
) -> Option<(LocalError, f64)> {
    let (Control::Error(judge), Some(newmark)) = (control, newmark) else {
        return None;
    };
    let error = LocalError::of(system, &newmark, &grid.du, &grid.fields.acceleration);
    let estimate = error.relative(dt, judge.velocity_scale);
    Some((error, estimate))
}

/// At a jump of the stepped gravity just after the start of a step, the
/// body force per mass jumps by −Δg ŷ while the stresses cannot: every
/// point's acceleration (and, generalised-α, its force per mass) jumps by the
/// same amount (theory eq. AS4). Adaptive steps end at each jump, so that the
/// next step starts from the acceleration after it and its error estimate
/// sees no load discontinuity.
fn restart_at_gravity_jump(model: &mut Model, newmark: Option<Newmark>) {
    let jump = model.settings.loads.gravity_jump_at(model.state.time);
    if jump == 0.0 || newmark.is_none() {
        return;
    }
    let p = &mut model.state.particles;
    p.acceleration.iter_mut().for_each(|a| a[1] -= jump);
    if newmark.is_some_and(|n| n.is_generalised_alpha()) {
        p.force_per_mass.iter_mut().for_each(|q| q[1] -= jump);
    }
}

/// The nodal fields of a converged (sub-)step that G2P and the commit read,
/// kept by the integrator from one (sub-)step to the next.
#[derive(Default)]
struct GridFields {
    /// a_{n+1} per grid node (dynamic runs; else empty).
    acceleration: Vec<[f64; 2]>,
    /// M⁻¹(f_ext − f_int) at t_{n+1} per grid node (generalised-α runs;
    /// else empty).
    force_per_mass: Vec<[f64; 2]>,
    /// Support reactions per grid node: −R, and at the frictional edges' free
    /// tangential dofs the friction force T (FR1).
    reaction: Vec<[f64; 2]>,
}

/// A converged (sub-)step's nodal solution, for the G2P and commit stages.
struct ConvergedGrid {
    /// Δu per grid node.
    du: Vec<[f64; 2]>,
    /// The nodal fields at Δu.
    fields: GridFields,
    /// Stresses, states and tangents at Δu.
    trial: TrialStresses,
    /// Newton iterations.
    iterations: usize,
    /// ‖R‖ per iteration, kN/m.
    history: Vec<f64>,
    /// F_ref of D18 at convergence.
    reference: f64,
}

impl ConvergedGrid {
    /// The converged `solution` of `system`, its nodal fields refilled into
    /// `fields`.
    fn new(system: &StepSystem, solution: Solution, mut fields: GridFields) -> Self {
        let Solution {
            du,
            trial,
            residual,
            iterations,
            history,
            ..
        } = solution;
        fields.reaction.clear();
        fields
            .reaction
            .extend(residual.residual.iter().map(|r| [-r[0], -r[1]]));
        system.add_friction_reactions(&du, &mut fields.reaction);
        fields.acceleration.clear();
        fields.force_per_mass.clear();
        if let Some(newmark) = system.newmark {
            system.nodal_acceleration_into(&newmark, &du, &mut fields.acceleration);
            if newmark.is_generalised_alpha() {
                system.nodal_inertial_acceleration_into(&newmark, &du, &mut fields.force_per_mass);
            }
        }
        Self {
            fields,
            reference: residual.reference,
            du,
            trial,
            iterations,
            history,
        }
    }

    /// G2P (theory §3): x_p += Σ N Δu_i; dynamic: a_p = Σ N a_i, Newmark v_p.
    fn motion(&self, dt: f64, newmark: Option<Newmark>) -> GridMotion<'_> {
        let rule = newmark.map(|n| VelocityUpdate::Newmark { gamma: n.gamma });
        let fields = &self.fields;
        GridMotion {
            dt,
            displacement: &self.du,
            scale: 1.0,
            acceleration: rule.map(|rule| (&fields.acceleration[..], rule)),
            force_per_mass: (!fields.force_per_mass.is_empty())
                .then_some(&fields.force_per_mass[..]),
            velocity_removed: None,
        }
    }
}

/// Solves of one step with frictional nodes opened or closed (FR7): the
/// first with the start's guess, then one per change of the contact set. A
/// set still changing after the last pass is kept as it is.
const MAX_CONTACT_PASSES: usize = 4;

/// The least motion v_n Δt away from a frictional edge, as a share of the
/// cell size, with which a node starts a step open (FR7). The mapped
/// velocity of soil resting on the edge is not zero but the noise of its
/// vibration: on the sliding block (h = 0.0625 m, Δt = 2 ms) ~1e-4 h, and
/// nodes opened on it chattered (the slide grew by 8 %); the tossed block
/// leaves at 0.06 h per step.
const LIFT_OFF: f64 = 1e-3;

/// Dirichlet dofs neither move nor accelerate (theory §3): v_n, a_n (and
/// generalised-α's q_n) are zeroed at the fixed dofs that `dofs` does not
/// release, and what the zeroing removed is kept for G2P and the budget
/// ([`super::boundary_work`] B1).
fn hold_fixed_dofs(
    nodal: &mut NodalKinematics,
    model: &Model,
    setup: &StepSetup,
    dofs: &DofMap,
    newmark: Option<Newmark>,
) {
    if newmark.is_none() {
        return;
    }
    let dof = &model.constraints.dof;
    let held = |d: usize| dof[d] == DofConstraint::Fixed && !dofs.is_free(d);
    nodal.removed_energy = fixed_dof_kinetic_energy(
        held,
        setup.bins.active_nodes.iter().map(|&n| n as usize),
        0.0,
        |i| nodal.mass[i],
        |i| nodal.velocity[i],
    );
    let carry_force = !nodal.force_per_mass.is_empty();
    for d in (0..dof.len()).filter(|&d| held(d)) {
        let (node, c) = (d / 2, d % 2);
        let v = nodal.velocity[node][c];
        if v != 0.0 {
            if nodal.removed_velocity.is_empty() {
                nodal
                    .removed_velocity
                    .resize(nodal.velocity.len(), [0.0; 2]);
            }
            nodal.removed_velocity[node][c] = v;
        }
        nodal.velocity[node][c] = 0.0;
        nodal.acceleration[node][c] = 0.0;
        if carry_force {
            nodal.force_per_mass[node][c] = 0.0;
        }
    }
}

/// The frictional nodes that start the step open (FR7): no compressive
/// reaction in the last step and a mapped velocity leaving the edge (none in
/// quasi-static steps, which have no velocity).
fn open_at_start(model: &Model, setup: &StepSetup, mapped: &NodalKinematics, dt: f64) -> Vec<bool> {
    let edges = &model.friction;
    if mapped.velocity.is_empty() {
        return vec![false; edges.nodes.len()];
    }
    edges.open_at_start(
        |node| setup.bins.node_active[node],
        |c| model.state.reaction[c.node][c.normal] * c.inward,
        |c| mapped.velocity[c.node][c.normal] * c.inward * dt - LIFT_OFF * model.grid.cell_size,
    )
}

/// Release the normal dofs of the `open` frictional nodes in `dofs`.
fn release_open(dofs: &mut DofMap, model: &Model, open: &[bool]) {
    for (contact, _) in model.friction.nodes.iter().zip(open).filter(|(_, &o)| o) {
        dofs.release(2 * contact.node + contact.normal);
    }
}

/// The frictional nodes whose contact the converged `solution` changes
/// (FR7): closed ones pulled by the edge open, open ones moved into the
/// edge by more than 1e-9 h close.
fn contact_changes(system: &StepSystem, open: &[bool], solution: &Solution) -> Vec<usize> {
    let model = system.model;
    if model.friction.is_empty() || system.newmark.is_none() {
        return Vec::new();
    }
    let (residual, du) = (&solution.residual.residual, &solution.du);
    model.friction.contact_changes(
        |node| system.setup.bins.node_active[node],
        open,
        |c| -residual[c.node][c.normal] * c.inward,
        |c| du[c.node][c.normal] * c.inward,
        1e-9 * model.grid.cell_size,
    )
}

/// Refresh the step setup `setup` (reusing its arrays) and number the
/// unknowns into `dofs`.
fn refresh_setup(model: &Model, setup: &mut StepSetup, dofs: &mut DofMap) -> Result<(), StepError> {
    setup.refresh(model)?;
    dofs.renumber(&setup.bins, &model.constraints);
    Ok(())
}
