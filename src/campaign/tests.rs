use std::path::{Path, PathBuf};

use super::report::{read_curve, write_outputs};
use super::*;
use crate::scene::Scene;

fn validation_scene(name: &str, overrides: &[&str]) -> Scene {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("validation")
        .join(name);
    let overrides: Vec<String> = overrides.iter().map(|o| o.to_string()).collect();
    Scene::load(&path, &overrides).expect("valid scene")
}

fn write_file(dir: &Path, name: &str, text: &str) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, text).expect("write test file");
    path
}

/// The load curve is read from the columns of the scene's displacement and force
/// monitors, whatever their names: rigid-body monitors first, point displacement and
/// reaction otherwise; δ = −displacement. Columns named `load` and `top_uy` that
/// belong to no such monitor are ignored.
#[test]
fn curve_is_read_through_the_scene_monitors() {
    let biaxial = validation_scene(
        "biaxial/local_h300.toml",
        &["monitor.0.name=platen_force", "monitor.1.name=platen_uy"],
    );
    let columns = CurveColumns::of_scene(&biaxial).expect("biaxial has a load curve");
    assert_eq!(columns.force, "platen_force");
    assert_eq!(columns.displacement, "platen_uy");

    let dir = tempfile::tempdir().unwrap();
    let path = write_file(
        dir.path(),
        "curve.csv",
        "step,time,load,top_uy,platen_force,platen_uy\n\
         0,0e0,9e0,9e0,3e0,-0e0\n\
         1,1e-3,9e0,9e0,3.5e0,-1e-5\n",
    );
    let curve = read_curve(&path, &columns).unwrap();
    assert_eq!(curve, vec![(0.0, 3.0), (1e-5, 3.5)]);

    let oedometer = CurveColumns::of_scene(&validation_scene("elastic/oedometer.toml", &[]));
    assert_eq!(
        oedometer,
        Some(CurveColumns {
            displacement: "top_settlement".into(),
            force: "base_reaction".into(),
        })
    );
    assert_eq!(
        CurveColumns::of_scene(&validation_scene("elastic/patch.toml", &[])),
        None
    );
}

/// A curve that is missing, empty, lacks a column or holds a row that does not parse
/// is refused with a message naming the file and the problem; the partial curve of a
/// run that stopped mid-way is read.
#[test]
fn unreadable_curve_is_refused_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let columns = CurveColumns {
        displacement: "top_uy".into(),
        force: "load".into(),
    };
    let header = "step,time,load,top_uy\n";
    let cases = [
        ("empty.csv", String::new(), "has no header row"),
        (
            "no_load.csv",
            "step,time,top_uy\n0,0e0,0e0\n".to_string(),
            "has no column `load`",
        ),
        (
            "not_a_number.csv",
            format!("{header}0,0e0,3e0,0e0\n1,1e-3,abc,-1e-5\n"),
            "line 3: `abc` in column `load` is not a number",
        ),
        (
            "short_row.csv",
            format!("{header}0,0e0,3e0,0e0\n1,1e-3\n"),
            "has a row that does not parse",
        ),
    ];
    for (name, text, problem) in cases {
        let path = write_file(dir.path(), name, &text);
        let message = read_curve(&path, &columns).unwrap_err().to_string();
        assert!(
            message.contains(&path.display().to_string()) && message.contains(problem),
            "{name}: {message}"
        );
    }
    let missing = dir.path().join("missing.csv");
    let message = read_curve(&missing, &columns).unwrap_err().to_string();
    assert!(
        message.contains(&missing.display().to_string()) && message.contains("cannot be opened"),
        "{message}"
    );

    let partial = write_file(
        dir.path(),
        "partial.csv",
        &format!("{header}0,0e0,3e0,0e0\n1,1e-3,3.5e0,-1e-5\n"),
    );
    assert_eq!(
        read_curve(&partial, &columns).unwrap(),
        vec![(0.0, 3.0), (1e-5, 3.5)]
    );
}

/// A run whose scene has no displacement or no force monitor is listed in
/// `report.md` as having no load curve.
#[test]
fn report_names_a_run_without_load_curve() {
    let dir = tempfile::tempdir().unwrap();
    let run = CampaignRun {
        name: "patch".into(),
        cell_size: 0.5,
        length_scale: None,
        curve: Vec::new(),
        curve_columns: None,
        positions: Vec::new(),
        eps_q: Vec::new(),
        kappa_bar: Vec::new(),
        error: None,
        lost_points: (0, 0.0),
        dissipation: None,
        energy: None,
        wall_seconds: 0.0,
        profile: String::new(),
        step_factor: 1,
    };
    write_outputs(dir.path(), &[run]).unwrap();
    let report = std::fs::read_to_string(dir.path().join("report.md")).unwrap();
    assert!(report.contains("\n- patch: no load curve ("), "{report}");
}
