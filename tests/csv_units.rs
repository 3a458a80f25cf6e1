//! Issue 41, item 10 and check 2: every CSV file the programs write is read
//! back; each header names its unit and each field is a number or empty.
//!
//! The test writes them all into a temporary directory with the release
//! binaries' own code paths: runs (`curve.csv` with monitors of every unit,
//! the adaptive step columns), `mpm-geo point` (`point.csv`), a load-curve
//! campaign with step refinement (`curves.csv`, `metrics.csv`,
//! `step_convergence.csv`), a time-history campaign with its explicit twins
//! (`histories.csv`, `metrics.csv`, `integrators.csv`), a study with an axis
//! and a case study (`study.csv`) and the solver bench on a run's exported
//! systems (`bench.csv`). Then every `*.csv` under the directory is checked:
//! - a column is an *identifier column* (text naming a row) if its name is
//!   one of [`IDENTIFIERS`] or starts with `axis_` (a study's axes, as
//!   docs/guide.md §9 declares); every other column ends in `_<unit>` with a
//!   unit of [`UNITS`] after a non-empty quantity name;
//! - every field of a number column is empty or a finite number (`NaN`,
//!   `inf`, `–`, `n/a` or any text fail).
//!
//! Before issue 41 every file failed: `step` and `time` had no unit, and
//! campaign tables held `–` and study tables `nan`.

mod common;

use std::path::{Path, PathBuf};
use std::process::Command;

/// The units a column name may end in (docs/guide.md §9): `1` for
/// dimensionless numbers and counts.
const UNITS: [&str; 15] = [
    "1",
    "s",
    "m",
    "m_per_s",
    "m_per_s2",
    "kPa",
    "kN_per_m",
    "kN_per_m2",
    "kN_per_m3",
    "kJ_per_m",
    "m2_per_m",
    "t_per_m3",
    "deg",
    "MB",
    "GB",
];

/// The identifier columns (docs/guide.md §9): text that names a row.
const IDENTIFIERS: [&str; 12] = [
    "run",
    "scene",
    "family",
    "integrator",
    "status",
    "case",
    "method",
    "series",
    "refine",
    "reference",
    "system",
    "solver",
];

/// Whether `column` is an identifier column.
fn is_identifier(column: &str) -> bool {
    IDENTIFIERS.contains(&column) || column.starts_with("axis_")
}

/// Whether `column` ends in `_<unit>` after a non-empty quantity name.
fn has_unit(column: &str) -> bool {
    UNITS.iter().any(|unit| {
        column
            .strip_suffix(unit)
            .and_then(|rest| rest.strip_suffix('_'))
            .is_some_and(|quantity| !quantity.is_empty())
    })
}

/// The problems of one CSV file: columns without a unit, fields of number
/// columns that are neither empty nor a finite number.
fn problems(path: &Path) -> Vec<String> {
    let mut reader = csv::Reader::from_path(path).unwrap_or_else(|e| panic!("{path:?}: {e}"));
    let header = reader.headers().expect("a header").clone();
    let mut found = Vec::new();
    for column in header.iter() {
        if !is_identifier(column) && !has_unit(column) {
            found.push(format!("column `{column}` has no unit"));
        }
    }
    for (row, record) in reader.records().enumerate() {
        let record = record.unwrap_or_else(|e| panic!("{path:?}: {e}"));
        for (column, field) in header.iter().zip(record.iter()) {
            let number = field.parse::<f64>().is_ok_and(f64::is_finite);
            if !is_identifier(column) && !field.is_empty() && !number {
                found.push(format!("row {}: `{field}` in `{column}`", row + 1));
            }
        }
    }
    found
}

/// Every `*.csv` file under `dir`.
fn csv_files(dir: &Path) -> Vec<PathBuf> {
    let mut files = Vec::new();
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            files.extend(csv_files(&path));
        } else if path.extension().is_some_and(|e| e == "csv") {
            files.push(path);
        }
    }
    files
}

