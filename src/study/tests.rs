//! Unit tests of the study spec, its plan and the report's selections.

use super::*;

const SPEC: &str = r#"
[study]
name = "t"
scene = "validation/elastic/bar_implicit.toml"
set = ["scene.steps=100"]

[reference]
kind = "series"

[[quantity]]
monitor = "top_uy"

[[axis]]
name = "nu"
key = "materials.bar.nu"
values = [0.0, 0.2]

[[series]]
label = "implicit"
refine = "dt"
values = [4e-4, 1e-4]
reference_value = 1e-5

[[series]]
label = "explicit"
integrator = "explicit"
refine = "solver.cfl"
values = [0.5]
reference_value = 0.01
"#;

fn spec(text: &str) -> Result<StudySpec, StudyError> {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("spec.toml");
    let text = text.replace(
        "validation/",
        &format!("{}/validation/", env!("CARGO_MANIFEST_DIR")),
    );
    std::fs::write(&path, text).expect("write spec");
    StudySpec::load(&path)
}

/// Axes cross every series; `dt` keeps the end time (steps × Δt); the
/// explicit series runs the twin; every method gets its own reference run.
#[test]
fn plan_crosses_axes_and_keeps_the_end_time() {
    let plan = spec(SPEC).unwrap().plan().unwrap();
    assert_eq!(plan.runs.len(), 2 * 2 + 2);
    assert_eq!(plan.references.len(), 4);
    let fine = &plan.runs[1];
    assert_eq!(fine.scene.scene.steps, Some(200));
    assert_eq!(fine.scene.scene.dt, Some(1e-4));
    assert_eq!(fine.axes, vec![("nu".to_string(), "0.0".to_string())]);
    let explicit = plan.runs.last().unwrap();
    assert_eq!(
        explicit.scene.scene.analysis,
        crate::scene::AnalysisKind::Explicit
    );
    assert_eq!(explicit.scene.solver.cfl, 0.5);
    assert!((explicit.scene.scene.end_time.unwrap() - 0.02).abs() < 1e-15);
    assert_eq!(plan.runs[2].method, "implicit, nu = 0.2");
    assert!(plan
        .runs
        .iter()
        .all(|r| r.scene.output.snapshots.is_empty()));
}

/// A resolved scene written as TOML reads back as the same scene (each run
/// is executed from its written `scene.toml`).
#[test]
fn planned_scenes_round_trip_through_toml() {
    let plan = spec(SPEC).unwrap().plan().unwrap();
    for run in &plan.runs {
        let text = toml::to_string(&run.scene).unwrap();
        let back = crate::scene::Scene::from_str_with_overrides(&text, "rt", &[]).unwrap();
        assert_eq!(
            format!("{back:?}"),
            format!("{:?}", run.scene),
            "{}",
            run.name
        );
    }
}

/// Bad specs are refused naming the field.
#[test]
fn bad_specs_name_the_field() {
    let cases = [
        ("repeats = 0\n", "[study]\nname = \"t\"\n", "study.repeats"),
        ("", "reference_value = 1e-5\n", "series[0].reference_value"),
        ("", "values = [4e-4, 1e-4]\n", "series"),
        ("", "key = \"materials.bar.nu\"\n", "axis[0].values"),
    ];
    let bad = [
        SPEC.replace(
            "set = [\"scene.steps=100\"]",
            "set = [\"scene.steps=100\"]\nrepeats = 0",
        ),
        SPEC.replacen("reference_value = 1e-5\n", "", 1),
        SPEC.replacen("values = [4e-4, 1e-4]", "values = [4e-4, -1.0]", 1),
        SPEC.replace("key = \"materials.bar.nu\"\n", ""),
    ];
    for ((_, _, field), text) in cases.iter().zip(&bad) {
        let message = match spec(text) {
            Ok(_) => panic!("{field}: accepted\n{text}"),
            Err(e) => e.to_string(),
        };
        assert!(message.contains(field), "{field}: {message}");
    }
    let unknown = SPEC.replace("[reference]", "[reference]\ncolour = 1");
    assert!(spec(&unknown).unwrap_err().to_string().contains("colour"));
    // an invalid value reaches the scene validation before anything runs
    let invalid = SPEC.replace("values = [0.0, 0.2]", "values = [0.0, 0.7]");
    let message = spec(&invalid).unwrap().plan().unwrap_err().to_string();
    assert!(message.contains("nu"), "{message}");
}

