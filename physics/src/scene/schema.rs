//! The scene file's serde structures and configuration enums: every key of
//! `docs/scene.md`, with its unit and default.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

/// A complete scene.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Scene {
    /// Analysis type, step count and time step.
    pub scene: Analysis,
    /// Background grid.
    pub grid: GridSpec,
    /// Nonlinear and linear solver settings.
    #[serde(default)]
    pub solver: SolverSpec,
    /// Materials by name.
    pub materials: BTreeMap<String, MaterialSpec>,
    /// Bodies filled with material points.
    pub body: Vec<BodySpec>,
    /// Body loads.
    #[serde(default)]
    pub loads: LoadSpec,
    /// Boundary conditions.
    #[serde(default)]
    pub bc: BoundarySpec,
    /// Output settings.
    #[serde(default)]
    pub output: OutputSpec,
    /// Monitored quantities written to `curve.csv`.
    #[serde(default)]
    pub monitor: Vec<MonitorSpec>,
    /// Nonlocal regularisation (absent: local model).
    #[serde(default)]
    pub nonlocal: Option<NonlocalSpec>,
    /// Stress smoothing.
    #[serde(default)]
    pub smoothing: SmoothingSpec,
    /// Resource limits checked before the run (defaults: half the available
    /// memory, 1e7 steps).
    #[serde(default)]
    pub limits: LimitsSpec,
}

/// `[limits]`: what a run may use, checked before anything big is allocated
/// ([`Scene::check_resources`]); `--max-memory` and `--max-steps` set them.
#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct LimitsSpec {
    /// Largest estimated memory, GB (10⁹ bytes); default half the memory
    /// available when the run starts.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max_memory_gb: Option<f64>,
    /// Largest number of steps (implicit `steps`, explicit `end_time` over the
    /// stable step); default 10⁷.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max_steps: Option<u64>,
}

pub use crate::nonlocal::{NonlocalSpec, NonlocalUpdate};

/// `[smoothing]`.
#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct SmoothingSpec {
    /// `auto` (on for softening materials with bilinear cells), `off`,
    /// `increment` or `total` (theory §7).
    #[serde(default)]
    pub double_mapping: DoubleMapping,
    /// Restore the internal forces of the unsmoothed stresses after smoothing
    /// (default false, the paper's double mapping; see
    /// `smoothing::restore_internal_forces`).
    #[serde(default)]
    pub restore_forces: bool,
}

/// `[smoothing] double_mapping`: which stress is smoothed (theory §7).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum DoubleMapping {
    /// `Increment` with bilinear cells when a material can soften (the
    /// paper's use), `Off` otherwise (GIMP: theory decision 27).
    #[default]
    Auto,
    /// No smoothing.
    Off,
    /// Smooth the step's stress increment σ(n+1) − σ^R(n) (theory D37–D38).
    Increment,
    /// Smooth the total stress σ(n+1).
    Total,
}

/// The time integration scheme.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum AnalysisKind {
    /// Implicit, no inertia (no mass matrix is built; theory §3 quasi-static variant).
    QuasiStatic,
    /// Implicit Newmark trapezoidal rule (paper eq. 2, theory D15–D17).
    ImplicitDynamic,
    /// Explicit MUSL central difference (theory §4).
    Explicit,
}

impl AnalysisKind {
    /// The value of `scene.analysis` that selects this scheme.
    pub fn key(self) -> &'static str {
        match self {
            Self::QuasiStatic => "quasi_static",
            Self::ImplicitDynamic => "implicit_dynamic",
            Self::Explicit => "explicit",
        }
    }
}

/// `[scene]`: analysis type and time stepping.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Analysis {
    /// Free-text name, written to `run.json`.
    #[serde(default)]
    pub name: String,
    /// `quasi_static`, `implicit_dynamic` or `explicit`.
    pub analysis: AnalysisKind,
    /// Number of (implicit) steps. Explicit runs end at `end_time` instead.
    #[serde(default)]
    pub steps: Option<usize>,
    /// Time step, s (quasi-static: pseudo-time per step, default 1). Explicit:
    /// a fixed step that must not exceed the stability limit; omit it to use the CFL rule.
    #[serde(default)]
    pub dt: Option<f64>,
    /// End time, s (explicit runs, and implicit runs with adaptive steps,
    /// which end at `steps` × `dt` when it is not given; other implicit runs
    /// end after `steps`).
    #[serde(default)]
    pub end_time: Option<f64>,
}

impl Analysis {
    /// The end time of a run that ends on time: `end_time`, else `steps` × `dt`.
    pub fn end_time_or_steps(&self) -> f64 {
        self.end_time
            .unwrap_or_else(|| self.steps.unwrap_or(0) as f64 * self.dt.unwrap_or(1.0))
    }
}

