//! The triangular solves of the multifrontal factors, in parallel over the elimination tree.
//!
//! The tree is cut into *solve tasks* (subtrees) and the fronts above them, by
//! [`SOLVE_TASK_SPLIT`], a fixed number that does not depend on the threads: the order of
//! every sum is fixed by the cut alone, so the solution is bit-identical for any number of
//! threads.
//!
//! * **A task** (root `r`, its fronts in ascending order, which hold the consecutive permuted
//!   unknowns `lo..hi`) runs on one thread as a sequential supernodal solve: forward, each
//!   front solves its pivots and subtracts `L21 z` from the entries of its rows. A row below
//!   `hi` lies in the task's own slice of the vector; every other one is a row of `r` (the
//!   rows of a subtree outside it are rows of its root), and is accumulated in `r`'s row
//!   vector, which the task hands to its parent. Backward, the task reads the solution at
//!   `r`'s rows from its parent, then runs its fronts in descending order.
//! * **A front above the tasks** works multifrontally: forward, it adds its children's row
//!   vectors (in the fixed order of its children) to its pivots and its own row vector, solves
//!   its pivots and hands `rows − L21 z` on; backward, it reads the solution at its rows from
//!   its parent and solves for its pivots. Independent branches run in parallel (rayon).

use std::sync::Mutex;

use faer::linalg::matmul::matmul;
use faer::linalg::triangular_solve::{
    solve_lower_triangular_in_place, solve_unit_lower_triangular_in_place,
    solve_upper_triangular_in_place,
};
use faer::{Accum, MatMut, MatRef, Par};
use rayon::prelude::*;

use super::{split_tasks, subtree, Front, FrontFactor, Symbolic};

/// The solve's cut of the elimination tree: as the factorisation's for this many threads
/// ([`split_tasks`]), whatever the actual number.
const SOLVE_TASK_SPLIT: usize = 4;

/// The solve's cut of the elimination tree, and where the tasks' fronts send their rows
/// outside the task.
#[derive(Debug)]
pub(super) struct SolvePlan {
    /// The units of the solve in ascending order of their unknowns.
    units: Vec<Unit>,
    /// Per front: its unit (for a front inside a task, the task's).
    unit_of: Vec<usize>,
    /// Per front inside a task: for each of its rows outside the task (those ≥ `hi`, the last
    /// ones), its place among the task root's rows; empty above the tasks.
    outside: Vec<Vec<usize>>,
    /// Row vectors of all units together.
    row_count: usize,
}

/// A unit of the solve.
#[derive(Debug)]
enum Unit {
    /// A front above the tasks.
    Above(usize),
    /// A task: its fronts (ascending, the root last), which hold the unknowns `lo..hi`.
    Task {
        fronts: Vec<usize>,
        lo: usize,
        hi: usize,
    },
}

impl Unit {
    /// The unit's root front: the front itself, or the task's root (its last front).
    fn root(&self) -> usize {
        match self {
            Unit::Above(s) => *s,
            Unit::Task { fronts, .. } => *fronts.last().expect("a task has a root"),
        }
    }
}

/// One unit's share of the vectors of a solve: its unknowns' entries of the permuted vector,
/// and a vector over its (root's) rows: the forward pass's update to its parent, then the
/// solution at those rows in the backward pass.
struct Slot<'a> {
    pivots: &'a mut [f64],
    rows: &'a mut [f64],
}

impl SolvePlan {
    /// The plan of the tree `fronts` (roots `roots`). A subtree's fronts hold consecutive
    /// unknowns when the tree is numbered in postorder (faer's supernodes are); were they
    /// not, every front would be a unit of its own (a plan without tasks).
    pub(super) fn new(fronts: &[Front], roots: &[usize]) -> Self {
        let above = split_tasks(fronts, roots, SOLVE_TASK_SPLIT);
        let count = fronts.len();
        let mut outside = vec![Vec::new(); count];
        let mut units = Vec::new();
        for r in 0..count {
            if above[r] {
                units.push(Unit::Above(r));
            } else if fronts[r].parent.is_none_or(|p| above[p]) {
                let subtree = subtree(fronts, r);
                let (lo, hi) = (fronts[subtree[0]].begin, fronts[r].end);
                let held: usize = subtree.iter().map(|&f| fronts[f].pivots()).sum();
                if held != hi - lo {
                    return Self::without_tasks(fronts);
                }
                for &f in &subtree {
                    outside[f] = places_outside(&fronts[f].rows, &fronts[r].rows, hi);
                }
                units.push(Unit::Task {
                    fronts: subtree,
                    lo,
                    hi,
                });
            }
        }
        Self::with_units(fronts, units, outside)
    }

