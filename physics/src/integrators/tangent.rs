//! The implicit tangent (theory D17, D19, D41): its sparsity pattern, built
//! once per step, the assembly of K_T (+ M/(βΔt²) when dynamic) from the
//! cell blocks, and the sparse direct factorisation and solve (faer
//! Cholesky or LU).

use rayon::prelude::*;

use mpm_solvers::{
    Assembler, FactorKind, LinearSolver, SolverError, SolverStats, SparseMatrix, Used,
};

use super::export::SystemExport;
use super::step_system::StepSystem;
use super::{SolverUsage, TrialStresses};
use crate::constitutive::LinearElastic;
use crate::dofs::DofMap;
use crate::error::StepError;
use crate::grid::Grid;
use crate::model::Model;
use crate::profile::{Profile, Stage, Work};
use crate::scene::{FieldError, SceneError};
use crate::settings::Settings;
use crate::stiffness;
use crate::transfer::{ParticleBins, NONE};
use crate::volumetric::CellMeanGradients;

/// The tangent of the implicit integrator and its caches.
pub struct Tangent {
    /// Linear solver (a direct one keeps its symbolic factorisation while the pattern holds).
    solver: LinearSolver,
    /// `[output] systems`: the systems to write, once the output directory is known.
    export: Option<SystemExport>,
    /// What the elements' system dofs were made of, and the assembler of
    /// the pattern they make.
    pattern: Option<(PatternKey, Assembler)>,
    /// Whether `pattern` belongs to the current step.
    pattern_current: bool,
    /// Every material's tangent is symmetric: Cholesky allowed.
    symmetric: bool,
    /// The active cells' patch blocks, flat (reused by every assembly).
    blocks: Vec<f64>,
    /// The last matrix assembled, whose values the next assembly of the
    /// same pattern overwrites.
    matrix: Option<SparseMatrix>,
}

impl Tangent {
    /// The tangent of `model`'s scene, with its linear solver. A solver that
    /// needs a symmetric tangent (`cholesky`, `pcg`, `ldl`) is refused for a
    /// scene with a material whose tangent is unsymmetric (the choice `auto`
    /// makes for it).
    pub fn new(model: &Model) -> Result<Self, SceneError> {
        let symmetric = model.symmetric_tangent();
        let options = model.settings.solver.linear_options();
        let refuse = |message: String| SceneError::Invalid {
            path: model.settings.run.name.clone(),
            errors: vec![FieldError {
                field: "solver.linear_solver".into(),
                message,
            }],
        };
        if options.method.needs_symmetry() && !symmetric {
            let unsymmetric: Vec<&str> = model
                .material_names
                .iter()
                .zip(&model.materials)
                .filter(|(_, m)| !m.has_symmetric_tangent())
                .map(|(n, _)| n.as_str())
                .collect();
            return Err(refuse(format!(
                "{:?} needs a symmetric tangent, but material(s) {} have an unsymmetric one (softening or non-associated plasticity): use `lu` or `auto`",
                model.settings.solver.linear_solver,
                unsymmetric.join(", ")
            )));
        }
        let solver = LinearSolver::new(options).map_err(|e| refuse(e.to_string()))?;
        Ok(Self {
            solver,
            export: None,
            pattern: None,
            pattern_current: false,
            symmetric,
            blocks: Vec::new(),
            matrix: None,
        })
    }

    /// Counters and timings of the linear solver (symbolic and numeric
    /// factorisations, Cholesky fallbacks, PCG iterations, seconds).
    pub fn solver_stats(&self) -> SolverStats {
        self.solver.stats()
    }

    /// Fallbacks of the linear solver and skipped system exports.
    pub fn warnings(&self) -> Vec<String> {
        let mut w = self.solver.warnings();
        if let Some(export) = &self.export {
            w.extend(export.warnings.iter().cloned());
        }
        w
    }

    /// Write the systems of `[output] systems` into `dir`.
    pub fn export_systems(&mut self, dir: std::path::PathBuf, steps: Vec<usize>, max_mb: f64) {
        self.export = (!steps.is_empty()).then(|| SystemExport::new(dir, steps, max_mb));
    }

    /// Systems exported so far.
    pub fn systems_written(&self) -> usize {
        self.export.as_ref().map_or(0, |e| e.written)
    }

    /// A new step: its pattern is checked at the first assembly.
    pub fn begin_step(&mut self) {
        self.pattern_current = false;
    }

    /// A Newton solve of `system` begins: a new step for the pattern, and
    /// the export's iteration count restarts.
    pub fn begin_newton(&mut self, system: &StepSystem) {
        self.begin_step();
        if let Some(export) = self.export.as_mut() {
            export.begin_solve(system);
        }
    }

