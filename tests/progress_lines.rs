//! A run whose stderr is a pipe (a batch job, a log file) prints plain
//! progress lines, the step, the time reached and its share, the first
//! monitor and an estimate of the time left, at the interval asked for;
//! with `--quiet` a successful run prints nothing.

use std::path::Path;
use std::process::Command;

/// stderr of `mpm-geo run` on the coarse friction cut to t = 0.25 s (before any point leaves the grid) with
/// the extra `args`.
fn run_cut(args: &[&str]) -> String {
    let dir = tempfile::tempdir().unwrap();
    let scene = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("validation/vertical_cut_friction/local_h100.toml");
    let output = Command::new(env!("CARGO_BIN_EXE_mpm-geo"))
        .arg("run")
        .arg(&scene)
        .args(["--set", "grid.cell_size=0.25", "--set", "scene.steps=250"])
        .arg("--out")
        .arg(dir.path())
        .args(args)
        .output()
        .unwrap();
    assert!(output.status.success(), "{output:?}");
    String::from_utf8(output.stderr).unwrap()
}

/// With lines every 0.05 s a run of more than 0.5 s prints several, each
/// with its step, time, share done and the first monitor (u_A), the shares
/// rising; the last says how long is left.
#[test]
fn a_piped_run_prints_progress_lines() {
    let stderr = run_cut(&["--progress-every", "0.05"]);
    let lines: Vec<&str> = stderr.lines().filter(|l| l.starts_with("step ")).collect();
    assert!(lines.len() >= 2, "{stderr}");
    let share = |line: &str| -> f64 {
        let open = line.find('(').unwrap();
        let close = line.find(" %)").unwrap();
        line[open + 1..close].parse().unwrap()
    };
    for pair in lines.windows(2) {
        assert!(share(pair[1]) > share(pair[0]), "{pair:?}");
    }
    for line in &lines {
        assert!(line.contains(" t = ") && line.contains("  uA = "), "{line}");
    }
    assert!(lines[0].contains("left ~"), "{}", lines[0]);
}

/// `--quiet`: no progress lines, no profile, nothing on a success without
/// warnings (a warning, e.g. of points that left the grid, is still told).
#[test]
fn a_quiet_run_prints_nothing() {
    let stderr = run_cut(&["--quiet", "--progress-every", "0.05"]);
    assert_eq!(stderr, "");
}
