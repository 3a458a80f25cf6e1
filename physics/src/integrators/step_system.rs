//! The nonlinear system of one implicit (sub-)step, R(Δu) = 0 (theory
//! D16): the Newmark family that discretises the inertia ([`Newmark`]), the
//! start-of-step nodal quantities ([`NodalKinematics`]), the system itself
//! ([`StepSystem`]) with the stress update and residual it evaluates at an
//! increment ([`Residual`]), and why an evaluation fails ([`NewtonError`]).
//! [`super::newton`] solves it; [`super::tangent`] linearises it.

use std::sync::Mutex;

use mpm_solvers::SolverError;
use rayon::prelude::*;

use super::path::PathConstraint;
use super::{
    evaluate_stresses, evaluate_stresses_without_tangent, NonlocalStep, StepSetup, TrialStresses,
    POINTS_PER_TASK,
};
use crate::bc::{DofConstraint, TravelDerivatives};
use crate::constitutive::ConstitutiveError;
use crate::dofs::{gather_free_into, DofMap};
use crate::error::{DofPlace, LargestResidual, NewtonFailure, StepError};
use crate::friction::ContactState;
use crate::grid::Grid;
use crate::model::Model;
use crate::profile::{Profile, Stage};
use crate::scene::{PredictorChoice, SolverSpec};
use crate::transfer::{self, NodalField, NONE};

/// Parameters of the Newmark family (paper eq. 2 uses γ = ½, β = ¼), including
/// the generalised-α scheme (theory "Generalised-α"): the step's balance
/// M ā + f_int(n+1) = f_ext(n+1) with the inertial acceleration
/// ā = [(1 − α_m) a(n+1) + α_m a(n) − α_f q(n)] / (1 − α_f), where
/// q(n) = M⁻¹(f_ext − f_int) at t_n is carried by the points
/// ([`crate::particles::Particles::force_per_mass`]). Newmark is α_m = α_f = 0.
#[derive(Clone, Copy, Debug)]
pub struct Newmark {
    /// γ: weight of a_{n+1} in the velocity update.
    pub gamma: f64,
    /// β: weight of a_{n+1} in the displacement update.
    pub beta: f64,
    /// α_m: weight of a_n in the inertia of the balance (0 for Newmark).
    pub alpha_m: f64,
    /// α_f: weight of the forces at t_n in the balance (0 for Newmark).
    pub alpha_f: f64,
}

impl Newmark {
    /// γ from the scene and β = (γ + ½)²/4 (unconditionally stable; γ = ½ is
    /// the trapezoidal rule of paper eq. 2, γ > ½ damps the highest frequencies).
    pub fn with_gamma(gamma: f64) -> Self {
        Self {
            gamma,
            beta: 0.25 * (gamma + 0.5) * (gamma + 0.5),
            alpha_m: 0.0,
            alpha_f: 0.0,
        }
    }

    /// Chung and Hulbert's generalised-α with spectral radius `rho_infinity`
    /// at infinite frequency (theory eq. GA2): α_m = (2ρ∞ − 1)/(ρ∞ + 1),
    /// α_f = ρ∞/(ρ∞ + 1), γ = ½ − α_m + α_f, β = ¼ (1 − α_m + α_f)².
    /// Second order for every ρ∞; ρ∞ = 1 is the trapezoidal rule.
    pub fn generalised_alpha(rho_infinity: f64) -> Self {
        let alpha_m = (2.0 * rho_infinity - 1.0) / (rho_infinity + 1.0);
        let alpha_f = rho_infinity / (rho_infinity + 1.0);
        let gamma = 0.5 - alpha_m + alpha_f;
        Self {
            gamma,
            beta: 0.25 * (gamma + 0.5) * (gamma + 0.5),
            alpha_m,
            alpha_f,
        }
    }

    /// The scheme of `[solver]`: generalised-α when `rho_infinity` is set,
    /// else Newmark with `newmark_gamma`.
    pub fn from_solver(solver: &SolverSpec) -> Self {
        match solver.rho_infinity {
            Some(rho) => Self::generalised_alpha(rho),
            None => Self::with_gamma(solver.gamma()),
        }
    }

    /// Whether the balance weights the start of the step (α_m or α_f ≠ 0), so
    /// that the points must carry q = M⁻¹(f_ext − f_int).
    pub fn is_generalised_alpha(&self) -> bool {
        self.alpha_m != 0.0 || self.alpha_f != 0.0
    }

    /// ∂ā/∂a(n+1) = (1 − α_m)/(1 − α_f): the factor of M/(βΔt²) in the tangent.
    pub fn inertia_factor(&self) -> f64 {
        (1.0 - self.alpha_m) / (1.0 - self.alpha_f)
    }