    /// Assemble K_T (+ M/(βΔt²) when dynamic) at `trial` (theory D17, D19,
    /// D41), counted in `profile` (the mass diagonal separately).
    pub fn assemble(
        &mut self,
        system: &StepSystem,
        trial: &TrialStresses,
        profile: &Profile,
    ) -> Result<SparseMatrix, StepError> {
        self.assemble_reusing(system, trial, profile).cloned()
    }

    /// [`Self::assemble`] into the matrix kept from the previous assembly
    /// when it has this step's pattern (its values overwritten: no
    /// allocation), else into a new one; the cell blocks are formed in the
    /// reused flat array [`Self::blocks`].
    fn assemble_reusing(
        &mut self,
        system: &StepSystem,
        trial: &TrialStresses,
        profile: &Profile,
    ) -> Result<&SparseMatrix, StepError> {
        profile.time(Stage::Assembly, || {
            if !self.pattern_current {
                self.update_pattern(system)?;
            }
            let Some((_, assembler)) = self.pattern.as_ref() else {
                return Err(StepError::NotAvailable("no sparsity pattern was built"));
            };
            fill_cell_blocks(system, trial, &mut self.blocks);
            let size = stiffness::patch_dofs(&system.model.grid).pow(2);
            let background = &system.background_block[..];
            let reached = system.setup.bins.reached_cells.len();
            let elements: Vec<&[f64]> = self
                .blocks
                .chunks(size)
                .chain(std::iter::repeat_n(background, reached))
                .collect();
            let diagonal = system.diagonal(trial);
            let diagonal = diagonal.as_deref();
            match self.matrix.as_mut() {
                Some(k) if assembler.built(k) => assembler.reassemble(k, &elements, diagonal)?,
                _ => self.matrix = Some(assembler.assemble_with_diagonal(&elements, diagonal)?),
            }
            profile.count(Work::Assemblies, 1);
            profile.count(Work::MassDiagonals, u64::from(diagonal.is_some()));
            Ok(self.matrix.as_ref().expect("assembled above"))
        })
    }

    /// Assemble and factorise the tangent, then solve K δu = R for the
    /// correction (Cholesky when every material's tangent is symmetric). The
    /// factorisations the solver did (a failed attempt too) are counted in
    /// `profile`.
    pub fn solve(
        &mut self,
        system: &StepSystem,
        trial: &TrialStresses,
        residual: &[f64],
        usage: &mut SolverUsage,
        profile: &Profile,
    ) -> Result<Vec<f64>, StepError> {
        self.assemble_reusing(system, trial, profile)?;
        let matrix = self.matrix.take().expect("assembled above");
        let symmetric = self.symmetric;
        let result = self.factorise_and_solve(system, &matrix, residual, symmetric, usage, profile);
        self.matrix = Some(matrix);
        result
    }

    /// Assemble the tangent, border it (theory PF4) and solve
    /// [K −∂f/∂τ; ∂gᵀ/∂Δu ∂g/∂τ] [δu; δτ] = [R; −g] by LU: the correction δu
    /// and the travel correction δτ. The border keeps the system regular
    /// where K is singular, at a limit point or along a mechanism of the
    /// softened soil that the path constraint controls.
    pub fn solve_bordered(
        &mut self,
        system: &StepSystem,
        trial: &TrialStresses,
        (residual, border): (&[f64], &Border),
        usage: &mut SolverUsage,
        profile: &Profile,
    ) -> Result<(Vec<f64>, f64), StepError> {
        let matrix = self.assemble_reusing(system, trial, profile)?;
        let bordered = matrix.bordered(&border.column, &border.row, border.corner)?;
        let mut rhs = residual.to_vec();
        rhs.push(border.rhs);
        let unsymmetric = false;
        let mut x =
            self.factorise_and_solve(system, &bordered, &rhs, unsymmetric, usage, profile)?;
        let travel = x.pop().unwrap_or(0.0);
        Ok((x, travel))
    }

