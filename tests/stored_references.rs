//! The stored references of the paper's benchmarks (issue 40): each
//! `validation/<benchmark>/reference/reference.toml` names a coarse scene,
//! its overrides, the curve's columns and a tolerance; its `curve.csv` is
//! that run's curve as made by `scripts/update_references.py`. The run is
//! repeated here and every listed column must stay within the tolerance
//! (a share of the column's largest magnitude) at every row, so a change
//! that moves a benchmark curve fails until its reference is remade on
//! purpose. The runs are deterministic (`tests/reproducibility.rs`): on this
//! machine they reproduce their references exactly.

use std::path::Path;

use mpm_geo::output::TIME_COLUMN;

mod common;

/// A `reference.toml`.
#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct Reference {
    /// Scene path under `validation/`.
    scene: String,
    /// `--set` overrides of the run.
    overrides: Vec<String>,
    /// Monitors compared (each in its `curve.csv` column, named with its unit).
    columns: Vec<String>,
    /// Largest change allowed, as a share of the column's largest magnitude.
    tolerance: f64,
}

/// The time column and the `columns` of a stored `curve.csv`.
fn stored_curve(path: &Path, columns: &[String]) -> (Vec<f64>, Vec<Vec<f64>>) {
    let mut reader = csv::Reader::from_path(path).unwrap_or_else(|e| panic!("{path:?}: {e}"));
    let header = reader.headers().unwrap().clone();
    let index = |name: &str| {
        header
            .iter()
            .position(|h| h == name)
            .unwrap_or_else(|| panic!("{path:?} has no column {name}"))
    };
    let (time, wanted): (usize, Vec<usize>) = (
        index(TIME_COLUMN),
        columns.iter().map(|c| index(c)).collect(),
    );
    let (mut times, mut values) = (Vec::new(), vec![Vec::new(); columns.len()]);
    for record in reader.records() {
        let record = record.unwrap();
        let number = |i: usize| record[i].parse::<f64>().unwrap();
        times.push(number(time));
        for (column, &i) in values.iter_mut().zip(&wanted) {
            column.push(number(i));
        }
    }
    (times, values)
}

/// The largest deviation of `run` from `stored` as a share of the stored
/// column's largest magnitude.
fn relative_deviation(run: &[f64], stored: &[f64]) -> f64 {
    let scale = stored.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
    let deviation = run
        .iter()
        .zip(stored)
        .fold(0.0_f64, |m, (a, b)| m.max((a - b).abs()));
    deviation / scale.max(f64::MIN_POSITIVE)
}

/// Repeat the reference run of `benchmark` and compare it with its curve.
fn check(benchmark: &str) {
    let dir = common::validation(benchmark).join("reference");
    let spec: Reference = toml::from_str(
        &std::fs::read_to_string(dir.join("reference.toml")).expect("reference.toml"),
    )
    .expect("a valid reference.toml");
    let overrides: Vec<&str> = spec.overrides.iter().map(String::as_str).collect();
    let mut sim = common::simulation(&spec.scene, &overrides);
    let history = common::run_history(&mut sim);
    let csv_columns: Vec<String> = spec
        .columns
        .iter()
        .map(|name| sim.monitors[common::column(&sim, name)].spec.column())
        .collect();
    let (times, stored) = stored_curve(&dir.join("curve.csv"), &csv_columns);
    assert_eq!(history.len(), times.len(), "{benchmark}: rows");
    for (row, ((t, _), stored_t)) in history.iter().zip(&times).enumerate() {
        assert!(
            (t - stored_t).abs() <= 1e-9 * stored_t.abs().max(1e-3),
            "{benchmark}: time of row {row}"
        );
    }
    for (name, stored) in spec.columns.iter().zip(&stored) {
        let i = common::column(&sim, name);
        let run: Vec<f64> = history.iter().map(|(_, v)| v[i]).collect();
        let deviation = relative_deviation(&run, stored);
        println!(
            "{benchmark} {name}: largest deviation {deviation:.2e} of its range (tolerance {:.0e})",
            spec.tolerance
        );
        assert!(
            deviation <= spec.tolerance,
            "{benchmark}: {name} moved by {deviation:.2e} of its largest value (tolerance {}); if the change is meant, remake the reference with scripts/update_references.py",
            spec.tolerance
        );
    }
}

#[test]
fn biaxial_reference_curve_holds() {
    check("biaxial");
}

#[test]
fn footing_reference_curve_holds() {
    check("footing");
}

#[test]
fn vertical_cut_reference_curve_holds() {
    check("vertical_cut");
}

/// The comparison notices a change of the size the tolerance names: a
/// curve raised by 0.3 % of its peak is outside 2e-3.
#[test]
fn a_moved_curve_is_caught() {
    let stored = [0.0, 50.0, 100.0, 80.0];
    let moved: Vec<f64> = stored.iter().map(|v| v + 0.3).collect();
    assert!((relative_deviation(&moved, &stored) - 3e-3).abs() < 1e-12);
    assert_eq!(relative_deviation(&stored, &stored), 0.0);
}
