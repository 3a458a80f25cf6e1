//! Time-history campaigns (the vertical cut, paper Figs. 10–12, theory §8.3
//! and §9 M1, M6): u_A(t), q_B(t) and the run-out read from each run's
//! `curve.csv`, their metrics per run, the implicit/explicit comparison, and
//! the combined CSVs, report and figures.

use std::fmt::Write as _;
use std::path::Path;

use super::report::{fmt_opt, lost_points_notes, number_in, profiles_section, stopped_notes};
use super::{CampaignError, CampaignRun, CurveProblem};
use crate::csv_columns::{number, optional};
use crate::metrics;
use crate::output::TIME_COLUMN;
use crate::plot::{self, Bounds, Panel, Series};
use crate::scene::{MonitorKind, Scene, StressQuantity, VectorComponent};

/// |u_A| that marks the collapse onset, m (issue 12: first time |u_A| > 5 cm).
pub const ONSET_DISPLACEMENT: f64 = 0.05;

/// Time at which implicit and explicit |u_A| are compared, s (issue 12 check 4).
pub const COMPARISON_TIME: f64 = 0.3;

/// Reversals of q_B are counted with a hysteresis of this fraction of its peak.
pub const REVERSAL_THRESHOLD: f64 = 0.02;

/// The failure phase of q_B: its peak is sought up to 0.05 s after the onset
/// and its fall judged up to [`FALL_WINDOW`] after the onset. Later, B is
/// carried in the run-out flow under up to 60 g and q_B follows the debris
/// over it, not the band (measured at h = 0.1 m: the local and nonlocal q_B
/// both peak at ~270–280 kPa within 5 ms of the onset).
pub const PEAK_WINDOW: f64 = 0.05;

/// End of the failure phase after the onset, s (see [`PEAK_WINDOW`]).
pub const FALL_WINDOW: f64 = 0.1;

/// The failure-phase figure of q_B runs from this long before each run's
/// onset, s.
const FAILURE_LEAD: f64 = 0.02;

/// ... to this long after it, s (the failure window of issue 40, item 3).
const FAILURE_PLOT: f64 = 0.15;

/// The `curve.csv` columns of a time-history run, those of the scene's monitors.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct HistoryColumns {
    /// |u| of the monitored point A (`point_displacement`, `component = "norm"`).
    pub displacement: String,
    /// q at the monitored point B (`point_stress`, `quantity = "q"`).
    pub stress: Option<String>,
    /// q of the points around B (`neighbourhood_stress`, `quantity = "q"`).
    pub neighbourhood_stress: Option<String>,
    /// Run-out front (`run_out`).
    pub run_out: Option<String>,
    /// The energy budget's W, W_int, K, B and R (theory E1), when the scene
    /// monitors all five.
    pub budget: Option<[String; 5]>,
}

/// The monitors of the energy budget, in the order of [`HistoryColumns::budget`].
const BUDGET_KINDS: [MonitorKind; 5] = [
    MonitorKind::ExternalWork,
    MonitorKind::InternalWork,
    MonitorKind::KineticEnergy,
    MonitorKind::BoundaryWork,
    MonitorKind::EnergyRemainder,
];

impl HistoryColumns {
    /// The columns of `scene`; `None` without a `point_displacement` norm monitor.
    pub fn of_scene(scene: &Scene) -> Option<Self> {
        let find = |pred: &dyn Fn(&crate::scene::MonitorSpec) -> bool| {
            scene.monitor.iter().find(|m| pred(m)).map(|m| m.column())
        };
        Some(Self {
            displacement: find(&|m| {
                m.kind == MonitorKind::PointDisplacement
                    && m.component == Some(VectorComponent::Norm)
            })?,
            stress: find(&|m| {
                m.kind == MonitorKind::PointStress && m.quantity == Some(StressQuantity::Q)
            }),
            neighbourhood_stress: find(&|m| {
                m.kind == MonitorKind::NeighbourhoodStress && m.quantity == Some(StressQuantity::Q)
            }),
            run_out: find(&|m| m.kind == MonitorKind::RunOut),
            budget: BUDGET_KINDS
                .iter()
                .map(|&kind| find(&|m| m.kind == kind))
                .collect::<Option<Vec<_>>>()
                .and_then(|names| names.try_into().ok()),
        })
    }
}

