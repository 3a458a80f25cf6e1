//! Runs that survive a hostile user (issue 14, check 3): a signal ends a run
//! after a whole step with `run.json` saying `interrupted`; a second run
//! into a locked directory is refused; a reused directory is refused without
//! `--overwrite` and cleared of the earlier run's files with it; a stale lock
//! of a dead process is taken over; a full disk (a real 64–96 KiB tmpfs)
//! stops the run with exit 1 naming step, time and path, and leaves every
//! file whole or absent. The tests drive the `mpm-geo` binary as a user would.

#![cfg(target_os = "linux")]

mod common;

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::Duration;

const BIN: &str = env!("CARGO_BIN_EXE_mpm-geo");

/// The explicit elastic bar (80 points, 2.5e-4 s steps): cheap steps.
fn bar() -> String {
    common::validation("elastic/bar_explicit.toml")
        .display()
        .to_string()
}

/// Start `mpm-geo run SCENE --out OUT --quiet ARGS`, stderr to `log`.
fn spawn_run(scene: &str, out: &Path, args: &[&str], log: &Path) -> Child {
    Command::new(BIN)
        .args(["run", scene, "--out"])
        .arg(out)
        .arg("--quiet")
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(std::fs::File::create(log).unwrap())
        .spawn()
        .expect("binary runs")
}

