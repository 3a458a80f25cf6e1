//! The plot of one run: each monitor column of its `curve.csv` against the
//! time column, one chart per monitor stacked in `curve.png` and
//! `curve.svg` beside `curve.csv`. `mpm-geo run` and `resume` draw it when
//! the run ends; `mpm-geo plot DIR` draws it again (of a run still going,
//! of the rows so far).

use std::path::{Path, PathBuf};

use super::{plot_curve_panels_sized, svg_path, CurvePanel, PlotError, Result, Series};
use crate::output::{STEP_COLUMN, TIME_COLUMN};
use crate::simulation::STEP_COLUMNS;

/// The PNG of the run's curve, in the run's directory.
pub const CURVE_PLOT: &str = "curve.png";
/// The files the run's curve plot writes: the PNG and the SVG beside it.
pub const FILES: [&str; 2] = [CURVE_PLOT, "curve.svg"];

/// Width of the figure, px.
const WIDTH: u32 = 960;
/// Height of one chart, px (a single chart: 680).
const CHART_H: u32 = 420;

/// Display forms of the unit suffixes of the `curve.csv` columns
/// ([`crate::csv_columns::Unit::suffix`]), longest first.
const UNITS: [(&str, &str); 15] = [
    ("kN_per_m2", "kN/m²"),
    ("kN_per_m3", "kN/m³"),
    ("kN_per_m", "kN/m"),
    ("kJ_per_m", "kJ/m"),
    ("m_per_s2", "m/s²"),
    ("m2_per_m", "m²/m"),
    ("t_per_m3", "t/m³"),
    ("m_per_s", "m/s"),
    ("kPa", "kPa"),
    ("deg", "°"),
    ("MB", "MB"),
    ("GB", "GB"),
    ("s", "s"),
    ("m", "m"),
    ("1", "1"),
];

/// The quantity and the displayed unit of the number column `column`
/// (`quantity_unit`): ("load", "kN/m") for `load_kN_per_m`; `None` when no
/// unit is known.
fn split_unit(column: &str) -> Option<(&str, &'static str)> {
    UNITS.iter().find_map(|&(suffix, shown)| {
        let quantity = column.strip_suffix(suffix)?.strip_suffix('_')?;
        (!quantity.is_empty()).then_some((quantity, shown))
    })
}

/// Axis label of the number column `column` (`quantity_unit`): "load
/// (kN/m)" for `load_kN_per_m`; the name as it is when no unit is known.
pub fn axis_label(column: &str) -> String {
    match split_unit(column) {
        Some((quantity, unit)) => format!("{quantity} ({unit})"),
        None => column.to_string(),
    }
}

/// One monitor column of `curve.csv` as (time, value) points.
#[derive(Debug, Clone, PartialEq)]
pub struct MonitorCurve {
    /// The column's name (`load_kN_per_m`).
    pub column: String,
    /// `(t, value)` per row; empty fields are left out.
    pub points: Vec<(f64, f64)>,
}

fn input(path: &Path, e: impl std::fmt::Display) -> PlotError {
    PlotError::Input(format!("{}: {e}", path.display()))
}

/// The monitor columns of the `curve.csv` at `path` (every column but the
/// step, the time and the step's own columns) against time.
pub fn read_monitors(path: &Path) -> Result<Vec<MonitorCurve>> {
    let mut reader = csv::Reader::from_path(path).map_err(|e| input(path, e))?;
    let header = reader.headers().map_err(|e| input(path, e))?.clone();
    let time = header
        .iter()
        .position(|c| c == TIME_COLUMN)
        .ok_or_else(|| input(path, format!("no `{TIME_COLUMN}` column")))?;
    let monitors: Vec<usize> = (0..header.len())
        .filter(|&i| {
            let c = &header[i];
            i != time && c != STEP_COLUMN && !STEP_COLUMNS.contains(&c)
        })
        .collect();
    let mut curves: Vec<MonitorCurve> = monitors
        .iter()
        .map(|&i| MonitorCurve {
            column: header[i].to_string(),
            points: Vec::new(),
        })
        .collect();
    for (row, record) in reader.records().enumerate() {
        let record = record.map_err(|e| input(path, e))?;
        let number = |i: usize| -> Result<Option<f64>> {
            let field = record.get(i).unwrap_or("");
            if field.is_empty() {
                return Ok(None);
            }
            field
                .parse()
                .map(Some)
                .map_err(|_| input(path, format!("row {}: `{field}` is no number", row + 2)))
        };
        let Some(t) = number(time)? else { continue };
        for (curve, &i) in curves.iter_mut().zip(&monitors) {
            if let Some(v) = number(i)? {
                curve.points.push((t, v));
            }
        }
    }
    Ok(curves)
}

