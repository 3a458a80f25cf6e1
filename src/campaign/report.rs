//! Reporting a campaign: the runs' curves, the metrics of theory §9 (M1–M5),
//! the time-step convergence, `curves.csv`, `metrics.csv`, `report.md` and the
//! plots.

use crate::atomic_file::write_atomic;
use crate::csv_columns::{number, optional};
use std::fmt::Write as _;
use std::path::Path;

use super::footing::{corner_band_reach, soil_inside_outline};
use super::spec::Benchmark;
use super::{CampaignError, CampaignRun, CurveProblem};
use crate::metrics;
use crate::plot::{self, Bounds, Panel, Series};
use crate::scene::{MonitorKind, Scene};

/// The two `curve.csv` columns a run's load curve is read from, named by the
/// scene's monitors.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct CurveColumns {
    /// Abscissa: the displacement monitor (`rigid_displacement`, else
    /// `point_displacement`), m; plotted as δ = −value (positive downward).
    pub displacement: String,
    /// Ordinate: the force monitor (`rigid_force`, else `reaction`), kN/m.
    pub force: String,
}

impl CurveColumns {
    /// The load-curve columns of `scene`; `None` when it has no displacement
    /// monitor or no force monitor (the run then has no load curve).
    pub fn of_scene(scene: &Scene) -> Option<Self> {
        Some(Self {
            displacement: first_monitor_of(
                scene,
                &[
                    MonitorKind::RigidDisplacement,
                    MonitorKind::PointDisplacement,
                ],
            )?,
            force: first_monitor_of(scene, &[MonitorKind::RigidForce, MonitorKind::Reaction])?,
        })
    }
}

/// The `curve.csv` column of the scene's first monitor of the first kind in
/// `kinds` it has.
pub(super) fn first_monitor_of(scene: &Scene, kinds: &[MonitorKind]) -> Option<String> {
    kinds.iter().find_map(|kind| {
        scene
            .monitor
            .iter()
            .find(|m| m.kind == *kind)
            .map(|m| m.column())
    })
}

/// The load curve (δ, F) of a run's `curve.csv`: δ = −(displacement column),
/// F = force column. A run that stopped mid-way has the rows up to its last
/// step. A file that is missing, has no header, lacks a column or holds a row
/// that does not parse is refused.
pub(super) fn read_curve(
    path: &Path,
    columns: &CurveColumns,
) -> Result<Vec<(f64, f64)>, CampaignError> {
    let refuse = |problem| CampaignError::Curve {
        path: path.display().to_string(),
        problem,
    };
    let mut reader =
        csv::Reader::from_path(path).map_err(|e| refuse(CurveProblem::Missing(e.to_string())))?;
    let headers = match reader.headers() {
        Ok(headers) if !headers.is_empty() => headers.clone(),
        _ => return Err(refuse(CurveProblem::NoHeader)),
    };
    let column = |name: &str| {
        headers
            .iter()
            .position(|h| h == name)
            .ok_or_else(|| refuse(CurveProblem::MissingColumn(name.to_string())))
    };
    let (displacement, force) = (column(&columns.displacement)?, column(&columns.force)?);
    reader
        .records()
        .map(|record| {
            let record = record.map_err(|e| refuse(CurveProblem::BadRow(e.to_string())))?;
            let value = |index: usize| number_in(&record, index, &headers).map_err(refuse);
            Ok((-value(displacement)?, value(force)?))
        })
        .collect()
}

/// The number in column `index` of a curve row.
pub(super) fn number_in(
    record: &csv::StringRecord,
    index: usize,
    headers: &csv::StringRecord,
) -> Result<f64, CurveProblem> {
    let text = record.get(index).unwrap_or_default();
    text.parse().map_err(|_| CurveProblem::NotANumber {
        line: record.position().map_or(0, |p| p.line()),
        column: headers.get(index).unwrap_or_default().to_string(),
        value: text.to_string(),
    })
}

/// Last value of `column` of a CSV file.
pub(super) fn last_value(path: &Path, column: &str) -> Option<f64> {
    let mut reader = csv::Reader::from_path(path).ok()?;
    let column = reader.headers().ok()?.iter().position(|h| h == column)?;
    reader
        .records()
        .filter_map(|r| r.ok())
        .last()?
        .get(column)?
        .parse()
        .ok()
}

