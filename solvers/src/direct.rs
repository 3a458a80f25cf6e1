//! Sparse direct solver with symbolic-factorisation reuse (theory §3 "Linear system").

use std::sync::Arc;
use std::time::Instant;

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::perm::PermRef;
use faer::sparse::linalg::cholesky::{
    factorize_symbolic_cholesky, simplicial::SimplicialLltRef, supernodal::SupernodalLltRef,
    CholeskySymbolicParams, SymbolicCholesky, SymbolicCholeskyRaw, SymmetricOrdering,
};
use faer::sparse::linalg::lu::{
    factorize_symbolic_lu, simplicial::SimplicialLu, LuRef, LuSymbolicParams, NumericLu, SymbolicLu,
};
use faer::sparse::linalg::{LuError, SupernodalThreshold};
use faer::{Conj, MatMut, Par, Side};

use crate::matrix::{Pattern, SparseMatrix};
use crate::SolverError;

/// Which factorisation [`DirectSolver`] tries (theory §3 "Linear system": LU by default,
/// Cholesky only for elastic or associated perfectly plastic local scenes).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum SolverPolicy {
    /// Cholesky when the caller says the matrix is symmetric (SPD expected), else LU.
    #[default]
    Auto,
    /// Always Cholesky (the caller asserts symmetry: only the lower triangle is read), with the
    /// automatic LU fallback if K is not positive definite.
    Cholesky,
    /// Always LU with partial pivoting.
    Lu,
}

/// Factorisation actually in use.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FactorKind {
    /// Sparse LL^T (AMD ordering), lower triangle of K.
    Cholesky,
    /// Sparse LU with partial pivoting (COLAMD column ordering).
    Lu,
}

/// Supernodal or simplicial factorisation (faer chooses by a flop-per-non-zero ratio unless
/// told).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Factorization {
    /// faer's automatic choice (supernodal when the factor is dense enough to pay off).
    #[default]
    Auto,
    /// Always supernodal (dense blocks of columns, BLAS-3 kernels).
    Supernodal,
    /// Always simplicial (column by column, no dense blocks).
    Simplicial,
}

impl Factorization {
    fn threshold(self) -> SupernodalThreshold {
        match self {
            Factorization::Auto => SupernodalThreshold::AUTO,
            Factorization::Supernodal => SupernodalThreshold::FORCE_SUPERNODAL,
            Factorization::Simplicial => SupernodalThreshold::FORCE_SIMPLICIAL,
        }
    }
}

/// Fill-reducing ordering of the factorisation.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Ordering {
    /// faer's default: AMD for Cholesky, COLAMD for LU.
    #[default]
    Default,
    /// Approximate minimum degree on the pattern of K + Kᵀ (faer's `amd`). For LU only with
    /// [`Factorization::Simplicial`] (faer's supernodal LU always orders by COLAMD; a
    /// Cholesky's LU fallback then uses COLAMD).
    Amd,
    /// Column approximate minimum degree (faer's `colamd`); for Cholesky applied as a
    /// symmetric permutation.
    Colamd,
    /// No reordering (the engine's dof numbering). For LU only with
    /// [`Factorization::Simplicial`].
    Identity,
}

/// Tolerances of the singularity checks of [`DirectSolver::factorize`], and the factorisation
/// variant and ordering.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SolverOptions {
    /// Cholesky: K is reported singular when `min_i d_i / max_i d_i < pivot_ratio_tol`, with
    /// `d_i = L_ii^2` the pivots. For SPD K this ratio is `>= 1 / cond_2(K)`, so a smaller ratio
    /// proves `cond_2(K) > 1 / pivot_ratio_tol`. Default `1e-14`.
    pub pivot_ratio_tol: f64,
    /// LU: after each LU factorisation, solve `K x = K p` for a fixed vector `p` and report K
    /// singular when `max|x - p| / max|p| > probe_tol` (or non-finite). faer's LU does not stop on
    /// a zero pivot (it produces inf/NaN or huge finite factors), so this probe is what turns a
    /// singular K into an error. Costs one mat-vec and one solve. Default `true`.
    pub lu_probe: bool,
    /// Forward-error threshold of the LU probe. Default `1e-4`.
    pub probe_tol: f64,
    /// Supernodal or simplicial. Default [`Factorization::Auto`].
    pub factorization: Factorization,
    /// Fill-reducing ordering. Default [`Ordering::Default`].
    pub ordering: Ordering,
}