    /// The inertial acceleration ā of the balance from a(n+1), a(n) and q(n).
    #[inline]
    pub fn inertial_acceleration(&self, a_next: f64, a_start: f64, q_start: f64) -> f64 {
        if !self.is_generalised_alpha() {
            return a_next;
        }
        ((1.0 - self.alpha_m) * a_next + self.alpha_m * a_start - self.alpha_f * q_start)
            / (1.0 - self.alpha_f)
    }
}

/// Start-of-step nodal quantities of an implicit (sub-)step (P2G).
#[derive(Default)]
pub struct NodalKinematics {
    /// Lumped nodal mass (dynamic only, else empty).
    pub mass: Vec<f64>,
    /// Nodal velocity v_n (dynamic only).
    pub velocity: Vec<[f64; 2]>,
    /// Nodal acceleration a_n (dynamic only).
    pub acceleration: Vec<[f64; 2]>,
    /// Nodal q_n = M⁻¹(f_ext − f_int) at t_n, mapped from the points
    /// (generalised-α only, else empty).
    pub force_per_mass: Vec<[f64; 2]>,
    /// External force at t_{n+1} (body force + traction), per grid node.
    pub external: Vec<[f64; 2]>,
    /// The mapped velocity that the fixed dofs zeroed, per grid node (zero
    /// elsewhere; empty when nothing was zeroed): G2P takes it from the
    /// points, as the explicit integrator does ([`super::boundary_work`] B1).
    pub removed_velocity: Vec<[f64; 2]>,
    /// Σ ½ m v² of `removed_velocity`, kJ/m (B1).
    pub removed_energy: f64,
}

/// `clone_from` refills every array in place (a derived one would allocate
/// anew): the implicit step copies the mapped kinematics into its system
/// each contact pass.
impl Clone for NodalKinematics {
    fn clone(&self) -> Self {
        let mut copy = Self::default();
        copy.clone_from(self);
        copy
    }

    fn clone_from(&mut self, source: &Self) {
        self.mass.clone_from(&source.mass);
        self.velocity.clone_from(&source.velocity);
        self.acceleration.clone_from(&source.acceleration);
        self.force_per_mass.clone_from(&source.force_per_mass);
        self.external.clone_from(&source.external);
        self.removed_velocity.clone_from(&source.removed_velocity);
        self.removed_energy = source.removed_energy;
    }
}

/// The nonlinear system of one (sub-)step from `t` to `t + dt`.
pub struct StepSystem<'a> {
    /// The model at the start of the step.
    pub model: &'a Model,
    /// Shape functions and bins at the start-of-step positions.
    pub setup: &'a StepSetup,
    /// Numbering of the unknowns.
    pub dofs: DofMap,
    /// P2G of the step.
    pub nodal: NodalKinematics,
    /// Start time, s.
    pub t: f64,
    /// Time step, s.
    pub dt: f64,
    /// Newmark parameters; `None` in quasi-static runs (no inertia).
    pub newmark: Option<Newmark>,
    /// ε_bg · K_cell^el (theory D19): tangent of every active cell, and
    /// residual term of the GIMP-reached cells.
    pub background_block: [f64; 64],
    /// Which frictional nodes are held in stick for the rest of the solve
    /// (FR6).
    pub held_sticks: Mutex<HeldSticks>,
    /// Path following (theory §3.7): the constraint that makes the anchors'
    /// step Δτ an unknown; `None`: the anchors move over `dt`.
    pub path: Option<PathConstraint>,
}

/// The frictional nodes held in stick (FR6) and the states of the last
/// iterate.
#[derive(Default)]
pub struct HeldSticks {
    /// Per frictional node: held in stick; empty until the holding starts.
    held: Vec<bool>,
    /// The Coulomb states of the last iterate.
    last: Vec<ContactState>,
}

/// Newton iterations after which a frictional node found in stick stays in
/// stick for the rest of the solve (theory eq. FR6). A node whose trial force
/// lies at the Coulomb bound can flip between stick and slip from iteration
/// to iteration (a cycle of the residual far above the tolerance: the
/// full-size friction cut at h = 0.1 m stopped at t = 0.23 s after four to
/// six step halvings). Holding the states found at one iteration, slips
/// included, let a held slip drive a node against its motion (a node of
/// the cut's base moved 40 m in one step, and the edge created 5,000 kJ/m).
pub const CONTACT_HOLD_ITERATION: usize = 8;

/// Residual-side quantities of one Newton iterate.
#[derive(Default)]
pub struct Residual {
    /// R = f_ext + f_pen − f_int − M a, per grid node.
    pub residual: Vec<[f64; 2]>,
    /// ‖R‖ over free dofs.
    pub norm: f64,
    /// Reference force of theory D18.
    pub reference: f64,
    /// Path following: the constraint's value g at the iterate (PF2; `None`
    /// without path following).
    pub constraint: Option<f64>,
}

