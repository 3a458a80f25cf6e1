use super::*;

const MINIMAL: &str = r#"
        [scene]
        analysis = "quasi_static"
        steps = 1
        [grid]
        size = [1.0, 2.0]
        cell_size = 0.5
        [materials.soil]
        model = "linear_elastic"
        E = 1000.0
        nu = 0.3
        density = 2.0
        [[body]]
        material = "soil"
        box = [[0.0, 0.0], [1.0, 1.0]]
    "#;

#[test]
fn minimal_scene_loads_with_defaults() {
    let s = Scene::from_str_with_overrides(MINIMAL, "t", &[]).unwrap();
    assert_eq!(s.grid.points_per_cell, 2);
    assert_eq!(s.solver.tolerance_force, 1e-5);
    assert_eq!(s.grid_cells(), [2, 4]);
}

#[test]
fn overrides_change_values_and_reject_unknown_paths() {
    let s = Scene::from_str_with_overrides(
        MINIMAL,
        "t",
        &[
            "grid.cell_size=0.25".into(),
            "body.0.box=[[0.0,0.0],[0.5,0.5]]".into(),
        ],
    )
    .unwrap();
    assert_eq!(s.grid.cell_size, 0.25);
    assert_eq!(s.body[0].rectangle, Some([[0.0, 0.0], [0.5, 0.5]]));
    let e =
        Scene::from_str_with_overrides(MINIMAL, "t", &["gird.cell_size=0.25".into()]).unwrap_err();
    assert!(e.to_string().contains("gird"), "{e}");
    // a new key inside a known table is refused by deny_unknown_fields
    let e =
        Scene::from_str_with_overrides(MINIMAL, "t", &["grid.cel_size=0.25".into()]).unwrap_err();
    assert!(e.to_string().contains("cel_size"), "{e}");
}

/// An empty value removes a key, so that its default applies: the biaxial
/// scene's generalised-α gives way to Newmark γ = 0.6, which the scene
/// refuses beside ρ∞; a key inside an array's table goes too; an array
/// element cannot be removed.
#[test]
fn empty_override_removes_a_key() {
    let biaxial = include_str!("../../../validation/biaxial/local_h300.toml");
    let scene = |overrides: &[&str]| {
        let overrides: Vec<String> = overrides.iter().map(|o| o.to_string()).collect();
        Scene::from_str_with_overrides(biaxial, "biaxial", &overrides)
    };
    let both = scene(&["solver.newmark_gamma=0.6"]).unwrap_err();
    assert!(both.to_string().contains("newmark_gamma"), "{both}");
    let newmark = scene(&["solver.rho_infinity=", "solver.newmark_gamma=0.6"]).unwrap();
    assert_eq!(newmark.solver.rho_infinity, None);
    assert_eq!(newmark.solver.newmark_gamma, Some(0.6));
    let unnamed = scene(&["monitor.0.name="]).unwrap_err();
    assert!(unnamed.to_string().contains("name"), "{unnamed}");
    let element = scene(&["bc.fixed.0="]).unwrap_err();
    assert!(element.to_string().contains("array element"), "{element}");
    // removing what is not there changes nothing
    assert_eq!(
        scene(&["solver.no_such_key="]).unwrap(),
        scene(&[]).unwrap()
    );
}

#[test]
fn invalid_values_are_all_reported_with_field_names() {
    let bad = MINIMAL
        .replace("nu = 0.3", "nu = 0.5")
        .replace("cell_size = 0.5", "cell_size = 0.3");
    let e = Scene::from_str_with_overrides(&bad, "t", &[])
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("materials.soil.nu") && e.contains("(-1, 0.5)"),
        "{e}"
    );
    assert!(
        e.contains("grid.size[0]") && e.contains("whole number of cells"),
        "{e}"
    );
}