fn row(method: &str, wall: f64, error: f64) -> StudyRow {
    let plan = spec(SPEC).unwrap().plan().unwrap();
    let mut planned = plan.runs[0].clone();
    planned.method = method.into();
    planned.name = format!("{method}{wall}");
    StudyRow {
        planned,
        measured: Measured {
            wall_seconds: vec![wall],
            stage_seconds: Vec::new(),
            status: "completed".into(),
            steps: 1,
            newton_iterations: 0,
            factorisations: 0,
            halvings: 0,
            linear: Default::default(),
            histories: Vec::new(),
        },
        errors: vec![Some(error)],
    }
}

/// The Pareto front keeps the runs no other run beats in both time and
/// error; two methods whose time-to-error lines cross give one crossover.
#[test]
fn pareto_front_and_crossover() {
    // A: cheap but slow to converge (error ∝ 1/t); B: costly start, fast convergence (∝ 1/t³)
    let rows: Vec<StudyRow> = [1.0, 2.0, 4.0]
        .iter()
        .map(|&t| row("A", t, 0.1 / t))
        .chain(
            [2.0, 4.0, 8.0]
                .iter()
                .map(|&t| row("B", t, 0.8 / (t * t * t))),
        )
        .collect();
    let front: Vec<String> = pareto_front(&rows)
        .into_iter()
        .map(|i| rows[i].planned.name.clone())
        .collect();
    assert_eq!(front, ["A1", "A2", "B4", "B8"]);
    let crossings = crossovers(&rows);
    assert_eq!(crossings.len(), 1, "{crossings:?}");
    let c = &crossings[0];
    assert_eq!(
        (c.faster_below.as_str(), c.faster_above.as_str()),
        ("B", "A")
    );
    // analytic: 0.1/t = 0.8/t³ → t = √8, error 0.1/√8 (lines are straight in log–log)
    assert!((c.wall_seconds - 8f64.sqrt()).abs() < 1e-9, "{c:?}");
    assert!((c.error - 0.1 / 8f64.sqrt()).abs() < 1e-12, "{c:?}");
}

/// Every shipped study spec in `validation/studies/` reads and plans (every
/// run's scene is valid), so the specs cannot drift from the scene types.
#[test]
fn shipped_specs_plan() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("validation/studies");
    let mut planned = 0;
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "toml") {
            let plan = StudySpec::load(&path)
                .and_then(|s| s.plan())
                .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
            assert!(!plan.runs.is_empty(), "{}", path.display());
            planned += 1;
        }
    }
    assert!(planned >= 4, "{planned} specs");
}

/// A case study: every case with every series (a series without `refine` is
/// one run), each case with its own scene, overrides, time step, reference
/// and quantities.
const CASES: &str = r#"
[study]
name = "cases"
scene = "validation/elastic/bar_implicit.toml"
set = ["scene.steps=100"]
timeout = 60

[reference]
kind = "closed_form"
name = "bar_vibration"
monitor = "top_uy"

[[quantity]]
monitor = "top_uy"

[[series]]
label = "implicit"

[[series]]
label = "explicit"
integrator = "explicit"

[[case]]
name = "nu"
set = ["materials.bar.nu=0.49"]

[[case]]
name = "big step"
dt = 5e-3

[[case]]
name = "column"
scene = "validation/elastic/soft_column.toml"
reference = { kind = "closed_form", name = "column_settlement", monitor = "top_settlement" }
quantity = [{ monitor = "top_settlement", measure = "at_time", time = 1.0 }]

[[case]]
name = "biaxial"
scene = "validation/biaxial/local_h300.toml"
set = ["scene.steps=3"]
reference = { kind = "run", set = ["scene.dt=5e-4", "scene.steps=6"] }
quantity = [{ monitor = "load" }]

[[case]]
name = "cut"
scene = "validation/vertical_cut/local_h100.toml"
set = ["materials.soil.c_ini=0"]
reference = { kind = "none", why = "no closed form" }
"#;

