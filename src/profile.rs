//! Per-stage wall-time profile (call count and seconds per stage), reported
//! at the end of a run and written to `run.json`.

use std::cell::Cell;
use std::time::Instant;

use serde::Serialize;

/// The stages of an MPM step (paper Fig. 1) and the solver around it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Stage {
    /// Shape functions, binning, dof numbering.
    Setup,
    /// Particle-to-grid transfers (mass, momentum, forces).
    P2G,
    /// Constitutive stress update at the material points.
    StressUpdate,
    /// Nonlocal weights and averaging (DESIGN §6).
    Nonlocal,
    /// Double mapping of the stresses (DESIGN §7).
    Smoothing,
    /// Tangent assembly (cell blocks and CSC values).
    Assembly,
    /// Sparse factorisation (symbolic + numeric).
    Factorisation,
    /// Triangular solves.
    Solve,
    /// Grid-to-particle update of positions, velocities, deformation.
    G2P,
    /// Curve rows and snapshots.
    Output,
}

impl Stage {
    /// All stages in report order.
    pub const ALL: [Stage; 10] = [
        Stage::Setup,
        Stage::P2G,
        Stage::StressUpdate,
        Stage::Nonlocal,
        Stage::Assembly,
        Stage::Factorisation,
        Stage::Solve,
        Stage::Smoothing,
        Stage::G2P,
        Stage::Output,
    ];

    /// Report name.
    pub fn name(self) -> &'static str {
        match self {
            Stage::Setup => "setup",
            Stage::P2G => "p2g",
            Stage::StressUpdate => "stress_update",
            Stage::Nonlocal => "nonlocal",
            Stage::Smoothing => "double_mapping",
            Stage::Assembly => "assembly",
            Stage::Factorisation => "factorisation",
            Stage::Solve => "solve",
            Stage::G2P => "g2p",
            Stage::Output => "output",
        }
    }
}

/// Accumulated call counts and seconds per stage.
#[derive(Debug, Default)]
pub struct Profile {
    entries: [Cell<(u64, f64)>; 10],
}

/// One row of the profile.
#[derive(Clone, Debug, Serialize)]
pub struct StageTotal {
    /// Stage name.
    pub stage: &'static str,
    /// Number of calls.
    pub calls: u64,
    /// Total wall time, s.
    pub seconds: f64,
}

impl Profile {
    /// Time `f` under `stage`.
    pub fn time<T>(&self, stage: Stage, f: impl FnOnce() -> T) -> T {
        let start = Instant::now();
        let out = f();
        self.add(stage, start.elapsed().as_secs_f64());
        out
    }

    /// Add one call of `seconds` to `stage`.
    pub fn add(&self, stage: Stage, seconds: f64) {
        let cell = &self.entries[stage as usize];
        let (n, s) = cell.get();
        cell.set((n + 1, s + seconds));
    }

    /// Totals per stage, in report order.
    pub fn totals(&self) -> Vec<StageTotal> {
        Stage::ALL
            .iter()
            .map(|&st| {
                let (calls, seconds) = self.entries[st as usize].get();
                StageTotal {
                    stage: st.name(),
                    calls,
                    seconds,
                }
            })
            .collect()
    }

    /// A plain-text table of the totals.
    pub fn table(&self, wall_seconds: f64) -> String {
        let mut out = format!(
            "{:<15} {:>10} {:>12} {:>8}\n",
            "stage", "calls", "seconds", "share"
        );
        for t in self.totals() {
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
