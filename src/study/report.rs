//! The study's outputs: `study.csv`, the work-precision figure and
//! `report.md` (Pareto-optimal runs, crossover points, observed orders).

use std::fmt::Write as _;
use std::path::Path;

use super::execute::Measured;
use super::measure::log_log_slope;
use super::spec::{PlannedRun, RunReference, StudySpec};
use super::StudyError;
use crate::atomic_file::{write_atomic, AtomicFile};
use crate::campaign::IntegratorChoice;
use crate::csv_columns::{column, number, optional, scene_key_unit, Unit};
use crate::plot::{plot_work_precision, Marker, Series};
use crate::profile::Stage;
use crate::scene::AnalysisKind;

/// One compared run with its errors.
#[derive(Clone, Debug)]
pub struct StudyRow {
    /// The planned run.
    pub planned: PlannedRun,
    /// What it measured.
    pub measured: Measured,
    /// Error per quantity (spec order); `None` where it cannot be measured.
    pub errors: Vec<Option<f64>>,
}

impl StudyRow {
    /// The run's error: the largest over the quantities (`None` if any is
    /// missing, the run did not complete or it has no reference).
    pub fn error(&self) -> Option<f64> {
        if !self.measured.completed()
            || matches!(self.planned.reference, RunReference::Unavailable(_))
            || self.errors.is_empty()
        {
            return None;
        }
        self.errors
            .iter()
            .try_fold(0.0f64, |m, e| e.map(|e| m.max(e)))
    }
}

/// Indices of the Pareto-optimal rows: no other row is both faster and more
/// accurate (ties broken towards the earlier row).
pub fn pareto_front(rows: &[StudyRow]) -> Vec<usize> {
    let points: Vec<Option<(f64, f64)>> = rows
        .iter()
        .map(|r| r.error().map(|e| (r.measured.median_wall(), e)))
        .collect();
    let mut front: Vec<usize> = (0..rows.len())
        .filter(|&i| {
            let Some((ti, ei)) = points[i] else {
                return false;
            };
            !points.iter().enumerate().any(|(j, p)| {
                p.is_some_and(|(tj, ej)| {
                    j != i && tj <= ti && ej <= ei && (tj < ti || ej < ei || j < i)
                })
            })
        })
        .collect();
    front.sort_by(|&a, &b| {
        let (ta, tb) = (
            points[a].map_or(0.0, |p| p.0),
            points[b].map_or(0.0, |p| p.0),
        );
        ta.total_cmp(&tb)
    });
    front
}

/// A crossover: at errors below `error` method `faster_below` reaches the
/// same error in less time than `faster_above` (log–log interpolation).
#[derive(Clone, Debug, PartialEq)]
pub struct Crossover {
    /// The error at the crossing.
    pub error: f64,
    /// The wall time at the crossing, s.
    pub wall_seconds: f64,
    /// The method faster for smaller errors.
    pub faster_below: String,
    /// The method faster for larger errors.
    pub faster_above: String,
}

/// The (log error, log time) polyline of one method, sorted by error.
fn method_curve(rows: &[&StudyRow]) -> Vec<(f64, f64)> {
    let mut pts: Vec<(f64, f64)> = rows
        .iter()
        .filter_map(|r| {
            let e = r.error()?;
            (e > 0.0).then(|| (e.ln(), r.measured.median_wall().max(1e-9).ln()))
        })
        .collect();
    pts.sort_by(|a, b| a.0.total_cmp(&b.0));
    pts.dedup_by(|a, b| a.0 == b.0);
    pts
}

fn interp(curve: &[(f64, f64)], x: f64) -> Option<f64> {
    let k = curve.partition_point(|p| p.0 <= x);
    if k == 0 || k == curve.len() {
        return (curve.last()?.0 == x)
            .then(|| curve.last().map(|p| p.1))
            .flatten();
    }
    let (a, b) = (curve[k - 1], curve[k]);
    Some(a.1 + (b.1 - a.1) * (x - a.0) / (b.0 - a.0))
}

