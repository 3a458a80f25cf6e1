//! Checkpoint and restart (issue 14, checks 1 and 2), through the
//! `mpm-geo` binary as a user runs it.
//!
//! Check 1: an implicit dynamic nonlocal softening run (the vertical cut of
//! `validation/vertical_cut/nonlocal_h100.toml` at h = 0.25 m, 120 steps of
//! 1 ms, collapsing from ~0.05 s) and an explicit one (the same cut with
//! explicit MUSL at the CFL step, 0.2 s), each ended after a step between two
//! checkpoints (`--stop-after-step`, as a kill would) and resumed, write the
//! same `curve.csv` and snapshots, byte for byte, as an uninterrupted run.
//! Check 2: a corrupted, truncated, foreign (another scene's) or other-version
//! checkpoint, and a `curve.csv` changed after the checkpoint, are refused
//! with their identifiers, and nothing in the directory changes.

mod common;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// The coarse vertical cut of the CI variants (12 × 12 cells over the block).
const COARSE: &[&str] = &[
    "grid.cell_size=0.25",
    "output.snapshot_times=[0.05, 0.1]",
    "output.snapshot_every=20",
];

fn mpm_geo(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_mpm-geo"))
        .args(args)
        .output()
        .expect("mpm-geo runs")
}

/// `mpm-geo run SCENE --out OUT --set ... EXTRA...`, which must succeed.
fn run(scene: &Path, out: &Path, overrides: &[&str], extra: &[&str]) -> String {
    let mut args = vec![
        "run".to_string(),
        scene.display().to_string(),
        "--quiet".into(),
        "--out".into(),
        out.display().to_string(),
    ];
    for o in overrides {
        args.extend(["--set".to_string(), o.to_string()]);
    }
    args.extend(extra.iter().map(|s| s.to_string()));
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let output = mpm_geo(&args);
    let stderr = String::from_utf8_lossy(&output.stderr).into_owned();
    assert!(output.status.success(), "mpm-geo {args:?}:\n{stderr}");
    stderr
}

fn resume(dir: &Path, extra: &[&str]) -> Output {
    let dir = dir.display().to_string();
    let mut args = vec!["resume", dir.as_str(), "--quiet"];
    args.extend(extra);
    mpm_geo(&args)
}

/// Every file of `dir` and its bytes.
fn files(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .map(|p| {
            let name = p.file_name().unwrap().to_string_lossy().into_owned();
            (name, std::fs::read(&p).unwrap())
        })
        .collect()
}

/// The outputs a run is judged by: `curve.csv` and the snapshots.
fn outputs(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    let mut out = files(dir);
    out.retain(|name, _| name == "curve.csv" || name.ends_with(".vtu"));
    out
}

/// Step of the last row of `curve.csv`.
fn last_row_step(dir: &Path) -> usize {
    let text = std::fs::read_to_string(dir.join("curve.csv")).unwrap();
    let last = text.lines().last().unwrap();
    last.split(',').next().unwrap().parse().unwrap()
}

fn run_json(dir: &Path) -> serde_json::Value {
    serde_json::from_slice(&std::fs::read(dir.join("run.json")).unwrap()).unwrap()
}

fn status(dir: &Path) -> (String, u64) {
    let json = run_json(dir);
    (
        json["status"].as_str().unwrap().to_string(),
        json["steps_completed"].as_u64().unwrap(),
    )
}

