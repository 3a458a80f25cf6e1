//! Multifrontal LU (and Cholesky) on the symmetric pattern of `K + Kᵀ` (issue 15).
//!
//! The tangents of the implicit core are unsymmetric in their values (non-associated flow,
//! nonlocal coupling), while their pattern comes from element blocks that couple nodes both
//! ways. faer's sparse LU pivots across the whole matrix, so its symbolic step must size the
//! factors by the Cholesky factor of `KᵀK` (COLAMD): on the footing's tangent
//! (n = 22,700) that bound holds 14.5 M entries and the numeric LU costs 5× the Cholesky of
//! a symmetric matrix of the same pattern. This module factorises on the pattern of
//! `K + Kᵀ` instead:
//!
//! * **Symbolic** (once per pattern): AMD ordering, elimination tree and supernodes of the
//!   Cholesky factor of `K + Kᵀ`, from faer's supernodal symbolic Cholesky. Every supernode
//!   `s` (columns `b..e`, off-diagonal rows `R_s`) becomes a *front*, a dense matrix of order
//!   `m = (e − b) + |R_s|` over the indices `b..e ∪ R_s`.
//! * **Numeric**, children before parents: a front sums the entries of `K` whose smaller
//!   (permuted) index lies in `b..e` and the contribution blocks of its children (extend-add),
//!
//!   ```text
//!       F = [F11 F12]    P F11 = L11 U11   (partial pivoting among the rows b..e only)
//!           [F21 F22]    U12 = L11⁻¹ P F12,  L21 = F21 U11⁻¹,  C = F22 − L21 U12,
//!   ```
//!
//!   and hands `C` to its parent. For a symmetric K the fronts are factorised by Cholesky
//!   instead (`F11 = L11 L11ᵀ`, `L21 = F21 L11⁻ᵀ`, lower triangle of `C = F22 − L21 L21ᵀ`:
//!   half the flops), and by LU if K proves not positive definite.
//! * **Accuracy**: pivots are never delayed to the parent, so LU factors can be less
//!   accurate than faer's (on the softening tangents of the finest nonlocal biaxial run a
//!   plain solve had a forward error of up to 1.2e-7 where faer's LU had 1e-11). Every
//!   solve with LU factors makes one step of iterative refinement, after which the error
//!   was at most 1.9e-11 there. A correction larger than [`CORRECTION_LIMIT`] rejects the
//!   factors, and the caller ([`crate::LinearSolver`]) solves that system with faer's LU.
//! * **Parallel**: independent subtrees of the elimination tree are factorised as rayon
//!   tasks, each on one thread; a front above them starts once its children are done, so the
//!   top fronts of independent branches run side by side too. Every front is computed by the
//!   same sequence of dense operations (faer, `Par::Seq`) whatever the thread that runs it,
//!   and children are summed in a fixed order: the factors are bit-identical for any number
//!   of threads.
//! * **Solves** run in parallel over the tree too ([`solve`]: independent subtrees as
//!   sequential supernodal solves, the fronts above them multifrontally), cut by a fixed
//!   rule: the solution is bit-identical for any number of threads as well.

use std::sync::{Arc, Mutex};
use std::time::Instant;

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt::factor::{cholesky_in_place, cholesky_in_place_scratch};
use faer::linalg::lu::partial_pivoting::factor::{lu_in_place, lu_in_place_scratch};
use faer::linalg::matmul::matmul;
use faer::linalg::matmul::triangular::{self, BlockStructure};
use faer::linalg::triangular_solve::{
    solve_lower_triangular_in_place, solve_unit_lower_triangular_in_place,
};
use faer::reborrow::{Reborrow, ReborrowMut};
use faer::sparse::linalg::cholesky::{
    factorize_symbolic_cholesky, CholeskySymbolicParams, SymbolicCholeskyRaw, SymmetricOrdering,
};
use faer::sparse::linalg::SupernodalThreshold;
use faer::sparse::SymbolicSparseColMat;
use faer::{Accum, MatMut, Par, Side};
use rayon::prelude::*;

use crate::matrix::Pattern;
use crate::{FactorKind, SolverError, SparseMatrix};

mod solve;

/// Largest relative size `‖Δx‖∞ / ‖x‖∞` of the refinement correction of
/// [`MultifrontalLu::solve`] that is accepted: a larger one means the factors (pivots
/// chosen within each front only) are too far from K, or K is singular, and the caller solves
/// with faer's LU instead. Measured on the finest nonlocal biaxial run (1,302 tangents): the
/// correction is at most ~1e-7 (faer's LU needs none).
pub const CORRECTION_LIMIT: f64 = 1e-4;

/// Subtrees with fewer estimated flops than this are factorised by one task, without
/// further splitting.
const MIN_TASK_FLOPS: f64 = 2e5;

/// Contribution blocks of at least this many entries (64 KiB) are recycled through
/// [`BlockPool`]; smaller ones are left to the allocator.
const POOL_MIN: usize = 8192;

/// Storage of consumed contribution blocks, kept across factorisations: a large block
/// allocated anew would be fresh memory, mapped and zeroed page by page by the kernel at
/// every factorisation.
#[derive(Debug, Default)]
struct BlockPool(Mutex<Vec<Vec<f64>>>);

impl BlockPool {
    /// An empty vector with room for `len` entries: the smallest pooled one that has it,
    /// else a new one.
    fn take(&self, len: usize) -> Vec<f64> {
        if len >= POOL_MIN {
            if let Ok(mut pool) = self.0.lock() {
                let fitting = (pool.iter().enumerate())
                    .filter(|(_, b)| b.capacity() >= len)
                    .min_by_key(|(_, b)| b.capacity())
                    .map(|(i, _)| i);
                if let Some(i) = fitting {
                    return pool.swap_remove(i);
                }
            }
        }
        Vec::with_capacity(len)
    }

