//! Preconditioned conjugate gradient for symmetric positive definite systems, with a Jacobi or
//! a zero-fill incomplete Cholesky (IC(0)) preconditioner.
//!
//! Conjugate gradients are only correct for symmetric positive definite K: a curvature
//! `pᵀKp ≤ 0` (K indefinite), a non-positive IC(0) pivot or a non-positive diagonal are
//! reported as [`SolverError::NotPositiveDefinite`], never answered with a wrong solution;
//! a solve that does not reach its tolerance is [`SolverError::NotConverged`].

use crate::norms::{dot, norm, true_residual};
use crate::{SolverError, SparseMatrix};

/// Preconditioner of [`Pcg`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Preconditioner {
    /// Diagonal scaling M = diag(K).
    #[default]
    Jacobi,
    /// Incomplete Cholesky with zero fill, IC(0): L has the pattern of the lower triangle of K.
    IncompleteCholesky,
}

/// Stopping rule and preconditioner of [`Pcg`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PcgOptions {
    /// The preconditioner.
    pub preconditioner: Preconditioner,
    /// Stop when `‖b − K x‖ / ‖b‖ ≤ tolerance`. Default `1e-10`.
    pub tolerance: f64,
    /// Iteration limit. Default `10_000`.
    pub max_iterations: usize,
}

impl Default for PcgOptions {
    fn default() -> Self {
        Self {
            preconditioner: Preconditioner::Jacobi,
            tolerance: 1e-10,
            max_iterations: 10_000,
        }
    }
}

/// Result of one [`Pcg::solve`].
#[derive(Debug, Clone, PartialEq)]
pub struct PcgOutcome {
    /// The solution.
    pub x: Vec<f64>,
    /// Iterations taken.
    pub iterations: usize,
    /// True relative residual `‖b − K x‖ / ‖b‖` of `x` (recomputed, not the recurrence's).
    pub residual: f64,
}

/// A preconditioner built for one matrix.
#[derive(Debug, Clone)]
enum Built {
    /// Inverse diagonal.
    Jacobi(Vec<f64>),
    /// IC(0) factor L (CSC, lower triangle, diagonal first in each column).
    Ic0 {
        col_ptr: Vec<usize>,
        row_idx: Vec<usize>,
        values: Vec<f64>,
    },
}

/// Conjugate gradients on a fixed matrix with a preconditioner built by [`Pcg::new`].
///
/// The iteration is hand-written, not faer 0.24's `faer::matrix_free::conjugate_gradient`
/// (which the feature `study` runs with the same preconditioners, operator and stopping rule
/// as `Pcg::solve_faer`), because faer's is measurably slower at the same iteration counts.
/// Medians of 7 solves to ‖b − K x‖/‖b‖ ≤ 1e-10 on the crate's elastic grid tangents, one
/// sitting, `cargo test --release -p mpm-solvers --features study --lib measure_pcg --
/// --ignored --nocapture --test-threads=1`, five runs on 2 shared cores (two with faer's
/// sparse product as the operator, three with [`SparseMatrix::mul_vec`]; the ranges span them):
///
/// | system (n) | preconditioner | iterations (hand / faer) | faer's time / hand-written's |
/// |---|---|---|---|
/// | grid 40×40 (3,280) | Jacobi | 365 / 365 | 0.98–1.23 |
/// | grid 100×100 (20,200) | Jacobi | 913 / 912 | 1.05–1.25 |
/// | grid 200×150 (60,300) | Jacobi | 1522 / 1522 | 1.08–1.20 |
/// | grid 40×40 | IC(0) | 74 / 74 | 1.05–1.10 |
/// | grid 100×100 | IC(0) | 184 / 184 | 1.04–1.09 |
/// | grid 200×150 | IC(0) | 305 / 305 | 0.99–1.12 |
///
/// faer's is a block method (a pivoted Cholesky and triangular products of the k × k
/// Gram matrices every step), overhead that one right-hand side does not pay back; its
/// zero-initial-guess mode also leaves the residual uninitialised in 0.24 (the zero guess
/// must be passed as a general one, one more product), and it stops on a curvature `< 0`
/// where this one stops on `≤ 0`.
#[derive(Debug, Clone)]
pub struct Pcg {
    options: PcgOptions,
    built: Built,
}