    /// Factorise the assembled `matrix` (Cholesky allowed where
    /// `symmetric`) and solve for the correction ([`Self::solve`]). An
    /// exported step's system is written whether or not the solve succeeds.
    fn factorise_and_solve(
        &mut self,
        system: &StepSystem,
        matrix: &SparseMatrix,
        residual: &[f64],
        symmetric: bool,
        usage: &mut SolverUsage,
        profile: &Profile,
    ) -> Result<Vec<f64>, StepError> {
        let before = self.solver.stats();
        let solved = self.factorise_then_solve(matrix, residual, symmetric, profile);
        if let Some(export) = self.export.as_mut() {
            let outcome = match &solved {
                Ok((correction, used)) => Ok((&correction[..], *used)),
                Err(e) => Err(e.to_string()),
            };
            let solver = (&before, &self.solver.stats());
            export.record(system, (matrix, residual), outcome, symmetric, solver);
        }
        let (correction, used) = solved?;
        usage.max_unknowns = usage.max_unknowns.max(matrix.n());
        // the multifrontal factorisation counts as the kind of its fronts
        let multifrontal_kind = self.solver.stats().last_factor;
        match used {
            Used::Cholesky => usage.cholesky += 1,
            Used::Multifrontal if multifrontal_kind == Some(FactorKind::Cholesky) => {
                usage.cholesky += 1
            }
            Used::Lu | Used::LuReused | Used::Multifrontal => usage.lu += 1,
            Used::Pcg => usage.pcg += 1,
            Used::Ldl => usage.ldl += 1,
        }
        Ok(correction)
    }

    /// The factorisation and solve of [`Self::factorise_and_solve`], timed
    /// and counted: the correction and the solver that gave it.
    fn factorise_then_solve(
        &mut self,
        matrix: &SparseMatrix,
        residual: &[f64],
        symmetric: bool,
        profile: &Profile,
    ) -> Result<(Vec<f64>, Used), SolverError> {
        let before = self.solver.stats();
        let kind = profile.time(Stage::Factorisation, || {
            self.solver.factorize(matrix, symmetric)
        });
        let factorised = self.solver.stats();
        count_factorisations(&before, &factorised, profile);
        kind?;
        let mut correction = residual.to_vec();
        let used = profile.time(Stage::Solve, || self.solver.solve_in_place(&mut correction));
        // `lu_reuse` factorises in the solve when GMRES gives up
        count_factorisations(&factorised, &self.solver.stats(), profile);
        Ok((correction, used?))
    }

    /// The pattern of this step's elements: the previous one while every
    /// element keeps its dofs, else a new one (GIMP patches drop the
    /// couplings of nodes three apart, `stiffness::patch_coupling`).
    fn update_pattern(&mut self, system: &StepSystem) -> Result<(), StepError> {
        let (grid, bins, dofs) = (&system.model.grid, &system.setup.bins, &system.dofs);
        let same = matches!(&self.pattern, Some((key, _)) if key.holds(bins, dofs));
        if !same {
            let element_dofs = dofs.element_dofs(grid, bins);
            let coupling = stiffness::patch_coupling(grid, system.model.b_bar());
            let assembler = Assembler::with_couplings(dofs.n_free, &element_dofs, coupling)?;
            self.pattern = Some((PatternKey::new(bins, dofs), assembler));
        }
        self.pattern_current = true;
        Ok(())
    }
}

/// The border of path following's Newton system (theory PF4), over the
/// unknowns: sparse `(unknown, value)` pairs in increasing order.
#[derive(Clone, Debug, Default)]
pub struct Border {
    /// −∂R/∂τ = −∂f_pen/∂τ.
    pub column: Vec<(usize, f64)>,
    /// ∂g/∂Δu.
    pub row: Vec<(usize, f64)>,
    /// ∂g/∂τ.
    pub corner: f64,
    /// −g at the iterate.
    pub rhs: f64,
}

/// What a step's elements and their system dofs are made of
/// (`DofMap::element_dofs`): the active cells, the reached cells and the
/// numbering of the unknowns. Steps with equal keys have the same elements
/// with the same dofs, so the same pattern; comparing the key costs a pass
/// over three arrays, not the forming of every element's dof list.
struct PatternKey {
    active_cells: Vec<u32>,
    reached_cells: Vec<u32>,
    dof_index: Vec<u32>,
}

impl PatternKey {
    fn new(bins: &ParticleBins, dofs: &DofMap) -> Self {
        Self {
            active_cells: bins.active_cells.clone(),
            reached_cells: bins.reached_cells.clone(),
            dof_index: dofs.index.clone(),
        }
    }

    /// Whether the elements of `bins` and `dofs` have this key's dofs.
    fn holds(&self, bins: &ParticleBins, dofs: &DofMap) -> bool {
        self.active_cells == bins.active_cells
            && self.reached_cells == bins.reached_cells
            && self.dof_index == dofs.index
    }
}

