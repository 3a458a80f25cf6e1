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
//! values = [4e-4, 2e-4, 1e-4]              # (no refine/values: one run per method)
//! ```
//!
//! A *case study* lists `[[case]]`s instead of (or with) axes: each case is a
//! problem (its own base scene, overrides, time step, reference and
//! quantities), run with every series. A case run whose scene the validation
//! refuses (an explicit step above the stability limit, a quasi-static scene
//! with no explicit twin, a parameter out of range) is recorded as
//! `refused: <why>` instead of stopping the study; a misspelt key or a bad
//! override still stops it before anything runs.
//!
//! ```toml
//! [[case]]
//! name = "Δt = 10 × h/c_p"
//! scene = "../elastic/bar_implicit.toml"   # optional: replaces study.scene
//! set = ["materials.bar.nu=0.3"]           # after study.set, before axes and series
//! dt = 5e-3                                # optional: like refine = "dt"
//! reference = { kind = "none", why = "…" } # optional: replaces [reference]
//! quantity = [{ monitor = "load" }]        # optional: replaces [[quantity]]
//! ```

use std::path::{Path, PathBuf};

use serde::Deserialize;

use super::closed_form::{BarVibration, ClosedForm, ClosedFormName};
use super::StudyError;
use crate::campaign::IntegratorChoice;
use crate::scene::{AnalysisKind, Scene, SceneError};

/// The contents of a study spec file.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct StudySpec {
    /// Name, base scene, repeats and common overrides.
    pub study: StudySection,
    /// What the runs are compared against.
    pub reference: ReferenceSpec,
    /// The compared quantities (at least one, unless there is no reference).
    #[serde(default)]
    pub quantity: Vec<Quantity>,
    /// Axes crossed with every series (each combination is one method).
    #[serde(default)]
    pub axis: Vec<Axis>,
    /// The series: a method refined along one key (at least one).
    pub series: Vec<SeriesSpec>,
    /// Cases: problems each run with every method (a case study).
    #[serde(default)]
    pub case: Vec<CaseSpec>,
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
    /// Wall-time limit of one run process, s: a run still going after it is
    /// killed and recorded as `timed out` (default: no limit).
    #[serde(default)]
    pub timeout: Option<f64>,
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
        /// Its parameters (`bar_vibration` only); absent: read from each
        /// run's resolved scene, which must be one the closed form describes.
        #[serde(default)]
        parameters: Option<BarVibration>,
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
    /// No reference: the runs' outcomes are recorded without an error.
    #[serde(rename = "none")]
    Unavailable {
        /// Why there is none (written to the report).
        why: String,
    },
}

impl ReferenceSpec {
    /// `kind` as written in the spec.
    fn kind(&self) -> &'static str {
        match self {
            Self::ClosedForm { .. } => "closed_form",
            Self::Run { .. } => "run",
            Self::Series {} => "series",
            Self::Unavailable { .. } => "none",
        }
    }
}

fn as_written() -> IntegratorChoice {
    IntegratorChoice::AsWritten
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
    /// (`solver.cfl`, `grid.cell_size`); absent: one run per method.
    #[serde(default)]
    pub refine: Option<String>,
    /// Values of the refined key, coarse to fine (only with `refine`).
    #[serde(default)]
    pub values: Vec<f64>,
    /// Value of the refined key of this series' reference run
    /// (`reference.kind = "series"`).
    pub reference_value: Option<f64>,
}

impl SeriesSpec {
    /// `(index, value)` of each run of the series: one `(0, None)` without `refine`.
    fn runs(&self) -> Vec<(usize, Option<(String, f64)>)> {
        match &self.refine {
            Some(key) => self
                .values
                .iter()
                .enumerate()
                .map(|(k, &v)| (k, Some((key.clone(), v))))
                .collect(),
            None => vec![(0, None)],
        }
    }
}