    /// Returns a consumed block to the pool.
    fn give(&self, mut block: Vec<f64>) {
        if block.capacity() >= POOL_MIN {
            block.clear();
            if let Ok(mut pool) = self.0.lock() {
                pool.push(block);
            }
        }
    }
}

/// One front: the supernode's columns and off-diagonal rows (permuted numbering), its
/// children, where its rows go in the parent's front, and the entries of `K` it sums.
#[derive(Debug)]
struct Front {
    begin: usize,
    end: usize,
    rows: Vec<usize>,
    children: Vec<usize>,
    /// The parent front (`None` for a root).
    parent: Option<usize>,
    /// For each of `rows`, its local index in the parent's front.
    to_parent: Vec<usize>,
    /// `(position in K's values, offset in the column-major m × m front)`, those in the
    /// front's lower triangle (row ≥ column) first: a Cholesky front sums only these
    /// (`u32`: K's positions are, [`crate::Assembler`], and a front's are for any front that
    /// fits in memory; half the bytes every numeric factorisation reads).
    entries: Vec<(u32, u32)>,
    /// Number of `entries` in the lower triangle.
    lower_entries: usize,
    /// Estimated flops of the whole subtree rooted here.
    subtree_flops: f64,
}

impl Front {
    fn pivots(&self) -> usize {
        self.end - self.begin
    }

    fn order(&self) -> usize {
        self.pivots() + self.rows.len()
    }

    /// Local index of permuted index `x` (a column of the front or one of its rows).
    fn local(&self, x: usize) -> usize {
        if x < self.end {
            x - self.begin
        } else {
            self.pivots()
                + self
                    .rows
                    .binary_search(&x)
                    .expect("index in the front's row pattern")
        }
    }
}

/// The symbolic analysis of one pattern.
#[derive(Debug)]
struct Symbolic {
    pattern: Arc<Pattern>,
    /// `perm[new] = old`.
    perm: Vec<usize>,
    fronts: Vec<Front>,
    /// Roots of the elimination tree.
    roots: Vec<usize>,
    /// Per front: above the tasks (its children are factorised in parallel before it), or in
    /// the subtree of a task (factorised on one thread, children before parents).
    above_tasks: Vec<bool>,
    /// The solves' cut of the tree (fixed, whatever the threads).
    solve_plan: solve::SolvePlan,
}

/// The dense factors of one front.
#[derive(Debug, Default)]
struct FrontFactor {
    /// `[L11\U11; L21]`, column-major, `m × ns` (leading dimension m): the first `m · ns`
    /// entries (a Cholesky front keeps the rest of its `m × m` storage for the next
    /// factorisation).
    lu: Vec<f64>,
    /// `U12`, column-major `ns × (m − ns)`.
    u12: Vec<f64>,
    /// Row permutation of the fully summed block: row `i` of `P F11` is row `piv[i]` of `F11`.
    piv: Vec<usize>,
}

/// Multifrontal LU with a symmetric-pattern analysis, see the module documentation.
#[derive(Debug, Default)]
pub struct MultifrontalLu {
    symbolic: Option<Symbolic>,
    factors: Vec<FrontFactor>,
    /// Contribution blocks' storage, reused by the next factorisation.
    pool: BlockPool,
    /// The permuted vector and the units' row vectors of a solve, kept for the next one.
    solve_storage: Mutex<(Vec<f64>, Vec<f64>)>,
    /// The kind of the present factors (`None` before a successful factorisation).
    current: Option<FactorKind>,
    /// Symmetric systems the Cholesky variant found not positive definite (then factorised
    /// by the LU variant).
    pub cholesky_failures: usize,
    /// Symbolic analyses made.
    pub symbolic_count: usize,
    /// Seconds in symbolic analyses.
    pub symbolic_seconds: f64,
    /// Seconds in numeric factorisations (probe excluded).
    pub numeric_seconds: f64,
    /// Relative size of the last refinement correction ([`Self::solve`]; `None` after a Cholesky solve).
    pub last_correction: Option<f64>,
    /// Stored entries of the last factors (L and U, fronts in full).
    pub factor_nnz: usize,
}

impl MultifrontalLu {
    /// An empty solver; the first [`Self::factorize`] makes the symbolic analysis.
    pub fn new() -> Self {
        Self::default()
    }