/// Count the symbolic and numeric factorisations the solver did between its
/// counters `before` and `after`.
fn count_factorisations(before: &SolverStats, after: &SolverStats, profile: &Profile) {
    let done = |now: usize, then: usize| now.saturating_sub(then) as u64;
    profile.count(
        Work::SymbolicFactorisations,
        done(after.symbolic, before.symbolic),
    );
    profile.count(
        Work::FactorisationsCholesky,
        done(after.numeric_cholesky, before.numeric_cholesky),
    );
    profile.count(
        Work::FactorisationsLu,
        done(after.numeric_lu, before.numeric_lu),
    );
}

/// The active cells' patch blocks of the system, flat into `blocks`
/// (`stiffness::cell_stiffness_blocks_into`): every active cell's patch
/// stiffness (with the spin term when the tangent is unsymmetric), the
/// penalty springs of driven points, and the background stiffness on the
/// cell's own nodes. The reached cells' elements (GIMP) carry the
/// background block alone (`stiffness::system_blocks`, same values).
fn fill_cell_blocks(system: &StepSystem, trial: &TrialStresses, blocks: &mut Vec<f64>) {
    let (model, setup) = (system.model, system.setup);
    let grid = &model.grid;
    let spin = (!trial.spin_sensitivity.is_empty()).then_some(trial.spin_sensitivity.as_slice());
    let places = grid.patch_side() * grid.patch_side();
    let b_bar = model.b_bar().then(|| {
        CellMeanGradients::new(
            &setup.bins,
            &setup.shapes,
            &model.state.particles.volume,
            places,
        )
    });
    let points = stiffness::PointStiffness {
        shapes: &setup.shapes,
        volume: &model.state.particles.volume,
        tangent: &trial.tangent,
        spin_sensitivity: spin,
        b_bar: b_bar.as_ref(),
    };
    stiffness::cell_stiffness_blocks_into(grid, &setup.bins, &points, blocks);
    let dofs = stiffness::patch_dofs(grid);
    model
        .state
        .driven
        .add_stiffness(&setup.driven_shapes, &setup.bins, dofs, blocks);
    let background = &system.background_block;
    blocks
        .par_chunks_mut(dofs * dofs)
        .for_each(|block| stiffness::add_own_cell_block(grid, block, background));
}

impl StepSystem<'_> {
    /// The tangent's diagonal terms at the free dofs: the inertia's
    /// [`Self::mass_diagonal`] and the frictional edges' tangential springs
    /// at `trial` (`None` when there are neither).
    fn diagonal(&self, trial: &TrialStresses) -> Option<Vec<f64>> {
        let mut diag = self.mass_diagonal();
        let edges = &self.model.friction;
        for (contact, &k_t) in edges.nodes.iter().zip(&trial.friction_stiffness) {
            let index = self.dofs.index[2 * contact.node + contact.tangent()];
            if index != NONE && k_t != 0.0 {
                diag.get_or_insert_with(|| vec![0.0; self.dofs.n_free])[index as usize] += k_t;
            }
        }
        diag
    }

    /// (1 − α_m)/(1 − α_f) M/(βΔt²) at the free dofs (dynamic runs; `None` when quasi-static).
    fn mass_diagonal(&self) -> Option<Vec<f64>> {
        let newmark = self.newmark.as_ref()?;
        let (factor, beta_dt2) = (newmark.inertia_factor(), newmark.beta * self.dt * self.dt);
        let mut diag = vec![0.0; self.dofs.n_free];
        for (d, &index) in self.dofs.index.iter().enumerate() {
            if index != NONE {
                diag[index as usize] = self.nodal.mass[d / 2] * factor / beta_dt2;
            }
        }
        Some(diag)
    }
}

/// ε_bg times the 2×2-Gauss bilinear elastic stiffness of a full cell with the
/// stiffest material's E and its ν (theory D19), over the cell's nodes in
/// row-major order (see `stiffness::system_blocks`).
pub fn background_block(settings: &Settings, grid: &Grid) -> [f64; 64] {
    let mut block = [0.0; 64];
    let Some((youngs_modulus, poisson_ratio)) = settings.stiffest_material else {
        return block;
    };
    let d = LinearElastic::new(youngs_modulus, poisson_ratio).stiffness();
    let h = grid.cell_size;
    let grid = Grid::bilinear(grid.origin, h, grid.cells);
    let g = 0.5 / 3f64.sqrt();
    for (gx, gy) in [(-g, -g), (g, -g), (g, g), (-g, g)] {
        let x = [
            grid.origin[0] + (0.5 + gx) * h,
            grid.origin[1] + (0.5 + gy) * h,
        ];
        let shape = grid.shape_in_cell(0, 0, x);
        stiffness::add_particle_stiffness(&mut block, 8, &shape, 0.25 * h * h, &d);
    }
    block
        .iter_mut()
        .for_each(|v| *v *= settings.solver.background_stiffness);
    block
}
