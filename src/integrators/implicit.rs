//! Implicit integrator (DESIGN §3): full Newton–Raphson on the nodal
//! equilibrium of each step, quasi-static or dynamic with the Newmark
//! rule (paper eq. 2, DESIGN D15–D17), consistent tangent assembled per cell
//! and factorised by the sparse direct solver; a step whose Newton loop
//! fails is halved, up to `solver.max_halvings` times.

use mpm_solvers::{SolverStats, SparseMatrix};

use super::commit::{commit, NodalResults};
use super::g2p::{g2p, GridMotion, VelocityUpdate};
use super::newton::{
    self, Newmark, NewtonBuffers, NewtonError, NodalKinematics, Solution, StepSystem,
};
use super::p2g::{external_force, nodal_kinematics, KinematicsBuffers};
use super::stresses::converged_stresses;
use super::tangent::{background_block, Tangent};
use super::{NonlocalStep, SolverUsage, StepReport, StepSetup, TrialStresses};
use crate::bc::DofConstraint;
use crate::dofs::{gather_free, DofMap};
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
    /// ε_bg · K_cell^el (DESIGN D19).
    background_block: [f64; 64],
    /// The step setup, refreshed in place each (sub-)step (its shape
    /// functions and bins reuse the previous step's arrays).
    setup: StepSetup,
    /// Factorisations, Newton iterations, halvings.
    pub usage: SolverUsage,
    /// ‖R‖ per Newton iteration of the last converged (sub-)step, kN/m, and the
    /// reference force of DESIGN D18 it was compared with.
    pub last_residuals: (Vec<f64>, f64),
    /// The Newton iterates' buffers, kept from one (sub-)step to the next.
    newton_buffers: NewtonBuffers,
    /// The P2G pass's buffers, kept from one (sub-)step to the next.
    p2g: KinematicsBuffers,
}