/// Where two methods' time-to-error curves cross, for every pair of methods
/// whose error ranges overlap.
pub fn crossovers(rows: &[StudyRow]) -> Vec<Crossover> {
    let methods = method_names(rows);
    let curves: Vec<Vec<(f64, f64)>> = methods
        .iter()
        .map(|m| {
            method_curve(
                &rows
                    .iter()
                    .filter(|r| &r.planned.method == m)
                    .collect::<Vec<_>>(),
            )
        })
        .collect();
    let mut out = Vec::new();
    for a in 0..methods.len() {
        for b in a + 1..methods.len() {
            let (ca, cb) = (&curves[a], &curves[b]);
            let mut xs: Vec<f64> = ca.iter().chain(cb.iter()).map(|p| p.0).collect();
            xs.sort_by(f64::total_cmp);
            xs.dedup();
            let diffs: Vec<(f64, f64)> = xs
                .iter()
                .filter_map(|&x| Some((x, interp(ca, x)? - interp(cb, x)?)))
                .collect();
            for w in diffs.windows(2) {
                let ((x0, d0), (x1, d1)) = (w[0], w[1]);
                if d0 == 0.0 || d0.signum() == d1.signum() || d1 == 0.0 {
                    continue;
                }
                let x = x0 + (x1 - x0) * d0 / (d0 - d1);
                let Some(t) = interp(ca, x) else { continue };
                // below the crossing (smaller x) the sign of d0 says who is faster
                let (below, above) = if d0 < 0.0 { (a, b) } else { (b, a) };
                out.push(Crossover {
                    error: x.exp(),
                    wall_seconds: t.exp(),
                    faster_below: methods[below].clone(),
                    faster_above: methods[above].clone(),
                });
            }
        }
    }
    out
}

/// Method labels in first-appearance order.
fn method_names(rows: &[StudyRow]) -> Vec<String> {
    let mut names: Vec<String> = Vec::new();
    for r in rows {
        if !names.contains(&r.planned.method) {
            names.push(r.planned.method.clone());
        }
    }
    names
}

/// Observed order per method: slope of log error against log refined value.
pub fn observed_orders(rows: &[StudyRow]) -> Vec<(String, Option<f64>)> {
    method_names(rows)
        .into_iter()
        .map(|m| {
            let pts: Vec<(f64, f64)> = rows
                .iter()
                .filter(|r| r.planned.method == m)
                .filter_map(|r| Some((r.planned.refine.as_ref()?.1, r.error()?)))
                .collect();
            (m, log_log_slope(&pts))
        })
        .collect()
}

/// The column of the refined values of `key` in `study.csv`: the key and
/// its unit (`dt_s`, `solver.cfl_1`); `<key>_unknown_unit` for a key of no
/// known unit ([`scene_key_unit`]).
pub fn refined_column(key: &str) -> String {
    match scene_key_unit(key) {
        Some(unit) => column(key, unit),
        None => format!("{key}_unknown_unit"),
    }
}

/// The error columns of `study.csv`: every quantity of the spec and its
/// cases, in order, as relative errors (`error_top_uy_l2_1`).
fn error_columns(spec: &StudySpec, rows: &[StudyRow]) -> Vec<String> {
    let mut columns: Vec<String> = Vec::new();
    for q in spec
        .quantity
        .iter()
        .chain(rows.iter().flat_map(|r| r.planned.quantities.iter()))
    {
        if !columns.contains(&q.column()) {
            columns.push(q.column());
        }
    }
    columns
}

/// The refined keys of the rows, in order of first appearance.
fn refined_keys(rows: &[StudyRow]) -> Vec<String> {
    let mut keys: Vec<String> = Vec::new();
    for (key, _) in rows.iter().filter_map(|r| r.planned.refine.as_ref()) {
        if !keys.contains(key) {
            keys.push(key.clone());
        }
    }
    keys
}

/// Header of `study.csv`: identifiers (run, case, method, series,
/// integrator, the axes, the refined key), the refined value per key, the
/// effort and stage times, the errors, the status and the case's reference.
fn study_header(spec: &StudySpec, keys: &[String], errors: &[String]) -> Vec<String> {
    let cases = !spec.case.is_empty();
    let mut header: Vec<String> = ["run", "method", "series", "integrator"]
        .iter()
        .map(|s| s.to_string())
        .collect();
    if cases {
        header.insert(1, "case".into());
    }
    header.extend(spec.axis.iter().map(|a| format!("axis_{}", a.name)));
    header.push("refine".into());
    header.extend(keys.iter().map(|k| refined_column(k)));
    header.extend(
        [
            "repeats_1",
            "wall_s",
            "wall_min_s",
            "wall_max_s",
            "steps_1",
            "newton_iterations_1",
            "factorisations_1",
            "halvings_1",
            "linear_time_per_newton_iteration_s",
            "factor_nnz_1",
            "pcg_iterations_1",
            "linear_fallbacks_1",
        ]
        .iter()
        .map(|s| s.to_string()),
    );
    header.extend(Stage::ALL.iter().map(|s| column(s.name(), Unit::Second)));
    header.extend(errors.iter().map(|c| column(c, Unit::One)));
    header.extend(["error_1".to_string(), "status".to_string()]);
    if cases {
        header.push("reference".into());
    }
    header
}