impl SolverOptions {
    /// `Err` with a reason if the LU of these options is not available (AMD or identity
    /// ordering need the simplicial LU: faer's supernodal LU orders by COLAMD only).
    pub fn check_lu(&self) -> Result<(), String> {
        match (self.ordering, self.factorization) {
            (Ordering::Amd | Ordering::Identity, Factorization::Auto | Factorization::Supernodal) => {
                Err(format!(
                    "LU with ordering {:?} needs factorization = simplicial (faer's supernodal LU orders by COLAMD only)",
                    self.ordering
                ))
            }
            _ => Ok(()),
        }
    }

    /// Whether these options choose one of faer's orderings or factorisation variants
    /// (anything but [`Ordering::Default`] and [`Factorization::Auto`]): then
    /// [`crate::Method::Auto`] factorises an unsymmetric K with faer's LU, as asked, rather
    /// than with the multifrontal LU, which has its own ordering and dense fronts.
    pub fn asks_for_faer(&self) -> bool {
        self.ordering != Ordering::Default || self.factorization != Factorization::Auto
    }
}

impl Default for SolverOptions {
    fn default() -> Self {
        Self {
            pivot_ratio_tol: 1e-14,
            lu_probe: true,
            probe_tol: 1e-4,
            factorization: Factorization::Auto,
            ordering: Ordering::Default,
        }
    }
}

/// Counters and cumulative wall-clock seconds of a [`DirectSolver`].
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SolverStats {
    /// Symbolic factorisations computed (Cholesky and LU together).
    pub symbolic: usize,
    /// Numeric factorisations attempted (a failed Cholesky followed by LU counts 2).
    pub numeric: usize,
    /// Numeric Cholesky factorisations attempted (those that found K not
    /// positive definite included).
    pub numeric_cholesky: usize,
    /// Numeric LU factorisations attempted.
    pub numeric_lu: usize,
    /// Calls of [`DirectSolver::solve_in_place`] (the LU probe is not counted).
    pub solves: usize,
    /// Times Cholesky failed (K not positive definite) and LU was used instead.
    pub cholesky_fallbacks: usize,
    /// Cumulative seconds spent in symbolic factorisations.
    pub symbolic_seconds: f64,
    /// Cumulative seconds spent in numeric factorisations (including the Cholesky pivot check).
    pub numeric_seconds: f64,
    /// Cumulative seconds spent in [`DirectSolver::solve_in_place`].
    pub solve_seconds: f64,
    /// Cumulative seconds spent in the LU singularity probe.
    pub probe_seconds: f64,
    /// Factorisation of the last successful `factorize` call.
    pub last_factor: Option<FactorKind>,
    /// Pivot ratio `min d_i / max d_i` of the last successful Cholesky factorisation.
    pub last_pivot_ratio: Option<f64>,
    /// Relative forward error of the last LU probe (a cheap conditioning indicator).
    pub last_probe_error: Option<f64>,
    /// Stored entries of the last factor: L for Cholesky (supernodal blocks in full), L + U for
    /// a simplicial LU; `None` for faer's supernodal LU, whose storage faer does not expose.
    pub factor_nnz: Option<usize>,
    /// Total conjugate-gradient iterations ([`crate::LinearSolver`] with PCG).
    pub pcg_iterations: usize,
    /// Iterations of the last PCG solve.
    pub last_pcg_iterations: Option<usize>,
    /// True relative residual `‖b − Kx‖/‖b‖` of the last PCG solve.
    pub last_pcg_residual: Option<f64>,
    /// Largest final relative residual of the PCG solves.
    pub max_pcg_residual: Option<f64>,
    /// Systems for which the method asked for did not apply and faer LU was used instead
    /// ([`crate::LinearSolver`]: PCG or LDLᵀ on an unsymmetric or indefinite K).
    pub fallbacks: usize,
    /// `"supernodal"`, `"simplicial"`, or `"auto"` (faer's own choice for its LU, not exposed).
    pub last_variant: Option<&'static str>,
    /// Systems solved by GMRES with the LU factors of an earlier matrix
    /// ([`crate::Method::LuReuse`]).
    pub reused_factors: usize,
    /// Total GMRES steps of [`crate::Method::LuReuse`] (those of the solves that gave up too).
    pub gmres_iterations: usize,
    /// Solves of [`crate::Method::LuReuse`] in which GMRES gave up and K was factorised anew.
    pub gmres_refactorisations: usize,
}

