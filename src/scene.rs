//! Scene files (TOML): plain serde structures, `--set` overrides, and the one
//! place where every value is validated before a run.
//!
//! Every key is documented in `docs/scene.md`. Unknown keys are refused by
//! `deny_unknown_fields`; [`Scene::validate`] returns every semantic problem
//! with the path of the offending field and the allowed range.

use std::collections::BTreeMap;
use std::fmt;
use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::constitutive::ConstitutiveModel;

/// One problem found in a scene: the field path (`grid.cell_size`,
/// `body[0].box`, …) and what is wrong with it.
#[derive(Debug, Clone, PartialEq)]
pub struct FieldError {
    /// Dotted path of the offending field.
    pub field: String,
    /// What is wrong and what is allowed.
    pub message: String,
}

impl fmt::Display for FieldError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}: {}", self.field, self.message)
    }
}

/// Why a scene could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    /// The file could not be read.
    #[error("cannot read scene file {path}: {source}")]
    Io {
        /// The scene path.
        path: String,
        /// The I/O error.
        source: std::io::Error,
    },
    /// TOML syntax error, unknown key, or a value of the wrong type.
    #[error("scene {path}: {message}")]
    Parse {
        /// The scene path.
        path: String,
        /// The parser's message (names the key and its location).
        message: String,
    },
    /// A `--set key=value` override that cannot be applied.
    #[error("override `{assignment}`: {message}")]
    Override {
        /// The override as given.
        assignment: String,
        /// What is wrong with it.
        message: String,
    },
    /// Values out of range or impossible geometry.
    #[error("scene {path} is invalid:\n{}", list(.errors))]
    Invalid {
        /// The scene path.
        path: String,
        /// Every problem found.
        errors: Vec<FieldError>,
    },
}

fn list(errors: &[FieldError]) -> String {
    errors
        .iter()
        .map(|e| format!("  - {e}"))
        .collect::<Vec<_>>()
        .join("\n")
}

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
}

/// When the nonlocal variable is updated (DESIGN §6).
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum NonlocalUpdate {
    /// Every Newton iteration, lagged by one (DESIGN D36).
    #[default]
    Iteration,
    /// Once per step after convergence (strength frozen at κ̄(n)); explicit runs always.
    Step,
}

/// `[nonlocal]`: averaging of the equivalent plastic strain (paper eq. 6, DESIGN §6).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct NonlocalSpec {
    /// Length scale l_s, m (> cell size; ≥ 5 cells recommended, the paper's 0.2 l_s rule).
    pub length_scale: f64,
    /// Cutoff radius in units of l_s (DESIGN: 3).
    #[serde(default = "default_cutoff")]
    pub cutoff_factor: f64,
    /// `iteration` (default) or `step`.
    #[serde(default)]
    pub update: NonlocalUpdate,
    /// ε_κ of DESIGN D18 (third criterion).
    #[serde(default = "default_kappa_tolerance")]
    pub tolerance: f64,
    /// Over-nonlocal factor m in [1, 3] (Vermeer & Brinkgreve 1994): κ̄ = κ̄(n) +
    /// m Σ_q W_pq Δκ_q + (1 − m) Δκ_p. The default 1 is DESIGN D35.
    #[serde(default = "default_over_nonlocal")]
    pub over_nonlocal: f64,
}

fn default_over_nonlocal() -> f64 {
    1.0
}

fn default_cutoff() -> f64 {
    3.0
}

fn default_kappa_tolerance() -> f64 {
    1e-3
}

/// `[smoothing]`.
#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct SmoothingSpec {
    /// `auto` (on for softening materials), `off`, `increment` or `total` (DESIGN §7).
    #[serde(default)]
    pub double_mapping: DoubleMapping,
    /// Restore the internal forces of the unsmoothed stresses after smoothing
    /// (default false, the paper's double mapping; see
    /// `smoothing::restore_internal_forces`).
    #[serde(default)]
    pub restore_forces: bool,
}

/// `[smoothing] double_mapping`: which stress is smoothed (DESIGN §7).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum DoubleMapping {
    /// On for materials that can soften, off otherwise (the paper's use).
    #[default]
    Auto,
    /// No smoothing.
    Off,
    /// Smooth the step's stress increment σ(n+1) − σ^R(n) (DESIGN D37–D38).
    Increment,
    /// Smooth the total stress σ(n+1).
    Total,
}

/// The time integration scheme.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum AnalysisKind {
    /// Implicit, no inertia (no mass matrix is built; DESIGN §3 quasi-static variant).
    QuasiStatic,
    /// Implicit Newmark trapezoidal rule (paper eq. 2, DESIGN D15–D17).
    ImplicitDynamic,
    /// Explicit MUSL central difference (DESIGN §4).
    Explicit,
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
    /// End time, s (explicit runs; implicit runs end after `steps`).
    #[serde(default)]
    pub end_time: Option<f64>,
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
    /// `gauss` (Gauss–Legendre positions, DESIGN §2) or `uniform` (sub-cell centres).
    #[serde(default)]
    pub point_layout: PointLayout,
    /// `bilinear` (DESIGN D9, the paper's) or `gimp` (uGIMP: shape functions
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
    /// Bilinear shape functions of the holding cell (DESIGN D9).
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
    /// Gauss–Legendre positions with Gauss-weight volumes (DESIGN §2 choice 14).
    #[default]
    Gauss,
    /// Centres of n×n equal sub-cells.
    Uniform,
}

