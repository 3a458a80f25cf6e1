//! `mpm-geo study SPEC`: error against run time.
//!
//! A study spec ([`StudySpec`], `validation/studies/*.toml`) names a base
//! scene, the series to compare (a method — integrator, overrides — refined
//! along one key such as Δt, the CFL number or the cell size), axes crossed
//! with every series, the quantities compared (monitors, as a relative L2 norm
//! in time, a value at a time or a period) and the reference: a closed form,
//! one reference run, or each series against its own finest run. Every run
//! is first built and validated ([`StudySpec::plan`]), then run as a whole
//! `mpm-geo run` process on its resolved `scene.toml`, one at a time, timed
//! `repeats` times (`execute.rs`). Outputs (`report.rs`): `study.csv`,
//! `work_precision.png` (log–log error against median wall time, one line per
//! method, the Pareto front marked) and `report.md` (Pareto-optimal runs,
//! crossover points, observed orders of convergence).
//!
//! A *case study* (`[[case]]`, e.g. `validation/studies/extreme_cases.toml`)
//! runs a list of problems — each its own base scene, overrides, time step,
//! reference and quantities — with every method, and reports each run's
//! outcome: completed with its error, `stopped: why` or `refused: why` (a
//! scene the validation refuses is recorded, not an error of the study). A
//! closed form may read its parameters from each run's scene
//! ([`ClosedForm::from_scene`]), and says why when it does not describe it.
//! A run process that panics, is killed by a signal or exceeds
//! `study.timeout` is recorded as such ([`Measured::stated`] is false).

mod closed_form;
mod execute;
mod measure;
mod report;
mod spec;

use crate::campaign::Part;
use crate::progress_lines::BatchProgress;
use crate::scene::Scene;
use std::path::{Path, PathBuf};

pub use closed_form::{BarVibration, ClosedForm, ClosedFormName, ColumnSettlement};
pub use execute::{median, read_curve, Measured};
pub use measure::{error, interpolate, log_log_slope, mean_period, Reference};
pub use report::{crossovers, observed_orders, pareto_front, refined_column, Crossover, StudyRow};
pub use spec::{
    refined, Axis, CaseSpec, Measure, PlannedRun, Quantity, ReferenceSpec, RunReference,
    SeriesSpec, StudyPlan, StudySection, StudySpec,
};

/// Why a study could not run.
#[derive(Debug, thiserror::Error)]
pub enum StudyError {
    /// The spec file is unreadable or invalid (the message names the field).
    #[error("study spec {path}: {message}")]
    Spec {
        /// The spec path.
        path: String,
        /// What is wrong.
        message: String,
    },
    /// A run's scene is invalid (nothing was run).
    #[error("{0}")]
    Scene(String),
    /// Reading or writing a file failed.
    #[error("{path}: {message}")]
    Io {
        /// The file.
        path: String,
        /// The system's message.
        message: String,
    },
    /// A reference run did not complete: no error can be measured.
    /// `--collect` (or a shard) found runs not measured yet.
    #[error("study runs not measured yet (run their shards first): {0}")]
    Unfinished(String),
    /// SIGINT or SIGTERM stopped the study: the run in progress was passed
    /// the signal and ended after a whole step (its `run.json` says
    /// `interrupted`); it is not recorded as measured, and no other starts.
    #[error(
        "study interrupted by {}: {}; run the same command again to finish it (measured runs are not run again)",
        signal.name(),
        run.as_ref().map_or("no run was in progress".to_string(), |r| format!("run {r} stopped after a whole step (its run.json says interrupted)"))
    )]
    Interrupted {
        /// The signal.
        signal: crate::interrupt::Interruption,
        /// The run it stopped, if one was in progress.
        run: Option<String>,
    },
    /// A reference run that did not complete (a study without cases).
    #[error("reference run {run} did not complete: {status}")]
    Reference {
        /// The reference run.
        run: String,
        /// Its status.
        status: String,
    },
}

/// Options of [`run_study`].
#[derive(Clone, Debug)]
pub struct StudyOptions {
    /// The `mpm-geo` executable that runs each scene.
    pub executable: PathBuf,
    /// Repeats instead of the spec's `study.repeats`.
    pub repeats: Option<usize>,
    /// Print one line per finished run.
    pub verbose: bool,
    /// `key=value` overrides applied last to every run's scene, after the
    /// spec's own (e.g. `scene.steps=2` for a quick look at a study).
    pub overrides: Vec<String>,
    /// The whole study, one shard of it, or the report from the shards
    /// (runs measured earlier with the same scene, repeats and time-out are
    /// not run again in any of them).
    pub part: Part,
}