/// Draw the run in `dir`: each monitor of its `curve.csv` against time, one
/// chart per monitor, into `dir/curve.png` and `dir/curve.svg`. Returns the
/// two files written; [`PlotError::Empty`] when `curve.csv` has no monitor
/// column or no row.
pub fn plot_run(dir: &Path) -> Result<[PathBuf; 2]> {
    let curves = read_monitors(&dir.join("curve.csv"))?;
    if curves.is_empty() {
        return Err(PlotError::Empty("curve.csv has no monitor column"));
    }
    let series: Vec<[Series; 1]> = curves
        .iter()
        .map(|c| {
            [Series {
                name: String::new(),
                points: c.points.clone(),
                dashed: false,
                color: 0,
                marker: None,
            }]
        })
        .collect();
    let labels: Vec<String> = curves.iter().map(|c| axis_label(&c.column)).collect();
    let panels: Vec<CurvePanel> = curves
        .iter()
        .zip(&series)
        .zip(&labels)
        .filter(|((c, _), _)| !c.points.is_empty())
        .map(|((c, s), label)| CurvePanel {
            title: split_unit(&c.column).map_or(&c.column, |(q, _)| q),
            y_label: label,
            series: s,
        })
        .collect();
    if panels.is_empty() {
        return Err(PlotError::Empty("curve.csv has no row"));
    }
    let height = (CHART_H * panels.len() as u32).max(680);
    let png = dir.join(CURVE_PLOT);
    plot_curve_panels_sized(&png, (WIDTH, height), "t (s)", &panels)?;
    let svg = svg_path(&png);
    Ok([png, svg])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn axis_labels_carry_the_unit() {
        assert_eq!(axis_label("load_kN_per_m"), "load (kN/m)");
        assert_eq!(axis_label("crest_m"), "crest (m)");
        assert_eq!(axis_label("q_B_kPa"), "q_B (kPa)");
        assert_eq!(axis_label("kappa_max_1"), "kappa_max (1)");
        assert_eq!(axis_label("g_m_per_s2"), "g (m/s²)");
        assert_eq!(axis_label("stiffness_kN_per_m2"), "stiffness (kN/m²)");
        assert_eq!(axis_label("noUnit"), "noUnit");
    }

    #[test]
    fn a_run_directory_gets_its_curve_plot() {
        let dir = tempfile::tempdir().unwrap();
        let mut csv = String::from("step_1,time_s,dt_s,load_kN_per_m,crest_m\n");
        for k in 0..50 {
            let t = k as f64 * 0.01;
            csv.push_str(&format!("{k},{t:e},1e-2,{:e},{:e}\n", 10.0 * t, -0.1 * t));
        }
        // a row whose monitor had no value
        csv.push_str("50,5e-1,1e-2,,-5e-2\n");
        std::fs::write(dir.path().join("curve.csv"), csv).unwrap();
        let curves = read_monitors(&dir.path().join("curve.csv")).unwrap();
        let names: Vec<&str> = curves.iter().map(|c| c.column.as_str()).collect();
        assert_eq!(names, ["load_kN_per_m", "crest_m"]);
        assert_eq!((curves[0].points.len(), curves[1].points.len()), (50, 51));
        let [png, svg] = plot_run(dir.path()).unwrap();
        assert_eq!(png, dir.path().join("curve.png"));
        let img = image::open(&png).unwrap();
        assert_eq!((img.width(), img.height()), (WIDTH, 2 * CHART_H));
        let text = std::fs::read_to_string(&svg).unwrap();
        for label in ["load (kN/m)", "crest (m)", "t (s)"] {
            assert!(text.contains(label), "{label} missing from the SVG");
        }
    }

    #[test]
    fn a_curve_without_monitors_or_rows_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("curve.csv");
        std::fs::write(&path, "step_1,time_s,dt_s\n0,0e0,1e-2\n").unwrap();
        assert!(matches!(plot_run(dir.path()), Err(PlotError::Empty(_))));
        std::fs::write(&path, "step_1,time_s,dt_s,load_kN_per_m\n").unwrap();
        assert!(matches!(plot_run(dir.path()), Err(PlotError::Empty(_))));
        std::fs::write(&path, "step_1,time_s,load_kN_per_m\n0,0,x\n").unwrap();
        assert!(matches!(plot_run(dir.path()), Err(PlotError::Input(_))));
        assert!(!dir.path().join(CURVE_PLOT).exists());
        let missing = tempfile::tempdir().unwrap();
        assert!(matches!(plot_run(missing.path()), Err(PlotError::Input(_))));
    }
}