    /// Factorises `k`; the symbolic analysis is reused while the pattern is unchanged. With
    /// `symmetric` (the caller's knowledge that K is symmetric) the fronts are factorised by
    /// Cholesky, `F11 = L11 L11ᵀ`, `L21 = F21 L11⁻ᵀ`, `C = F22 − L21 L21ᵀ` (lower triangles only:
    /// half the flops of the LU); a K that is not positive definite is then factorised by the
    /// LU variant (counted in `cholesky_failures`). Returns the kind of the factors.
    ///
    /// Errors: [`SolverError::EmptySystem`] for n = 0; [`SolverError::Singular`] (factor kind
    /// LU) for a zero or non-finite pivot; [`SolverError::Faer`] if faer's symbolic analysis
    /// fails.
    pub fn factorize(
        &mut self,
        k: &SparseMatrix,
        symmetric: bool,
    ) -> Result<FactorKind, SolverError> {
        self.current = None;
        if k.n() == 0 {
            return Err(SolverError::EmptySystem);
        }
        let reuse = self
            .symbolic
            .as_ref()
            .is_some_and(|s| s.pattern.same_as(&k.pattern));
        if !reuse {
            let t = Instant::now();
            self.symbolic = None;
            self.symbolic = Some(Symbolic::new(&k.pattern)?);
            self.symbolic_count += 1;
            self.symbolic_seconds += t.elapsed().as_secs_f64();
        }
        let t = Instant::now();
        let symbolic = self
            .symbolic
            .as_ref()
            .expect("symbolic analysis made above");
        let mut kind = if symmetric {
            FactorKind::Cholesky
        } else {
            FactorKind::Lu
        };
        // the last factors' storage is refilled where the analysis is the same
        let recycled = if reuse {
            std::mem::take(&mut self.factors)
        } else {
            Vec::new()
        };
        let factors = match symbolic.factorize(k.values(), kind, recycled, &self.pool) {
            Err(SolverError::NotPositiveDefinite { .. }) => {
                self.cholesky_failures += 1;
                kind = FactorKind::Lu;
                symbolic.factorize(k.values(), kind, Vec::new(), &self.pool)
            }
            other => other,
        };
        self.numeric_seconds += t.elapsed().as_secs_f64();
        self.factors = factors?;
        let symbolic = self
            .symbolic
            .as_ref()
            .expect("symbolic analysis made above");
        self.factor_nnz = (symbolic.fronts.iter().zip(&self.factors))
            .map(|(front, f)| front.order() * front.pivots() + f.u12.len())
            .sum();
        self.current = Some(kind);
        Ok(kind)
    }

    /// Solves `K x = rhs` for the `k` of the last successful [`Self::factorize`]; `x` overwrites
    /// `rhs`. LU factors are followed by one step of iterative refinement (`r = b − K x`,
    /// `x += (LU)⁻¹ r`), whose size `‖Δx‖∞ / ‖x‖∞` estimates the error of the plain solve and
    /// is kept in `last_correction`; Cholesky factors (backward stable without pivoting) are
    /// used as they are.
    ///
    /// Errors: [`SolverError::NotFactorized`], [`SolverError::RhsMismatch`];
    /// [`SolverError::Singular`] if the solution is not finite or the correction exceeds
    /// [`CORRECTION_LIMIT`] (the factors are then too inaccurate to refine; `rhs` is left as
    /// it was given).
    pub fn solve(&mut self, k: &SparseMatrix, rhs: &mut [f64]) -> Result<(), SolverError> {
        if self.current == Some(FactorKind::Cholesky) {
            self.last_correction = None;
            self.solve_unrefined(rhs)?;
            return match rhs.iter().position(|v| !v.is_finite()) {
                Some(i) => Err(SolverError::Singular {
                    factor: FactorKind::Cholesky,
                    detail: format!("multifrontal solution is not finite (first at dof {i})"),
                    unknown: Some(i),
                }),
                None => Ok(()),
            };
        }
        let b = rhs.to_vec();
        self.solve_unrefined(rhs)?;
        let mut r = vec![0.0; b.len()];
        k.mul_vec(rhs, &mut r);
        for (ri, bi) in r.iter_mut().zip(&b) {
            *ri = bi - *ri;
        }
        self.solve_unrefined(&mut r)?;
        let max_abs = |v: &[f64]| v.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        let size = max_abs(&r) / max_abs(rhs).max(f64::MIN_POSITIVE);
        self.last_correction = Some(size);
        if !size.is_finite()
            || r.iter().chain(rhs.iter()).any(|v| !v.is_finite())
            || size > CORRECTION_LIMIT
        {
            rhs.copy_from_slice(&b);
            return Err(SolverError::Singular {
                factor: FactorKind::Lu,
                detail: format!(
                    "multifrontal LU: refinement correction {size:.3e} of the solution exceeds {CORRECTION_LIMIT:.0e}"
                ),
                unknown: crate::norms::largest_entry(&r),
            });
        }
        for (x, d) in rhs.iter_mut().zip(&r) {
            *x += d;
        }
        Ok(())
    }

    /// Solves `K x = rhs` with the factors alone (no refinement); `x` overwrites `rhs`.
    ///
    /// Errors: [`SolverError::NotFactorized`], [`SolverError::RhsMismatch`].
    pub fn solve_unrefined(&self, rhs: &mut [f64]) -> Result<(), SolverError> {
        let (symbolic, kind) = match (&self.symbolic, self.current) {
            (Some(s), Some(kind)) => (s, kind),
            _ => return Err(SolverError::NotFactorized),
        };
        let cholesky = kind == FactorKind::Cholesky;
        let n = symbolic.perm.len();
        if rhs.len() != n {
            return Err(SolverError::RhsMismatch {
                expected: n,
                found: rhs.len(),
            });
        }
        let mut storage = self.solve_storage.lock().expect("solve storage lock");
        let (w, at_rows) = &mut *storage;
        w.clear();
        w.extend(symbolic.perm.iter().map(|&old| rhs[old]));
        solve::solve(symbolic, &self.factors, cholesky, w, at_rows);
        for (&old, v) in symbolic.perm.iter().zip(w.iter()) {
            rhs[old] = *v;
        }
        Ok(())
    }
}

