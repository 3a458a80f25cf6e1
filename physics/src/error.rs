//! Errors of a run. A failed step is a [`RunError::Step`]: the step and time
//! are filled in once, by the time loop, around a typed [`StepError`] cause
//! raised by the integrator; the CLI prints them as they are.

use std::fmt;

use mpm_solvers::SolverError;

use crate::constitutive::ConstitutiveError;
use crate::nonlocal::NonlocalError;

/// Why a run stopped before its end.
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    /// A step failed; outputs up to the previous step are kept.
    #[error("step {step} (t = {time:.6e} s): {cause}")]
    Step {
        /// Step being computed (1-based).
        step: usize,
        /// Time reached when it failed (the start of the failed step or
        /// sub-step), s.
        time: f64,
        /// What went wrong.
        #[source]
        cause: StepError,
    },
    /// Writing an output failed (the first such error ends the run; every
    /// file written before it is whole, the one being written is absent or
    /// keeps its previous version, `curve.csv` ends with a whole row).
    #[error("step {step} (t = {time:.6e} s): cannot write {path}: {message}")]
    Output {
        /// Step whose outputs were being written (0: the initial state).
        step: usize,
        /// Time of that step, s.
        time: f64,
        /// File that could not be written.
        path: String,
        /// Why.
        message: String,
    },
}

impl RunError {
    /// Whether `mpm-geo resume` can get past this stop: a failed write can
    /// succeed once the cause is removed (a full disk), but a failed step
    /// is computed again from the same checkpoint and fails the same way.
    pub fn resumable(&self) -> bool {
        matches!(self, RunError::Output { .. })
    }

    /// The step error, if the run stopped in a step.
    pub fn cause(&self) -> Option<&StepError> {
        match self {
            RunError::Step { cause, .. } => Some(cause),
            RunError::Output { .. } => None,
        }
    }
}

/// Which kind of boundary point left the grid.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BoundaryPointKind {
    /// A traction point carrying a follower pressure.
    Traction,
    /// A rigid body's surface contact point.
    Contact,
}

impl fmt::Display for BoundaryPointKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            BoundaryPointKind::Traction => "traction",
            BoundaryPointKind::Contact => "contact",
        })
    }
}

/// What limits the explicit stable time step (theory D20, §4).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TimeStepLimit {
    /// h / (c_p + |v_p|) of the material points.
    WaveSpeed,
    /// The wave limit combined with the penalty springs of driven points.
    WaveSpeedAndSprings,
}

impl fmt::Display for TimeStepLimit {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            TimeStepLimit::WaveSpeed => "wave speed, theory D20",
            TimeStepLimit::WaveSpeedAndSprings => {
                "wave speed and penalty springs of driven points, theory §4"
            }
        })
    }
}

impl serde::Serialize for TimeStepLimit {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.collect_str(self)
    }
}

impl<'de> serde::Deserialize<'de> for TimeStepLimit {
    /// Reads the text [`serde::Serialize`] writes.
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        let text = String::deserialize(deserializer)?;
        [Self::WaveSpeed, Self::WaveSpeedAndSprings]
            .into_iter()
            .find(|limit| limit.to_string() == text)
            .ok_or_else(|| serde::de::Error::custom(format!("unknown time-step limit `{text}`")))
    }
}

/// A D18 criterion of the implicit Newton loop.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Criterion {
    /// ‖R‖ ≤ ε_R F_ref.
    Force,
    /// |δu · R| ≤ ε_E |δu⁰ · R⁰|.
    Energy,
    /// κ̄ lagged one iteration has settled (nonlocal runs).
    NonlocalKappa,
    /// The path-following constraint holds (theory PF2).
    PathConstraint,
}

impl fmt::Display for Criterion {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Criterion::Force => "force",
            Criterion::Energy => "energy",
            Criterion::NonlocalKappa => "nonlocal κ̄",
            Criterion::PathConstraint => "path constraint",
        })
    }
}