/// Time-step convergence of one scene: its curve against the curve of its
/// refinement (K times the steps), the more accurate one taken as reference.
#[derive(Clone, Debug)]
pub struct StepConvergence {
    /// Scene name.
    pub name: String,
    /// K.
    pub factor: usize,
    /// Post-peak discrepancy \[D42\] of the scene's curve against the refined one.
    pub discrepancy: Option<f64>,
    /// Relative L2 discrepancy over the whole curve, δ from 0 to the end (the
    /// D42 formula on [0, δ_end]).
    pub whole_curve_discrepancy: Option<f64>,
    /// Peak spread (M2) against the refined curve.
    pub peak_spread: Option<f64>,
    /// Load at the last step: as written, refined.
    pub final_loads: (f64, f64),
    /// Wall times, s: as written, refined.
    pub wall_seconds: (f64, f64),
}

/// Pair every refined run with its scene and compare their curves.
pub fn step_convergence(runs: &[CampaignRun]) -> Vec<StepConvergence> {
    runs.iter()
        .filter(|r| r.step_factor > 1)
        .filter_map(|refined| {
            let suffix = format!("_dt{}", refined.step_factor);
            let name = refined.name.strip_suffix(&suffix)?;
            let base = runs.iter().find(|r| r.step_factor == 1 && r.name == name)?;
            let end = base
                .curve
                .last()
                .map(|c| c.0)
                .unwrap_or(0.0)
                .min(refined.curve.last().map(|c| c.0).unwrap_or(0.0));
            Some(StepConvergence {
                name: name.to_string(),
                factor: refined.step_factor,
                discrepancy: metrics::post_peak_discrepancy(&base.curve, &refined.curve, end).ok(),
                whole_curve_discrepancy: metrics::curve_discrepancy(
                    &base.curve,
                    &refined.curve,
                    0.0,
                    end,
                )
                .ok(),
                peak_spread: metrics::peak_spread(&base.curve, &refined.curve).ok(),
                final_loads: (
                    base.curve.last().map(|c| c.1).unwrap_or(f64::NAN),
                    refined.curve.last().map(|c| c.1).unwrap_or(f64::NAN),
                ),
                wall_seconds: (base.wall_seconds, refined.wall_seconds),
            })
        })
        .collect()
}

/// `step_convergence.csv` and a section appended to `report.md`.
pub(super) fn write_step_convergence(
    out: &Path,
    runs: &[CampaignRun],
) -> Result<(), CampaignError> {
    let io = |p: &Path, e: &dyn std::fmt::Display| {
        CampaignError::Output(p.display().to_string(), e.to_string())
    };
    let rows = step_convergence(runs);
    let mut csv = String::from(
        "run,step_factor_1,M1_step_discrepancy_1,whole_curve_step_discrepancy_1,M2_step_peak_spread_1,final_load_kN_per_m,final_load_refined_kN_per_m,wall_s,wall_refined_s\n",
    );
    let mut md = String::from(
        "\n## Time-step convergence\n\nEach scene against the same scene with K times the steps at Δt / K (reference: the refined run). M1 and M2 as above.\n\n| run | K | M1 (step) | whole curve | M2 (step) | F_end | F_end (refined) | wall (s) | wall refined (s) |\n|---|---|---|---|---|---|---|---|---|\n",
    );
    for r in &rows {
        let fields = [
            r.factor.to_string(),
            optional(r.discrepancy),
            optional(r.whole_curve_discrepancy),
            optional(r.peak_spread),
            number(r.final_loads.0),
            number(r.final_loads.1),
            number(r.wall_seconds.0),
            number(r.wall_seconds.1),
        ];
        let _ = writeln!(csv, "{},{}", r.name, fields.join(","));
        let _ = writeln!(
            md,
            "| {} | {} | {} | {} | {} | {:.3} | {:.3} | {:.1} | {:.1} |",
            r.name,
            r.factor,
            fmt_opt(r.discrepancy, 1.0, 4),
            fmt_sci(r.whole_curve_discrepancy),
            fmt_opt(r.peak_spread, 1.0, 4),
            r.final_loads.0,
            r.final_loads.1,
            r.wall_seconds.0,
            r.wall_seconds.1
        );
    }
    let path = out.join("step_convergence.csv");
    write_atomic(&path, csv).map_err(|e| io(&path, &e))?;
    let report = out.join("report.md");
    let mut text = std::fs::read_to_string(&report).map_err(|e| io(&report, &e))?;
    text.push_str(&md);
    write_atomic(&report, text).map_err(|e| io(&report, &e))?;
    Ok(())
}