impl Symbolic {
    /// AMD ordering and supernodes of the Cholesky factor of `K + Kᵀ` (faer), then the fronts,
    /// their tree, the scatter of K's entries and the parallel tasks.
    fn new(pattern: &Arc<Pattern>) -> Result<Self, SolverError> {
        let n = pattern.n();
        let (col_ptr, row_idx) = (pattern.col_ptr(), pattern.row_idx());
        let (sym_ptr, sym_idx) = upper_pattern(col_ptr, row_idx);
        let sym = SymbolicSparseColMat::new_checked(n, n, sym_ptr, None, sym_idx);
        let params = CholeskySymbolicParams {
            supernodal_flop_ratio_threshold: SupernodalThreshold::FORCE_SUPERNODAL,
            ..Default::default()
        };
        let analysis =
            factorize_symbolic_cholesky(sym.as_ref(), Side::Upper, SymmetricOrdering::Amd, params)
                .map_err(|e| SolverError::Faer(format!("multifrontal symbolic analysis: {e:?}")))?;
        let (perm, perm_inv): (Vec<usize>, Vec<usize>) = match analysis.perm() {
            Some(p) => {
                let (fwd, inv) = p.arrays();
                (fwd.to_vec(), inv.to_vec())
            }
            None => ((0..n).collect(), (0..n).collect()),
        };
        let SymbolicCholeskyRaw::Supernodal(supernodal) = analysis.raw() else {
            return Err(SolverError::Faer(
                "multifrontal symbolic analysis: faer returned a simplicial structure".into(),
            ));
        };
        let count = supernodal.n_supernodes();
        let mut fronts: Vec<Front> = (0..count)
            .map(|s| Front {
                begin: supernodal.supernode_begin()[s],
                end: supernodal.supernode_end()[s],
                rows: supernodal.supernode(s).pattern().to_vec(),
                children: Vec::new(),
                parent: None,
                to_parent: Vec::new(),
                entries: Vec::new(),
                lower_entries: 0,
                subtree_flops: 0.0,
            })
            .collect();
        let mut front_of = vec![0usize; n];
        for (s, f) in fronts.iter().enumerate() {
            front_of[f.begin..f.end].fill(s);
        }
        let mut roots = Vec::new();
        for s in 0..count {
            match fronts[s].rows.first() {
                Some(&r) => {
                    let parent = front_of[r];
                    let to_parent: Vec<usize> = fronts[s]
                        .rows
                        .iter()
                        .map(|&x| fronts[parent].local(x))
                        .collect();
                    fronts[s].to_parent = to_parent;
                    fronts[s].parent = Some(parent);
                    fronts[parent].children.push(s);
                }
                None => roots.push(s),
            }
        }
        scatter_entries(&mut fronts, &front_of, &perm_inv, col_ptr, row_idx)?;
        for s in 0..count {
            let (ns, m) = (fronts[s].pivots() as f64, fronts[s].order() as f64);
            let own = ns * m * m + m * m;
            let below: f64 = fronts[s]
                .children
                .iter()
                .map(|&c| fronts[c].subtree_flops)
                .sum();
            fronts[s].subtree_flops = own + below;
        }
        let above_tasks = split_tasks(&fronts, &roots, rayon::current_num_threads());
        let solve_plan = solve::SolvePlan::new(&fronts, &roots);
        Ok(Self {
            pattern: Arc::clone(pattern),
            perm,
            fronts,
            roots,
            above_tasks,
            solve_plan,
        })
    }

    /// The numeric factorisation: from the roots down, the children of a front above the tasks
    /// in parallel before the front itself, a task's subtree on one thread.
    /// `recycled`: the factors of an earlier factorisation with this analysis (or empty),
    /// whose storage is refilled (no fresh memory to map for the large fronts).
    fn factorize(
        &self,
        values: &[f64],
        kind: FactorKind,
        recycled: Vec<FrontFactor>,
        pool: &BlockPool,
    ) -> Result<Vec<FrontFactor>, SolverError> {
        let count = self.fronts.len();
        let contributions: Vec<Mutex<Vec<f64>>> = (0..count).map(|_| Mutex::default()).collect();
        let factors: Vec<Mutex<FrontFactor>> = if recycled.len() == count {
            recycled.into_iter().map(Mutex::new).collect()
        } else {
            (0..count).map(|_| Mutex::default()).collect()
        };
        let run = |s: usize| -> Result<(), SolverError> {
            let storage = std::mem::take(&mut *factors[s].lock().expect("front factor lock"));
            let (factor, contribution) =
                self.factor_front(s, values, kind, (&contributions, pool), storage)?;
            *factors[s].lock().expect("front factor lock") = factor;
            *contributions[s].lock().expect("contribution lock") = contribution;
            Ok(())
        };
        self.roots
            .par_iter()
            .try_for_each(|&root| self.factor_tree(root, &run))?;
        Ok(factors
            .into_iter()
            .map(|f| f.into_inner().expect("front factor lock"))
            .collect())
    }

    /// Factorises the tree below front `s` and `s` itself with `run`: the children of a
    /// front above the tasks in parallel (each by this function), a task's subtree on this
    /// thread in ascending order (children before parents).
    fn factor_tree(
        &self,
        s: usize,
        run: &(impl Fn(usize) -> Result<(), SolverError> + Sync),
    ) -> Result<(), SolverError> {
        if self.above_tasks[s] {
            self.fronts[s]
                .children
                .par_iter()
                .try_for_each(|&c| self.factor_tree(c, run))?;
            return run(s);
        }
        subtree(&self.fronts, s).into_iter().try_for_each(run)
    }