/// `[grid]`: the background grid.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct GridSpec {
    /// Lower-left corner, m.
    #[serde(default)]
    pub origin: [f64; 2],
    /// Width and height of the grid, m (multiples of `cell_size`).
    pub size: [f64; 2],
    /// Cell side h, m.
    pub cell_size: f64,
    /// Material points per cell and direction (1–4; the paper uses 2).
    #[serde(default = "default_points_per_cell")]
    pub points_per_cell: usize,
    /// `gauss` (Gauss–Legendre positions, theory §2) or `uniform` (sub-cell centres).
    #[serde(default)]
    pub point_layout: PointLayout,
    /// `bilinear` (theory D9, the paper's) or `gimp` (uGIMP: shape functions
    /// averaged over each point's square domain of side h/points_per_cell;
    /// needs `point_layout = "uniform"`).
    #[serde(default)]
    pub shape_functions: ShapeFunctionChoice,
    /// What happens when a material point leaves the grid: `stop` (default, the
    /// run ends with an error naming the point) or `remove` (the point is
    /// dropped from the run and listed in `run.json`; points tied to a rigid
    /// body or followed by a monitor still stop the run).
    #[serde(default)]
    pub lost_points: LostPointPolicy,
    /// `standard` (each point's own strain) or `b_bar` (each point's
    /// dilatation replaced by its cell's volume average: the volumetric
    /// locking remedy of [`crate::volumetric`], for ν → ½ and isochoric
    /// plastic flow; both integrators).
    #[serde(default)]
    pub volumetric: VolumetricTreatment,
    /// Largest volume a material point may take, in cell areas h² (× 1 m):
    /// V ← min(det(I + L) V, max_point_volume · h²) at every commit
    /// (theory D14 with a bound). Unset: unbounded. A point fully softened
    /// to the apex of the yield surface carries no tension, so the grid can
    /// stretch it without limit (measured on the vertical cut at h = 0.1 m:
    /// J = V/V₀ up to 2.6·10⁶ by t = 1 s); such a point would dominate the
    /// volume-weighted nonlocal average (D34) and, through its density
    /// m/V, drive the explicit stable step (D20) towards zero. One cell is
    /// the most space a point's integration domain can stand for.
    #[serde(default)]
    pub max_point_volume: Option<f64>,
}

/// `[grid] volumetric`: how the volumetric strain of a material point is taken.
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum VolumetricTreatment {
    /// The point's own strain (full quadrature: locks as ν → ½).
    #[default]
    Standard,
    /// B-bar: the cell's volume-averaged dilatation at every point of the
    /// cell, with its consistent tangent ([`crate::volumetric`] B1–B4).
    BBar,
}

/// `[grid] lost_points`: the treatment of material points that leave the grid.
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum LostPointPolicy {
    /// Stop the run with an error naming the point (outputs so far kept).
    #[default]
    Stop,
    /// Drop the point (e.g. a stress-free fragment ejected from a free surface)
    /// and record it; the run goes on.
    Remove,
}

/// Shape functions of the material points.
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum ShapeFunctionChoice {
    /// Bilinear shape functions of the holding cell (theory D9).
    #[default]
    Bilinear,
    /// Generalised interpolation material point (uGIMP): no cell-crossing error.
    Gimp,
}

fn default_points_per_cell() -> usize {
    2
}

/// Where material points are seeded inside a cell.
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum PointLayout {
    /// Gauss–Legendre positions with Gauss-weight volumes (theory §2 choice 14).
    #[default]
    Gauss,
    /// Centres of n×n equal sub-cells.
    Uniform,
}

/// Which linear solver factorises the tangent.
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum LinearSolverChoice {
    /// The multifrontal factorisation ([`Self::Multifrontal`]), with Cholesky fronts when
    /// every material has a symmetric tangent; faer's Cholesky or LU when `ordering` or
    /// `factorization` is set.
    #[default]
    Auto,
    /// Sparse Cholesky (falls back to LU if the matrix is not positive definite).
    Cholesky,
    /// Sparse LU with partial pivoting.
    Lu,
    /// Preconditioned conjugate gradients (`pcg_preconditioner`, `pcg_tolerance`); only for
    /// scenes whose materials all have a symmetric tangent (refused otherwise), LU where K
    /// turns out indefinite (recorded in run.json).
    Pcg,
    /// sprs_ldl's LDLᵀ (build with `--features ldl`); symmetric scenes only.
    Ldl,
    /// Sparse LU whose factors precondition GMRES for the next Newton iterations while the
    /// pattern holds (refactorised when GMRES needs more than 12 steps).
    LuReuse,
    /// Multifrontal factorisation on the symmetric pattern of K + Kᵀ (AMD ordering; Cholesky
    /// fronts for a symmetric positive definite K, else LU fronts with partial pivoting within
    /// each front; independent subtrees in parallel; one step of iterative refinement per
    /// solve with LU fronts); faer's LU for a system it cannot factorise accurately
    /// (recorded).
    Multifrontal,
}

