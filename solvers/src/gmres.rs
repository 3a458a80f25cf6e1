//! Right-preconditioned GMRES (Saad & Schultz 1986) for `K x = b`, used to solve a
//! Newton iteration's system with the LU factors of an earlier matrix of the same pattern
//! as the preconditioner ([`crate::Method::LuReuse`]): when K changes little between
//! iterations, a few Krylov steps (one product with K and one pair of triangular solves
//! each) replace a numeric factorisation.
//!
//! Hand-written because faer 0.24 has no GMRES: its matrix-free Krylov solvers
//! (`faer::matrix_free`) are conjugate gradients (symmetric positive definite only), BiCGSTAB
//! (another method, two products and two preconditioner solves a step, no minimal-residual
//! property) and LSMR (least squares).

use crate::norms::{dot, norm, true_residual};
use crate::{SolverError, SparseMatrix};

/// The step from which [`gmres`] judges whether it will converge in time.
pub const EARLY_CHECK: usize = 4;

/// The result of a converged [`gmres`] solve.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GmresOutcome {
    /// Krylov iterations done.
    pub iterations: usize,
    /// True relative residual `‖b − K x‖ / ‖b‖` of the returned x.
    pub residual: f64,
}

/// Solves `K x = b` by GMRES without restart, right-preconditioned by `precondition`
/// (`z ← M⁻¹ z` in place), from x = 0; `x` overwrites `rhs`. Stops when the residual
/// estimate reaches `tolerance · ‖b‖`, then checks the true residual. Gives up early, from
/// the `EARLY_CHECK` (4)-th step on, when the mean contraction of the residual so far
/// predicts more than `max_iterations` steps (a poor preconditioner costs a few steps,
/// not `max_iterations`).
///
/// # Errors
/// [`SolverError::NotConverged`] (with `rhs` unchanged) when `max_iterations` Krylov
/// steps do not reach the tolerance (or are predicted not to), or the true residual
/// misses it by more than 10×; the preconditioner's errors.
pub fn gmres(
    k: &SparseMatrix,
    rhs: &mut [f64],
    mut precondition: impl FnMut(&mut [f64]) -> Result<(), SolverError>,
    tolerance: f64,
    max_iterations: usize,
) -> Result<GmresOutcome, SolverError> {
    let n = k.n();
    let b_norm = norm(rhs);
    if b_norm == 0.0 {
        return Ok(GmresOutcome {
            iterations: 0,
            residual: 0.0,
        });
    }
    let not_converged = |iterations: usize, residual: f64| SolverError::NotConverged {
        method: "GMRES",
        iterations,
        residual,
        tolerance,
    };
    // Arnoldi basis V, Hessenberg columns rotated to upper triangular R, rotated g = β e₁
    let mut basis: Vec<Vec<f64>> = vec![rhs.iter().map(|v| v / b_norm).collect()];
    let mut columns: Vec<Vec<f64>> = Vec::new();
    let mut rotations: Vec<(f64, f64)> = Vec::new();
    let mut g = vec![b_norm];
    let mut z = vec![0.0; n];
    let mut w = vec![0.0; n];
    let mut estimate = b_norm;
    while columns.len() < max_iterations && estimate > tolerance * b_norm && estimate.is_finite() {
        let j = columns.len();
        z.copy_from_slice(&basis[j]);
        precondition(&mut z)?;
        k.mul_vec(&z, &mut w);
        // modified Gram–Schmidt
        let mut h = Vec::with_capacity(j + 2);
        for v in &basis {
            let hij = dot(&w, v);
            for (wi, vi) in w.iter_mut().zip(v) {
                *wi -= hij * vi;
            }
            h.push(hij);
        }
        let next = norm(&w);
        h.push(next);
        for (i, &(c, s)) in rotations.iter().enumerate() {
            let (a, b) = (h[i], h[i + 1]);
            h[i] = c * a + s * b;
            h[i + 1] = -s * a + c * b;
        }
        let (a, b) = (h[j], h[j + 1]);
        let r = a.hypot(b);
        let (c, s) = if r == 0.0 { (1.0, 0.0) } else { (a / r, b / r) };
        h[j] = r;
        h.truncate(j + 1);
        rotations.push((c, s));
        g.push(-s * g[j]);
        g[j] *= c;
        estimate = g[j + 1].abs();
        columns.push(h);
        let steps = columns.len();
        if steps >= EARLY_CHECK && estimate > tolerance * b_norm {
            // ‖r_j‖ ≈ ρ^j ‖b‖: steps to the tolerance at the mean contraction ρ so far
            let contraction = (estimate / b_norm).powf(1.0 / steps as f64);
            let predicted = tolerance.ln() / contraction.ln();
            if contraction >= 1.0 || predicted > max_iterations as f64 {
                return Err(not_converged(steps, estimate / b_norm));
            }
        }
        if next == 0.0 {
            break; // the Krylov space holds the solution
        }
        basis.push(w.iter().map(|v| v / next).collect());
    }
    let iterations = columns.len();
    if estimate.is_nan() || estimate > tolerance * b_norm {
        return Err(not_converged(iterations, estimate / b_norm));
    }
    // R y = g, then x = M⁻¹ V y
    let mut y = vec![0.0; iterations];
    for i in (0..iterations).rev() {
        let tail: f64 = (i + 1..iterations).map(|c| columns[c][i] * y[c]).sum();
        y[i] = (g[i] - tail) / columns[i][i];
    }
    z.fill(0.0);
    for (v, yi) in basis.iter().zip(&y) {
        for (zi, vi) in z.iter_mut().zip(v) {
            *zi += yi * vi;
        }
    }
    precondition(&mut z)?;
    let residual = true_residual(k, &z, rhs, b_norm);
    if residual.is_nan() || residual > 10.0 * tolerance {
        // too large, or NaN (a singular R, a preconditioner gone wrong)
        return Err(not_converged(iterations, residual));
    }
    rhs.copy_from_slice(&z);
    Ok(GmresOutcome {
        iterations,
        residual,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{DirectSolver, SolverPolicy};

    /// An unsymmetric convection–diffusion matrix on a line of `n` unknowns, scaled by `scale`
    /// on the diagonal.
    fn convection_diffusion(n: usize, scale: f64) -> SparseMatrix {
        let mut t = Vec::new();
        for i in 0..n {
            t.push((i, i, 2.5 * scale));
            if i > 0 {
                t.push((i, i - 1, -1.4));
            }
            if i + 1 < n {
                t.push((i, i + 1, -0.6));
            }
        }
        SparseMatrix::from_triplets(n, &t).unwrap()
    }

    fn rhs(n: usize) -> Vec<f64> {
        (0..n).map(|i| ((i * 7919) % 13) as f64 - 6.0).collect()
    }

    fn residual(k: &SparseMatrix, x: &[f64], b: &[f64]) -> f64 {
        true_residual(k, x, b, norm(b))
    }

    #[test]
    fn exact_preconditioner_converges_in_one_iteration() {
        let k = convection_diffusion(200, 1.0);
        let mut lu = DirectSolver::new(SolverPolicy::Lu);
        lu.factorize(&k, false).unwrap();
        let b = rhs(200);
        let mut x = b.clone();
        let out = gmres(&k, &mut x, |z| lu.solve_in_place(z), 1e-12, 20).unwrap();
        assert_eq!(out.iterations, 1);
        assert!(residual(&k, &x, &b) < 1e-13, "{out:?}");
    }

    #[test]
    fn factors_of_a_nearby_matrix_converge_in_a_few_iterations() {
        // the factors of M = K with a 10 % larger diagonal precondition K:
        // ‖I − K M⁻¹‖ ≤ 0.25 ‖M⁻¹‖ ≤ 0.25 / 0.75 (M diagonally dominant by 0.75)
        let (k, earlier) = (
            convection_diffusion(500, 1.0),
            convection_diffusion(500, 1.1),
        );
        let mut lu = DirectSolver::new(SolverPolicy::Lu);
        lu.factorize(&earlier, false).unwrap();
        let b = rhs(500);
        let mut x = b.clone();
        let out = gmres(&k, &mut x, |z| lu.solve_in_place(z), 1e-10, 50).unwrap();
        println!("{out:?}");
        assert!(out.iterations <= 12, "{out:?}");
        assert!(residual(&k, &x, &b) <= 1e-9);
        // without a preconditioner the same tolerance takes many more steps
        let mut plain = b.clone();
        let unpreconditioned = gmres(&k, &mut plain, |_| Ok(()), 1e-10, 500).unwrap();
        assert!(unpreconditioned.iterations > 3 * out.iterations);
    }

    #[test]
    fn too_few_iterations_leave_the_right_hand_side_and_report_it() {
        let k = convection_diffusion(300, 1.0);
        let b = rhs(300);
        let mut x = b.clone();
        let err = gmres(&k, &mut x, |_| Ok(()), 1e-12, 3).unwrap_err();
        assert!(
            matches!(err, SolverError::NotConverged { iterations: 3, .. }),
            "{err:?}"
        );
        assert_eq!(x, b);
        // unpreconditioned, 1e-12 takes ~40 steps: with 20 allowed it gives up at the check
        let err = gmres(&k, &mut x, |_| Ok(()), 1e-12, 20).unwrap_err();
        assert!(
            matches!(
                err,
                SolverError::NotConverged {
                    iterations: EARLY_CHECK,
                    ..
                }
            ),
            "{err:?}"
        );
    }

    #[test]
    fn a_preconditioner_that_gives_nan_is_reported_not_returned() {
        let k = convection_diffusion(50, 1.0);
        let b = rhs(50);
        let mut x = b.clone();
        let err = gmres(
            &k,
            &mut x,
            |z| {
                z.fill(f64::NAN);
                Ok(())
            },
            1e-10,
            12,
        )
        .unwrap_err();
        assert!(matches!(err, SolverError::NotConverged { .. }), "{err:?}");
        assert_eq!(x, b);
    }
}