/// The time histories of one run (one entry per `curve.csv` row).
#[derive(Clone, Debug, Default)]
pub struct History {
    /// (t, |u_A|), m.
    pub displacement: Vec<(f64, f64)>,
    /// (t, q_B), kPa (empty without the monitor).
    pub stress: Vec<(f64, f64)>,
    /// (t, q) of the points around B, kPa (empty without the monitor).
    pub neighbourhood_stress: Vec<(f64, f64)>,
    /// (t, x_front), m (empty without the monitor).
    pub run_out: Vec<(f64, f64)>,
    /// (t, [W, W_int, K, B, R]), kJ/m (empty without the monitors).
    pub budget: Vec<(f64, [f64; 5])>,
    /// (t, R/W): the budget's remainder as a share of the work put in, from
    /// the first row where W reaches 1 % (`SHARE_FROM`) of its largest value (a
    /// ratio of round-offs before).
    pub remainder_share: Vec<(f64, f64)>,
}

impl History {
    /// Read the histories of a run's `curve.csv`.
    pub fn read(path: &Path, columns: &HistoryColumns) -> Result<Self, CampaignError> {
        let refuse = |problem| CampaignError::Curve {
            path: path.display().to_string(),
            problem,
        };
        let mut reader = csv::Reader::from_path(path)
            .map_err(|e| refuse(CurveProblem::Missing(e.to_string())))?;
        let headers = match reader.headers() {
            Ok(h) if !h.is_empty() => h.clone(),
            _ => return Err(refuse(CurveProblem::NoHeader)),
        };
        let column = |name: &str| {
            headers
                .iter()
                .position(|h| h == name)
                .ok_or_else(|| refuse(CurveProblem::MissingColumn(name.to_string())))
        };
        let time = column(TIME_COLUMN)?;
        let displacement = column(&columns.displacement)?;
        let stress = columns.stress.as_deref().map(column).transpose()?;
        let run_out = columns.run_out.as_deref().map(column).transpose()?;
        let group = columns
            .neighbourhood_stress
            .as_deref()
            .map(column)
            .transpose()?;
        let budget = match &columns.budget {
            Some(names) => {
                let mut places = [0; 5];
                for (place, name) in places.iter_mut().zip(names) {
                    *place = column(name)?;
                }
                Some(places)
            }
            None => None,
        };
        let mut history = History::default();
        for record in reader.records() {
            let record = record.map_err(|e| refuse(CurveProblem::BadRow(e.to_string())))?;
            let value = |i: usize| number_in(&record, i, &headers).map_err(refuse);
            let t = value(time)?;
            history.displacement.push((t, value(displacement)?));
            if let Some(i) = stress {
                history.stress.push((t, value(i)?));
            }
            if let Some(i) = run_out {
                history.run_out.push((t, value(i)?));
            }
            if let Some(i) = group {
                history.neighbourhood_stress.push((t, value(i)?));
            }
            if let Some(places) = budget {
                let mut terms = [0.0; 5];
                for (term, i) in terms.iter_mut().zip(places) {
                    *term = value(i)?;
                }
                history.budget.push((t, terms));
            }
        }
        history.remainder_share = remainder_share(&history.budget);
        Ok(history)
    }

    /// Time of the last row, s.
    pub fn end_time(&self) -> f64 {
        self.displacement.last().map_or(0.0, |p| p.0)
    }
}

/// R/W is followed from where W reaches this share of its largest value.
pub const SHARE_FROM: f64 = 0.01;

/// (t, R/W) of a budget history (see [`History::remainder_share`]).
pub(crate) fn remainder_share(budget: &[(f64, [f64; 5])]) -> Vec<(f64, f64)> {
    let largest = budget.iter().map(|(_, b)| b[0].abs()).fold(0.0, f64::max);
    budget
        .iter()
        .skip_while(|(_, b)| b[0].abs() < SHARE_FROM * largest || b[0] == 0.0)
        .map(|&(t, b)| (t, b[4] / b[0]))
        .collect()
}

/// The metrics of one time-history run (theory §9 M1 and M6, issue 12).
#[derive(Clone, Debug, Default)]
pub struct HistoryMetrics {
    /// First time |u_A| > `ONSET_DISPLACEMENT`, s.
    pub onset: Option<f64>,
    /// |u_A| at `COMPARISON_TIME`, m.
    pub displacement_at_comparison: Option<f64>,
    /// |u_A| at the end, m.
    pub final_displacement: f64,
    /// Run-out front at the end, m.
    pub final_run_out: Option<f64>,
    /// Peak q_B of the failure phase (kPa, up to `PEAK_WINDOW` after the
    /// onset) and its time (s).
    pub stress_peak: Option<(f64, f64)>,
    /// Total variation of q_B from that peak to `FALL_WINDOW` after the
    /// onset over its net drop (1: monotone fall).
    pub stress_roughness: Option<f64>,
    /// The fall roughness of the neighbourhood reading of q_B
    /// (`neighbourhood_stress`, the points that started within one cell of
    /// B), over the same window.
    pub neighbourhood_roughness: Option<f64>,
    /// Reversals of q_B after the onset, with a hysteresis of
    /// `REVERSAL_THRESHOLD` q_peak (M6 noise index).
    pub stress_reversals: Option<usize>,
    /// M1 \[D42\] of u_A(t) on [0, t_end] against the family reference.
    pub discrepancy: Option<f64>,
    /// The budget's remainder R/W at the end (theory E1).
    pub final_remainder_share: Option<f64>,
}