/// Run `mpm-geo` with `args`; it must succeed.
fn mpm_geo(args: &[&str]) {
    let output = Command::new(env!("CARGO_BIN_EXE_mpm-geo"))
        .args(args)
        .output()
        .unwrap();
    assert!(
        output.status.success(),
        "mpm-geo {args:?}: {}",
        String::from_utf8_lossy(&output.stderr)
    );
}

/// `--set` arguments of `overrides`.
fn sets<'a>(overrides: &[&'a str]) -> Vec<&'a str> {
    overrides.iter().flat_map(|o| ["--set", *o]).collect()
}

/// Copy the named files of `validation/<from>/` into `dir`.
fn copy_scenes(dir: &Path, from: &str, names: &[&str]) {
    std::fs::create_dir_all(dir).unwrap();
    for name in names {
        std::fs::copy(
            common::validation(&format!("{from}/{name}")),
            dir.join(name),
        )
        .unwrap();
    }
}

/// Runs: the nonlocal biaxial (force, displacement, plastic strain and
/// energy monitors) exporting its first step's systems, which the solver
/// bench then reads; the adaptive bar (the step columns); the cut (point,
/// neighbourhood, gravity and run-out monitors); a material-point test.
fn write_run_outputs(out: &Path) {
    let biaxial = out.join("biaxial");
    let mut args = vec!["run", "--quiet", "--out", biaxial.to_str().unwrap()];
    let scene = common::validation("biaxial/nonlocal_h300.toml");
    args.push(scene.to_str().unwrap());
    args.extend(sets(&["scene.steps=4", "output.systems=[1]"]));
    mpm_geo(&args);
    let bench = out.join("bench");
    std::fs::create_dir_all(&bench).unwrap();
    let options = mpm_solvers::bench::BenchOptions {
        repeats: 1,
        ..Default::default()
    };
    let rows = mpm_solvers::bench::run_bench(&biaxial.join("systems"), &options, |_| {}).unwrap();
    mpm_solvers::bench::write_csv(&rows, &bench.join("bench.csv")).unwrap();

    let bar = common::validation("elastic/bar_implicit.toml");
    let adaptive = out.join("adaptive");
    let mut args = vec!["run", "--quiet", "--out", adaptive.to_str().unwrap()];
    args.push(bar.to_str().unwrap());
    args.extend(sets(&["scene.steps=40", "solver.time_step=\"adaptive\""]));
    mpm_geo(&args);

    let cut = common::validation("vertical_cut/nonlocal_h100.toml");
    let cut_out = out.join("cut");
    let mut args = vec!["run", "--quiet", "--out", cut_out.to_str().unwrap()];
    args.push(cut.to_str().unwrap());
    args.extend(sets(&["scene.steps=5", "grid.cell_size=0.25"]));
    mpm_geo(&args);

    let point = out.join("point.csv");
    mpm_geo(&[
        "point",
        "--test",
        "biaxial",
        "--steps",
        "10",
        "--out",
        point.to_str().unwrap(),
    ]);
}

/// A load-curve campaign with step refinement and a time-history campaign
/// with explicit twins, both short.
fn write_campaign_outputs(out: &Path) {
    let scenes = out.join("biaxial_scenes");
    copy_scenes(
        &scenes,
        "biaxial",
        &["local_h300.toml", "nonlocal_h300.toml", "campaign.toml"],
    );
    let result = out.join("campaign-biaxial");
    let mut args = vec![
        "campaign",
        scenes.to_str().unwrap(),
        "--out",
        result.to_str().unwrap(),
        "--step-refinement",
        "2",
    ];
    args.extend(sets(&["scene.steps=6"]));
    mpm_geo(&args);

    let scenes = out.join("cut_scenes");
    copy_scenes(
        &scenes,
        "vertical_cut",
        &["local_h100.toml", "campaign.toml"],
    );
    let result = out.join("campaign-cut");
    let mut args = vec![
        "campaign",
        scenes.to_str().unwrap(),
        "--out",
        result.to_str().unwrap(),
    ];
    args.extend(sets(&["scene.steps=5", "grid.cell_size=0.25"]));
    mpm_geo(&args);
}