impl Pcg {
    /// Builds the preconditioner of `k` (symmetric; full storage, both triangles).
    ///
    /// Errors: [`SolverError::NotPositiveDefinite`] for a non-positive diagonal entry (Jacobi)
    /// or pivot (IC(0)), [`SolverError::NonFinite`].
    pub fn new(k: &SparseMatrix, options: PcgOptions) -> Result<Self, SolverError> {
        if let Some(index) = k.values().iter().position(|v| !v.is_finite()) {
            return Err(SolverError::NonFinite {
                what: "matrix values",
                index,
            });
        }
        let built = match options.preconditioner {
            Preconditioner::Jacobi => {
                let mut inv = Vec::with_capacity(k.n());
                for i in 0..k.n() {
                    let d = k.get(i, i);
                    if d.is_nan() || d <= 0.0 {
                        return Err(SolverError::NotPositiveDefinite {
                            method: "PCG Jacobi",
                            detail: format!("diagonal entry K[{i},{i}] = {d:.3e} <= 0"),
                        });
                    }
                    inv.push(1.0 / d);
                }
                Built::Jacobi(inv)
            }
            Preconditioner::IncompleteCholesky => ic0(k)?,
        };
        Ok(Self { options, built })
    }

    /// Stored entries of the preconditioner: n for Jacobi, nnz(L) for IC(0).
    pub fn nnz(&self) -> usize {
        match &self.built {
            Built::Jacobi(d) => d.len(),
            Built::Ic0 { values, .. } => values.len(),
        }
    }

    /// Unknowns of the matrix the preconditioner was built for.
    #[cfg(feature = "study")]
    pub(crate) fn dim(&self) -> usize {
        match &self.built {
            Built::Jacobi(d) => d.len(),
            Built::Ic0 { col_ptr, .. } => col_ptr.len() - 1,
        }
    }

    /// The options given at construction.
    pub fn options(&self) -> &PcgOptions {
        &self.options
    }

    /// `z = M⁻¹ r`.
    pub(crate) fn apply(&self, r: &[f64], z: &mut [f64]) {
        match &self.built {
            Built::Jacobi(inv) => {
                for ((z, r), d) in z.iter_mut().zip(r).zip(inv) {
                    *z = r * d;
                }
            }
            Built::Ic0 {
                col_ptr,
                row_idx,
                values,
            } => {
                let n = z.len();
                z.copy_from_slice(r);
                // L y = r (column oriented)
                for j in 0..n {
                    let (a, b) = (col_ptr[j], col_ptr[j + 1]);
                    let yj = z[j] / values[a];
                    z[j] = yj;
                    for p in a + 1..b {
                        z[row_idx[p]] -= values[p] * yj;
                    }
                }
                // Lᵀ x = y (the columns of L are the rows of Lᵀ)
                for j in (0..n).rev() {
                    let (a, b) = (col_ptr[j], col_ptr[j + 1]);
                    let mut s = z[j];
                    for p in a + 1..b {
                        s -= values[p] * z[row_idx[p]];
                    }
                    z[j] = s / values[a];
                }
            }
        }
    }

