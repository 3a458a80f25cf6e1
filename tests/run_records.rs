//! Records that are not lost or wrong (issue 41, items 1–4), through the
//! `mpm-geo` binary as a user runs it, on the explicit elastic bar (80
//! points, ~25 µs a step) and the one-step oedometer:
//! - a second campaign into the same `--out` while the first runs records
//!   nothing, and once the first is killed a re-run runs its run again;
//! - `run --overwrite` removes the files the earlier run listed in its
//!   `run.json` and nothing else (a user's `checkpoints/notes.txt` stays),
//!   including the earlier run's exported `systems/`;
//! - `resume` removes the temporary files of the killed process, refuses a
//!   completed run, and a resume that fails before its first step leaves
//!   `run.json` as it was;
//! - SIGTERM to a campaign or a study ends the runs in progress after a
//!   whole step with `run.json` saying `interrupted`, no record, no lock,
//!   exit code 143.

#![cfg(target_os = "linux")]

mod common;

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

const BIN: &str = env!("CARGO_BIN_EXE_mpm-geo");

/// The explicit elastic bar.
fn bar() -> PathBuf {
    common::validation("elastic/bar_explicit.toml")
}

fn mpm_geo(args: &[&str]) -> Output {
    Command::new(BIN).args(args).output().expect("mpm-geo runs")
}

fn text(path: &Path) -> String {
    std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&text(path)).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

fn status(dir: &Path) -> String {
    json(&dir.join("run.json"))["status"]
        .as_str()
        .unwrap()
        .to_string()
}

/// Start `mpm-geo ARGS`, stderr to `log`.
fn spawn(args: &[&str], log: &Path) -> Child {
    Command::new(BIN)
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(std::fs::File::create(log).unwrap())
        .spawn()
        .expect("mpm-geo runs")
}

fn send(child: &Child, signal: i32) {
    let pid = libc::pid_t::try_from(child.id()).unwrap();
    // SAFETY: sends a signal to our own child process.
    assert_eq!(unsafe { libc::kill(pid, signal) }, 0);
}

/// Every path under `dir` named `name`.
fn find(dir: &Path, name: &str) -> Vec<PathBuf> {
    let mut found = Vec::new();
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            found.extend(find(&path, name));
        }
        if path.file_name().is_some_and(|n| n == name) {
            found.push(path);
        }
    }
    found
}

