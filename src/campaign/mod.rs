//! A mesh-objectivity campaign: every scene of a directory run side by side,
//! a combined curve CSV, Fig. 3/4/5-style plots and the objectivity metrics of
//! theory §9 (M1–M4) in `metrics.csv` and `report.md`.
//!
//! Scenes are grouped into families by the presence of `[nonlocal]` (local vs
//! nonlocal); within a family the finest mesh is the reference (theory §9).
//! Curves are read from each run's `curve.csv`, in the columns of the scene's
//! monitors ([`CurveColumns`]): the abscissa is δ = −(displacement monitor) (m,
//! positive downward), the ordinate the force monitor (kN/m); a scene without
//! them is reported as having no load curve. With a step refinement K every
//! scene is also run at Δt / K and each curve's time-step discrepancy is
//! reported next to the run times (error against run time).
//!
//! `run.rs` finds the scenes and runs them; `report.rs` computes the metrics and
//! writes the combined outputs.

mod footing;
mod history;
mod record;
mod report;
mod run;
mod spec;

pub use footing::{
    corner_band_reach, soil_inside_outline, FootingGeometry, CORNER_BAND_STRAIN,
    CORNER_STRIP_HALF_WIDTH,
};
pub use history::{
    compute_history_metrics, failure_fall, History, HistoryColumns, HistoryMetrics,
    ONSET_DISPLACEMENT,
};
pub use record::{fingerprint_text, Part, RunRecord, RECORD_FILE};
pub use report::{compute_metrics, step_convergence, CurveColumns, RunMetrics, StepConvergence};
pub use run::{
    finish_campaign, plan_campaign, run_campaign, run_queued, CampaignOptions, CampaignPlan,
};
pub use spec::{Benchmark, CampaignSpec, IntegratorChoice, SPEC_FILE};

use crate::run::FieldSnapshot;
use crate::scene::AnalysisKind;

/// Why a campaign could not run.
#[derive(Debug, thiserror::Error)]
pub enum CampaignError {
    /// The directory could not be read or holds no scene.
    #[error("campaign directory {0}: {1}")]
    Directory(String, String),
    /// A scene is invalid (nothing was run).
    #[error("{0}")]
    Scene(String),
    /// An output could not be written.
    #[error("campaign output {0}: {1}")]
    Output(String, String),
    /// `--collect` (or a shard's own report) found runs without a finished
    /// record: their shards have not run yet, or stopped.
    #[error("campaign runs not finished (run their shards first): {0}")]
    Unfinished(String),
    /// Runs whose directories another live process holds (a second
    /// campaign into the same `--out`): not run here, nothing recorded.
    #[error("campaign runs being written by another process, not run here: {0}; run the campaign again once it has ended (finished runs are not run again)")]
    Locked(String),
    /// SIGINT or SIGTERM stopped the campaign: the runs in progress ended
    /// after a whole step (`run.json` says `interrupted`), no other started.
    #[error(
        "campaign interrupted by {}: {}; run the same command again to finish it",
        signal.name(),
        if stopped.is_empty() { "no run was in progress".to_string() } else { format!("{} stopped after a whole step (run.json says interrupted)", stopped.join(", ")) }
    )]
    Interrupted {
        /// The signal.
        signal: crate::interrupt::Interruption,
        /// The runs it stopped.
        stopped: Vec<String>,
    },
    /// A run's `curve.csv` cannot be read as its load curve.
    #[error("campaign curve {path}: {problem}")]
    Curve {
        /// The curve file.
        path: String,
        /// What is wrong with it.
        problem: CurveProblem,
    },
}

/// What is wrong with a run's `curve.csv`.
#[derive(Debug, thiserror::Error)]
pub enum CurveProblem {
    /// The file is missing or cannot be opened.
    #[error("cannot be opened ({0})")]
    Missing(String),
    /// The file is empty or its first line is not a header.
    #[error("has no header row")]
    NoHeader,
    /// A column named by the scene's monitors is not in the header.
    #[error("has no column `{0}`")]
    MissingColumn(String),
    /// A row the CSV reader refuses (wrong number of fields, not UTF-8).
    #[error("has a row that does not parse: {0}")]
    BadRow(String),
    /// A value in a curve column that is not a number.
    #[error("line {line}: `{value}` in column `{column}` is not a number")]
    NotANumber {
        /// Line of the file (1-based).
        line: u64,
        /// The column's name.
        column: String,
        /// The text found.
        value: String,
    },
}