/// Node-sized buffers of the residual evaluation, reused by every
/// evaluation of every Newton solve (no allocation once they have grown).
#[derive(Default)]
pub struct ResidualScratch {
    /// f_int per grid node.
    internal: NodalField<[f64; 2]>,
    /// Patch sums of the internal force (`transfer::internal_force_into`).
    cell_sums: Vec<[f64; 2]>,
    /// f_pen per grid node.
    penalty: Vec<[f64; 2]>,
}

/// Why an attempt at a (sub-)step failed.
#[derive(Debug)]
pub enum NewtonError {
    /// Newton failed; retried with a halved step.
    Failed {
        /// Why.
        cause: NewtonFailure,
        /// ‖R‖ per iteration of the attempt, kN/m.
        history: Vec<f64>,
        /// Where the last iterate's residual is largest (set by `located`).
        largest: Option<Box<LargestResidual>>,
    },
    /// The stress update failed at a point; retried with a halved step.
    Constitutive(usize, ConstitutiveError),
    /// The linear solver failed; retried with a halved step.
    Solver(SolverError),
    /// Not retried.
    Fatal(StepError),
}

impl NewtonError {
    pub(super) fn failed(cause: NewtonFailure, history: &[f64]) -> Self {
        NewtonError::Failed {
            cause,
            history: history.to_vec(),
            largest: None,
        }
    }

    /// A failure of Newton's iteration itself (divergence, iteration limit)
    /// with the place of the largest free residual component of its last
    /// iterate, `free_residual` (indexed by `dofs`); other errors unchanged.
    pub(super) fn located(self, dofs: &DofMap, grid: &Grid, free_residual: &[f64]) -> Self {
        match self {
            NewtonError::Failed {
                cause: cause @ (NewtonFailure::Diverged | NewtonFailure::IterationLimit { .. }),
                history,
                largest: None,
            } => NewtonError::Failed {
                cause,
                history,
                largest: largest_residual(dofs, grid, free_residual).map(Box::new),
            },
            other => other,
        }
    }

    /// Whether halving the step may help.
    pub fn retry(&self) -> bool {
        !matches!(self, NewtonError::Fatal(_))
    }

    /// The step error after `halvings` halvings.
    pub fn into_step_error(self, halvings: usize) -> StepError {
        match self {
            NewtonError::Failed {
                cause,
                history,
                largest,
            } => StepError::NewtonFailed {
                halvings,
                cause,
                history,
                largest,
            },
            NewtonError::Constitutive(particle, source) => {
                halved(StepError::Constitutive { particle, source }, halvings)
            }
            NewtonError::Solver(e) => halved(StepError::Solver(e), halvings),
            NewtonError::Fatal(e) => e,
        }
    }
}

/// `error` as the last attempt's failure after `halvings` halvings (itself
/// where none was tried).
fn halved(error: StepError, halvings: usize) -> StepError {
    match halvings {
        0 => error,
        _ => StepError::Halved {
            halvings,
            source: Box::new(error),
        },
    }
}

impl From<StepError> for NewtonError {
    fn from(e: StepError) -> Self {
        match e {
            StepError::Solver(e) => NewtonError::Solver(e),
            StepError::Constitutive { particle, source } => {
                NewtonError::Constitutive(particle, source)
            }
            e => NewtonError::Fatal(e),
        }
    }
}