/// Sorted names in `dir`.
fn names(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

/// A campaign directory `dir/scenes` with the bar under each of `names`.
fn bar_campaign(dir: &Path, names: &[&str]) -> PathBuf {
    let scenes = dir.join("scenes");
    std::fs::create_dir_all(&scenes).unwrap();
    for name in names {
        std::fs::copy(bar(), scenes.join(format!("{name}.toml"))).unwrap();
    }
    scenes
}

/// Item 1. Campaign A runs the bar for ~2.5 s; campaign B into the same
/// `--out` meanwhile is refused for that run (`OUTPUT_LOCKED`, exit 2) and
/// writes no record into A's directory (before: B stored its "locked"
/// refusal as the run's finished record). A is then killed; campaign C, the
/// same command, does not take the half-written run as finished (before: it
/// skipped it for good and reported the cut curve) but runs it again whole.
#[test]
fn a_second_campaign_records_nothing_and_a_killed_run_is_run_again() {
    let tmp = tempfile::tempdir().unwrap();
    let scenes = bar_campaign(tmp.path(), &["bar"]);
    let out = tmp.path().join("out");
    let args = [
        "campaign",
        scenes.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--jobs",
        "1",
        "--set",
        "scene.end_time=40",
        "--set",
        "output.curve_every=100",
    ];
    let run = out.join("bar");
    let mut first = spawn(&args, &tmp.path().join("a.log"));
    common::wait_for_rows(&run, 20, &mut first);

    let second = mpm_geo(&args);
    let stderr = String::from_utf8_lossy(&second.stderr);
    assert_eq!(second.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("error[OUTPUT_LOCKED]")
            && stderr.contains(&format!("process {}", first.id())),
        "{stderr}"
    );
    assert!(
        !run.join("campaign_run.json").exists(),
        "the refused campaign wrote a record into the running run's directory"
    );
    assert!(!out.join("report.md").exists());

    send(&first, libc::SIGKILL);
    common::wait(&mut first, Duration::from_secs(30));
    assert_eq!(status(&run), "running");
    let cut = text(&run.join("curve.csv")).lines().count();
    assert!(
        cut < 1 + 1600,
        "the run ended before the kill ({cut} lines)"
    );

    let third = mpm_geo(&args);
    let stderr = String::from_utf8_lossy(&third.stderr);
    assert!(third.status.success(), "{stderr}");
    assert!(!stderr.contains("not run again"), "{stderr}");
    assert!(stderr.contains("taking over the lock"), "{stderr}");
    assert_eq!(status(&run), "completed");
    // the whole curve: a row every 100 steps up to the last step's
    let steps = json(&run.join("run.json"))["steps_completed"]
        .as_u64()
        .unwrap();
    assert!(steps >= 160_000, "{steps} steps");
    let curve = text(&run.join("curve.csv"));
    assert!(curve.lines().count() > cut);
    let last: u64 = curve
        .lines()
        .last()
        .unwrap()
        .split(',')
        .next()
        .unwrap()
        .parse()
        .unwrap();
    assert_eq!(last, steps);
    let record = json(&run.join("campaign_run.json"));
    assert_eq!(record["status"], "completed");
    assert_eq!(record["effort"]["steps"], steps);
    // and a fourth runs nothing
    let fourth = mpm_geo(&args);
    assert!(String::from_utf8_lossy(&fourth.stderr).contains("finished earlier, not run again"));
}

/// Item 2. `run --overwrite` removes the files the earlier run listed in
/// its `run.json` and nothing else: a user's `checkpoints/notes.txt`, and
/// files named like a run's (`*.pvd`, `checkpoint*`, `.tmp.*`,
/// `particles_*.vtu`), stay (before: `checkpoints/` went with
/// `remove_dir_all`, and the others too).
#[test]
fn overwrite_removes_only_the_files_the_earlier_run_listed() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    let (scene, out_arg) = (bar().display().to_string(), out.display().to_string());
    let first = mpm_geo(&[
        "run",
        &scene,
        "--out",
        &out_arg,
        "--quiet",
        "--set",
        "output.snapshot_every=400",
        "--checkpoint-every",
        "500",
    ]);
    assert!(first.status.success());
    assert!(out.join("particles_001600.vtu").exists());
    let listed = json(&out.join("run.json"))["manifest"]["files"].clone();
    assert!(
        listed
            .as_array()
            .unwrap()
            .contains(&"checkpoint.bin".into()),
        "{listed}"
    );
    // the run's curve plot is drawn and listed, so --overwrite removes it
    for plot in ["curve.png", "curve.svg"] {
        assert!(out.join(plot).exists(), "{plot} not drawn");
        assert!(
            listed.as_array().unwrap().contains(&plot.into()),
            "{plot} not listed: {listed}"
        );
    }
    let first_plot = std::fs::read(out.join("curve.png")).unwrap();
    let mine = [
        "checkpoints/notes.txt",
        "checkpoint_plan.txt",
        "results.pvd",
        ".tmp.notes",
        "particles_plot.vtu",
        "notes.txt",
    ];
    std::fs::create_dir_all(out.join("checkpoints")).unwrap();
    for name in mine {
        std::fs::write(out.join(name), format!("mine: {name}")).unwrap();
    }

    let second = mpm_geo(&[
        "run",
        &scene,
        "--out",
        &out_arg,
        "--quiet",
        "--overwrite",
        "--set",
        "scene.end_time=0.1",
    ]);
    assert!(
        second.status.success(),
        "{}",
        String::from_utf8_lossy(&second.stderr)
    );
    for name in mine {
        assert_eq!(text(&out.join(name)), format!("mine: {name}"), "{name}");
    }
    let mut want = vec![
        ".tmp.notes",
        "checkpoint_plan.txt",
        "checkpoints",
        "curve.csv",
        "curve.png",
        "curve.svg",
        "notes.txt",
        "particles_plot.vtu",
        "results.pvd",
        "run.json",
    ];
    want.sort();
    assert_eq!(
        names(&out),
        want,
        "the earlier run's files are gone, the user's stay"
    );
    assert_eq!(status(&out), "completed");
    // the plot is the second run's (a shorter curve), not the first's
    assert_ne!(std::fs::read(out.join("curve.png")).unwrap(), first_plot);

    let help = String::from_utf8_lossy(&mpm_geo(&["run", "--help"]).stdout).into_owned();
    assert!(
        help.contains("listed in its run.json") && help.contains("nothing else"),
        "{help}"
    );
}