/// Run `scene` straight through and, in another directory, with a
/// checkpoint every `every` steps ended after `stop`, then resumed (after
/// `stop_again`, if given, the resumed run is ended and resumed once more);
/// the two directories must hold the same outputs.
fn assert_resume_is_seamless(
    scene: &Path,
    overrides: &[&str],
    every: usize,
    stop: usize,
    stop_again: Option<usize>,
) {
    let tmp = tempfile::tempdir().unwrap();
    let (straight, resumed) = (tmp.path().join("straight"), tmp.path().join("resumed"));
    run(scene, &straight, overrides, &[]);
    let every_arg = every.to_string();
    let stop_arg = stop.to_string();
    let stderr = run(
        scene,
        &resumed,
        overrides,
        &[
            "--checkpoint-every",
            &every_arg,
            "--stop-after-step",
            &stop_arg,
        ],
    );
    assert!(
        stderr.contains(&format!("stopped after step {stop}")),
        "{stderr}"
    );
    assert_eq!(
        status(&resumed).0,
        "running",
        "a killed run leaves run.json running"
    );
    // the stopped run wrote rows past its last checkpoint: the resume must cut them
    let checkpoint = stop / every * every;
    let row_at_stop = last_row_step(&resumed);
    assert!(
        row_at_stop > checkpoint,
        "last row of step {row_at_stop} at the stop"
    );
    let mut stops = vec![checkpoint];
    if let Some(again) = stop_again {
        let again_arg = again.to_string();
        let output = resume(&resumed, &["--stop-after-step", &again_arg]);
        assert!(
            output.status.success(),
            "{}",
            String::from_utf8_lossy(&output.stderr)
        );
        stops.push(again / every * every);
    }
    let output = resume(&resumed, &[]);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(output.status.success(), "{stderr}");
    let last = stops.last().unwrap();
    assert!(
        stderr.contains(&format!("from the checkpoint of step {last}")),
        "{stderr}"
    );
    let (want, got) = (outputs(&straight), outputs(&resumed));
    assert_eq!(
        want.keys().collect::<Vec<_>>(),
        got.keys().collect::<Vec<_>>(),
        "output files"
    );
    for (name, bytes) in &want {
        assert!(
            got[name] == *bytes,
            "{name} differs after resuming at steps {stops:?}"
        );
    }
    let (state, steps) = status(&resumed);
    assert_eq!((state.as_str(), steps), ("completed", status(&straight).1));
    // the whole-run records of run.json carry on too (wall times aside)
    let (want, got) = (run_json(&straight), run_json(&resumed));
    for key in ["time", "particles", "lost_points"] {
        assert_eq!(want[key], got[key], "run.json {key}");
    }
    // every work counter, but a resumed implicit run factorises its first
    // pattern symbolically once more (the solver's cache is not stored)
    let (mut want_work, mut got_work) = (want["work"].clone(), got["work"].clone());
    let symbolic = |work: &mut serde_json::Value| {
        work.as_object_mut()
            .and_then(|w| w.remove("symbolic_factorisations"))
            .and_then(|n| n.as_u64())
            .unwrap()
    };
    let (before, after) = (symbolic(&mut want_work), symbolic(&mut got_work));
    assert_eq!(want_work, got_work, "run.json work");
    let resumes = stops.len() as u64;
    let implicit = before > 0;
    assert!(
        after >= before && after <= before + u64::from(implicit) * resumes,
        "symbolic factorisations {before} straight, {after} resumed"
    );
    assert_eq!(
        want["solver"]["usage"], got["solver"]["usage"],
        "run.json solver usage"
    );
    // the stage profile covers every process: the same calls of each stage
    // of the steps (each process builds the model, the resume writes its
    // snapshots again), and a wall time that holds every stage's seconds
    let calls = |run: &serde_json::Value| -> BTreeMap<String, u64> {
        let rows = run["profile"].as_array().unwrap();
        rows.iter()
            .map(|row| {
                (
                    row["stage"].as_str().unwrap().to_string(),
                    row["calls"].as_u64().unwrap(),
                )
            })
            .filter(|(stage, _)| !["build", "output", "other"].contains(&stage.as_str()))
            .collect()
    };
    assert_eq!(calls(&want), calls(&got), "run.json profile calls");
    let staged: f64 = got["profile"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|row| row["stage"] != "other")
        .map(|row| row["seconds"].as_f64().unwrap())
        .sum();
    let wall = got["wall_seconds"].as_f64().unwrap();
    assert!(staged <= wall, "stages {staged} s > wall {wall} s");
}

/// The explicit twin of the nonlocal vertical cut, to t = 0.2 s, as a scene file in `dir`.
fn explicit_cut(dir: &Path) -> PathBuf {
    let text = std::fs::read_to_string(common::validation("vertical_cut/nonlocal_h100.toml"))
        .unwrap()
        .replace(
            "analysis = \"implicit_dynamic\"\nsteps = 1000\ndt = 1.0e-3",
            "analysis = \"explicit\"\nend_time = 0.2",
        );
    assert!(text.contains("end_time = 0.2"), "the cut scene changed");
    let path = dir.join("cut_explicit.toml");
    std::fs::write(&path, text).unwrap();
    path
}

#[test]
fn implicit_nonlocal_softening_run_resumes_to_identical_outputs() {
    let scene = common::validation("vertical_cut/nonlocal_h100.toml");
    let mut overrides = COARSE.to_vec();
    overrides.extend(["scene.steps=120", "output.curve_every=3"]);
    // the checkpoint of step 50, stopped at 67 (after the 0.05 s snapshot,
    // in the collapse)
    assert_resume_is_seamless(&scene, &overrides, 25, 67, None);
}