/// Which linear solver factorises the tangent.
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum LinearSolverChoice {
    /// Cholesky when every material has a symmetric tangent, LU otherwise.
    #[default]
    Auto,
    /// Sparse Cholesky (falls back to LU if the matrix is not positive definite).
    Cholesky,
    /// Sparse LU with partial pivoting.
    Lu,
}

/// `[solver]`: Newton, linear solver and explicit settings (defaults of DESIGN §3–4).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct SolverSpec {
    /// ε_R of DESIGN D18 (relative residual force).
    pub tolerance_force: f64,
    /// ε_E of DESIGN D18 (relative energy norm).
    pub tolerance_energy: f64,
    /// Newton iteration limit per step (default 25 local, 60 nonlocal, DESIGN §3).
    pub max_iterations: Option<usize>,
    /// Number of step halvings allowed when Newton fails (DESIGN §3: 4, i.e. 1/16).
    pub max_halvings: usize,
    /// `auto`, `cholesky` or `lu`.
    pub linear_solver: LinearSolverChoice,
    /// ε_bg of DESIGN D19 (background stiffness added to the tangent only).
    pub background_stiffness: f64,
    /// Penalty factor β_pen of DESIGN D41 (k_p = β_pen E); default 1e3 implicit, 10 explicit.
    pub penalty_factor: Option<f64>,
    /// Explicit: CFL factor α_CFL of DESIGN D20, in (0, 1].
    pub cfl: f64,
    /// Explicit: local (Cundall) damping α_d of DESIGN D21, in [0, 1).
    pub damping: f64,
    /// Implicit dynamic: Newmark γ in [0.5, 1], with β = (γ + ½)²/4. The
    /// default ½ is the trapezoidal rule of paper eq. 2 (D15, no numerical
    /// damping); γ > ½ damps the highest frequencies.
    pub newmark_gamma: f64,
}

impl Default for SolverSpec {
    fn default() -> Self {
        Self {
            tolerance_force: 1e-5,
            tolerance_energy: 1e-10,
            max_iterations: None,
            max_halvings: 4,
            linear_solver: LinearSolverChoice::Auto,
            background_stiffness: 1e-6,
            penalty_factor: None,
            cfl: 0.5,
            damping: 0.0,
            newmark_gamma: 0.5,
        }
    }
}

/// A material, tagged by `model`.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(tag = "model", rename_all = "snake_case")]
pub enum MaterialSpec {
    /// Isotropic linear elasticity (DESIGN D22).
    LinearElastic(ElasticSpec),
    /// Hyperbolic Mohr–Coulomb with exponential softening (paper eq. 3–5, DESIGN §5),
    /// keys named as in the paper's Table 1.
    Hmc(crate::constitutive::hmc::HmcParameters),
}

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
        }
    }

    /// Young's modulus E, kPa (penalty stiffness and background stiffness scale).
    pub fn youngs_modulus(&self) -> f64 {
        match self {
            MaterialSpec::LinearElastic(e) => e.youngs_modulus,
            MaterialSpec::Hmc(h) => h.youngs_modulus,
        }
    }

    /// Poisson's ratio ν.
    pub fn poisson_ratio(&self) -> f64 {
        match self {
            MaterialSpec::LinearElastic(e) => e.nu,
            MaterialSpec::Hmc(h) => h.poisson_ratio,
        }
    }

    fn validate(&self, prefix: &str, errors: &mut Vec<FieldError>) {
        match self {
            MaterialSpec::LinearElastic(e) => {
                check(
                    errors,
                    format!("{prefix}.E"),
                    e.youngs_modulus > 0.0,
                    format!("must be > 0 kPa (got {})", e.youngs_modulus),
                );
                check(
                    errors,
                    format!("{prefix}.nu"),
                    e.nu > -1.0 && e.nu < 0.5,
                    format!("must lie in (-1, 0.5) (got {})", e.nu),
                );
                check(
                    errors,
                    format!("{prefix}.density"),
                    e.density > 0.0,
                    format!("must be > 0 t/m³ (got {})", e.density),
                );
            }
            MaterialSpec::Hmc(h) => {
                errors.extend(h.validate().into_iter().map(|problem| FieldError {
                    field: format!("{prefix}.{}", problem.key),
                    message: problem.message,
                }));
            }
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
    /// v = `velocity0` · sin(π (y − y_min) / (2 H)), H the body height (the bar's first mode, DESIGN §8.4).
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
/// (validation scenes): u(t, x) = t · (rate + gradient · x).
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

/// `[[bc.pressure]]`: a follower pressure on a side of a rectangular body (DESIGN §8.0 traction points).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct PressureSpec {
    /// Body name (default: the first body).
    #[serde(default)]
    pub body: Option<String>,
    /// Loaded side.
    pub side: Side,
    /// Pressure, kPa (positive pushes into the body).
    pub p: f64,
}

/// `[[bc.rigid]]`: a rigid, perfectly rough platen or footing driving the top
/// material points of a body (DESIGN D40–D41).
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
    /// Where the body is tied to the soil: `top_points` (the top row of
    /// material points, DESIGN §8.0) or `surface` (points on the soil surface).
    #[serde(default)]
    pub contact: ContactKind,
}