/// Why the last attempt at an implicit (sub-)step failed.
#[derive(Debug, Clone, PartialEq)]
pub enum NewtonFailure {
    /// The residual grew in three consecutive iterations.
    Diverged,
    /// The iteration limit was reached with D18 criteria unmet.
    IterationLimit {
        /// The limit.
        iterations: usize,
        /// The criteria still unmet at the last iterate.
        unmet: Vec<Criterion>,
        /// The force reference F_ref of D18, kN/m.
        reference: f64,
    },
    /// A non-finite residual or solution.
    NonFinite(&'static str),
    /// A point moved more than half a cell in one dynamic step (theory §3).
    Motion {
        /// The point.
        particle: usize,
        /// Its position at the start of the step, m.
        position: [f64; 2],
        /// How far it moved, m.
        distance: f64,
    },
}

impl fmt::Display for NewtonFailure {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            NewtonFailure::Diverged => write!(f, "residual grew in 3 consecutive iterations"),
            NewtonFailure::IterationLimit {
                iterations,
                unmet,
                reference,
            } => {
                let unmet: Vec<String> = unmet.iter().map(|c| c.to_string()).collect();
                write!(
                    f,
                    "no convergence within {iterations} iterations (unmet D18 criteria: {}; force reference F_ref = {reference:.3e})",
                    unmet.join(", ")
                )
            }
            NewtonFailure::NonFinite(what) => write!(f, "non-finite {what}"),
            NewtonFailure::Motion {
                particle,
                position,
                distance,
            } => write!(
                f,
                "material point {particle} at ({:.6}, {:.6}) m moved {distance:.3e} m > h/2 in one step",
                position[0], position[1]
            ),
        }
    }
}

/// A grid dof named for a user: its component at its node.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DofPlace {
    /// 0: x, 1: y.
    pub component: usize,
    /// The node's position, m.
    pub node: [f64; 2],
}

impl fmt::Display for DofPlace {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "in {} at the node ({:.4}, {:.4}) m",
            ["x", "y"][self.component.min(1)],
            self.node[0],
            self.node[1]
        )
    }
}

/// Where an iterate's equilibrium fails most: the largest free component of
/// the residual R (theory D16) and its place.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LargestResidual {
    /// R at that dof, kN/m.
    pub value: f64,
    /// The dof.
    pub place: DofPlace,
}

impl fmt::Display for LargestResidual {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "largest residual {:.3e} kN/m {}", self.value, self.place)
    }
}

/// `"; "` and `largest`, or nothing (the located part of a Newton failure's message).
fn located(largest: &Option<Box<LargestResidual>>) -> String {
    largest
        .as_ref()
        .map_or_else(String::new, |l| format!("; {l}"))
}

/// ‖R‖ per iteration as `[5.574e0, 4.716e0, …]`: four significant digits,
/// enough to see how the iteration went.
fn residual_norms(history: &[f64]) -> String {
    let norms: Vec<String> = history.iter().map(|r| format!("{r:.3e}")).collect();
    format!("[{}]", norms.join(", "))
}