    /// Assembles front `s` (K's entries, then its children's contribution blocks in order) and
    /// factorises its fully summed block; returns its factors (in `storage`'s vectors) and
    /// its contribution block.
    fn factor_front(
        &self,
        s: usize,
        values: &[f64],
        kind: FactorKind,
        (contributions, pool): (&[Mutex<Vec<f64>>], &BlockPool),
        storage: FrontFactor,
    ) -> Result<(FrontFactor, Vec<f64>), SolverError> {
        let front = &self.fronts[s];
        let (ns, m) = (front.pivots(), front.order());
        let ms = m - ns;
        let FrontFactor {
            lu: mut dense,
            mut u12,
            mut piv,
        } = storage;
        let cholesky = kind == FactorKind::Cholesky;
        if cholesky {
            // Cholesky reads and writes lower triangles only (F11, F21, the lower triangle of
            // F22): the upper one keeps whatever the storage held and is never read
            dense.resize(m * m, 0.0);
            for (j, column) in dense.chunks_exact_mut(m).enumerate() {
                column[j..].fill(0.0);
            }
        } else {
            dense.clear();
            dense.resize(m * m, 0.0);
        }
        let entries = if cholesky {
            &front.entries[..front.lower_entries]
        } else {
            &front.entries[..]
        };
        for &(k, offset) in entries {
            dense[offset as usize] += values[k as usize];
        }
        for &c in &front.children {
            let block = std::mem::take(&mut *contributions[c].lock().expect("contribution lock"));
            extend_add(&mut dense, m, &self.fronts[c].to_parent, &block, cholesky);
            pool.give(block);
        }
        piv.clear();
        {
            let matrix = MatMut::from_column_major_slice_mut(&mut dense, m, m);
            let (f11, f12, f21, f22) = matrix.split_at_mut(ns, ns);
            match kind {
                FactorKind::Lu => factor_lu(f11, f12, f21, f22, front.begin, &mut piv)?,
                FactorKind::Cholesky => factor_cholesky(f11, f21, f22, front.begin)?,
            }
        }
        // U12 is kept for LU factors only (Cholesky's is L21ᵀ); a Cholesky front hands on the
        // lower triangle of C, packed by columns
        u12.clear();
        u12.resize(if cholesky { 0 } else { ns * ms }, 0.0);
        let mut contribution = pool.take(if cholesky { ms * (ms + 1) / 2 } else { ms * ms });
        for j in 0..ms {
            let column = &dense[(ns + j) * m..(ns + j + 1) * m];
            if cholesky {
                contribution.extend_from_slice(&column[ns + j..]);
            } else {
                u12[j * ns..(j + 1) * ns].copy_from_slice(&column[..ns]);
                contribution.extend_from_slice(&column[ns..]);
            }
        }
        // a Cholesky front keeps its m × m storage (L in the first ns columns), which the
        // next factorisation zeroes in its lower triangle only
        if !cholesky {
            dense.truncate(m * ns);
        }
        Ok((
            FrontFactor {
                lu: dense,
                u12,
                piv,
            },
            contribution,
        ))
    }
}

/// The upper triangle (diagonal included) of the pattern of `K + Kᵀ`, in compressed columns
/// with sorted rows, from K's pattern (`col_ptr`, `row_idx`).
fn upper_pattern(col_ptr: &[usize], row_idx: &[usize]) -> (Vec<usize>, Vec<usize>) {
    let n = col_ptr.len() - 1;
    let entries = |j: usize| {
        row_idx[col_ptr[j]..col_ptr[j + 1]]
            .iter()
            .map(move |&i| (i, j))
    };
    // entry (i, j) of K or of Kᵀ lands in column max(i, j), row min(i, j); the diagonal is
    // added to every column
    let mut ptr = vec![0usize; n + 1];
    for j in 0..n {
        ptr[j + 1] += 1;
        for (i, j) in entries(j) {
            ptr[i.max(j) + 1] += 1;
        }
    }
    for j in 0..n {
        ptr[j + 1] += ptr[j];
    }
    let mut idx = vec![0usize; ptr[n]];
    let mut next = ptr[..n].to_vec();
    for j in 0..n {
        idx[next[j]] = j;
        next[j] += 1;
        for (i, j) in entries(j) {
            let column = i.max(j);
            idx[next[column]] = i.min(j);
            next[column] += 1;
        }
    }
    // sort and deduplicate each column, compacting in place
    let mut kept = 0;
    let mut start = 0;
    for j in 0..n {
        let end = ptr[j + 1];
        idx[start..end].sort_unstable();
        ptr[j] = kept;
        let mut last = usize::MAX;
        for k in start..end {
            let row = idx[k];
            if row != last {
                idx[kept] = row;
                kept += 1;
                last = row;
            }
        }
        start = end;
    }
    ptr[n] = kept;
    idx.truncate(kept);
    (ptr, idx)
}

