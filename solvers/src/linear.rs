//! One front for every linear solver of the implicit core: faer's Cholesky and LU
//! ([`DirectSolver`]), preconditioned conjugate gradients ([`Pcg`]) and, with the `ldl` feature,
//! sprs_ldl's LDLᵀ. A method that does not apply to the system at hand (PCG or LDLᵀ on an
//! unsymmetric or indefinite K, Cholesky on an unsymmetric one) falls back to faer's LU and
//! the fallback is counted and described in [`LinearSolver::warnings`]: never a silent wrong
//! answer.

use std::sync::Arc;
use std::time::Instant;

use crate::gmres::gmres;
use crate::matrix::Pattern;
use crate::pcg::{Pcg, PcgOptions};
use crate::{DirectSolver, FactorKind, SolverError, SolverOptions, SolverPolicy, SolverStats};
use crate::{MultifrontalLu, SparseMatrix};

/// Which linear solver [`LinearSolver`] uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Method {
    /// The multifrontal factorisation ([`Method::Multifrontal`]): Cholesky fronts when the
    /// caller says K is symmetric (LU fronts if it is not positive definite), LU fronts for an
    /// unsymmetric K, with its fallback to faer's LU; faer's Cholesky or LU where the options
    /// ask for one of faer's orderings or factorisations ([`SolverOptions::asks_for_faer`]).
    #[default]
    Auto,
    /// faer's sparse Cholesky (LU when K is unsymmetric or not positive definite, recorded).
    Cholesky,
    /// faer's sparse LU with partial pivoting.
    Lu,
    /// Preconditioned conjugate gradients (symmetric positive definite K only; LU otherwise,
    /// recorded).
    Pcg,
    /// sprs_ldl's LDLᵀ (feature `ldl`; symmetric K only; LU otherwise, recorded).
    Ldl,
    /// faer's LU, whose factors then serve the following systems of the same pattern
    /// (the next Newton iterations) as the preconditioner of GMRES ([`crate::gmres`]),
    /// to a relative residual of `REUSE_TOLERANCE` (1e-10); K is factorised anew when GMRES needs
    /// more than `REUSE_MAX_ITERATIONS` (12) steps or the pattern changes.
    LuReuse,
    /// Multifrontal factorisation on the symmetric pattern of K + Kᵀ ([`crate::MultifrontalLu`]:
    /// AMD ordering, Cholesky fronts for a symmetric positive definite K, else LU fronts with
    /// partial pivoting within each front; independent subtrees in parallel);
    /// every solve with LU fronts refines once, and a system whose refinement correction exceeds
    /// `MULTIFRONTAL_CORRECTION_LIMIT` (1e-4) is solved by faer's LU instead (recorded).
    Multifrontal,
}

/// Relative residual `‖b − K x‖/‖b‖` a GMRES solve of [`Method::LuReuse`] reaches (a fresh
/// LU reaches ~1e-13 on the tangents of the benchmarks).
pub const REUSE_TOLERANCE: f64 = 1e-10;

/// GMRES steps of [`Method::LuReuse`] after which the factors are judged too far from K
/// and K is factorised anew: each step costs a pair of triangular solves and a product
/// with K, a small fraction of a numeric factorisation.
pub const REUSE_MAX_ITERATIONS: usize = 12;

impl Method {
    /// Whether the method needs a symmetric K (it is refused or falls back otherwise).
    pub fn needs_symmetry(self) -> bool {
        matches!(self, Method::Cholesky | Method::Pcg | Method::Ldl)
    }

    /// Whether this build has the method (`ldl` needs the cargo feature `ldl`).
    pub fn available(self) -> bool {
        self != Method::Ldl || cfg!(feature = "ldl")
    }
}

/// Everything that configures a [`LinearSolver`].
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct LinearOptions {
    /// The method.
    pub method: Method,
    /// faer's options (also those of the LU fallback's singularity probe).
    pub direct: SolverOptions,
    /// Conjugate-gradient options (method [`Method::Pcg`]).
    pub pcg: PcgOptions,
}