/// Why a step failed.
#[derive(Debug, thiserror::Error)]
pub enum StepError {
    /// A material point left the background grid.
    #[error("material point {particle} left the grid at ({:.6}, {:.6}) m", position[0], position[1])]
    ParticleLeftGrid {
        /// Particle index.
        particle: usize,
        /// Where it went, m.
        position: [f64; 2],
    },
    /// A boundary point left the background grid.
    #[error("{kind} point {point} left the grid at ({:.6}, {:.6}) m", position[0], position[1])]
    BoundaryPointLeftGrid {
        /// Traction or contact point.
        kind: BoundaryPointKind,
        /// Index of the point among the points of its kind.
        point: usize,
        /// Where it went, m.
        position: [f64; 2],
    },
    /// Newton–Raphson failed even after the allowed step halvings.
    #[error("Newton did not converge after {halvings} step halvings: {cause}{}; residual history {} kN/m", located(.largest), residual_norms(.history))]
    NewtonFailed {
        /// Number of halvings tried.
        halvings: usize,
        /// Cause of the last failure.
        cause: NewtonFailure,
        /// ‖R‖ per iteration of the last attempt, kN/m.
        history: Vec<f64>,
        /// Where the last attempt's last iterate was furthest from
        /// equilibrium (`None` where no residual was judged).
        largest: Option<Box<LargestResidual>>,
    },
    /// Path following (theory §3.7) took its step budget without reaching
    /// the end travel.
    #[error("path following took its {steps} steps (solver.path_max_steps) and reached travel time {reached:.6e} of {end:.6e}")]
    PathBudget {
        /// Steps taken.
        steps: usize,
        /// The rigid bodies' time parameter reached.
        reached: f64,
        /// The end of the path.
        end: f64,
    },
    /// Every attempt at a path-following step jumped off the path (theory
    /// PF5).
    #[error("path following lost its path at travel time {travel:.6e}: the step jumped off the path at every one of {cuts} halvings")]
    PathJump {
        /// The rigid bodies' time parameter at the start of the step.
        travel: f64,
        /// Halvings tried.
        cuts: usize,
    },
    /// A stress update or linear solve (`source`) that failed again at the
    /// last of the allowed step halvings.
    #[error("{source} (after {halvings} step halvings)")]
    Halved {
        /// Number of halvings tried.
        halvings: usize,
        /// The failure of the last attempt.
        source: Box<StepError>,
    },
    /// The stress update failed at a material point.
    #[error("stress update failed at material point {particle}: {source}")]
    Constitutive {
        /// Particle index.
        particle: usize,
        /// The constitutive error.
        source: ConstitutiveError,
    },
    /// A stress became NaN or infinite.
    #[error("non-finite value: stress of material point {particle}")]
    NonFiniteStress {
        /// Particle index.
        particle: usize,
    },
    /// A material point variable other than the stress became NaN or
    /// infinite (found by the one pass of the commit stage).
    #[error("non-finite value: {quantity} of material point {particle} at ({:.6e}, {:.6e}) m", position[0], position[1])]
    NonFinitePoint {
        /// Particle index.
        particle: usize,
        /// Which variable (`position`, `velocity`, `volume`, …).
        quantity: &'static str,
        /// Its position, m (its initial position if the position itself is not finite).
        position: [f64; 2],
    },
    /// A nodal result of the step (reaction, displacement increment) became
    /// NaN or infinite.
    #[error("non-finite value: {quantity} at grid node {node} ({:.6e}, {:.6e}) m", position[0], position[1])]
    NonFiniteNode {
        /// Node index.
        node: usize,
        /// Which nodal result.
        quantity: &'static str,
        /// Node position, m.
        position: [f64; 2],
    },
    /// A monitor (a `curve.csv` column) became NaN or infinite after the step.
    #[error("non-finite value: monitor `{name}` = {value}")]
    NonFiniteMonitor {
        /// Monitor name.
        name: String,
        /// Its value.
        value: f64,
    },
    /// The explicit time step is not a positive finite number.
    #[error("non-finite value: explicit time step {dt}")]
    InvalidTimeStep {
        /// The time step, s.
        dt: f64,
    },
    /// The explicit time step exceeds the stability limit.
    #[error(
        "explicit time step {dt:.4e} s exceeds the stability limit {limit:.4e} s ({limited_by})"
    )]
    UnstableTimeStep {
        /// The time step, s.
        dt: f64,
        /// The limit, s.
        limit: f64,
        /// Which limit.
        limited_by: TimeStepLimit,
    },
    /// The linear solver (or the pattern of its system) failed.
    #[error("linear solver: {0}")]
    Solver(#[from] SolverError),
    /// The nonlocal averaging failed.
    #[error("nonlocal averaging: {0}")]
    Nonlocal(#[from] NonlocalError),
    /// Double mapping of the stresses failed (its force-restoring solve).
    #[error("double mapping: {0}")]
    DoubleMapping(#[source] SolverError),
    /// The integrator asked of the run does not offer this (e.g. a tangent
    /// of an explicit run).
    #[error("{0}")]
    NotAvailable(&'static str),
    /// Verification access with inputs of the wrong size.
    #[error("{what}: {given} values given for {expected}")]
    WrongLength {
        /// Which call.
        what: &'static str,
        /// Values given.
        given: usize,
        /// Values expected.
        expected: usize,
    },
}

use crate::error_id::{ErrorId, Identified};

impl Identified for RunError {
    fn error_id(&self) -> ErrorId {
        match self {
            RunError::Step { cause, .. } => cause.error_id(),
            RunError::Output { .. } => ErrorId::OutputWrite,
        }
    }
}

impl Identified for StepError {
    fn error_id(&self) -> ErrorId {
        match self {
            StepError::ParticleLeftGrid { .. } => ErrorId::RunPointLeftGrid,
            StepError::BoundaryPointLeftGrid { .. } => ErrorId::RunBoundaryPointLeftGrid,
            StepError::NewtonFailed { .. } => ErrorId::RunNewtonFailed,
            StepError::Halved { source, .. } => source.error_id(),
            StepError::PathBudget { .. } => ErrorId::RunPathBudget,
            StepError::PathJump { .. } => ErrorId::RunPathLost,
            StepError::Constitutive { .. } => ErrorId::RunStressUpdate,
            StepError::NonFiniteStress { .. }
            | StepError::NonFinitePoint { .. }
            | StepError::NonFiniteNode { .. }
            | StepError::NonFiniteMonitor { .. } => ErrorId::RunNonFinite,
            StepError::InvalidTimeStep { .. } | StepError::UnstableTimeStep { .. } => {
                ErrorId::RunTimeStep
            }
            StepError::Solver(_) | StepError::DoubleMapping(_) => ErrorId::RunLinearSolver,
            StepError::Nonlocal(_) => ErrorId::RunNonlocal,
            StepError::NotAvailable(_) | StepError::WrongLength { .. } => ErrorId::RunInternal,
        }
    }
}

impl Identified for SolverError {
    fn error_id(&self) -> ErrorId {
        ErrorId::RunLinearSolver
    }
}