/// Sparse direct solver (faer, sequential: `Par::Seq`) that caches the symbolic factorisation
/// keyed on the sparsity pattern and reuses factor storage and workspace between
/// refactorisations (one per Newton iteration, \[D17\]).
pub struct DirectSolver {
    policy: SolverPolicy,
    options: SolverOptions,
    pattern: Option<Arc<Pattern>>,
    llt_symbolic: Option<SymbolicCholesky<usize>>,
    llt_values: Vec<f64>,
    llt_scratch: Option<MemBuffer>,
    lu_symbolic: Option<SymbolicLu<usize>>,
    lu_numeric: NumericLu<usize, f64>,
    lu_scratch: Option<MemBuffer>,
    /// LU with an ordering of our own (simplicial only): column permutation and factors.
    custom_lu: Option<CustomLu>,
    current: Option<FactorKind>,
    stats: SolverStats,
}

/// A simplicial LU with a column ordering chosen here (AMD or identity), through faer's
/// low-level simplicial API.
struct CustomLu {
    col_fwd: Vec<usize>,
    col_inv: Vec<usize>,
    row_fwd: Vec<usize>,
    row_inv: Vec<usize>,
    lu: SimplicialLu<usize, f64>,
    scratch: MemBuffer,
}

impl std::fmt::Debug for DirectSolver {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("DirectSolver")
            .field("policy", &self.policy)
            .field("options", &self.options)
            .field("n", &self.pattern.as_ref().map(|p| p.n()))
            .field("current", &self.current)
            .field("stats", &self.stats)
            .finish_non_exhaustive()
    }
}

/// Index of the first non-finite entry of `v`.
fn first_non_finite(v: &[f64]) -> Option<usize> {
    v.iter().position(|x| !x.is_finite())
}

fn faer_err(e: impl std::fmt::Debug) -> SolverError {
    SolverError::Faer(format!("{e:?}"))
}

impl DirectSolver {
    /// New solver with default [`SolverOptions`].
    pub fn new(policy: SolverPolicy) -> Self {
        Self::with_options(policy, SolverOptions::default())
    }

    /// New solver with explicit singularity-check tolerances.
    pub fn with_options(policy: SolverPolicy, options: SolverOptions) -> Self {
        Self {
            policy,
            options,
            pattern: None,
            llt_symbolic: None,
            llt_values: Vec::new(),
            llt_scratch: None,
            lu_symbolic: None,
            lu_numeric: NumericLu::new(),
            lu_scratch: None,
            custom_lu: None,
            current: None,
            stats: SolverStats::default(),
        }
    }

    /// The policy given at construction.
    pub fn policy(&self) -> SolverPolicy {
        self.policy
    }

    /// The singularity-check options.
    pub fn options(&self) -> &SolverOptions {
        &self.options
    }

    /// Factorisation currently held, if the last `factorize` succeeded.
    pub fn factor_kind(&self) -> Option<FactorKind> {
        self.current
    }

    /// Counters and timings.
    pub fn stats(&self) -> &SolverStats {
        &self.stats
    }

    /// Drops the cached symbolic factorisations (the next `factorize` recomputes them).
    pub fn reset_symbolic(&mut self) {
        self.pattern = None;
        self.llt_symbolic = None;
        self.llt_scratch = None;
        self.lu_symbolic = None;
        self.lu_scratch = None;
        self.lu_numeric = NumericLu::new();
        self.custom_lu = None;
        self.current = None;
    }

