//! The study spec (`validation/studies/*.toml`) and its expansion into runs.
//!
//! ```toml
//! [study]
//! name = "elastic_bar"
//! scene = "../elastic/bar_implicit.toml"   # base scene, relative to the spec
//! repeats = 3                              # each run timed n times, median
//! set = ["scene.steps=200"]                # overrides of every run
//!
//! [reference]                              # closed form, one run, or per series
//! kind = "closed_form"
//! name = "bar_vibration"
//! monitor = "top_uy"
//! parameters = { height = 1.0, wave_speed = 100.0, velocity = 0.01 }
//!
//! [[quantity]]                             # what the error is measured on
//! monitor = "top_uy"
//! measure = "l2"                           # "l2" | "at_time" (+ time) | "period"
//!
//! [[axis]]                                 # crossed with every series
//! name = "nu"
//! key = "materials.soil.nu"
//! values = [0.3, 0.49]
//!
//! [[axis]]                                 # values that set several keys
//! name = "shape"
//! values = [
//!   { label = "bilinear", set = ["grid.shape_functions=bilinear", "grid.point_layout=gauss"] },
//!   { label = "gimp", set = ["grid.shape_functions=gimp", "grid.point_layout=uniform"] },
//! ]
//!
//! [[series]]                               # one line of the work-precision plot
//! label = "Newmark γ = 1/2"
//! integrator = "as_written"                # or "explicit" (the scene's explicit twin)
//! set = ["solver.newmark_gamma=0.5"]
//! refine = "dt"                            # "dt" keeps the end time; or any key path
//! values = [4e-4, 2e-4, 1e-4]
//! ```

use std::path::{Path, PathBuf};

use serde::Deserialize;

use super::StudyError;
use crate::campaign::IntegratorChoice;
use crate::scene::{AnalysisKind, Scene};

/// The contents of a study spec file.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct StudySpec {
    /// Name, base scene, repeats and common overrides.
    pub study: StudySection,
    /// What the runs are compared against.
    pub reference: ReferenceSpec,
    /// The compared quantities (at least one).
    pub quantity: Vec<Quantity>,
    /// Axes crossed with every series (each combination is one method).
    #[serde(default)]
    pub axis: Vec<Axis>,
    /// The series: a method refined along one key (at least one).
    pub series: Vec<SeriesSpec>,
}

/// `[study]`.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct StudySection {
    /// Study name (output directory `out/study-<name>` by default).
    pub name: String,
    /// Base scene file, relative to the spec file.
    pub scene: PathBuf,
    /// How many times each run is timed (the median wall time is reported).
    #[serde(default = "one")]
    pub repeats: usize,
    /// Overrides (`key=value`) applied to every run, before the axes and series.
    #[serde(default)]
    pub set: Vec<String>,
}

fn one() -> usize {
    1
}

/// `[reference]`: what the error of a run is measured against.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum ReferenceSpec {
    /// A closed-form solution of the scene's problem.
    ClosedForm {
        /// Which closed form.
        name: ClosedFormName,
        /// The monitor it describes (every quantity must be on it).
        monitor: String,
        /// Its parameters.
        parameters: BarVibration,
    },
    /// One reference run for the whole study (say how it was chosen: finest
    /// mesh, smallest step).
    Run {
        /// Integrator of the reference run.
        #[serde(default = "as_written")]
        integrator: IntegratorChoice,
        /// Overrides of the reference run (after `study.set`).
        #[serde(default)]
        set: Vec<String>,
    },
    /// Each series against its own run at `reference_value` of its refined
    /// key (same mesh and method: only the refined discretisation differs).
    /// (A struct variant, so that unknown keys in `[reference]` are refused.)
    Series {},
}

fn as_written() -> IntegratorChoice {
    IntegratorChoice::AsWritten
}

/// Closed forms a spec can name.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum ClosedFormName {
    /// First mode of a fixed–free elastic bar (DESIGN §8.4).
    BarVibration,
}

/// Parameters of the bar closed form: u_top(t) = (v0/ω) sin ωt, ω = π c / (2H),
/// period T = 4H/c (initial velocity v0 sin(π y / 2H), DESIGN §8.4).
#[derive(Clone, Copy, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct BarVibration {
    /// Bar height H, m.
    pub height: f64,
    /// Wave speed c = √(E/ρ), m/s.
    pub wave_speed: f64,
    /// Top velocity amplitude v0 of the initial profile, m/s.
    pub velocity: f64,
}

impl BarVibration {
    /// Angular frequency ω = π c / (2H), rad/s.
    pub fn omega(&self) -> f64 {
        std::f64::consts::PI * self.wave_speed / (2.0 * self.height)
    }

    /// Period T = 4H/c, s.
    pub fn period(&self) -> f64 {
        4.0 * self.height / self.wave_speed
    }

