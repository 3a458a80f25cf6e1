//! Time integrators. Each is a type that owns its caches and advances the
//! [`Model`] by one step with `step(&mut self, model, profile)`, as a short
//! list of named, timed stages in the order of paper Fig. 1:
//!
//! | stage | implicit ([`ImplicitIntegrator`]) | explicit ([`ExplicitIntegrator`]) |
//! |---|---|---|
//! | setup | [`StepSetup`] | [`StepSetup`] |
//! | P2G | mass, v_n, a_n, f_ext | mass, momentum, forces |
//! | solve | [`newton`] on Δu (stress update, tangent, factorisation) | [`time_step`], nodal momentum update |
//! | G2P | [`g2p`] (Newmark) | [`g2p`] (forward) |
//! | remap | — | MUSL re-map, stress update |
//! | stresses | [`converged_stresses`]: energies, κ̄(n+1), double mapping | the same |
//! | commit | [`commit`]: F, V, σ, boundary points, lost points | the same |
//!
//! Both use the same transfer kernels ([`crate::transfer`]), the same
//! constitutive interface and the same boundary-condition devices.

pub mod boundary_work;
pub mod commit;
pub mod converged_stresses;
pub mod explicit;
mod export;
pub mod g2p;
pub mod implicit;
pub mod newton;
pub mod p2g;
pub mod path;
mod regularisation;
pub mod setup;
pub mod step_control;
pub mod step_system;
mod stress_update;
pub mod tangent;
pub mod time_step;

pub use explicit::ExplicitIntegrator;
pub use implicit::ImplicitIntegrator;
pub(crate) use regularisation::NonlocalStep;
pub use setup::StepSetup;
pub(crate) use stress_update::{
    evaluate_stresses, evaluate_stresses_without_tangent, TrialStresses,
};

use mpm_solvers::SolverStats;

use crate::error::{StepError, TimeStepLimit};
use crate::model::{Model, PointRemap};
use crate::profile::Profile;
use crate::scene::{AnalysisKind, SceneError};

/// Points handed to one rayon task at least, in the passes over points.
const POINTS_PER_TASK: usize = 256;

/// What one completed step did.
#[derive(Clone, Debug, Default)]
pub struct StepReport {
    /// Step number (1-based) after the step.
    pub step: usize,
    /// Time after the step, s.
    pub time: f64,
    /// Time step used, s.
    pub dt: f64,
    /// Newton iterations (implicit; summed over sub-steps), 0 for explicit.
    pub iterations: usize,
    /// Number of sub-steps the step needed (1 without halving).
    pub substeps: usize,
    /// Adaptive steps: the relative local error estimate of the step taken.
    pub error_estimate: Option<f64>,
    /// Adaptive steps: attempts redone because their error was too large.
    pub rejected_error: usize,
    /// Adaptive steps: attempts redone with half the step after Newton failed.
    pub rejected_newton: usize,
    /// Index remaps of the points removed in the step, in order (each maps
    /// the indices left by the previous one).
    pub removed_points: Vec<PointRemap>,
}

/// Counts of what the integrator did (written to `run.json`).
#[derive(Clone, Debug, Default, serde::Serialize, serde::Deserialize)]
pub struct SolverUsage {
    /// Factorisations done with sparse Cholesky.
    pub cholesky: usize,
    /// Factorisations done with sparse LU.
    pub lu: usize,
    /// Systems solved by preconditioned conjugate gradients.
    pub pcg: usize,
    /// Systems solved by sprs_ldl's LDLᵀ.
    pub ldl: usize,
    /// Largest system size, unknowns.
    pub max_unknowns: usize,
    /// Total Newton iterations.
    pub newton_iterations: usize,
    /// Step halvings.
    pub halvings: usize,
    /// Implicit steps solved again because a frictional node opened or
    /// closed (theory eq. FR7): one per change of the contact set.
    pub contact_resolves: usize,
    /// Steps accepted on the force criterion alone because the residual had
    /// stagnated (the energy criterion of D18 cannot be met by iterating).
    pub stagnated_steps: usize,
    /// Explicit runs: smallest and largest time step taken, s (before the last
    /// step is shortened to end at `end_time`).
    pub explicit_time_step: Option<(f64, f64)>,
    /// Explicit runs: what limited the stable time step at the last step.
    pub time_step_limited_by: Option<TimeStepLimit>,
    /// Implicit runs with adaptive steps: what the step control did.
    pub step_control: Option<step_control::StepControlRecord>,
    /// Path-following runs: where the path stands and what it did.
    pub path: Option<path::PathRecord>,
    /// Fixed steps with `solver.remember_halvings`: the halving depth the
    /// next step starts at (2^depth equal substeps).
    pub start_depth: usize,
    /// Fixed steps with `solver.remember_halvings`: the pieces that steps
    /// were split into from their start, at a remembered depth (each may
    /// still be halved).
    pub remembered_substeps: usize,
}

/// The integrator of a run, chosen by `scene.analysis`.
pub enum Integrator {
    /// Quasi-static or Newmark implicit (theory §3); boxed, it holds the
    /// solver's caches.
    Implicit(Box<ImplicitIntegrator>),
    /// MUSL explicit (theory §4); boxed, it holds its node-sized buffers.
    Explicit(Box<ExplicitIntegrator>),
}

impl Integrator {
    /// The integrator the scene asks for, with its checks before the run.
    pub fn for_model(model: &Model) -> Result<Self, SceneError> {
        Ok(match model.analysis() {
            AnalysisKind::QuasiStatic | AnalysisKind::ImplicitDynamic => {
                Integrator::Implicit(Box::new(ImplicitIntegrator::new(model)?))
            }
            AnalysisKind::Explicit => {
                Integrator::Explicit(Box::new(ExplicitIntegrator::new(model)?))
            }
        })
    }

    /// Advance the model by one step.
    pub fn step(&mut self, model: &mut Model, profile: &Profile) -> Result<StepReport, StepError> {
        match self {
            Integrator::Implicit(implicit) => implicit.step(model, profile),
            Integrator::Explicit(explicit) => explicit.step(model, profile),
        }
    }

    /// What the integrator did so far.
    pub fn usage(&self) -> &SolverUsage {
        match self {
            Integrator::Implicit(implicit) => &implicit.usage,
            Integrator::Explicit(explicit) => &explicit.usage,
        }
    }

    /// Counters and timings of the implicit tangent's sparse direct solver
    /// (all zero for an explicit run, which factorises nothing).
    pub fn factorisation_stats(&self) -> SolverStats {
        match self {
            Integrator::Implicit(implicit) => implicit.solver_stats(),
            Integrator::Explicit(_) => SolverStats::default(),
        }
    }

    /// The implicit integrator, if the run has one.
    pub fn implicit(&self) -> Option<&ImplicitIntegrator> {
        match self {
            Integrator::Implicit(implicit) => Some(implicit),
            Integrator::Explicit(_) => None,
        }
    }

    /// The implicit integrator, mutable (verification access: `linearize`).
    pub fn implicit_mut(&mut self) -> Option<&mut ImplicitIntegrator> {
        match self {
            Integrator::Implicit(implicit) => Some(implicit),
            Integrator::Explicit(_) => None,
        }
    }
}