/// What solved the last system.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Used {
    /// faer Cholesky.
    Cholesky,
    /// faer LU (asked for, or a fallback).
    Lu,
    /// Conjugate gradients.
    Pcg,
    /// sprs_ldl LDLᵀ.
    Ldl,
    /// GMRES preconditioned by the LU factors of an earlier K ([`Method::LuReuse`]).
    LuReused,
    /// The multifrontal factorisation, LU or Cholesky fronts ([`Method::Multifrontal`]).
    Multifrontal,
}

enum Active {
    Direct,
    /// [`Method::LuReuse`]: the factors of a matrix of the pattern `factored` precondition
    /// GMRES on `matrix`.
    Reused,
    Multifrontal,
    Fallback,
    Pcg(Pcg),
    #[cfg(feature = "ldl")]
    Ldl,
}

/// The linear solver of the implicit core, see the module documentation.
pub struct LinearSolver {
    options: LinearOptions,
    direct: DirectSolver,
    /// The LU used when PCG or LDLᵀ do not apply.
    fallback: DirectSolver,
    #[cfg(feature = "ldl")]
    ldl: crate::ldl::LdlSolver,
    multifrontal: MultifrontalLu,
    active: Option<Active>,
    /// The matrix last factorised (PCG needs it for its products and for a late fallback;
    /// [`Method::LuReuse`]: the present K, for the products of GMRES).
    matrix: Option<SparseMatrix>,
    /// [`Method::LuReuse`]: the pattern of the matrix whose LU factors `direct` holds.
    factored: Option<Arc<Pattern>>,
    own: SolverStats,
    first_fallback: Option<String>,
}

impl std::fmt::Debug for LinearSolver {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LinearSolver")
            .field("options", &self.options)
            .field("stats", &self.stats())
            .finish_non_exhaustive()
    }
}

impl LinearSolver {
    /// A solver with `options`. Errors: [`SolverError::Unsupported`] for a method this build
    /// lacks (`ldl` without the feature) or an LU ordering faer's supernodal LU cannot use.
    pub fn new(options: LinearOptions) -> Result<Self, SolverError> {
        if !options.method.available() {
            return Err(SolverError::Unsupported(
                "linear solver `ldl` needs mpm-solvers built with the cargo feature `ldl`".into(),
            ));
        }
        if options.method == Method::Lu {
            options
                .direct
                .check_lu()
                .map_err(SolverError::Unsupported)?;
        }
        let policy = match options.method {
            Method::Lu | Method::LuReuse => SolverPolicy::Lu,
            _ => SolverPolicy::Auto,
        };
        Ok(Self {
            options,
            direct: DirectSolver::with_options(policy, options.direct),
            fallback: DirectSolver::with_options(
                SolverPolicy::Lu,
                SolverOptions {
                    factorization: Default::default(),
                    ordering: Default::default(),
                    ..options.direct
                },
            ),
            #[cfg(feature = "ldl")]
            ldl: crate::ldl::LdlSolver::new(),
            multifrontal: MultifrontalLu::new(),
            active: None,
            matrix: None,
            factored: None,
            own: SolverStats::default(),
            first_fallback: None,
        })
    }

    /// The options given at construction.
    pub fn options(&self) -> &LinearOptions {
        &self.options
    }

    fn record_fallback(&mut self, why: String) {
        self.own.fallbacks += 1;
        if self.first_fallback.is_none() {
            self.first_fallback = Some(why);
        }
    }

    fn fall_back(&mut self, k: &SparseMatrix, why: String) -> Result<Used, SolverError> {
        self.record_fallback(why);
        self.fallback.factorize(k, false)?;
        self.active = Some(Active::Fallback);
        self.own.last_factor = Some(FactorKind::Lu);
        Ok(Used::Lu)
    }