    /// Top displacement u(H, t) = (v0/ω) sin ωt, m.
    pub fn top_displacement(&self, t: f64) -> f64 {
        self.velocity / self.omega() * (self.omega() * t).sin()
    }
}

/// `[[quantity]]`: one monitor and how its error is measured.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Quantity {
    /// Monitor name (a column of `curve.csv`).
    pub monitor: String,
    /// Error measure.
    #[serde(default)]
    pub measure: Measure,
    /// Time of the `at_time` measure, s.
    pub time: Option<f64>,
}

impl Quantity {
    /// Column name in `study.csv`: `error_<monitor>_<measure>`.
    pub fn column(&self) -> String {
        let measure = match self.measure {
            Measure::L2 => "l2".to_string(),
            Measure::AtTime => format!("t{}", self.time.unwrap_or(f64::NAN)),
            Measure::Period => "period".to_string(),
        };
        format!("error_{}_{measure}", self.monitor)
    }
}

/// How a quantity's error is measured.
#[derive(Clone, Copy, Debug, Default, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum Measure {
    /// Relative L2 norm in time over the run: ‖u − u_ref‖ / ‖u_ref‖
    /// (trapezoidal weights on the run's rows).
    #[default]
    L2,
    /// |u(t) − u_ref(t)| / max_t |u_ref| at `time`.
    AtTime,
    /// Relative error of the mean period between upward zero crossings.
    Period,
}

/// `[[axis]]`: values crossed with every series.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Axis {
    /// Column name in `study.csv`.
    pub name: String,
    /// Scene key path (`grid.shape_functions`) set to each scalar value.
    pub key: Option<String>,
    /// Scalars (with `key`), or tables `{ label, set = [overrides] }`.
    pub values: Vec<toml::Value>,
}

impl Axis {
    /// `(label, overrides)` of each value; `None` for a malformed value.
    fn settings(&self) -> Vec<Option<(String, Vec<String>)>> {
        self.values
            .iter()
            .map(|v| match (v, &self.key) {
                (toml::Value::Table(t), _) => {
                    let label = t.get("label")?.as_str()?.to_string();
                    let set = t.get("set")?.as_array()?;
                    let set: Option<Vec<String>> =
                        set.iter().map(|o| o.as_str().map(String::from)).collect();
                    (t.len() == 2).then_some((label, set?))
                }
                (toml::Value::Array(_), _) | (_, None) => None,
                (scalar, Some(key)) => {
                    let text = value_text(scalar);
                    Some((
                        text.trim_matches('"').to_string(),
                        vec![format!("{key}={text}")],
                    ))
                }
            })
            .collect()
    }
}

/// `[[series]]`: a method refined along one key.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct SeriesSpec {
    /// Legend entry.
    pub label: String,
    /// Integrator: the scene as written or its explicit twin.
    #[serde(default = "as_written")]
    pub integrator: IntegratorChoice,
    /// Overrides of this series (after `study.set` and the axes).
    #[serde(default)]
    pub set: Vec<String>,
    /// Refined key: `dt` (time step, end time kept) or a scene key path
    /// (`solver.cfl`, `grid.cell_size`).
    pub refine: String,
    /// Values of the refined key, coarse to fine.
    pub values: Vec<f64>,
    /// Value of the refined key of this series' reference run
    /// (`reference.kind = "series"`).
    pub reference_value: Option<f64>,
}

/// One run of a study, fully resolved.
#[derive(Clone, Debug)]
pub struct PlannedRun {
    /// Directory name (unique in the study).
    pub name: String,
    /// Method label: series label and axis values.
    pub method: String,
    /// Index of the series.
    pub series: usize,
    /// `(axis name, value)` of this run.
    pub axes: Vec<(String, String)>,
    /// Integrator of the run.
    pub integrator: IntegratorChoice,
    /// Refined key and its value (`None` for the study's reference run).
    pub refine: Option<(String, f64)>,
    /// The scene run.
    pub scene: Scene,
}

/// The runs of a study: the compared runs and the reference runs.
#[derive(Clone, Debug)]
pub struct StudyPlan {
    /// The spec.
    pub spec: StudySpec,
    /// The compared runs, in spec order.
    pub runs: Vec<PlannedRun>,
    /// Reference runs: one (`run`), one per method (`series`), none (closed form).
    pub references: Vec<PlannedRun>,
}

impl StudySpec {
    /// Read and check a spec file; the base scene path is resolved against
    /// the spec's directory.
    pub fn load(path: &Path) -> Result<Self, StudyError> {
        let spec_error = |message: String| StudyError::Spec {
            path: path.display().to_string(),
            message,
        };
        let text = std::fs::read_to_string(path).map_err(|e| spec_error(e.to_string()))?;
        let mut spec: StudySpec = toml::from_str(&text).map_err(|e| spec_error(e.to_string()))?;
        if spec.study.scene.is_relative() {
            let dir = path.parent().unwrap_or(Path::new("."));
            spec.study.scene = dir.join(&spec.study.scene);
        }
        spec.check().map_err(spec_error)?;
        Ok(spec)
    }