    /// Solves `K x = b` from `x = 0` (K must be the matrix the preconditioner was built for).
    ///
    /// Errors: [`SolverError::RhsMismatch`], [`SolverError::NonFinite`],
    /// [`SolverError::NotPositiveDefinite`] on a curvature `pᵀKp ≤ 0` or `rᵀM⁻¹r ≤ 0`,
    /// [`SolverError::NotConverged`] at the iteration limit.
    pub fn solve(&self, k: &SparseMatrix, b: &[f64]) -> Result<PcgOutcome, SolverError> {
        let n = k.n();
        let norm_b = checked_rhs_norm(n, b)?;
        let mut x = vec![0.0; n];
        if norm_b == 0.0 {
            return Ok(PcgOutcome {
                x,
                iterations: 0,
                residual: 0.0,
            });
        }
        let tol = self.options.tolerance;
        let mut r = b.to_vec();
        let mut z = vec![0.0; n];
        self.apply(&r, &mut z);
        let mut p = z.clone();
        let mut q = vec![0.0; n];
        let mut rz = dot(&r, &z);
        let mut iterations = 0;
        loop {
            if iterations == self.options.max_iterations {
                let residual = true_residual(k, &x, b, norm_b);
                return Err(SolverError::NotConverged {
                    method: "PCG",
                    iterations,
                    residual,
                    tolerance: tol,
                });
            }
            if rz.is_nan() || rz <= 0.0 {
                return Err(SolverError::NotPositiveDefinite {
                    method: "PCG",
                    detail: format!(
                        "preconditioned residual rᵀM⁻¹r = {rz:.3e} <= 0 at iteration {iterations}"
                    ),
                });
            }
            k.mul_vec(&p, &mut q);
            let curvature = dot(&p, &q);
            if curvature.is_nan() || curvature <= 0.0 {
                return Err(SolverError::NotPositiveDefinite {
                    method: "PCG",
                    detail: format!(
                        "curvature pᵀKp = {curvature:.3e} <= 0 at iteration {iterations}: K is not positive definite"
                    ),
                });
            }
            let alpha = rz / curvature;
            for i in 0..n {
                x[i] += alpha * p[i];
                r[i] -= alpha * q[i];
            }
            iterations += 1;
            if norm(&r) <= tol * norm_b {
                // confirm on the true residual (the recurrence drifts by round-off)
                let residual = true_residual(k, &x, b, norm_b);
                if residual <= tol {
                    return Ok(PcgOutcome {
                        x,
                        iterations,
                        residual,
                    });
                }
                k.mul_vec(&x, &mut q);
                for i in 0..n {
                    r[i] = b[i] - q[i];
                }
            }
            self.apply(&r, &mut z);
            let rz_new = dot(&r, &z);
            let beta = rz_new / rz;
            rz = rz_new;
            for i in 0..n {
                p[i] = z[i] + beta * p[i];
            }
        }
    }
}

/// IC(0) of the lower triangle of `k` (right-looking, column by column).
fn ic0(k: &SparseMatrix) -> Result<Built, SolverError> {
    let n = k.n();
    let (cp, ri, kv) = (k.col_ptr(), k.row_idx(), k.values());
    let mut col_ptr = Vec::with_capacity(n + 1);
    let mut row_idx = Vec::new();
    let mut values = Vec::new();
    col_ptr.push(0);
    for j in 0..n {
        let mut has_diag = false;
        for p in cp[j]..cp[j + 1] {
            // rows are sorted: the diagonal is the first entry kept
            if ri[p] >= j {
                has_diag |= ri[p] == j;
                row_idx.push(ri[p]);
                values.push(kv[p]);
            }
        }
        if !has_diag {
            return Err(SolverError::NotPositiveDefinite {
                method: "IC(0)",
                detail: format!("no diagonal entry in column {j}"),
            });
        }
        col_ptr.push(row_idx.len());
    }
    // position of row i within column j, via a scatter array per column
    let mut pos = vec![usize::MAX; n];
    for kcol in 0..n {
        let (a, b) = (col_ptr[kcol], col_ptr[kcol + 1]);
        let d = values[a];
        if d.is_nan() || d <= 0.0 {
            return Err(SolverError::NotPositiveDefinite {
                method: "IC(0)",
                detail: format!("pivot {d:.3e} <= 0 at column {kcol}"),
            });
        }
        let l = d.sqrt();
        values[a] = l;
        for v in &mut values[a + 1..b] {
            *v /= l;
        }
        // update the later columns j in the pattern of column k
        for pj in a + 1..b {
            let j = row_idx[pj];
            let ljk = values[pj];
            let (ja, jb) = (col_ptr[j], col_ptr[j + 1]);
            for p in ja..jb {
                pos[row_idx[p]] = p;
            }
            for pi in pj..b {
                let target = pos[row_idx[pi]];
                if target != usize::MAX {
                    values[target] -= values[pi] * ljk;
                }
            }
            for p in ja..jb {
                pos[row_idx[p]] = usize::MAX;
            }
        }
    }
    Ok(Built::Ic0 {
        col_ptr,
        row_idx,
        values,
    })
}

/// ‖b‖ of a right-hand side `b` for a system of `n` unknowns, refused when
/// its length is not `n` or an entry is not finite.
pub(crate) fn checked_rhs_norm(n: usize, b: &[f64]) -> Result<f64, SolverError> {
    if b.len() != n {
        return Err(SolverError::RhsMismatch {
            expected: n,
            found: b.len(),
        });
    }
    if let Some(index) = b.iter().position(|v| !v.is_finite()) {
        return Err(SolverError::NonFinite {
            what: "right-hand side",
            index,
        });
    }
    Ok(norm(b))
}
