//! Bad input is refused before the run with a message naming the field, and a
//! run that fails mid-way exits non-zero, names step and cause, and keeps
//! `curve.csv` with every completed step (issue 3, check 7). These tests drive
//! the `mpm-geo` binary as a user would.

mod common;

use std::process::Command;

fn mpm_geo(args: &[&str]) -> (i32, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_mpm-geo"))
        .args(args)
        .output()
        .expect("binary runs");
    let text =
        String::from_utf8_lossy(&out.stderr).into_owned() + &String::from_utf8_lossy(&out.stdout);
    (out.status.code().unwrap_or(-1), text)
}

fn check_refused(extra: &[&str], needles: &[&str]) {
    let scene = common::validation("elastic/oedometer.toml");
    let mut args = vec!["check", scene.to_str().unwrap()];
    args.extend_from_slice(extra);
    let (code, text) = mpm_geo(&args);
    assert_ne!(code, 0, "accepted: {text}");
    for n in needles {
        assert!(text.contains(n), "message lacks `{n}`: {text}");
    }
    assert!(!text.contains("panicked"), "{text}");
}

#[test]
fn valid_scene_passes_check() {
    let scene = common::validation("elastic/oedometer.toml");
    let (code, text) = mpm_geo(&["check", scene.to_str().unwrap()]);
    assert_eq!(code, 0, "{text}");
}

#[test]
fn unknown_key_is_refused_naming_it() {
    // a misspelt key inside a known table
    check_refused(
        &["--set", "grid.cel_size=0.1"],
        &["cel_size", "unknown field"],
    );
}

#[test]
fn unknown_key_in_file_is_refused_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(common::validation("elastic/oedometer.toml"))
        .unwrap()
        .replace("density = 2.0", "density = 2.0\ndensty = 2.0");
    let path = dir.path().join("typo.toml");
    std::fs::write(&path, text).unwrap();
    let (code, msg) = mpm_geo(&["check", path.to_str().unwrap()]);
    assert_ne!(code, 0);
    assert!(msg.contains("densty"), "{msg}");
}

#[test]
fn poisson_ratio_of_one_half_is_refused() {
    check_refused(
        &["--set", "materials.soil.nu=0.5"],
        &["materials.soil.nu", "(-1, 0.5)"],
    );
}

#[test]
fn body_outside_the_grid_is_refused() {
    check_refused(
        &["--set", "body.0.box=[[0.0, 0.0], [0.3, 1.0]]"],
        &["body[0].box", "outside the grid"],
    );
}

#[test]
fn other_out_of_range_values_are_refused() {
    check_refused(
        &["--set", "materials.soil.E=-5"],
        &["materials.soil.E", "> 0"],
    );
    check_refused(
        &["--set", "grid.cell_size=0.3"],
        &["grid.size", "whole number of cells"],
    );
    check_refused(&["--set", "solver.cfl=1.5"], &["solver.cfl", "(0, 1]"]);
    check_refused(
        &["--set", "bc.fixed.0.line=\"x=0.05\""],
        &["bc.fixed[0].line", "selects no grid node"],
    );
    check_refused(
        &["--set", "materials.soil.density=0"],
        &["materials.soil.density"],
    );
}

/// Run a scene of `validation/failures/` into a temporary directory:
/// (exit code, messages, the temporary directory, the output folder).
fn run_failing(scene: &str) -> (i32, String, tempfile::TempDir, std::path::PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    let scene = common::validation(scene);
    let out = dir.path().join("out");
    let (code, text) = mpm_geo(&[
        "run",
        scene.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--quiet",
    ]);
    (code, text, dir, out)
}

#[test]
fn particle_leaving_the_grid_stops_the_run_and_keeps_the_curve() {
    let (code, text, _dir, out) = run_failing("failures/falls_out_of_grid.toml");
    assert_eq!(code, 1, "{text}");
    assert!(
        text.contains("left the grid") && text.contains("material point"),
        "{text}"
    );
    // the failing step number from the message, e.g. "run stopped: step 812 (t = ...)"
    let step: usize = text
        .split("run stopped: step ")
        .nth(1)
        .and_then(|s| s.split_whitespace().next())
        .and_then(|s| s.parse().ok())
        .expect("step in message");
    let curve = std::fs::read_to_string(out.join("curve.csv")).unwrap();
    let rows: Vec<&str> = curve.lines().skip(1).collect();
    assert_eq!(rows.len(), step, "rows for steps 0..{} expected", step - 1);
    assert!(rows.last().unwrap().starts_with(&format!("{},", step - 1)));
    let json = std::fs::read_to_string(out.join("run.json")).unwrap();
    assert!(json.contains("\"status\": \"failed\""), "{json}");
}

