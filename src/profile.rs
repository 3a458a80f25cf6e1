//! Per-stage wall-time profile (call count and seconds per stage), reported
//! at the end of a run and written to `run.json`.
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
    /// Explicit: stable time step and nodal momentum update (DESIGN D20–D21).
    TimeStep,
    /// Implicit: the Newton loop's own work (convergence checks, residual
    /// norms, line-search bookkeeping), not the stages it calls.
    Newton,
    /// Constitutive stress update at the material points.
    StressUpdate,
    /// Nonlocal weights and averaging (DESIGN §6).
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
    /// Double mapping of the stresses (DESIGN §7).
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

/// Accumulated call counts and exclusive seconds per stage.
#[derive(Debug, Default)]
pub struct Profile {
    entries: [Cell<(u64, f64)>; Stage::ALL.len()],
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
}