impl ImplicitIntegrator {
    /// The integrator for `model`'s scene.
    pub fn new(model: &Model) -> Result<Self, crate::scene::SceneError> {
        let dynamic = model.analysis() == AnalysisKind::ImplicitDynamic;
        Ok(Self {
            dt: model.scene.scene.dt.unwrap_or(1.0),
            newmark: dynamic.then(|| Newmark::with_gamma(model.scene.solver.newmark_gamma)),
            tangent: Tangent::new(model)?,
            background_block: background_block(&model.scene, &model.grid),
            setup: StepSetup::default(),
            usage: SolverUsage::default(),
            last_residuals: (Vec::new(), 0.0),
            newton_buffers: NewtonBuffers::default(),
            p2g: KinematicsBuffers::default(),
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

    /// One implicit step of Δt, halved on Newton failure (DESIGN §3).
    pub fn step(&mut self, model: &mut Model, profile: &Profile) -> Result<StepReport, StepError> {
        let (t0, dt) = (model.time, self.dt);
        let mut report = StepReport {
            step: model.step + 1,
            dt,
            ..Default::default()
        };
        self.advance(model, profile, t0, dt, 0, &mut report)?;
        model.step += 1;
        model.time = t0 + dt;
        report.time = model.time;
        Ok(report)
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
        match self.substep(model, profile, t, dt, report) {
            Ok(iterations) => {
                report.iterations += iterations;
                report.substeps += 1;
                self.usage.newton_iterations += iterations;
                Ok(())
            }
            Err(e) if e.retry() && depth < model.scene.solver.max_halvings => {
                self.usage.halvings += 1;
                self.advance(model, profile, t, 0.5 * dt, depth + 1, report)?;
                self.advance(model, profile, t + 0.5 * dt, 0.5 * dt, depth + 1, report)
            }
            Err(e) => Err(e.into_step_error(depth)),
        }
    }

    /// One (sub-)step from `t` to `t + dt`, in the order of paper Fig. 1;
    /// returns the Newton iterations. The step setup is the integrator's,
    /// refreshed in place.
    fn substep(
        &mut self,
        model: &mut Model,
        profile: &Profile,
        t: f64,
        dt: f64,
        report: &mut StepReport,
    ) -> Result<usize, NewtonError> {
        let mut setup = std::mem::take(&mut self.setup);
        let result = self.substep_with(model, profile, t, dt, report, &mut setup);
        self.setup = setup;
        result
    }

    /// [`Self::substep`] with the step setup `setup` (refreshed here).
    fn substep_with(
        &mut self,
        model: &mut Model,
        profile: &Profile,
        t: f64,
        dt: f64,
        report: &mut StepReport,
        setup: &mut StepSetup,
    ) -> Result<usize, NewtonError> {
        let dofs = profile.time(Stage::Setup, || refresh_setup(model, setup))?;
        let setup = &*setup;
        let nodal = profile.time(Stage::P2G, || {
            self.map_to_grid(model, setup, t + dt, profile)
        });
        let mut nonlocal = NonlocalStep::start(model, false, profile).map_err(StepError::from)?;
        let system = self.system(model, setup, dofs, nodal, t, dt);
        let solution = profile.time(Stage::Newton, || {
            newton::solve(
                &system,
                &mut self.tangent,
                nonlocal.as_mut(),
                &mut self.usage,
                profile,
                &mut self.newton_buffers,
            )
        })?;
        let grid = ConvergedGrid::new(&system, solution);
        self.last_residuals = (grid.history.clone(), grid.reference);
        let motion = grid.motion(dt, self.newmark);
        profile.time(Stage::G2P, || {
            g2p(&mut model.particles, &setup.shapes, &motion)
        });
        let converged = profile.time(Stage::Stresses, || {
            converged_stresses(model, setup, &grid.trial, nonlocal.as_mut(), profile)
        })?;
        let removed = profile.time(Stage::Commit, || {
            let nodal = NodalResults {
                reaction: &grid.reaction,
                increment: &grid.du,
                contact_motion: &grid.du,
                gravity: model.scene.loads.gravity_at(t + dt),
                end_time: t + dt,
                nonzero_at: None,
                // the points keep the velocity P2G zeroes (boundary_work B2)
                boundary_work: 0.0,
            };
            commit(model, setup, &grid.trial, converged, nodal)
        })?;
        report.removed_points.extend(removed);
        model.time = t + dt;
        self.newton_buffers.recycle(grid.trial);
        Ok(grid.iterations)
    }

    /// The nonlinear system of a (sub-)step.
    fn system<'a>(
        &self,
        model: &'a Model,
        setup: &'a StepSetup,
        dofs: DofMap,
        nodal: NodalKinematics,
        t: f64,
        dt: f64,
    ) -> StepSystem<'a> {
        StepSystem {
            model,
            setup,
            dofs,
            nodal,
            t,
            dt,
            newmark: self.newmark,
            background_block: self.background_block,
        }
    }

    /// P2G: nodal mass, v_n and a_n (dynamic only, in one pass; Dirichlet
    /// dofs neither move nor accelerate; the mass counted in `profile`) and
    /// the external force at `t1` (DESIGN D10).
    fn map_to_grid(
        &mut self,
        model: &Model,
        setup: &StepSetup,
        t1: f64,
        profile: &Profile,
    ) -> NodalKinematics {
        if self.newmark.is_none() {
            return NodalKinematics {
                mass: Vec::new(),
                velocity: Vec::new(),
                acceleration: Vec::new(),
                external: external_force(model, setup, t1),
            };
        }
        let mut nodal = nodal_kinematics(model, setup, t1, &mut self.p2g);
        profile.count(Work::MassMatrix, 1);
        for (d, c) in model.constraints.dof.iter().enumerate() {
            if *c == DofConstraint::Fixed {
                nodal.velocity[d / 2][d % 2] = 0.0;
                nodal.acceleration[d / 2][d % 2] = 0.0;
            }
        }
        nodal
    }

    /// The next step's linearisation at a given free-dof displacement increment
    /// (verification access, e.g. finite-difference checks of the tangent):
    /// the residual R = f_ext + f_pen − f_int − M a at the free dofs and the
    /// assembled tangent (DESIGN D16–D17, incl. the \[D19\] term), without
    /// changing the model. `free_increment` has one entry per unknown (see
    /// [`Self::unknowns`]).
    pub fn linearize(
        &mut self,
        model: &Model,
        free_increment: &[f64],
    ) -> Result<(Vec<f64>, SparseMatrix), StepError> {
        let (t, dt) = (model.time, self.dt);
        let profile = Profile::default();
        let (setup, dofs) = step_setup(model)?;
        if free_increment.len() != dofs.n_free {
            return Err(StepError::WrongLength {
                what: "linearize",
                given: free_increment.len(),
                expected: dofs.n_free,
            });
        }
        let nodal = self.map_to_grid(model, &setup, t + dt, &profile);
        let system = self.system(model, &setup, dofs, nodal, t, dt);
        let du = system.initial_increment(free_increment);
        let mut trial = TrialStresses::default();
        let res = system
            .evaluate(&du, None, &mut trial, &profile)
            .map_err(|e| e.into_step_error(0))?;
        self.tangent.begin_step();
        let matrix = self.tangent.assemble(&system, &trial, &profile)?;
        Ok((gather_free(&system.dofs, &res.residual), matrix))
    }

    /// Number of unknowns of the next step.
    pub fn unknowns(model: &Model) -> Result<usize, StepError> {
        Ok(step_setup(model)?.1.n_free)
    }
}

/// A converged (sub-)step's nodal solution, for the G2P and commit stages.
struct ConvergedGrid {
    /// Δu per grid node.
    du: Vec<[f64; 2]>,
    /// a_{n+1} per grid node (dynamic runs).
    acceleration: Option<Vec<[f64; 2]>>,
    /// Support reactions −R per grid node.
    reaction: Vec<[f64; 2]>,
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
    fn new(system: &StepSystem, solution: Solution) -> Self {
        let Solution {
            du,
            trial,
            residual,
            iterations,
            history,
        } = solution;
        Self {
            acceleration: system
                .newmark
                .map(|newmark| system.nodal_acceleration(&newmark, &du)),
            reaction: residual.residual.iter().map(|r| [-r[0], -r[1]]).collect(),
            reference: residual.reference,
            du,
            trial,
            iterations,
            history,
        }
    }

    /// G2P (DESIGN §3): x_p += Σ N Δu_i; dynamic: a_p = Σ N a_i, Newmark v_p.
    fn motion(&self, dt: f64, newmark: Option<Newmark>) -> GridMotion<'_> {
        let rule = newmark.map(|n| VelocityUpdate::Newmark { gamma: n.gamma });
        GridMotion {
            dt,
            displacement: &self.du,
            scale: 1.0,
            acceleration: self.acceleration.as_deref().zip(rule),
        }
    }
}

/// The shared step setup and the numbering of the unknowns.
fn step_setup(model: &Model) -> Result<(StepSetup, DofMap), StepError> {
    let mut setup = StepSetup::default();
    let dofs = refresh_setup(model, &mut setup)?;
    Ok((setup, dofs))
}

/// [`step_setup`] into `setup` (reusing its arrays); returns the numbering
/// of the unknowns.
fn refresh_setup(model: &Model, setup: &mut StepSetup) -> Result<DofMap, StepError> {
    setup.refresh(model)?;
    Ok(DofMap::new(&setup.bins, &model.constraints))
}