    /// Range and consistency checks, naming the field.
    fn check(&self) -> Result<(), String> {
        if self.study.name.trim().is_empty() || self.study.name.contains(['/', '\\']) {
            return Err("study.name: must be a non-empty name without path separators".into());
        }
        if self.study.repeats == 0 || self.study.repeats > 100 {
            return Err(format!(
                "study.repeats: must be 1 to 100, got {}",
                self.study.repeats
            ));
        }
        if self.quantity.is_empty() {
            return Err("quantity: at least one [[quantity]] is needed".into());
        }
        for (i, q) in self.quantity.iter().enumerate() {
            match (q.measure, q.time) {
                (Measure::AtTime, Some(t)) if t.is_finite() && t >= 0.0 => {}
                (Measure::AtTime, _) => {
                    return Err(format!(
                        "quantity[{i}].time: `at_time` needs a finite time >= 0"
                    ))
                }
                (_, Some(_)) => {
                    return Err(format!(
                        "quantity[{i}].time: only the `at_time` measure takes a time"
                    ))
                }
                _ => {}
            }
            if let ReferenceSpec::ClosedForm { monitor, .. } = &self.reference {
                if &q.monitor != monitor {
                    return Err(format!(
                        "quantity[{i}].monitor: the closed form describes `{monitor}`, not `{}`",
                        q.monitor
                    ));
                }
            }
        }
        if let ReferenceSpec::ClosedForm { parameters: p, .. } = &self.reference {
            for (field, v) in [
                ("height", p.height),
                ("wave_speed", p.wave_speed),
                ("velocity", p.velocity),
            ] {
                if !(v.is_finite() && v != 0.0) || (field != "velocity" && v < 0.0) {
                    return Err(format!(
                        "reference.parameters.{field}: must be finite and nonzero (> 0 for lengths and speeds), got {v}"
                    ));
                }
            }
        }
        for (i, a) in self.axis.iter().enumerate() {
            if a.values.is_empty() || a.name.trim().is_empty() {
                return Err(format!("axis[{i}]: needs a name and values"));
            }
            if let Some(k) = a.settings().iter().position(Option::is_none) {
                return Err(format!(
                    "axis[{i}].values[{k}]: a scalar needs `axis.key`; a table needs exactly `label` (string) and `set` (list of key=value strings)"
                ));
            }
        }
        if self.series.is_empty() {
            return Err("series: at least one [[series]] is needed".into());
        }
        for (i, s) in self.series.iter().enumerate() {
            if s.values.is_empty() || s.values.iter().any(|v| !(v.is_finite() && *v > 0.0)) {
                return Err(format!(
                    "series[{i}].values: needs at least one value, each finite and > 0"
                ));
            }
            match (&self.reference, s.reference_value) {
                (ReferenceSpec::Series {}, Some(v)) if v.is_finite() && v > 0.0 => {}
                (ReferenceSpec::Series {}, _) => {
                    return Err(format!(
                        "series[{i}].reference_value: `reference.kind = \"series\"` needs a finite value > 0"
                    ))
                }
                (_, Some(_)) => {
                    return Err(format!(
                        "series[{i}].reference_value: only used with `reference.kind = \"series\"`"
                    ))
                }
                _ => {}
            }
        }
        Ok(())
    }

    /// Every run of the study, each scene built and validated (nothing runs
    /// before every scene is known to be valid).
    pub fn plan(&self) -> Result<StudyPlan, StudyError> {
        let methods = self.methods();
        let mut runs = Vec::new();
        let mut references = Vec::new();
        for (method_index, method) in methods.iter().enumerate() {
            let series = &self.series[method.series];
            let base = self.scene_for(&method.overrides, series.integrator)?;
            for (k, &value) in series.values.iter().enumerate() {
                let scene = refined(&base, &series.refine, value)?;
                runs.push(PlannedRun {
                    name: format!("m{method_index:02}_{k:02}_{}", slug(&method.label)),
                    method: method.label.clone(),
                    series: method.series,
                    axes: method.axes.clone(),
                    integrator: series.integrator,
                    refine: Some((series.refine.clone(), value)),
                    scene,
                });
            }
            if let (ReferenceSpec::Series {}, Some(value)) =
                (&self.reference, series.reference_value)
            {
                references.push(PlannedRun {
                    name: format!("m{method_index:02}_reference"),
                    method: method.label.clone(),
                    series: method.series,
                    axes: method.axes.clone(),
                    integrator: series.integrator,
                    refine: Some((series.refine.clone(), value)),
                    scene: refined(&base, &series.refine, value)?,
                });
            }
        }
        if let ReferenceSpec::Run { integrator, set } = &self.reference {
            references.push(PlannedRun {
                name: "reference".into(),
                method: "reference".into(),
                series: usize::MAX,
                axes: Vec::new(),
                integrator: *integrator,
                refine: None,
                scene: self.scene_for(set, *integrator)?,
            });
        }
        Ok(StudyPlan {
            spec: self.clone(),
            runs,
            references,
        })
    }

