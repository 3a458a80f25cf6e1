//! Feature `study`: [`Pcg::solve_faer`], the same preconditioned conjugate gradient on faer's
//! `faer::matrix_free::conjugate_gradient`, kept to repeat the measurement that keeps the
//! hand-written [`Pcg::solve`] (see its documentation).

use faer::dyn_stack::{MemBuffer, MemStack, StackReq};
use faer::matrix_free::conjugate_gradient::{
    conjugate_gradient, conjugate_gradient_scratch, CgError, CgParams,
};
use faer::matrix_free::{InitialGuessStatus, LinOp, Precond};
use faer::reborrow::ReborrowMut;
use faer::{Mat, MatMut, MatRef, Par};

use crate::norms::true_residual;
use crate::pcg::checked_rhs_norm;
use crate::{Pcg, PcgOutcome, SolverError, SparseMatrix};

impl Pcg {
    /// Solves `K x = b` from `x = 0` (K must be the matrix the preconditioner was built for)
    /// by faer's preconditioned conjugate gradient
    /// (`faer::matrix_free::conjugate_gradient`, one right-hand side, `Par::Seq`), whose
    /// recurrence residual stops it at `‖r‖ < tolerance · ‖b‖`; the true residual
    /// `‖b − K x‖ / ‖b‖` is then checked and, where round-off left it above the tolerance,
    /// faer's solver restarts from x on the true residual, within the same iteration limit.
    ///
    /// Errors: [`SolverError::RhsMismatch`], [`SolverError::NonFinite`],
    /// [`SolverError::NotPositiveDefinite`] when faer finds a curvature `pᵀKp < 0` or
    /// `rᵀM⁻¹r < 0`, [`SolverError::NotConverged`] at the iteration limit.
    pub fn solve_faer(&self, k: &SparseMatrix, b: &[f64]) -> Result<PcgOutcome, SolverError> {
        let n = k.n();
        let norm_b = checked_rhs_norm(n, b)?;
        if norm_b == 0.0 {
            return Ok(PcgOutcome {
                x: vec![0.0; n],
                iterations: 0,
                residual: 0.0,
            });
        }
        let tol = self.options().tolerance;
        let max_iterations = self.options().max_iterations;
        let op = Product(k);
        let precond = Applied(self);
        let rhs = MatRef::from_column_major_slice(b, n, 1);
        let mut x = Mat::<f64>::zeros(n, 1);
        let mut buffer = MemBuffer::new(conjugate_gradient_scratch(&precond, op, 1, Par::Seq));
        let mut iterations = 0;
        let not_positive = |iterations: usize| {
            SolverError::NotPositiveDefinite {
            method: "PCG",
            detail: format!(
                "curvature pᵀKp or rᵀM⁻¹r < 0 near iteration {iterations}: K is not positive definite"
            ),
        }
        };
        loop {
            // `InitialGuessStatus::Zero` leaves faer 0.24's residual uninitialised (it never
            // copies b into it): the zero x is passed as a guess, for one product with K
            let params = CgParams::<f64> {
                initial_guess: InitialGuessStatus::MaybeNonZero,
                abs_tolerance: 0.0,
                rel_tolerance: tol,
                max_iters: max_iterations - iterations,
                ..Default::default()
            };
            let mut done = 0;
            let result = conjugate_gradient(
                x.as_mut(),
                &precond,
                op,
                rhs,
                params,
                |_| done += 1,
                Par::Seq,
                MemStack::new(&mut buffer),
            );
            iterations += done;
            let solution = x
                .col(0)
                .try_as_col_major()
                .expect("a column of a Mat")
                .as_slice();
            match result {
                Ok(info) => {
                    let residual = true_residual(k, solution, b, norm_b);
                    if residual <= tol {
                        return Ok(PcgOutcome {
                            x: solution.to_vec(),
                            iterations,
                            residual,
                        });
                    }
                    if info.iter_count == 0 || iterations >= max_iterations {
                        return Err(SolverError::NotConverged {
                            method: "PCG",
                            iterations,
                            residual,
                            tolerance: tol,
                        });
                    }
                }
                Err(CgError::NoConvergence { .. }) => {
                    return Err(SolverError::NotConverged {
                        method: "PCG",
                        iterations,
                        residual: true_residual(k, solution, b, norm_b),
                        tolerance: tol,
                    })
                }
                Err(_) => return Err(not_positive(iterations)),
            }
        }
    }
}

/// `K x` by [`SparseMatrix::mul_vec`] as faer's operator.
#[derive(Debug, Clone, Copy)]
struct Product<'a>(&'a SparseMatrix);

impl LinOp<f64> for Product<'_> {
    fn apply_scratch(&self, _rhs_ncols: usize, _par: Par) -> StackReq {
        StackReq::EMPTY
    }

    fn nrows(&self) -> usize {
        self.0.n()
    }

    fn ncols(&self) -> usize {
        self.0.n()
    }

    fn apply(&self, out: MatMut<'_, f64>, rhs: MatRef<'_, f64>, _par: Par, _: &mut MemStack) {
        for_columns(out, rhs, |x, y| self.0.mul_vec(x, y));
    }

    fn conj_apply(&self, out: MatMut<'_, f64>, rhs: MatRef<'_, f64>, par: Par, s: &mut MemStack) {
        self.apply(out, rhs, par, s);
    }
}

/// `f(rhs_j, out_j)` for every column j, on slices (copied where a column is strided).
fn for_columns(mut out: MatMut<'_, f64>, rhs: MatRef<'_, f64>, f: impl Fn(&[f64], &mut [f64])) {
    for j in 0..rhs.ncols() {
        let column = rhs.col(j);
        let owned: Vec<f64>;
        let r = match column.try_as_col_major() {
            Some(c) => c.as_slice(),
            None => {
                owned = column.iter().copied().collect();
                &owned
            }
        };
        match out.rb_mut().col_mut(j).try_as_col_major_mut() {
            Some(z) => f(r, z.as_slice_mut()),
            None => {
                let mut z = vec![0.0; r.len()];
                f(r, &mut z);
                for (o, v) in out.rb_mut().col_mut(j).iter_mut().zip(z) {
                    *o = v;
                }
            }
        }
    }
}

/// [`Pcg`]'s preconditioner as faer's operator `z = M⁻¹ r`.
#[derive(Debug)]
struct Applied<'a>(&'a Pcg);

impl LinOp<f64> for Applied<'_> {
    fn apply_scratch(&self, _rhs_ncols: usize, _par: Par) -> StackReq {
        StackReq::EMPTY
    }

    fn nrows(&self) -> usize {
        self.0.dim()
    }

    fn ncols(&self) -> usize {
        self.0.dim()
    }

    fn apply(&self, out: MatMut<'_, f64>, rhs: MatRef<'_, f64>, _par: Par, _: &mut MemStack) {
        for_columns(out, rhs, |r, z| self.0.apply(r, z));
    }

    fn conj_apply(&self, out: MatMut<'_, f64>, rhs: MatRef<'_, f64>, par: Par, s: &mut MemStack) {
        self.apply(out, rhs, par, s);
    }
}

impl Precond<f64> for Applied<'_> {}