/// The fields of one run in the order of [`study_header`].
fn study_record(
    spec: &StudySpec,
    row: &StudyRow,
    keys: &[String],
    errors: &[String],
) -> Vec<String> {
    let (p, m) = (&row.planned, &row.measured);
    let mut record = vec![
        p.name.clone(),
        p.method.clone(),
        spec.series
            .get(p.series)
            .map_or("reference".into(), |s| s.label.clone()),
        format!("{:?}", p.integrator).to_lowercase(),
    ];
    if !spec.case.is_empty() {
        record.insert(1, p.case.clone().unwrap_or_default());
    }
    for axis in &spec.axis {
        record.push(
            p.axes
                .iter()
                .find(|(name, _)| name == &axis.name)
                .map_or(String::new(), |(_, v)| v.clone()),
        );
    }
    record.push(p.refine.as_ref().map_or(String::new(), |(k, _)| k.clone()));
    record.extend(keys.iter().map(|key| match &p.refine {
        Some((k, value)) if k == key => number(*value),
        _ => String::new(),
    }));
    let walls = &m.wall_seconds;
    record.extend([
        walls.len().to_string(),
        number(m.median_wall()),
        optional(walls.iter().copied().reduce(f64::min)),
        optional(walls.iter().copied().reduce(f64::max)),
        m.steps.to_string(),
        m.newton_iterations.to_string(),
        m.factorisations.to_string(),
        m.halvings.to_string(),
        number(m.linear.seconds_per_newton_iteration),
        m.linear
            .factor_nnz
            .map_or_else(String::new, |n| n.to_string()),
        m.linear.pcg_iterations.to_string(),
        m.linear.fallbacks.to_string(),
    ]);
    record.extend(
        (0..Stage::ALL.len()).map(|i| number(m.stage_seconds.get(i).copied().unwrap_or(0.0))),
    );
    record.extend(errors.iter().map(|c| {
        p.quantities
            .iter()
            .position(|q| &q.column() == c)
            .map_or(String::new(), |i| {
                optional(row.errors.get(i).copied().flatten())
            })
    }));
    record.push(optional(row.error()));
    record.push(m.status.clone());
    if !spec.case.is_empty() {
        record.push(p.reference.describe().replace(',', ";"));
    }
    record
}

/// `study.csv`: one row per run with its identifiers (every axis value as
/// `axis_<name>`, the refined key), the refined value in the column of its
/// key, wall time (median, min, max over the repeats), per-stage seconds,
/// steps, Newton iterations, factorisations, halvings, the relative error
/// per quantity and the run's error (docs/study.md).
pub fn write_csv(path: &Path, spec: &StudySpec, rows: &[StudyRow]) -> Result<(), StudyError> {
    let io = |e: &dyn std::fmt::Display| StudyError::Io {
        path: path.display().to_string(),
        message: e.to_string(),
    };
    let file = AtomicFile::create(path).map_err(|e| io(&e))?;
    let mut w = csv::Writer::from_writer(file);
    let (keys, errors) = (refined_keys(rows), error_columns(spec, rows));
    w.write_record(study_header(spec, &keys, &errors))
        .map_err(|e| io(&e))?;
    for row in rows {
        w.write_record(study_record(spec, row, &keys, &errors))
            .map_err(|e| io(&e))?;
    }
    // whole or absent: renamed to its name once every row is written
    let file = w.into_inner().map_err(|e| io(&e.to_string()))?;
    file.commit().map_err(|e| io(&e))
}

/// The work-precision figure: error against median wall time, log–log, one
/// line per method, the Pareto front marked.
pub fn write_figure(path: &Path, spec: &StudySpec, rows: &[StudyRow]) -> Result<(), StudyError> {
    let series: Vec<Series> = method_names(rows)
        .iter()
        .enumerate()
        .map(|(i, m)| {
            let mut points: Vec<(f64, f64)> = rows
                .iter()
                .filter(|r| &r.planned.method == m)
                .filter_map(|r| Some((r.measured.median_wall(), r.error()?)))
                .collect();
            points.sort_by(|a, b| a.0.total_cmp(&b.0));
            Series {
                name: m.clone(),
                points,
                dashed: false,
                color: i,
                marker: Some(Marker::of_index(i)),
            }
        })
        .collect();
    if series.iter().all(|s| s.points.is_empty()) {
        // no run has an error to plot (every one stopped): the CSV and the
        // report say why
        return Ok(());
    }
    let front: Vec<(f64, f64)> = pareto_front(rows)
        .into_iter()
        .filter_map(|i| Some((rows[i].measured.median_wall(), rows[i].error()?)))
        .collect();
    plot_work_precision(
        path,
        &format!("{}: error against wall time", spec.study.name),
        &series,
        &front,
    )
    .map_err(|e| StudyError::Io {
        path: path.display().to_string(),
        message: e.to_string(),
    })
}