/// Item 3a. `--overwrite` removes the earlier run's exported linear
/// systems (before: its `systems/` stayed beside the new run's).
#[test]
fn overwrite_removes_the_earlier_runs_exported_systems() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    let scene = common::validation("elastic/oedometer.toml")
        .display()
        .to_string();
    let out_arg = out.display().to_string();
    let run = |extra: &[&str]| {
        let mut args = vec!["run", &scene, "--out", &out_arg, "--quiet"];
        args.extend(extra);
        let o = mpm_geo(&args);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    };
    run(&["--set", "output.systems=[1]"]);
    assert!(out.join("systems/step000001_solve00_it00_K.mtx").exists());
    std::fs::write(out.join("systems/README"), "mine").unwrap();
    run(&[
        "--overwrite",
        "--set",
        "scene.steps=2",
        "--set",
        "output.systems=[2]",
    ]);
    let left = names(&out.join("systems"));
    assert!(!left.is_empty());
    assert!(
        left.iter()
            .all(|n| n == "README" || n.starts_with("step000002_")),
        "{left:?}"
    );
    run(&["--overwrite"]);
    assert_eq!(names(&out.join("systems")), ["README"]);
}

/// `mpm-geo run BAR --out OUT` with a checkpoint every 100 steps, ended after
/// step 250 as a kill would (spawned to learn its process id).
fn stopped_bar(out: &Path, log: &Path) -> u32 {
    let (scene, out_arg) = (bar().display().to_string(), out.display().to_string());
    let mut child = spawn(
        &[
            "run",
            &scene,
            "--out",
            &out_arg,
            "--quiet",
            "--set",
            "output.snapshot_every=100",
            "--checkpoint-every",
            "100",
            "--stop-after-step",
            "250",
        ],
        log,
    );
    assert!(
        common::wait(&mut child, Duration::from_secs(60)).success(),
        "{}",
        text(log)
    );
    assert_eq!(status(out), "running");
    child.id()
}

/// Item 3b. The temporary files a killed run left (`.tmp.<its pid>.…`) are
/// removed by `resume` (before: never); a user's `.tmp.*` file stays.
#[test]
fn resume_removes_the_temporary_files_of_the_killed_process() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    let pid = stopped_bar(&out, &tmp.path().join("log"));
    // what a kill mid-snapshot and mid-checkpoint leaves
    let left = [
        format!(".tmp.{pid}.7.particles_000300.vtu"),
        format!(".tmp.{pid}.8.checkpoint.bin"),
    ];
    for name in &left {
        std::fs::write(out.join(name), "<VTKFile").unwrap();
    }
    std::fs::write(out.join(".tmp.notes"), "mine").unwrap();
    let resumed = mpm_geo(&["resume", out.to_str().unwrap(), "--quiet"]);
    assert!(
        resumed.status.success(),
        "{}",
        String::from_utf8_lossy(&resumed.stderr)
    );
    assert_eq!(status(&out), "completed");
    for name in &left {
        assert!(!out.join(name).exists(), "{name} left behind");
    }
    assert_eq!(text(&out.join(".tmp.notes")), "mine");
    let temporaries: Vec<String> = names(&out)
        .into_iter()
        .filter(|n| n.starts_with(".tmp.") && n != ".tmp.notes")
        .collect();
    assert!(temporaries.is_empty(), "{temporaries:?}");
}