    /// The series crossed with the axes: label, axis values and overrides of
    /// each method.
    fn methods(&self) -> Vec<Method> {
        // (axis name, value label, overrides) per axis of each combination
        type Setting = (String, String, Vec<String>);
        let mut combos: Vec<Vec<Setting>> = vec![Vec::new()];
        for axis in &self.axis {
            let settings: Vec<(String, Vec<String>)> =
                axis.settings().into_iter().flatten().collect();
            combos = combos
                .into_iter()
                .flat_map(|combo| {
                    settings.iter().map(move |(label, set)| {
                        let mut next = combo.clone();
                        next.push((axis.name.clone(), label.clone(), set.clone()));
                        next
                    })
                })
                .collect();
        }
        let mut methods = Vec::new();
        for (s, series) in self.series.iter().enumerate() {
            for combo in &combos {
                let mut overrides = self.study.set.clone();
                overrides.extend(combo.iter().flat_map(|(_, _, set)| set.iter().cloned()));
                overrides.extend(series.set.iter().cloned());
                let mut label = series.label.clone();
                for (name, value, _) in combo {
                    label += &format!(", {name} = {value}");
                }
                methods.push(Method {
                    series: s,
                    label,
                    axes: combo
                        .iter()
                        .map(|(name, value, _)| (name.clone(), value.clone()))
                        .collect(),
                    overrides,
                });
            }
        }
        methods
    }

    /// The base scene with `overrides` (after `study.set` for a reference),
    /// for `integrator`.
    fn scene_for(
        &self,
        overrides: &[String],
        integrator: IntegratorChoice,
    ) -> Result<Scene, StudyError> {
        let mut all = self.study.set.clone();
        for o in overrides {
            if !all.contains(o) {
                all.push(o.clone());
            }
        }
        let scene =
            Scene::load(&self.study.scene, &all).map_err(|e| StudyError::Scene(e.to_string()))?;
        integrator
            .apply(&scene)
            .map_err(|e| StudyError::Scene(e.to_string()))
    }
}

/// One method: a series with one combination of axis values.
struct Method {
    series: usize,
    label: String,
    axes: Vec<(String, String)>,
    overrides: Vec<String>,
}

/// `scene` with the refined key set to `value`. `dt` keeps the end time of an
/// implicit scene (steps = round(T / Δt)); an explicit scene gets a fixed Δt.
pub fn refined(scene: &Scene, key: &str, value: f64) -> Result<Scene, StudyError> {
    let mut overrides = Vec::new();
    if key == "dt" {
        overrides.push(format!("scene.dt={value:e}"));
        if scene.scene.analysis != AnalysisKind::Explicit {
            let (Some(steps), Some(dt)) = (scene.scene.steps, scene.scene.dt) else {
                return Err(StudyError::Scene(
                    "refine = \"dt\": the implicit scene needs scene.steps and scene.dt".into(),
                ));
            };
            let end = steps as f64 * dt;
            let new_steps = (end / value).round().max(1.0);
            if new_steps > 1e8 {
                return Err(StudyError::Scene(format!(
                    "refine = \"dt\": Δt = {value:e} s gives {new_steps:e} steps"
                )));
            }
            overrides.push(format!("scene.steps={}", new_steps as usize));
        }
    } else {
        overrides.push(format!("{key}={value:e}"));
    }
    // a study times the computation and reads curve.csv: no snapshot files
    overrides.push("output.snapshots=[]".into());
    let text = toml::to_string(scene).map_err(|e| StudyError::Scene(e.to_string()))?;
    Scene::from_str_with_overrides(&text, &scene.scene.name, &overrides)
        .map_err(|e| StudyError::Scene(e.to_string()))
}

/// A TOML value as `--set` text (strings quoted).
fn value_text(v: &toml::Value) -> String {
    match v {
        toml::Value::String(s) => format!("\"{s}\""),
        other => other.to_string(),
    }
}

/// File-name-safe form of a label.
fn slug(label: &str) -> String {
    let mut out = String::new();
    for c in label.chars() {
        if c.is_ascii_alphanumeric() || c == '.' || c == '-' {
            out.push(c.to_ascii_lowercase());
        } else if !out.ends_with('_') {
            out.push('_');
        }
    }
    out.trim_matches('_').chars().take(48).collect()
}