    /// Numeric factorisation of `k`. The symbolic factorisation is reused when the pattern is the
    /// same as last time (same [`Arc`] or equal `col_ptr`/`row_idx`), else recomputed.
    ///
    /// `symmetric` is the caller's knowledge that K is symmetric (elastic, or associated
    /// perfectly plastic local: theory §3 "Linear system"); with [`SolverPolicy::Auto`] it selects
    /// Cholesky. If Cholesky fails because K is not positive definite, LU is used instead and
    /// [`SolverStats::cholesky_fallbacks`] is incremented (Cholesky is tried again next call).
    ///
    /// Errors: [`SolverError::NonFinite`] (NaN/inf in K, checked before factorising),
    /// [`SolverError::Singular`] (structurally singular LU, Cholesky pivot ratio below
    /// [`SolverOptions::pivot_ratio_tol`], or the LU probe failing), [`SolverError::Faer`].
    /// On error no factorisation is held and [`DirectSolver::solve_in_place`] returns
    /// [`SolverError::NotFactorized`].
    pub fn factorize(
        &mut self,
        k: &SparseMatrix,
        symmetric: bool,
    ) -> Result<FactorKind, SolverError> {
        self.current = None;
        if k.n() == 0 {
            return Err(SolverError::EmptySystem);
        }
        if let Some(index) = first_non_finite(k.values()) {
            return Err(SolverError::NonFinite {
                what: "matrix values",
                index,
            });
        }
        let same = self.pattern.as_ref().is_some_and(|p| p.same_as(&k.pattern));
        if !same {
            self.reset_symbolic();
            self.pattern = Some(k.pattern.clone());
        }
        let try_cholesky = match self.policy {
            SolverPolicy::Auto => symmetric,
            SolverPolicy::Cholesky => true,
            SolverPolicy::Lu => false,
        };
        if try_cholesky {
            match self.factorize_llt(k)? {
                true => {
                    self.current = Some(FactorKind::Cholesky);
                    self.stats.last_factor = self.current;
                    return Ok(FactorKind::Cholesky);
                }
                false => self.stats.cholesky_fallbacks += 1,
            }
        }
        self.factorize_lu(k)?;
        self.current = Some(FactorKind::Lu);
        self.stats.last_factor = self.current;
        Ok(FactorKind::Lu)
    }

    /// Cholesky attempt: `Ok(true)` success, `Ok(false)` not positive definite (fall back).
    fn factorize_llt(&mut self, k: &SparseMatrix) -> Result<bool, SolverError> {
        if self.llt_symbolic.is_none() {
            let t = Instant::now();
            let params = CholeskySymbolicParams {
                supernodal_flop_ratio_threshold: self.options.factorization.threshold(),
                ..Default::default()
            };
            // faer's `SymmetricOrdering::Identity` skips the conversion of the full-storage
            // input to one triangle, so the identity is passed as a custom permutation
            let custom = match self.options.ordering {
                Ordering::Colamd => Some(colamd_order(k)?),
                Ordering::Identity => Some(((0..k.n()).collect(), (0..k.n()).collect())),
                _ => None,
            };
            let ordering = match &custom {
                Some((fwd, inv)) => {
                    SymmetricOrdering::Custom(PermRef::new_checked(fwd, inv, k.n()))
                }
                None => SymmetricOrdering::Amd,
            };
            let sym = factorize_symbolic_cholesky(
                k.pattern.symbolic.as_ref(),
                Side::Lower,
                ordering,
                params,
            )
            .map_err(faer_err)?;
            let req = sym.factorize_numeric_llt_scratch::<f64>(Par::Seq, Default::default());
            self.llt_scratch = Some(MemBuffer::try_new(req).map_err(faer_err)?);
            self.llt_values = vec![0.0; sym.len_val()];
            self.llt_symbolic = Some(sym);
            self.stats.symbolic += 1;
            self.stats.symbolic_seconds += t.elapsed().as_secs_f64();
        }
        let (Some(sym), Some(scratch)) = (&self.llt_symbolic, &mut self.llt_scratch) else {
            unreachable!("symbolic Cholesky computed above");
        };
        let t = Instant::now();
        self.stats.numeric += 1;
        self.stats.numeric_cholesky += 1;
        self.llt_values.fill(0.0);
        let res = sym.factorize_numeric_llt::<f64>(
            &mut self.llt_values,
            k.as_faer(),
            Side::Lower,
            Default::default(),
            Par::Seq,
            MemStack::new(scratch),
            Default::default(),
        );
        let out = match res {
            Ok(_) => {
                self.stats.factor_nnz = Some(sym.len_val());
                self.stats.last_variant = Some(match sym.raw() {
                    SymbolicCholeskyRaw::Simplicial(_) => "simplicial",
                    SymbolicCholeskyRaw::Supernodal(_) => "supernodal",
                });
                let ratio = llt_pivot_ratio(sym, &self.llt_values);
                self.stats.last_pivot_ratio = Some(ratio);
                if ratio.is_nan() || ratio < self.options.pivot_ratio_tol {
                    Err(SolverError::Singular {
                        factor: FactorKind::Cholesky,
                        detail: format!(
                            "pivot ratio min/max = {ratio:.3e} < {:.1e} (condition number > {:.1e})",
                            self.options.pivot_ratio_tol,
                            1.0 / self.options.pivot_ratio_tol
                        ),
                        unknown: None,
                    })
                } else {
                    Ok(true)
                }
            }
            // NonPositivePivot: not (numerically) positive definite
            Err(_) => Ok(false),
        };
        self.stats.numeric_seconds += t.elapsed().as_secs_f64();
        out
    }

