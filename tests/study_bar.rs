//! Issue 13, check 1: the elastic-bar study (`validation/studies/elastic_bar_order.toml`)
//! run through `mpm-geo study`, each series against its own run with a step 100×
//! smaller than its finest on the same mesh (the spatial error cancels). The
//! observed orders are read from the study's own `study.csv`.

mod common;

use std::collections::BTreeMap;
use std::path::Path;

use mpm_geo::study::{log_log_slope, refined_column, run_study, StudyOptions};

/// (refined value, error) per series, from `study.csv`.
fn series_errors(csv_path: &Path) -> BTreeMap<String, Vec<(f64, f64)>> {
    let mut reader = csv::Reader::from_path(csv_path).expect("study.csv");
    let header = reader.headers().expect("header").clone();
    let column = |name: &str| {
        header
            .iter()
            .position(|h| h == name)
            .unwrap_or_else(|| panic!("study.csv has no column {name}"))
    };
    let (series, refine, error, status) = (
        column("series"),
        column("refine"),
        column("error_1"),
        column("status"),
    );
    let mut out: BTreeMap<String, Vec<(f64, f64)>> = BTreeMap::new();
    for record in reader.records() {
        let r = record.expect("row");
        assert_eq!(&r[status], "completed", "run {} did not complete", &r[0]);
        let parse = |i: usize| r[i].parse::<f64>().expect("number");
        // the refined value is in the column of its key (`dt_s`, `solver.cfl_1`)
        let value = column(&refined_column(&r[refine]));
        out.entry(r[series].to_string())
            .or_default()
            .push((parse(value), parse(error)));
    }
    out
}

/// Local order between consecutive refinements, coarse to fine.
fn local_orders(points: &[(f64, f64)]) -> Vec<f64> {
    points
        .windows(2)
        .map(|w| (w[0].1 / w[1].1).ln() / (w[0].0 / w[1].0).ln())
        .collect()
}

#[test]
fn time_integrators_converge_at_their_orders() {
    let out = tempfile::tempdir().expect("temp dir");
    let options = StudyOptions {
        executable: env!("CARGO_BIN_EXE_mpm-geo").into(),
        repeats: Some(1),
        verbose: false,
        overrides: Vec::new(),
        part: mpm_geo::campaign::Part::Whole,
    };
    let spec = common::validation("studies/elastic_bar_order.toml");
    let rows = run_study(&spec, out.path(), &options).expect("study runs");
    assert_eq!(rows.len(), 20, "5 series x 4 refinements");
    for file in [
        "study.csv",
        "report.md",
        "work_precision.png",
        "work_precision.svg",
    ] {
        assert!(out.path().join(file).exists(), "{file} written");
    }
    let series = series_errors(&out.path().join("study.csv"));
    let slope = |label: &str| {
        let points = &series[label];
        let slope = log_log_slope(points).expect("slope");
        eprintln!("{label}: errors {points:?}, order {slope:.3}");
        slope
    };
    // trapezoidal Newmark is second order (measured 2.01)
    let trapezoidal = slope("Newmark γ = 1/2");
    assert!(
        (trapezoidal - 2.0).abs() <= 0.3,
        "γ = 1/2 order {trapezoidal}"
    );
    // γ > 1/2 damps at the price of first order (measured 0.99)
    let damped = slope("Newmark γ = 0.6 (damped)");
    assert!((damped - 1.0).abs() <= 0.3, "γ = 0.6 order {damped}");
    // generalised-α damps without losing the second order (issue 39, check 1:
    // within ±0.2 of 2)
    for rho in ["0.8", "0.5"] {
        let order = slope(&format!("generalised-α ρ∞ = {rho}"));
        assert!((order - 2.0).abs() <= 0.2, "ρ∞ = {rho} order {order}");
    }
    // explicit MUSL: second order at the usual CFL numbers, tending to first
    // order as Δt → 0 (the re-mapped velocity of the strain increment differs
    // from the one that moved the points by O(Δt h²) per step); measured local
    // orders 1.84, 1.67, 1.39 for CFL 0.8 → 0.1
    let explicit = &series["explicit MUSL"];
    let orders = local_orders(explicit);
    eprintln!("explicit MUSL local orders {orders:?}");
    assert!(orders[0] >= 1.7, "coarsest local order {}", orders[0]);
    assert!(
        orders.windows(2).all(|w| w[1] < w[0]),
        "local orders fall with the step: {orders:?}"
    );
    let finest = orders[orders.len() - 1];
    assert!(
        (1.0..=1.55).contains(&finest),
        "finest local order {finest}"
    );
}

/// `study.csv` without its timing columns (wall and stage seconds: the
/// values that differ between processes).
fn study_without_timings(out: &Path) -> Vec<Vec<String>> {
    let mut reader = csv::Reader::from_path(out.join("study.csv")).expect("study.csv");
    let keep: Vec<bool> = reader
        .headers()
        .unwrap()
        .iter()
        .map(|h| !(h.starts_with("wall") || (h.ends_with("_s") && h != "dt_s")))
        .collect();
    reader
        .records()
        .map(|r| {
            r.unwrap()
                .iter()
                .zip(&keep)
                .filter(|(_, k)| **k)
                .map(|(v, _)| v.to_string())
                .collect()
        })
        .collect()
}

/// Issue 14, check 5 for studies: a small bar study run whole, and as two
/// shards in separate processes followed by `--collect`, gives the same
/// `study.csv` (timings aside); a re-run measures nothing again.
#[test]
fn sharded_study_collects_to_the_same_table_and_a_rerun_measures_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let spec = dir.path().join("bar.toml");
    let scene = common::validation("elastic/bar_implicit.toml");
    std::fs::write(
        &spec,
        format!(
            "[study]\nname = \"bar\"\nscene = {scene:?}\nrepeats = 1\nset = [\"scene.steps=20\"]\n\n\
             [reference]\nkind = \"series\"\n\n[[quantity]]\nmonitor = \"top_uy\"\nmeasure = \"l2\"\n\n\
             [[series]]\nlabel = \"Newmark\"\nrefine = \"dt\"\nvalues = [8e-4, 4e-4]\nreference_value = 1e-4\n\n\
             [[series]]\nlabel = \"explicit\"\nintegrator = \"explicit\"\nrefine = \"solver.cfl\"\nvalues = [0.8, 0.4]\nreference_value = 0.1\n"
        ),
    )
    .unwrap();
    let study = |out: &Path, extra: &[&str]| {
        std::process::Command::new(env!("CARGO_BIN_EXE_mpm-geo"))
            .arg("study")
            .arg(&spec)
            .arg("--out")
            .arg(out)
            .args(extra)
            .output()
            .unwrap()
    };
    let whole = dir.path().join("whole");
    assert!(study(&whole, &[]).status.success());
    let sharded = dir.path().join("sharded");
    for shard in ["1/2", "2/2"] {
        let output = study(&sharded, &["--shard", shard]);
        assert!(output.status.success(), "shard {shard}");
    }
    assert!(
        !sharded.join("study.csv").exists(),
        "a shard writes no report"
    );
    assert!(study(&sharded, &["--collect"]).status.success());
    let table = study_without_timings(&whole);
    assert_eq!(table.len(), 4);
    assert_eq!(table, study_without_timings(&sharded));
    let rerun = study(&whole, &[]);
    assert!(rerun.status.success());
    let stderr = String::from_utf8_lossy(&rerun.stderr);
    // four compared runs and their two series references
    assert_eq!(stderr.matches("not run again").count(), 6, "{stderr}");
    assert_eq!(table, study_without_timings(&whole));
}