    /// Every front a unit of its own.
    fn without_tasks(fronts: &[Front]) -> Self {
        let units = (0..fronts.len()).map(Unit::Above).collect();
        Self::with_units(fronts, units, vec![Vec::new(); fronts.len()])
    }

    /// The plan of `units`, sorted here in ascending order of their unknowns.
    fn with_units(fronts: &[Front], mut units: Vec<Unit>, outside: Vec<Vec<usize>>) -> Self {
        let first = |unit: &Unit| match unit {
            Unit::Above(s) => fronts[*s].begin,
            Unit::Task { lo, .. } => *lo,
        };
        units.sort_by_key(first);
        let mut unit_of = vec![0; fronts.len()];
        for (u, unit) in units.iter().enumerate() {
            match unit {
                Unit::Above(s) => unit_of[*s] = u,
                Unit::Task { fronts, .. } => fronts.iter().for_each(|&f| unit_of[f] = u),
            }
        }
        let row_count = units.iter().map(|u| fronts[u.root()].rows.len()).sum();
        Self {
            units,
            unit_of,
            outside,
            row_count,
        }
    }
}

/// The places among the task root's rows (`root_rows`) of a task's front's `rows` outside the
/// task (those ≥ `hi`: the rows of a subtree outside it are rows of its root).
fn places_outside(rows: &[usize], root_rows: &[usize], hi: usize) -> Vec<usize> {
    let inside = rows.partition_point(|&x| x < hi);
    rows[inside..]
        .iter()
        .map(|x| match root_rows.binary_search(x) {
            Ok(place) => place,
            Err(_) => unreachable!("the rows of a subtree outside it are rows of its root"),
        })
        .collect()
}

/// Solves `L U x = P b` (or `L Lᵀ x = b`) in place on the permuted vector `w`; `at_rows` is
/// scratch of the units' row vectors (resized here).
pub(super) fn solve(
    symbolic: &Symbolic,
    factors: &[FrontFactor],
    cholesky: bool,
    w: &mut [f64],
    at_rows: &mut Vec<f64>,
) {
    let plan = &symbolic.solve_plan;
    at_rows.resize(plan.row_count, 0.0);
    let slots = slots(symbolic, w, at_rows);
    let run = Run {
        symbolic,
        factors,
        cholesky,
        slots: &slots,
    };
    symbolic.roots.par_iter().for_each(|&r| run.forward(r));
    symbolic.roots.par_iter().for_each(|&r| run.backward(r));
}

/// Splits `w` and `at_rows` into the units' slots.
fn slots<'a>(
    symbolic: &Symbolic,
    mut w: &'a mut [f64],
    mut at_rows: &'a mut [f64],
) -> Vec<Mutex<Slot<'a>>> {
    let fronts = &symbolic.fronts;
    let mut slots = Vec::with_capacity(symbolic.solve_plan.units.len());
    for unit in &symbolic.solve_plan.units {
        let unknowns = match unit {
            Unit::Above(s) => fronts[*s].pivots(),
            Unit::Task { lo, hi, .. } => hi - lo,
        };
        let (pivots, rest) = std::mem::take(&mut w).split_at_mut(unknowns);
        let root_rows = fronts[unit.root()].rows.len();
        let (rows, rest_rows) = std::mem::take(&mut at_rows).split_at_mut(root_rows);
        (w, at_rows) = (rest, rest_rows);
        slots.push(Mutex::new(Slot { pivots, rows }));
    }
    slots
}

/// The data of one solve.
struct Run<'a, 'b> {
    symbolic: &'a Symbolic,
    factors: &'a [FrontFactor],
    cholesky: bool,
    slots: &'a [Mutex<Slot<'b>>],
}