    fn factorize_lu(&mut self, k: &SparseMatrix) -> Result<(), SolverError> {
        // the simplicial LU goes through faer's low-level API, which takes any column
        // ordering and exposes the factors' size
        // (a Cholesky fallback whose ordering the supernodal LU cannot use gets faer's COLAMD)
        match self.options.factorization {
            Factorization::Simplicial => self.factorize_custom_lu(k)?,
            _ => self.factorize_faer_lu(k)?,
        }
        self.lu_probe(k)
    }

    /// Simplicial LU with a COLAMD, AMD (on K + Kᵀ) or identity column ordering.
    fn factorize_custom_lu(&mut self, k: &SparseMatrix) -> Result<(), SolverError> {
        let n = k.n();
        if self.custom_lu.is_none() {
            let t = Instant::now();
            let (col_fwd, col_inv) = match self.options.ordering {
                Ordering::Amd => amd_order(k)?,
                Ordering::Identity => ((0..n).collect(), (0..n).collect()),
                Ordering::Default | Ordering::Colamd => colamd_order(k)?,
            };
            let req =
                faer::sparse::linalg::lu::simplicial::factorize_simplicial_numeric_lu_scratch::<
                    usize,
                    f64,
                >(n, n)
                .or(
                    faer::sparse::linalg::lu::simplicial::solve_in_place_scratch::<usize, f64>(
                        n,
                        1,
                        Par::Seq,
                    ),
                );
            self.custom_lu = Some(CustomLu {
                col_fwd,
                col_inv,
                row_fwd: vec![0; n],
                row_inv: vec![0; n],
                lu: SimplicialLu::new(),
                scratch: MemBuffer::try_new(req).map_err(faer_err)?,
            });
            self.stats.symbolic += 1;
            self.stats.symbolic_seconds += t.elapsed().as_secs_f64();
        }
        let Some(c) = self.custom_lu.as_mut() else {
            unreachable!("custom LU prepared above");
        };
        let t = Instant::now();
        self.stats.numeric += 1;
        self.stats.numeric_lu += 1;
        let res = faer::sparse::linalg::lu::simplicial::factorize_simplicial_numeric_lu(
            &mut c.row_fwd,
            &mut c.row_inv,
            &mut c.lu,
            k.as_faer(),
            PermRef::new_checked(&c.col_fwd, &c.col_inv, n),
            MemStack::new(&mut c.scratch),
        );
        self.stats.numeric_seconds += t.elapsed().as_secs_f64();
        lu_result(res)?;
        self.stats.factor_nnz =
            Some(c.lu.l_factor_unsorted().compute_nnz() + c.lu.u_factor_unsorted().compute_nnz());
        self.stats.last_variant = Some("simplicial");
        Ok(())
    }

    fn factorize_faer_lu(&mut self, k: &SparseMatrix) -> Result<(), SolverError> {
        if self.lu_symbolic.is_none() {
            let t = Instant::now();
            let params = LuSymbolicParams {
                supernodal_flop_ratio_threshold: self.options.factorization.threshold(),
                ..Default::default()
            };
            let sym =
                factorize_symbolic_lu(k.pattern.symbolic.as_ref(), params).map_err(faer_err)?;
            let req = sym.factorize_numeric_lu_scratch::<f64>(Par::Seq, Default::default());
            self.lu_scratch = Some(MemBuffer::try_new(req).map_err(faer_err)?);
            self.lu_symbolic = Some(sym);
            self.stats.symbolic += 1;
            self.stats.symbolic_seconds += t.elapsed().as_secs_f64();
        }
        let (Some(sym), Some(scratch)) = (&self.lu_symbolic, &mut self.lu_scratch) else {
            unreachable!("symbolic LU computed above");
        };
        let t = Instant::now();
        self.stats.numeric += 1;
        self.stats.numeric_lu += 1;
        let res = sym.factorize_numeric_lu::<f64>(
            &mut self.lu_numeric,
            k.as_faer(),
            Par::Seq,
            MemStack::new(scratch),
            Default::default(),
        );
        self.stats.numeric_seconds += t.elapsed().as_secs_f64();
        lu_result(res.map(|_| ()))?;
        // faer keeps the symbolic LU's variant and the factors' storage private
        self.stats.last_variant = Some(match self.options.factorization {
            Factorization::Supernodal => "supernodal",
            _ => "auto",
        });
        self.stats.factor_nnz = None;
        Ok(())
    }

