//! LDLᵀ of the `sprs_ldl` crate (a port of T. Davis's LDL; LGPL-2.1, hence behind the optional
//! `ldl` feature): an independent second library for symmetric systems, ordered by faer's AMD.
//! It does not pivot: a zero pivot is an error, and it is applied to symmetric K only.

use std::time::Instant;

use sprs::{CsMatViewI, PermOwnedI, SymmetryCheck};
use sprs_ldl::{LdlNumeric, LdlSymbolic};

use crate::direct::amd_order;
use crate::{SolverError, SparseMatrix};

/// A cached sprs_ldl factorisation (symbolic part reused while the pattern holds).
#[derive(Default)]
pub struct LdlSolver {
    pattern: Option<(Vec<usize>, Vec<usize>)>,
    numeric: Option<LdlNumeric<f64, usize>>,
    /// Seconds of the last symbolic factorisation (ordering included), if it was redone.
    pub last_symbolic_seconds: f64,
    /// Seconds of the last numeric factorisation.
    pub last_numeric_seconds: f64,
}

impl std::fmt::Debug for LdlSolver {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LdlSolver")
            .field("nnz", &self.numeric.as_ref().map(|n| n.nnz()))
            .finish_non_exhaustive()
    }
}

fn view(k: &SparseMatrix) -> Result<CsMatViewI<'_, f64, usize>, SolverError> {
    CsMatViewI::try_new_csc((k.n(), k.n()), k.col_ptr(), k.row_idx(), k.values())
        .map_err(|e| SolverError::Unsupported(format!("sprs view: {e:?}")))
}

impl LdlSolver {
    /// New solver holding nothing.
    pub fn new() -> Self {
        Self::default()
    }

    /// Factorises symmetric `k` (symbolic step redone when the pattern changed).
    ///
    /// Errors: [`SolverError::NonFinite`], [`SolverError::Singular`] (a zero pivot).
    pub fn factorize(&mut self, k: &SparseMatrix) -> Result<(), SolverError> {
        if let Some(index) = k.values().iter().position(|v| !v.is_finite()) {
            return Err(SolverError::NonFinite {
                what: "matrix values",
                index,
            });
        }
        let a = view(k)?;
        let same = self
            .pattern
            .as_ref()
            .is_some_and(|(c, r)| c == k.col_ptr() && r == k.row_idx());
        let singular = |e: sprs::errors::LinalgError| SolverError::Singular {
            factor: crate::FactorKind::Cholesky,
            detail: format!("sprs_ldl: {e}"),
            unknown: None,
        };
        self.last_symbolic_seconds = 0.0;
        match (&mut self.numeric, same) {
            (Some(numeric), true) => {
                let t = Instant::now();
                let res = numeric.update(a);
                self.last_numeric_seconds = t.elapsed().as_secs_f64();
                if let Err(e) = res {
                    self.numeric = None;
                    self.pattern = None;
                    return Err(singular(e));
                }
            }
            _ => {
                self.numeric = None;
                let t = Instant::now();
                let (fwd, _) = amd_order(k)?;
                let symbolic = LdlSymbolic::new_perm(
                    a,
                    PermOwnedI::new(fwd),
                    SymmetryCheck::DontCheckSymmetry,
                );
                self.last_symbolic_seconds = t.elapsed().as_secs_f64();
                let t = Instant::now();
                let numeric = symbolic.factor(a).map_err(singular)?;
                self.last_numeric_seconds = t.elapsed().as_secs_f64();
                self.numeric = Some(numeric);
                self.pattern = Some((k.col_ptr().to_vec(), k.row_idx().to_vec()));
            }
        }
        Ok(())
    }

    /// Stored entries of L (unit diagonal not stored) plus the n entries of D.
    pub fn nnz(&self) -> Option<usize> {
        self.numeric.as_ref().map(|n| n.nnz() + n.problem_size())
    }

    /// Solves with the last factorisation; `rhs` is overwritten by x.
    ///
    /// Errors: [`SolverError::NotFactorized`], [`SolverError::RhsMismatch`],
    /// [`SolverError::Singular`] for a non-finite solution.
    pub fn solve_in_place(&self, rhs: &mut [f64]) -> Result<(), SolverError> {
        let numeric = self.numeric.as_ref().ok_or(SolverError::NotFactorized)?;
        if rhs.len() != numeric.problem_size() {
            return Err(SolverError::RhsMismatch {
                expected: numeric.problem_size(),
                found: rhs.len(),
            });
        }
        let x: Vec<f64> = numeric.solve(&rhs.to_vec());
        if let Some(i) = x.iter().position(|v| !v.is_finite()) {
            return Err(SolverError::Singular {
                factor: crate::FactorKind::Cholesky,
                detail: format!("sprs_ldl solution is not finite (first at dof {i})"),
                unknown: Some(i),
            });
        }
        rhs.copy_from_slice(&x);
        Ok(())
    }
}