/// The failure phase of a q_B reading `stress` after the onset `t0`: its
/// peak (q, t) up to `PEAK_WINDOW` (0.05 s) after the onset and the fall
/// roughness from the peak to `FALL_WINDOW` (0.1 s) after the onset; `None`
/// without a peak.
pub fn failure_fall(stress: &[(f64, f64)], t0: f64) -> Option<((f64, f64), Option<f64>)> {
    let until =
        |end: f64| -> Vec<(f64, f64)> { stress.iter().copied().filter(|p| p.0 <= end).collect() };
    let (t, q) = metrics::peak(&until(t0 + PEAK_WINDOW)).ok()?;
    let fall: Vec<(f64, f64)> = until(t0 + FALL_WINDOW)
        .into_iter()
        .filter(|p| p.0 >= t)
        .collect();
    Some(((q, t), metrics::fall_roughness(&fall).ok()))
}

/// Metrics of every run; the reference of a run is the finest completed
/// mesh of its family (regularisation and integrator).
pub fn compute_history_metrics(runs: &[CampaignRun]) -> Vec<HistoryMetrics> {
    runs.iter()
        .map(|run| {
            let Some(h) = &run.history else {
                return HistoryMetrics::default();
            };
            let u = &h.displacement;
            let mut m = HistoryMetrics {
                onset: metrics::first_exceedance(u, ONSET_DISPLACEMENT),
                displacement_at_comparison: metrics::interpolate(u, COMPARISON_TIME).ok(),
                final_displacement: u.last().map_or(f64::NAN, |p| p.1),
                final_run_out: h.run_out.last().map(|p| p.1),
                final_remainder_share: h.remainder_share.last().map(|p| p.1),
                ..Default::default()
            };
            if let Some(t0) = m.onset {
                if let Some((peak, roughness)) = failure_fall(&h.stress, t0) {
                    m.stress_peak = Some(peak);
                    m.stress_roughness = roughness;
                    let threshold = REVERSAL_THRESHOLD * peak.0;
                    m.stress_reversals = Some(metrics::reversals(&h.stress, t0, threshold));
                }
                m.neighbourhood_roughness =
                    failure_fall(&h.neighbourhood_stress, t0).and_then(|(_, roughness)| roughness);
            }
            let reference = runs
                .iter()
                .filter(|r| r.same_family(run) && r.error.is_none() && r.history.is_some())
                .min_by(|a, b| a.cell_size.total_cmp(&b.cell_size));
            if let Some(Some(reference)) = reference.map(|r| r.history.as_ref()) {
                let end = h.end_time().min(reference.end_time());
                m.discrepancy =
                    metrics::curve_discrepancy(u, &reference.displacement, 0.0, end).ok();
            }
            m
        })
        .collect()
}

/// The implicit run of a scene beside its explicit twin.
struct IntegratorPair<'a> {
    implicit: (&'a CampaignRun, &'a HistoryMetrics),
    explicit: (&'a CampaignRun, &'a HistoryMetrics),
}

impl IntegratorPair<'_> {
    /// Onset time, explicit − implicit, s.
    fn onset_difference(&self) -> Option<f64> {
        let (i, e) = (self.implicit.1, self.explicit.1);
        i.onset.zip(e.onset).map(|(a, b)| b - a)
    }

    /// |u_A| at [`COMPARISON_TIME`], explicit relative to implicit, − 1.
    fn displacement_difference(&self) -> Option<f64> {
        let (i, e) = (self.implicit.1, self.explicit.1);
        i.displacement_at_comparison
            .zip(e.displacement_at_comparison)
            .map(|(a, b)| (b - a) / a)
    }

    /// |u_A| at the end, explicit relative to implicit, − 1.
    fn final_displacement_difference(&self) -> f64 {
        let (i, e) = (self.implicit.1, self.explicit.1);
        (e.final_displacement - i.final_displacement) / i.final_displacement
    }

    /// M1 \[D42\] of the explicit u_A(t) against the implicit one on [0, t_end].
    fn discrepancy(&self) -> Option<f64> {
        let (a, b) = (
            self.implicit.0.history.as_ref()?,
            self.explicit.0.history.as_ref()?,
        );
        let end = a.end_time().min(b.end_time());
        metrics::curve_discrepancy(&b.displacement, &a.displacement, 0.0, end).ok()
    }
}

