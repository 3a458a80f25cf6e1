use std::path::{Path, PathBuf};

use super::history::write_history_outputs;
use super::report::{read_curve, write_outputs};
use super::*;
use crate::plot::Bounds;
use crate::scene::Scene;

/// A run with no results yet.
fn blank_run(
    name: &str,
    cell_size: f64,
    length_scale: Option<f64>,
    analysis: AnalysisKind,
) -> CampaignRun {
    CampaignRun {
        name: name.into(),
        cell_size,
        length_scale,
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
        scheme: String::new(),
        profile: String::new(),
        step_factor: 1,
        scene: name.trim_end_matches("_explicit").into(),
        analysis,
        history: None,
        fields: Vec::new(),
        volumes: Vec::new(),
        initial_volumes: Vec::new(),
        footing: None,
        effort: Effort::default(),
    }
}

/// A cut-like history: at rest until `onset_at`, then |u_A| grows as
/// (t − t0)² · `rate`; q_B rises to 100 kPa at the onset and falls linearly.
fn cut_run(
    name: &str,
    h: f64,
    nonlocal: bool,
    explicit: bool,
    onset_at: f64,
    rate: f64,
) -> CampaignRun {
    let analysis = if explicit {
        AnalysisKind::Explicit
    } else {
        AnalysisKind::ImplicitDynamic
    };
    let mut run = blank_run(name, h, nonlocal.then_some(0.4), analysis);
    let mut history = History::default();
    for i in 0..=1000 {
        let t = i as f64 * 1e-3;
        let u = rate * (t - onset_at).max(0.0).powi(2);
        let q = if t < onset_at {
            100.0 * t / onset_at
        } else {
            100.0 * (1.0 - (t - onset_at))
        };
        history.displacement.push((t, u));
        history.stress.push((t, q));
        // the group's reading: the same fall with a wobble of ±2 kPa
        let wobble = if i % 2 == 0 { 2.0 } else { -2.0 };
        history.neighbourhood_stress.push((t, q + wobble));
        history.run_out.push((t, 3.0 + 0.5 * u));
        // a budget whose remainder is 2 % of W implicit, −1 % explicit
        let (work, share) = (100.0 * t, if explicit { -0.01 } else { 0.02 });
        let terms = [
            work,
            0.5 * work,
            0.3 * work,
            (0.2 - share) * work,
            share * work,
        ];
        history.budget.push((t, terms));
    }
    history.remainder_share = super::history::remainder_share(&history.budget);
    run.history = Some(history);
    run
}

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
    assert_eq!(columns.force, "platen_force_kN_per_m");
    assert_eq!(columns.displacement, "platen_uy_m");

    let dir = tempfile::tempdir().unwrap();
    let path = write_file(
        dir.path(),
        "curve.csv",
        "step_1,time_s,load,top_uy,platen_force_kN_per_m,platen_uy_m\n\
         0,0e0,9e0,9e0,3e0,-0e0\n\
         1,1e-3,9e0,9e0,3.5e0,-1e-5\n",
    );
    let curve = read_curve(&path, &columns).unwrap();
    assert_eq!(curve, vec![(0.0, 3.0), (1e-5, 3.5)]);

    let oedometer = CurveColumns::of_scene(&validation_scene("elastic/oedometer.toml", &[]));
    assert_eq!(
        oedometer,
        Some(CurveColumns {
            displacement: "top_settlement_m".into(),
            force: "base_reaction_kN_per_m".into(),
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
    let header = "step_1,time_s,load,top_uy\n";
    let cases = [
        ("empty.csv", String::new(), "has no header row"),
        (
            "no_load.csv",
            "step_1,time_s,top_uy\n0,0e0,0e0\n".to_string(),
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
    let run = blank_run("patch", 0.5, None, AnalysisKind::QuasiStatic);
    write_outputs(
        dir.path(),
        &[run],
        Benchmark::LoadCurve,
        Bounds::new(0.0, 1.0, 0.0, 1.0),
    )
    .unwrap();
    let report = std::fs::read_to_string(dir.path().join("report.md")).unwrap();
    assert!(report.contains("\n- patch: no load curve ("), "{report}");
}

/// The cut's metrics on synthetic histories: onset where |u_A| passes 5 cm,
/// M1 against the finest mesh of the same family (regularisation and
/// integrator), and the implicit/explicit pairs of one scene.
#[test]
fn history_metrics_follow_families_and_pair_the_integrators() {
    // rate 10 m/s²: |u_A| = 0.05 m at 0.0707 s after the onset
    let runs = vec![
        cut_run("nonlocal_h100", 0.1, true, false, 0.06, 10.0),
        cut_run("nonlocal_h62", 0.0625, true, false, 0.06, 11.0),
        cut_run("nonlocal_h62_explicit", 0.0625, true, true, 0.065, 11.0),
        cut_run("local_h62", 0.0625, false, false, 0.05, 20.0),
    ];
    let m = compute_history_metrics(&runs);
    let expected_onset = 0.06 + (0.05f64 / 10.0).sqrt();
    let onset = m[0].onset.unwrap();
    assert!(
        (onset - expected_onset).abs() < 1e-4,
        "{onset} vs {expected_onset}"
    );
    // u ∝ rate: the whole-history M1 of rate 10 against rate 11 is 1/11
    let e = m[0].discrepancy.unwrap();
    assert!((e - 1.0 / 11.0).abs() < 1e-9, "{e}");
    // each finest run is its family's own reference (the explicit one too)
    assert_eq!(m[1].discrepancy, Some(0.0));
    assert_eq!(m[2].discrepancy, Some(0.0));
    assert_eq!(m[3].discrepancy, Some(0.0));
    assert_eq!(m[1].stress_reversals, Some(0));
    assert!((m[1].stress_roughness.unwrap() - 1.0).abs() < 1e-9);
    // the wobble adds 4 kPa of variation per ms to the group's fall
    let group = m[1].neighbourhood_roughness.unwrap();
    assert!(group > 10.0, "{group}");

    let dir = tempfile::tempdir().unwrap();
    write_history_outputs(dir.path(), &runs, Bounds::new(0.0, 16.0, 0.0, 3.5)).unwrap();
    let pairs = std::fs::read_to_string(dir.path().join("integrators.csv")).unwrap();
    let rows: Vec<&str> = pairs.lines().skip(1).collect();
    assert_eq!(rows.len(), 1, "{pairs}");
    assert!(rows[0].starts_with("nonlocal_h62,nonlocal,"), "{pairs}");
    // explicit onset 5 ms later
    let fields: Vec<&str> = rows[0].split(',').collect();
    let difference: f64 = fields[5].parse().unwrap();
    assert!((difference - 0.005).abs() < 1e-4, "{difference}");
    // u_A(1 s) ∝ (1 − t0)²: explicit (0.935/0.94)² − 1 of the implicit one
    let final_difference: f64 = fields[12].parse().unwrap();
    let expected = (0.935f64 / 0.94).powi(2) - 1.0;
    assert!(
        (final_difference - expected).abs() < 1e-5,
        "{final_difference}"
    );
    let shares: Vec<f64> = [fields[15], fields[16]]
        .iter()
        .map(|v| v.parse().unwrap())
        .collect();
    assert!(
        (shares[0] - 0.02).abs() < 1e-12 && (shares[1] + 0.01).abs() < 1e-12,
        "{pairs}"
    );
    let histories = std::fs::read_to_string(dir.path().join("histories.csv")).unwrap();
    let last: Vec<&str> = histories.lines().last().unwrap().split(',').collect();
    let budget: Vec<f64> = last[10..].iter().map(|v| v.parse().unwrap()).collect();
    assert_eq!(budget.len(), 5, "{histories}");
    assert!((budget[4] - 0.02 * budget[0]).abs() < 1e-9, "{budget:?}");
    for file in [
        "histories.csv",
        "metrics.csv",
        "report.md",
        "fig12_uA.png",
        "fig11_qB.png",
        "fig11_qB_neighbourhood.png",
        "fig11_qB_neighbourhood_failure.png",
        "implicit_vs_explicit.png",
        "integrators.png",
    ] {
        assert!(dir.path().join(file).exists(), "{file} missing");
        if file.ends_with(".png") {
            let svg = crate::plot::svg_path(&dir.path().join(file));
            assert!(svg.exists(), "{} missing", svg.display());
        }
    }
}

/// R/W is followed from the first row where W reaches 1 % of its largest
/// value (a ratio of round-offs before).
#[test]
fn remainder_share_starts_where_the_work_is_put_in() {
    let row = |t: f64, work: f64, remainder: f64| (t, [work, 0.0, 0.0, 0.0, remainder]);
    let budget = [
        row(0.0, 0.0, 0.0),
        row(1.0, 0.005, 0.004),
        row(2.0, 0.5, 0.01),
        row(3.0, 1.0, -0.02),
    ];
    let share = super::history::remainder_share(&budget);
    assert_eq!(share, vec![(2.0, 0.02), (3.0, -0.02)]);
}

/// `campaign.toml` names the benchmark and the integrators; an unknown key or
/// an empty list of integrators is refused, a missing file is the default.
#[test]
fn campaign_spec_is_read_and_checked() {
    let dir = tempfile::tempdir().unwrap();
    assert_eq!(
        CampaignSpec::load(dir.path()).unwrap(),
        CampaignSpec::default()
    );
    write_file(
        dir.path(),
        SPEC_FILE,
        "benchmark = \"vertical_cut\"\nintegrators = [\"as_written\", \"explicit\"]\n",
    );
    let spec = CampaignSpec::load(dir.path()).unwrap();
    assert_eq!(spec.benchmark, Benchmark::VerticalCut);
    assert_eq!(
        spec.integrators,
        vec![IntegratorChoice::AsWritten, IntegratorChoice::Explicit]
    );
    write_file(
        dir.path(),
        SPEC_FILE,
        "benchmark = \"footing\"\nintegrator = [\"explicit\"]\n",
    );
    let message = CampaignSpec::load(dir.path()).unwrap_err().to_string();
    assert!(message.contains("integrator"), "{message}");
    write_file(dir.path(), SPEC_FILE, "integrators = []\n");
    assert!(CampaignSpec::load(dir.path()).is_err());
    for shipped in ["biaxial", "footing", "vertical_cut"] {
        let path = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("validation")
            .join(shipped);
        CampaignSpec::load(&path).expect("shipped campaign.toml");
    }
}