/// Item 3c. A resume that fails at its first write (here `particles.pvd`
/// made a folder) leaves `run.json` as it was; a completed run is refused
/// before anything is written (before: both were marked `failed`, and the
/// completed run's curve was cut back to its last checkpoint).
#[test]
fn a_failed_resume_keeps_the_runs_status_and_a_completed_run_is_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    let out_arg = out.display().to_string();
    stopped_bar(&out, &tmp.path().join("log"));
    let block_pvd = || {
        std::fs::remove_file(out.join("particles.pvd")).unwrap();
        std::fs::create_dir(out.join("particles.pvd")).unwrap();
        std::fs::write(out.join("particles.pvd/x"), "").unwrap();
    };
    block_pvd();
    let before = std::fs::read(out.join("run.json")).unwrap();
    let failed = mpm_geo(&["resume", &out_arg, "--quiet"]);
    let stderr = String::from_utf8_lossy(&failed.stderr);
    assert_eq!(failed.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("particles.pvd"), "{stderr}");
    assert_eq!(
        std::fs::read(out.join("run.json")).unwrap(),
        before,
        "run.json changed"
    );
    assert_eq!(status(&out), "running");
    assert!(!out.join(".mpm-geo.lock").exists());

    // with the folder gone the run resumes to its end
    std::fs::remove_dir_all(out.join("particles.pvd")).unwrap();
    let resumed = mpm_geo(&["resume", &out_arg, "--quiet"]);
    assert!(
        resumed.status.success(),
        "{}",
        String::from_utf8_lossy(&resumed.stderr)
    );
    assert_eq!(status(&out), "completed");

    // a completed run (its last checkpoint still there) is not resumed
    block_pvd();
    let (run_json, curve) = (
        std::fs::read(out.join("run.json")).unwrap(),
        std::fs::read(out.join("curve.csv")).unwrap(),
    );
    let refused = mpm_geo(&["resume", &out_arg, "--quiet"]);
    let stderr = String::from_utf8_lossy(&refused.stderr);
    assert_eq!(refused.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains("error[CHECKPOINT_COMPLETED]"), "{stderr}");
    assert_eq!(std::fs::read(out.join("run.json")).unwrap(), run_json);
    assert_eq!(std::fs::read(out.join("curve.csv")).unwrap(), curve);
}

/// Item 4, campaign. SIGTERM (and SIGINT) to a campaign of two endless bar
/// runs in parallel: both end after a whole step with `run.json` saying
/// `interrupted`, neither leaves a record or a lock, the campaign exits
/// 143 (130) naming them (before: the process died at once, the runs'
/// `run.json` said `running` and their locks stayed).
#[test]
fn a_signal_to_a_campaign_interrupts_its_runs_and_releases_their_locks() {
    for (signal, name, code) in [
        (libc::SIGTERM, "SIGTERM", 143),
        (libc::SIGINT, "SIGINT", 130),
    ] {
        let tmp = tempfile::tempdir().unwrap();
        let scenes = bar_campaign(tmp.path(), &["bar_a", "bar_b"]);
        let out = tmp.path().join("out");
        let log = tmp.path().join("log");
        let mut campaign = spawn(
            &[
                "campaign",
                scenes.to_str().unwrap(),
                "--out",
                out.to_str().unwrap(),
                "--jobs",
                "2",
                "--set",
                "scene.end_time=1000",
                "--set",
                "output.curve_every=100",
                "--checkpoint-every",
                "100000",
            ],
            &log,
        );
        for run in ["bar_a", "bar_b"] {
            common::wait_for_rows(&out.join(run), 5, &mut campaign);
        }
        send(&campaign, signal);
        let exit = common::wait(&mut campaign, Duration::from_secs(60));
        let stderr = text(&log);
        assert_eq!(exit.code(), Some(code), "{stderr}");
        assert!(
            stderr.contains(&format!("campaign interrupted by {name}"))
                && stderr.contains("bar_a, bar_b"),
            "{stderr}"
        );
        for run in ["bar_a", "bar_b"] {
            let dir = out.join(run);
            let report = json(&dir.join("run.json"));
            assert_eq!(report["status"], "interrupted", "{run}");
            assert_eq!(report["interrupted"]["signal"], name);
            assert!(!dir.join("campaign_run.json").exists(), "{run} recorded");
            // the checkpoint of the interrupted step, to resume from
            assert!(dir.join("checkpoint.bin").exists(), "{run}");
        }
        assert!(find(&out, ".mpm-geo.lock").is_empty(), "a lock is left");
        assert!(!out.join("report.md").exists());
    }
}

