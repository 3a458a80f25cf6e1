//! Per-stage wall-time profile (call count and seconds per stage) and work
//! counters (how often each costly structure was built or operation done),
//! reported at the end of a run and written to `run.json`.
//!
//! Stages are timed *exclusively*: while a stage runs inside another (the
//! stress update inside Newton, the nonlocal average inside the stresses
//! stage), the inner one's time is charged to it alone and the outer one is
//! paused. Every instant of a run is therefore counted once, and the stage
//! times plus `other` (what no stage covers) add up to the wall time.

use std::cell::Cell;
use std::time::Instant;

use serde::Serialize;

/// The stages of an MPM step, in the order of paper Fig. 1 (setup → P2G →
/// time step / Newton → G2P → remap → stresses → commit), with the solver
/// stages Newton calls and what a run does around its steps.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Stage {
    /// Building the model from the scene: seeding points, boundary devices.
    Build,
    /// Shape functions, binning, dof numbering, boundary points' shapes.
    Setup,
    /// Particle-to-grid transfers (mass, momentum, external and internal forces).
    P2G,
    /// Explicit: stable time step and nodal momentum update (theory D20–D21).
    TimeStep,
    /// Implicit: the Newton loop's own work (convergence checks, residual
    /// norms, line-search bookkeeping), not the stages it calls.
    Newton,
    /// Constitutive stress update at the material points.
    StressUpdate,
    /// Nonlocal weights and averaging (theory §6).
    Nonlocal,
    /// Tangent assembly (cell blocks and CSC values).
    Assembly,
    /// Sparse factorisation (symbolic + numeric).
    Factorisation,
    /// Triangular solves.
    Solve,
    /// Grid-to-particle update of positions, velocities, accelerations.
    G2P,
    /// Explicit MUSL re-map of the updated particle momentum.
    Remap,
    /// Converged stresses: step energies and what the stresses stage does
    /// besides the nonlocal commit and double mapping.
    Stresses,
    /// Double mapping of the stresses (theory §7).
    DoubleMapping,
    /// Committing the step at the points: F, V, stresses, boundary points.
    Commit,
    /// Curve rows, monitors and snapshots.
    Output,
}

impl Stage {
    /// All stages in report order.
    pub const ALL: [Stage; 16] = [
        Stage::Build,
        Stage::Setup,
        Stage::P2G,
        Stage::TimeStep,
        Stage::Newton,
        Stage::StressUpdate,
        Stage::Nonlocal,
        Stage::Assembly,
        Stage::Factorisation,
        Stage::Solve,
        Stage::G2P,
        Stage::Remap,
        Stage::Stresses,
        Stage::DoubleMapping,
        Stage::Commit,
        Stage::Output,
    ];

    /// Report name.
    pub fn name(self) -> &'static str {
        match self {
            Stage::Build => "build",
            Stage::Setup => "setup",
            Stage::P2G => "p2g",
            Stage::TimeStep => "time_step",
            Stage::Newton => "newton",
            Stage::StressUpdate => "stress_update",
            Stage::Nonlocal => "nonlocal",
            Stage::Assembly => "assembly",
            Stage::Factorisation => "factorisation",
            Stage::Solve => "solve",
            Stage::G2P => "g2p",
            Stage::Remap => "remap",
            Stage::Stresses => "stresses",
            Stage::DoubleMapping => "double_mapping",
            Stage::Commit => "commit",
            Stage::Output => "output",
        }
    }
}

/// Name of the row that holds the wall time no stage covers.
pub const OTHER: &str = "other";

/// Costly structures and operations of a run, each counted where it is built
/// or done (not inferred from the scene), so that a run shows what it
/// skipped: a quasi-static scene builds no mass matrix, a local one no
/// neighbour lists, an elastic one does no return mapping.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Work {
    /// Implicit dynamic: lumped nodal mass m_i built for the inertia term,
    /// one per (sub-)step (P2G; theory D15–D16). Quasi-static runs build none.
    MassMatrix,
    /// Implicit dynamic: M/(βΔt²) diagonals added to a tangent assembly
    /// (theory D17), one per assembly.
    MassDiagonals,
    /// Explicit: nodal mass m_i of the momentum update, one per step
    /// (theory §4 step 1; the stability check before the run is not counted).
    ExplicitNodalMass,
    /// Material-point stress updates, every material (theory §5).
    StressUpdates,
    /// Stress updates of a material that can yield (`is_elastic()` false):
    /// each evaluates its yield function.
    YieldChecks,
    /// Stress updates that returned to the yield surface (`yielded`).
    ReturnMappings,
    /// Nonlocal neighbour structures (cell-linked lists of
    /// `NonlocalAverager::new`), one per nonlocal (sub-)step (theory D34).
    NeighbourLists,
    /// Nonlocal weight denominators Σ_s w V_s computed (the O(N n_nb) pass of
    /// D34); a step whose increments are all zero needs none.
    NonlocalWeights,
    /// Weight-cache blocks built (`NonlocalAverager::cache_sources` calls that
    /// cached new sources; `iteration` update only, D36).
    WeightCaches,
    /// Applications of the averaging operator (`NonlocalAverager::average`,
    /// D35–D36).
    NonlocalAverages,
    /// Double-mapping passes over the stresses (theory D37–D39).
    SmoothingPasses,
    /// Internal-force restorations after double mapping (GGᵀ assembled and
    /// factorised; `[smoothing] restore_forces`).
    ForceRestorations,
    /// Implicit tangent assemblies (theory D17, D19).
    Assemblies,
    /// Numeric Cholesky factorisations of the implicit tangent (attempts:
    /// one that finds K not positive definite and falls back to LU counts).
    FactorisationsCholesky,
    /// Numeric LU factorisations of the implicit tangent.
    FactorisationsLu,
    /// Symbolic factorisations of the implicit tangent (a new sparsity
    /// pattern, or the first of each kind).
    SymbolicFactorisations,
}