/// `report.md`: the runs, the Pareto-optimal ones, the crossovers and the
/// observed orders.
pub fn write_report(
    path: &Path,
    spec: &StudySpec,
    reference: &str,
    rows: &[StudyRow],
) -> Result<(), StudyError> {
    let mut md = format!("# Study `{}`\n\n", spec.study.name);
    let _ = writeln!(
        md,
        "Base scene `{}`; each run timed {} time(s) as a whole `mpm-geo run` process, one at a time (median wall time). Reference: {reference}. Error: the largest over the quantities ({}).\n",
        spec.study.scene.display(),
        spec.study.repeats,
        spec.quantity
            .iter()
            .map(|q| format!("`{}`", q.column()))
            .collect::<Vec<_>>()
            .join(", ")
    );
    md += "| run | method | refined | wall (s) | steps | Newton its | factorisations | error | status |\n|---|---|---|---|---|---|---|---|---|\n";
    for r in rows {
        let (key, value) = r.planned.refine.clone().unwrap_or_default();
        let _ = writeln!(
            md,
            "| {} | {} | {key} = {value:.3e} | {:.3} | {} | {} | {} | {} | {} |",
            r.planned.name,
            r.planned.method,
            r.measured.median_wall(),
            r.measured.steps,
            r.measured.newton_iterations,
            r.measured.factorisations,
            r.error().map_or("—".into(), |e| format!("{e:.3e}")),
            r.measured.status
        );
    }
    md += "\n## Pareto-optimal runs (no run both faster and more accurate)\n\n";
    for i in pareto_front(rows) {
        let r = &rows[i];
        let _ = writeln!(
            md,
            "- `{}` ({}): {:.3} s, error {:.3e}",
            r.planned.name,
            r.planned.method,
            r.measured.median_wall(),
            r.error().unwrap_or(f64::NAN)
        );
    }
    md += "\n## Crossovers (time to reach an error, interpolated log–log)\n\n";
    let crossings = crossovers(rows);
    if crossings.is_empty() {
        md += "None within the measured ranges: where the error ranges overlap, one method is faster throughout.\n";
    }
    for c in crossings {
        let _ = writeln!(
            md,
            "- at error {:.3e} ({:.3} s): below it {} is faster, above it {}",
            c.error, c.wall_seconds, c.faster_below, c.faster_above
        );
    }
    md += "\n## Observed order (slope of log error against log refined value)\n\n";
    for (m, slope) in observed_orders(rows) {
        let _ = writeln!(
            md,
            "- {m}: {}",
            slope.map_or("—".into(), |s| format!("{s:.2}"))
        );
    }
    md += "\nFigure: `work_precision.png`. Every run's scene is `runs/<run>/scene.toml`.\n";
    write_atomic(path, md).map_err(|e| StudyError::Io {
        path: path.display().to_string(),
        message: e.to_string(),
    })
}

/// The outcome cell of a run in a markdown table: the status, cut at
/// `limit` characters (the full text is in `study.csv`).
fn outcome_cell(status: &str, limit: usize) -> String {
    let text = status.replace('|', "/");
    if text.chars().count() <= limit {
        text
    } else {
        format!("{}…", text.chars().take(limit).collect::<String>())
    }
}

/// The error cell of a run: the error, `no reference`, or `—` (did not complete).
fn error_cell(row: &StudyRow) -> String {
    match (&row.planned.reference, row.error()) {
        (_, Some(e)) => format!("{e:.3e}"),
        _ if !row.measured.completed() => "—".into(),
        (RunReference::Unavailable(_), None) => "no reference".into(),
        _ => "not measured".into(),
    }
}

/// The integrator a run actually used (a case may make the scene as written
/// quasi-static), with its step rule.
fn integrator_text(p: &PlannedRun) -> String {
    let s = &p.scene.solver;
    let mut text = match (p.integrator, p.scene.scene.analysis) {
        (IntegratorChoice::Explicit, _) | (_, AnalysisKind::Explicit) => {
            let mut t = "explicit MUSL".to_string();
            if p.refused.is_none() {
                match p.scene.scene.dt {
                    Some(dt) => t += &format!(", Δt = {dt:e} s"),
                    None => t += &format!(", CFL {}", s.cfl),
                }
            }
            if s.damping > 0.0 {
                t += &format!(", local damping {}", s.damping);
            }
            t
        }
        (_, AnalysisKind::ImplicitDynamic) => format!("implicit {}", s.time_scheme()),
        (_, AnalysisKind::QuasiStatic) => "implicit quasi-static Newton".to_string(),
    };
    for (name, value) in &p.axes {
        text += &format!(", {name} = {value}");
    }
    text
}

