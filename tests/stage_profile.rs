//! The stage profile adds up (issue 11): every stage is timed once, so the
//! stage times in `run.json` plus the `other` row equal the run's wall time,
//! no stage is counted inside another, and `other` (what no stage covers)
//! stays small. Checked on an implicit and an explicit scene with double
//! mapping on and the nonlocal model, where stages nest (stress updates and
//! nonlocal averages inside Newton, double mapping inside the stresses stage).

mod common;

use mpm_geo::run::run_scene;

/// (stage, calls, seconds) rows of `run.json`'s profile and its wall time.
fn profile_of(scene: &str, overrides: &[&str]) -> (Vec<(String, u64, f64)>, f64) {
    let dir = tempfile::tempdir().unwrap();
    let outcome = run_scene(common::scene(scene, overrides), dir.path(), false).unwrap();
    assert!(outcome.error.is_none(), "{:?}", outcome.error);
    let text = std::fs::read_to_string(dir.path().join("run.json")).unwrap();
    let json: serde_json::Value = serde_json::from_str(&text).unwrap();
    let rows = json["profile"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| {
            (
                r["stage"].as_str().unwrap().to_string(),
                r["calls"].as_u64().unwrap(),
                r["seconds"].as_f64().unwrap(),
            )
        })
        .collect();
    (rows, json["wall_seconds"].as_f64().unwrap())
}

/// Asserts the profile adds up to the wall time within 2 %, with at most
/// 2 % of it in `other`, and that each named stage ran. Of three runs the
/// one with the least `other` is checked: untimed work shows in every run,
/// while the system preempting the process between two stages lands in
/// `other` of one run now and then (measured: 0.3–0.4 % of a 0.3 s run
/// alone, single runs up to 2.5 % beside a campaign and a build).
fn assert_adds_up(scene: &str, overrides: &[&str], stages_that_ran: &[&str]) {
    let other_share = |(rows, wall): &(Vec<(String, u64, f64)>, f64)| {
        rows.iter().find(|r| r.0 == "other").unwrap().2 / wall
    };
    let (rows, wall) = (0..3)
        .map(|_| profile_of(scene, overrides))
        .min_by(|a, b| other_share(a).total_cmp(&other_share(b)))
        .unwrap();
    let staged: f64 = rows.iter().filter(|r| r.0 != "other").map(|r| r.2).sum();
    let other = rows.iter().find(|r| r.0 == "other").unwrap().2;
    println!("{scene}: stages {staged:.4} s + other {other:.4} s, wall {wall:.4} s");
    for row in &rows {
        println!("  {:<15} {:>6} {:>9.4}", row.0, row.1, row.2);
    }
    assert!(
        staged <= 1.02 * wall,
        "stages sum to {staged} s > wall {wall} s"
    );
    assert!(((staged + other) / wall - 1.0).abs() <= 0.02);
    assert!(other <= 0.02 * wall, "other {other} s of {wall} s");
    for stage in stages_that_ran {
        let row = rows.iter().find(|r| r.0 == *stage).unwrap();
        assert!(row.1 > 0 && row.2 > 0.0, "{stage} not timed: {row:?}");
    }
}

#[test]
fn implicit_profile_with_double_mapping_adds_up() {
    assert_adds_up(
        "biaxial/nonlocal_h300.toml",
        &[
            "scene.steps=100",
            "smoothing.double_mapping=\"increment\"",
            "grid.shape_functions=\"bilinear\"",
            "grid.point_layout=\"gauss\"",
        ],
        &[
            "build",
            "setup",
            "p2g",
            "newton",
            "stress_update",
            "nonlocal",
            "assembly",
            "factorisation",
            "solve",
            "g2p",
            "stresses",
            "double_mapping",
            "commit",
            "output",
        ],
    );
}

#[test]
fn explicit_profile_with_double_mapping_adds_up() {
    assert_adds_up(
        "biaxial/nonlocal_h300.toml",
        &[
            "scene.analysis=\"explicit\"",
            "scene.dt=5e-6",
            "scene.end_time=0.002",
            "bc.rigid.0.velocity=[0.0,-0.1]",
            "solver.damping=0.7",
            "smoothing.double_mapping=\"increment\"",
        ],
        &[
            "build",
            "setup",
            "p2g",
            "time_step",
            "g2p",
            "remap",
            "stress_update",
            "nonlocal",
            "stresses",
            "double_mapping",
            "commit",
            "output",
        ],
    );
}
