//! Sparse assembly and direct solves for mpm-geo (theory §3 "Linear system", \[D17\], \[D19\]).
//!
//! Each Newton iteration the engine assembles the tangent `K_T (+ 4M/dt^2)` of \[D17\] (with the
//! \[D19\] background stiffness already summed into the cell blocks) from per-cell 8x8 blocks,
//! eliminates constrained dofs ([`NO_DOF`]), and solves with faer's sparse Cholesky or LU:
//!
//! * [`Assembler`] builds the CSC pattern once per set of active cells and scatters blocks
//!   deterministically (fixed element order, no thread-count dependence);
//! * [`SparseMatrix`] holds the values and shares the pattern through an `Arc`;
//! * [`DirectSolver`] factorises with `Par::Seq`, caching the symbolic factorisation while the
//!   pattern is unchanged, falling back from Cholesky to LU when K is not positive definite,
//!   and reporting singular systems as [`SolverError::Singular`];
//! * [`LinearSolver`] puts faer's Cholesky/LU (supernodal or simplicial, AMD/COLAMD/identity
//!   orderings), preconditioned conjugate gradients ([`Pcg`]: Jacobi or IC(0)) and, with the
//!   `ldl` feature, sprs_ldl's LDLᵀ behind one front, falling back to LU (recorded) where a
//!   method does not apply;
//! * [`MultifrontalLu`] factorises K on the symmetric pattern of K + Kᵀ (faer's AMD analysis,
//!   dense faer LU or Cholesky inside each front, independent subtrees in parallel in the
//!   factorisation and in the solves), several
//!   times faster than faer's sparse LU on the benchmarks' tangents, and on two threads faster
//!   than faer's sparse Cholesky on symmetric ones (`linear_solver = "auto"`, the default, or
//!   `"multifrontal"`);
//! * [`mm`] writes and reads systems in Matrix Market format (the runs' `[output] systems`).
//!
//! With the cargo feature `study`, `bench` runs every solver, ordering and variant on a
//! directory of exported systems (the binary `mpm-solvers bench`, which needs the feature).

mod assembly;
#[cfg(feature = "study")]
pub mod bench;
mod direct;
mod error;
mod gmres;
#[cfg(feature = "ldl")]
mod ldl;
mod linear;
mod matrix;
pub mod mm;
mod multifrontal;
mod norms;
mod pcg;
#[cfg(feature = "study")]
mod pcg_faer;

pub use assembly::Assembler;
pub use direct::{
    DirectSolver, FactorKind, Factorization, Ordering, SolverOptions, SolverPolicy, SolverStats,
};
pub use error::SolverError;
pub use gmres::{gmres, GmresOutcome};
#[cfg(feature = "ldl")]
pub use ldl::LdlSolver;
pub use linear::{LinearOptions, LinearSolver, Method, Used};
pub use matrix::SparseMatrix;
pub use multifrontal::{MultifrontalLu, CORRECTION_LIMIT as MULTIFRONTAL_CORRECTION_LIMIT};
pub use pcg::{Pcg, PcgOptions, PcgOutcome, Preconditioner};

/// Marker in an element dof list for an eliminated (constrained) dof: its rows and columns of
/// the element block are skipped (theory §3 "Linear system").
pub const NO_DOF: u32 = u32::MAX;

#[cfg(test)]
mod tests;