/// `[[case]]`: one problem of a case study, run with every method.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct CaseSpec {
    /// Name (the `case` column of the report).
    pub name: String,
    /// Base scene of this case, relative to the spec file (default `study.scene`).
    #[serde(default)]
    pub scene: Option<PathBuf>,
    /// Overrides of the case (after `study.set`, before the axes and series).
    #[serde(default)]
    pub set: Vec<String>,
    /// Time step, s: an implicit run keeps its end time (steps = round(T/Δt)),
    /// an explicit run gets this fixed step (refused above its stability limit).
    #[serde(default)]
    pub dt: Option<f64>,
    /// What this case's runs are compared against (default `[reference]`);
    /// a `run` reference gets the case's scene and overrides, then its own.
    #[serde(default)]
    pub reference: Option<ReferenceSpec>,
    /// The quantities of this case (default `[[quantity]]`).
    #[serde(default)]
    pub quantity: Option<Vec<Quantity>>,
}

/// What one planned run's error is measured against.
#[derive(Clone, Debug, PartialEq)]
pub enum RunReference {
    /// A closed form with its parameters.
    ClosedForm(ClosedForm),
    /// The reference run of this name (a [`StudyPlan::references`] entry).
    Run(String),
    /// No error is measured, and why.
    Unavailable(String),
}