/// `[solver] factorization`: faer's supernodal or simplicial factorisation.
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum FactorizationChoice {
    /// faer's automatic choice.
    #[default]
    Auto,
    /// Always supernodal.
    Supernodal,
    /// Always simplicial.
    Simplicial,
}

/// `[solver] ordering`: fill-reducing ordering of the factorisation.
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum OrderingChoice {
    /// AMD for Cholesky and LDLᵀ, COLAMD for LU.
    #[default]
    Default,
    /// Approximate minimum degree (LU: simplicial only).
    Amd,
    /// Column approximate minimum degree.
    Colamd,
    /// None: the dof numbering (LU: simplicial only).
    Identity,
}

/// `[solver] predictor`: where Newton starts each implicit dynamic step.
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum PredictorChoice {
    /// The nodal motion at the start of the step carried on: Δu⁰ = Δt v_n + ½ Δt² a_n at the
    /// free dofs (measured on the local footing, h = 0.25 m: 924 instead of 1,977 Newton
    /// iterations, the same curve to 4e-7).
    #[default]
    Motion,
    /// Zero at the free dofs (theory D17: only the prescribed increments).
    Zero,
}

/// `[solver] time_step`: how an implicit dynamic run chooses its steps.
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum TimeStepControl {
    /// `scene.dt` throughout (halved where Newton fails).
    #[default]
    Fixed,
    /// Steps chosen by the local error estimate against
    /// `solver.error_tolerance`, from `scene.dt` on, within
    /// [`dt_min`, `dt_max`] (theory "Error-controlled steps").
    Adaptive,
}

/// `[solver] path_following`: how a quasi-static run driven by rigid bodies
/// chooses its steps.
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum PathFollowing {
    /// Each step moves the rigid bodies by `velocity · scene.dt`
    /// (displacement control; halved where Newton fails).
    #[default]
    Off,
    /// The rigid bodies' travel is an unknown of each step: the travel is
    /// prescribed in the elastic range, the plastic travel (whose product
    /// with the load is the dissipated energy) once the steps are mostly
    /// plastic (theory §3.7, PF1–PF6): the run follows a load–displacement
    /// path through its peak and where it snaps back.
    Dissipation,
}

/// `[solver] pcg_preconditioner`.
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum PreconditionerChoice {
    /// Diagonal scaling.
    #[default]
    Jacobi,
    /// Zero-fill incomplete Cholesky, IC(0).
    IncompleteCholesky,
}

/// `[solver]`: Newton, linear solver and explicit settings (defaults of theory §3–4).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct SolverSpec {
    /// ε_R of theory D18 (relative residual force).
    pub tolerance_force: f64,
    /// ε_E of theory D18 (relative energy norm).
    pub tolerance_energy: f64,
    /// Newton iteration limit per step (default 25 local, 60 nonlocal, theory §3).
    pub max_iterations: Option<usize>,
    /// Number of step halvings allowed when Newton fails (theory §3: 4, i.e. 1/16).
    pub max_halvings: usize,
    /// The largest Newton correction of one node, in cell sizes: a node
    /// whose correction is longer has it scaled to this length, the other
    /// nodes keep theirs (theory §3.3, "Correction limit"); unset: none.
    pub max_correction: Option<f64>,
    /// Fixed steps: a step that needed halvings starts the next one at the
    /// depth that converged, 2^k equal substeps, and each step that passes
    /// at its starting depth lets the next try one level coarser (theory
    /// §3, "Remembered halvings"). Off: every step starts whole.
    pub remember_halvings: bool,
    /// `auto`, `cholesky`, `lu`, `pcg` or `ldl`.
    pub linear_solver: LinearSolverChoice,
    /// faer's `auto`, `supernodal` or `simplicial` factorisation.
    pub factorization: FactorizationChoice,
    /// Fill-reducing ordering: `default`, `amd`, `colamd` or `identity`.
    pub ordering: OrderingChoice,
    /// PCG preconditioner: `jacobi` or `incomplete_cholesky`.
    pub pcg_preconditioner: PreconditionerChoice,
    /// PCG stops when ‖R − Kδu‖/‖R‖ ≤ this, in (0, 1).
    pub pcg_tolerance: f64,
    /// PCG iteration limit (LU is used for a system that does not converge, recorded).
    pub pcg_max_iterations: usize,
    /// ε_bg of theory D19 (background stiffness added to the tangent only).
    pub background_stiffness: f64,
    /// Implicit dynamic: Newton's starting increment, `motion` or `zero`.
    pub predictor: PredictorChoice,
    /// Penalty factor β_pen of theory D41 (k_p = β_pen E); default 1e3 implicit, 10 explicit.
    pub penalty_factor: Option<f64>,
    /// Explicit: CFL factor α_CFL of theory D20, in (0, 1].
    pub cfl: f64,
    /// Explicit: local (Cundall) damping α_d of theory D21, in [0, 1).
    pub damping: f64,
    /// Implicit dynamic: Newmark γ in [0.5, 1], with β = (γ + ½)²/4. Unset
    /// (and no `rho_infinity`): ½, the trapezoidal rule of paper eq. 2 (D15,
    /// no numerical damping); γ > ½ damps the highest frequencies at the price
    /// of first-order accuracy.
    pub newmark_gamma: Option<f64>,
    /// Implicit dynamic: the generalised-α scheme of Chung and Hulbert with
    /// this spectral radius at infinite frequency, in [0, 1] (theory
    /// "Generalised-α"): second order for every value, the highest
    /// frequencies damped to ρ∞ per step; 1 is the trapezoidal rule.
    /// Refused together with `newmark_gamma`.
    pub rho_infinity: Option<f64>,
    /// Implicit dynamic: `fixed` (`scene.dt` throughout) or `adaptive`.
    pub time_step: TimeStepControl,
    /// Adaptive steps: the largest local error of a step relative to its
    /// displacement increment, in (0, 1).
    pub error_tolerance: f64,
    /// Adaptive steps: the smallest step, s (default `scene.dt`/1000).
    pub dt_min: Option<f64>,
    /// Adaptive steps: the largest step, s (default 100 `scene.dt`).
    pub dt_max: Option<f64>,
    /// Quasi-static runs driven by rigid bodies: `off` or `dissipation`.
    pub path_following: PathFollowing,
    /// Path following: the most steps the run may take to reach its end
    /// travel (default 10 × `scene.steps`).
    pub path_max_steps: Option<usize>,
}