impl StepSystem<'_> {
    /// Δu of the step: prescribed nodal increments u(t + dt) − u(t) at prescribed
    /// dofs of active nodes, `free` at the free dofs, zero elsewhere.
    pub fn initial_increment(&self, free: &[f64]) -> Vec<[f64; 2]> {
        let (model, t, dt) = (self.model, self.t, self.dt);
        let mut du = vec![[0.0; 2]; model.grid.node_count()];
        for (d, c) in model.constraints.dof.iter().enumerate() {
            if matches!(c, DofConstraint::Prescribed { .. }) && self.setup.bins.node_active[d / 2] {
                du[d / 2][d % 2] = model.constraints.prescribed_value(&model.grid, d, t + dt)
                    - model.constraints.prescribed_value(&model.grid, d, t);
            }
            let index = self.dofs.index[d];
            if index != NONE {
                du[d / 2][d % 2] = free[index as usize];
            }
        }
        du
    }

    /// The free dofs' starting increment of Newton (`solver.predictor`): in a dynamic run
    /// by default the nodal motion at the start of the step carried on,
    /// Δu⁰ = Δt v_n + ½ Δt² a_n (a Taylor step, i.e. a_{n+1} = a_n); zero in a
    /// quasi-static run or with `predictor = "zero"` (theory D17).
    pub fn predictor(&self) -> Vec<f64> {
        let mut free = vec![0.0; self.dofs.n_free];
        if self.newmark.is_none() || self.model.settings.solver.predictor == PredictorChoice::Zero {
            return free;
        }
        let (dt, nodal) = (self.dt, &self.nodal);
        for (d, &index) in self.dofs.index.iter().enumerate() {
            if index != NONE {
                let (node, c) = (d / 2, d % 2);
                free[index as usize] =
                    dt * nodal.velocity[node][c] + 0.5 * dt * dt * nodal.acceleration[node][c];
            }
        }
        free
    }

    /// Stress update and residual at the increment `du` (one Newton evaluation).
    pub fn evaluate(
        &self,
        du: &[[f64; 2]],
        nonlocal: Option<&NonlocalStep>,
        trial: &mut TrialStresses,
        profile: &Profile,
    ) -> Result<Residual, NewtonError> {
        let mut res = Residual::default();
        let mut scratch = ResidualScratch::default();
        let at = (du, self.dt);
        self.evaluate_into(at, nonlocal, trial, &mut scratch, &mut res, profile)?;
        Ok(res)
    }

    /// [`Self::evaluate`] into `res` at the increment `du` with the anchors
    /// moved over `travel` (`dt`, or the iterate's Δτ under path following),
    /// with the buffers of `scratch` (the Newton loop's form: no allocation
    /// once the buffers have grown).
    pub fn evaluate_into(
        &self,
        (du, travel): (&[[f64; 2]], f64),
        nonlocal: Option<&NonlocalStep>,
        trial: &mut TrialStresses,
        scratch: &mut ResidualScratch,
        res: &mut Residual,
        profile: &Profile,
    ) -> Result<(), NewtonError> {
        self.evaluate_with((du, travel), nonlocal, trial, (scratch, res), profile, true)
    }

    /// The stress update and the residual; with `tangents` false (a residual
    /// that no tangent is assembled from, e.g. the line search's reference at
    /// a new κ̄) the same stresses and residual, `trial.tangent` left empty and
    /// no sensitivity solves in the return mappings.
    pub(super) fn evaluate_with(
        &self,
        (du, travel): (&[[f64; 2]], f64),
        nonlocal: Option<&NonlocalStep>,
        trial: &mut TrialStresses,
        (scratch, res): (&mut ResidualScratch, &mut Residual),
        profile: &Profile,
        tangents: bool,
    ) -> Result<(), NewtonError> {
        let model = self.model;
        // compliances for the spin term of the tangent (`stiffness::add_spin_stiffness`),
        // included when the tangent is unsymmetric anyway (LU); symmetric
        // (Cholesky) scenes omit this unsymmetric geometric term and converge
        // linearly under large rotations.
        let spin_term = !model.symmetric_tangent();
        let strength = nonlocal.map(|n| n.strength());
        profile
            .time(Stage::StressUpdate, || {
                let tally = if tangents {
                    evaluate_stresses(model, self.setup, du, strength, spin_term, trial)
                } else {
                    let shapes = &self.setup.shapes;
                    evaluate_stresses_without_tangent(
                        model, self.setup, shapes, du, strength, trial,
                    )
                };
                tally.counted(profile)
            })
            .map_err(|(p, e)| NewtonError::Constitutive(p, e))?;
        let mut friction = std::mem::take(&mut trial.friction_stiffness);
        self.residual(trial, (du, travel), scratch, res, &mut friction, profile);
        trial.friction_stiffness = friction;
        // path following: the norm is that of the bordered system's
        // residual [R; g F_ref] (PF4), so that the line search weighs the
        // constraint too (from a converged start R ≈ 0, and every step along
        // the path would otherwise count as a growth of ‖R‖)
        res.constraint = self
            .path
            .map(|c| c.value(travel, self.driven_load(du, travel)));
        if let Some(g) = res.constraint {
            res.norm = res.norm.hypot(g * res.reference);
        }
        Ok(())
    }

    /// Newmark acceleration at grid dof (`node`, `c`):
    /// a_{n+1} = (Δu − Δt v_n − Δt²(½ − β) a_n) / (β Δt²); for the trapezoidal
    /// rule (β = ¼) this is D15, (4/Δt²) Δu − (4/Δt) v_n − a_n.
    pub fn acceleration(&self, newmark: &Newmark, du: &[[f64; 2]], node: usize, c: usize) -> f64 {
        let (beta, dt, nodal) = (newmark.beta, self.dt, &self.nodal);
        (du[node][c]
            - dt * nodal.velocity[node][c]
            - dt * dt * (0.5 - beta) * nodal.acceleration[node][c])
            / (beta * dt * dt)
    }

    /// The balance's inertial acceleration ā at grid dof (`node`, `c`)
    /// ([`Newmark::inertial_acceleration`]; a_{n+1} for Newmark).
    pub fn inertial_acceleration(
        &self,
        newmark: &Newmark,
        du: &[[f64; 2]],
        node: usize,
        c: usize,
    ) -> f64 {
        let a_next = self.acceleration(newmark, du, node, c);
        if !newmark.is_generalised_alpha() {
            return a_next;
        }
        let nodal = &self.nodal;
        newmark.inertial_acceleration(
            a_next,
            nodal.acceleration[node][c],
            nodal.force_per_mass[node][c],
        )
    }

    /// ā at every active node (zero elsewhere) into `field`: at convergence
    /// the nodal M⁻¹(f_ext − f_int) of t_{n+1}, which G2P carries to the
    /// points (generalised-α).
    pub fn nodal_inertial_acceleration_into(
        &self,
        newmark: &Newmark,
        du: &[[f64; 2]],
        field: &mut Vec<[f64; 2]>,
    ) {
        self.at_active_nodes(field, |node, c| {
            self.inertial_acceleration(newmark, du, node, c)
        })
    }

    /// a_{n+1} at every active node (zero elsewhere) into `field`, for the
    /// G2P stage.
    pub fn nodal_acceleration_into(
        &self,
        newmark: &Newmark,
        du: &[[f64; 2]],
        field: &mut Vec<[f64; 2]>,
    ) {
        self.at_active_nodes(field, |node, c| self.acceleration(newmark, du, node, c))
    }

    /// The nodal field `value(node, component)` at the active nodes, zero
    /// elsewhere, refilled into `field`.
    fn at_active_nodes(&self, field: &mut Vec<[f64; 2]>, value: impl Fn(usize, usize) -> f64) {
        field.clear();
        field.resize(self.model.grid.node_count(), [0.0; 2]);
        for (node, at_node) in field.iter_mut().enumerate() {
            if self.setup.bins.node_active[node] {
                *at_node = [value(node, 0), value(node, 1)];
            }
        }
    }

    /// Residual R = f_ext + f_pen − f_int − M a (theory D16), the anchors
    /// moved over `travel`, with the frictional edges' tangential forces
    /// (their stiffnesses into `friction`), and its norms (D18), into `res`.
    fn residual(
        &self,
        trial: &TrialStresses,
        (du, travel): (&[[f64; 2]], f64),
        scratch: &mut ResidualScratch,
        res: &mut Residual,
        friction: &mut Vec<f64>,
        profile: &Profile,
    ) {
        let model = self.model;
        let (grid, p, bins) = (&model.grid, &model.state.particles, &self.setup.bins);
        let ResidualScratch {
            internal,
            cell_sums,
            penalty,
        } = scratch;
        profile.time(Stage::P2G, || {
            transfer::internal_force_into(
                grid,
                bins,
                &self.setup.shapes,
                &p.volume,
                &model.force_stresses(bins, &trial.stress),
                cell_sums,
                internal,
            )
        });
        // the nodes of the reached cells are active: written by the scatter
        let internal_values = internal.values_mut();
        crate::stiffness::add_reached_cells_force(
            grid,
            bins,
            &self.background_block,
            du,
            internal_values,
        );
        zeroed(penalty, grid.node_count());
        model.state.driven.add_forces(
            p,
            &self.setup.driven_shapes,
            bins,
            du,
            self.t + travel,
            penalty,
        );
        let residual = &mut res.residual;
        zeroed(residual, grid.node_count());
        let (mut norm2, mut ext2, mut int2, mut inertia2) = (0.0, 0.0, 0.0, 0.0);
        for &node in &bins.active_nodes {
            let node = node as usize;
            for c in 0..2 {
                let inertia = match &self.newmark {
                    Some(newmark) => {
                        self.nodal.mass[node] * self.inertial_acceleration(newmark, du, node, c)
                    }
                    None => 0.0,
                };
                let ext = self.nodal.external[node][c] + penalty[node][c];
                let r = ext - internal[node][c] - inertia;
                residual[node][c] = r;
                ext2 += ext * ext;
                int2 += internal[node][c] * internal[node][c];
                inertia2 += inertia * inertia;
                if self.dofs.index[2 * node + c] != NONE {
                    norm2 += r * r;
                }
            }
        }
        norm2 += self.add_friction(du, residual, friction);
        let floor = 1e-6 * model.max_youngs_modulus() * grid.cell_size;
        res.reference = ext2.sqrt().max(int2.sqrt()).max(inertia2.sqrt()).max(floor);
        res.norm = norm2.sqrt();
    }

    /// The tangential forces of the frictional edges (theory eq. FR1) added
    /// into `residual` at the free tangential dofs of active nodes, their
    /// stiffnesses into `stiffness`; returns the change of ‖R‖² at those dofs.
    /// The normal force is the edge's reaction of the last step (lagged by
    /// one step: the bound μ N is then fixed within the step, and Newton
    /// meets only the stick–slip switch, as in a return mapping), each
    /// contact patch's net force shared by the filtered reactions (eq. FR4);
    /// the stick spring continues from the last step's friction force,
    /// `model.state.reaction` at the tangential dof (FR1).
    fn add_friction(
        &self,
        du: &[[f64; 2]],
        residual: &mut [[f64; 2]],
        stiffness: &mut Vec<f64>,
    ) -> f64 {
        stiffness.clear();
        stiffness.resize(self.model.friction.nodes.len(), 0.0);
        let mut change = 0.0;
        self.for_each_friction_force(du, |k, node, t, force, k_t, _| {
            let before = residual[node][t];
            residual[node][t] += force;
            change += residual[node][t] * residual[node][t] - before * before;
            stiffness[k] = k_t;
        });
        change
    }

    /// Adds the frictional edges' tangential forces T at `du` (FR1) to the
    /// support reactions `reaction` (−R, in which Newton balanced them):
    /// the edge's whole force on the soil, from which the next step's stick
    /// spring continues.
    /// An open node (FR7) carries none: its normal reaction is set to zero
    /// (the residual left there is no support force).
    pub fn add_friction_reactions(&self, du: &[[f64; 2]], reaction: &mut [[f64; 2]]) {
        self.for_each_friction_force(du, |_, node, t, force, _, _| reaction[node][t] += force);
        for contact in &self.model.friction.nodes {
            if self.dofs.is_free(2 * contact.node + contact.normal) {
                reaction[contact.node][contact.normal] = 0.0;
            }
        }
    }

    /// Hold in stick, for the rest of the solve, every frictional node that
    /// is in stick at `du` or whose slip changed direction since the last
    /// iterate (FR6; those held already stay held).
    pub(super) fn hold_sticks(&self, du: &[[f64; 2]]) {
        let mut guard = self.held_sticks.lock().unwrap_or_else(|e| e.into_inner());
        let n = self.model.friction.nodes.len();
        let HeldSticks { held, last } = &mut *guard;
        if held.is_empty() {
            held.resize(n, false);
        }
        let mut now = vec![ContactState::Stick; n];
        self.friction_forces_with(du, Some(held), |k, _, _, _, _, state| now[k] = state);
        for (k, state) in now.iter().enumerate() {
            let reversed = last.get(k).is_some_and(|before| before != state);
            if *state == ContactState::Stick || reversed {
                held[k] = true;
            }
        }
        *last = now;
    }

    /// The work the frictional edges take from the soil over the step `du`,
    /// −Σ T Δu_t ≥ 0 (kJ/m, theory eq. FR5): a part of the boundary work B of
    /// [`crate::energy`] (E1).
    pub fn friction_work(&self, du: &[[f64; 2]]) -> f64 {
        let mut work = 0.0;
        self.for_each_friction_force(du, |_, node, t, force, _, _| work -= force * du[node][t]);
        work
    }

    /// `apply(k, node, tangential component, T, dT/dΔu_t, state)` for every
    /// frictional node k with a free tangential dof at an active node (FR1,
    /// FR4, FR6).
    fn for_each_friction_force(
        &self,
        du: &[[f64; 2]],
        apply: impl FnMut(usize, usize, usize, f64, f64, ContactState),
    ) {
        let guard = self.held_sticks.lock().unwrap_or_else(|e| e.into_inner());
        let held = Some(&guard.held[..]).filter(|h| !h.is_empty());
        self.friction_forces_with(du, held, apply);
    }

    /// [`Self::for_each_friction_force`] with the nodes `held` in stick
    /// (none: every node by the Coulomb law at `du`).
    fn friction_forces_with(
        &self,
        du: &[[f64; 2]],
        held: Option<&[bool]>,
        mut apply: impl FnMut(usize, usize, usize, f64, f64, ContactState),
    ) {
        let edges = &self.model.friction;
        if edges.is_empty() {
            return;
        }
        let model = self.model;
        let mut normals = Vec::new();
        // the nodes in contact (active and closed, FR7) share the normal force
        let in_contact = |node: usize| {
            self.setup.bins.node_active[node]
                && edges
                    .at(node)
                    .is_some_and(|c| !self.dofs.is_free(2 * node + c.normal))
        };
        edges.patch_normals(
            in_contact,
            |c| model.state.reaction[c.node][c.normal] * c.inward,
            &mut normals,
        );
        for (k, contact) in edges.nodes.iter().enumerate() {
            let (node, t) = (contact.node, contact.tangent());
            // an open node (its normal dof released, FR7) has no friction
            if !self.setup.bins.node_active[node]
                || !self.dofs.is_free(2 * node + t)
                || self.dofs.is_free(2 * node + contact.normal)
            {
                continue;
            }
            let previous = model.state.reaction[node][t];
            let (force, k_t, state) = edges.tangential_force(
                contact,
                du[node][t],
                normals[k],
                previous,
                held.is_some_and(|sticks| sticks[k]),
            );
            apply(k, node, t, force, k_t, state);
        }
    }

    /// The free dofs' part of the model's last nodal increment times `factor`
    /// (path following's start, PF4).
    pub(super) fn scaled_last_increment(&self, factor: f64) -> Vec<f64> {
        let mut free = Vec::new();
        gather_free_into(&self.dofs, &self.model.state.last_increment, &mut free);
        free.iter_mut().for_each(|x| *x *= factor);
        free
    }

    /// The driven load F of the rigid bodies at the increment `du` with the
    /// anchors moved over `travel` (theory PF1), kN/m.
    pub fn driven_load(&self, du: &[[f64; 2]], travel: f64) -> f64 {
        let model = self.model;
        model.state.driven.load_along_motion(
            &model.state.particles,
            &self.setup.driven_shapes,
            &self.setup.bins,
            du,
            self.t + travel,
        )
    }

    /// ∂f_pen/∂τ and the derivatives of the driven load over the unknowns
    /// (theory PF3).
    pub(super) fn travel_derivatives(&self) -> TravelDerivatives {
        let setup = self.setup;
        self.model.state.driven.travel_derivatives(
            &setup.driven_shapes,
            &setup.bins,
            &self.dofs.index,
            self.dofs.n_free,
        )
    }

    /// theory §3 motion limit (dynamic): no point may move more than half a
    /// cell in one step.
    pub(super) fn check_motion(&self, du: &[[f64; 2]]) -> Result<(), NewtonFailure> {
        if self.newmark.is_none() {
            return Ok(());
        }
        // the first point of the largest motion (in parallel: the reduction
        // keeps the order of the points, so ties go to the lowest index)
        let first_larger = |a: (usize, f64), b: (usize, f64)| if b.1 > a.1 { b } else { a };
        let (particle, distance) = self
            .setup
            .shapes
            .par_iter()
            .with_min_len(POINTS_PER_TASK)
            .map(|s| {
                let u = transfer::interpolate(s, du);
                (u[0] * u[0] + u[1] * u[1]).sqrt()
            })
            .enumerate()
            .fold(|| (0, 0.0), first_larger)
            .reduce(|| (0, 0.0), first_larger);
        if distance > 0.5 * self.model.grid.cell_size {
            return Err(NewtonFailure::Motion {
                particle,
                position: self.model.state.particles.position[particle],
                distance,
            });
        }
        Ok(())
    }
}