#[test]
fn singular_system_stops_the_run_with_a_solver_error() {
    let (code, text, _dir, out) = run_failing("failures/floating_body.toml");
    assert_eq!(code, 1, "{text}");
    assert!(
        text.contains("step 1") && text.contains("linear solver"),
        "{text}"
    );
    let curve = std::fs::read_to_string(out.join("curve.csv")).unwrap();
    assert_eq!(curve.lines().count(), 2, "header + step 0: {curve}");
}

/// A fixed explicit step that passes the wave-speed limit but not the limit
/// with the platen's penalty springs (DESIGN §4) is refused by `check`, naming
/// `scene.dt` (biaxial h = 1/300 m: wave limit 3.2e-5 s, combined 1.1e-5 s);
/// 8e-6 s is accepted.
#[test]
fn explicit_step_above_the_penalty_limit_is_refused_before_the_run() {
    let scene = common::validation("biaxial/local_h300.toml");
    let explicit = [
        "--set",
        "scene.analysis=explicit",
        "--set",
        "scene.end_time=0.01",
    ];
    let mut args = vec!["check", scene.to_str().unwrap()];
    args.extend_from_slice(&explicit);
    let mut refused = args.clone();
    refused.extend_from_slice(&["--set", "scene.dt=1.5e-5"]);
    let (code, text) = mpm_geo(&refused);
    assert_ne!(code, 0, "accepted: {text}");
    assert!(
        text.contains("scene.dt") && text.contains("penalty springs"),
        "{text}"
    );
    assert!(!text.contains("panicked"), "{text}");
    let mut accepted = args;
    accepted.extend_from_slice(&["--set", "scene.dt=8e-6"]);
    let (code, text) = mpm_geo(&accepted);
    assert_eq!(code, 0, "{text}");
}

/// GIMP needs point domains that tile the cells; a rigid body's contact kind
/// must be one of the two; a surface contact whose footprint leaves the
/// body's top is refused.
#[test]
fn shape_function_and_contact_options_are_checked() {
    check_refused(
        &["--set", "grid.shape_functions=\"gimp\""],
        &["grid.point_layout", "uniform"],
    );
    let platen = common::validation("elastic/platen.toml");
    let platen = platen.to_str().unwrap();
    let (code, text) = mpm_geo(&["check", platen, "--set", "bc.rigid.0.contact=\"edge\""]);
    assert_ne!(code, 0);
    assert!(
        text.contains("bc.rigid.contact") && text.contains("surface"),
        "{text}"
    );
    let (code, text) = mpm_geo(&[
        "check",
        platen,
        "--set",
        "bc.rigid.0.contact=\"surface\"",
        "--set",
        "bc.rigid.0.footprint=[0.1, 0.3]",
    ]);
    assert_ne!(code, 0);
    assert!(text.contains("bc.rigid[0].footprint"), "{text}");
    assert!(!text.contains("panicked"), "{text}");
}

#[test]
fn out_of_range_over_nonlocal_factor_and_unknown_lost_point_policy_are_refused() {
    let scene = common::validation("biaxial/nonlocal_h300.toml");
    let scene = scene.to_str().unwrap();
    for (set, needles) in [
        (
            "nonlocal.over_nonlocal=0.5",
            ["nonlocal.over_nonlocal", "[1, 3]"],
        ),
        ("grid.lost_points=\"drop\"", ["lost_points", "drop"]),
    ] {
        let (code, text) = mpm_geo(&["check", scene, "--set", set]);
        assert_ne!(code, 0, "accepted {set}: {text}");
        for n in needles {
            assert!(text.contains(n), "message lacks `{n}`: {text}");
        }
        assert!(!text.contains("panicked"), "{text}");
    }
}
