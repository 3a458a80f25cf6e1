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

/// A misspelt key in a `--set` is `SCENE_OVERRIDE`, naming the override and
/// the key meant (issue 41, item 11).
#[test]
fn unknown_key_is_refused_naming_it() {
    check_refused(
        &["--set", "grid.cel_size=0.1"],
        &[
            "error[SCENE_OVERRIDE]",
            "`grid.cel_size=0.1`",
            "unknown key `cel_size`",
            "did you mean `cell_size`?",
        ],
    );
}

/// A misspelt key in the file is reported with the file, line and column,
/// the line itself and the key meant (issue 41, item 11).
#[test]
fn unknown_key_in_file_is_refused_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(common::validation("elastic/oedometer.toml"))
        .unwrap()
        .replace("density = 2.0", "density = 2.0\ndensty = 2.0");
    let line = text.lines().position(|l| l == "densty = 2.0").unwrap() + 1;
    let path = dir.path().join("typo.toml");
    std::fs::write(&path, text).unwrap();
    let (code, msg) = mpm_geo(&["check", path.to_str().unwrap()]);
    assert_eq!(code, 2, "{msg}");
    let place = format!("error[SCENE_SYNTAX]: {}:{line}:1: ", path.display());
    assert!(msg.contains(&place), "lacks `{place}`: {msg}");
    assert!(
        msg.contains("unknown key `densty` in `materials.soil`; did you mean `density`?")
            && msg.contains(&format!("{line} | densty = 2.0")),
        "{msg}"
    );
}