impl RunReference {
    /// One line for the report.
    pub fn describe(&self) -> String {
        match self {
            Self::ClosedForm(c) => c.describe(),
            Self::Run(name) => format!("reference run `{name}`"),
            Self::Unavailable(why) => format!("no reference: {why}"),
        }
    }
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
    /// Refined key and its value (`None` for the study's reference run and
    /// a series without `refine`; a case's `dt` shows as `dt`).
    pub refine: Option<(String, f64)>,
    /// The scene run (when `refused`, as far as it was built).
    pub scene: Scene,
    /// The case (case studies).
    pub case: Option<String>,
    /// Why the run's scene was refused (case studies): it is not run.
    pub refused: Option<String>,
    /// What its error is measured against.
    pub reference: RunReference,
    /// The quantities its error is measured on.
    pub quantities: Vec<Quantity>,
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
    /// Read and check a spec file; the base scene paths (`study.scene`,
    /// `case.scene`) are resolved against the spec's directory.
    pub fn load(path: &Path) -> Result<Self, StudyError> {
        let spec_error = |message: String| StudyError::Spec {
            path: path.display().to_string(),
            message,
        };
        let text = std::fs::read_to_string(path).map_err(|e| spec_error(e.to_string()))?;
        let mut spec: StudySpec = toml::from_str(&text).map_err(|e| spec_error(e.to_string()))?;
        let dir = path.parent().unwrap_or(Path::new("."));
        if spec.study.scene.is_relative() {
            spec.study.scene = dir.join(&spec.study.scene);
        }
        for case in &mut spec.case {
            if let Some(scene) = case.scene.as_mut().filter(|s| s.is_relative()) {
                *scene = dir.join(&*scene);
            }
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
        if let Some(t) = self.study.timeout {
            if !(t.is_finite() && t > 0.0) {
                return Err(format!("study.timeout: must be finite and > 0 s, got {t}"));
            }
        }
        check_reference("reference", &self.reference)?;
        if self.case.is_empty() {
            check_quantities("quantity", &self.quantity, &self.reference)?;
        } else {
            if matches!(self.reference, ReferenceSpec::Series {}) {
                return Err("reference.kind: `series` is not available with [[case]] (give each case its reference)".into());
            }
            // the spec's quantities serve the cases without their own
            check_quantities(
                "quantity",
                &self.quantity,
                &ReferenceSpec::Unavailable { why: String::new() },
            )?;
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
            match &s.refine {
                Some(_) => {
                    if s.values.is_empty() || s.values.iter().any(|v| !(v.is_finite() && *v > 0.0))
                    {
                        return Err(format!(
                            "series[{i}].values: needs at least one value, each finite and > 0"
                        ));
                    }
                }
                None => {
                    if !s.values.is_empty() {
                        return Err(format!(
                            "series[{i}].values: only with `refine` (a series without it is one run per method)"
                        ));
                    }
                }
            }
            match (&self.reference, s.reference_value) {
                (ReferenceSpec::Series {}, Some(v))
                    if v.is_finite() && v > 0.0 && s.refine.is_some() => {}
                (ReferenceSpec::Series {}, _) => {
                    return Err(format!(
                        "series[{i}].reference_value: `reference.kind = \"series\"` needs `refine` and a finite value > 0"
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
        for (i, case) in self.case.iter().enumerate() {
            let field = format!("case[{i}]");
            if case.name.trim().is_empty() {
                return Err(format!("{field}.name: must not be empty"));
            }
            if self.case[..i].iter().any(|c| c.name == case.name) {
                return Err(format!("{field}.name: `{}` is used twice", case.name));
            }
            if let Some(dt) = case.dt {
                if !(dt.is_finite() && dt > 0.0) {
                    return Err(format!("{field}.dt: must be finite and > 0 s, got {dt}"));
                }
                if let Some(j) = self
                    .series
                    .iter()
                    .position(|s| s.refine.as_deref() == Some("dt"))
                {
                    return Err(format!("{field}.dt: series[{j}] refines `dt` already"));
                }
            }
            let reference = case.reference.as_ref().unwrap_or(&self.reference);
            if let Some(r) = &case.reference {
                if matches!(r, ReferenceSpec::Series {}) {
                    return Err(format!(
                        "{field}.reference.kind: `series` is not available in a case"
                    ));
                }
                check_reference(&format!("{field}.reference"), r)?;
            }
            match &case.quantity {
                Some(q) => check_quantities(&format!("{field}.quantity"), q, reference)?,
                None => check_quantities("quantity", &self.quantity, reference).map_err(|e| {
                    format!("{e} (for {field}, which has no `quantity` of its own)")
                })?,
            }
        }
        Ok(())
    }

    /// Every run of the study, each scene built and validated (nothing runs
    /// before every scene is known to be valid; in a case study a run whose
    /// scene the validation refuses is planned as `refused`).
    pub fn plan(&self) -> Result<StudyPlan, StudyError> {
        if !self.case.is_empty() {
            return self.plan_cases();
        }
        let methods = self.methods();
        let mut runs = Vec::new();
        let mut references = Vec::new();
        for (method_index, method) in methods.iter().enumerate() {
            let series = &self.series[method.series];
            let base = self.scene_for(&method.overrides, series.integrator)?;
            for (k, refine) in series.runs() {
                let scene = match &refine {
                    Some((key, value)) => refined(&base, key, *value)?,
                    None => without_snapshots(&base),
                };
                let name = match refine {
                    Some(_) => format!("m{method_index:02}_{k:02}_{}", slug(&method.label)),
                    None => format!("m{method_index:02}_{}", slug(&method.label)),
                };
                let reference = match &self.reference {
                    ReferenceSpec::Series {} => {
                        RunReference::Run(format!("m{method_index:02}_reference"))
                    }
                    ReferenceSpec::Run { .. } => RunReference::Run("reference".into()),
                    other => run_reference(other, &scene),
                };
                runs.push(PlannedRun {
                    name,
                    method: method.label.clone(),
                    series: method.series,
                    axes: method.axes.clone(),
                    integrator: series.integrator,
                    refine,
                    scene,
                    case: None,
                    refused: None,
                    reference,
                    quantities: self.quantity.clone(),
                });
            }
            if let (ReferenceSpec::Series {}, Some(value), Some(key)) =
                (&self.reference, series.reference_value, &series.refine)
            {
                references.push(PlannedRun {
                    name: format!("m{method_index:02}_reference"),
                    method: method.label.clone(),
                    series: method.series,
                    axes: method.axes.clone(),
                    integrator: series.integrator,
                    refine: Some((key.clone(), value)),
                    scene: refined(&base, key, value)?,
                    case: None,
                    refused: None,
                    reference: RunReference::Unavailable("a reference run".into()),
                    quantities: self.quantity.clone(),
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
                case: None,
                refused: None,
                reference: RunReference::Unavailable("a reference run".into()),
                quantities: self.quantity.clone(),
            });
        }
        Ok(StudyPlan {
            spec: self.clone(),
            runs,
            references,
        })
    }

    /// The plan of a case study: every case with every method (and every
    /// value of a refined series), and one reference run per case with a
    /// `run` reference.
    fn plan_cases(&self) -> Result<StudyPlan, StudyError> {
        let methods = self.methods();
        let mut runs = Vec::new();
        let mut references = Vec::new();
        for (case_index, case) in self.case.iter().enumerate() {
            let scene_path = case.scene.as_ref().unwrap_or(&self.study.scene);
            let reference_spec = case.reference.as_ref().unwrap_or(&self.reference);
            let quantities = case
                .quantity
                .clone()
                .unwrap_or_else(|| self.quantity.clone());
            let mut case_overrides = self.study.set.clone();
            case_overrides.extend(case.set.iter().cloned());
            // the case's reference run, if any (refused: the case has no reference)
            let mut case_reference = None;
            if let ReferenceSpec::Run { integrator, set } = reference_spec {
                let name = format!("c{case_index:02}_reference");
                let mut overrides = case_overrides.clone();
                overrides.extend(set.iter().cloned());
                case_reference = Some(match build(scene_path, &overrides, *integrator, &[])? {
                    Ok(scene) => {
                        references.push(PlannedRun {
                            name: name.clone(),
                            method: "reference".into(),
                            series: usize::MAX,
                            axes: Vec::new(),
                            integrator: *integrator,
                            refine: None,
                            scene,
                            case: Some(case.name.clone()),
                            refused: None,
                            reference: RunReference::Unavailable("a reference run".into()),
                            quantities: quantities.clone(),
                        });
                        RunReference::Run(name)
                    }
                    Err(why) => {
                        RunReference::Unavailable(format!("the reference run is refused: {why}"))
                    }
                });
            }
            for (method_index, method) in methods.iter().enumerate() {
                let series = &self.series[method.series];
                let mut overrides = case_overrides.clone();
                overrides.extend(method.overrides.iter().cloned());
                for (k, refine) in series.runs() {
                    let mut steps = Vec::new();
                    if let Some(dt) = case.dt {
                        steps.push(("dt".to_string(), dt));
                    }
                    steps.extend(refine.clone());
                    let suffix = match refine {
                        Some(_) => format!("_{k:02}"),
                        None => String::new(),
                    };
                    let name = format!(
                        "c{case_index:02}_m{method_index:02}{suffix}_{}",
                        slug(&format!("{} {}", case.name, method.label))
                    );
                    let built = build(scene_path, &overrides, series.integrator, &steps)?;
                    let (scene, refused) = match built {
                        Ok(scene) => (scene, None),
                        // the scene as far as it was built: the base with the overrides
                        Err(why) => (
                            parse_unchecked(scene_path, &overrides).map_err(scene_error)?,
                            Some(why),
                        ),
                    };
                    let reference = match (&refused, &case_reference) {
                        (Some(_), _) => RunReference::Unavailable("the run is refused".into()),
                        (None, Some(r)) => r.clone(),
                        (None, None) => run_reference(reference_spec, &scene),
                    };
                    runs.push(PlannedRun {
                        name,
                        method: method.label.clone(),
                        series: method.series,
                        axes: method.axes.clone(),
                        integrator: series.integrator,
                        refine: refine.or_else(|| case.dt.map(|dt| ("dt".to_string(), dt))),
                        scene,
                        case: Some(case.name.clone()),
                        refused,
                        reference,
                        quantities: quantities.clone(),
                    });
                }
            }
        }
        Ok(StudyPlan {
            spec: self.clone(),
            runs,
            references,
        })
    }

    /// The series crossed with the axes: label, axis values and overrides
    /// (axes, then series; `study.set` comes first, added by the caller) of
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
                let mut overrides: Vec<String> = combo
                    .iter()
                    .flat_map(|(_, _, set)| set.iter().cloned())
                    .collect();
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

/// The parameters of a reference, naming `field`.
fn check_reference(field: &str, reference: &ReferenceSpec) -> Result<(), String> {
    match reference {
        ReferenceSpec::ClosedForm {
            name: ClosedFormName::BarVibration,
            parameters: Some(p),
            ..
        } => {
            for (key, v) in [
                ("height", p.height),
                ("wave_speed", p.wave_speed),
                ("velocity", p.velocity),
            ] {
                if !(v.is_finite() && v != 0.0) || (key != "velocity" && v < 0.0) {
                    return Err(format!(
                        "{field}.parameters.{key}: must be finite and nonzero (> 0 for lengths and speeds), got {v}"
                    ));
                }
            }
        }
        ReferenceSpec::ClosedForm {
            name: ClosedFormName::ColumnSettlement,
            parameters: Some(_),
            ..
        } => {
            return Err(format!(
                "{field}.parameters: `column_settlement` reads its parameters from each run's scene"
            ))
        }
        ReferenceSpec::Unavailable { why } if why.trim().is_empty() => {
            return Err(format!("{field}.why: say why there is no reference"))
        }
        _ => {}
    }
    Ok(())
}

/// The quantities `field` against `reference`: at least one unless there is
/// no reference; `time` with `at_time` only; on the closed form's monitor; a
/// period only where the closed form has one.
fn check_quantities(
    field: &str,
    quantities: &[Quantity],
    reference: &ReferenceSpec,
) -> Result<(), String> {
    if quantities.is_empty() && !matches!(reference, ReferenceSpec::Unavailable { .. }) {
        return Err(format!(
            "{field}: at least one [[quantity]] is needed (reference kind `{}`)",
            reference.kind()
        ));
    }
    for (i, q) in quantities.iter().enumerate() {
        match (q.measure, q.time) {
            (Measure::AtTime, Some(t)) if t.is_finite() && t >= 0.0 => {}
            (Measure::AtTime, _) => {
                return Err(format!(
                    "{field}[{i}].time: `at_time` needs a finite time >= 0"
                ))
            }
            (_, Some(_)) => {
                return Err(format!(
                    "{field}[{i}].time: only the `at_time` measure takes a time"
                ))
            }
            _ => {}
        }
        if let ReferenceSpec::ClosedForm { monitor, name, .. } = reference {
            if &q.monitor != monitor {
                return Err(format!(
                    "{field}[{i}].monitor: the closed form describes `{monitor}`, not `{}`",
                    q.monitor
                ));
            }
            if q.measure == Measure::Period && *name == ClosedFormName::ColumnSettlement {
                return Err(format!(
                    "{field}[{i}].measure: `column_settlement` has no period"
                ));
            }
        }
    }
    Ok(())
}

/// The reference of a run of `scene` (a case's reference run and a series'
/// own reference run are named by the caller).
fn run_reference(spec: &ReferenceSpec, scene: &Scene) -> RunReference {
    match spec {
        ReferenceSpec::ClosedForm {
            parameters: Some(p),
            ..
        } => RunReference::ClosedForm(ClosedForm::Bar(*p)),
        ReferenceSpec::ClosedForm {
            name,
            parameters: None,
            ..
        } => match ClosedForm::from_scene(*name, scene) {
            Ok(c) => RunReference::ClosedForm(c),
            Err(why) => RunReference::Unavailable(format!(
                "the closed form `{}` does not describe this scene: {why}",
                closed_form_name(*name)
            )),
        },
        ReferenceSpec::Unavailable { why } => RunReference::Unavailable(why.clone()),
        ReferenceSpec::Run { .. } | ReferenceSpec::Series {} => {
            RunReference::Run("reference".into())
        }
    }
}

fn closed_form_name(name: ClosedFormName) -> &'static str {
    match name {
        ClosedFormName::BarVibration => "bar_vibration",
        ClosedFormName::ColumnSettlement => "column_settlement",
    }
}

/// One method: a series with one combination of axis values.
struct Method {
    series: usize,
    label: String,
    axes: Vec<(String, String)>,
    overrides: Vec<String>,
}

fn scene_error(e: SceneError) -> StudyError {
    StudyError::Scene(e.to_string())
}

/// A validation refusal becomes the run's outcome (`Ok(Err(why))`, one line);
/// any other scene error (unreadable file, unknown key, bad override) is a
/// spec error that stops the study.
fn refusal(e: SceneError) -> Result<String, StudyError> {
    match e {
        SceneError::Invalid { errors, .. } => Ok(errors
            .iter()
            .map(|e| e.to_string())
            .collect::<Vec<_>>()
            .join("; ")),
        other => Err(scene_error(other)),
    }
}

/// The scene at `path` with `overrides` for `integrator`, refined along
/// `steps` (`(key, value)`, as [`refined`]), without snapshots. The outer
/// error stops the study; the inner one is a validation refusal, as text.
fn build(
    path: &Path,
    overrides: &[String],
    integrator: IntegratorChoice,
    steps: &[(String, f64)],
) -> Result<Result<Scene, String>, StudyError> {
    let attempt = || -> Result<Scene, SceneError> {
        let mut scene = Scene::load(path, overrides)?;
        if integrator == IntegratorChoice::Explicit {
            scene = scene.explicit_twin()?;
        }
        for (key, value) in steps {
            scene = refine_scene(&scene, key, *value)?;
        }
        Ok(without_snapshots(&scene))
    };
    match attempt() {
        Ok(scene) => Ok(Ok(scene)),
        Err(e) => refusal(e).map(Err),
    }
}

/// The scene at `path` with `overrides`, parsed but not validated (the scene
/// of a refused run).
fn parse_unchecked(path: &Path, overrides: &[String]) -> Result<Scene, SceneError> {
    let text = std::fs::read_to_string(path).map_err(|source| SceneError::Io {
        path: path.display().to_string(),
        source,
    })?;
    let mut table: toml::Table = text
        .parse()
        .map_err(|e: toml::de::Error| SceneError::Parse {
            path: path.display().to_string(),
            message: e.to_string(),
        })?;
    for o in overrides {
        crate::scene::apply_override(&mut table, o)?;
    }
    toml::Value::Table(table)
        .try_into()
        .map_err(|e: toml::de::Error| SceneError::Parse {
            path: path.display().to_string(),
            message: e.to_string(),
        })
}

/// `scene` with the refined key set to `value`. `dt` keeps the end time of an
/// implicit scene (steps = round(T / Δt)); an explicit scene gets a fixed Δt.
pub fn refined(scene: &Scene, key: &str, value: f64) -> Result<Scene, StudyError> {
    refine_scene(scene, key, value).map_err(scene_error)
}

/// [`refined`] with the scene's own error (a validation refusal stays one).
fn refine_scene(scene: &Scene, key: &str, value: f64) -> Result<Scene, SceneError> {
    let mut overrides = Vec::new();
    if key == "dt" {
        overrides.push(format!("scene.dt={value:e}"));
        if scene.scene.analysis != AnalysisKind::Explicit {
            let invalid = |message: String| SceneError::Invalid {
                path: scene.scene.name.clone(),
                errors: vec![crate::scene::FieldError {
                    field: "scene.dt".into(),
                    message,
                }],
            };
            let (Some(steps), Some(dt)) = (scene.scene.steps, scene.scene.dt) else {
                return Err(invalid(
                    "refine = \"dt\": the implicit scene needs scene.steps and scene.dt".into(),
                ));
            };
            let end = steps as f64 * dt;
            let new_steps = (end / value).round().max(1.0);
            if new_steps > 1e8 {
                return Err(invalid(format!(
                    "refine = \"dt\": Δt = {value:e} s gives {new_steps:e} steps"
                )));
            }
            overrides.push(format!("scene.steps={}", new_steps as usize));
        }
    } else {
        overrides.push(format!("{key}={value:e}"));
    }
    let text = toml::to_string(scene).map_err(|e| SceneError::Parse {
        path: scene.scene.name.clone(),
        message: e.to_string(),
    })?;
    let scene = Scene::from_str_with_overrides(&text, &scene.scene.name, &overrides)?;
    Ok(without_snapshots(&scene))
}

/// A study times the computation and reads `curve.csv`: no snapshot files
/// (by step, every n steps or at times).
fn without_snapshots(scene: &Scene) -> Scene {
    let mut scene = scene.clone();
    scene.output.snapshots.clear();
    scene.output.snapshot_every = 0;
    scene.output.snapshot_times.clear();
    scene
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