/// Per-run metrics of theory §9 against the family reference.
#[derive(Clone, Debug, Default)]
pub struct RunMetrics {
    /// Initial slope dF/dδ, least-squares fit over the benchmark's elastic
    /// window ([`Benchmark::slope_window`]; biaxial δ ∈ [0.1, 0.5] mm, after
    /// the start-up transient of dynamic runs), kN/m per m.
    pub initial_slope: f64,
    /// Peak load and its δ.
    pub peak: (f64, f64),
    /// Load at the last δ reached.
    pub final_load: f64,
    /// M1 post-peak discrepancy e_h against the family reference.
    pub discrepancy: Option<f64>,
    /// M2 peak spread.
    pub peak_spread: Option<f64>,
    /// M3 brittleness.
    pub brittleness: Option<f64>,
    /// M3 drop length: δ from the peak to where the load first halves after
    /// it (`None`: it never halves).
    pub half_peak_drop: Option<f64>,
    /// M4 band width, m.
    pub band_width: Option<f64>,
    /// M4 applied to the nonlocal variable κ̄ instead of εq (nonlocal runs), m:
    /// the width of the regularised softening zone (the εq band lies inside it).
    pub band_width_kappa_bar: Option<f64>,
    /// External work W = ∫F dδ, kJ/m.
    pub external_work: Option<f64>,
    /// Footing: soil area (undeformed) inside the footing's outline above
    /// its base at the last δ, m² per m ([`soil_inside_outline`]; `None`
    /// for a record without the points' undeformed volumes).
    pub soil_inside_footing: Option<f64>,
    /// Footing: depth (in B below the base) that the deviatoric strain
    /// reaches under the left and the right corner ([`corner_band_reach`]).
    pub corner_band: Option<[f64; 2]>,
}

/// Metrics of every run (reference: the finest completed mesh of its family).
pub fn compute_metrics(runs: &[CampaignRun], benchmark: Benchmark) -> Vec<RunMetrics> {
    runs.iter()
        .map(|run| {
            let delta_end = run.curve.last().map(|c| c.0).unwrap_or(0.0);
            let (from, to) = benchmark.slope_window(delta_end);
            let mut m = RunMetrics {
                initial_slope: fitted_slope(&run.curve, from, to),
                ..Default::default()
            };
            if let (Some(footing), false) = (&run.footing, run.positions.is_empty()) {
                m.soil_inside_footing =
                    (run.initial_volumes.len() == run.positions.len()).then(|| {
                        soil_inside_outline(
                            footing,
                            delta_end,
                            &run.positions,
                            &run.initial_volumes,
                        )
                    });
                m.corner_band = Some(corner_band_reach(
                    footing,
                    delta_end,
                    &run.positions,
                    &run.eps_q,
                ));
            }
            if let Ok((d, f)) = metrics::peak(&run.curve) {
                m.peak = (d, f);
            }
            m.final_load = run.curve.last().map(|c| c.1).unwrap_or(f64::NAN);
            let reference = runs
                .iter()
                .filter(|r| r.same_family(run) && r.error.is_none())
                .min_by(|a, b| a.cell_size.total_cmp(&b.cell_size));
            if let Some(reference) = reference {
                let end = delta_end.min(reference.curve.last().map(|c| c.0).unwrap_or(0.0));
                m.discrepancy =
                    metrics::post_peak_discrepancy(&run.curve, &reference.curve, end).ok();
                m.peak_spread = metrics::peak_spread(&run.curve, &reference.curve).ok();
            }
            m.brittleness = metrics::brittleness(&run.curve, delta_end).ok();
            m.half_peak_drop = metrics::half_peak_drop(&run.curve).ok().flatten();
            if !run.positions.is_empty() && benchmark.has_one_band() {
                let eps_q = metrics::clip_outliers(&run.eps_q, 0.99);
                m.band_width = metrics::shear_band_width(
                    &run.positions,
                    &eps_q,
                    run.cell_size,
                    run.length_scale.unwrap_or(0.0),
                )
                .ok()
                .map(|b| b.width);
            }
            if let (false, Some(l_s), true) = (
                run.kappa_bar.is_empty(),
                run.length_scale,
                benchmark.has_one_band(),
            ) {
                m.band_width_kappa_bar =
                    metrics::shear_band_width(&run.positions, &run.kappa_bar, run.cell_size, l_s)
                        .ok()
                        .map(|b| b.width);
            }
            m.external_work = metrics::external_work(&run.curve).ok();
            m
        })
        .collect()
}