#[test]
fn case_study_plans_every_case_with_every_series() {
    let plan = spec(CASES).unwrap().plan().unwrap();
    assert_eq!(plan.runs.len(), 5 * 2);
    let run = |case: &str, series: usize| {
        plan.runs
            .iter()
            .find(|r| r.case.as_deref() == Some(case) && r.series == series)
            .unwrap()
    };
    // ν = 0.49: the closed form's wave speed is the P-wave speed of the scene
    let nu = run("nu", 1);
    assert_eq!(nu.name, "c00_m01_nu_explicit");
    assert_eq!(nu.refused, None);
    let RunReference::ClosedForm(ClosedForm::Bar(bar)) = &nu.reference else {
        panic!("{:?}", nu.reference)
    };
    assert!((bar.wave_speed - (1e4 * 0.51 / (1.49 * 0.02f64)).sqrt()).abs() < 1e-9);
    // the case's Δt: the implicit run keeps its end time, the explicit one is
    // refused above its stability limit (recorded, not an error of the plan)
    let implicit = run("big step", 0);
    assert_eq!(implicit.scene.scene.steps, Some(4));
    assert_eq!(implicit.refine, Some(("dt".to_string(), 5e-3)));
    let explicit = run("big step", 1);
    let why = explicit.refused.as_deref().unwrap();
    assert!(
        why.contains("scene.dt") && why.contains("stability limit"),
        "{why}"
    );
    // a quasi-static case has no explicit twin: refused with the reason
    let why = run("column", 1).refused.as_deref().unwrap();
    assert!(why.contains("explicit twin"), "{why}");
    assert!(matches!(
        run("column", 0).reference,
        RunReference::ClosedForm(ClosedForm::Column(_))
    ));
    assert_eq!(run("column", 0).quantities[0].monitor, "top_settlement");
    // a `run` reference: one reference run per case, with the case's scene
    assert_eq!(plan.references.len(), 1);
    assert_eq!(plan.references[0].name, "c03_reference");
    assert_eq!(plan.references[0].scene.scene.steps, Some(6));
    assert_eq!(
        run("biaxial", 0).reference,
        RunReference::Run("c03_reference".into())
    );
    // a parameter out of range is the case's outcome in both integrators
    for s in 0..2 {
        let why = run("cut", s).refused.as_deref().unwrap();
        assert!(why.contains("c_ini"), "{why}");
    }
    assert!(plan.runs.iter().filter(|r| r.refused.is_none()).all(|r| r
        .scene
        .output
        .snapshots
        .is_empty()
        && r.scene.output.snapshot_times.is_empty()));
}

/// A misspelt key stops a case study before anything runs (only the
/// validation's refusals are outcomes).
#[test]
fn case_study_stops_on_a_misspelt_override() {
    let bad = CASES.replace("materials.bar.nu=0.49", "materials.bar.poisson=0.49");
    let message = spec(&bad).unwrap().plan().unwrap_err().to_string();
    assert!(message.contains("poisson"), "{message}");
}

/// Bad case-study specs are refused naming the field.
#[test]
fn bad_case_specs_name_the_field() {
    let cases = [
        (
            CASES.replace("name = \"nu\"\n", "name = \"nu\"\ncolour = 1\n"),
            "colour",
        ),
        (
            CASES.replace(
                "reference = { kind = \"none\", why = \"no closed form\" }",
                "reference = { kind = \"series\" }",
            ),
            "case[4].reference.kind",
        ),
        (
            CASES.replace("why = \"no closed form\"", "why = \" \""),
            "case[4].reference.why",
        ),
        (
            CASES.replace("label = \"implicit\"", "label = \"implicit\"\nvalues = [1.0]"),
            "series[0].values",
        ),
        (
            CASES.replace("label = \"implicit\"", "label = \"implicit\"\nrefine = \"dt\"\nvalues = [1e-3]"),
            "case[1].dt",
        ),
        (
            CASES.replace("dt = 5e-3", "dt = -1.0"),
            "case[1].dt",
        ),
        (
            CASES.replace("name = \"big step\"", "name = \"nu\""),
            "case[1].name",
        ),
        (
            CASES.replace("timeout = 60", "timeout = 0"),
            "study.timeout",
        ),
        (
            CASES.replace(
                "monitor = \"top_settlement\" }",
                "monitor = \"top_settlement\", parameters = { height = 1.0, wave_speed = 1.0, velocity = 1.0 } }",
            ),
            "case[2].reference.parameters",
        ),
        (
            CASES.replace("measure = \"at_time\", time = 1.0", "measure = \"period\""),
            "case[2].quantity[0].measure",
        ),
        // the spec's quantity is not on the case's closed-form monitor
        (
            CASES.replace(
                "quantity = [{ monitor = \"top_settlement\", measure = \"at_time\", time = 1.0 }]",
                "",
            ),
            "case[2]",
        ),
        (
            CASES.replace("kind = \"closed_form\"\nname", "kind = \"series\"\nname"),
            "reference",
        ),
    ];
    for (text, field) in &cases {
        let message = match spec(text) {
            Ok(_) => panic!("{field}: accepted\n{text}"),
            Err(e) => e.to_string(),
        };
        assert!(message.contains(field), "{field}: {message}");
    }
}