impl Work {
    /// All counters in report order.
    pub const ALL: [Work; 16] = [
        Work::MassMatrix,
        Work::MassDiagonals,
        Work::ExplicitNodalMass,
        Work::StressUpdates,
        Work::YieldChecks,
        Work::ReturnMappings,
        Work::NeighbourLists,
        Work::NonlocalWeights,
        Work::WeightCaches,
        Work::NonlocalAverages,
        Work::SmoothingPasses,
        Work::ForceRestorations,
        Work::Assemblies,
        Work::FactorisationsCholesky,
        Work::FactorisationsLu,
        Work::SymbolicFactorisations,
    ];

    /// Report name (the key in `run.json`'s `"work"` object).
    pub fn name(self) -> &'static str {
        match self {
            Work::MassMatrix => "mass_matrix",
            Work::MassDiagonals => "mass_diagonals",
            Work::ExplicitNodalMass => "explicit_nodal_mass",
            Work::StressUpdates => "stress_updates",
            Work::YieldChecks => "yield_checks",
            Work::ReturnMappings => "return_mappings",
            Work::NeighbourLists => "neighbour_lists",
            Work::NonlocalWeights => "nonlocal_weights",
            Work::WeightCaches => "weight_caches",
            Work::NonlocalAverages => "nonlocal_averages",
            Work::SmoothingPasses => "smoothing_passes",
            Work::ForceRestorations => "force_restorations",
            Work::Assemblies => "assemblies",
            Work::FactorisationsCholesky => "factorisations_cholesky",
            Work::FactorisationsLu => "factorisations_lu",
            Work::SymbolicFactorisations => "symbolic_factorisations",
        }
    }
}

/// Accumulated call counts and exclusive seconds per stage, and the work
/// counters.
#[derive(Debug, Default)]
pub struct Profile {
    entries: [Cell<(u64, f64)>; Stage::ALL.len()],
    work: [Cell<u64>; Work::ALL.len()],
    /// The stage running now and when its current stretch of own time began.
    running: Cell<Option<(Stage, Instant)>>,
}

/// One row of the profile.
#[derive(Clone, Debug, Serialize)]
pub struct StageTotal {
    /// Stage name ([`OTHER`] for the remainder).
    pub stage: &'static str,
    /// Number of calls.
    pub calls: u64,
    /// Exclusive wall time, s.
    pub seconds: f64,
}

impl Profile {
    /// Time `f` under `stage`. A stage already running is paused meanwhile,
    /// so nested stages are never counted twice.
    pub fn time<T>(&self, stage: Stage, f: impl FnOnce() -> T) -> T {
        let start = Instant::now();
        let outer = self.running.get();
        if let Some((running, since)) = outer {
            self.charge(running, start - since, 0);
        }
        self.running.set(Some((stage, start)));
        let out = f();
        let end = Instant::now();
        if let Some((running, since)) = self.running.get() {
            self.charge(running, end - since, 0);
        }
        self.charge(stage, std::time::Duration::ZERO, 1);
        self.running.set(outer.map(|(running, _)| (running, end)));
        out
    }

    fn charge(&self, stage: Stage, elapsed: std::time::Duration, calls: u64) {
        let cell = &self.entries[stage as usize];
        let (n, s) = cell.get();
        cell.set((n + calls, s + elapsed.as_secs_f64()));
    }

    /// Add `n` to the counter `work` (call where the work is done; after a
    /// parallel loop, from its results).
    pub fn count(&self, work: Work, n: u64) {
        let cell = &self.work[work as usize];
        cell.set(cell.get() + n);
    }

    /// The counter `work` so far.
    pub fn work_count(&self, work: Work) -> u64 {
        self.work[work as usize].get()
    }

    /// Every counter, zeros included, in report order: (name, count).
    pub fn work(&self) -> Vec<(&'static str, u64)> {
        Work::ALL
            .iter()
            .map(|&w| (w.name(), self.work_count(w)))
            .collect()
    }

    /// The counters on one line, `work: name n, name n, …`.
    pub fn work_line(&self) -> String {
        let counts: Vec<String> = self
            .work()
            .iter()
            .map(|(name, n)| format!("{name} {n}"))
            .collect();
        format!("work: {}", counts.join(", "))
    }