/// The footing's report section: soil inside the footing's outline and the
/// reach of the corner bands per run.
fn footing_section(runs: &[CampaignRun], m: &[RunMetrics]) -> String {
    use super::footing::{CORNER_BAND_STRAIN, CORNER_STRIP_HALF_WIDTH};
    let mut md = format!(
        "\n## Footing: soil over the base and the corner band\n\nSoil inside the outline = undeformed area (Σ m_p/ρ) of the soil inside the footing's footprint above its base at the last δ (the paper's 3 m footing is not modelled, so nothing keeps heaving soil out of it; – for a record without the points' undeformed volumes). Corner-band reach = depth below the base, in units of B, of the deepest point with εq ≥ {} in a vertical strip {:.2} B wide under each footing corner: the Prandtl mechanism alone reaches about 1.1 B there (its outer log-spiral); the paper's \"secondary vertical band below the footing corner\" reaches deeper.\n\n| run | soil inside outline (m²/m) | corner-band reach left (B) | corner-band reach right (B) |\n|---|---|---|---|\n",
        CORNER_BAND_STRAIN,
        2.0 * CORNER_STRIP_HALF_WIDTH,
    );
    for (r, mm) in runs.iter().zip(m) {
        let _ = writeln!(
            md,
            "| {} | {} | {} | {} |",
            r.name,
            fmt_opt(mm.soil_inside_footing, 1.0, 4),
            fmt_opt(mm.corner_band.map(|c| c[0]), 1.0, 3),
            fmt_opt(mm.corner_band.map(|c| c[1]), 1.0, 3),
        );
    }
    md
}

/// Least-squares slope of the curve points with δ in [from, to] (NaN if < 2 points).
fn fitted_slope(curve: &[(f64, f64)], from: f64, to: f64) -> f64 {
    let pts: Vec<&(f64, f64)> = curve
        .iter()
        .filter(|(d, _)| *d >= from && *d <= to)
        .collect();
    let n = pts.len() as f64;
    if pts.len() < 2 {
        return f64::NAN;
    }
    let (mx, my) = (
        pts.iter().map(|p| p.0).sum::<f64>() / n,
        pts.iter().map(|p| p.1).sum::<f64>() / n,
    );
    let sxy: f64 = pts.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
    let sxx: f64 = pts.iter().map(|p| (p.0 - mx).powi(2)).sum();
    sxy / sxx
}

fn fmt_sci(v: Option<f64>) -> String {
    v.map(|x| format!("{x:.3e}")).unwrap_or_else(|| "–".into())
}

pub(super) fn fmt_opt(v: Option<f64>, scale: f64, digits: usize) -> String {
    v.map(|x| format!("{:.*}", digits, x * scale))
        .unwrap_or_else(|| "–".into())
}

/// Report lines for the runs that lost points off the grid.
pub(super) fn lost_points_notes(runs: &[CampaignRun]) -> String {
    let mut md = String::new();
    for r in runs.iter().filter(|r| r.lost_points.0 > 0) {
        let _ = writeln!(
            md,
            "\n- {}: {} material point(s) left the grid and were removed ({:.2e} of the mass; run.json lists them)",
            r.name, r.lost_points.0, r.lost_points.1
        );
    }
    md
}

/// Report lines for the runs that stopped early, with their errors.
pub(super) fn stopped_notes(runs: &[CampaignRun]) -> String {
    let mut md = String::new();
    for r in runs.iter().filter(|r| r.error.is_some()) {
        let _ = writeln!(
            md,
            "\n- {} stopped: {}",
            r.name,
            r.error.as_deref().unwrap_or_default()
        );
    }
    md
}