impl SolverSpec {
    /// Whether a quasi-static run follows its path (dissipation control).
    pub fn follows_path(&self) -> bool {
        self.path_following == PathFollowing::Dissipation
    }

    /// The most steps a path-following run may take to its end travel:
    /// `path_max_steps`, by default 10 × the nominal `steps`.
    pub fn path_step_budget(&self, steps: Option<usize>) -> usize {
        self.path_max_steps
            .unwrap_or(10 * steps.unwrap_or(0).max(1))
    }

    /// Whether an implicit dynamic run chooses its own steps.
    pub fn adaptive(&self) -> bool {
        self.time_step == TimeStepControl::Adaptive
    }

    /// The adaptive steps' bounds [dt_min, dt_max], s, around the first step `dt`.
    pub fn step_bounds(&self, dt: f64) -> (f64, f64) {
        (
            self.dt_min.unwrap_or(1e-3 * dt),
            self.dt_max.unwrap_or(100.0 * dt),
        )
    }

    /// Newmark γ of the scene (½ when unset).
    pub fn gamma(&self) -> f64 {
        self.newmark_gamma.unwrap_or(0.5)
    }

    /// The implicit dynamic time scheme, for reports: "generalised-α ρ∞ = …"
    /// or "Newmark γ = …".
    pub fn time_scheme(&self) -> String {
        match self.rho_infinity {
            Some(rho) => format!("generalised-α ρ∞ = {rho}"),
            None => format!("Newmark γ = {}", self.gamma()),
        }
    }
}

impl Default for SolverSpec {
    fn default() -> Self {
        Self {
            tolerance_force: 1e-5,
            tolerance_energy: 1e-10,
            max_iterations: None,
            max_halvings: 4,
            max_correction: None,
            remember_halvings: false,
            linear_solver: LinearSolverChoice::Auto,
            factorization: FactorizationChoice::Auto,
            ordering: OrderingChoice::Default,
            pcg_preconditioner: PreconditionerChoice::Jacobi,
            pcg_tolerance: 1e-10,
            pcg_max_iterations: 10_000,
            background_stiffness: 1e-6,
            predictor: PredictorChoice::Motion,
            penalty_factor: None,
            cfl: 0.5,
            damping: 0.0,
            newmark_gamma: None,
            rho_infinity: None,
            time_step: TimeStepControl::Fixed,
            error_tolerance: 1e-3,
            dt_min: None,
            dt_max: None,
            path_following: PathFollowing::Off,
            path_max_steps: None,
        }
    }
}

/// A material, tagged by `model`. Read by `model` first, then as the
/// model's own parameter table, so that an error names the key inside the
/// material (`` `materials.soil.E` must be a number, not … (model `hmc`) ``).
#[derive(Debug, Clone, Serialize, PartialEq)]
#[serde(tag = "model", rename_all = "snake_case")]
pub enum MaterialSpec {
    /// Isotropic linear elasticity (theory D22).
    LinearElastic(ElasticSpec),
    /// Hyperbolic Mohr–Coulomb with exponential softening (paper eq. 3–5, theory §5),
    /// keys named as in the paper's Table 1.
    Hmc(crate::constitutive::hmc::HmcParameters),
    /// Von Mises elastic–perfectly plastic with undrained strength `c` (yield when
    /// √J₂ > c; Tresca's limit loads in plane strain, theory §8.4).
    VonMises(VonMisesSpec),
}