/// Hands every entry of K (`col_ptr`, `row_idx`; `perm_inv[old] = new`) to the front that sums
/// it, the front of its smaller permuted index, as `(position in K's values, offset in the
/// column-major front)`, the entries in the front's lower triangle first
/// ([`Front::entries`]).
fn scatter_entries(
    fronts: &mut [Front],
    front_of: &[usize],
    perm_inv: &[usize],
    col_ptr: &[usize],
    row_idx: &[usize],
) -> Result<(), SolverError> {
    let n = perm_inv.len();
    // K's positions fit (the assembler refuses larger patterns); a front's offsets do for
    // any front of fewer than 65,536 unknowns (a dense 32 GB block)
    let too_large = |m: usize| {
        SolverError::Unsupported(format!(
            "a multifrontal front of order {m} exceeds 32-bit offsets"
        ))
    };
    if row_idx.len() > u32::MAX as usize {
        return Err(SolverError::TooManyNonZeros { nnz: row_idx.len() });
    }
    if let Some(m) = fronts
        .iter()
        .map(Front::order)
        .find(|&m| m * m > u32::MAX as usize)
    {
        return Err(too_large(m));
    }
    // K's entries (position, permuted row, permuted column) grouped by front, in K's order
    let mut start = vec![0usize; fronts.len() + 1];
    let owner = |i: usize, j: usize| front_of[perm_inv[i].min(perm_inv[j])];
    for j in 0..n {
        for &i in &row_idx[col_ptr[j]..col_ptr[j + 1]] {
            start[owner(i, j) + 1] += 1;
        }
    }
    for s in 0..fronts.len() {
        start[s + 1] += start[s];
    }
    let mut grouped = vec![(0u32, 0u32, 0u32); row_idx.len()];
    let mut next = start[..fronts.len()].to_vec();
    for j in 0..n {
        for (k, &i) in (col_ptr[j]..).zip(&row_idx[col_ptr[j]..col_ptr[j + 1]]) {
            let s = owner(i, j);
            grouped[next[s]] = (k as u32, perm_inv[i] as u32, perm_inv[j] as u32);
            next[s] += 1;
        }
    }
    // local index of a front's rows, refilled front by front
    let mut local_of_row = vec![0usize; n];
    for (s, front) in fronts.iter_mut().enumerate() {
        let (ns, m) = (front.pivots(), front.order());
        for (r, &x) in front.rows.iter().enumerate() {
            local_of_row[x] = ns + r;
        }
        let local = |x: u32| {
            let x = x as usize;
            if x < front.end {
                x - front.begin
            } else {
                local_of_row[x]
            }
        };
        // every position of a front receives one entry of K at most: the order of the
        // entries does not change a sum; the lower triangle's first, each part in K's order
        let group = &grouped[start[s]..start[s + 1]];
        let placed = || group.iter().map(|&(k, pi, pj)| (k, local(pi), local(pj)));
        let mut entries = Vec::with_capacity(group.len());
        for lower in [true, false] {
            for (k, row, column) in placed().filter(|&(_, row, column)| (row >= column) == lower) {
                entries.push((k, (column * m + row) as u32));
            }
            if lower {
                front.lower_entries = entries.len();
            }
        }
        front.entries = entries;
    }
    Ok(())
}

/// Extend-add: adds a child's contribution block `block` to the parent's m × m front `dense`
/// (column-major) at the parent's local indices `map` (increasing). `lower`: the block holds
/// the lower triangle only, packed by columns (a Cholesky front), and only the parent's lower
/// triangle receives it; else it is the full square, column-major.
fn extend_add(dense: &mut [f64], m: usize, map: &[usize], block: &[f64], lower: bool) {
    let mc = map.len();
    let mut start = 0;
    for (jj, &col) in map.iter().enumerate() {
        let target = &mut dense[col * m..(col + 1) * m];
        let rows = if lower { &map[jj..] } else { map };
        for (&row, v) in rows.iter().zip(&block[start..start + rows.len()]) {
            target[row] += v;
        }
        start += rows.len();
    }
    debug_assert_eq!(start, if lower { mc * (mc + 1) / 2 } else { mc * mc });
}

type Block<'a> = MatMut<'a, f64>;

/// The LU step of a front (module documentation): `P F11 = L11 U11` with partial pivoting
/// among the fully summed rows, `U12 = L11⁻¹ P F12`, `L21 = F21 U11⁻¹`, `C = F22 − L21 U12`,
/// all in place; the row permutation is written to `piv`. `first` (the front's first permuted unknown)
/// names a zero pivot in the error.
fn factor_lu(
    mut f11: Block,
    mut f12: Block,
    mut f21: Block,
    mut f22: Block,
    first: usize,
    piv: &mut Vec<usize>,
) -> Result<(), SolverError> {
    let (ns, ms) = (f11.nrows(), f12.ncols());
    piv.resize(ns, 0);
    let mut piv_inv = vec![0usize; ns];
    let mut memory = MemBuffer::new(lu_in_place_scratch::<usize, f64>(
        ns,
        ns,
        Par::Seq,
        Default::default(),
    ));
    lu_in_place(
        f11.rb_mut(),
        piv,
        &mut piv_inv,
        Par::Seq,
        MemStack::new(&mut memory),
        Default::default(),
    );
    for i in 0..ns {
        let pivot = f11[(i, i)];
        if pivot == 0.0 || !pivot.is_finite() {
            return Err(SolverError::Singular {
                factor: FactorKind::Lu,
                detail: format!(
                    "multifrontal LU: pivot {pivot:e} at unknown {} (permuted)",
                    first + i
                ),
                unknown: None,
            });
        }
    }
    if ms > 0 {
        let mut column = vec![0.0; ns];
        for j in 0..ms {
            for (i, c) in column.iter_mut().enumerate() {
                *c = f12[(piv[i], j)];
            }
            for (i, c) in column.iter().enumerate() {
                f12[(i, j)] = *c;
            }
        }
        solve_unit_lower_triangular_in_place(f11.rb(), f12.rb_mut(), Par::Seq);
        solve_lower_triangular_in_place(
            f11.rb().transpose(),
            f21.rb_mut().transpose_mut(),
            Par::Seq,
        );
        matmul(f22.rb_mut(), Accum::Add, f21.rb(), f12.rb(), -1.0, Par::Seq);
    }
    Ok(())
}

/// The Cholesky step of a front of a symmetric K: `F11 = L11 L11ᵀ`, `L21 = F21 L11⁻ᵀ`, and the
/// lower triangle of `C = F22 − L21 L21ᵀ`, in place (the upper triangles are not read).
///
/// Errors: [`SolverError::NotPositiveDefinite`] if `F11` is not.
fn factor_cholesky(
    mut f11: Block,
    mut f21: Block,
    mut f22: Block,
    first: usize,
) -> Result<(), SolverError> {
    let ns = f11.nrows();
    let mut memory = MemBuffer::new(cholesky_in_place_scratch::<f64>(
        ns,
        Par::Seq,
        Default::default(),
    ));
    cholesky_in_place(
        f11.rb_mut(),
        Default::default(),
        Par::Seq,
        MemStack::new(&mut memory),
        Default::default(),
    )
    .map_err(|_| SolverError::NotPositiveDefinite {
        method: "multifrontal Cholesky",
        detail: format!("a pivot of the front at unknown {first} (permuted) is not positive"),
    })?;
    if f21.nrows() > 0 {
        solve_lower_triangular_in_place(f11.rb(), f21.rb_mut().transpose_mut(), Par::Seq);
        triangular::matmul(
            f22.rb_mut(),
            BlockStructure::TriangularLower,
            Accum::Add,
            f21.rb(),
            BlockStructure::Rectangular,
            f21.rb().transpose(),
            BlockStructure::Rectangular,
            -1.0,
            Par::Seq,
        );
    }
    Ok(())
}