/// Run to the end: (exit code, stderr).
fn run(scene: &str, out: &Path, args: &[&str]) -> (i32, String) {
    let o = Command::new(BIN)
        .args(["run", scene, "--out"])
        .arg(out)
        .arg("--quiet")
        .args(args)
        .output()
        .expect("binary runs");
    (
        o.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

fn json(path: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{} is not whole: {e}", path.display()))
}

/// The rows of `curve.csv` after checking that every row is whole: the file
/// ends with a newline, every row has the header's fields, numbers parse and
/// the steps run 0, 1, 2, … (`curve_every = 1`). Returns (step, time) per row.
fn whole_rows(path: &Path) -> Vec<(usize, f64)> {
    let text = std::fs::read_to_string(path).unwrap();
    assert!(text.ends_with('\n'), "curve.csv ends in a cut row");
    let mut lines = text.lines();
    let fields = lines.next().expect("header").split(',').count();
    let rows: Vec<(usize, f64)> = lines
        .map(|l| {
            let cells: Vec<&str> = l.split(',').collect();
            assert_eq!(cells.len(), fields, "cut row `{l}`");
            for c in &cells[1..] {
                c.parse::<f64>()
                    .unwrap_or_else(|_| panic!("cut number in `{l}`"));
            }
            (cells[0].parse().unwrap(), cells[1].parse().unwrap())
        })
        .collect();
    for (i, (step, _)) in rows.iter().enumerate() {
        assert_eq!(*step, i, "rows out of order");
    }
    rows
}

/// Every snapshot is a whole `.vtu`, the `.pvd` is whole and lists exactly
/// the snapshots present; no temporary file is left. Returns the snapshots.
fn whole_snapshots(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    assert!(
        !names.iter().any(|n| n.starts_with(".tmp.")),
        "temporary file left: {names:?}"
    );
    let vtus: Vec<String> = names
        .iter()
        .filter(|n| n.ends_with(".vtu"))
        .cloned()
        .collect();
    for v in &vtus {
        let text = std::fs::read_to_string(dir.join(v)).unwrap();
        assert!(text.ends_with("</VTKFile>\n"), "{v} is cut");
    }
    let pvd = dir.join("particles.pvd");
    if pvd.exists() {
        let text = std::fs::read_to_string(&pvd).unwrap();
        assert!(text.ends_with("</VTKFile>\n"), "particles.pvd is cut");
        let listed: Vec<String> = text
            .split("file=\"")
            .skip(1)
            .map(|s| s.split('"').next().unwrap().to_string())
            .collect();
        assert_eq!(listed, vtus, "particles.pvd lists other files");
    } else {
        assert!(vtus.is_empty(), "snapshots without particles.pvd");
    }
    vtus
}

/// `[…]` scene overrides of a bar run long enough never to end by itself.
const ENDLESS: [&str; 4] = [
    "--set",
    "scene.end_time=1000",
    "--set",
    "output.snapshot_every=200",
];

fn send(child: &Child, signal: i32) {
    let pid = libc::pid_t::try_from(child.id()).unwrap();
    // SAFETY: sends a signal to our own child process.
    assert_eq!(unsafe { libc::kill(pid, signal) }, 0);
}

#[test]
fn a_signal_ends_the_run_after_a_whole_step_and_a_second_run_is_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = bar();
    let cases = [
        (libc::SIGTERM, "SIGTERM", 143),
        (libc::SIGINT, "SIGINT", 130),
    ];
    let mut children: Vec<(Child, PathBuf)> = cases
        .iter()
        .map(|(_, name, _)| {
            let out = tmp.path().join(name);
            let log = tmp.path().join(format!("{name}.log"));
            (spawn_run(&scene, &out, &ENDLESS, &log), out)
        })
        .collect();
    for ((signal, name, code), (child, out)) in cases.iter().zip(&mut children) {
        // past the first snapshots: the run is in its time loop
        common::wait_for_rows(out, 450, child);
        let running = json(&out.join("run.json"));
        assert_eq!(running["status"], "running", "{running}");

        // a second run into the locked directory is refused and writes nothing
        let before = std::fs::read(out.join("particles_000000.vtu")).unwrap();
        let (refused, text) = run(&scene, out, &["--set", "scene.end_time=0.01"]);
        assert_eq!(refused, 2, "{text}");
        assert!(
            text.contains("locked by process") && text.contains(&child.id().to_string()),
            "{text}"
        );
        assert_eq!(
            std::fs::read(out.join("particles_000000.vtu")).unwrap(),
            before
        );

        send(child, *signal);
        let status = common::wait(child, Duration::from_secs(60));
        let log = std::fs::read_to_string(tmp.path().join(format!("{name}.log"))).unwrap();
        assert_eq!(status.code(), Some(*code), "{log}");
        let report = json(&out.join("run.json"));
        assert_eq!(report["status"], "interrupted", "{report}");
        assert_eq!(report["interrupted"]["signal"], *name);
        let step = report["steps_completed"].as_u64().unwrap() as usize;
        let time = report["time"].as_f64().unwrap();
        let rows = whole_rows(&out.join("curve.csv"));
        assert!(rows.len() > 450);
        // the last row is the interrupted step, and run.json says so
        // (serde_json reads the time to within an ulp or so)
        let last = rows.last().unwrap();
        assert_eq!(last.0, step);
        assert!(
            (last.1 - time).abs() <= 1e-14 * time,
            "{last:?} vs t = {time}"
        );
        assert!(time < 1000.0);
        assert!(
            log.contains(&format!("interrupted by {name} after step {step}")),
            "{log}"
        );
        let snapshots = whole_snapshots(out);
        assert_eq!(snapshots.len(), step / 200 + 1);
        // the collection gives each snapshot the time of its step
        let pvd = std::fs::read_to_string(out.join("particles.pvd")).unwrap();
        let times: Vec<f64> = pvd
            .split("timestep=\"")
            .skip(1)
            .map(|s| s.split('"').next().unwrap().parse().unwrap())
            .collect();
        for (name, t) in snapshots.iter().zip(&times) {
            let snap_step: usize = name[10..16].parse().unwrap();
            assert_eq!(*t, rows[snap_step].1, "{name}");
        }
        assert!(!out.join(".mpm-geo.lock").exists(), "lock left behind");
    }
}

#[test]
fn a_reused_directory_is_refused_unless_overwrite_then_cleared_of_the_old_run() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    let scene = bar();
    let (code, text) = run(
        &scene,
        &out,
        &[
            "--set",
            "scene.end_time=0.01",
            "--set",
            "output.snapshot_every=10",
        ],
    );
    assert_eq!(code, 0, "{text}");
    assert!(out.join("particles_000040.vtu").exists());
    std::fs::write(out.join("notes.txt"), "mine").unwrap();
    let old_json = std::fs::read(out.join("run.json")).unwrap();

    // another scene into the same directory: refused, nothing touched
    let oedometer = common::validation("elastic/oedometer.toml");
    let oedometer = oedometer.to_str().unwrap();
    let (code, text) = run(oedometer, &out, &[]);
    assert_eq!(code, 2, "{text}");
    assert!(
        text.contains("earlier run's files") && text.contains("--overwrite"),
        "{text}"
    );
    assert_eq!(std::fs::read(out.join("run.json")).unwrap(), old_json);
    assert!(out.join("particles_000040.vtu").exists());

    // with --overwrite: the old run's files go, the user's stay
    let (code, text) = run(oedometer, &out, &["--overwrite"]);
    assert_eq!(code, 0, "{text}");
    let report = json(&out.join("run.json"));
    assert_eq!(report["status"], "completed");
    assert_eq!(report["scene"]["scene"]["name"], "oedometer", "{report}");
    assert!(
        !out.join("particles_000040.vtu").exists(),
        "old snapshot kept"
    );
    whole_snapshots(&out);
    let rows = whole_rows(&out.join("curve.csv"));
    assert_eq!(
        rows.last().unwrap().0,
        report["steps_completed"].as_u64().unwrap() as usize
    );
    assert_eq!(
        std::fs::read_to_string(out.join("notes.txt")).unwrap(),
        "mine"
    );
}