fn integrator_pairs<'a>(
    runs: &'a [CampaignRun],
    m: &'a [HistoryMetrics],
) -> Vec<IntegratorPair<'a>> {
    let explicit = |r: &CampaignRun| r.integrator() == "explicit";
    runs.iter()
        .zip(m)
        .filter(|(r, _)| !explicit(r))
        .filter_map(|implicit| {
            let twin = runs
                .iter()
                .zip(m)
                .find(|(r, _)| explicit(r) && r.scene == implicit.0.scene)?;
            Some(IntegratorPair {
                implicit,
                explicit: twin,
            })
        })
        .collect()
}

/// Write `histories.csv`, `metrics.csv`, `integrators.csv`, `report.md` and
/// the figures of a time-history campaign into `out`.
pub(super) fn write_history_outputs(
    out: &Path,
    runs: &[CampaignRun],
    window: Bounds,
) -> Result<(), CampaignError> {
    let io = |p: &Path, e: &dyn std::fmt::Display| {
        CampaignError::Output(p.display().to_string(), e.to_string())
    };
    std::fs::create_dir_all(out).map_err(|e| io(out, &e))?;
    let m = compute_history_metrics(runs);
    let write = |name: &str, text: String| {
        let path = out.join(name);
        crate::atomic_file::write_atomic(&path, text).map_err(|e| io(&path, &e))
    };
    write("histories.csv", histories_csv(runs))?;
    write("metrics.csv", metrics_csv(runs, &m))?;
    let pairs = integrator_pairs(runs, &m);
    write("integrators.csv", integrators_csv(&pairs))?;
    write("report.md", report_md(runs, &m, &pairs))?;
    plot_histories(out, runs).map_err(|e| io(out, &e))?;
    plot_snapshots(out, runs, window).map_err(|e| io(out, &e))?;
    Ok(())
}

/// Header of `histories.csv`: the run's identifiers, then t and the
/// monitored histories.
const HISTORIES_HEADER: &str = "run,scene,family,integrator,cell_size_m,time_s,uA_m,qB_kPa,qB_neighbourhood_kPa,run_out_m,external_work_kJ_per_m,internal_work_kJ_per_m,kinetic_energy_kJ_per_m,boundary_work_kJ_per_m,energy_remainder_kJ_per_m\n";

/// The value of row `i` of a history, an empty field past its end.
fn history_field(history: &[(f64, f64)], i: usize) -> String {
    optional(history.get(i).map(|p| p.1))
}

fn histories_csv(runs: &[CampaignRun]) -> String {
    let mut text = String::from(HISTORIES_HEADER);
    for r in runs {
        let Some(h) = &r.history else { continue };
        for (i, (t, u)) in h.displacement.iter().enumerate() {
            let budget = match h.budget.get(i) {
                Some((_, terms)) => terms.map(number).join(","),
                None => ",,,,".to_string(),
            };
            let _ = writeln!(
                text,
                "{},{},{},{},{},{},{},{},{},{},{budget}",
                r.name,
                r.scene,
                r.regularisation(),
                r.integrator(),
                number(r.cell_size),
                number(*t),
                number(*u),
                history_field(&h.stress, i),
                history_field(&h.neighbourhood_stress, i),
                history_field(&h.run_out, i),
            );
        }
    }
    text
}

fn status(r: &CampaignRun) -> &'static str {
    if r.error.is_some() {
        "stopped"
    } else {
        "completed"
    }
}

/// Header of a time-history campaign's `metrics.csv`.
const METRICS_HEADER: &str = "run,scene,family,integrator,cell_size_m,length_scale_m,status,wall_s,steps_1,newton_iterations_1,halvings_1,lost_points_1,onset_time_s,uA_at_0.3_m,uA_final_m,run_out_final_m,qB_peak_kPa,qB_peak_time_s,qB_fall_roughness_1,qB_neighbourhood_fall_roughness_1,qB_reversals_1,M1_discrepancy_1,energy_remainder_share_1\n";

