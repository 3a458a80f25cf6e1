//! `[output] systems = [steps…]`: every Newton iteration's linear system of
//! the chosen steps (tangent K, residual R, correction δu with K δu = R)
//! written to `<out>/systems/` in Matrix Market format, with a JSON
//! description (scene, step, iteration, dof map, the solver's time and
//! work for it). A system the solver fails on is written too, with the
//! solver's error in place of the correction. Systems whose files would
//! exceed `systems_max_mb` are skipped with a warning (recorded in
//! `run.json`).

use std::path::PathBuf;

use mpm_solvers::{mm, SolverStats, SparseMatrix, Used};
use serde_json::json;

use super::step_system::StepSystem;
use crate::transfer::NONE;

/// Where and what to export.
pub struct SystemExport {
    dir: PathBuf,
    steps: Vec<usize>,
    max_bytes: f64,
    /// Systems written.
    pub written: usize,
    /// Why some were not.
    pub warnings: Vec<String>,
    /// (step, sub-step start time) of the current Newton solve, and its iteration.
    current: Option<(usize, f64)>,
    iteration: usize,
    /// Newton solves of the current step (a halved step has several).
    solve_in_step: usize,
}

impl SystemExport {
    /// Export the systems of `steps` (1-based step numbers) into `dir`.
    pub fn new(dir: PathBuf, steps: Vec<usize>, max_mb: f64) -> Self {
        Self {
            dir,
            steps,
            max_bytes: max_mb * 1e6,
            written: 0,
            warnings: Vec::new(),
            current: None,
            iteration: 0,
            solve_in_step: 0,
        }
    }

    /// A Newton solve begins (iteration numbers restart).
    pub fn begin_solve(&mut self, system: &StepSystem) {
        let step = system.model.state.step + 1;
        if self.current.is_some_and(|(s, _)| s == step) {
            self.solve_in_step += 1;
        } else {
            self.solve_in_step = 0;
        }
        self.current = Some((step, system.t));
        self.iteration = 0;
    }

    /// Write the system `(k, rhs)` of the current Newton iteration if its
    /// step is exported: with its correction and the solver that gave it,
    /// or with the solver's error where the solve failed (no correction).
    /// `solver` is the solver's counters before and after the solve.
    pub fn record(
        &mut self,
        system: &StepSystem,
        (k, rhs): (&SparseMatrix, &[f64]),
        outcome: Result<(&[f64], Used), String>,
        symmetric: bool,
        (before, after): (&SolverStats, &SolverStats),
    ) {
        let iteration = self.iteration;
        self.iteration += 1;
        let step = system.model.state.step + 1;
        if !self.steps.contains(&step) {
            return;
        }
        let stem = format!(
            "step{step:06}_solve{:02}_it{iteration:02}",
            self.solve_in_step
        );
        let bytes = mm::estimated_bytes(k.n(), k.nnz()) as f64;
        if bytes > self.max_bytes {
            self.warnings.push(format!(
                "system {stem} skipped: about {:.0} MB > output.systems_max_mb = {:.0}",
                bytes / 1e6,
                self.max_bytes / 1e6
            ));
            return;
        }
        let mut dofs = vec![[0usize; 2]; system.dofs.n_free];
        for (d, &index) in system.dofs.index.iter().enumerate() {
            if index != NONE {
                dofs[index as usize] = [d / 2, d % 2];
            }
        }
        let meta = json!({
            "scene": system.model.settings.run.name,
            "step": step,
            "newton_solve_in_step": self.solve_in_step,
            "newton_iteration": iteration,
            "t": system.t,
            "dt": system.dt,
            "symmetric": symmetric,
            "linear_solver": outcome.as_ref().map(|(_, used)| format!("{used:?}")).ok(),
            "solver_error": outcome.as_ref().err(),
            "solver_seconds": {
                "symbolic": after.symbolic_seconds - before.symbolic_seconds,
                "numeric": after.numeric_seconds - before.numeric_seconds,
                "solve": after.solve_seconds - before.solve_seconds,
                "probe": after.probe_seconds - before.probe_seconds,
            },
            "factor_nnz": after.factor_nnz,
            "pcg_iterations": after.pcg_iterations - before.pcg_iterations,
            "equation": "K x = rhs: K the tangent, rhs the residual R at the free dofs, x the Newton correction (absent where the solve failed); under path following the last unknown is the travel, and the last row the constraint (theory PF4)",
            "dof_map": "dofs[i] = [grid node, component (0 = x, 1 = y)] of unknown i (the free dofs; the travel's unknown follows them)",
            "dofs": dofs,
        });
        match mm::write_system(&self.dir, &stem, k, rhs, outcome.ok().map(|(x, _)| x), meta) {
            Ok(_) => self.written += 1,
            Err(e) => self
                .warnings
                .push(format!("system {stem} not written: {e}")),
        }
    }
}