/// Every command-line usage error carries `error[CLI_ARGUMENT]` and exits
/// with 2; numbers are asked for in plain words (issue 41, item 11); help
/// is no error.
#[test]
fn every_usage_error_carries_an_identifier() {
    let scene = common::validation("elastic/oedometer.toml");
    let scene = scene.to_str().unwrap();
    for args in [
        &["check", scene, "--bogus"][..],
        &["frobnicate"][..],
        &["check"][..],
        &[][..],
        &["run", scene, "--checkpoint-every", "0"][..],
        &["campaign", "validation/biaxial", "--jobs", "two"][..],
        &["point", "--steps", "-3"][..],
    ] {
        let (code, text) = mpm_geo(args);
        assert_eq!(code, 2, "{args:?}: {text}");
        assert!(text.contains("error[CLI_ARGUMENT]: "), "{args:?}: {text}");
        assert!(!text.contains("\nerror: "), "{args:?}: {text}");
    }
    let (_, text) = mpm_geo(&["campaign", "validation/biaxial", "--jobs", "two"]);
    assert!(
        text.contains("a whole number ≥ 1") && !text.contains("invalid digit"),
        "{text}"
    );
    let (code, text) = mpm_geo(&["check", "--help"]);
    assert_eq!(code, 0, "{text}");
    assert!(!text.contains("error["), "{text}");
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
/// with the platen's penalty springs (theory §4) is refused by `check`, naming
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
fn out_of_range_nonlocal_settings_lost_point_policy_and_volume_bound_are_refused() {
    let scene = common::validation("biaxial/nonlocal_h300.toml");
    let scene = scene.to_str().unwrap();
    for (set, needles) in [
        (
            "nonlocal.over_nonlocal=0.5",
            ["nonlocal.over_nonlocal", "[1, 3]"],
        ),
        ("grid.lost_points=\"drop\"", ["lost_points", "drop"]),
        (
            "nonlocal.weight_cache_mb=-1",
            ["nonlocal.weight_cache_mb", "[0, 1e6]"],
        ),
        (
            "nonlocal.grid_spacing_factor=0",
            ["nonlocal.grid_spacing_factor", "(0, 1]"],
        ),
        (
            "nonlocal.averaging=\"fft\"",
            ["nonlocal.averaging", "points"],
        ),
        // below a point's initial volume (1/2² of a cell), and not finite
        (
            "grid.max_point_volume=0.2",
            ["grid.max_point_volume", "0.25"],
        ),
        (
            "grid.max_point_volume=inf",
            ["grid.max_point_volume", "inf"],
        ),
    ] {
        let (code, text) = mpm_geo(&["check", scene, "--set", set]);
        assert_ne!(code, 0, "accepted {set}: {text}");
        for n in needles {
            assert!(text.contains(n), "message lacks `{n}`: {text}");
        }
        assert!(!text.contains("panicked"), "{text}");
    }
}

/// `check` on a validation scene with extra arguments: (exit code, messages).
fn check_scene(scene: &str, extra: &[&str]) -> (i32, String) {
    let scene = common::validation(scene);
    let mut args = vec!["check", scene.to_str().unwrap()];
    args.extend_from_slice(extra);
    mpm_geo(&args)
}

fn assert_refused(code: i32, text: &str, needles: &[&str]) {
    assert_eq!(code, 2, "not refused: {text}");
    for n in needles {
        assert!(text.contains(n), "message lacks `{n}`: {text}");
    }
    assert!(!text.contains("panicked"), "{text}");
}

/// A scene of 8e7 material points (the oedometer at h = 0.1 mm) is refused by
/// `check` before anything is seeded, naming the keys that drive the estimate
/// and the estimate; a grid of 3.9e7 cells around a small body is refused
/// under a 2 GB limit naming `grid.size`, and passes with a larger one.
#[test]
fn oversize_scenes_are_refused_by_check_naming_the_fields() {
    let (code, text) = check_scene(
        "elastic/oedometer.toml",
        &["--set", "grid.cell_size=0.0001"],
    );
    assert_refused(
        code,
        &text,
        &[
            "too large",
            "estimated memory",
            "material points",
            "grid.cell_size",
            "grid.points_per_cell",
            "body[0].box",
            "--max-memory",
        ],
    );
    let cells = ["--set", "grid.size=[624.0, 625.0]"];
    let (code, text) = check_scene(
        "elastic/oedometer.toml",
        &[cells[0], cells[1], "--max-memory", "2G"],
    );
    assert_refused(
        code,
        &text,
        &["3.900e7 grid cells", "grid.size", "2.000 GB"],
    );
    // the same limit as a scene key
    let (code, text) = check_scene(
        "elastic/oedometer.toml",
        &[cells[0], cells[1], "--set", "limits.max_memory_gb=2.0"],
    );
    assert_refused(code, &text, &["grid.size", "limits.max_memory_gb"]);
    // a valid scene reports its estimate; a limit below it refuses it
    let (code, text) = check_scene("elastic/oedometer.toml", &[]);
    assert_eq!(code, 0, "{text}");
    assert!(text.contains("estimated memory"), "{text}");
    let (code, text) = check_scene("elastic/oedometer.toml", &["--max-memory", "1M"]);
    assert_refused(code, &text, &["too large", "1.000 MB"]);
}

/// An explicit scene whose stable step is absurdly small (E = 1e300, or a
/// density, CFL or dt of 1e-300) would write rows forever: refused for its
/// step count naming the keys; a step limit set by `--max-steps` applies too.
#[test]
fn explicit_scene_with_absurd_step_count_is_refused() {
    for (set, key) in [
        ("materials.bar.E=1e300", "materials.bar.E"),
        ("materials.bar.density=1e-300", "materials.bar.density"),
        ("solver.cfl=1e-300", "solver.cfl"),
        ("scene.dt=1e-300", "scene.dt"),
    ] {
        let (code, text) = check_scene("elastic/bar_explicit.toml", &["--set", set]);
        assert_refused(code, &text, &["steps", "more than the limit", key]);
    }
    // the scene as written takes 0.4 s / (0.5 · h / c_p = 2.5e-4 s) = 1600 steps
    let (code, text) = check_scene("elastic/bar_explicit.toml", &["--max-steps", "1599"]);
    assert_refused(code, &text, &["1.600e3 steps", "scene.end_time", "1599"]);
    let (code, text) = check_scene("elastic/bar_explicit.toml", &["--max-steps", "1601"]);
    assert_eq!(code, 0, "{text}");
}

/// Non-finite input anywhere is refused naming the key.
#[test]
fn infinite_velocity_and_other_non_finite_values_are_refused_naming_the_key() {
    let (code, text) = check_scene(
        "elastic/bar_explicit.toml",
        &["--set", "body.0.velocity0=[-inf, 0.01]"],
    );
    assert_refused(code, &text, &["non-finite", "body[0].velocity0[0]"]);
    let (code, text) = check_scene(
        "elastic/platen.toml",
        &["--set", "bc.rigid.0.footprint=[0.0, nan]"],
    );
    assert_refused(code, &text, &["non-finite", "bc.rigid[0].footprint[1]"]);
}

/// Two conditions on one dof: fixed and a prescribed rate on the same line,
/// or two different rates, are refused naming both entries.
#[test]
fn contradictory_conditions_on_one_dof_are_refused_naming_both() {
    let (code, text) = check_scene(
        "elastic/oedometer.toml",
        &[
            "--set",
            "bc.prescribed=[{ line = \"y=0\", dof = \"y\", rate = -0.001 }]",
        ],
    );
    assert_refused(
        code,
        &text,
        &["bc.prescribed[0]", "bc.fixed[2]", "contradicts"],
    );
    // two rates on the top of the element path (the last used to win)
    let (code, text) = check_scene(
        "hmc/element_path.toml",
        &[
            "--set",
            "bc.prescribed=[{ line = \"y=0.05\", dof = \"y\", rate = -1e-5 }, { line = \"y=0.05\", dof = \"y\", rate = -2e-5 }]",
        ],
    );
    assert_refused(
        code,
        &text,
        &["bc.prescribed[1]", "bc.prescribed[0]", "contradicts"],
    );
    // crossing lines that agree at their node are accepted (the patch test)
    let (code, text) = check_scene("elastic/patch.toml", &[]);
    assert_eq!(code, 0, "{text}");
}

/// A fixed line on the top a rigid platen drives, and a second pressure on
/// a side already loaded, are refused naming both entries (issue 41, item 6).
#[test]
fn contradictory_boundary_entries_are_refused_naming_both() {
    let (code, text) = check_scene(
        "elastic/platen.toml",
        &[
            "--set",
            "bc.fixed=[{ line = \"x=0\", dofs = [\"x\"] }, { line = \"y=0\", dofs = [\"y\"] }, { line = \"y=0.2\", dofs = [\"y\"] }]",
        ],
    );
    assert_refused(
        code,
        &text,
        &[
            "error[SCENE_INVALID]",
            "bc.rigid[0]",
            "`platen`",
            "bc.fixed[2]",
        ],
    );
    let (code, text) = check_scene(
        "biaxial/local_h300.toml",
        &[
            "--set",
            "bc.pressure=[{ side = \"right\", p = 100.0 }, { side = \"top\", p = 100.0 }, { side = \"right\", p = 50.0 }]",
        ],
    );
    assert_refused(
        code,
        &text,
        &["bc.pressure[2]", "bc.pressure[0]", "150 kPa"],
    );
}

/// A bow-tie outline is refused naming the polygon and the crossing edges.
#[test]
fn self_intersecting_polygon_is_refused() {
    let (code, text) = check_scene(
        "elastic/lame_cylinder.toml",
        &[
            "--set",
            "body.0.polygon=[[0.1, 0.1], [1.0, 1.0], [1.0, 0.1], [0.1, 1.0]]",
        ],
    );
    assert_refused(
        code,
        &text,
        &["body[0].polygon", "edge 0", "edge 2", "crosses itself"],
    );
}

/// A value of the wrong type inside a material names the key, not only the table.
#[test]
fn type_error_inside_a_material_names_the_key() {
    let (code, text) = check_scene(
        "biaxial/local_h300.toml",
        &["--set", "materials.soil.phi_res=\"steep\""],
    );
    assert_refused(
        code,
        &text,
        &[
            "error[SCENE_OVERRIDE]",
            "`materials.soil.phi_res` must be a number, not the string \"steep\"",
        ],
    );
}

/// An initial stress far outside the yield surface is refused naming the body's key.
#[test]
fn initial_stress_far_outside_the_yield_surface_is_refused() {
    let (code, text) = check_scene(
        "biaxial/local_h300.toml",
        &["--set", "body.0.stress0=[1000.0, 1000.0, 1000.0, 0.0]"],
    );
    assert_refused(
        code,
        &text,
        &["body[0].stress0", "outside the yield surface"],
    );
}

/// A value that becomes NaN during a run stops it with the step, the point
/// and the variable (the one pass of the commit stage); an infinite monitor
/// stops it naming the monitor.
#[test]
fn non_finite_state_during_a_run_stops_it_with_point_and_step() {
    use mpm_physics::error::{RunError, StepError};
    // a NaN in a variable only the outputs read (the deformation gradient)
    let mut sim = common::simulation("elastic/bar_explicit.toml", &[]);
    sim.step_once().unwrap();
    sim.model.state.particles.def_grad[40][0] = f64::NAN;
    match sim.step_once() {
        Err(
            e @ RunError::Step {
                step: 2,
                cause:
                    StepError::NonFinitePoint {
                        particle: 40,
                        quantity: "deformation gradient",
                        ..
                    },
                ..
            },
        ) => assert!(e.to_string().contains("material point 40"), "{e}"),
        other => panic!(
            "expected a non-finite F at point 40, step 2, got {:?}",
            other.err()
        ),
    }
    // a NaN velocity spreads through the grid: the run stops at that step
    // naming a material point and the non-finite value
    let mut sim = common::simulation("elastic/bar_explicit.toml", &[]);
    sim.step_once().unwrap();
    sim.model.state.particles.velocity[40][1] = f64::NAN;
    let text = sim
        .step_once()
        .expect_err("the NaN stops the run")
        .to_string();
    assert!(
        text.starts_with("step 2 ")
            && text.contains("material point")
            && (text.contains("NaN") || text.contains("non-finite")),
        "{text}"
    );
    // a finite state whose monitor overflows: ½ m v² · scale with scale 1e308
    let mut sim = common::simulation("elastic/bar_explicit.toml", &["monitor.1.scale=1e308"]);
    for v in &mut sim.model.state.particles.velocity {
        v[1] = 1e10;
    }
    match sim.step_once() {
        Err(
            e @ RunError::Step {
                step: 1,
                cause: StepError::NonFiniteMonitor { .. },
                ..
            },
        ) => assert!(e.to_string().contains("kinetic_energy"), "{e}"),
        other => panic!(
            "expected a non-finite monitor at step 1, got {:?}",
            other.err()
        ),
    }
}