/// The report section with every run's stage profile (wall time by stage).
pub(super) fn profiles_section(runs: &[CampaignRun]) -> String {
    let mut md = String::from(
        "\n## Stage profiles\n\nThe scheme of every run and its wall time by stage (exclusive).\n\n",
    );
    for r in runs {
        let (name, scheme, profile) = (&r.name, &r.scheme, r.profile.trim_end());
        let _ = writeln!(md, "### {name}\n\n{scheme}\n\n```\n{profile}\n```\n");
    }
    md
}

/// Header of a load-curve campaign's `metrics.csv`.
const METRICS_HEADER: &str = "run,family,cell_size_m,length_scale_m,status,wall_s,initial_slope_kN_per_m2,peak_delta_m,peak_load_kN_per_m,final_load_kN_per_m,M1_discrepancy_1,M2_peak_spread_1,M3_brittleness_1,M3_half_peak_drop_m,M4_band_width_m,M4_band_width_kappa_bar_m,load_curve_work_kJ_per_m,M5_dissipation_kJ_per_m,external_work_kJ_per_m,internal_work_kJ_per_m,kinetic_energy_kJ_per_m,energy_loss_1,soil_inside_footing_m2_per_m,corner_band_reach_left_1,corner_band_reach_right_1\n";

/// The fields of `metrics.csv` after `run` and `family`.
fn metrics_fields(r: &CampaignRun, mm: &RunMetrics, status: &str) -> Vec<String> {
    vec![
        number(r.cell_size),
        optional(r.length_scale),
        status.to_string(),
        number(r.wall_seconds),
        number(mm.initial_slope),
        number(mm.peak.0),
        number(mm.peak.1),
        number(mm.final_load),
        optional(mm.discrepancy),
        optional(mm.peak_spread),
        optional(mm.brittleness),
        optional(mm.half_peak_drop),
        optional(mm.band_width),
        optional(mm.band_width_kappa_bar),
        optional(mm.external_work),
        optional(r.dissipation),
        optional(r.energy.map(|e| e.external)),
        optional(r.energy.map(|e| e.internal)),
        optional(r.energy.map(|e| e.kinetic)),
        optional(r.energy.map(|e| e.relative_loss())),
        optional(mm.soil_inside_footing),
        optional(mm.corner_band.map(|c| c[0])),
        optional(mm.corner_band.map(|c| c[1])),
    ]
}

/// Write `curves.csv`, `metrics.csv`, `report.md` and the figures of a
/// load-curve campaign (biaxial, footing) into `out`.
pub(super) fn write_outputs(
    out: &Path,
    runs: &[CampaignRun],
    benchmark: Benchmark,
    window: Bounds,
) -> Result<(), CampaignError> {
    std::fs::create_dir_all(out).map_err(|e| output_error(out, &e))?;
    write_combined_curves(out, runs)?;
    let m = compute_metrics(runs, benchmark);
    let (csv, md) = metrics_and_report(runs, &m, benchmark);
    let metrics_path = out.join("metrics.csv");
    write_atomic(&metrics_path, csv).map_err(|e| output_error(&metrics_path, &e))?;
    let report = out.join("report.md");
    write_atomic(&report, md).map_err(|e| output_error(&report, &e))?;
    plot_load_curves(out, runs, benchmark)?;
    plot_strain_fields(out, runs, benchmark, window)
}

/// The campaign's output error for `p`.
fn output_error(p: &Path, e: &dyn std::fmt::Display) -> CampaignError {
    CampaignError::Output(p.display().to_string(), e.to_string())
}

/// The runs' family: `nonlocal` with a length scale, else `local`.
fn family(r: &CampaignRun) -> &'static str {
    if r.length_scale.is_some() {
        "nonlocal"
    } else {
        "local"
    }
}

/// `curves.csv`: every run's load curve, one row a step.
fn write_combined_curves(out: &Path, runs: &[CampaignRun]) -> Result<(), CampaignError> {
    let combined = out.join("curves.csv");
    let mut text = String::from("run,family,cell_size_m,step_1,delta_m,load_kN_per_m\n");
    for r in runs {
        let family = family(r);
        for (step, (d, f)) in r.curve.iter().enumerate() {
            let _ = writeln!(
                text,
                "{},{family},{},{step},{},{}",
                r.name,
                number(r.cell_size),
                number(*d),
                number(*f)
            );
        }
    }
    write_atomic(&combined, text).map_err(|e| output_error(&combined, &e))
}