    /// Prepares the solve of `K x = b`: factorises (direct methods) or builds the
    /// preconditioner (PCG). `symmetric` is the caller's knowledge that K is symmetric.
    ///
    /// Errors: those of the method, or of the LU it falls back to.
    pub fn factorize(&mut self, k: &SparseMatrix, symmetric: bool) -> Result<Used, SolverError> {
        self.active = None;
        self.matrix = None;
        let method = self.options.method;
        if method.needs_symmetry() && !symmetric {
            return self.fall_back(
                k,
                format!("{method:?} asked for an unsymmetric tangent: faer LU used instead"),
            );
        }
        match method {
            Method::Auto if !self.options.direct.asks_for_faer() => {
                self.factorize_multifrontal(k, symmetric)
            }
            Method::Auto | Method::Cholesky | Method::Lu => {
                let kind = self.direct.factorize(k, symmetric)?;
                self.active = Some(Active::Direct);
                self.own.factor_nnz = None;
                Ok(match kind {
                    FactorKind::Cholesky => Used::Cholesky,
                    FactorKind::Lu => Used::Lu,
                })
            }
            Method::Pcg => {
                let t = Instant::now();
                let built = Pcg::new(k, self.options.pcg);
                self.own.numeric_seconds += t.elapsed().as_secs_f64();
                self.own.numeric += 1;
                match built {
                    Ok(pcg) => {
                        self.own.factor_nnz = Some(pcg.nnz());
                        self.own.last_factor = None;
                        self.active = Some(Active::Pcg(pcg));
                        self.matrix = Some(k.clone());
                        Ok(Used::Pcg)
                    }
                    Err(e @ SolverError::NotPositiveDefinite { .. }) => {
                        self.fall_back(k, format!("{e}: faer LU used instead"))
                    }
                    Err(e) => Err(e),
                }
            }
            Method::Ldl => self.factorize_ldl(k),
            Method::Multifrontal => self.factorize_multifrontal(k, symmetric),
            Method::LuReuse => {
                let reusable = self
                    .factored
                    .as_ref()
                    .is_some_and(|f| Arc::ptr_eq(f, &k.pattern));
                if reusable {
                    self.matrix = Some(k.clone());
                    self.active = Some(Active::Reused);
                    Ok(Used::LuReused)
                } else {
                    self.factorize_lu_for_reuse(k)
                }
            }
        }
    }

    /// [`Method::Multifrontal`] (Cholesky fronts when K is symmetric and positive definite, LU
    /// fronts otherwise); faer's LU for a system with a zero pivot (recorded).
    fn factorize_multifrontal(
        &mut self,
        k: &SparseMatrix,
        symmetric: bool,
    ) -> Result<Used, SolverError> {
        let mf = &mut self.multifrontal;
        let before = (
            mf.symbolic_count,
            mf.symbolic_seconds,
            mf.numeric_seconds,
            mf.cholesky_failures,
        );
        let result = mf.factorize(k, symmetric);
        self.own.symbolic += mf.symbolic_count - before.0;
        self.own.symbolic_seconds += mf.symbolic_seconds - before.1;
        self.own.numeric_seconds += mf.numeric_seconds - before.2;
        // a Cholesky attempt that found K indefinite counts, as faer's does
        let failed_cholesky = mf.cholesky_failures - before.3;
        self.own.numeric += 1 + failed_cholesky;
        self.own.numeric_cholesky += failed_cholesky;
        match result {
            Ok(kind) => {
                match kind {
                    FactorKind::Cholesky => self.own.numeric_cholesky += 1,
                    FactorKind::Lu => self.own.numeric_lu += 1,
                }
                self.own.factor_nnz = Some(mf.factor_nnz);
                self.own.last_factor = Some(kind);
                self.active = Some(Active::Multifrontal);
                self.matrix = Some(k.clone());
                Ok(Used::Multifrontal)
            }
            Err(e @ SolverError::Singular { .. }) => {
                self.fall_back(k, format!("{e}: faer LU used instead"))
            }
            Err(e) => Err(e),
        }
    }

    /// [`Method::Multifrontal`]'s solve; faer's LU when the refinement rejects the
    /// factors (recorded).
    fn solve_multifrontal(&mut self, rhs: &mut [f64]) -> Result<Used, SolverError> {
        let k = self.matrix.take().ok_or(SolverError::NotFactorized)?;
        let t = Instant::now();
        let result = self.multifrontal.solve(&k, rhs);
        self.own.solve_seconds += t.elapsed().as_secs_f64();
        self.own.solves += 1;
        self.own.last_probe_error = self.multifrontal.last_correction;
        let used = match result {
            Ok(()) => Ok(Used::Multifrontal),
            Err(e @ SolverError::Singular { .. }) => {
                self.fall_back(&k, format!("{e}: faer LU used instead"))?;
                self.fallback.solve_in_place(rhs)?;
                Ok(Used::Lu)
            }
            Err(e) => Err(e),
        };
        self.matrix = Some(k);
        used
    }

