//! `run.json` says where a run came from and what it found (issue 41
//! items 8–9): the provenance (build, command line, overrides, scene and its
//! fingerprint, start and end, host, CPU, threads) and the summary (status,
//! steps, each monitor's last and peak value, where the files are); `run`
//! prints that summary, and the stage profile only with `--profile`. A run
//! that crushes its body says so (item 5): a warning and the points outside
//! the trusted range of V/V0 in `run.json` → `point_volumes`.

use std::process::Command;

mod common;

const BIN: &str = env!("CARGO_BIN_EXE_mpm-geo");

/// Run the tossed block for 30 steps with `extra` arguments; returns the
/// output folder (kept alive: `out` in it) and the process's output.
fn run(extra: &[&str]) -> (tempfile::TempDir, std::process::Output) {
    let mut args = vec!["--set", "scene.steps=30"];
    args.extend_from_slice(extra);
    run_scene("friction/tossed_block.toml", &args)
}

/// Run the validation scene `scene` with `args` into a new folder's `out`.
fn run_scene(scene: &str, args: &[&str]) -> (tempfile::TempDir, std::process::Output) {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let scene = common::validation(scene);
    let output = Command::new(BIN)
        .args([
            "run",
            scene.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ])
        .args(args)
        .output()
        .unwrap();
    assert!(output.status.success(), "{output:?}");
    (dir, output)
}

fn is_utc_second(s: &serde_json::Value) -> bool {
    let s = s.as_str().unwrap_or("");
    s.len() == 20 && s.ends_with('Z') && s.as_bytes()[10] == b'T'
}

#[test]
fn run_json_holds_provenance_and_summary() {
    let (dir, _) = run(&["--quiet", "--set", "loads.gravity=9.0"]);
    let run_json = std::fs::read_to_string(dir.path().join("out/run.json")).unwrap();
    let json: serde_json::Value = serde_json::from_str(&run_json).unwrap();
    let p = &json["provenance"];
    let command: Vec<&str> = p["command_line"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_str().unwrap())
        .collect();
    assert!(command.contains(&"loads.gravity=9.0"), "{command:?}");
    assert_eq!(
        p["overrides"],
        serde_json::json!(["scene.steps=30", "loads.gravity=9.0"])
    );
    assert!(p["scene_path"]
        .as_str()
        .unwrap()
        .ends_with("friction/tossed_block.toml"));
    let fingerprint = p["scene_fingerprint"].as_str().unwrap();
    assert!(fingerprint.len() == 16 && fingerprint.chars().all(|c| c.is_ascii_hexdigit()));
    assert!(
        is_utc_second(&p["started_at"]) && is_utc_second(&p["ended_at"]),
        "{p}"
    );
    assert!(p["started_at"].as_str() <= p["ended_at"].as_str());
    assert_eq!(p["version"], env!("CARGO_PKG_VERSION"));
    // built from a checkout here: a 40-digit commit and a dirty flag
    let commit = p["git_commit"].as_str().unwrap_or("");
    assert!(
        commit.is_empty() || (commit.len() == 40 && p["git_dirty"].is_boolean()),
        "{p}"
    );
    assert!(p["threads"].as_u64().unwrap() >= 1);
    assert!(!p["host"].as_str().unwrap().is_empty() && !p["cpu"].as_str().unwrap().is_empty());

    let s = &json["summary"];
    assert_eq!(
        (s["status"].as_str(), s["steps"].as_u64()),
        (Some("completed"), Some(30))
    );
    // the monitors' last values are the curve's last row
    let curve = std::fs::read_to_string(dir.path().join("out/curve.csv")).unwrap();
    let header: Vec<&str> = curve.lines().next().unwrap().split(',').collect();
    let last: Vec<f64> = curve
        .lines()
        .last()
        .unwrap()
        .split(',')
        .map(|v| v.parse().unwrap())
        .collect();
    let monitors = s["monitors"].as_array().unwrap();
    assert_eq!(monitors.len(), 2);
    for m in monitors {
        let i = header
            .iter()
            .position(|h| *h == m["column"].as_str().unwrap())
            .unwrap();
        assert_eq!(m["last"].as_f64().unwrap(), last[i]);
        assert!(m["peak"].as_f64().unwrap().abs() >= last[i].abs());
    }
    // the block starts with all its kinetic energy, ½ m v² = ½ · 1 t · 4 = 2 kJ/m
    let kinetic = monitors
        .iter()
        .find(|m| m["name"] == "kinetic_energy")
        .unwrap();
    assert_eq!(
        (kinetic["peak"].as_f64(), kinetic["peak_time"].as_f64()),
        (Some(2.0), Some(0.0))
    );
}

/// Without `--quiet` the summary is printed; the stage profile only with
/// `--profile`, and then also with `--quiet` (which drops the summary).
#[test]
fn run_prints_its_summary_and_the_profile_on_demand() {
    let plain = |extra: &[&str]| {
        let (_dir, output) = run(extra);
        String::from_utf8_lossy(&output.stderr).into_owned()
    };
    let summary = plain(&["--progress-every", "100"]);
    assert!(summary.contains("30 steps to t = "), "{summary}");
    assert!(
        summary.contains("kinetic_energy") && summary.contains("peak"),
        "{summary}"
    );
    assert!(!summary.contains("wall"), "{summary}");
    let profiled = plain(&["--profile"]);
    assert!(
        profiled.contains("wall") && profiled.contains("work:"),
        "{profiled}"
    );
    let quiet = plain(&["--profile", "--quiet"]);
    assert!(quiet.contains("wall") && quiet.contains("work:"), "{quiet}");
    assert!(!quiet.contains("30 steps to t = "), "{quiet}");
}

/// The elastic bar under 1e4 g completes with its points crushed to
/// V/V0 ~ 1e-20 (measured 1.7e-20 to 2.3e-12): every point is counted
/// outside [1e-2, 1e2] and the run warns; under its own 1 g it is not.
#[test]
fn a_crushed_body_is_flagged() {
    let bar = |gravity: &str| {
        let gravity = format!("loads.gravity={gravity}");
        let (dir, output) = run_scene("elastic/bar_explicit.toml", &["--set", &gravity]);
        let run_json = std::fs::read_to_string(dir.path().join("out/run.json")).unwrap();
        let json: serde_json::Value = serde_json::from_str(&run_json).unwrap();
        (json, String::from_utf8_lossy(&output.stderr).into_owned())
    };
    let (crushed, stderr) = bar("98100");
    let volumes = &crushed["point_volumes"];
    let particles = crushed["particles"].as_u64().unwrap();
    assert_eq!(
        volumes["jacobian_out_of_range"].as_u64(),
        Some(particles),
        "{volumes}"
    );
    assert!(
        volumes["jacobian_range"][1].as_f64().unwrap() < 1e-2,
        "{volumes}"
    );
    assert!(stderr.contains("volume ratio V/V0 outside"), "{stderr}");
    assert!(crushed["warnings"].to_string().contains("volume ratio"));
    let (resting, stderr) = bar("9.81");
    let volumes = &resting["point_volumes"];
    assert_eq!(
        volumes["jacobian_out_of_range"].as_u64(),
        Some(0),
        "{volumes}"
    );
    let [lo, hi] = [0, 1].map(|i| volumes["jacobian_range"][i].as_f64().unwrap());
    assert!(lo > 0.99 && hi < 1.01, "{volumes}");
    assert!(!stderr.contains("volume ratio"), "{stderr}");
}