/// `linear_solver = "multifrontal"` loads; with faer's ordering or factorisation keys (which it
/// would ignore) it is refused naming them.
#[test]
fn multifrontal_refuses_faer_only_keys() {
    let set = |extra: &[&str]| {
        let mut o = vec!["solver.linear_solver=\"multifrontal\"".to_string()];
        o.extend(extra.iter().map(|s| s.to_string()));
        Scene::from_str_with_overrides(MINIMAL, "t", &o)
    };
    assert!(set(&[]).is_ok());
    let e = set(&[
        "solver.ordering=\"colamd\"",
        "solver.factorization=\"simplicial\"",
    ])
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("solver.ordering") && e.contains("solver.factorization"),
        "{e}"
    );
}

#[test]
fn gravity_ramp_steps_like_the_vertical_cut() {
    let l = LoadSpec {
        gravity: 0.0,
        gravity_ramp: Some(GravityRamp {
            increment: 0.981,
            interval: 0.001,
            max: 588.6,
        }),
    };
    assert!((l.gravity_at(0.001) - 0.981).abs() < 1e-12);
    assert!((l.gravity_at(0.0015) - 2.0 * 0.981).abs() < 1e-12);
    assert!((l.gravity_at(0.8) - 588.6).abs() < 1e-12);
    assert_eq!(l.gravity_at(0.0), 0.0);
}

#[test]
fn polygon_point_test() {
    let tri = [[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]];
    assert!(polygon_contains(&tri, [0.2, 0.2]));
    assert!(!polygon_contains(&tri, [0.6, 0.6]));
}

/// `model = "von_mises"` loads and builds; c = −1 is refused naming `materials.soil.c`; an unknown
/// key is refused naming the key (deny_unknown_fields).
#[test]
fn von_mises_material_loads_and_bad_keys_are_named() {
    let scene = MINIMAL.replace(
        "model = \"linear_elastic\"",
        "model = \"von_mises\"\n        c = 50.0",
    );
    let s = Scene::from_str_with_overrides(&scene, "t", &[]).unwrap();
    let spec = &s.materials["soil"];
    assert_eq!(
        spec,
        &MaterialSpec::VonMises(VonMisesSpec {
            youngs_modulus: 1000.0,
            poisson_ratio: 0.3,
            density: 2.0,
            undrained_strength: 50.0,
        })
    );
    assert_eq!(
        (spec.density(), spec.youngs_modulus(), spec.poisson_ratio()),
        (2.0, 1000.0, 0.3)
    );
    let law = crate::model::build_material("soil", spec).unwrap();
    assert_eq!(law.name(), "von_mises");
    assert!(law.has_symmetric_tangent() && !law.is_elastic() && !law.can_soften());

    let e = Scene::from_str_with_overrides(&scene.replace("c = 50.0", "c = -1.0"), "t", &[])
        .unwrap_err()
        .to_string();
    assert!(e.contains("materials.soil.c") && e.contains("c > 0"), "{e}");
    let e = Scene::from_str_with_overrides(&scene, "t", &["materials.soil.E=0.0".into()])
        .unwrap_err()
        .to_string();
    assert!(e.contains("materials.soil.E"), "{e}");

    let e = Scene::from_str_with_overrides(
        &scene.replace("c = 50.0", "c = 50.0\n        cu = 50.0"),
        "t",
        &[],
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("cu"), "{e}");
    let e = Scene::from_str_with_overrides(
        &scene.replace("c = 50.0", "c = 50.0\n        phi = 30.0"),
        "t",
        &[],
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("phi"), "{e}");
}