/// The text of `metrics.csv` (one row a run) and of `report.md` (the metrics
/// table of theory §9 and the sections and notes after it).
fn metrics_and_report(
    runs: &[CampaignRun],
    m: &[RunMetrics],
    benchmark: Benchmark,
) -> (String, String) {
    let (unit, scale) = benchmark.length_unit();
    let mut csv = String::from(METRICS_HEADER);
    let mut md = format!("# Mesh-objectivity report\n\nReference of each family: its finest completed mesh (theory §9). h and δ in {unit}, loads in kN/m, band width w (M4 on εq) and w_κ̄ (M4 on the nonlocal variable κ̄) in {unit}{}; Δδ_½ the travel from the peak to where the load first falls to half of it (– where it stays above).\n\n| run | h ({unit}) | status | wall (s) | slope (kN/m/m) | peak F | δ_peak | F_end | β (M3) | Δδ_½ (M3) | M1 e_h | M2 | w ({unit}) | w/l_s | w_κ̄ ({unit}) | D (kJ/m, M5) |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n", if benchmark.has_one_band() {
        ""
    } else {
        " (not measured here: at the last δ the mechanism has collapsed and no single band crosses it, theory §9)"
    });
    for (r, mm) in runs.iter().zip(m) {
        let family = family(r);
        let status = if r.error.is_some() {
            "stopped"
        } else {
            "completed"
        };
        let _ = writeln!(
            csv,
            "{},{family},{}",
            r.name,
            metrics_fields(r, mm, status).join(",")
        );
        let ratio = match (mm.band_width, r.length_scale) {
            (Some(w), Some(l)) => format!("{:.2}", w / l),
            _ => "–".into(),
        };
        let _ = writeln!(
            md,
            "| {} | {:.3} | {status} | {:.1} | {:.0} | {:.3} | {:.3} | {:.3} | {} | {} | {} | {} | {} | {ratio} | {} | {} |",
            r.name,
            r.cell_size * scale,
            r.wall_seconds,
            mm.initial_slope,
            mm.peak.1,
            mm.peak.0 * scale,
            mm.final_load,
            fmt_opt(mm.brittleness, 1.0, 3),
            fmt_opt(mm.half_peak_drop, scale, 3),
            fmt_opt(mm.discrepancy, 1.0, 4),
            fmt_opt(mm.peak_spread, 1.0, 4),
            fmt_opt(mm.band_width, scale, 3),
            fmt_opt(mm.band_width_kappa_bar, scale, 3),
            fmt_opt(r.dissipation, 1.0, 4),
        );
    }
    if m.iter().any(|mm| mm.corner_band.is_some()) {
        md.push_str(&footing_section(runs, m));
    }
    md.push_str(&energy_balance_section(runs));
    md.push_str(&lost_points_notes(runs));
    md.push_str(&no_curve_notes(runs));
    md.push_str(&stopped_notes(runs));
    md.push_str(&profiles_section(runs));
    (csv, md)
}

/// The report's energy balance table (M5), at the last step of each run
/// that has one; empty when no run has.
fn energy_balance_section(runs: &[CampaignRun]) -> String {
    let mut md = String::new();
    if runs.iter().any(|r| r.energy.is_some()) {
        md.push_str("\n## Energy balance (M5)\n\nAt the last step, kJ/m: W work of the loads on the soil (pressures, rigid bodies, gravity), W_int work of the stresses on the strain increments (elastic energy stored + dissipation D), K kinetic energy, B kinetic energy removed at the fixed dofs (monitor `boundary_work`, explicit runs; 0 without it). The loss (W − W_int − K − B)/W is the energy the time integration removed (Newmark γ > ½ damping a dynamic snap, MUSL's velocity remap; about 2e-5 in an elastic biaxial run and 5e-3 in an elastic explicit cut, tests/energy_balance.rs); a negative loss is energy the run created.\n\n| run | W | W_int | D | K | B | loss |\n|---|---|---|---|---|---|---|\n");
        for r in runs {
            if let Some(e) = r.energy {
                let _ = writeln!(
                    md,
                    "| {} | {:.5} | {:.5} | {} | {:.2e} | {:.2e} | {:.2} % |",
                    r.name,
                    e.external,
                    e.internal,
                    fmt_opt(r.dissipation, 1.0, 5),
                    e.kinetic,
                    e.boundary,
                    100.0 * e.relative_loss()
                );
            }
        }
    }
    md
}