#[test]
fn explicit_run_resumes_twice_to_identical_outputs() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = explicit_cut(tmp.path());
    // variable CFL steps; stopped at 47 (checkpoint 40), resumed and stopped
    // at 133 (checkpoint 130), resumed to the end (175 steps)
    assert_resume_is_seamless(&scene, COARSE, 10, 47, Some(133));
}

#[test]
fn runs_with_removed_points_and_a_rigid_platen_resume_identically() {
    // explicit: points leave the grid at steps 120 and 151 (checkpoint 150)
    let lost = common::validation("lost_points/block_leaves_grid.toml");
    assert_resume_is_seamless(&lost, &[], 50, 160, None);
    // implicit nonlocal biaxial: the platen's tied points and its work
    let biaxial = common::validation("biaxial/nonlocal_h300.toml");
    let coarse = ["grid.cell_size=0.01", "scene.steps=80"];
    assert_resume_is_seamless(&biaxial, &coarse, 10, 33, None);
}

/// A stopped run of the explicit cut with a checkpoint at step 40, in `dir`.
fn stopped_run(scene: &Path, dir: &Path) {
    run(
        scene,
        dir,
        COARSE,
        &["--checkpoint-every", "20", "--stop-after-step", "47"],
    );
}

/// `resume dir` must fail with `id` in its message and leave every file as it was.
fn assert_refused(dir: &Path, id: &str) {
    let before = files(dir);
    let output = resume(dir, &[]);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert_eq!(output.status.code(), Some(2), "{id}: {stderr}");
    assert!(
        stderr.contains(&format!("[{id}]")),
        "expected {id}: {stderr}"
    );
    assert!(
        files(dir) == before,
        "{id}: the refused resume changed the directory"
    );
}

#[test]
fn damaged_foreign_and_other_version_checkpoints_are_refused_and_nothing_changes() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = explicit_cut(tmp.path());
    let dir = tmp.path().join("run");
    stopped_run(&scene, &dir);
    let checkpoint = dir.join("checkpoint.bin");
    let good = std::fs::read(&checkpoint).unwrap();
    let put = |bytes: &[u8]| std::fs::write(&checkpoint, bytes).unwrap();

    let mut corrupted = good.clone();
    let middle = good.len() / 2;
    corrupted[middle] ^= 0x01;
    put(&corrupted);
    assert_refused(&dir, "CHECKPOINT_CORRUPT");

    put(&good[..good.len() * 2 / 3]);
    assert_refused(&dir, "CHECKPOINT_TRUNCATED");

    let mut newer = good.clone();
    newer[8..12].copy_from_slice(&(mpm_geo::checkpoint::FORMAT_VERSION + 1).to_le_bytes());
    put(&newer);
    assert_refused(&dir, "CHECKPOINT_VERSION");

    // a whole, valid checkpoint of another scene (the elastic bar)
    let other = tmp.path().join("other");
    run(
        &common::validation("elastic/bar_explicit.toml"),
        &other,
        &[],
        &["--checkpoint-every", "5", "--stop-after-step", "12"],
    );
    std::fs::copy(other.join("checkpoint.bin"), &checkpoint).unwrap();
    assert_refused(&dir, "CHECKPOINT_FOREIGN");

    // the good checkpoint, but curve.csv edited after it
    put(&good);
    let curve = dir.join("curve.csv");
    let text = std::fs::read_to_string(&curve).unwrap();
    std::fs::write(&curve, text.replacen("\n1,", "\n1 ,", 1)).unwrap();
    assert_refused(&dir, "CHECKPOINT_OUTPUTS");
    std::fs::write(&curve, &text).unwrap();

    std::fs::remove_file(&checkpoint).unwrap();
    assert_refused(&dir, "CHECKPOINT_MISSING");

    // with everything put back the same directory resumes
    put(&good);
    let output = resume(&dir, &[]);
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    assert_eq!(status(&dir).0, "completed");
}