/// A run without a reference has no error (not zero); a stated outcome is
/// completed, or stopped / refused with a reason.
#[test]
fn outcomes_and_missing_references() {
    let mut r = row("A", 1.0, 0.1);
    assert_eq!(r.error(), Some(0.1));
    r.planned.reference = RunReference::Unavailable("none".into());
    assert_eq!(r.error(), None);
    assert!(r.measured.stated());
    for (status, stated) in [
        ("stopped: step 3: Newton did not converge", true),
        ("refused: scene.dt: too large", true),
        ("stopped: ", false),
        (
            "panicked: thread 'main' panicked at src/x.rs:1:1: boom",
            false,
        ),
        ("timed out: killed after 60.0 s", false),
        ("killed: signal 9", false),
    ] {
        r.measured.status = status.into();
        assert_eq!(r.measured.stated(), stated, "{status}");
    }
}

/// A run process that panics (exit code 101) or outlives `study.timeout` is
/// recorded as such, not as a refusal: neither is a stated outcome. (A
/// stand-in executable plays the run.)
#[cfg(unix)]
#[test]
fn panics_and_time_outs_are_faults() {
    use std::os::unix::fs::PermissionsExt;
    let dir = tempfile::tempdir().unwrap();
    let planned = spec(SPEC).unwrap().plan().unwrap().runs[0].clone();
    let script = |name: &str, body: &str| {
        let path = dir.path().join(name);
        std::fs::write(&path, format!("#!/bin/sh\n{body}\n")).unwrap();
        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o755)).unwrap();
        path
    };
    let panics = script(
        "panics",
        "echo \"thread 'main' (7) panicked at src/x.rs:1:2:\" >&2; echo 'index out of bounds' >&2; exit 101",
    );
    let m = super::execute::execute(&panics, &planned, &dir.path().join("a"), 3, None).unwrap();
    assert!(
        m.status.starts_with("panicked: ") && m.status.contains("index out of bounds"),
        "{}",
        m.status
    );
    assert!(!m.stated());
    assert_eq!(m.wall_seconds.len(), 1, "a panic is not repeated");
    let hangs = script("hangs", "sleep 20");
    let start = std::time::Instant::now();
    let m = super::execute::execute(&hangs, &planned, &dir.path().join("b"), 1, Some(0.3)).unwrap();
    assert!(m.status.starts_with("timed out: "), "{}", m.status);
    assert!(!m.stated());
    assert!(start.elapsed().as_secs_f64() < 10.0);
    let stops = script(
        "stops",
        "echo 'error: run stopped: step 3: NaN' >&2; exit 1",
    );
    let m = super::execute::execute(&stops, &planned, &dir.path().join("c"), 1, None).unwrap();
    assert_eq!(m.status, "stopped: run stopped: step 3: NaN");
    assert!(m.stated());
    let refuses = script(
        "refuses",
        "printf 'error: scene s is invalid:\\n  - scene.dt: too large\\n  - solver.cfl: too large\\n' >&2; exit 2",
    );
    let m = super::execute::execute(&refuses, &planned, &dir.path().join("d"), 1, None).unwrap();
    assert_eq!(
        m.status,
        "refused: scene s is invalid: scene.dt: too large; solver.cfl: too large"
    );
}