#[test]
fn a_stale_lock_of_a_dead_process_is_taken_over_with_a_warning() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    std::fs::create_dir_all(&out).unwrap();
    // the pid of a process that has ended (a run killed with SIGKILL)
    let mut gone = Command::new("true").spawn().unwrap();
    let pid = gone.id();
    gone.wait().unwrap();
    std::fs::write(out.join(".mpm-geo.lock"), pid.to_string()).unwrap();
    let (code, text) = run(&bar(), &out, &["--set", "scene.end_time=0.01"]);
    assert_eq!(code, 0, "{text}");
    assert!(
        text.contains("taking over the lock") && text.contains(&format!("process {pid}")),
        "{text}"
    );
    assert_eq!(json(&out.join("run.json"))["status"], "completed");
    assert!(!out.join(".mpm-geo.lock").exists());
}

/// Run the bar on a fresh tmpfs of `size` (a mount namespace of its own:
/// `unshare`), copying its output directory to `keep` afterwards: (exit
/// code, stderr, the output directory's path inside the mount).
fn run_on_small_disk(size: &str, args: &[&str], keep: &Path) -> (i32, String, String) {
    let mount = keep.with_extension("mnt");
    std::fs::create_dir_all(&mount).unwrap();
    let log = keep.with_extension("log");
    let script = r#"mount -t tmpfs -o size="$SIZE" tmpfs "$MNT" || exit 90
"$BIN" "$@" 2> "$LOG"
rc=$?
cp -a "$MNT/out" "$KEEP" || exit 91
exit $rc"#;
    let out_inside = format!("{}/out", mount.display());
    let scene = bar();
    let status = Command::new("unshare")
        .args([
            "--user",
            "--map-root-user",
            "--mount",
            "sh",
            "-c",
            script,
            "sh",
        ])
        .args(["run", &scene, "--out", &out_inside, "--quiet"])
        .args(args)
        .env("SIZE", size)
        .env("MNT", &mount)
        .env("BIN", BIN)
        .env("LOG", &log)
        .env("KEEP", keep)
        .status()
        .expect("unshare (util-linux) runs");
    let code = status.code().unwrap_or(-1);
    assert!(
        code != 90 && code != 91,
        "could not mount a small tmpfs (user namespaces): {status}"
    );
    (code, std::fs::read_to_string(&log).unwrap(), out_inside)
}

/// `run stopped: step N (t = T s): cannot write PATH: …` → (N, T, PATH).
fn stopped_at(text: &str) -> (usize, f64, String) {
    let rest = text
        .split("run stopped: step ")
        .nth(1)
        .unwrap_or_else(|| panic!("no step in {text}"));
    let step = rest.split_whitespace().next().unwrap().parse().unwrap();
    let time = rest
        .split("(t = ")
        .nth(1)
        .and_then(|s| s.split_whitespace().next())
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| panic!("no time in {text}"));
    let path = rest
        .split("cannot write ")
        .nth(1)
        .and_then(|s| s.split(": ").next())
        .unwrap_or_else(|| panic!("no path in {text}"))
        .to_string();
    (step, time, path)
}