/// `solver.predictor` defaults to `motion`, is read by implicit dynamic runs only (set in a
/// quasi-static scene it is reported as unused, not refused), and an unknown value is refused
/// naming the key.
#[test]
fn predictor_is_used_by_implicit_dynamic_runs_only() {
    let s = Scene::from_str_with_overrides(MINIMAL, "t", &[]).unwrap();
    assert_eq!(s.solver.predictor, PredictorChoice::Motion);
    let unused = |analysis: &str| {
        let overrides = [
            format!("scene.analysis=\"{analysis}\""),
            "solver.predictor=\"zero\"".to_string(),
            "scene.dt=0.01".to_string(),
        ];
        let s = Scene::from_str_with_overrides(MINIMAL, "t", &overrides).unwrap();
        assert_eq!(s.solver.predictor, PredictorChoice::Zero);
        let warning = format!(
            "solver.predictor is set but not used with scene.analysis = \"{analysis}\" (ignored)"
        );
        assert_eq!(s.scene.analysis.key(), analysis, "the key parses back");
        s.warnings().contains(&warning)
    };
    assert!(unused("quasi_static"));
    assert!(!unused("implicit_dynamic"));
    let bad = Scene::from_str_with_overrides(MINIMAL, "t", &["solver.predictor=\"linear\"".into()]);
    assert!(bad.unwrap_err().to_string().contains("predictor"));
}

/// Generalised-α and adaptive steps: `rho_infinity` outside [0, 1] or beside
/// `newmark_gamma` is refused naming the field; adaptive steps need an
/// implicit dynamic run, and end at `steps` × `dt` without an `end_time`.
#[test]
fn time_scheme_keys_are_checked() {
    let dynamic = [
        "scene.analysis=\"implicit_dynamic\"",
        "scene.dt=0.01",
        "scene.steps=5",
    ];
    let set = |extra: &[&str]| {
        let o: Vec<String> = dynamic.iter().chain(extra).map(|s| s.to_string()).collect();
        Scene::from_str_with_overrides(MINIMAL, "t", &o)
    };
    assert!(set(&["solver.rho_infinity=0.8"]).is_ok());
    for (extra, field) in [
        (&["solver.rho_infinity=1.2"][..], "solver.rho_infinity"),
        (
            &["solver.rho_infinity=0.5", "solver.newmark_gamma=0.6"],
            "solver.rho_infinity",
        ),
        (
            &["solver.time_step=\"adaptive\"", "solver.error_tolerance=0"],
            "solver.error_tolerance",
        ),
        (
            &["solver.time_step=\"adaptive\"", "solver.dt_max=0.001"],
            "solver.dt_max",
        ),
        (
            &[
                "solver.time_step=\"adaptive\"",
                "scene.analysis=\"explicit\"",
                "scene.end_time=1.0",
            ],
            "solver.time_step",
        ),
    ] {
        let e = set(extra).unwrap_err().to_string();
        assert!(e.contains(field), "{extra:?}: {e}");
    }
    let adaptive = set(&["solver.time_step=\"adaptive\""]).unwrap();
    assert_eq!(adaptive.scene.end_time_or_steps(), 0.05);
    assert_eq!(adaptive.solver.step_bounds(0.01), (1e-5, 1.0));
}

/// The adaptive steps end at every jump of the stepped gravity: the next jump
/// after t is the end of t's interval, the jump just after a boundary is one
/// increment, and nothing jumps once the ramp is done.
#[test]
fn gravity_ramp_jumps_at_interval_ends() {
    let l = LoadSpec {
        gravity: 0.0,
        gravity_ramp: Some(GravityRamp {
            increment: 1.0,
            interval: 0.001,
            max: 3.0,
        }),
    };
    assert!((l.next_gravity_jump(0.0).unwrap() - 0.001).abs() < 1e-15);
    assert!((l.next_gravity_jump(0.0015).unwrap() - 0.002).abs() < 1e-15);
    assert!((l.next_gravity_jump(0.002 - 1e-16).unwrap() - 0.003).abs() < 1e-15);
    assert_eq!(l.gravity_jump_at(0.0), 1.0);
    assert_eq!(l.gravity_jump_at(0.002), 1.0);
    assert_eq!(l.gravity_jump_at(0.0015), 0.0);
    assert_eq!(l.next_gravity_jump(0.0035), None);
    assert_eq!(l.gravity_jump_at(0.003), 0.0);
}

