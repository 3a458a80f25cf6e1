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
//! `repeats` times ([`execute`]). Outputs ([`report`]): `study.csv`,
//! `work_precision.png` (log–log error against median wall time, one line per
//! method, the Pareto front marked) and `report.md` (Pareto-optimal runs,
//! crossover points, observed orders of convergence).

mod execute;
mod measure;
mod report;
mod spec;

use std::path::{Path, PathBuf};

pub use execute::{median, read_curve, Measured};
pub use measure::{error, interpolate, log_log_slope, mean_period, Reference};
pub use report::{crossovers, observed_orders, pareto_front, Crossover, StudyRow};
pub use spec::{
    Axis, BarVibration, ClosedFormName, Measure, PlannedRun, Quantity, ReferenceSpec, SeriesSpec,
    StudyPlan, StudySection, StudySpec,
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
}

/// Run the study of `spec_path` into `out`; returns the compared runs.
pub fn run_study(
    spec_path: &Path,
    out: &Path,
    options: &StudyOptions,
) -> Result<Vec<StudyRow>, StudyError> {
    let spec = StudySpec::load(spec_path)?;
    let plan = spec.plan()?;
    let repeats = options.repeats.unwrap_or(spec.study.repeats).max(1);
    let say = |name: &str, m: &Measured| {
        if options.verbose {
            eprintln!(
                "study: {name}: {} in {:.3} s (median of {})",
                m.status,
                m.median_wall(),
                m.wall_seconds.len()
            );
        }
    };
    // references once (timed once: they are not compared)
    let mut references = Vec::new();
    for planned in &plan.references {
        let measured = execute::execute(
            &options.executable,
            planned,
            &execute::run_dir(out, planned),
            1,
        )?;
        say(&planned.name, &measured);
        if !measured.completed() {
            return Err(StudyError::Reference {
                run: planned.name.clone(),
                status: measured.status,
            });
        }
        references.push((planned.method.clone(), measured));
    }
    let mut rows = Vec::new();
    for planned in &plan.runs {
        let measured = execute::execute(
            &options.executable,
            planned,
            &execute::run_dir(out, planned),
            repeats,
        )?;
        say(&planned.name, &measured);
        let errors = spec
            .quantity
            .iter()
            .map(|q| {
                let history = measured.history(&q.monitor)?;
                match &spec.reference {
                    ReferenceSpec::ClosedForm {
                        name: ClosedFormName::BarVibration,
                        parameters,
                        ..
                    } => {
                        let value = |t: f64| parameters.top_displacement(t);
                        let reference = Reference::ClosedForm {
                            value: &value,
                            period: parameters.period(),
                        };
                        error(q, history, &reference)
                    }
                    ReferenceSpec::Run { .. } | ReferenceSpec::Series {} => {
                        let own = references
                            .iter()
                            .find(|(m, _)| m == &planned.method)
                            .or_else(|| references.iter().find(|(m, _)| m == "reference"))?;
                        error(q, history, &Reference::Run(own.1.history(&q.monitor)?))
                    }
                }
            })
            .collect();
        rows.push(StudyRow {
            planned: planned.clone(),
            measured,
            errors,
        });
    }
    let reference = match &spec.reference {
        ReferenceSpec::ClosedForm { name, .. } => format!("closed form `{name:?}`"),
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
    };
    report::write_csv(&out.join("study.csv"), &spec, &rows)?;
    report::write_figure(&out.join("work_precision.png"), &spec, &rows)?;
    report::write_report(&out.join("report.md"), &spec, &reference, &rows)?;
    Ok(rows)
}

#[cfg(test)]
mod tests;
