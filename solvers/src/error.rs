//! Typed errors of the assembly and direct-solve layer.

use crate::FactorKind;

/// Everything that can go wrong while building a pattern, assembling, factorising or solving.
///
/// No function of this crate panics on bad *numeric* input (NaN, singular matrices): such cases
/// come back as one of these variants.
#[derive(thiserror::Error, Debug, Clone, PartialEq)]
pub enum SolverError {
    /// The system has no unknowns (n = 0); there is nothing to assemble or factorise.
    #[error("empty system: the matrix has no unknowns (n = 0)")]
    EmptySystem,

    /// A slice handed in has the wrong length.
    #[error("dimension mismatch in {context}: expected length {expected}, got {found}")]
    DimensionMismatch {
        /// Which argument was wrong.
        context: &'static str,
        /// Length that was required.
        expected: usize,
        /// Length that was passed.
        found: usize,
    },

    /// An element dof list refers to a dof `>= n_dofs` (and is not [`crate::NO_DOF`]).
    #[error("element {element} refers to dof {dof}, out of range for n_dofs = {n_dofs}")]
    DofOutOfRange {
        /// Index of the element in the list given to [`crate::Assembler::new`].
        element: usize,
        /// The offending dof index.
        dof: u32,
        /// Number of dofs of the system.
        n_dofs: usize,
    },

    /// A triplet lies outside an `n x n` matrix.
    #[error("triplet ({row}, {col}) lies outside a {n} x {n} matrix")]
    IndexOutOfRange {
        /// Row index of the triplet.
        row: usize,
        /// Column index of the triplet.
        col: usize,
        /// Matrix dimension.
        n: usize,
    },

    /// The pattern has more non-zeros than the 32-bit scatter positions can address.
    #[error(
        "sparsity pattern has {nnz} non-zeros, more than 32-bit scatter positions can address"
    )]
    TooManyNonZeros {
        /// Number of non-zeros of the pattern.
        nnz: usize,
    },

    /// A NaN or infinite value was found in the matrix or a right-hand side.
    #[error("non-finite value (NaN or inf) in the {what} at index {index}")]
    NonFinite {
        /// `"matrix values"` or `"right-hand side"`.
        what: &'static str,
        /// Position of the first non-finite entry (value position for the matrix, dof for a vector).
        index: usize,
    },

    /// The matrix is singular or numerically singular; the factorisation (or its solution) is
    /// unusable. See `detail` for how it was detected.
    #[error("singular matrix ({factor:?} factorisation): {detail}")]
    Singular {
        /// Factorisation that detected the singularity.
        factor: FactorKind,
        /// Human-readable description of the test that failed.
        detail: String,
        /// The unknown where that test failed most (the probe solve's or the
        /// refinement's largest deviation, the first non-finite entry of the
        /// solution), where the test tells one: a caller can name its dof.
        unknown: Option<usize>,
    },

    /// [`crate::DirectSolver::solve_in_place`] was called with no valid factorisation
    /// (never factorised, or the last `factorize` call failed).
    #[error("no valid factorisation: call factorize first (or the last factorize call failed)")]
    NotFactorized,

    /// The right-hand side does not match the dimension of the factorised matrix.
    #[error("right-hand side has length {found}, factorised matrix has dimension {expected}")]
    RhsMismatch {
        /// Dimension of the factorised matrix.
        expected: usize,
        /// Length of the right-hand side.
        found: usize,
    },

    /// The matrix is not symmetric positive definite where the method needs it (a conjugate
    /// gradient breakdown `pᵀKp ≤ 0`, a non-positive pivot of the incomplete Cholesky or a
    /// non-positive diagonal for Jacobi).
    #[error("not positive definite ({method}): {detail}")]
    NotPositiveDefinite {
        /// Which method found it.
        method: &'static str,
        /// What was found.
        detail: String,
    },

    /// An iterative solve did not reach its tolerance.
    #[error("{method} did not converge: relative residual {residual:.3e} > {tolerance:.1e} after {iterations} iterations")]
    NotConverged {
        /// Which method.
        method: &'static str,
        /// Iterations done.
        iterations: usize,
        /// Relative residual reached, ‖b − Kx‖ / ‖b‖.
        residual: f64,
        /// Tolerance asked for.
        tolerance: f64,
    },

    /// The combination of options is not available (named in the message).
    #[error("unsupported solver options: {0}")]
    Unsupported(String),

    /// Reading or writing an exported system failed.
    #[error("{path}: {message}")]
    Io {
        /// The file.
        path: String,
        /// Why.
        message: String,
    },

    /// A non-numerical failure inside faer (allocation failure, index overflow).
    #[error("faer failure: {0}")]
    Faer(String),
}