/// The report's notes on the runs without a load curve.
fn no_curve_notes(runs: &[CampaignRun]) -> String {
    let mut md = String::new();
    for r in runs.iter().filter(|r| r.curve_columns.is_none()) {
        let _ = writeln!(
            md,
            "\n- {}: no load curve (the scene needs a `rigid_force` or `reaction` monitor and a `rigid_displacement` or `point_displacement` monitor)",
            r.name
        );
    }
    md
}

/// `curves.png`: the load curves, one colour per cell size (local dashed,
/// nonlocal solid), coarse to fine.
fn plot_load_curves(
    out: &Path,
    runs: &[CampaignRun],
    benchmark: Benchmark,
) -> Result<(), CampaignError> {
    let (unit, scale) = benchmark.length_unit();
    let mut sizes: Vec<f64> = runs.iter().map(|r| r.cell_size).collect();
    sizes.sort_by(|a, b| b.total_cmp(a));
    sizes.dedup();
    let mut ordered: Vec<&CampaignRun> = runs.iter().filter(|r| r.curve.len() > 1).collect();
    ordered.sort_by(|a, b| {
        (a.length_scale.is_some(), -a.cell_size)
            .partial_cmp(&(b.length_scale.is_some(), -b.cell_size))
            .unwrap_or(std::cmp::Ordering::Equal)
    });
    let series: Vec<Series> = ordered
        .iter()
        .map(|r| Series {
            name: format!("{} h={:.3} {unit}", r.regularisation(), r.cell_size * scale),
            points: r.curve.iter().map(|(d, f)| (d * scale, *f)).collect(),
            dashed: r.length_scale.is_none(),
            color: sizes.iter().position(|&h| h == r.cell_size).unwrap_or(0),
            marker: Some(plot::Marker::of_regularisation(r.length_scale.is_some())),
        })
        .collect();
    if !series.is_empty() {
        let path = out.join("curves.png");
        plot::plot_curves(
            &path,
            "Load vs displacement (dashed: local, solid: nonlocal)",
            &format!("δ ({unit})"),
            "F (kN/m)",
            &series,
        )
        .map_err(|e| output_error(&path, &e))?;
    }
    Ok(())
}

/// `fields_local.png` and `fields_nonlocal.png`: the deviatoric strain εq at
/// the last step, one panel per run of the family, coarse to fine.
fn plot_strain_fields(
    out: &Path,
    runs: &[CampaignRun],
    benchmark: Benchmark,
    window: Bounds,
) -> Result<(), CampaignError> {
    let (unit, scale) = benchmark.length_unit();
    for (family, nonlocal) in [("local", false), ("nonlocal", true)] {
        let members: Vec<&CampaignRun> = runs
            .iter()
            .filter(|r| r.length_scale.is_some() == nonlocal && !r.positions.is_empty())
            .collect();
        let mut members = members;
        members.sort_by(|a, b| b.cell_size.total_cmp(&a.cell_size));
        if members.is_empty() {
            continue;
        }
        let panels: Vec<Panel> = members
            .iter()
            .map(|r| Panel {
                title: format!("h = {:.3} {unit}", r.cell_size * scale),
                positions: &r.positions,
                values: &r.eps_q,
                bounds: window,
                volumes: (r.volumes.len() == r.positions.len()).then_some(&r.volumes[..]),
                marker: Some(0.6 * r.cell_size),
            })
            .collect();
        let path = out.join(format!("fields_{family}.png"));
        plot::plot_field_panels(
            &path,
            &format!("Deviatoric strain εq at the last step ({family})"),
            &panels,
            None,
            "εq (1)",
        )
        .map_err(|e| output_error(&path, &e))?;
    }
    Ok(())
}