/// A study of the elastic bar with an axis, a step series and an explicit
/// CFL series; a case study of two cases.
fn write_study_outputs(out: &Path) {
    let bar = common::validation("elastic/bar_implicit.toml");
    let study = format!(
        r#"
[study]
name = "units"
scene = "{bar}"
set = ["scene.steps=20"]

[reference]
kind = "closed_form"
name = "bar_vibration"
monitor = "top_uy"
parameters = {{ height = 1.0, wave_speed = 100.0, velocity = 0.01 }}

[[quantity]]
monitor = "top_uy"
measure = "l2"

[[axis]]
name = "shape_functions"
values = [
  {{ label = "bilinear", set = ["grid.shape_functions=bilinear", "grid.point_layout=gauss"] }},
  {{ label = "gimp", set = ["grid.shape_functions=gimp", "grid.point_layout=uniform"] }},
]

[[series]]
label = "Newmark"
refine = "dt"
values = [4e-4, 2e-4]

[[series]]
label = "explicit"
integrator = "explicit"
refine = "solver.cfl"
values = [0.5]
"#,
        bar = bar.display()
    );
    let cases = format!(
        r#"
[study]
name = "cases"
scene = "{bar}"
set = ["scene.steps=20"]

[reference]
kind = "closed_form"
name = "bar_vibration"
monitor = "top_uy"

[[quantity]]
monitor = "top_uy"
measure = "l2"

[[series]]
label = "as written"

[[case]]
name = "bar, nu = 0"

[[case]]
name = "bar, large step"
dt = 5e-3
"#,
        bar = bar.display()
    );
    for (name, text) in [("units", study), ("cases", cases)] {
        let spec = out.join(format!("{name}.toml"));
        std::fs::write(&spec, text).unwrap();
        let result = out.join(format!("study-{name}"));
        mpm_geo(&[
            "study",
            spec.to_str().unwrap(),
            "--out",
            result.to_str().unwrap(),
        ]);
    }
}

#[test]
fn every_csv_file_has_units_and_numbers() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path();
    write_run_outputs(out);
    write_campaign_outputs(out);
    write_study_outputs(out);
    let files = csv_files(out);
    let mut names: Vec<String> = files
        .iter()
        .map(|f| f.file_name().unwrap().to_string_lossy().into_owned())
        .collect();
    names.sort();
    names.dedup();
    assert_eq!(
        names,
        [
            "bench.csv",
            "curve.csv",
            "curves.csv",
            "histories.csv",
            "integrators.csv",
            "metrics.csv",
            "point.csv",
            "step_convergence.csv",
            "study.csv",
        ],
        "the files written"
    );
    let mut report = Vec::new();
    for file in &files {
        for problem in problems(file) {
            report.push(format!(
                "{}: {problem}",
                file.strip_prefix(out).unwrap().display()
            ));
        }
    }
    assert!(
        report.is_empty(),
        "{} problems:\n{}",
        report.len(),
        report.join("\n")
    );
}

/// The checks themselves: units at the end of a name only, after a
/// quantity; text, NaN and infinities refused outside identifier columns.
#[test]
fn the_check_refuses_what_it_should() {
    for good in [
        "time_s",
        "load_kN_per_m",
        "kappa_max_1",
        "error_run_out_t0.5_1",
    ] {
        assert!(has_unit(good), "{good}");
    }
    for bad in [
        "time",
        "step",
        "_s",
        "s",
        "load_kN",
        "wall_seconds",
        "value",
    ] {
        assert!(!has_unit(bad), "{bad}");
    }
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("t.csv");
    std::fs::write(
        &path,
        "run,axis_shape,time_s,load\nr1,gimp,1e-3,2\nr2,,NaN,–\nr3,x,inf,\n",
    )
    .unwrap();
    assert_eq!(
        problems(&path),
        [
            "column `load` has no unit",
            "row 2: `NaN` in `time_s`",
            "row 2: `–` in `load`",
            "row 3: `inf` in `time_s`",
        ]
    );
}