/// The fronts of the subtree rooted at `s`, ascending (children before parents).
fn subtree(fronts: &[Front], s: usize) -> Vec<usize> {
    let mut subtree = Vec::new();
    let mut stack = vec![s];
    while let Some(f) = stack.pop() {
        subtree.push(f);
        stack.extend_from_slice(&fronts[f].children);
    }
    subtree.sort_unstable();
    subtree
}

/// Splits the elimination tree into subtrees for parallel tasks: starting from the roots,
/// the subtree with the most flops is opened (its root joins the top fronts, its children
/// become subtrees) while it holds more than `1 / (4 threads)` of the total and more than
/// [`MIN_TASK_FLOPS`]. Returns, per front, whether it lies above the tasks (was opened).
fn split_tasks(fronts: &[Front], roots: &[usize], threads: usize) -> Vec<bool> {
    let total: f64 = roots.iter().map(|&r| fronts[r].subtree_flops).sum();
    let limit = (total / (4 * threads.max(1)) as f64).max(MIN_TASK_FLOPS);
    let mut tasks: Vec<usize> = roots.to_vec();
    let mut opened = vec![false; fronts.len()];
    if threads > 1 {
        while let Some((index, &largest)) = tasks.iter().enumerate().max_by(|a, b| {
            fronts[*a.1]
                .subtree_flops
                .total_cmp(&fronts[*b.1].subtree_flops)
        }) {
            if fronts[largest].subtree_flops <= limit {
                break;
            }
            tasks.swap_remove(index);
            opened[largest] = true;
            tasks.extend_from_slice(&fronts[largest].children);
        }
    }
    opened
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::norms::relative_residual as residual;

    /// A 2D 5-point stencil with two unknowns per node and unsymmetric values (a convection-like
    /// skew part), diagonally dominant: every pivot is safe.
    fn grid_matrix(nx: usize, ny: usize, skew: f64) -> SparseMatrix {
        grid_matrix_coupled(nx, ny, skew, 0.1)
    }

    /// [`grid_matrix`] with a cross-component coupling `± coupling` to the neighbours (sign by
    /// direction: antisymmetric; `coupling = 0` and `skew = 0` give a symmetric matrix).
    pub(super) fn grid_matrix_coupled(
        nx: usize,
        ny: usize,
        skew: f64,
        coupling: f64,
    ) -> SparseMatrix {
        let node = |i: usize, j: usize| j * nx + i;
        let mut t = Vec::new();
        for j in 0..ny {
            for i in 0..nx {
                let a = node(i, j);
                let mut neighbours = Vec::new();
                if i > 0 {
                    neighbours.push(node(i - 1, j));
                }
                if i + 1 < nx {
                    neighbours.push(node(i + 1, j));
                }
                if j > 0 {
                    neighbours.push(node(i, j - 1));
                }
                if j + 1 < ny {
                    neighbours.push(node(i, j + 1));
                }
                for c in 0..2 {
                    t.push((2 * a + c, 2 * a + c, 8.5 + c as f64));
                    t.push((2 * a + c, 2 * a + 1 - c, 0.3));
                    for &b in &neighbours {
                        let sign = if b > a { 1.0 } else { -1.0 };
                        t.push((2 * a + c, 2 * b + c, -1.0 + sign * skew));
                        t.push((2 * a + c, 2 * b + 1 - c, coupling * sign));
                    }
                }
            }
        }
        SparseMatrix::from_triplets(2 * nx * ny, &t).unwrap()
    }

    #[test]
    fn solves_an_unsymmetric_grid_system_to_round_off() {
        let k = grid_matrix(37, 23, 0.4);
        let n = k.n();
        let b: Vec<f64> = (0..n).map(|i| ((i * 31) % 17) as f64 - 8.0).collect();
        let mut lu = MultifrontalLu::new();
        lu.factorize(&k, false).unwrap();
        let mut x = b.clone();
        lu.solve(&k, &mut x).unwrap();
        let res = residual(&k, &x, &b);
        assert!(res < 1e-15, "relative residual {res:e}");
        assert!(lu.last_correction.unwrap() < 1e-14);
    }

    #[test]
    fn pivots_within_a_front_when_the_diagonal_vanishes() {
        // the diagonal of the first unknown of every node is zero: without the partial pivoting
        // inside the fully summed block the very first pivot would be 0
        let base = grid_matrix(9, 7, 0.2);
        let mut values = base.values().to_vec();
        for i in (0..base.n()).step_by(2) {
            let p = base.position(i, i).unwrap();
            values[p] = 0.0;
        }
        let k = SparseMatrix::from_parts(Arc::clone(&base.pattern), values);
        let b: Vec<f64> = (0..k.n()).map(|i| 1.0 + (i % 5) as f64).collect();
        let mut lu = MultifrontalLu::new();
        lu.factorize(&k, false).unwrap();
        let mut x = b.clone();
        lu.solve(&k, &mut x).unwrap();
        let res = residual(&k, &x, &b);
        assert!(res < 1e-13, "relative residual {res:e}");
    }

    #[test]
    fn refactorises_new_values_on_the_same_analysis_and_is_independent_of_threads() {
        let k = grid_matrix(30, 30, 0.3);
        let mut scaled = k.clone();
        for (i, v) in scaled.values_mut().iter_mut().enumerate() {
            *v *= 1.0 + 0.01 * (i % 7) as f64;
        }
        let b: Vec<f64> = (0..k.n()).map(|i| (i as f64).sin()).collect();
        let solve = |lu: &mut MultifrontalLu, m: &SparseMatrix| {
            lu.factorize(m, false).unwrap();
            let mut x = b.clone();
            lu.solve(m, &mut x).unwrap();
            x
        };
        let mut lu = MultifrontalLu::new();
        let x1 = solve(&mut lu, &k);
        let x2 = solve(&mut lu, &scaled);
        assert_eq!(lu.symbolic_count, 1);
        // the recycled storage of the second factorisation gives the first one's bits again
        assert_eq!(solve(&mut lu, &k), x1);
        assert!(residual(&scaled, &x2, &b) < 1e-15);
        let single = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap();
        let x1_single = single.install(|| solve(&mut MultifrontalLu::new(), &k));
        assert_eq!(x1, x1_single, "bit-identical on one thread");
    }

    /// A Cholesky front zeroes, sums and hands on its lower triangle only: with the upper
    /// triangles of the kept storage poisoned by NaN (and the storage of LU fronts of the same
    /// analysis recycled), a refactorisation gives the first one's bits.
    #[test]
    fn cholesky_fronts_never_read_their_upper_triangle() {
        let k = grid_matrix_coupled(61, 53, 0.0, 0.0);
        let b: Vec<f64> = (0..k.n()).map(|i| (i as f64).cos()).collect();
        let solve = |lu: &mut MultifrontalLu, symmetric: bool| {
            assert_eq!(
                lu.factorize(&k, symmetric).unwrap() == FactorKind::Cholesky,
                symmetric
            );
            let mut x = b.clone();
            lu.solve(&k, &mut x).unwrap();
            x
        };
        let mut lu = MultifrontalLu::new();
        let first = solve(&mut lu, true);
        assert!(residual(&k, &first, &b) < 1e-15);
        let fronts = &lu.symbolic.as_ref().unwrap().fronts;
        // faer's dense Cholesky works by blocks of 128 columns (recursing below 64): a front
        // of more pivots takes the blocked path too
        assert!(fronts.iter().any(|f| f.pivots() > 128));
        for (front, factor) in fronts.iter().zip(&mut lu.factors) {
            let m = front.order();
            assert_eq!(
                factor.lu.len(),
                m * m,
                "a Cholesky front keeps its m × m storage"
            );
            for (j, column) in factor.lu.chunks_exact_mut(m).enumerate() {
                column[..j].fill(f64::NAN);
            }
        }
        assert_eq!(solve(&mut lu, true), first);
        // from the storage of LU fronts (m × ns, their U11 in the upper triangle)
        solve(&mut lu, false);
        assert_eq!(solve(&mut lu, true), first);
        assert_eq!(lu.symbolic_count, 1);
    }

    #[test]
    fn reports_a_singular_matrix() {
        let base = grid_matrix(6, 5, 0.1);
        let n = base.n();
        // a zero row and column: structurally present, numerically singular
        let mut values = base.values().to_vec();
        let (cp, ri) = (base.col_ptr().to_vec(), base.row_idx().to_vec());
        for j in 0..n {
            for p in cp[j]..cp[j + 1] {
                if j == 7 || ri[p] == 7 {
                    values[p] = 0.0;
                }
            }
        }
        let k = SparseMatrix::from_parts(Arc::clone(&base.pattern), values);
        let err = MultifrontalLu::new().factorize(&k, false).unwrap_err();
        assert!(matches!(err, SolverError::Singular { .. }), "{err}");
    }

    #[test]
    fn cholesky_fronts_for_a_symmetric_matrix_and_lu_fronts_when_it_is_indefinite() {
        let k = grid_matrix_coupled(25, 21, 0.0, 0.0);
        assert!(k.is_symmetric(0.0));
        let b: Vec<f64> = (0..k.n()).map(|i| ((i * 13) % 11) as f64 - 5.0).collect();
        let mut solutions = Vec::new();
        for symmetric in [true, false] {
            let mut lu = MultifrontalLu::new();
            let kind = lu.factorize(&k, symmetric).unwrap();
            assert_eq!(kind == FactorKind::Cholesky, symmetric);
            let mut x = b.clone();
            lu.solve(&k, &mut x).unwrap();
            let res = residual(&k, &x, &b);
            assert!(res < 1e-15, "{kind:?}: relative residual {res:e}");
            solutions.push(x);
        }
        let d = solutions[0]
            .iter()
            .zip(&solutions[1])
            .fold(0.0f64, |m, (a, c)| m.max((a - c).abs()));
        assert!(d < 5e-15, "Cholesky and LU fronts differ by {d:e}");

        // a negative diagonal entry makes K indefinite: the LU fronts take over
        let mut values = k.values().to_vec();
        values[k.position(40, 40).unwrap()] = -8.0;
        let indefinite = SparseMatrix::from_parts(Arc::clone(&k.pattern), values);
        let mut lu = MultifrontalLu::new();
        assert_eq!(lu.factorize(&indefinite, true).unwrap(), FactorKind::Lu);
        assert_eq!(lu.cholesky_failures, 1);
        let mut x = b.clone();
        lu.solve(&indefinite, &mut x).unwrap();
        let res = residual(&indefinite, &x, &b);
        assert!(res < 1e-15, "relative residual {res:e}");
    }
}