/// `report.md` of a case study: one row per case and method (case,
/// integrator, outcome, error, steps, wall time), then each case's
/// reference and the solver counts.
pub fn write_case_report(
    path: &Path,
    spec: &StudySpec,
    rows: &[StudyRow],
) -> Result<(), StudyError> {
    let mut md = format!("# Study `{}`\n\n", spec.study.name);
    let _ = writeln!(
        md,
        "{} cases, each run with every method as a whole `mpm-geo run` process (median wall time of {} repeat(s)). Outcome: `completed`, `stopped: why` (the run failed mid-way; its outputs up to then are kept) or `refused: why` (the scene was refused before anything ran). Error: the largest relative error over the case's quantities, against the case's reference (below).\n",
        spec.case.len(),
        spec.study.repeats
    );
    let count = |prefix: &str| {
        rows.iter()
            .filter(|r| r.measured.stated() && r.measured.status.starts_with(prefix))
            .count()
    };
    let _ = writeln!(
        md,
        "{} runs: {} completed, {} stopped, {} refused, {} without a stated outcome (panic, time-out or signal).\n",
        rows.len(),
        count("completed"),
        count("stopped"),
        count("refused"),
        rows.iter().filter(|r| !r.measured.stated()).count()
    );
    md += "| case | integrator | outcome | error | steps | wall time (s) |\n|---|---|---|---|---|---|\n";
    for r in rows {
        let wall = r.measured.median_wall();
        let _ = writeln!(
            md,
            "| {} | {} | {} | {} | {} | {} |",
            r.planned.case.as_deref().unwrap_or(""),
            integrator_text(&r.planned),
            outcome_cell(&r.measured.status, 180),
            error_cell(r),
            if r.measured.wall_seconds.is_empty() {
                "—".to_string()
            } else {
                r.measured.steps.to_string()
            },
            if wall.is_finite() {
                format!("{wall:.3}")
            } else {
                "—".into()
            },
        );
    }
    md += "\n## References\n\n";
    for case in &spec.case {
        let mut seen: Vec<String> = Vec::new();
        for r in rows
            .iter()
            .filter(|r| r.planned.case.as_deref() == Some(case.name.as_str()))
        {
            if r.planned.refused.is_some() {
                continue;
            }
            // a stopped reference run's status can be long (a residual history)
            let text = outcome_cell(&r.planned.reference.describe(), 400);
            if !seen.contains(&text) {
                seen.push(text);
            }
        }
        let quantities: Vec<String> = rows
            .iter()
            .find(|r| r.planned.case.as_deref() == Some(case.name.as_str()))
            .map(|r| {
                r.planned
                    .quantities
                    .iter()
                    .map(|q| format!("`{}`", q.column()))
                    .collect()
            })
            .unwrap_or_default();
        let _ = writeln!(
            md,
            "- **{}**: {}{}",
            case.name,
            if seen.is_empty() {
                "every run refused".to_string()
            } else {
                seen.join("; ")
            },
            if quantities.is_empty() || seen.iter().all(|s| s.starts_with("no reference")) {
                String::new()
            } else {
                format!(" — on {}", quantities.join(", "))
            }
        );
    }
    md += "\n## Runs\n\n| run | case | method | refined | Newton its | halvings | factorisations | status |\n|---|---|---|---|---|---|---|---|\n";
    for r in rows {
        let refined = r
            .planned
            .refine
            .as_ref()
            .map_or("—".to_string(), |(k, v)| format!("{k} = {v:.3e}"));
        let _ = writeln!(
            md,
            "| {} | {} | {} | {refined} | {} | {} | {} | {} |",
            r.planned.name,
            r.planned.case.as_deref().unwrap_or(""),
            r.planned.method,
            r.measured.newton_iterations,
            r.measured.halvings,
            r.measured.factorisations,
            outcome_cell(&r.measured.status, 60),
        );
    }
    md += "\nEvery run's scene is `runs/<run>/scene.toml` (not written for a refused run), its stderr `runs/<run>/stderr.txt`; `study.csv` has the full outcomes, every error and the stage times.\n";
    write_atomic(path, md).map_err(|e| StudyError::Io {
        path: path.display().to_string(),
        message: e.to_string(),
    })
}