/// Run the study of `spec_path` into `out`; returns the compared runs.
pub fn run_study(
    spec_path: &Path,
    out: &Path,
    options: &StudyOptions,
) -> Result<Vec<StudyRow>, StudyError> {
    let spec = StudySpec::load(spec_path)?;
    run_spec(&spec, out, options)
}

/// Run a loaded (and possibly edited) study spec into `out`; returns the
/// compared runs. A reference run that does not complete stops a study
/// without cases; in a case study its case's runs get no error instead, and
/// the report says why.
pub fn run_spec(
    spec: &StudySpec,
    out: &Path,
    options: &StudyOptions,
) -> Result<Vec<StudyRow>, StudyError> {
    let mut plan = spec.plan()?;
    if !options.overrides.is_empty() {
        for planned in plan.references.iter_mut().chain(plan.runs.iter_mut()) {
            if planned.refused.is_none() {
                planned.scene = with_overrides(&planned.scene, &options.overrides)?;
            }
        }
    }
    let repeats = options.repeats.unwrap_or(spec.study.repeats).max(1);
    let timeout = spec.study.timeout;
    let say = |name: &str, m: &Measured| {
        if options.verbose {
            if m.wall_seconds.is_empty() {
                eprintln!("study: {name}: {} (not run)", m.status);
            } else {
                eprintln!(
                    "study: {name}: {} in {:.3} s (median of {})",
                    m.status,
                    m.median_wall(),
                    m.wall_seconds.len()
                );
            }
        }
    };
    // references first, timed once (they are not compared); every run's
    // measurement is kept in its directory, so a re-run study, a shard or a
    // collect reuses what was measured with the same scene
    let all: Vec<&PlannedRun> = plan.references.iter().chain(&plan.runs).collect();
    let repeats_of = |i: usize| {
        if i < plan.references.len() {
            1
        } else {
            repeats
        }
    };
    let costs: Vec<f64> = all.iter().map(|p| execute::cost(&p.scene)).collect();
    let selected = options.part.selects(&costs);
    let earlier: Vec<Option<Measured>> = all
        .iter()
        .enumerate()
        .map(|(i, planned)| {
            let dir = execute::run_dir(out, planned);
            execute::load_measured(&dir, &execute::fingerprint(planned, repeats_of(i), timeout))
        })
        .collect();
    let to_do: Vec<f64> = (0..all.len())
        .filter(|&i| selected[i] && all[i].refused.is_none() && earlier[i].is_none())
        .map(|i| costs[i] * repeats_of(i) as f64)
        .collect();
    let done_before = (0..all.len())
        .filter(|&i| selected[i] && earlier[i].is_some())
        .count();
    let mut progress = options
        .verbose
        .then(|| BatchProgress::start("study", &to_do, done_before, 1));
    let mut measurements: Vec<Option<Measured>> = Vec::with_capacity(all.len());
    for ((i, planned), earlier) in all.iter().enumerate().zip(earlier) {
        let dir = execute::run_dir(out, planned);
        let fingerprint = execute::fingerprint(planned, repeats_of(i), timeout);
        let measured = match (&planned.refused, earlier) {
            (Some(why), _) => Some(Measured::refused(why)),
            (None, Some(measured)) => {
                if options.verbose && selected[i] {
                    eprintln!("study: {}: measured earlier, not run again", planned.name);
                }
                Some(measured)
            }
            (None, None) if selected[i] => {
                if let Some(signal) = crate::interrupt::requested() {
                    return Err(StudyError::Interrupted { signal, run: None });
                }
                if let Some(p) = &mut progress {
                    p.started(&planned.name);
                }
                let measured =
                    execute::execute(&options.executable, planned, &dir, repeats_of(i), timeout)?;
                execute::save_measured(&dir, &fingerprint, &measured)?;
                say(&planned.name, &measured);
                if let Some(p) = progress.as_mut() {
                    eprintln!("{}", p.finished(costs[i] * repeats_of(i) as f64));
                }
                Some(measured)
            }
            (None, None) => None,
        };
        measurements.push(measured);
    }
    let in_scope = |i: usize| match options.part {
        Part::Shard { .. } => selected[i],
        Part::Whole | Part::Collect => true,
    };
    let missing: Vec<&str> = (0..all.len())
        .filter(|&i| in_scope(i) && measurements[i].is_none())
        .map(|i| all[i].name.as_str())
        .collect();
    if !missing.is_empty() {
        return Err(StudyError::Unfinished(missing.join(", ")));
    }
    if let Part::Shard { .. } = options.part {
        // a shard's rows carry no error: the references may be in other shards
        let first = plan.references.len();
        return Ok(plan
            .runs
            .iter()
            .enumerate()
            .filter(|(j, _)| selected[first + j])
            .filter_map(|(j, planned)| {
                Some(StudyRow {
                    planned: planned.clone(),
                    measured: measurements[first + j].clone()?,
                    errors: vec![None; planned.quantities.len()],
                })
            })
            .collect());
    }
    let mut measurements = measurements.into_iter().flatten();
    let mut references: Vec<(String, Measured)> = Vec::new();
    for planned in &plan.references {
        let measured = measurements
            .next()
            .unwrap_or_else(|| Measured::refused("not run"));
        if !measured.completed() && spec.case.is_empty() {
            return Err(StudyError::Reference {
                run: planned.name.clone(),
                status: measured.status,
            });
        }
        references.push((planned.name.clone(), measured));
    }
    let mut rows = Vec::new();
    for planned in &plan.runs {
        let measured = measurements
            .next()
            .unwrap_or_else(|| Measured::refused("not run"));
        let mut planned = planned.clone();
        if let RunReference::Run(name) = &planned.reference {
            match references.iter().find(|(n, _)| n == name) {
                Some((_, r)) if !r.completed() => {
                    planned.reference = RunReference::Unavailable(format!(
                        "the reference run `{name}` did not complete ({})",
                        r.status
                    ))
                }
                None => {
                    planned.reference =
                        RunReference::Unavailable(format!("no reference run `{name}`"))
                }
                _ => {}
            }
        }
        let errors = planned
            .quantities
            .iter()
            .map(|q| {
                let history = measured.history(&q.monitor)?;
                match &planned.reference {
                    RunReference::ClosedForm(closed) => {
                        let value = |t: f64| closed.value(t);
                        let reference = Reference::ClosedForm {
                            value: &value,
                            period: closed.period(),
                        };
                        error(q, history, &reference)
                    }
                    RunReference::Run(name) => {
                        let own = references.iter().find(|(n, _)| n == name)?;
                        error(q, history, &Reference::Run(own.1.history(&q.monitor)?))
                    }
                    RunReference::Unavailable(_) => None,
                }
            })
            .collect();
        rows.push(StudyRow {
            planned,
            measured,
            errors,
        });
    }
    let reference = match &spec.reference {
        ReferenceSpec::ClosedForm {
            name,
            parameters: Some(_),
            ..
        } => format!("closed form `{name:?}`"),
        ReferenceSpec::ClosedForm { name, .. } => {
            format!("closed form `{name:?}`, its parameters read from each run's scene")
        }
        ReferenceSpec::Run { set, integrator } => format!(
            "one run ({integrator:?}, overrides {})",
            if set.is_empty() {
                "none".to_string()
            } else {
                set.join(" ")
            }
        ),
        ReferenceSpec::Series {} => {
            "each method against its own run at the series' `reference_value`".to_string()
        }
        ReferenceSpec::Unavailable { why } => format!("none ({why})"),
    };
    report::write_csv(&out.join("study.csv"), spec, &rows)?;
    if spec.case.is_empty() {
        report::write_figure(&out.join("work_precision.png"), spec, &rows)?;
        report::write_report(&out.join("report.md"), spec, &reference, &rows)?;
    } else {
        report::write_case_report(&out.join("report.md"), spec, &rows)?;
    }
    Ok(rows)
}

/// `scene` with `overrides` applied (and validated again).
fn with_overrides(scene: &Scene, overrides: &[String]) -> Result<Scene, StudyError> {
    let text = toml::to_string(scene).map_err(|e| StudyError::Scene(e.to_string()))?;
    Scene::from_str_with_overrides(&text, &scene.scene.name, overrides)
        .map_err(|e| StudyError::Scene(e.to_string()))
}

use mpm_physics::error_id::{ErrorId, Identified};

impl Identified for StudyError {
    fn error_id(&self) -> ErrorId {
        match self {
            StudyError::Spec { .. } => ErrorId::StudySpec,
            StudyError::Scene(_) => ErrorId::StudyScene,
            StudyError::Io { .. } => ErrorId::StudyIo,
            StudyError::Unfinished(_) => ErrorId::StudyUnfinished,
            StudyError::Reference { .. } => ErrorId::StudyReference,
            StudyError::Interrupted { .. } => ErrorId::Interrupted,
        }
    }
}

#[cfg(test)]
mod tests;