impl<'de> Deserialize<'de> for MaterialSpec {
    /// `model` first, then the model's own parameter table; an error names
    /// the key inside the table (`in `E`: …`, see `scene::diagnostics`)
    /// and the model.
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        use super::diagnostics::{message_and_keys, with_inner_key};
        use serde::de::Error;
        const MODELS: &str = "`linear_elastic`, `hmc` or `von_mises`";
        let mut table = toml::Table::deserialize(deserializer)?;
        let model = match table.remove("model") {
            Some(toml::Value::String(model)) => model,
            Some(other) => {
                return Err(D::Error::custom(with_inner_key(
                    &format!(
                        "must be a string naming the model ({MODELS}), not {}",
                        other.type_str()
                    ),
                    Some("model"),
                )))
            }
            None => return Err(D::Error::custom("missing field `model`")),
        };
        let parameters = toml::Value::Table(table);
        let parsed = match model.as_str() {
            "linear_elastic" => parameters.try_into().map(MaterialSpec::LinearElastic),
            "hmc" => parameters.try_into().map(MaterialSpec::Hmc),
            "von_mises" => parameters.try_into().map(MaterialSpec::VonMises),
            other => {
                return Err(D::Error::custom(with_inner_key(
                    &format!("unknown variant `{other}`, expected one of {MODELS}"),
                    Some("model"),
                )))
            }
        };
        parsed.map_err(|e: toml::de::Error| {
            let (message, keys) = message_and_keys(&e);
            D::Error::custom(format!(
                "{} (model `{model}`)",
                with_inner_key(&message, keys.as_deref())
            ))
        })
    }
}

/// Parameters of `model = "von_mises"`: `E` (kPa), `nu`, `density` (t/m³), `c` (kPa);
/// unknown keys are refused.
pub type VonMisesSpec = crate::constitutive::von_mises::VonMisesParameters;

/// Parameters of `model = "linear_elastic"`.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ElasticSpec {
    /// Young's modulus, kPa.
    #[serde(rename = "E")]
    pub youngs_modulus: f64,
    /// Poisson's ratio, in (−1, 0.5).
    pub nu: f64,
    /// Density, t/m³.
    pub density: f64,
}

impl MaterialSpec {
    /// Density ρ, t/m³.
    pub fn density(&self) -> f64 {
        match self {
            MaterialSpec::LinearElastic(e) => e.density,
            MaterialSpec::Hmc(h) => h.density,
            MaterialSpec::VonMises(v) => v.density,
        }
    }

    /// Young's modulus E, kPa (penalty stiffness and background stiffness scale).
    pub fn youngs_modulus(&self) -> f64 {
        match self {
            MaterialSpec::LinearElastic(e) => e.youngs_modulus,
            MaterialSpec::Hmc(h) => h.youngs_modulus,
            MaterialSpec::VonMises(v) => v.youngs_modulus,
        }
    }

    /// Poisson's ratio ν.
    pub fn poisson_ratio(&self) -> f64 {
        match self {
            MaterialSpec::LinearElastic(e) => e.nu,
            MaterialSpec::Hmc(h) => h.poisson_ratio,
            MaterialSpec::VonMises(v) => v.poisson_ratio,
        }
    }
}

/// Initial velocity profile of a body.
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum VelocityProfile {
    /// v = `velocity0` everywhere.
    #[default]
    Uniform,
    /// v = `velocity0` · sin(π (y − y_min) / (2 H)), H the body height (the bar's first mode, theory §8.4).
    QuarterSineY,
}

/// Geostatic (K0) initial stress: σyy = −γ (y_s − y), σxx = σzz = K0 σyy.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct K0Spec {
    /// Lateral earth pressure coefficient K0 ≥ 0.
    pub k0: f64,
    /// Unit weight γ, kN/m³.
    pub unit_weight: f64,
    /// Level y_s of the free surface, m.
    pub surface_y: f64,
}

/// `[[body]]`: a region filled with material points.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct BodySpec {
    /// Name used by boundary conditions (default `body<i>`).
    #[serde(default)]
    pub name: Option<String>,
    /// Name of a `[materials.*]` entry.
    pub material: String,
    /// Axis-aligned rectangle `[[x_min, y_min], [x_max, y_max]]`, m.
    #[serde(default, rename = "box")]
    pub rectangle: Option<[[f64; 2]; 2]>,
    /// Polygon vertices (counter-clockwise or clockwise), m; alternative to `box`.
    #[serde(default)]
    pub polygon: Option<Vec<[f64; 2]>>,
    /// Uniform initial stress `[σxx, σyy, σzz, σxy]`, kPa, tension positive.
    #[serde(default)]
    pub stress0: Option<[f64; 4]>,
    /// Geostatic initial stress (added to `stress0`).
    #[serde(default)]
    pub k0: Option<K0Spec>,
    /// Initial velocity, m/s.
    #[serde(default)]
    pub velocity0: Option<[f64; 2]>,
    /// Initial velocity profile.
    #[serde(default)]
    pub velocity_profile: VelocityProfile,
}