/// What an interruption (SIGINT/SIGTERM) does: the run ends after a step
/// that is neither a checkpoint step nor a `curve.csv` row step, a checkpoint
/// of that very step is written on request (`every = 0`: no periodic ones),
/// and `resume` continues from it to the uninterrupted outputs.
#[test]
fn a_checkpoint_written_on_request_at_any_step_resumes_identically() {
    use mpm_geo::checkpoint::{Checkpointer, SceneSource};
    use mpm_geo::manifest::Manifest;
    use mpm_geo::run::OutputObserver;
    use mpm_geo::simulation::Simulation;

    let tmp = tempfile::tempdir().unwrap();
    let scene = explicit_cut(tmp.path());
    let mut overrides = COARSE.to_vec();
    overrides.push("output.curve_every=4");
    let (straight, stopped) = (tmp.path().join("straight"), tmp.path().join("stopped"));
    run(&scene, &straight, &overrides, &[]);

    let overrides: Vec<String> = overrides.iter().map(|s| s.to_string()).collect();
    let source = SceneSource::read(&scene, &overrides).unwrap();
    let started = std::time::Instant::now();
    let mut sim = Simulation::new(source.scene().unwrap()).unwrap();
    let checkpoints =
        Checkpointer::start(&stopped, &source, 0, started).unwrap_or_else(|e| panic!("{e}"));
    let mut observer = OutputObserver::new(&stopped, &sim, false, Manifest::new())
        .unwrap()
        .with_checkpoints(Some(checkpoints), Some(47));
    sim.run(&mut observer).unwrap();
    assert_eq!(sim.model.state.step, 47);
    observer.write_checkpoint(&sim).unwrap();
    observer.finish(&sim).unwrap(); // the interrupted run's last row (step 47)
    assert_eq!(last_row_step(&stopped), 47);

    let output = resume(&stopped, &[]);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(output.status.success(), "{stderr}");
    assert!(
        stderr.contains("from the checkpoint of step 47"),
        "{stderr}"
    );
    assert!(
        outputs(&straight) == outputs(&stopped),
        "outputs differ after the resume"
    );
}

/// Issue 14 check 1 as a user meets it: SIGTERM at whatever step the run
/// has reached (once `curve.csv` has 20 rows), exit 143 with `run.json`
/// `interrupted` and a checkpoint of that step, then `resume`: the same
/// outputs as the uninterrupted run.
#[cfg(unix)]
#[test]
fn sigterm_then_resume_gives_the_uninterrupted_outputs() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = common::validation("vertical_cut/nonlocal_h100.toml");
    let mut overrides = COARSE.to_vec();
    overrides.extend(["scene.steps=200", "output.curve_every=3"]);
    let (straight, killed) = (tmp.path().join("straight"), tmp.path().join("killed"));
    run(&scene, &straight, &overrides, &[]);

    let mut args = vec![
        "run".to_string(),
        scene.display().to_string(),
        "--quiet".into(),
        "--out".into(),
        killed.display().to_string(),
        "--checkpoint-every".into(),
        "1000".into(),
    ];
    for o in &overrides {
        args.extend(["--set".to_string(), o.to_string()]);
    }
    let mut child = Command::new(env!("CARGO_BIN_EXE_mpm-geo"))
        .args(&args)
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let rows = || {
        std::fs::read_to_string(killed.join("curve.csv"))
            .map(|t| t.lines().count())
            .unwrap_or(0)
    };
    while rows() < 20 {
        assert!(
            child.try_wait().unwrap().is_none(),
            "the run ended before the signal"
        );
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    let pid = child.id().to_string();
    assert!(Command::new("kill")
        .args(["-TERM", &pid])
        .status()
        .unwrap()
        .success());
    let code = child.wait().unwrap().code();
    assert_eq!(code, Some(143));
    let (state, step) = status(&killed);
    assert_eq!(state, "interrupted");
    assert!(step < 200, "interrupted at step {step}");

    let output = resume(&killed, &[]);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(output.status.success(), "{stderr}");
    assert!(
        stderr.contains(&format!("from the checkpoint of step {step}")),
        "{stderr}"
    );
    assert!(
        outputs(&straight) == outputs(&killed),
        "outputs differ after SIGTERM and resume (step {step})"
    );
    assert_eq!(status(&killed).0, "completed");
}

#[test]
fn adaptive_generalised_alpha_run_resumes_to_identical_outputs() {
    // the controller's proposed step, velocity scale and counts, and the
    // points' force per mass are in the checkpoint: stopped at 37
    // (checkpoint 30) of the bar's ~100 error-controlled steps
    let bar = common::validation("elastic/bar_implicit.toml");
    let adaptive = [
        "scene.steps=400",
        "solver.rho_infinity=0.8",
        "solver.time_step=\"adaptive\"",
        "solver.error_tolerance=1e-3",
    ];
    assert_resume_is_seamless(&bar, &adaptive, 10, 37, None);
}