/// A negative or non-finite `ramp_time` of a rigid body or a prescribed line
/// is refused naming its field; two prescribed entries moving one dof with
/// different ramps contradict each other.
#[test]
fn bad_ramp_times_are_refused_naming_the_field() {
    let driven = format!(
        "{MINIMAL}\n[bc]\n{}\n{}\n",
        r#"rigid = [{ name = "platen", footprint = [0.0, 1.0], velocity = [0.0, -0.01], ramp_time = -0.1 }]"#,
        r#"prescribed = [{ line = "x=1", dof = "x", rate = 0.01, ramp_time = nan }]"#
    );
    // nan is refused with every non-finite number, before the other checks
    let e = Scene::from_str_with_overrides(&driven, "t", &[])
        .unwrap_err()
        .to_string();
    assert!(e.contains("bc.prescribed[0].ramp_time"), "{e}");
    let negative = ["bc.prescribed.0.ramp_time=-1.0".into()];
    let e = Scene::from_str_with_overrides(&driven, "t", &negative)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("bc.rigid[0].ramp_time") && e.contains("got -0.1"),
        "{e}"
    );
    assert!(
        e.contains("bc.prescribed[0].ramp_time") && e.contains("got -1"),
        "{e}"
    );
    let fine = Scene::from_str_with_overrides(
        &driven,
        "t",
        &[
            "bc.rigid.0.ramp_time=0.1".into(),
            "bc.prescribed.0.ramp_time=0.0".into(),
        ],
    )
    .unwrap();
    assert_eq!(fine.bc.rigid[0].ramp_time, 0.1);
    let twice = format!(
        "{MINIMAL}\n[bc]\n{}\n",
        r#"prescribed = [{ line = "x=1", dof = "x", rate = 0.01 }, { line = "x=1", dof = "x", rate = 0.01, ramp_time = 1.0 }]"#
    );
    let e = Scene::from_str_with_overrides(&twice, "t", &[])
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("bc.prescribed[1]") && e.contains("ramp times 0 and 1"),
        "{e}"
    );
}

/// MINIMAL with a `[bc]` table holding `entries`.
fn with_bc(entries: &[&str]) -> String {
    format!("{MINIMAL}\n[bc]\n{}\n", entries.join("\n"))
}

/// The message of a refused scene (panics when it is accepted).
fn refusal(text: &str) -> String {
    Scene::from_str_with_overrides(text, "t", &[])
        .expect_err("contradictory scene accepted")
        .to_string()
}

/// Issue 41 item 6: a fixed or prescribed line through the top that a rigid
/// body drives is refused naming both entries, when it gives a driven
/// component another motion; a condition that agrees with the body (a
/// roller in x under a vertical platen, a prescribed line moving with it)
/// is accepted.
#[test]
fn a_line_holding_what_a_rigid_body_drives_is_refused_naming_both() {
    let platen =
        r#"rigid = [{ name = "platen", footprint = [0.0, 1.0], velocity = [0.0, -0.01] }]"#;
    let e = refusal(&with_bc(&[
        platen,
        r#"fixed = [{ line = "y=0", dofs = ["y"] }, { line = "y=1", dofs = ["y"] }]"#,
    ]));
    assert!(
        e.contains("bc.rigid[0]") && e.contains("bc.fixed[1]") && e.contains("`platen`"),
        "{e}"
    );
    assert!(!e.contains("bc.fixed[0]"), "the base is not driven: {e}");
    // a vertical line meeting the top, fixed in the driven component
    let e = refusal(&with_bc(&[
        platen,
        r#"fixed = [{ line = "y=0", dofs = ["y"] }, { line = "x=0", dofs = ["x", "y"] }]"#,
    ]));
    assert!(
        e.contains("bc.rigid[0]") && e.contains("bc.fixed[1]") && e.contains("(0, 1) m"),
        "{e}"
    );
    // a prescribed top moving otherwise than the platen
    let e = refusal(&with_bc(&[
        platen,
        r#"prescribed = [{ line = "y=1", dof = "y", rate = -0.02 }]"#,
    ]));
    assert!(
        e.contains("bc.rigid[0]") && e.contains("bc.prescribed[0]"),
        "{e}"
    );
    // conditions that agree with the platen
    for agreeing in [
        r#"fixed = [{ line = "y=0", dofs = ["y"] }, { line = "x=0", dofs = ["x"] }, { line = "y=1", dofs = ["x"] }]"#,
        r#"prescribed = [{ line = "y=1", dof = "y", rate = -0.01 }]"#,
    ] {
        let text = with_bc(&[platen, agreeing]);
        assert!(
            Scene::from_str_with_overrides(&text, "t", &[]).is_ok(),
            "{agreeing}"
        );
    }
}