impl BodySpec {
    /// The body's outline as a polygon.
    pub fn outline(&self) -> Vec<[f64; 2]> {
        if let Some([lo, hi]) = self.rectangle {
            vec![lo, [hi[0], lo[1]], hi, [lo[0], hi[1]]]
        } else {
            self.polygon.clone().unwrap_or_default()
        }
    }

    /// Bounding box `[[x_min, y_min], [x_max, y_max]]`.
    pub fn bounds(&self) -> [[f64; 2]; 2] {
        let pts = self.outline();
        let mut b = [[f64::INFINITY; 2], [f64::NEG_INFINITY; 2]];
        for p in pts {
            for c in 0..2 {
                b[0][c] = b[0][c].min(p[c]);
                b[1][c] = b[1][c].max(p[c]);
            }
        }
        b
    }

    /// Name of body `index`.
    pub fn name_or_default(&self, index: usize) -> String {
        self.name.clone().unwrap_or_else(|| format!("body{index}"))
    }
}

/// Time-dependent gravity in steps: g(t) = min(max, increment · ⌈t / interval⌉)
/// (the paper's vertical cut: 0.1 g every 1 ms up to 60 g).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct GravityRamp {
    /// Gravity added per interval, m/s².
    pub increment: f64,
    /// Interval, s.
    pub interval: f64,
    /// Final gravity, m/s².
    pub max: f64,
}

/// `[loads]`: body forces.
#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct LoadSpec {
    /// Constant gravity acceleration along −y, m/s² (from the first step on).
    #[serde(default)]
    pub gravity: f64,
    /// Stepped gravity ramp (replaces `gravity`).
    #[serde(default)]
    pub gravity_ramp: Option<GravityRamp>,
}

impl LoadSpec {
    /// Gravity magnitude g(t), m/s² (acts along −y).
    pub fn gravity_at(&self, t: f64) -> f64 {
        match &self.gravity_ramp {
            Some(r) => (r.increment * (t / r.interval - 1e-9).ceil().max(0.0)).min(r.max),
            None => self.gravity,
        }
    }

    /// The first time after `t` at which the stepped gravity jumps, s (`None`
    /// when it no longer changes): the end of the ramp interval holding `t`.
    pub fn next_gravity_jump(&self, t: f64) -> Option<f64> {
        let r = self.gravity_ramp.as_ref()?;
        let next = ((t / r.interval + 1e-9).floor() + 1.0) * r.interval;
        (self.gravity_at(t) < r.max).then_some(next)
    }

    /// The jump of the stepped gravity just after `t`, g(t⁺) − g(t), m/s².
    pub fn gravity_jump_at(&self, t: f64) -> f64 {
        match &self.gravity_ramp {
            Some(r) => self.gravity_at(t + 1e-6 * r.interval) - self.gravity_at(t),
            None => 0.0,
        }
    }
}

/// A grid line `x=value` or `y=value`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GridLine {
    /// 0 for `x = value`, 1 for `y = value`.
    pub axis: usize,
    /// Coordinate of the line, m.
    pub value: f64,
}

impl GridLine {
    /// Parse `"x=0.03"` / `"y = 0"`.
    pub fn parse(text: &str) -> Result<Self, String> {
        let (lhs, rhs) = text
            .split_once('=')
            .ok_or_else(|| format!("`{text}` is not of the form `x=<value>` or `y=<value>`"))?;
        let axis = match lhs.trim() {
            "x" => 0,
            "y" => 1,
            other => return Err(format!("axis `{other}` must be `x` or `y`")),
        };
        let value: f64 = rhs
            .trim()
            .parse()
            .map_err(|_| format!("`{}` is not a number", rhs.trim()))?;
        if !value.is_finite() {
            return Err("the coordinate must be finite".into());
        }
        Ok(Self { axis, value })
    }
}

/// A displacement component.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum Component {
    /// Horizontal.
    X,
    /// Vertical.
    Y,
}

impl Component {
    /// 0 for x, 1 for y.
    pub fn index(self) -> usize {
        match self {
            Component::X => 0,
            Component::Y => 1,
        }
    }
}

/// `[[bc.fixed]]`: homogeneous Dirichlet condition on a grid line (roller or fixity).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct FixedSpec {
    /// Grid line `x=<value>` or `y=<value>` (must coincide with a grid line).
    pub line: String,
    /// Fixed components, `["x"]`, `["y"]` or `["x", "y"]`.
    pub dofs: Vec<Component>,
}

/// `[[bc.prescribed]]`: a prescribed nodal displacement on a grid line
/// (validation scenes): u(t, x) = D(t) · (rate + gradient · x), D(t) = t
/// after the start ramp ([`crate::start_ramp::StartRamp`]).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct PrescribedSpec {
    /// Grid line `x=<value>` or `y=<value>`.
    pub line: String,
    /// Prescribed component.
    pub dof: Component,
    /// Displacement rate, m per unit time.
    #[serde(default)]
    pub rate: f64,
    /// Spatial gradient of the rate, 1/time (for homogeneous strain fields).
    #[serde(default)]
    pub gradient: [f64; 2],
    /// Time over which the rate rises smoothly from 0 to its value
    /// ([`crate::start_ramp::StartRamp`]), s or pseudo-time; 0 (default): the
    /// full rate from t = 0.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub ramp_time: f64,
}