    /// [`Method::LuReuse`]: factorise `k` and keep its pattern for the systems to come.
    fn factorize_lu_for_reuse(&mut self, k: &SparseMatrix) -> Result<Used, SolverError> {
        self.factored = None;
        self.direct.factorize(k, false)?;
        self.factored = Some(Arc::clone(&k.pattern));
        self.active = Some(Active::Direct);
        self.own.factor_nnz = None;
        Ok(Used::Lu)
    }

    /// [`Method::LuReuse`] with earlier factors: GMRES on `k`; if it needs more than
    /// `REUSE_MAX_ITERATIONS` (12) steps, `k` is factorised and solved directly.
    fn solve_reusing(&mut self, k: &SparseMatrix, rhs: &mut [f64]) -> Result<Used, SolverError> {
        let direct = &mut self.direct;
        let outcome = gmres(
            k,
            rhs,
            |z| direct.solve_in_place(z),
            REUSE_TOLERANCE,
            REUSE_MAX_ITERATIONS,
        );
        match outcome {
            Ok(out) => {
                self.own.reused_factors += 1;
                self.own.gmres_iterations += out.iterations;
                Ok(Used::LuReused)
            }
            Err(SolverError::NotConverged { iterations, .. }) => {
                self.own.gmres_iterations += iterations;
                self.own.gmres_refactorisations += 1;
                self.factorize_lu_for_reuse(k)?;
                self.direct.solve_in_place(rhs)?;
                Ok(Used::Lu)
            }
            Err(e) => Err(e),
        }
    }

    #[cfg(feature = "ldl")]
    fn factorize_ldl(&mut self, k: &SparseMatrix) -> Result<Used, SolverError> {
        let res = self.ldl.factorize(k);
        self.own.symbolic_seconds += self.ldl.last_symbolic_seconds;
        self.own.numeric_seconds += self.ldl.last_numeric_seconds;
        self.own.numeric += 1;
        self.own.symbolic += usize::from(self.ldl.last_symbolic_seconds > 0.0);
        match res {
            Ok(()) => {
                self.own.factor_nnz = self.ldl.nnz();
                self.active = Some(Active::Ldl);
                Ok(Used::Ldl)
            }
            Err(e @ SolverError::Singular { .. }) => {
                self.fall_back(k, format!("{e}: faer LU used instead"))
            }
            Err(e) => Err(e),
        }
    }

    #[cfg(not(feature = "ldl"))]
    fn factorize_ldl(&mut self, _k: &SparseMatrix) -> Result<Used, SolverError> {
        Err(SolverError::Unsupported(
            "linear solver `ldl` needs the cargo feature `ldl`".into(),
        ))
    }

    /// Solves `K x = rhs` for the K of the last [`LinearSolver::factorize`]; `x` overwrites
    /// `rhs`. A PCG solve that breaks down (`pᵀKp ≤ 0`) or does not converge falls back to LU
    /// (recorded). Returns what solved it.
    pub fn solve_in_place(&mut self, rhs: &mut [f64]) -> Result<Used, SolverError> {
        match self.active.as_ref().ok_or(SolverError::NotFactorized)? {
            Active::Fallback => {
                self.fallback.solve_in_place(rhs)?;
                Ok(Used::Lu)
            }
            Active::Direct => {
                self.direct.solve_in_place(rhs)?;
                Ok(match self.direct.factor_kind() {
                    Some(FactorKind::Cholesky) => Used::Cholesky,
                    _ => Used::Lu,
                })
            }
            Active::Multifrontal => self.solve_multifrontal(rhs),
            Active::Reused => {
                let k = self.matrix.take().ok_or(SolverError::NotFactorized)?;
                let used = self.solve_reusing(&k, rhs);
                self.matrix = Some(k);
                used
            }
            Active::Pcg(pcg) => {
                let k = self.matrix.as_ref().ok_or(SolverError::NotFactorized)?;
                let t = Instant::now();
                let res = pcg.solve(k, rhs);
                self.own.solve_seconds += t.elapsed().as_secs_f64();
                self.own.solves += 1;
                match res {
                    Ok(out) => {
                        self.own.pcg_iterations += out.iterations;
                        self.own.last_pcg_iterations = Some(out.iterations);
                        self.own.last_pcg_residual = Some(out.residual);
                        self.own.max_pcg_residual =
                            Some(self.own.max_pcg_residual.unwrap_or(0.0).max(out.residual));
                        rhs.copy_from_slice(&out.x);
                        Ok(Used::Pcg)
                    }
                    Err(
                        e @ (SolverError::NotPositiveDefinite { .. }
                        | SolverError::NotConverged { .. }),
                    ) => {
                        if let SolverError::NotConverged { iterations, .. } = e {
                            self.own.pcg_iterations += iterations;
                        }
                        let k = k.clone();
                        self.fall_back(&k, format!("{e}: faer LU used instead"))?;
                        self.fallback.solve_in_place(rhs)?;
                        Ok(Used::Lu)
                    }
                    Err(e) => Err(e),
                }
            }
            #[cfg(feature = "ldl")]
            Active::Ldl => {
                let t = Instant::now();
                let res = self.ldl.solve_in_place(rhs);
                self.own.solve_seconds += t.elapsed().as_secs_f64();
                self.own.solves += 1;
                res.map(|()| Used::Ldl)
            }
        }
    }