/// One finished (or stopped) run of a campaign.
#[derive(Clone, Debug)]
pub struct CampaignRun {
    /// Scene file stem.
    pub name: String,
    /// Cell size h, m.
    pub cell_size: f64,
    /// Nonlocal length scale l_s, m (None: local).
    pub length_scale: Option<f64>,
    /// (δ, F) after every step (empty without a load curve or when the run's setup failed).
    pub curve: Vec<(f64, f64)>,
    /// The `curve.csv` columns of δ and F, from the scene's monitors (`None`:
    /// the scene has no load curve).
    pub curve_columns: Option<CurveColumns>,
    /// Final material-point positions, m.
    pub positions: Vec<[f64; 2]>,
    /// Final deviatoric strain εq (theory D8) per point.
    pub eps_q: Vec<f64>,
    /// Final nonlocal equivalent plastic strain κ̄ (D35) per point (nonlocal
    /// runs only; empty otherwise).
    pub kappa_bar: Vec<f64>,
    /// The error that stopped the run, if any.
    pub error: Option<String>,
    /// Points that left the grid and were removed (`[grid] lost_points = "remove"`):
    /// (count, removed mass / initial mass).
    pub lost_points: (usize, f64),
    /// Plastic dissipation at the last step (monitor `dissipation`, D43), kJ/m.
    pub dissipation: Option<f64>,
    /// Energy balance at the last step, from the monitors `external_work`,
    /// `internal_work` and `kinetic_energy` (when the scene has all three).
    pub energy: Option<EnergyBalance>,
    /// Wall time, s.
    pub wall_seconds: f64,
    /// Per-stage profile table.
    pub profile: String,
    /// 1 for the scene as written; K for its time-step refinement (K times the
    /// steps, Δt / K), run with `--step-refinement K`.
    pub step_factor: usize,
    /// The scene file the run was made from (its stem).
    pub scene: String,
    /// The integrator the run used.
    pub analysis: AnalysisKind,
    /// The scheme in words ([`crate::scene::Scene::scheme`]), for the report.
    pub scheme: String,
    /// Time histories of a time-history benchmark (the cut: u_A, q_B, run-out).
    pub history: Option<History>,
    /// Fields at the scene's `[output] snapshot_times` (paper Fig. 10).
    pub fields: Vec<FieldSnapshot>,
    /// Final volume of every material point, m³ per m.
    pub volumes: Vec<f64>,
    /// Volume of every material point before it deformed (m_p / ρ), m³ per
    /// m; empty for a record written before it was kept.
    pub initial_volumes: Vec<f64>,
    /// The rigid footing's outline (footing benchmark).
    pub footing: Option<FootingGeometry>,
    /// Steps taken, Newton iterations, step halvings (implicit cut-backs).
    pub effort: Effort,
}

/// What a run cost in steps and iterations.
#[derive(Clone, Copy, Debug, Default, serde::Serialize, serde::Deserialize)]
pub struct Effort {
    /// Steps completed.
    pub steps: usize,
    /// Newton iterations (implicit runs).
    pub newton_iterations: usize,
    /// Step halvings after a failed Newton solve (implicit cut-backs).
    pub halvings: usize,
}

impl CampaignRun {
    /// Family of the run: regularisation and integrator (theory §9: the
    /// reference of a run is the finest mesh of its family).
    pub fn same_family(&self, other: &CampaignRun) -> bool {
        self.length_scale.is_some() == other.length_scale.is_some()
            && self.analysis == other.analysis
    }

    /// `local` or `nonlocal`.
    pub fn regularisation(&self) -> &'static str {
        if self.length_scale.is_some() {
            "nonlocal"
        } else {
            "local"
        }
    }

    /// `implicit` or `explicit`.
    pub fn integrator(&self) -> &'static str {
        match self.analysis {
            AnalysisKind::Explicit => "explicit",
            _ => "implicit",
        }
    }
}

/// M5 energy balance of a run at its last step, kJ/m.
#[derive(Debug, Clone, Copy)]
pub struct EnergyBalance {
    /// Work of the pressures and rigid bodies on the soil.
    pub external: f64,
    /// Work of the stresses on the strain increments (stored + dissipated).
    pub internal: f64,
    /// Kinetic energy.
    pub kinetic: f64,
    /// Kinetic energy removed at the fixed dofs (monitor `boundary_work`,
    /// [`crate::integrators::boundary_work`]); zero when the scene has no
    /// such monitor.
    pub boundary: f64,
}

impl EnergyBalance {
    /// (W − W_int − K − B) / W: the share of the external work lost by the
    /// time integration (e.g. Newmark γ > ½ damping a dynamic snap;
    /// [`crate::energy`] E1 with K0 = 0).
    pub fn relative_loss(&self) -> f64 {
        (self.external - self.internal - self.kinetic - self.boundary) / self.external
    }
}

use mpm_physics::error_id::{ErrorId, Identified};

impl Identified for CampaignError {
    fn error_id(&self) -> ErrorId {
        match self {
            CampaignError::Directory(..) => ErrorId::CampaignDirectory,
            CampaignError::Scene(_) => ErrorId::CampaignScene,
            CampaignError::Output(..) => ErrorId::CampaignOutput,
            CampaignError::Unfinished(_) => ErrorId::CampaignUnfinished,
            CampaignError::Curve { .. } => ErrorId::CampaignCurve,
            CampaignError::Locked(_) => ErrorId::OutputLocked,
            CampaignError::Interrupted { .. } => ErrorId::Interrupted,
        }
    }
}

#[cfg(test)]
mod tests;