/// The free dof of largest |R| (the first, in dof order, among equal ones)
/// and its node; `None` without free dofs.
fn largest_residual(dofs: &DofMap, grid: &Grid, free_residual: &[f64]) -> Option<LargestResidual> {
    let mut largest: Option<(usize, f64)> = None;
    for (d, &index) in dofs.index.iter().enumerate() {
        if index == NONE {
            continue;
        }
        let value = free_residual[index as usize];
        if largest.is_none_or(|(_, v)| value.abs() > v.abs()) {
            largest = Some((d, value));
        }
    }
    largest.map(|(d, value)| LargestResidual {
        value,
        place: dof_place(grid, d),
    })
}

/// Grid dof `d` (node d / 2, component d % 2) as a place.
fn dof_place(grid: &Grid, d: usize) -> DofPlace {
    DofPlace {
        component: d % 2,
        node: grid.node_position(d / 2),
    }
}

/// A singular tangent's error with the place its test failed most (the
/// unknown the solver names: a free dof's node and component, or under
/// path following the travel, unknown n) added to its detail; other errors
/// unchanged.
pub(super) fn singular_placed(e: StepError, dofs: &DofMap, grid: &Grid) -> StepError {
    let StepError::Solver(SolverError::Singular {
        factor,
        detail,
        unknown: Some(unknown),
    }) = e
    else {
        return e;
    };
    let place = match dofs.index.iter().position(|&i| i as usize == unknown) {
        Some(d) => Some(format!("most {}", dof_place(grid, d))),
        None => (unknown == dofs.n_free).then(|| "most in the travel (path following)".into()),
    };
    StepError::Solver(SolverError::Singular {
        factor,
        detail: match place {
            Some(place) => format!("{detail}, {place}"),
            None => detail,
        },
        unknown: Some(unknown),
    })
}