impl<'b> Run<'_, 'b> {
    fn lock(&self, unit: usize) -> std::sync::MutexGuard<'_, Slot<'b>> {
        self.slots[unit].lock().expect("solve slot lock")
    }

    /// The forward pass of the tree below front `s` (a unit's root) and of `s` (children
    /// before parents).
    fn forward(&self, s: usize) {
        let plan = &self.symbolic.solve_plan;
        let unit = plan.unit_of[s];
        debug_assert_eq!(plan.units[unit].root(), s);
        match &plan.units[unit] {
            Unit::Task { fronts, lo, .. } => self.task_forward(unit, fronts, *lo),
            Unit::Above(_) => {
                let front = &self.symbolic.fronts[s];
                front.children.par_iter().for_each(|&c| self.forward(c));
                let mut slot = self.lock(unit);
                let Slot { pivots, rows } = &mut *slot;
                rows.fill(0.0);
                let ns = front.pivots();
                for &c in &front.children {
                    let child = self.lock(plan.unit_of[c]);
                    let to_parent = &self.symbolic.fronts[c].to_parent;
                    for (&p, v) in to_parent.iter().zip(child.rows.iter()) {
                        if p < ns {
                            pivots[p] += v;
                        } else {
                            rows[p - ns] += v;
                        }
                    }
                }
                self.front_forward(s, pivots, rows, Accum::Add, &mut Vec::new());
            }
        }
    }

    /// The backward pass of front `s` (a unit's root: a front above the tasks or a task's
    /// root) and of the tree below it (parents before children).
    fn backward(&self, s: usize) {
        let plan = &self.symbolic.solve_plan;
        let unit = plan.unit_of[s];
        debug_assert_eq!(plan.units[unit].root(), s);
        let (fronts, lo) = match &plan.units[unit] {
            Unit::Task { fronts, lo, .. } => (Some(fronts), *lo),
            Unit::Above(_) => (None, 0),
        };
        {
            let mut slot = self.lock(unit);
            let Slot { pivots, rows } = &mut *slot;
            // the solution at the rows of `s` (the task's root, or the front), from the parent
            let front = &self.symbolic.fronts[s];
            if let Some(parent) = front.parent {
                let from = self.lock(plan.unit_of[parent]);
                let np = self.symbolic.fronts[parent].pivots();
                for (&p, x) in front.to_parent.iter().zip(rows.iter_mut()) {
                    *x = if p < np {
                        from.pivots[p]
                    } else {
                        from.rows[p - np]
                    };
                }
            }
            match fronts {
                Some(fronts) => self.task_backward(fronts, lo, pivots, rows),
                None => self.front_backward(s, pivots, rows),
            }
        }
        if fronts.is_none() {
            let children = &self.symbolic.fronts[s].children;
            children.par_iter().for_each(|&c| self.backward(c));
        }
    }

    /// The forward pass of a task: its fronts in ascending order on this thread.
    fn task_forward(&self, unit: usize, fronts: &[usize], lo: usize) {
        let mut slot = self.lock(unit);
        let Slot { pivots: own, rows } = &mut *slot;
        rows.fill(0.0);
        let (mut update, mut scratch) = (Vec::new(), Vec::new());
        for &f in fronts {
            let front = &self.symbolic.fronts[f];
            update.clear();
            update.resize(front.rows.len(), 0.0);
            let range = front.begin - lo..front.end - lo;
            let pivots = &mut own[range];
            self.front_forward(f, pivots, &mut update, Accum::Replace, &mut scratch);
            let outside = &self.symbolic.solve_plan.outside[f];
            let (to_own, to_root) = update.split_at(update.len() - outside.len());
            for (&x, v) in front.rows.iter().zip(to_own) {
                own[x - lo] += v;
            }
            for (&place, v) in outside.iter().zip(to_root) {
                rows[place] += v;
            }
        }
    }

    /// The backward pass of a task: its fronts in descending order on this thread, with the
    /// solution at its root's rows in `rows`.
    fn task_backward(&self, fronts: &[usize], lo: usize, own: &mut [f64], rows: &[f64]) {
        let mut gathered = Vec::new();
        for &f in fronts.iter().rev() {
            let front = &self.symbolic.fronts[f];
            let outside = &self.symbolic.solve_plan.outside[f];
            let inside = front.rows.len() - outside.len();
            gathered.clear();
            gathered.extend(front.rows[..inside].iter().map(|&x| own[x - lo]));
            gathered.extend(outside.iter().map(|&place| rows[place]));
            let range = front.begin - lo..front.end - lo;
            self.front_backward(f, &mut own[range], &gathered);
        }
    }

    /// Front `s` forward: `pivots ← L11⁻¹ P pivots`, then `update ← update − L21 pivots`
    /// (`Accum::Add`) or `update ← −L21 pivots` (`Accum::Replace`); `scratch`: room for the
    /// row permutation of LU factors.
    fn front_forward(
        &self,
        s: usize,
        pivots: &mut [f64],
        update: &mut [f64],
        accum: Accum,
        scratch: &mut Vec<f64>,
    ) {
        let (factor, m) = (&self.factors[s], self.symbolic.fronts[s].order());
        let (ns, ms) = (pivots.len(), update.len());
        let lu = MatRef::from_column_major_slice(&factor.lu[..m * ns], m, ns);
        if !self.cholesky {
            scratch.clear();
            scratch.extend(factor.piv.iter().map(|&i| pivots[i]));
            pivots.copy_from_slice(scratch);
        }
        let z = MatMut::from_column_major_slice_mut(pivots, ns, 1);
        if self.cholesky {
            solve_lower_triangular_in_place(lu.subrows(0, ns), z, Par::Seq);
        } else {
            solve_unit_lower_triangular_in_place(lu.subrows(0, ns), z, Par::Seq);
        }
        if ms > 0 {
            matmul(
                MatMut::from_column_major_slice_mut(update, ms, 1),
                accum,
                lu.subrows(ns, ms),
                MatRef::from_column_major_slice(pivots, ns, 1),
                -1.0,
                Par::Seq,
            );
        }
    }

    /// Front `s` backward: `pivots ← U11⁻¹ (pivots − U12 at_rows)` with `at_rows` the solution
    /// at the front's rows (`U = Lᵀ` for Cholesky factors).
    fn front_backward(&self, s: usize, pivots: &mut [f64], at_rows: &[f64]) {
        let (factor, m) = (&self.factors[s], self.symbolic.fronts[s].order());
        let (ns, ms) = (pivots.len(), at_rows.len());
        let lu = MatRef::from_column_major_slice(&factor.lu[..m * ns], m, ns);
        if ms > 0 {
            let u12 = if self.cholesky {
                lu.subrows(ns, ms).transpose()
            } else {
                MatRef::from_column_major_slice(&factor.u12, ns, ms)
            };
            matmul(
                MatMut::from_column_major_slice_mut(pivots, ns, 1),
                Accum::Add,
                u12,
                MatRef::from_column_major_slice(at_rows, ms, 1),
                -1.0,
                Par::Seq,
            );
        }
        let x = MatMut::from_column_major_slice_mut(pivots, ns, 1);
        if self.cholesky {
            solve_upper_triangular_in_place(lu.subrows(0, ns).transpose(), x, Par::Seq);
        } else {
            solve_upper_triangular_in_place(lu.subrows(0, ns), x, Par::Seq);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::tests::grid_matrix_coupled;
    use super::*;
    use crate::norms::{relative_difference, relative_residual};
    use crate::{FactorKind, MultifrontalLu};

    fn pool(threads: usize) -> rayon::ThreadPool {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
    }

    /// The solve with tasks and fronts above them: the solution of the grid system to
    /// round-off, the same bits on 1, 2 and 3 threads, and the same solution (to round-off) as
    /// a plan without tasks, where every front works multifrontally.
    #[test]
    fn tasks_and_fronts_above_them_solve_alike_on_any_number_of_threads() {
        for (skew, coupling, kind) in [(0.0, 0.0, FactorKind::Cholesky), (0.3, 0.2, FactorKind::Lu)]
        {
            let k = grid_matrix_coupled(61, 53, skew, coupling);
            let symmetric = kind == FactorKind::Cholesky;
            let b: Vec<f64> = (0..k.n()).map(|i| (0.37 * i as f64).sin()).collect();
            let mut solver = MultifrontalLu::new();
            assert_eq!(solver.factorize(&k, symmetric).unwrap(), kind);
            let plan = &solver.symbolic.as_ref().unwrap().solve_plan;
            let tasks = (plan.units.iter())
                .filter(|u| matches!(u, Unit::Task { .. }))
                .count();
            let above = plan.units.len() - tasks;
            assert!(
                tasks >= 4 && above >= 2,
                "{tasks} tasks, {above} fronts above"
            );
            let solve = |solver: &MultifrontalLu| {
                let mut x = b.clone();
                solver.solve_unrefined(&mut x).unwrap();
                x
            };
            let x = solve(&solver);
            // measured: 3.2e-16 (Cholesky) and 4.1e-16 (LU)
            let r = relative_residual(&k, &x, &b);
            assert!(r < 2e-15, "{kind:?}: residual {r:e}");
            for threads in [1, 2, 3] {
                let other = pool(threads).install(|| solve(&solver));
                assert_eq!(other, x, "{kind:?}: bit-identical on {threads} threads");
            }
            let symbolic = solver.symbolic.as_mut().unwrap();
            symbolic.solve_plan = SolvePlan::without_tasks(&symbolic.fronts);
            let multifrontal = solve(&solver);
            // measured: 9.4e-17 and 9.5e-17
            let d = relative_difference(&multifrontal, &x);
            assert!(d < 1e-15, "{kind:?}: {d:e} from the plan without tasks");
        }
    }
}