fn metrics_csv(runs: &[CampaignRun], m: &[HistoryMetrics]) -> String {
    let mut csv = String::from(METRICS_HEADER);
    for (r, mm) in runs.iter().zip(m) {
        let fields = [
            number(r.cell_size),
            optional(r.length_scale),
            status(r).to_string(),
            number(r.wall_seconds),
            r.effort.steps.to_string(),
            r.effort.newton_iterations.to_string(),
            r.effort.halvings.to_string(),
            r.lost_points.0.to_string(),
            optional(mm.onset),
            optional(mm.displacement_at_comparison),
            number(mm.final_displacement),
            optional(mm.final_run_out),
            optional(mm.stress_peak.map(|p| p.0)),
            optional(mm.stress_peak.map(|p| p.1)),
            optional(mm.stress_roughness),
            optional(mm.neighbourhood_roughness),
            mm.stress_reversals
                .map(|n| n.to_string())
                .unwrap_or_default(),
            optional(mm.discrepancy),
            optional(mm.final_remainder_share),
        ];
        let _ = writeln!(
            csv,
            "{},{},{},{},{}",
            r.name,
            r.scene,
            r.regularisation(),
            r.integrator(),
            fields.join(",")
        );
    }
    csv
}

/// Header of `integrators.csv`: one row per scene run by both integrators.
const INTEGRATORS_HEADER: &str = "scene,family,cell_size_m,onset_implicit_s,onset_explicit_s,onset_difference_s,uA_0.3_implicit_m,uA_0.3_explicit_m,uA_0.3_relative_difference_1,M1_explicit_vs_implicit_1,uA_final_implicit_m,uA_final_explicit_m,uA_final_relative_difference_1,run_out_implicit_m,run_out_explicit_m,remainder_share_implicit_1,remainder_share_explicit_1,wall_implicit_s,wall_explicit_s,steps_implicit_1,steps_explicit_1,newton_iterations_1,halvings_1\n";

fn integrators_csv(pairs: &[IntegratorPair]) -> String {
    let mut csv = String::from(INTEGRATORS_HEADER);
    for p in pairs {
        let ((ri, mi), (re, me)) = (p.implicit, p.explicit);
        let fields = [
            number(ri.cell_size),
            optional(mi.onset),
            optional(me.onset),
            optional(p.onset_difference()),
            optional(mi.displacement_at_comparison),
            optional(me.displacement_at_comparison),
            optional(p.displacement_difference()),
            optional(p.discrepancy()),
            number(mi.final_displacement),
            number(me.final_displacement),
            number(p.final_displacement_difference()),
            optional(mi.final_run_out),
            optional(me.final_run_out),
            optional(mi.final_remainder_share),
            optional(me.final_remainder_share),
            number(ri.wall_seconds),
            number(re.wall_seconds),
            ri.effort.steps.to_string(),
            re.effort.steps.to_string(),
            ri.effort.newton_iterations.to_string(),
            ri.effort.halvings.to_string(),
        ];
        let _ = writeln!(
            csv,
            "{},{},{}",
            ri.scene,
            ri.regularisation(),
            fields.join(",")
        );
    }
    csv
}

/// Spread of a family's values: (max − min) / mean.
fn spread(values: &[f64]) -> Option<f64> {
    if values.len() < 2 || values.iter().any(|v| !v.is_finite()) {
        return None;
    }
    let max = values.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let min = values.iter().copied().fold(f64::INFINITY, f64::min);
    let mean = values.iter().sum::<f64>() / values.len() as f64;
    Some((max - min) / mean)
}