    /// Counters and cumulative seconds of every part (faer's direct solver, its LU fallback,
    /// PCG and LDLᵀ) summed; `factor_nnz` and the `last_*` fields are those of the last
    /// system.
    pub fn stats(&self) -> SolverStats {
        let d = self.direct.stats();
        let f = self.fallback.stats();
        let o = &self.own;
        let fallback_last = matches!(self.active, Some(Active::Fallback));
        SolverStats {
            symbolic: d.symbolic + f.symbolic + o.symbolic,
            numeric: d.numeric + f.numeric + o.numeric,
            numeric_cholesky: d.numeric_cholesky + o.numeric_cholesky,
            numeric_lu: d.numeric_lu + f.numeric_lu + o.numeric_lu,
            solves: d.solves + f.solves + o.solves,
            cholesky_fallbacks: d.cholesky_fallbacks,
            symbolic_seconds: d.symbolic_seconds + f.symbolic_seconds + o.symbolic_seconds,
            numeric_seconds: d.numeric_seconds + f.numeric_seconds + o.numeric_seconds,
            solve_seconds: d.solve_seconds + f.solve_seconds + o.solve_seconds,
            probe_seconds: d.probe_seconds + f.probe_seconds,
            last_factor: if fallback_last {
                f.last_factor
            } else {
                d.last_factor.or(o.last_factor)
            },
            last_pivot_ratio: d.last_pivot_ratio,
            last_probe_error: match self.active {
                Some(Active::Fallback) => f.last_probe_error,
                Some(Active::Multifrontal) => o.last_probe_error,
                _ => d.last_probe_error,
            },
            factor_nnz: match self.active {
                Some(Active::Fallback) => f.factor_nnz,
                Some(Active::Direct | Active::Reused) => d.factor_nnz,
                _ => o.factor_nnz,
            },
            last_variant: if fallback_last {
                f.last_variant
            } else {
                d.last_variant
            },
            pcg_iterations: o.pcg_iterations,
            last_pcg_iterations: o.last_pcg_iterations,
            last_pcg_residual: o.last_pcg_residual,
            max_pcg_residual: o.max_pcg_residual,
            fallbacks: o.fallbacks,
            reused_factors: o.reused_factors,
            gmres_iterations: o.gmres_iterations,
            gmres_refactorisations: o.gmres_refactorisations,
        }
    }

    /// Human-readable notes on fallbacks so far (empty when every system was solved by the
    /// method asked for).
    pub fn warnings(&self) -> Vec<String> {
        let mut w = Vec::new();
        let chol = self.direct.stats().cholesky_fallbacks;
        if chol > 0 && self.options.method == Method::Cholesky {
            w.push(format!(
                "Cholesky found the tangent not positive definite {chol} time(s): faer LU used instead"
            ));
        }
        if self.own.fallbacks > 0 {
            w.push(format!(
                "{:?} did not apply {} time(s) and faer LU was used instead; first: {}",
                self.options.method,
                self.own.fallbacks,
                self.first_fallback.as_deref().unwrap_or("")
            ));
        }
        w
    }
}