#[test]
fn a_full_disk_stops_the_run_naming_step_time_and_path_and_leaves_files_whole() {
    let tmp = tempfile::tempdir().unwrap();
    // a: snapshots fill the disk; b: the curve does (no snapshots)
    let cases: [(&str, &[&str]); 2] = [
        (
            "96k",
            &[
                "--set",
                "scene.end_time=1000",
                "--set",
                "output.snapshot_every=50",
            ],
        ),
        ("64k", &["--set", "scene.end_time=1000"]),
    ];
    let mut failed_on = Vec::new();
    for (i, (size, args)) in cases.iter().enumerate() {
        let keep = tmp.path().join(format!("case{i}"));
        let (code, text, inside) = run_on_small_disk(size, args, &keep);
        assert_eq!(code, 1, "{text}");
        assert!(text.contains("No space left on device"), "{text}");
        let (step, time, path) = stopped_at(&text);
        assert!(step > 0, "{text}");
        let name = path
            .strip_prefix(&format!("{inside}/"))
            .unwrap_or_else(|| panic!("{path} is not in the output directory"))
            .to_string();
        failed_on.push(name.clone());

        let rows = whole_rows(&keep.join("curve.csv"));
        let last = *rows.last().unwrap();
        // the row of the failing step is whole or absent
        assert!(
            last.0 == step || last.0 + 1 == step,
            "{last:?} at step {step}"
        );
        if last.0 == step {
            assert!(
                (last.1 - time).abs() <= 1e-6 * time,
                "{last:?} vs t = {time}"
            );
        }
        let snapshots = whole_snapshots(&keep);
        if name.ends_with(".vtu") {
            assert!(
                !snapshots.contains(&name),
                "{name} written although it failed"
            );
        }
        // run.json is whole: `failed` with the same message, or still the
        // `running` written before step 1 if no space was left for it
        let report = json(&keep.join("run.json"));
        match report["status"].as_str() {
            Some("failed") => {
                let error = report["error"].as_str().unwrap();
                assert!(text.contains(error), "{error} vs {text}");
            }
            Some("running") => {}
            other => panic!("run.json status {other:?}"),
        }
    }
    assert!(failed_on[0].ends_with(".vtu"), "{failed_on:?}");
    assert_eq!(failed_on[1], "curve.csv");
}

#[test]
fn a_killed_run_leaves_no_cut_snapshot_and_overwrite_clears_its_leftovers() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    let scene = bar();
    // a 30 kB snapshot every step: most of the run is spent writing them
    let args = [
        "--set",
        "scene.end_time=1000",
        "--set",
        "output.snapshot_every=1",
    ];
    let mut child = spawn_run(&scene, &out, &args, &tmp.path().join("log"));
    common::wait_for_rows(&out, 40, &mut child);
    send(&child, libc::SIGKILL);
    common::wait(&mut child, Duration::from_secs(60));
    let mut names: Vec<String> = std::fs::read_dir(&out)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    // snapshots under their own names; a temporary name (`.tmp.<pid>.<n>.<name>`) left by
    // the kill mid-write is no snapshot (it is removed with --overwrite below). A step's
    // row is written before its snapshot, so every step before the last row's has its
    // snapshot whole, and the last row's step may be the one cut.
    let vtus: Vec<&String> = names
        .iter()
        .filter(|n| n.ends_with(".vtu") && !n.starts_with(".tmp."))
        .collect();
    let rows = whole_rows(&out.join("curve.csv")).len();
    assert!(rows >= 40, "{rows} rows");
    assert!(vtus.len() + 1 >= rows, "{rows} rows, {names:?}");
    for v in &vtus {
        let text = std::fs::read_to_string(out.join(v)).unwrap();
        assert!(text.ends_with("</VTKFile>\n"), "{v} is cut");
    }
    // killed with no chance to say more: run.json still says `running`
    assert_eq!(json(&out.join("run.json"))["status"], "running");

    // the dead run's lock is taken over; its files (a temporary name left
    // mid-write too, if any) are refused, then removed with --overwrite
    let short = ["--set", "scene.end_time=0.01"];
    let (code, text) = run(&scene, &out, &short);
    assert_eq!(code, 2, "{text}");
    assert!(text.contains("taking over the lock"), "{text}");
    let (code, text) = run(&scene, &out, &[short[0], short[1], "--overwrite"]);
    assert_eq!(code, 0, "{text}");
    assert_eq!(json(&out.join("run.json"))["status"], "completed");
    assert!(whole_snapshots(&out).is_empty(), "old snapshots kept");
}