    /// The LU singularity probe of [`SolverOptions::lu_probe`].
    fn lu_probe(&mut self, k: &SparseMatrix) -> Result<(), SolverError> {
        if self.options.lu_probe {
            let t = Instant::now();
            let n = k.n();
            let p: Vec<f64> = (0..n)
                .map(|i| 1.0 + ((i * 7919) % 31) as f64 / 31.0)
                .collect();
            let mut x = vec![0.0; n];
            k.mul_vec(&p, &mut x);
            self.lu_solve(&mut x);
            for (xi, pi) in x.iter_mut().zip(&p) {
                *xi -= pi;
            }
            // the deviation x − p is largest at `unknown` (or first not finite there)
            let unknown = crate::norms::largest_entry(&x);
            let err = unknown.map_or(0.0, |u| x[u].abs() / 2.0);
            self.stats.last_probe_error = Some(err);
            self.stats.probe_seconds += t.elapsed().as_secs_f64();
            if err.is_nan() || err > self.options.probe_tol {
                return Err(SolverError::Singular {
                    factor: FactorKind::Lu,
                    detail: format!(
                        "probe solve K x = K p has relative error {err:.3e} > {:.1e}",
                        self.options.probe_tol
                    ),
                    unknown,
                });
            }
        }
        Ok(())
    }

    fn lu_solve(&self, rhs: &mut [f64]) {
        let n = rhs.len();
        if let Some(c) = &self.custom_lu {
            let mut buf = MemBuffer::new(
                faer::sparse::linalg::lu::simplicial::solve_in_place_scratch::<usize, f64>(
                    n,
                    1,
                    Par::Seq,
                ),
            );
            c.lu.solve_in_place_with_conj(
                PermRef::new_checked(&c.row_fwd, &c.row_inv, n),
                PermRef::new_checked(&c.col_fwd, &c.col_inv, n),
                Conj::No,
                MatMut::from_column_major_slice_mut(rhs, n, 1),
                Par::Seq,
                MemStack::new(&mut buf),
            );
            return;
        }
        let sym = self.lu_symbolic.as_ref().expect("LU symbolic present");
        let mut buf = MemBuffer::new(sym.solve_in_place_scratch::<f64>(1, Par::Seq));
        LuRef::new_unchecked(sym, &self.lu_numeric).solve_in_place_with_conj(
            Conj::No,
            MatMut::from_column_major_slice_mut(rhs, n, 1),
            Par::Seq,
            MemStack::new(&mut buf),
        );
    }

    fn llt_solve(&self, rhs: &mut [f64]) {
        let sym = self
            .llt_symbolic
            .as_ref()
            .expect("Cholesky symbolic present");
        let n = rhs.len();
        let mut buf = MemBuffer::new(sym.solve_in_place_scratch::<f64>(1, Par::Seq));
        faer::sparse::linalg::cholesky::LltRef::new(sym, &self.llt_values)
            .solve_in_place_with_conj(
                Conj::No,
                MatMut::from_column_major_slice_mut(rhs, n, 1),
                Par::Seq,
                MemStack::new(&mut buf),
            );
    }

    /// Solves `K x = rhs` with the current factorisation; `x` overwrites `rhs`.
    ///
    /// Errors: [`SolverError::NotFactorized`], [`SolverError::RhsMismatch`],
    /// [`SolverError::NonFinite`] (NaN/inf in `rhs`), [`SolverError::Singular`] if the solution
    /// contains NaN/inf (then `rhs` holds garbage).
    pub fn solve_in_place(&mut self, rhs: &mut [f64]) -> Result<(), SolverError> {
        let kind = self.current.ok_or(SolverError::NotFactorized)?;
        let n = self.pattern.as_ref().map_or(0, |p| p.n());
        if rhs.len() != n {
            return Err(SolverError::RhsMismatch {
                expected: n,
                found: rhs.len(),
            });
        }
        if let Some(index) = first_non_finite(rhs) {
            return Err(SolverError::NonFinite {
                what: "right-hand side",
                index,
            });
        }
        let t = Instant::now();
        match kind {
            FactorKind::Cholesky => self.llt_solve(rhs),
            FactorKind::Lu => self.lu_solve(rhs),
        }
        self.stats.solves += 1;
        self.stats.solve_seconds += t.elapsed().as_secs_f64();
        if let Some(i) = first_non_finite(rhs) {
            return Err(SolverError::Singular {
                factor: kind,
                detail: format!("solution is not finite (first at dof {i})"),
                unknown: Some(i),
            });
        }
        Ok(())
    }

