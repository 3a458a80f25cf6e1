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