/// Where a rigid body's penalty springs hold the soil (DESIGN D40–D41).
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum ContactKind {
    /// The material points of the body's top point row inside the footprint
    /// (DESIGN §8.0). The soil between that row and the surface moves with the
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
}

impl Default for OutputSpec {
    fn default() -> Self {
        Self {
            curve_every: 1,
            snapshots: Vec::new(),
            snapshot_every: 0,
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
    /// Reaction force on the constrained nodes of grid line `line` (kN/m).
    Reaction,
    /// Force exerted by rigid body `rigid` on the soil (kN/m, DESIGN D40).
    RigidForce,
    /// Mean displacement of the points tied to rigid body `rigid` (m): the
    /// displacement of the contact surface for `contact = "surface"`.
    RigidDisplacement,
    /// Total kinetic energy Σ ½ m_p |v_p|², kJ/m.
    KineticEnergy,
    /// Total elastic strain energy Σ ½ V_p σ_pᵀ C σ_p, kJ/m.
    StrainEnergy,
    /// Work of the pressures and rigid bodies on the soil so far, kJ/m (gravity
    /// not included; see `Simulation::external_work`).
    ExternalWork,
    /// Work of the stresses on the strain increments so far (elastic energy
    /// stored plus dissipation), kJ/m.
    InternalWork,
    /// Maximum equivalent plastic strain over all material points.
    MaxPlasticStrain,
    /// Accumulated plastic dissipation (DESIGN D43, M5), kJ/m.
    DissipatedEnergy,
    /// Current gravity, m/s².
    Gravity,
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

/// A stress quantity for `point_stress`.
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
    /// Mean stress p (compression positive, DESIGN D1), kPa.
    P,
    /// Deviatoric stress q (paper eq. 7, DESIGN D5), kPa.
    Q,
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
    /// Quantity for `point_stress`.
    #[serde(default)]
    pub quantity: Option<StressQuantity>,
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

fn check(
    errors: &mut Vec<FieldError>,
    field: impl Into<String>,
    ok: bool,
    message: impl Into<String>,
) {
    if !ok {
        errors.push(FieldError {
            field: field.into(),
            message: message.into(),
        });
    }
}

/// Number of whole cells of size `h` in `length`, if `length` is a multiple of `h`.
fn whole_cells(length: f64, h: f64) -> Option<usize> {
    let n = (length / h).round();
    if n >= 1.0 && (length - n * h).abs() <= 1e-9 * length.abs().max(h) {
        Some(n as usize)
    } else {
        None
    }
}

/// Point-in-polygon test (crossing number); points on the boundary count as inside
/// only up to round-off, so callers seed strictly interior positions.
pub fn polygon_contains(polygon: &[[f64; 2]], x: [f64; 2]) -> bool {
    let mut inside = false;
    let n = polygon.len();
    for i in 0..n {
        let (a, b) = (polygon[i], polygon[(i + 1) % n]);
        if (a[1] > x[1]) != (b[1] > x[1]) {
            let t = (x[1] - a[1]) / (b[1] - a[1]);
            if x[0] < a[0] + t * (b[0] - a[0]) {
                inside = !inside;
            }
        }
    }
    inside
}

impl Scene {
    /// Read, apply `overrides` (`key.path=value`), parse and validate a scene file.
    pub fn load(path: &Path, overrides: &[String]) -> Result<Scene, SceneError> {
        let text = std::fs::read_to_string(path).map_err(|source| SceneError::Io {
            path: path.display().to_string(),
            source,
        })?;
        Self::from_str_with_overrides(&text, &path.display().to_string(), overrides)
    }

    /// Parse and validate scene text (`origin` names it in messages).
    pub fn from_str_with_overrides(
        text: &str,
        origin: &str,
        overrides: &[String],
    ) -> Result<Scene, SceneError> {
        let mut table: toml::Table =
            text.parse()
                .map_err(|e: toml::de::Error| SceneError::Parse {
                    path: origin.to_string(),
                    message: e.to_string(),
                })?;
        for assignment in overrides {
            apply_override(&mut table, assignment)?;
        }
        let scene: Scene = toml::Value::Table(table)
            .try_into()
            .map_err(|e: toml::de::Error| SceneError::Parse {
                path: origin.to_string(),
                message: e.to_string(),
            })?;
        let errors = scene.validate();
        if errors.is_empty() {
            Ok(scene)
        } else {
            Err(SceneError::Invalid {
                path: origin.to_string(),
                errors,
            })
        }
    }

    /// Number of cells of the grid along x and y (valid scenes only).
    pub fn grid_cells(&self) -> [usize; 2] {
        [
            whole_cells(self.grid.size[0], self.grid.cell_size).unwrap_or(1),
            whole_cells(self.grid.size[1], self.grid.cell_size).unwrap_or(1),
        ]
    }

    /// Newton iteration limit: the scene's value, else 25 (local) or 60 (nonlocal).
    pub fn max_iterations(&self) -> usize {
        self.solver
            .max_iterations
            .unwrap_or(if self.nonlocal.is_some() { 60 } else { 25 })
    }

    /// Index of the body named `name` (`None` → the first body).
    pub fn body_index(&self, name: Option<&str>) -> Option<usize> {
        match name {
            None => (!self.body.is_empty()).then_some(0),
            Some(n) => self
                .body
                .iter()
                .enumerate()
                .position(|(i, b)| b.name_or_default(i) == n),
        }
    }

    /// Every semantic problem of the scene (empty when valid).
    pub fn validate(&self) -> Vec<FieldError> {
        let mut e = Vec::new();
        self.validate_analysis(&mut e);
        let grid_ok = self.validate_grid(&mut e);
        for (name, m) in &self.materials {
            m.validate(&format!("materials.{name}"), &mut e);
        }
        check(
            &mut e,
            "materials",
            !self.materials.is_empty(),
            "at least one material is required",
        );
        self.validate_solver(&mut e);
        self.validate_bodies(&mut e, grid_ok);
        self.validate_loads(&mut e);
        if grid_ok {
            self.validate_bc(&mut e);
        }
        self.validate_monitors(&mut e, grid_ok);
        if let Some(nl) = &self.nonlocal {
            check(
                &mut e,
                "nonlocal.length_scale",
                nl.length_scale > 0.0 && nl.length_scale.is_finite(),
                format!("must be > 0 m (got {})", nl.length_scale),
            );
            check(
                &mut e,
                "nonlocal.cutoff_factor",
                nl.cutoff_factor >= 1.0 && nl.cutoff_factor <= 10.0,
                format!("must lie in [1, 10] (got {})", nl.cutoff_factor),
            );
            check(
                &mut e,
                "nonlocal.tolerance",
                nl.tolerance > 0.0 && nl.tolerance < 1.0,
                "must lie in (0, 1)",
            );
            check(
                &mut e,
                "nonlocal.over_nonlocal",
                (1.0..=3.0).contains(&nl.over_nonlocal),
                format!(
                    "must lie in [1, 3] (got {}; 1 is the plain nonlocal model of DESIGN D35)",
                    nl.over_nonlocal
                ),
            );
            check(
                &mut e,
                "grid.cell_size",
                self.grid.cell_size <= nl.length_scale,
                format!("{} m exceeds the nonlocal length scale {} m: the averaging needs cells no larger than l_s", self.grid.cell_size, nl.length_scale),
            );
        }
        e
    }

    /// Advice that does not stop a run (printed by the CLI, written to `run.json`).
    pub fn warnings(&self) -> Vec<String> {
        let mut w = Vec::new();
        if let Some(nl) = &self.nonlocal {
            if self.grid.cell_size > 0.2 * nl.length_scale {
                w.push(format!(
                    "grid.cell_size {} m > 0.2 l_s = {} m: the paper finds nonlocal results mesh-objective only for h <= 0.2 l_s",
                    self.grid.cell_size,
                    0.2 * nl.length_scale
                ));
            }
        }
        let gravity = self.loads.gravity != 0.0 || self.loads.gravity_ramp.is_some();
        for m in &self.monitor {
            if gravity && m.kind == MonitorKind::ExternalWork {
                w.push(format!(
                    "monitor {} (external_work) leaves out the work of gravity",
                    m.name
                ));
            }
        }
        let surface_contact = self
            .bc
            .rigid
            .iter()
            .any(|r| r.contact == ContactKind::Surface);
        if self.scene.analysis == AnalysisKind::Explicit && surface_contact && self.solver.cfl > 0.9
        {
            w.push(format!(
                "solver.cfl {} > 0.9 with a surface-tied rigid body: explicit runs with contact = \"surface\" were measured stable only up to CFL 0.9",
                self.solver.cfl
            ));
        }
        w
    }

    fn validate_analysis(&self, e: &mut Vec<FieldError>) {
        let a = &self.scene;
        if let Some(dt) = a.dt {
            check(
                e,
                "scene.dt",
                dt > 0.0 && dt.is_finite(),
                format!("must be > 0 s (got {dt})"),
            );
        }
        match a.analysis {
            AnalysisKind::Explicit => {
                check(
                    e,
                    "scene.end_time",
                    a.end_time.is_some_and(|t| t > 0.0 && t.is_finite()),
                    "explicit runs need end_time > 0 s",
                );
            }
            AnalysisKind::ImplicitDynamic => {
                check(
                    e,
                    "scene.steps",
                    a.steps.is_some_and(|n| n >= 1),
                    "implicit runs need steps >= 1",
                );
                check(
                    e,
                    "scene.dt",
                    a.dt.is_some(),
                    "implicit dynamic runs need a time step dt > 0 s",
                );
            }
            AnalysisKind::QuasiStatic => {
                check(
                    e,
                    "scene.steps",
                    a.steps.is_some_and(|n| n >= 1),
                    "implicit runs need steps >= 1",
                );
            }
        }
    }

    fn validate_grid(&self, e: &mut Vec<FieldError>) -> bool {
        let g = &self.grid;
        let before = e.len();
        check(
            e,
            "grid.cell_size",
            g.cell_size > 0.0 && g.cell_size.is_finite(),
            format!("must be > 0 m (got {})", g.cell_size),
        );
        check(
            e,
            "grid.origin",
            g.origin.iter().all(|v| v.is_finite()),
            "must be finite",
        );
        for (c, axis) in ["x", "y"].iter().enumerate() {
            check(
                e,
                format!("grid.size[{c}]"),
                g.size[c] > 0.0 && g.size[c].is_finite(),
                format!("{axis}-size must be > 0 m (got {})", g.size[c]),
            );
        }
        check(
            e,
            "grid.points_per_cell",
            (1..=4).contains(&g.points_per_cell),
            format!("must be 1, 2, 3 or 4 (got {})", g.points_per_cell),
        );
        check(
            e,
            "grid.point_layout",
            g.shape_functions == ShapeFunctionChoice::Bilinear
                || g.point_layout == PointLayout::Uniform,
            "shape_functions = \"gimp\" needs point_layout = \"uniform\" \
             (the point domains must tile the cells)"
                .to_string(),
        );
        if e.len() == before {
            for (c, axis) in ["x", "y"].iter().enumerate() {
                check(
                    e,
                    format!("grid.size[{c}]"),
                    whole_cells(g.size[c], g.cell_size).is_some(),
                    format!(
                        "the {axis}-size {} m is not a whole number of cells of size {} m",
                        g.size[c], g.cell_size
                    ),
                );
            }
            let cells = [g.size[0] / g.cell_size, g.size[1] / g.cell_size];
            check(
                e,
                "grid.cell_size",
                cells[0] * cells[1] <= 5.0e7,
                "the grid would have more than 5e7 cells",
            );
        }
        e.len() == before
    }

    fn validate_solver(&self, e: &mut Vec<FieldError>) {
        let s = &self.solver;
        check(
            e,
            "solver.tolerance_force",
            s.tolerance_force > 0.0 && s.tolerance_force < 1.0,
            "must lie in (0, 1)",
        );
        check(
            e,
            "solver.tolerance_energy",
            s.tolerance_energy > 0.0 && s.tolerance_energy < 1.0,
            "must lie in (0, 1)",
        );
        check(
            e,
            "solver.max_iterations",
            s.max_iterations.is_none_or(|n| n >= 1),
            "must be >= 1",
        );
        check(
            e,
            "solver.max_halvings",
            s.max_halvings <= 10,
            "must be <= 10",
        );
        check(
            e,
            "solver.background_stiffness",
            s.background_stiffness >= 0.0 && s.background_stiffness < 1.0,
            "must lie in [0, 1)",
        );
        if let Some(b) = s.penalty_factor {
            check(
                e,
                "solver.penalty_factor",
                b > 0.0 && b.is_finite(),
                format!("must be > 0 (got {b})"),
            );
        }
        check(
            e,
            "solver.cfl",
            s.cfl > 0.0 && s.cfl <= 1.0,
            format!("must lie in (0, 1] (got {})", s.cfl),
        );
        check(
            e,
            "solver.damping",
            s.damping >= 0.0 && s.damping < 1.0,
            format!("must lie in [0, 1) (got {})", s.damping),
        );
        check(
            e,
            "solver.newmark_gamma",
            (0.5..=1.0).contains(&s.newmark_gamma),
            format!("must lie in [0.5, 1] (got {})", s.newmark_gamma),
        );
        if self.scene.analysis == AnalysisKind::Explicit {
            if let Some(dt) = self.scene.dt {
                if let Some(limit) = self.critical_time_step() {
                    check(
                        e,
                        "scene.dt",
                        dt <= limit,
                        format!("{dt} s exceeds the explicit stability limit h/c_p = {limit:.4e} s (DESIGN D20)"),
                    );
                }
            }
        }
    }

    /// Smallest h / c_p over the materials in use (DESIGN D20 with α = 1, v = 0).
    pub fn critical_time_step(&self) -> Option<f64> {
        self.materials
            .values()
            .map(|m| {
                let modulus =
                    crate::constitutive::LinearElastic::new(m.youngs_modulus(), m.poisson_ratio())
                        .p_wave_modulus();
                self.grid.cell_size / (modulus / m.density()).sqrt()
            })
            .filter(|v| v.is_finite() && *v > 0.0)
            .min_by(f64::total_cmp)
    }

    fn validate_bodies(&self, e: &mut Vec<FieldError>, grid_ok: bool) {
        check(
            e,
            "body",
            !self.body.is_empty(),
            "at least one [[body]] is required",
        );
        let lo = self.grid.origin;
        let hi = [lo[0] + self.grid.size[0], lo[1] + self.grid.size[1]];
        let tol = 1e-9 * self.grid.cell_size.abs();
        for (i, b) in self.body.iter().enumerate() {
            let f = format!("body[{i}]");
            check(
                e,
                format!("{f}.material"),
                self.materials.contains_key(&b.material),
                format!("unknown material `{}`", b.material),
            );
            match (&b.rectangle, &b.polygon) {
                (Some(_), Some(_)) => e.push(FieldError {
                    field: f.clone(),
                    message: "give either `box` or `polygon`, not both".into(),
                }),
                (None, None) => e.push(FieldError {
                    field: f.clone(),
                    message: "needs a `box` or a `polygon`".into(),
                }),
                (Some([a, c]), None) => {
                    check(
                        e,
                        format!("{f}.box"),
                        a[0] < c[0] && a[1] < c[1],
                        "must be [[x_min, y_min], [x_max, y_max]] with min < max",
                    );
                }
                (None, Some(p)) => {
                    check(
                        e,
                        format!("{f}.polygon"),
                        p.len() >= 3,
                        "needs at least 3 vertices",
                    );
                }
            }
            let outline = b.outline();
            if grid_ok && !outline.is_empty() {
                let inside = outline.iter().all(|p| {
                    p[0] >= lo[0] - tol
                        && p[1] >= lo[1] - tol
                        && p[0] <= hi[0] + tol
                        && p[1] <= hi[1] + tol
                });
                let key = if b.rectangle.is_some() {
                    "box"
                } else {
                    "polygon"
                };
                check(
                    e,
                    format!("{f}.{key}"),
                    inside,
                    format!(
                        "the body lies (partly) outside the grid [{}, {}] × [{}, {}] m",
                        lo[0], hi[0], lo[1], hi[1]
                    ),
                );
            }
            if let Some(k0) = &b.k0 {
                check(e, format!("{f}.k0.k0"), k0.k0 >= 0.0, "must be >= 0");
                check(
                    e,
                    format!("{f}.k0.unit_weight"),
                    k0.unit_weight >= 0.0,
                    "must be >= 0 kN/m³",
                );
            }
            if let Some(s) = b.stress0 {
                check(
                    e,
                    format!("{f}.stress0"),
                    s.iter().all(|v| v.is_finite()),
                    "must be finite",
                );
            }
            let names: Vec<String> = self
                .body
                .iter()
                .enumerate()
                .map(|(j, b)| b.name_or_default(j))
                .collect();
            check(
                e,
                format!("{f}.name"),
                names.iter().filter(|n| **n == names[i]).count() == 1,
                "body names must be unique",
            );
        }
    }

    fn validate_loads(&self, e: &mut Vec<FieldError>) {
        check(
            e,
            "loads.gravity",
            self.loads.gravity.is_finite(),
            "must be finite",
        );
        if let Some(r) = &self.loads.gravity_ramp {
            check(
                e,
                "loads.gravity_ramp.interval",
                r.interval > 0.0,
                "must be > 0 s",
            );
            check(
                e,
                "loads.gravity_ramp.increment",
                r.increment.is_finite(),
                "must be finite",
            );
            check(
                e,
                "loads.gravity_ramp.max",
                r.max.is_finite(),
                "must be finite",
            );
        }
    }

    /// Check a grid line reference: it parses, lies on a grid line inside the grid.
    fn check_line(&self, e: &mut Vec<FieldError>, field: String, text: &str) -> Option<GridLine> {
        match GridLine::parse(text) {
            Err(m) => {
                e.push(FieldError { field, message: m });
                None
            }
            Ok(line) => {
                let h = self.grid.cell_size;
                let offset = (line.value - self.grid.origin[line.axis]) / h;
                let on_line = (offset - offset.round()).abs() < 1e-6
                    && offset.round() >= 0.0
                    && offset.round() <= self.grid_cells()[line.axis] as f64;
                check(e, field, on_line, format!("`{text}` selects no grid node: it must be a grid line inside the grid (cell size {h} m)"));
                on_line.then_some(line)
            }
        }
    }

    fn validate_bc(&self, e: &mut Vec<FieldError>) {
        for (i, f) in self.bc.fixed.iter().enumerate() {
            self.check_line(e, format!("bc.fixed[{i}].line"), &f.line);
            check(
                e,
                format!("bc.fixed[{i}].dofs"),
                !f.dofs.is_empty(),
                "must list at least one of \"x\", \"y\"",
            );
        }
        for (i, p) in self.bc.prescribed.iter().enumerate() {
            self.check_line(e, format!("bc.prescribed[{i}].line"), &p.line);
            check(
                e,
                format!("bc.prescribed[{i}].rate"),
                p.rate.is_finite() && p.gradient.iter().all(|g| g.is_finite()),
                "must be finite",
            );
        }
        for (i, p) in self.bc.pressure.iter().enumerate() {
            let f = format!("bc.pressure[{i}]");
            match self.body_index(p.body.as_deref()) {
                None => e.push(FieldError {
                    field: format!("{f}.body"),
                    message: format!("no body named `{}`", p.body.clone().unwrap_or_default()),
                }),
                Some(b) => check(
                    e,
                    format!("{f}.body"),
                    self.body[b].rectangle.is_some(),
                    "pressure is supported on sides of `box` bodies only",
                ),
            }
            check(e, format!("{f}.p"), p.p.is_finite(), "must be finite");
        }
        let mut names = Vec::new();
        for (i, r) in self.bc.rigid.iter().enumerate() {
            let f = format!("bc.rigid[{i}]");
            check(
                e,
                format!("{f}.name"),
                !names.contains(&&r.name),
                format!("duplicate rigid body name `{}`", r.name),
            );
            names.push(&r.name);
            match self.body_index(r.body.as_deref()) {
                None => e.push(FieldError {
                    field: format!("{f}.body"),
                    message: format!("no body named `{}`", r.body.clone().unwrap_or_default()),
                }),
                Some(b) => {
                    let bounds = self.body[b].bounds();
                    let fp = r.footprint;
                    check(
                        e,
                        format!("{f}.footprint"),
                        fp[0] < fp[1] && fp[0] < bounds[1][0] && fp[1] > bounds[0][0],
                        format!("[{}, {}] must be an interval (min < max) overlapping the body's x-range [{}, {}] m", fp[0], fp[1], bounds[0][0], bounds[1][0]),
                    );
                }
            }
            check(
                e,
                format!("{f}.velocity"),
                r.velocity.iter().all(|v| v.is_finite()),
                "must be finite",
            );
        }
    }

    fn validate_monitors(&self, e: &mut Vec<FieldError>, grid_ok: bool) {
        let lo = self.grid.origin;
        let hi = [lo[0] + self.grid.size[0], lo[1] + self.grid.size[1]];
        let mut seen = Vec::new();
        for (i, m) in self.monitor.iter().enumerate() {
            let f = format!("monitor[{i}]");
            check(
                e,
                format!("{f}.name"),
                !m.name.is_empty() && !seen.contains(&&m.name),
                "must be a non-empty, unique column name",
            );
            check(
                e,
                format!("{f}.name"),
                !matches!(m.name.as_str(), "step" | "time"),
                "`step` and `time` are reserved column names",
            );
            seen.push(&m.name);
            check(
                e,
                format!("{f}.scale"),
                m.scale.is_finite() && m.offset.is_finite(),
                "scale and offset must be finite",
            );
            match m.kind {
                MonitorKind::PointDisplacement
                | MonitorKind::PointVelocity
                | MonitorKind::PointStress => match m.point {
                    None => e.push(FieldError {
                        field: format!("{f}.point"),
                        message: "this monitor kind needs `point = [x, y]`".into(),
                    }),
                    Some(p) => check(
                        e,
                        format!("{f}.point"),
                        p[0] >= lo[0] && p[0] <= hi[0] && p[1] >= lo[1] && p[1] <= hi[1],
                        format!("{p:?} lies outside the grid"),
                    ),
                },
                MonitorKind::Reaction => match &m.line {
                    None => e.push(FieldError {
                        field: format!("{f}.line"),
                        message: "`reaction` needs `line = \"x=<value>\"` or `\"y=<value>\"`"
                            .into(),
                    }),
                    Some(l) => {
                        if grid_ok {
                            self.check_line(e, format!("{f}.line"), l);
                        }
                    }
                },
                MonitorKind::RigidForce | MonitorKind::RigidDisplacement => {
                    let ok = m
                        .rigid
                        .as_ref()
                        .is_some_and(|r| self.bc.rigid.iter().any(|b| &b.name == r));
                    check(
                        e,
                        format!("{f}.rigid"),
                        ok,
                        "must name a [[bc.rigid]] entry",
                    );
                }
                _ => {}
            }
            if m.kind == MonitorKind::PointStress {
                check(
                    e,
                    format!("{f}.quantity"),
                    m.quantity.is_some(),
                    "`point_stress` needs `quantity` (sxx, syy, szz, sxy, p or q)",
                );
            }
        }
    }
}

/// Apply one `a.b.c=value` override to a TOML table. Path segments that are
/// numbers index arrays (`body.0.box`). The value is parsed as TOML (numbers,
/// booleans, arrays, strings in quotes) and taken as a bare string otherwise.
pub fn apply_override(table: &mut toml::Table, assignment: &str) -> Result<(), SceneError> {
    let err = |message: String| SceneError::Override {
        assignment: assignment.to_string(),
        message,
    };
    let (path, raw) = assignment
        .split_once('=')
        .ok_or_else(|| err("expected KEY=VALUE".into()))?;
    let keys: Vec<&str> = path.trim().split('.').collect();
    if keys.iter().any(|k| k.is_empty()) {
        return Err(err("empty key segment".into()));
    }
    let raw = raw.trim();
    let value: toml::Value = format!("v = {raw}")
        .parse::<toml::Table>()
        .ok()
        .and_then(|mut t| t.remove("v"))
        .unwrap_or_else(|| toml::Value::String(raw.to_string()));
    if keys.len() == 1 {
        table.insert(keys[0].to_string(), value);
        return Ok(());
    }
    // Missing intermediate tables are created (optional sections such as
    // `[solver]`); a misspelt key is then refused by `deny_unknown_fields`.
    let mut current: &mut toml::Value = table
        .entry(keys[0])
        .or_insert_with(|| toml::Value::Table(toml::Table::new()));
    for (depth, key) in keys.iter().enumerate().skip(1) {
        let last = depth == keys.len() - 1;
        current = match current {
            toml::Value::Table(t) => {
                if last {
                    t.insert((*key).to_string(), value);
                    return Ok(());
                }
                t.entry(*key)
                    .or_insert_with(|| toml::Value::Table(toml::Table::new()))
            }
            toml::Value::Array(a) => {
                let index: usize = key
                    .parse()
                    .map_err(|_| err(format!("`{key}` must be an array index")))?;
                let len = a.len();
                let slot = a
                    .get_mut(index)
                    .ok_or_else(|| err(format!("index {index} out of range (length {len})")))?;
                if last {
                    *slot = value;
                    return Ok(());
                }
                slot
            }
            _ => {
                return Err(err(format!(
                    "`{}` is not a table or array",
                    keys[..depth].join(".")
                )))
            }
        };
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    const MINIMAL: &str = r#"
        [scene]
        analysis = "quasi_static"
        steps = 1
        [grid]
        size = [1.0, 2.0]
        cell_size = 0.5
        [materials.soil]
        model = "linear_elastic"
        E = 1000.0
        nu = 0.3
        density = 2.0
        [[body]]
        material = "soil"
        box = [[0.0, 0.0], [1.0, 1.0]]
    "#;

    #[test]
    fn minimal_scene_loads_with_defaults() {
        let s = Scene::from_str_with_overrides(MINIMAL, "t", &[]).unwrap();
        assert_eq!(s.grid.points_per_cell, 2);
        assert_eq!(s.solver.tolerance_force, 1e-5);
        assert_eq!(s.grid_cells(), [2, 4]);
    }

    #[test]
    fn overrides_change_values_and_reject_unknown_paths() {
        let s = Scene::from_str_with_overrides(
            MINIMAL,
            "t",
            &[
                "grid.cell_size=0.25".into(),
                "body.0.box=[[0.0,0.0],[0.5,0.5]]".into(),
            ],
        )
        .unwrap();
        assert_eq!(s.grid.cell_size, 0.25);
        assert_eq!(s.body[0].rectangle, Some([[0.0, 0.0], [0.5, 0.5]]));
        let e = Scene::from_str_with_overrides(MINIMAL, "t", &["gird.cell_size=0.25".into()])
            .unwrap_err();
        assert!(e.to_string().contains("gird"), "{e}");
        // a new key inside a known table is refused by deny_unknown_fields
        let e = Scene::from_str_with_overrides(MINIMAL, "t", &["grid.cel_size=0.25".into()])
            .unwrap_err();
        assert!(e.to_string().contains("cel_size"), "{e}");
    }

    #[test]
    fn invalid_values_are_all_reported_with_field_names() {
        let bad = MINIMAL
            .replace("nu = 0.3", "nu = 0.5")
            .replace("cell_size = 0.5", "cell_size = 0.3");
        let e = Scene::from_str_with_overrides(&bad, "t", &[])
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("materials.soil.nu") && e.contains("(-1, 0.5)"),
            "{e}"
        );
        assert!(
            e.contains("grid.size[0]") && e.contains("whole number of cells"),
            "{e}"
        );
    }

    #[test]
    fn gravity_ramp_steps_like_the_vertical_cut() {
        let l = LoadSpec {
            gravity: 0.0,
            gravity_ramp: Some(GravityRamp {
                increment: 0.981,
                interval: 0.001,
                max: 588.6,
            }),
        };
        assert!((l.gravity_at(0.001) - 0.981).abs() < 1e-12);
        assert!((l.gravity_at(0.0015) - 2.0 * 0.981).abs() < 1e-12);
        assert!((l.gravity_at(0.8) - 588.6).abs() < 1e-12);
        assert_eq!(l.gravity_at(0.0), 0.0);
    }

    #[test]
    fn polygon_point_test() {
        let tri = [[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]];
        assert!(polygon_contains(&tri, [0.2, 0.2]));
        assert!(!polygon_contains(&tri, [0.6, 0.6]));
    }
}
