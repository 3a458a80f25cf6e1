//! Issue 41, item 5 (second half): a scene whose run would take hours is told
//! so by `check` and at the start of `run`, from an estimate of the step
//! count times the cost of a step (`physics/src/scene/run_time.rs`). These tests
//! check the model's behaviour, not a measured time: the estimate grows in
//! proportion to the steps, grows with the size, and puts the issue's
//! example (the biaxial test with E = 10¹² kPa, measured at 16 s of CPU time
//! a step) and its explicit twin beyond an hour; `check` and `run` print it.

mod common;

use std::process::Command;

use mpm_physics::scene::LONG_RUN_SECONDS;

/// The estimated run time of a validation scene with `overrides`, s.
fn estimate(path: &str, overrides: &[&str]) -> f64 {
    common::scene(path, overrides).estimate_run_time().seconds
}

/// Overrides that turn the implicit biaxial scenes into their explicit twin
/// (to the same end, 0.226 s).
const EXPLICIT: [&str; 6] = [
    "scene.analysis=explicit",
    "scene.end_time=0.226",
    "scene.steps=",
    "scene.dt=",
    "solver.newmark_gamma=",
    "solver.max_iterations=",
];

#[test]
fn the_estimate_is_proportional_to_the_steps() {
    let implicit = |steps: &str| estimate("elastic/bar_implicit.toml", &[steps]);
    let ratio = implicit("scene.steps=400") / implicit("scene.steps=200");
    assert!((ratio - 2.0).abs() < 1e-12, "implicit: ×{ratio}");
    let explicit = |end: &str| estimate("elastic/bar_explicit.toml", &[end]);
    let ratio = explicit("scene.end_time=0.2") / explicit("scene.end_time=0.1");
    assert!((ratio - 2.0).abs() < 1e-9, "explicit: ×{ratio}");
}

/// At the same step count, the finer biaxial mesh (h = 1/1000 m: 11 times
/// the points, 10 times the unknowns) costs more than 10 times the coarse
/// one (h = 1/300 m).
#[test]
fn the_estimate_grows_with_the_size() {
    let coarse = estimate("biaxial/nonlocal_h300.toml", &[]);
    let fine = estimate("biaxial/nonlocal_h1000.toml", &["scene.steps=226"]);
    assert!(fine > 10.0 * coarse, "{fine} s against {coarse} s");
}

/// The example: E = 10¹² kPa on `nonlocal_h300` drives every point
/// far past its strength in one step (a load-step ratio of 10⁶): more than
/// an hour, where the scene as written is estimated at under a minute.
/// Explicit, its stable step falls to 7e-10 s: more than an hour too.
#[test]
fn a_stiff_scene_is_estimated_at_hours() {
    let scene = "biaxial/nonlocal_h300.toml";
    let as_written = common::scene(scene, &[]).estimate_run_time();
    assert!(as_written.seconds < 60.0, "{as_written}");
    assert!(as_written.long_run_warning().is_none());
    let stiff = common::scene(scene, &["materials.soil.E=1e12"]).estimate_run_time();
    assert!(stiff.seconds > LONG_RUN_SECONDS, "{stiff}");
    assert!(stiff.load_step_ratio > 1e5, "{stiff}");
    let warning = stiff.long_run_warning().expect("a warning");
    assert!(warning.contains("strength"), "{warning}");
    let mut explicit: Vec<&str> = EXPLICIT.to_vec();
    explicit.extend(["materials.soil.E=1e12", "limits.max_steps=1000000000"]);
    let stiff_explicit = common::scene(scene, &explicit).estimate_run_time();
    assert!(
        stiff_explicit.seconds > LONG_RUN_SECONDS,
        "{stiff_explicit}"
    );
    assert!(stiff_explicit.steps > 1e8, "{stiff_explicit}");
}

/// `mpm-geo ARGS`: (success, stdout, stderr).
fn mpm_geo(args: &[&str]) -> (bool, String, String) {
    let output = Command::new(env!("CARGO_BIN_EXE_mpm-geo"))
        .args(args)
        .output()
        .unwrap();
    (
        output.status.success(),
        String::from_utf8_lossy(&output.stdout).into_owned(),
        String::from_utf8_lossy(&output.stderr).into_owned(),
    )
}

#[test]
fn check_prints_the_estimate_and_warns_of_hours() {
    let scene = common::validation("biaxial/nonlocal_h300.toml");
    let scene = scene.to_str().unwrap();
    let (ok, out, err) = mpm_geo(&["check", scene]);
    assert!(ok, "{err}");
    assert!(
        out.contains("estimated run time") && out.contains("a rough estimate"),
        "{out}"
    );
    assert!(!err.contains("the run is estimated to take"), "{err}");
    let (ok, out, err) = mpm_geo(&["check", scene, "--set", "materials.soil.E=1e12"]);
    assert!(ok, "{err}");
    assert!(out.contains("estimated run time"), "{out}");
    assert!(
        err.contains("warning: the run is estimated to take") && err.contains(" h,"),
        "{err}"
    );
}

#[test]
fn run_prints_the_estimate_at_its_start_unless_quiet() {
    let dir = tempfile::tempdir().unwrap();
    let scene = common::validation("elastic/bar_implicit.toml");
    let run = |out: &str, quiet: bool| {
        let out = dir.path().join(out);
        let mut args = vec![
            "run",
            scene.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--set",
            "scene.steps=5",
        ];
        if quiet {
            args.push("--quiet");
        }
        let (ok, _, err) = mpm_geo(&args);
        assert!(ok, "{err}");
        err
    };
    let told = run("told", false);
    let first = told.lines().next().unwrap_or_default();
    assert!(first.starts_with("estimated run time"), "{told}");
    let quiet = run("quiet", true);
    assert!(!quiet.contains("estimated run time"), "{quiet}");
}