/// Whether a default-zero key is at its default (left out of the scene
/// written with the run, which then reads as before the key existed).
fn is_zero(value: &f64) -> bool {
    *value == 0.0
}

/// Side of a rectangular body.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum Side {
    /// x = x_min.
    Left,
    /// x = x_max.
    Right,
    /// y = y_min.
    Bottom,
    /// y = y_max.
    Top,
}

/// `[[bc.pressure]]`: a follower pressure on a side of a rectangular body, or
/// on edges of a polygon body (theory §8.0 traction points).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct PressureSpec {
    /// Body name (default: the first body).
    #[serde(default)]
    pub body: Option<String>,
    /// Loaded side of a `box` body.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub side: Option<Side>,
    /// Loaded edges `[first, last]` (inclusive) of a `polygon` body: edge k
    /// joins vertex k to vertex k + 1 (the last vertex to the first).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub edges: Option<[usize; 2]>,
    /// Pressure, kPa (positive pushes into the body).
    pub p: f64,
}

/// `[[bc.friction]]`: a grid line on the edge of the grid that the soil
/// cannot cross and along which it slides with Coulomb friction (theory
/// "Frictional boundary"): the tangential reaction is at most μ times the
/// normal one, and none acts where the soil pulls away.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct FrictionSpec {
    /// Grid line `x=<value>` or `y=<value>` on the edge of the grid.
    pub line: String,
    /// Friction coefficient μ ≥ 0 (e.g. tan φ of the soil on the base).
    pub mu: f64,
}

/// `[[bc.rigid]]`: a rigid, perfectly rough platen or footing driving the top
/// material points of a body (theory D40–D41).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct RigidSpec {
    /// Name (used by monitors).
    pub name: String,
    /// Body name (default: the first body).
    #[serde(default)]
    pub body: Option<String>,
    /// Horizontal extent `[x_min, x_max]` of the contact, m.
    pub footprint: [f64; 2],
    /// Prescribed rigid velocity, m per unit time (quasi-static: per step with dt = 1).
    pub velocity: [f64; 2],
    /// Time over which the velocity rises smoothly from 0 to `velocity`
    /// ([`crate::start_ramp::StartRamp`]), s or pseudo-time; 0 (default): the
    /// full velocity from t = 0.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub ramp_time: f64,
    /// Where the body is tied to the soil: `top_points` (the top row of
    /// material points, theory §8.0) or `surface` (points on the soil surface).
    #[serde(default)]
    pub contact: ContactKind,
}

/// Where a rigid body's penalty springs hold the soil (theory D40–D41).
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum ContactKind {
    /// The material points of the body's top point row inside the footprint
    /// (theory §8.0). The soil between that row and the surface moves with the
    /// rigid body, which stiffens the response by O(h).
    #[default]
    TopPoints,
    /// Massless points on the body's top surface inside the footprint, two per
    /// cell-wide segment, moving with the soil surface: the tie acts where the
    /// body touches the soil.
    Surface,
}

/// `[bc]`: all boundary conditions.
#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct BoundarySpec {
    /// Homogeneous Dirichlet lines.
    #[serde(default)]
    pub fixed: Vec<FixedSpec>,
    /// Prescribed nodal displacements.
    #[serde(default)]
    pub prescribed: Vec<PrescribedSpec>,
    /// Pressures on body sides.
    #[serde(default)]
    pub pressure: Vec<PressureSpec>,
    /// Rigid platens / footings.
    #[serde(default)]
    pub rigid: Vec<RigidSpec>,
    /// Frictional grid edges.
    #[serde(default)]
    pub friction: Vec<FrictionSpec>,
}

/// `[output]`.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct OutputSpec {
    /// Write a `curve.csv` row every this many steps (the last step is always written).
    pub curve_every: usize,
    /// Steps at which to write particle snapshots (`.vtu`); step 0 is the initial state.
    pub snapshots: Vec<usize>,
    /// Also write a snapshot every this many steps (0 = never).
    pub snapshot_every: usize,
    /// Also write a snapshot at the end of the first step that reaches each of
    /// these times, s (explicit runs choose their own steps).
    pub snapshot_times: Vec<f64>,
    /// Implicit runs: steps whose every Newton iteration's system (tangent, residual,
    /// correction) is written to `systems/` in Matrix Market format with a JSON description.
    pub systems: Vec<usize>,
    /// A system whose files would exceed this many MB is skipped with a warning.
    pub systems_max_mb: f64,
    /// Warn at the end of a run whose energy remainder |W − W_int − ΔK − B|
    /// exceeds this share of the energy put in ([`crate::energy`] E1);
    /// unset (the default): no warning, since a dynamic collapse loses most
    /// of the work of gravity to the integrator (Newmark γ > ½, MUSL).
    pub energy_remainder_warning: Option<f64>,
}