/// Clear `values` and fill it with `n` zeros (in place: no allocation once
/// it has grown).
fn zeroed(values: &mut Vec<[f64; 2]>, n: usize) {
    values.clear();
    values.resize(n, [0.0; 2]);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::constitutive::ConstitutiveError;
    use crate::error_id::{ErrorId, Identified};

    /// 2 × 1 cells of 0.5 m from (1, 2) (nodes 0–2 on y = 2, 3–5 on
    /// y = 2.5) with node 1's x (dof 2) and node 4's y (dof 9) held, the
    /// other dofs free in dof order (10 free).
    fn two_cells() -> (Grid, DofMap) {
        let grid = Grid::bilinear([1.0, 2.0], 0.5, [2, 1]);
        let held = [2, 9];
        let mut index = vec![NONE; 12];
        let mut n_free = 0;
        for (d, i) in index.iter_mut().enumerate() {
            if !held.contains(&d) {
                *i = n_free as u32;
                n_free += 1;
            }
        }
        (grid, DofMap { index, n_free })
    }

    /// The located failure names the free dof of largest |R| (held dofs have
    /// no free index and are skipped) with its node's position and component,
    /// and gives the residual history to four digits.
    #[test]
    fn the_largest_free_residual_is_located_at_its_node() {
        let (grid, dofs) = two_cells();
        // R per free dof; −7 (free index 6: dof 7, node 3, y) is the largest
        let free_residual = [1.0, -2.0, 3.0, 0.5, 4.0, 6.0, -7.0, 2.0, 1.0, 0.0];
        let largest = largest_residual(&dofs, &grid, &free_residual).expect("free dofs");
        assert_eq!(largest.value, -7.0);
        assert_eq!(largest.place.component, 1);
        assert_eq!(largest.place.node, [1.0, 2.5]);
        let failure = NewtonError::failed(NewtonFailure::Diverged, &[1.0, 2.0])
            .located(&dofs, &grid, &free_residual)
            .into_step_error(3);
        let message = failure.to_string();
        assert!(
            message.contains("-7.000e0 kN/m in y at the node (1.0000, 2.5000) m"),
            "{message}"
        );
        assert!(
            message.ends_with("residual history [1.000e0, 2.000e0] kN/m"),
            "{message}"
        );
        // a motion failure keeps its own place (the point), not a residual's
        let motion = NewtonFailure::Motion {
            particle: 4,
            position: [1.2, 2.1],
            distance: 0.3,
        };
        let failure = NewtonError::failed(motion, &[1.0]).located(&dofs, &grid, &free_residual);
        assert!(matches!(failure, NewtonError::Failed { largest: None, .. }));
    }

    /// A linear solve or stress update that failed at the last halving says
    /// how many halvings were tried and keeps its own identifier; without a
    /// halving its message is unchanged.
    #[test]
    fn a_failure_after_halvings_says_how_many() {
        let singular = || {
            NewtonError::Solver(SolverError::Singular {
                factor: mpm_solvers::FactorKind::Lu,
                detail: "probe".into(),
                unknown: None,
            })
        };
        let alone = singular().into_step_error(0);
        let halved = singular().into_step_error(8);
        assert!(halved.to_string().starts_with(&alone.to_string()));
        assert!(halved.to_string().ends_with("(after 8 step halvings)"));
        assert_eq!(halved.error_id(), alone.error_id());
        let stress = NewtonError::Constitutive(3, ConstitutiveError::NonFinite("σ".into()));
        let stress = stress.into_step_error(2);
        assert!(
            stress.to_string().ends_with("(after 2 step halvings)"),
            "{stress}"
        );
        assert_eq!(stress.error_id(), ErrorId::RunStressUpdate);
    }

    /// A singular tangent's unknown is named as its node and component
    /// (free index 6: dof 7, node 3, y), the bordered system's last unknown
    /// as the travel; a singular matrix without an unknown is unchanged.
    #[test]
    fn a_singular_tangent_names_its_node() {
        let (grid, dofs) = two_cells();
        let singular = |unknown| {
            StepError::Solver(SolverError::Singular {
                factor: mpm_solvers::FactorKind::Lu,
                detail: "probe".into(),
                unknown,
            })
        };
        let placed = |unknown| singular_placed(singular(unknown), &dofs, &grid).to_string();
        assert!(
            placed(Some(6)).ends_with("probe, most in y at the node (1.0000, 2.5000) m"),
            "{}",
            placed(Some(6))
        );
        assert!(placed(Some(10)).ends_with("probe, most in the travel (path following)"));
        assert!(placed(None).ends_with("probe"));
    }
}