    /// Convenience: factorise `k` and solve one right-hand side, returning the solution.
    pub fn solve(
        &mut self,
        k: &SparseMatrix,
        symmetric: bool,
        rhs: &[f64],
    ) -> Result<Vec<f64>, SolverError> {
        self.factorize(k, symmetric)?;
        let mut x = rhs.to_vec();
        self.solve_in_place(&mut x)?;
        Ok(x)
    }
}

/// Maps faer's LU errors to [`SolverError`].
fn lu_result(res: Result<(), LuError>) -> Result<(), SolverError> {
    match res {
        Ok(()) => Ok(()),
        Err(LuError::SymbolicSingular { index }) => Err(SolverError::Singular {
            factor: FactorKind::Lu,
            detail: format!("no pivot available at elimination step {index}"),
            unknown: None,
        }),
        Err(LuError::Generic(e)) => Err(faer_err(e)),
    }
}

/// AMD ordering of the pattern of K + Kᵀ: (forward, inverse) permutation.
pub(crate) fn amd_order(k: &SparseMatrix) -> Result<(Vec<usize>, Vec<usize>), SolverError> {
    use faer::sparse::linalg::amd;
    let n = k.n();
    let (mut fwd, mut inv) = (vec![0usize; n], vec![0usize; n]);
    let req = amd::order_maybe_unsorted_scratch::<usize>(n, k.nnz());
    let mut buf = MemBuffer::try_new(req).map_err(faer_err)?;
    amd::order_maybe_unsorted(
        &mut fwd,
        &mut inv,
        k.pattern.symbolic.as_ref(),
        Default::default(),
        MemStack::new(&mut buf),
    )
    .map_err(faer_err)?;
    Ok((fwd, inv))
}

/// COLAMD column ordering of K: (forward, inverse) permutation.
pub(crate) fn colamd_order(k: &SparseMatrix) -> Result<(Vec<usize>, Vec<usize>), SolverError> {
    use faer::sparse::linalg::colamd;
    let n = k.n();
    let (mut fwd, mut inv) = (vec![0usize; n], vec![0usize; n]);
    let req = colamd::order_scratch::<usize>(n, n, k.nnz());
    let mut buf = MemBuffer::try_new(req).map_err(faer_err)?;
    colamd::order(
        &mut fwd,
        &mut inv,
        k.pattern.symbolic.as_ref(),
        Default::default(),
        MemStack::new(&mut buf),
    )
    .map_err(faer_err)?;
    Ok((fwd, inv))
}

/// `min_i L_ii^2 / max_i L_ii^2` of a Cholesky factor (0 if a pivot is not finite).
fn llt_pivot_ratio(sym: &SymbolicCholesky<usize>, values: &[f64]) -> f64 {
    let (mut lo, mut hi) = (f64::INFINITY, 0.0f64);
    let mut visit = |l: f64| {
        let d = l * l;
        if !d.is_finite() {
            lo = 0.0;
        }
        lo = lo.min(d);
        hi = hi.max(d);
    };
    match sym.raw() {
        SymbolicCholeskyRaw::Simplicial(s) => {
            // The diagonal is the first stored entry of each column of L.
            let _ = SimplicialLltRef::new(s, values);
            let cp = s.col_ptr();
            for j in 0..s.ncols() {
                visit(values[cp[j]]);
            }
        }
        SymbolicCholeskyRaw::Supernodal(s) => {
            let l = SupernodalLltRef::new(s, values);
            for k in 0..s.n_supernodes() {
                let m = l.supernode(k).val();
                for j in 0..m.ncols() {
                    visit(m[(j, j)]);
                }
            }
        }
    }
    if hi > 0.0 {
        lo / hi
    } else {
        0.0
    }
}