impl Default for OutputSpec {
    fn default() -> Self {
        Self {
            curve_every: 1,
            snapshots: Vec::new(),
            snapshot_every: 0,
            snapshot_times: Vec::new(),
            systems: Vec::new(),
            systems_max_mb: 500.0,
            energy_remainder_warning: None,
        }
    }
}

/// What a monitor measures.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum MonitorKind {
    /// Displacement of the material point initially nearest `point`.
    PointDisplacement,
    /// Velocity of the material point initially nearest `point`.
    PointVelocity,
    /// Stress quantity (`quantity`) at the material point initially nearest `point`.
    PointStress,
    /// `quantity` of the points that started within `radius` of `point`
    /// (default one cell), volume-weighted: stresses of the group's mean
    /// stress tensor, the mean κ or κ̄, or the group's centre (`x`, `y`).
    /// Smooths the single-point noise of `point_stress`.
    NeighbourhoodStress,
    /// Reaction force on the constrained nodes of grid line `line` (kN/m).
    Reaction,
    /// Force exerted by rigid body `rigid` on the soil (kN/m, theory D40).
    RigidForce,
    /// Mean displacement of the points tied to rigid body `rigid` (m): the
    /// displacement of the contact surface for `contact = "surface"`.
    RigidDisplacement,
    /// Total kinetic energy Σ ½ m_p |v_p|², kJ/m.
    KineticEnergy,
    /// Total elastic strain energy Σ ½ V_p σ_pᵀ C σ_p, kJ/m.
    StrainEnergy,
    /// Work of the pressures, rigid bodies and gravity on the soil so far,
    /// kJ/m (see `State::external_work`).
    ExternalWork,
    /// Work of the stresses on the strain increments so far (elastic energy
    /// stored plus dissipation), kJ/m.
    InternalWork,
    /// Maximum equivalent plastic strain over all material points.
    MaxPlasticStrain,
    /// Accumulated plastic dissipation (theory D43, M5), kJ/m.
    DissipatedEnergy,
    /// Kinetic energy removed at the fixed dofs so far, kJ/m
    /// (`crate::integrators::boundary_work` B1).
    BoundaryWork,
    /// The remainder of the energy budget W − W_int − (K − K0) − B, kJ/m: the
    /// integrator's numerical dissipation (`crate::energy` E1).
    EnergyRemainder,
    /// Current gravity, m/s².
    Gravity,
    /// Run-out front x_front = max_p x_p, m: the largest horizontal extent of
    /// the material (theory §8.3).
    RunOut,
}

/// A component selector for vector monitors.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum VectorComponent {
    /// x component.
    X,
    /// y component.
    Y,
    /// Euclidean norm.
    Norm,
}

/// A quantity of `point_stress` and `neighbourhood_stress`.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum StressQuantity {
    /// σxx, kPa.
    Sxx,
    /// σyy, kPa.
    Syy,
    /// σzz, kPa.
    Szz,
    /// σxy, kPa.
    Sxy,
    /// Mean stress p (compression positive, theory D1), kPa.
    P,
    /// Deviatoric stress q (paper eq. 7, theory D5), kPa.
    Q,
    /// Equivalent plastic strain κ (local).
    Kappa,
    /// Nonlocal equivalent plastic strain κ̄ (κ where there is no
    /// regularisation).
    KappaBar,
    /// Horizontal position of the point (of the group's centre), m.
    X,
    /// Vertical position of the point (of the group's centre), m.
    Y,
}

/// `[[monitor]]`: one column of `curve.csv`, value = `scale` · raw + `offset`.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct MonitorSpec {
    /// Column name in `curve.csv`.
    pub name: String,
    /// What is measured.
    pub kind: MonitorKind,
    /// Point for `point_*` monitors, m.
    #[serde(default)]
    pub point: Option<[f64; 2]>,
    /// Grid line for `reaction`.
    #[serde(default)]
    pub line: Option<String>,
    /// Rigid body name for `rigid_force`.
    #[serde(default)]
    pub rigid: Option<String>,
    /// Component for vector monitors (default `y`).
    #[serde(default)]
    pub component: Option<VectorComponent>,
    /// Quantity for `point_stress` and `neighbourhood_stress`.
    #[serde(default)]
    pub quantity: Option<StressQuantity>,
    /// Radius of the group of `neighbourhood_stress`, m (default: the cell
    /// size).
    #[serde(default)]
    pub radius: Option<f64>,
    /// Scale factor (default 1).
    #[serde(default = "one")]
    pub scale: f64,
    /// Offset (default 0).
    #[serde(default)]
    pub offset: f64,
}

fn one() -> f64 {
    1.0
}