    /// Calls and seconds of every stage so far, in [`Stage::ALL`] order.
    pub fn stage_entries(&self) -> Vec<(u64, f64)> {
        self.entries.iter().map(Cell::get).collect()
    }

    /// Add `entries` (calls and seconds per stage, in [`Stage::ALL`] order:
    /// an earlier process's share of a resumed run) to the stages.
    pub fn add_stage_entries(&self, entries: &[(u64, f64)]) {
        for (cell, &(calls, seconds)) in self.entries.iter().zip(entries) {
            let (n, s) = cell.get();
            cell.set((n + calls, s + seconds));
        }
    }

    /// Seconds charged to `stage` so far.
    pub fn seconds(&self, stage: Stage) -> f64 {
        self.entries[stage as usize].get().1
    }

    /// Totals per stage, in report order, then [`OTHER`]: the part of
    /// `wall_seconds` no stage covers (zero if the stages exceed it).
    pub fn totals(&self, wall_seconds: f64) -> Vec<StageTotal> {
        let mut rows: Vec<StageTotal> = Stage::ALL
            .iter()
            .map(|&stage| {
                let (calls, seconds) = self.entries[stage as usize].get();
                StageTotal {
                    stage: stage.name(),
                    calls,
                    seconds,
                }
            })
            .collect();
        let staged: f64 = rows.iter().map(|r| r.seconds).sum();
        rows.push(StageTotal {
            stage: OTHER,
            calls: 0,
            seconds: (wall_seconds - staged).max(0.0),
        });
        rows
    }

    /// A plain-text table of the totals with each stage's share of the wall time.
    pub fn table(&self, wall_seconds: f64) -> String {
        let mut out = format!(
            "{:<15} {:>10} {:>12} {:>8}\n",
            "stage", "calls", "seconds", "share"
        );
        for t in self.totals(wall_seconds) {
            let share = if wall_seconds > 0.0 {
                100.0 * t.seconds / wall_seconds
            } else {
                0.0
            };
            out += &format!(
                "{:<15} {:>10} {:>12.4} {:>7.1}%\n",
                t.stage, t.calls, t.seconds, share
            );
        }
        out += &format!("{:<15} {:>10} {:>12.4}\n", "wall", "", wall_seconds);
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn busy(seconds: f64) {
        let start = Instant::now();
        while start.elapsed().as_secs_f64() < seconds {
            std::hint::spin_loop();
        }
    }

    /// A stage nested in another is charged once: the outer stage's time
    /// excludes it, and the stage times add up to the elapsed time (to the
    /// few microseconds the timer calls themselves take).
    #[test]
    fn nested_stages_are_counted_once() {
        let profile = Profile::default();
        let start = Instant::now();
        profile.time(Stage::Newton, || {
            busy(0.01);
            profile.time(Stage::Solve, || busy(0.02));
            profile.time(Stage::Solve, || busy(0.02));
            busy(0.01);
        });
        let wall = start.elapsed().as_secs_f64();
        let newton = profile.seconds(Stage::Newton);
        let solve = profile.seconds(Stage::Solve);
        // at least the busy time each ran (more if the machine preempted it) …
        assert!(
            solve >= 0.04 && newton >= 0.02,
            "solve {solve}, newton {newton}"
        );
        // … and together exactly the elapsed time: counting the inner stage
        // in the outer one too would add its 0.04 s
        assert!(
            (newton + solve - wall).abs() < 1e-4,
            "{newton} + {solve} vs {wall}"
        );
        let totals = profile.totals(wall);
        let solve_row = totals.iter().find(|t| t.stage == "solve").unwrap();
        assert_eq!(solve_row.calls, 2);
        let sum: f64 = totals.iter().map(|t| t.seconds).sum();
        assert!((sum - wall).abs() < 1e-12);
    }

    /// Work counters add up per counter, never touch another one, and every
    /// counter is reported (zeros too) under a distinct name.
    #[test]
    fn work_counters_accumulate() {
        let profile = Profile::default();
        profile.count(Work::Assemblies, 2);
        profile.count(Work::Assemblies, 3);
        profile.count(Work::ReturnMappings, 0);
        profile.count(Work::NonlocalAverages, 1);
        assert_eq!(profile.work_count(Work::Assemblies), 5);
        assert_eq!(profile.work_count(Work::NonlocalAverages), 1);
        let work = profile.work();
        assert_eq!(work.len(), Work::ALL.len());
        for (i, w) in Work::ALL.iter().enumerate() {
            assert_eq!(*w as usize, i, "{w:?} out of place in Work::ALL");
        }
        for (w, (name, n)) in Work::ALL.iter().zip(&work) {
            assert_eq!(*name, w.name());
            let expected = match w {
                Work::Assemblies => 5,
                Work::NonlocalAverages => 1,
                _ => 0,
            };
            assert_eq!(*n, expected, "{name}");
        }
        let mut names: Vec<&str> = work.iter().map(|(name, _)| *name).collect();
        names.sort_unstable();
        names.dedup();
        assert_eq!(names.len(), Work::ALL.len());
        let line = profile.work_line();
        assert!(line.starts_with("work: mass_matrix 0, "), "{line}");
        assert!(line.contains("assemblies 5"), "{line}");
    }
}