fn report_md(runs: &[CampaignRun], m: &[HistoryMetrics], pairs: &[IntegratorPair]) -> String {
    let mut md = format!(
        "# Vertical-cut campaign report\n\nPer run (theory §9 M1, M6): collapse onset = first time |u_A| > {ONSET_DISPLACEMENT} m; u_A at t = {COMPARISON_TIME} s and at the end; run-out front x_front = max_p x_p at the end; q_B peak of the failure phase (up to {PEAK_WINDOW} s after the onset); fall roughness = total variation of q_B from that peak to {FALL_WINDOW} s after the onset / its net drop over that time (1 = monotone fall; later B rides in the run-out flow, and while gravity still rises, to t = 0.6 s, the level of q_B follows the weight of the debris above B, which grows with the gravity ramp: `fig11_qB_neighbourhood_failure.png` shows the failure phase alone, `fig11_qB_neighbourhood.png` the whole run), of the single point B and of the group of points that started within one cell of B (`neighbourhood_stress`, when the scene monitors it); reversals of q_B after the onset with a hysteresis of {:.0} % of its peak (M6 noise index); M1 = relative L2 discrepancy of u_A(t) on [0, t_end] against the finest mesh of the same family (regularisation and integrator); R/W = the energy budget's remainder (docs/theory.md E1) as a share of the work put in, at the end.\n\n| run | h (m) | status | wall (s) | steps | Newton | halvings | onset (s) | u_A(0.3) (m) | u_A end (m) | x_front end (m) | q_B peak (kPa) | roughness | roughness (group) | reversals | M1 | R/W end |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n",
        100.0 * REVERSAL_THRESHOLD
    );
    for (r, mm) in runs.iter().zip(m) {
        let _ =
            writeln!(
            md,
            "| {} | {:.4} | {} | {:.1} | {} | {} | {} | {} | {} | {:.3} | {} | {} | {} | {} | {} | {} | {} |",
            r.name,
            r.cell_size,
            status(r),
            r.wall_seconds,
            r.effort.steps,
            r.effort.newton_iterations,
            r.effort.halvings,
            fmt_opt(mm.onset, 1.0, 4),
            fmt_opt(mm.displacement_at_comparison, 1.0, 3),
            mm.final_displacement,
            fmt_opt(mm.final_run_out, 1.0, 2),
            fmt_opt(mm.stress_peak.map(|p| p.0), 1.0, 1),
            fmt_opt(mm.stress_roughness, 1.0, 2),
            fmt_opt(mm.neighbourhood_roughness, 1.0, 2),
            mm.stress_reversals.map(|n| n.to_string()).unwrap_or("–".into()),
            fmt_opt(mm.discrepancy, 1.0, 4),
            fmt_opt(mm.final_remainder_share, 1.0, 3),
        );
    }
    md.push_str("\n## Spread across meshes\n\nPer family: (max − min)/mean over its meshes of the final |u_A| and the final run-out, and S = max M1 over the meshes other than the coarsest (the three finer meshes against the finest).\n\n| family | integrator | meshes | final u_A spread | run-out spread | S (finer meshes) |\n|---|---|---|---|---|---|\n");
    let mut families: Vec<(&str, &str)> = runs
        .iter()
        .map(|r| (r.regularisation(), r.integrator()))
        .collect();
    families.sort();
    families.dedup();
    for (reg, int) in families {
        let members: Vec<(&CampaignRun, &HistoryMetrics)> = runs
            .iter()
            .zip(m)
            .filter(|(r, _)| r.regularisation() == reg && r.integrator() == int)
            .collect();
        let coarsest = members
            .iter()
            .map(|(r, _)| r.cell_size)
            .fold(f64::NEG_INFINITY, f64::max);
        let finals: Vec<f64> = members
            .iter()
            .map(|(_, mm)| mm.final_displacement)
            .collect();
        let runouts: Vec<f64> = members
            .iter()
            .filter_map(|(_, mm)| mm.final_run_out)
            .collect();
        let s = members
            .iter()
            .filter(|(r, _)| r.cell_size < coarsest)
            .filter_map(|(_, mm)| mm.discrepancy)
            .fold(None, |acc: Option<f64>, e| {
                Some(acc.map_or(e, |a| a.max(e)))
            });
        let _ = writeln!(
            md,
            "| {reg} | {int} | {} | {} | {} | {} |",
            members.len(),
            fmt_opt(spread(&finals), 1.0, 3),
            fmt_opt(spread(&runouts), 1.0, 3),
            fmt_opt(s, 1.0, 4),
        );
    }
    if !pairs.is_empty() {
        let _ = write!(md, "\n## Implicit against explicit\n\nThe same scene file run implicit as written (the scene's Newmark or generalised-α step) and with explicit MUSL (its stable step). Onset difference = explicit − implicit; u_A(0.3) difference relative to the implicit value; M1 = explicit u_A(t) against implicit on [0, t_end]; u_A, run-out and the budget's remainder R/W at the end, the u_A difference relative to the implicit value (figure `integrators.png`).\n\n| scene | onset impl. (s) | onset expl. (s) | Δ onset (s) | u_A(0.3) impl. | u_A(0.3) expl. | rel. diff. | M1 | u_A end impl. / expl. (m) | rel. diff. | run-out impl. / expl. (m) | R/W impl. / expl. | wall impl. (s) | wall expl. (s) | steps impl. / expl. | halvings |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
        for p in pairs {
            let ((ri, mi), (re, me)) = (p.implicit, p.explicit);
            let _ = writeln!(
                md,
                "| {} | {} | {} | {} | {} | {} | {} | {} | {:.3} / {:.3} | {:.3} | {} / {} | {} / {} | {:.1} | {:.1} | {} / {} | {} |",
                ri.scene,
                fmt_opt(mi.onset, 1.0, 4),
                fmt_opt(me.onset, 1.0, 4),
                fmt_opt(p.onset_difference(), 1.0, 4),
                fmt_opt(mi.displacement_at_comparison, 1.0, 3),
                fmt_opt(me.displacement_at_comparison, 1.0, 3),
                fmt_opt(p.displacement_difference(), 1.0, 3),
                fmt_opt(p.discrepancy(), 1.0, 4),
                mi.final_displacement,
                me.final_displacement,
                p.final_displacement_difference(),
                fmt_opt(mi.final_run_out, 1.0, 2),
                fmt_opt(me.final_run_out, 1.0, 2),
                fmt_opt(mi.final_remainder_share, 1.0, 3),
                fmt_opt(me.final_remainder_share, 1.0, 3),
                ri.wall_seconds,
                re.wall_seconds,
                ri.effort.steps,
                re.effort.steps,
                ri.effort.halvings,
            );
        }
    }
    md.push_str(&lost_points_notes(runs));
    md.push_str(&stopped_notes(runs));
    md.push_str(&profiles_section(runs));
    md
}

/// One colour per cell size, coarse to fine.
fn colour_of(runs: &[CampaignRun], h: f64) -> usize {
    let mut sizes: Vec<f64> = runs.iter().map(|r| r.cell_size).collect();
    sizes.sort_by(|a, b| b.total_cmp(a));
    sizes.dedup();
    sizes.iter().position(|&s| s == h).unwrap_or(0)
}

fn plot_histories(out: &Path, runs: &[CampaignRun]) -> plot::Result<()> {
    let series = |pick: &dyn Fn(&History) -> &Vec<(f64, f64)>,
                  filter: &dyn Fn(&CampaignRun) -> bool,
                  dashed: &dyn Fn(&CampaignRun) -> bool| {
        runs.iter()
            .filter(|r| filter(r))
            .filter_map(|r| {
                let points = pick(r.history.as_ref()?);
                (points.len() > 1).then(|| Series {
                    name: series_name(r),
                    points: points.clone(),
                    dashed: dashed(r),
                    color: colour_of(runs, r.cell_size),
                    marker: Some(plot::Marker::of_regularisation(r.length_scale.is_some())),
                })
            })
            .collect::<Vec<_>>()
    };
    let implicit = |r: &CampaignRun| r.integrator() == "implicit";
    let local = |r: &CampaignRun| r.length_scale.is_none();
    let figures: [(&str, &str, &str, Vec<Series>); 6] = [
        (
            "fig11_qB.png",
            "Fig. 11: q at B (implicit; dashed: local, solid: nonlocal)",
            "q_B (kPa)",
            series(&|h| &h.stress, &implicit, &local),
        ),
        (
            "fig11_qB_neighbourhood.png",
            "Fig. 11, q of the points within one cell of B (implicit; dashed: local)",
            "q_B (kPa)",
            series(&|h| &h.neighbourhood_stress, &implicit, &local),
        ),
        (
            "fig11_qB_neighbourhood_failure.png",
            "Fig. 11 over the failure phase: q of the points within one cell of B (implicit; dashed: local)",
            "q_B (kPa)",
            failure_window(runs),
        ),
        (
            "fig12_uA.png",
            "Fig. 12: |u_A| (implicit; dashed: local, solid: nonlocal)",
            "|u_A| (m)",
            series(&|h| &h.displacement, &implicit, &local),
        ),
        (
            "run_out.png",
            "Run-out front x_front (implicit; dashed: local, solid: nonlocal)",
            "x_front (m)",
            series(&|h| &h.run_out, &implicit, &local),
        ),
        (
            "implicit_vs_explicit.png",
            "|u_A|: implicit (solid) against explicit (dashed)",
            "|u_A| (m)",
            series(&|h| &h.displacement, &|_| true, &|r| !implicit(r)),
        ),
    ];
    for (file, title, y_label, s) in figures {
        let x_label = match file.contains("failure") {
            true => "t − t_onset (s)",
            false => "t (s)",
        };
        if !s.is_empty() {
            plot::plot_curves(out.join(file), title, x_label, y_label, &s)?;
        }
    }
    let explicit = |r: &CampaignRun| r.integrator() == "explicit";
    if !runs.iter().any(explicit) {
        return Ok(());
    }
    let every = |_: &CampaignRun| true;
    plot_integrators(
        out,
        [
            series(&|h| &h.displacement, &every, &explicit),
            series(&|h| &h.run_out, &every, &explicit),
            series(&|h| &h.remainder_share, &every, &explicit),
        ],
    )
}

/// The neighbourhood q_B of each implicit run over its failure phase: time
/// shifted to the run's onset, from [`FAILURE_LEAD`] before it to
/// [`FAILURE_PLOT`] after it; runs that never collapse are left out.
fn failure_window(runs: &[CampaignRun]) -> Vec<Series> {
    runs.iter()
        .filter(|r| r.integrator() == "implicit")
        .filter_map(|r| {
            let h = r.history.as_ref()?;
            let t0 = metrics::first_exceedance(&h.displacement, ONSET_DISPLACEMENT)?;
            let points: Vec<(f64, f64)> = h
                .neighbourhood_stress
                .iter()
                .map(|&(t, q)| (t - t0, q))
                .filter(|&(t, _)| (-FAILURE_LEAD..=FAILURE_PLOT).contains(&t))
                .collect();
            (points.len() > 1).then(|| Series {
                name: series_name(r),
                points,
                dashed: r.length_scale.is_none(),
                color: colour_of(runs, r.cell_size),
                marker: Some(plot::Marker::of_regularisation(r.length_scale.is_some())),
            })
        })
        .collect()
}

/// Legend entry of a run's curve.
fn series_name(r: &CampaignRun) -> String {
    format!(
        "{} {} h={:.3} m",
        r.regularisation(),
        r.integrator(),
        r.cell_size
    )
}

/// `integrators.png`: |u_A|, the run-out and the budget's remainder R/W
/// over time (`[crest, front, remainder]`), implicit (solid) against
/// explicit (dashed), every run.
fn plot_integrators(out: &Path, [crest, front, remainder]: [Vec<Series>; 3]) -> plot::Result<()> {
    let panels = [
        (
            "|u_A|: implicit (solid) against explicit (dashed)",
            "|u_A| (m)",
            &crest,
        ),
        ("Run-out front x_front", "x_front (m)", &front),
        (
            "Energy budget: remainder R/W (theory E1)",
            "R / W",
            &remainder,
        ),
    ];
    let panels: Vec<plot::CurvePanel> = panels
        .iter()
        .filter(|(_, _, s)| !s.is_empty())
        .map(|&(title, y_label, series)| plot::CurvePanel {
            title,
            y_label,
            series,
        })
        .collect();
    plot::plot_curve_panels(out.join("integrators.png"), "t (s)", &panels)
}

/// Paper Fig. 10: normalised εq and point positions at each snapshot time, one
/// figure per time, family and integrator, meshes coarse to fine.
fn plot_snapshots(out: &Path, runs: &[CampaignRun], window: Bounds) -> plot::Result<()> {
    let mut times: Vec<f64> = runs
        .iter()
        .flat_map(|r| r.fields.iter().map(|f| f.requested_time))
        .collect();
    times.sort_by(f64::total_cmp);
    times.dedup();
    for &time in &times {
        for family in ["local", "nonlocal"] {
            for integrator in ["implicit", "explicit"] {
                let mut members: Vec<&CampaignRun> = runs
                    .iter()
                    .filter(|r| r.regularisation() == family && r.integrator() == integrator)
                    .collect();
                members.sort_by(|a, b| b.cell_size.total_cmp(&a.cell_size));
                let normalised: Vec<(&CampaignRun, &crate::run::FieldSnapshot, Vec<f64>)> = members
                    .iter()
                    .filter_map(|r| {
                        let f = r.fields.iter().find(|f| f.requested_time == time)?;
                        let max = metrics::clip_outliers(&f.eps_q, 0.99)
                            .iter()
                            .copied()
                            .fold(0.0, f64::max);
                        let values = f
                            .eps_q
                            .iter()
                            .map(|e| if max > 0.0 { (e / max).min(1.0) } else { 0.0 })
                            .collect();
                        Some((*r, f, values))
                    })
                    .collect();
                if normalised.is_empty() {
                    continue;
                }
                let panels: Vec<Panel> = normalised
                    .iter()
                    .map(|(r, f, values)| Panel {
                        title: format!("h = {:.3} m, t = {:.3} s", r.cell_size, f.time),
                        positions: &f.positions,
                        values,
                        bounds: window,
                        volumes: Some(&f.volumes),
                        marker: Some(0.35 * r.cell_size),
                    })
                    .collect();
                let path = out.join(format!("fig10_{family}_{integrator}_t{time:.2}.png"));
                plot::plot_field_panels(
                    &path,
                    &format!("Normalised εq at t = {time} s ({family}, {integrator})"),
                    &panels,
                    Some((0.0, 1.0)),
                    "εq / max εq (1)",
                )?;
            }
        }
    }
    Ok(())
}