/// Item 4, study. SIGTERM to a study passes it to the run in progress
/// (a process of its own): the run ends after a whole step with `run.json`
/// saying `interrupted` and no lock, the study records no measurement and
/// exits 143 (before: the study died at once and its run went on alone).
#[test]
fn sigterm_to_a_study_interrupts_its_run() {
    let tmp = tempfile::tempdir().unwrap();
    let spec = tmp.path().join("signal.toml");
    std::fs::write(
        &spec,
        format!(
            r#"[study]
name = "signal"
scene = "{}"
repeats = 1

[reference]
kind = "closed_form"
name = "bar_vibration"
monitor = "top_uy"
parameters = {{ height = 1.0, wave_speed = 100.0, velocity = 0.01 }}

[[quantity]]
monitor = "top_uy"
measure = "l2"

[[series]]
label = "explicit"
integrator = "explicit"
refine = "solver.cfl"
values = [0.5, 0.25]
"#,
            bar().display()
        ),
    )
    .unwrap();
    let out = tmp.path().join("out");
    let log = tmp.path().join("log");
    let mut study = spawn(
        &[
            "study",
            spec.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--set",
            "scene.end_time=1000",
            "--set",
            "output.curve_every=100",
        ],
        &log,
    );
    let start = Instant::now();
    let run = loop {
        let found = if out.is_dir() {
            find(&out, "curve.csv")
        } else {
            Vec::new()
        };
        if let Some(curve) = found.first() {
            if text(curve).lines().count() > 5 {
                break curve.parent().unwrap().to_path_buf();
            }
        }
        assert!(
            start.elapsed() < Duration::from_secs(60),
            "no run started: {}",
            text(&log)
        );
        std::thread::sleep(Duration::from_millis(10));
    };
    send(&study, libc::SIGTERM);
    let exit = common::wait(&mut study, Duration::from_secs(60));
    let stderr = text(&log);
    assert_eq!(exit.code(), Some(143), "{stderr}");
    assert!(stderr.contains("study interrupted by SIGTERM"), "{stderr}");
    assert_eq!(status(&run), "interrupted");
    assert!(
        !run.join(".mpm-geo.lock").exists(),
        "the run's lock is left"
    );
    assert!(
        find(&out, "measured.json").is_empty(),
        "an interrupted run was recorded"
    );
    // the run process has ended (no orphan writing on)
    let rows = text(&run.join("curve.csv")).lines().count();
    std::thread::sleep(Duration::from_millis(300));
    assert_eq!(text(&run.join("curve.csv")).lines().count(), rows);
}

/// A run whose step fails (a point falls out of the grid) keeps its last
/// checkpoint but is not offered `mpm-geo resume`: the same step from the
/// same checkpoint fails the same way, so the message says so, and
/// `run.json`'s summary carries no resume command (an interrupted run, or
/// one whose write failed, gets both).
#[test]
fn a_run_stopped_by_a_failed_step_is_not_offered_a_resume() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    let scene = common::validation("failures/falls_out_of_grid.toml");
    let failed = mpm_geo(&[
        "run",
        scene.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--checkpoint-every",
        "10",
        "--quiet",
    ]);
    let stderr = String::from_utf8_lossy(&failed.stderr);
    assert_eq!(failed.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("error[RUN_POINT_LEFT_GRID]"), "{stderr}");
    assert!(out.join("checkpoint.bin").exists());
    assert!(!stderr.contains("mpm-geo resume"), "{stderr}");
    assert!(stderr.contains("would repeat this step"), "{stderr}");
    let summary = &json(&out.join("run.json"))["summary"];
    assert_eq!(summary["status"], "failed");
    assert!(summary["resume"].is_null(), "{summary}");
}