/// Issue 41 item 6: two pressures on the same side of a box body (one
/// naming the body, one defaulting to it), or on overlapping edges of a
/// polygon body, are refused naming both entries and the sum they would
/// make; different sides and disjoint edges are accepted.
#[test]
fn pressures_that_would_add_up_are_refused_naming_both() {
    let e = refusal(&with_bc(&[
        r#"pressure = [{ side = "top", p = 100.0 }, { side = "right", p = 50.0 }, { body = "body0", side = "top", p = 20.0 }]"#,
    ]));
    assert!(
        e.contains("bc.pressure[2]") && e.contains("bc.pressure[0]") && e.contains("120 kPa"),
        "{e}"
    );
    assert!(!e.contains("bc.pressure[1]"), "{e}");
    let accepted =
        with_bc(&[r#"pressure = [{ side = "top", p = 100.0 }, { side = "right", p = 50.0 }]"#]);
    assert!(Scene::from_str_with_overrides(&accepted, "t", &[]).is_ok());
    let polygon = |edges: &str| {
        MINIMAL.replace(
            "box = [[0.0, 0.0], [1.0, 1.0]]",
            "polygon = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.5, 1.0], [0.0, 1.0]]",
        ) + &format!("\n[bc]\npressure = {edges}\n")
    };
    let e = refusal(&polygon(
        "[{ edges = [1, 2], p = 10.0 }, { edges = [2, 3], p = 10.0 }]",
    ));
    assert!(
        e.contains("bc.pressure[1]") && e.contains("bc.pressure[0]") && e.contains("edge 2"),
        "{e}"
    );
    let disjoint = polygon("[{ edges = [1, 2], p = 10.0 }, { edges = [3, 3], p = 10.0 }]");
    assert!(Scene::from_str_with_overrides(&disjoint, "t", &[]).is_ok());
}

/// Line and column (from 1) of the first `needle` in `text`.
fn line_and_column(text: &str, needle: &str) -> (usize, usize) {
    let at = text.find(needle).expect("needle in text");
    let line_start = text[..at].rfind('\n').map_or(0, |i| i + 1);
    (
        text[..at].matches('\n').count() + 1,
        text[line_start..at].chars().count() + 1,
    )
}

/// Issue 41 item 11: a misspelt key in the file is reported at its line and
/// column, with the line and the key it was meant to be; an override that is
/// fine does not take the blame.
#[test]
fn a_typo_in_the_file_gives_line_column_and_suggestion() {
    let typo = MINIMAL.replace("cell_size = 0.5", "cel_size = 0.5");
    let (line, column) = line_and_column(&typo, "cel_size");
    for overrides in [vec![], vec!["scene.steps=2".to_string()]] {
        let e = Scene::from_str_with_overrides(&typo, "typo.toml", &overrides).unwrap_err();
        assert_eq!(
            crate::error_id::Identified::error_id(&e),
            crate::error_id::ErrorId::SceneSyntax
        );
        let SceneError::Located {
            ref location,
            ref message,
            ..
        } = e
        else {
            panic!("no location: {e}");
        };
        assert_eq!((location.line, location.column), (line, column), "{e}");
        assert!(
            message.contains("unknown key `cel_size` in `grid`")
                && message.contains("did you mean `cell_size`?"),
            "{e}"
        );
        let shown = e.to_string();
        assert!(
            shown.starts_with(&format!("typo.toml:{line}:{column}: "))
                && shown.contains("cel_size = 0.5\n"),
            "{shown}"
        );
    }
}

/// Issue 41 item 11: a `--set` that names no key or gives a value of the
/// wrong type is `SCENE_OVERRIDE`, naming that override (not the ones
/// before it) with a suggestion or the value wanted in plain words.
#[test]
fn a_bad_override_is_scene_override_naming_it() {
    let set = |overrides: &[&str]| {
        let overrides: Vec<String> = overrides.iter().map(|o| o.to_string()).collect();
        Scene::from_str_with_overrides(MINIMAL, "t", &overrides).unwrap_err()
    };
    for (overrides, culprit, words) in [
        (
            &["scene.steps=2", "grid.cel_size=0.25"][..],
            "grid.cel_size=0.25",
            "did you mean `cell_size`?",
        ),
        (
            &["gird.cell_size=0.25"][..],
            "gird.cell_size=0.25",
            "did you mean `grid`?",
        ),
        (
            &["scene.steps=abc"][..],
            "scene.steps=abc",
            "a whole number ≥ 1",
        ),
        (
            &["scene.analysis=explict"][..],
            "scene.analysis=explict",
            "did you mean `explicit`?",
        ),
        (
            &["materials.soil.nu=true"][..],
            "materials.soil.nu=true",
            "`materials.soil.nu` must be a number",
        ),
    ] {
        let e = set(overrides);
        assert_eq!(
            crate::error_id::Identified::error_id(&e),
            crate::error_id::ErrorId::SceneOverride,
            "{e}"
        );
        let SceneError::Override { ref assignment, .. } = e else {
            panic!("{e}");
        };
        assert_eq!(assignment, culprit);
        assert!(e.to_string().contains(words), "{e}");
    }
}

/// Issue 41 item 11: values of the wrong type are described in plain words
/// with the key's range, at the value's position, also inside a material's
/// parameter table (whose errors toml places at the table's header).
#[test]
fn wrong_types_are_named_in_plain_words_at_the_value() {
    let located = |text: &str| match Scene::from_str_with_overrides(text, "t", &[]) {
        Err(SceneError::Located {
            location, message, ..
        }) => (location.line, location.column, message),
        other => panic!("{other:?}"),
    };
    let steps = MINIMAL.replace("steps = 1", "steps = 2.5");
    let (line, column, message) = located(&steps);
    assert_eq!((line, column), line_and_column(&steps, "2.5"));
    assert_eq!(message, "`scene.steps` must be a whole number ≥ 1, not 2.5");
    let mut messages = vec![message];
    let young = MINIMAL.replace("E = 1000.0", "E = \"stiff\"");
    let (line, column, message) = located(&young);
    assert_eq!((line, column), line_and_column(&young, "\"stiff\""));
    assert!(
        message.starts_with("`materials.soil.E` must be a number, not the string \"stiff\""),
        "{message}"
    );
    messages.push(message);
    let extra = MINIMAL.replace("nu = 0.3", "nu = 0.3\nnu0 = 0.2");
    let (line, column, message) = located(&extra);
    assert_eq!((line, column), line_and_column(&extra, "nu0"));
    assert!(message.contains("did you mean `nu`?"), "{message}");
    messages.push(message);
    for message in &messages {
        for rust_type in ["usize", "f64", "expected", "invalid type"] {
            assert!(!message.contains(rust_type), "{message}");
        }
    }
}

/// A monitor's `curve.csv` column is its name and its unit: one that ends in
/// a column already taken (a step column, another monitor's) is refused
/// naming the column; distinct columns load.
#[test]
fn monitor_columns_must_be_distinct() {
    let with_monitors = |monitors: &str| {
        Scene::from_str_with_overrides(&format!("{MINIMAL}\n{monitors}"), "t", &[])
    };
    let monitor =
        |name: &str, kind: &str| format!("[[monitor]]\nname = \"{name}\"\nkind = \"{kind}\"\n");
    let taken = with_monitors(&monitor("error_estimate", "max_plastic_strain"))
        .unwrap_err()
        .to_string();
    assert!(taken.contains("`error_estimate_1`"), "{taken}");
    let both = format!(
        "{}{}",
        monitor("energy", "kinetic_energy"),
        monitor("energy_kJ_per", "run_out")
    );
    let taken = with_monitors(&both).unwrap_err().to_string();
    assert!(
        taken.contains("monitor[1].name") && taken.contains("`energy_kJ_per_m`"),
        "{taken}"
    );
    let scene = with_monitors(&format!(
        "{}{}",
        monitor("energy", "kinetic_energy"),
        monitor("front", "run_out")
    ))
    .unwrap();
    let columns: Vec<String> = scene.monitor.iter().map(|m| m.column()).collect();
    assert_eq!(columns, ["energy_kJ_per_m", "front_m"]);
}

/// A path-following run is budgeted at its most steps, `path_max_steps`
/// (10 × the nominal steps by default), not at its nominal step count.
#[test]
fn a_path_following_run_is_estimated_at_its_step_budget() {
    let biaxial = include_str!("../../../validation/biaxial/local_h300.toml");
    let path = |extra: &[&str]| {
        let overrides: Vec<String> = [
            "scene.analysis=\"quasi_static\"",
            "solver.rho_infinity=",
            "bc.rigid.0.ramp_time=0",
            "solver.path_following=\"dissipation\"",
        ]
        .iter()
        .chain(extra)
        .map(|o| o.to_string())
        .collect();
        Scene::from_str_with_overrides(biaxial, "biaxial", &overrides).unwrap()
    };
    let nominal = path(&[]).scene.steps.unwrap() as f64;
    assert_eq!(path(&[]).estimate_resources().steps, 10.0 * nominal);
    let capped = path(&["solver.path_max_steps=500"]).estimate_resources();
    assert_eq!(capped.steps, 500.0);
    assert!(
        capped.steps_reason.contains("path_max_steps"),
        "{}",
        capped.steps_reason
    );
}

/// `solver.max_correction` must be a positive number of cells and belongs
/// to implicit Newton steps without path following: otherwise it is refused
/// naming the field; on its own it is accepted.
#[test]
fn correction_limit_is_checked() {
    let set = |extra: &[&str]| {
        let o: Vec<String> = extra.iter().map(|s| s.to_string()).collect();
        Scene::from_str_with_overrides(MINIMAL, "t", &o)
    };
    assert_eq!(
        set(&["solver.max_correction=0.5"])
            .unwrap()
            .solver
            .max_correction,
        Some(0.5)
    );
    for (extra, message) in [
        (vec!["solver.max_correction=0"], "must be > 0"),
        (vec!["solver.max_correction=-1"], "must be > 0"),
        (
            vec!["solver.max_correction=0.5", r#"scene.analysis="explicit""#],
            "without path following",
        ),
    ] {
        let e = set(&extra).unwrap_err().to_string();
        assert!(
            e.contains("solver.max_correction") && e.contains(message),
            "{e}"
        );
    }
}

/// `solver.remember_halvings` belongs to fixed implicit steps: with adaptive
/// steps it is refused naming the field; on its own it is accepted.
#[test]
fn remembered_halvings_are_refused_with_adaptive_steps() {
    let set = |extra: &[&str]| {
        let mut o = vec!["solver.remember_halvings=true".to_string()];
        o.extend(extra.iter().map(|s| s.to_string()));
        Scene::from_str_with_overrides(MINIMAL, "t", &o)
    };
    assert!(set(&[]).unwrap().solver.remember_halvings);
    let e = set(&[
        r#"scene.analysis="implicit_dynamic""#,
        "scene.dt=0.1",
        r#"solver.time_step="adaptive""#,
    ])
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("solver.remember_halvings") && e.contains("fixed implicit steps only"),
        "{e}"
    );
}
