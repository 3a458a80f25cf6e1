//! Errors of a run. Every variant names the step, the time and the cause; the
//! CLI prints them as they are.

use crate::constitutive::ConstitutiveError;

/// Why a run stopped before its end.
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    /// A material point left the background grid.
    #[error("step {step} (t = {time:.6e} s): material point {particle} left the grid at ({:.6}, {:.6}) m", position[0], position[1])]
    ParticleLeftGrid {
        /// Step being computed.
        step: usize,
        /// Time at the end of that step, s.
        time: f64,
        /// Particle index.
        particle: usize,
        /// Where it went, m.
        position: [f64; 2],
    },
    /// A boundary point (a traction point carrying a pressure, or a rigid
    /// body's surface contact point) left the background grid.
    #[error("step {step} (t = {time:.6e} s): {kind} point {point} left the grid at ({:.6}, {:.6}) m", position[0], position[1])]
    BoundaryPointLeftGrid {
        /// Step being computed.
        step: usize,
        /// Time, s.
        time: f64,
        /// `traction` or `contact`.
        kind: &'static str,
        /// Index of the point among the points of its kind.
        point: usize,
        /// Where it went, m.
        position: [f64; 2],
    },
    /// Newton–Raphson failed even after the allowed step halvings.
    #[error("step {step} (t = {time:.6e} s): Newton did not converge after {halvings} step halvings: {cause}; residual history {history:?}")]
    NewtonFailed {
        /// Step being computed.
        step: usize,
        /// Time at the end of the failed (sub-)step, s.
        time: f64,
        /// Number of halvings tried.
        halvings: usize,
        /// Cause of the last failure.
        cause: String,
        /// ‖R‖ per iteration of the last attempt, kN/m.
        history: Vec<f64>,
    },
    /// The stress update failed at a material point.
    #[error("step {step} (t = {time:.6e} s): stress update failed at material point {particle}: {source}")]
    Constitutive {
        /// Step being computed.
        step: usize,
        /// Time, s.
        time: f64,
        /// Particle index.
        particle: usize,
        /// The constitutive error.
        source: ConstitutiveError,
    },
    /// A NaN or infinite value appeared.
    #[error("step {step} (t = {time:.6e} s): non-finite value: {what}")]
    NonFinite {
        /// Step being computed.
        step: usize,
        /// Time, s.
        time: f64,
        /// Where it appeared.
        what: String,
    },
    /// The explicit time step exceeds the stability limit.
    #[error("step {step} (t = {time:.6e} s): explicit time step {dt:.4e} s exceeds the stability limit {limit:.4e} s ({reason})")]
    UnstableTimeStep {
        /// Step being computed.
        step: usize,
        /// Time, s.
        time: f64,
        /// The time step, s.
        dt: f64,
        /// The limit, s.
        limit: f64,
        /// Which limit (wave speed or penalty springs).
        reason: String,
    },
    /// The linear solver failed.
    #[error("step {step} (t = {time:.6e} s): linear solver: {message}")]
    Solver {
        /// Step being computed.
        step: usize,
        /// Time, s.
        time: f64,
        /// The solver's message.
        message: String,
    },
    /// Writing an output failed.
    #[error("output {path}: {message}")]
    Output {
        /// File that could not be written.
        path: String,
        /// Why.
        message: String,
    },
}
