//! Running a study's runs: each as a whole `mpm-geo run` process on its
//! resolved `scene.toml`, one at a time (so timings do not compete), timed
//! `repeats` times.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use super::spec::PlannedRun;
use super::StudyError;
use crate::output::TIME_COLUMN;
use crate::profile::Stage;
use crate::scene::MonitorSpec;

/// Monitor histories `(t, value)` by monitor name.
pub type Histories = Vec<(String, Vec<(f64, f64)>)>;

/// What one run measured (from its process, `run.json` and `curve.csv`).
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct Measured {
    /// Wall time of the whole process per repeat, s.
    pub wall_seconds: Vec<f64>,
    /// Exclusive seconds per stage ([`Stage::ALL`] order) of the median repeat.
    pub stage_seconds: Vec<f64>,
    /// `completed`, or `stopped: <why>` (exit code 1: the run failed mid-way),
    /// `refused: <why>` (exit code 2 or refused by the plan: nothing ran);
    /// anything else is a fault of the engine: `panicked: <message>` (exit
    /// code 101), `timed out: …` (killed at `study.timeout`), `killed: …`
    /// (ended by a signal), `failed: exit code N: …`.
    pub status: String,
    /// Steps completed.
    pub steps: usize,
    /// Newton iterations (implicit).
    pub newton_iterations: usize,
    /// Factorisations (Cholesky + LU).
    pub factorisations: usize,
    /// Step halvings (implicit).
    pub halvings: usize,
    /// The linear solver's figures from `run.json` (issue 16).
    pub linear: LinearFigures,
    /// Monitor histories `(t, value)` by monitor name (from `curve.csv`).
    pub histories: Histories,
}

/// The linear solver's time per Newton iteration, fill and PCG work of a run
/// (`run.json` `solver.linear`).
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct LinearFigures {
    /// Seconds of ordering, factorisation and solves per Newton iteration.
    pub seconds_per_newton_iteration: f64,
    /// Stored entries of the last factor (or preconditioner), if known.
    pub factor_nnz: Option<u64>,
    /// Conjugate-gradient iterations, all systems together.
    pub pcg_iterations: u64,
    /// Systems solved by LU instead of the method asked for.
    pub fallbacks: u64,
}

impl Measured {
    /// Median wall time over the repeats, s.
    pub fn median_wall(&self) -> f64 {
        median(&self.wall_seconds)
    }

    /// The history of `monitor`.
    pub fn history(&self, monitor: &str) -> Option<&[(f64, f64)]> {
        self.histories
            .iter()
            .find(|(name, _)| name == monitor)
            .map(|(_, h)| h.as_slice())
    }

    /// Whether the run completed.
    pub fn completed(&self) -> bool {
        self.status == "completed"
    }

    /// Whether the run ended in a stated outcome: completed, or stopped or
    /// refused with a reason (not a panic, a time-out, a signal or an
    /// unknown exit code).
    pub fn stated(&self) -> bool {
        self.completed()
            || ["stopped: ", "refused: "].iter().any(|prefix| {
                self.status
                    .strip_prefix(prefix)
                    .is_some_and(|why| !why.trim().is_empty())
            })
    }

    /// A run refused before it was started (the plan's validation said why).
    pub fn refused(why: &str) -> Self {
        Self {
            wall_seconds: Vec::new(),
            stage_seconds: Vec::new(),
            status: format!("refused: {}", one_line(why)),
            steps: 0,
            newton_iterations: 0,
            factorisations: 0,
            halvings: 0,
            linear: LinearFigures::default(),
            histories: Vec::new(),
        }
    }
}

/// Median of a non-empty list (mean of the middle two for an even count).
pub fn median(values: &[f64]) -> f64 {
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    match v.len() {
        0 => f64::NAN,
        n if n % 2 == 1 => v[n / 2],
        n => 0.5 * (v[n / 2 - 1] + v[n / 2]),
    }
}

/// Run `planned` `repeats` times with the `mpm-geo` executable `exe` into
/// `dir` (its `scene.toml` is the scene run, so a run is reproduced by
/// `mpm-geo run dir/scene.toml`; its stderr is `dir/stderr.txt`), each
/// process killed after `timeout` seconds. A run the plan refused is not run.
/// Each run process has a process group of its own, so a signal caught by
/// [`crate::interrupt`] (SIGINT, SIGTERM) reaches it once, passed on by the
/// study: the run ends after a whole step and the study returns
/// [`StudyError::Interrupted`].
pub fn execute(
    exe: &Path,
    planned: &PlannedRun,
    dir: &Path,
    repeats: usize,
    timeout: Option<f64>,
) -> Result<Measured, StudyError> {
    if let Some(why) = &planned.refused {
        return Ok(Measured::refused(why));
    }
    let io = |path: &Path, e: &dyn std::fmt::Display| StudyError::Io {
        path: path.display().to_string(),
        message: e.to_string(),
    };
    std::fs::create_dir_all(dir).map_err(|e| io(dir, &e))?;
    let scene_path = dir.join("scene.toml");
    let text = toml::to_string(&planned.scene).map_err(|e| io(&scene_path, &e))?;
    crate::atomic_file::write_atomic(&scene_path, text).map_err(|e| io(&scene_path, &e))?;
    let out = dir.join("output");
    let mut runs: Vec<(f64, Vec<f64>)> = Vec::new();
    let mut last_status = String::new();
    for _ in 0..repeats.max(1) {
        if let Some(signal) = crate::interrupt::requested() {
            return Err(StudyError::Interrupted { signal, run: None });
        }
        // a refused or stopped run must not be read from an earlier run's files
        if out.exists() {
            std::fs::remove_dir_all(&out).map_err(|e| io(&out, &e))?;
        }
        let stderr_path = dir.join("stderr.txt");
        let stderr_file = std::fs::File::create(&stderr_path).map_err(|e| io(&stderr_path, &e))?;
        let start = Instant::now();
        let mut command = Command::new(exe);
        command
            .arg("run")
            .arg(&scene_path)
            .arg("--out")
            .arg(&out)
            .arg("--quiet")
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(stderr_file);
        own_process_group(&mut command);
        let mut child = command.spawn().map_err(|e| io(exe, &e))?;
        let mut passed_on = None;
        let (status, timed_out) = loop {
            if let Some(status) = child.try_wait().map_err(|e| io(exe, &e))? {
                break (Some(status), false);
            }
            if passed_on.is_none() {
                if let Some(signal) = crate::interrupt::requested() {
                    pass_on(&child, signal);
                    passed_on = Some(signal);
                }
            }
            let elapsed = start.elapsed().as_secs_f64();
            if timeout.is_some_and(|t| elapsed > t) {
                // the process may end between the check and the kill
                let _ = child.kill();
                let status = child.wait().map_err(|e| io(exe, &e))?;
                break (Some(status), true);
            }
            // poll finely at first: the wall time is measured to ~0.5 %
            std::thread::sleep(Duration::from_secs_f64((elapsed / 200.0).clamp(2e-4, 0.02)));
        };
        if let Some(signal) = passed_on {
            // not measured: the run is made again by the next study
            return Err(StudyError::Interrupted {
                signal,
                run: Some(planned.name.clone()),
            });
        }
        let wall = start.elapsed().as_secs_f64();
        let stderr = std::fs::read_to_string(&stderr_path).unwrap_or_default();
        last_status = match (timed_out, status.and_then(|s| s.code())) {
            (true, _) => format!(
                "timed out: killed after {wall:.1} s (study.timeout = {} s)",
                timeout.unwrap_or(f64::NAN)
            ),
            (false, Some(0)) => "completed".to_string(),
            (false, Some(1)) => format!("stopped: {}", last_error_line(&stderr)),
            (false, Some(2)) => format!("refused: {}", last_error_line(&stderr)),
            (false, Some(101)) => format!("panicked: {}", panic_message(&stderr)),
            (false, Some(code)) => {
                format!("failed: exit code {code}: {}", last_error_line(&stderr))
            }
            (false, None) => format!("killed: {}", signal_text(status)),
        };
        let stages = read_stage_seconds(&out.join("run.json")).unwrap_or_default();
        runs.push((wall, stages));
        if !last_status.starts_with("completed") && !last_status.starts_with("stopped") {
            // a refusal, a panic or a time-out is not timed again
            break;
        }
    }
    let walls: Vec<f64> = runs.iter().map(|r| r.0).collect();
    let median_wall = median(&walls);
    let stage_seconds = runs
        .iter()
        .min_by(|a, b| {
            (a.0 - median_wall)
                .abs()
                .total_cmp(&(b.0 - median_wall).abs())
        })
        .map(|r| r.1.clone())
        .unwrap_or_default();
    let usage = read_usage(&out.join("run.json")).unwrap_or_default();
    let histories = read_curve(&out.join("curve.csv"), &planned.scene.monitor).unwrap_or_default();
    Ok(Measured {
        wall_seconds: walls,
        stage_seconds,
        status: last_status,
        steps: usage.0,
        newton_iterations: usage.1,
        factorisations: usage.2,
        halvings: usage.3,
        linear: read_linear(&out.join("run.json")).unwrap_or_default(),
        histories,
    })
}

/// Start the run process in a process group of its own (Unix), so a
/// terminal's Ctrl-C reaches only the study, which passes it on once (a
/// second SIGINT would end the run at once, without its `run.json`).
fn own_process_group(command: &mut Command) {
    #[cfg(unix)]
    {
        use std::os::unix::process::CommandExt;
        command.process_group(0);
    }
    #[cfg(not(unix))]
    let _ = command;
}

/// Send `signal` to the run process `child` (Unix; elsewhere it is killed).
fn pass_on(child: &std::process::Child, signal: crate::interrupt::Interruption) {
    #[cfg(unix)]
    {
        if let Ok(pid) = libc::pid_t::try_from(child.id()) {
            // SAFETY: sends a signal to our own child process.
            unsafe {
                libc::kill(pid, signal.signal);
            }
        }
    }
    #[cfg(not(unix))]
    {
        let _ = (child, signal);
    }
}

/// The `error:` line of a run's stderr (else its last non-empty line), and
/// for a refused scene the list of fields below it, on one line.
fn last_error_line(stderr: &str) -> String {
    let mut lines = stderr.lines();
    // `error[ID]: message` (or `error: message` of older builds), kept with its identifier
    let message = |line: &str| {
        let rest = line.strip_prefix("error")?;
        if let Some(text) = rest.strip_prefix(": ") {
            return Some(text.to_string());
        }
        let (id, text) = rest.strip_prefix('[')?.split_once("]: ")?;
        Some(format!("[{id}] {text}"))
    };
    let text = match lines.by_ref().find_map(message) {
        Some(first) => {
            // `scene … is invalid:` is followed by `  - field: message` lines
            let items: Vec<&str> = lines
                .take_while(|l| l.starts_with("  - "))
                .map(|l| l.trim_start_matches("  - "))
                .collect();
            if items.is_empty() {
                first.to_string()
            } else {
                format!("{first} {}", items.join("; "))
            }
        }
        None => stderr
            .lines()
            .rev()
            .find(|l| !l.trim().is_empty())
            .unwrap_or("no message")
            .to_string(),
    };
    one_line(&text)
}

/// `text` on one CSV-safe line (commas become semicolons).
fn one_line(text: &str) -> String {
    text.split_whitespace()
        .collect::<Vec<_>>()
        .join(" ")
        .replace(',', ";")
}

/// Where and why a run panicked: the `panicked at` line and the message after it.
fn panic_message(stderr: &str) -> String {
    let mut lines = stderr.lines();
    match lines.by_ref().find(|l| l.contains("panicked at")) {
        Some(at) => one_line(&format!("{at} {}", lines.next().unwrap_or(""))),
        None => last_error_line(stderr),
    }
}

/// The signal that ended a process, as text.
fn signal_text(status: Option<std::process::ExitStatus>) -> String {
    #[cfg(unix)]
    {
        use std::os::unix::process::ExitStatusExt;
        if let Some(signal) = status.and_then(|s| s.signal()) {
            return format!("signal {signal}");
        }
    }
    format!("{status:?}")
}

fn read_json(path: &Path) -> Option<serde_json::Value> {
    serde_json::from_str(&std::fs::read_to_string(path).ok()?).ok()
}

/// Seconds per stage from `run.json`'s profile, in [`Stage::ALL`] order.
fn read_stage_seconds(path: &Path) -> Option<Vec<f64>> {
    let json = read_json(path)?;
    let rows = json.get("profile")?.as_array()?;
    Some(
        Stage::ALL
            .iter()
            .map(|stage| {
                rows.iter()
                    .find(|r| r.get("stage").and_then(|s| s.as_str()) == Some(stage.name()))
                    .and_then(|r| r.get("seconds")?.as_f64())
                    .unwrap_or(0.0)
            })
            .collect(),
    )
}

/// (steps, Newton iterations, factorisations, halvings) from `run.json`.
fn read_usage(path: &Path) -> Option<(usize, usize, usize, usize)> {
    let json = read_json(path)?;
    let usage = json.get("solver")?.get("usage")?;
    let count = |key: &str| usage.get(key).and_then(|v| v.as_u64()).unwrap_or(0) as usize;
    let steps = json.get("steps_completed")?.as_u64()? as usize;
    Some((
        steps,
        count("newton_iterations"),
        count("cholesky") + count("lu") + count("pcg") + count("ldl"),
        count("halvings"),
    ))
}

/// The linear solver's figures from `run.json`.
fn read_linear(path: &Path) -> Option<LinearFigures> {
    let json = read_json(path)?;
    let linear = json.get("solver")?.get("linear")?;
    let u = |key: &str| linear.get(key).and_then(|v| v.as_u64());
    Some(LinearFigures {
        seconds_per_newton_iteration: linear
            .get("seconds_per_newton_iteration")
            .and_then(|v| v.as_f64())
            .unwrap_or(0.0),
        factor_nnz: u("factor_nnz"),
        pcg_iterations: u("pcg_iterations").unwrap_or(0),
        fallbacks: u("fallbacks_to_lu").unwrap_or(0),
    })
}

/// The history `(t, value)` of each of `monitors` in `curve.csv`, by
/// monitor name; a monitor without its column (named with its unit,
/// [`crate::scene::MonitorSpec::column`]) is left out.
pub fn read_curve(path: &Path, monitors: &[MonitorSpec]) -> Option<Histories> {
    let mut reader = csv::Reader::from_path(path).ok()?;
    let header: Vec<String> = reader.headers().ok()?.iter().map(String::from).collect();
    let time = header.iter().position(|h| h == TIME_COLUMN)?;
    let (mut columns, indices): (Histories, Vec<usize>) = monitors
        .iter()
        .filter_map(|m| {
            let i = header.iter().position(|h| *h == m.column())?;
            Some(((m.name.clone(), Vec::new()), i))
        })
        .unzip();
    for record in reader.records() {
        let record = record.ok()?;
        let t: f64 = record.get(time)?.parse().ok()?;
        for (column, &i) in columns.iter_mut().zip(&indices) {
            if let Some(v) = record.get(i).and_then(|v| v.parse::<f64>().ok()) {
                column.1.push((t, v));
            }
        }
    }
    Some(columns)
}

/// The directory of a run inside the study's output directory.
pub fn run_dir(out: &Path, planned: &PlannedRun) -> PathBuf {
    out.join("runs").join(&planned.name)
}

/// File of a run's measurement in its directory.
const MEASURED_FILE: &str = "measured.json";

/// Fingerprint of a run: its scene, repeats and time-out (a change of any of
/// them measures it again).
pub fn fingerprint(planned: &PlannedRun, repeats: usize, timeout: Option<f64>) -> String {
    let scene = toml::to_string(&planned.scene).unwrap_or_default();
    crate::provenance::fingerprint_text(&format!("{scene}|{repeats}|{timeout:?}"))
}

/// Estimated cost of a run, to balance shards: steps (1000 when the
/// explicit integrator chooses them) over h².
pub fn cost(scene: &crate::scene::Scene) -> f64 {
    scene.scene.steps.unwrap_or(1000) as f64 / scene.grid.cell_size.powi(2)
}

/// The measurement kept in `dir` when it has `fingerprint` (else `None`:
/// measure it).
pub fn load_measured(dir: &Path, fingerprint: &str) -> Option<Measured> {
    let json = read_json(&dir.join(MEASURED_FILE))?;
    if json.get("fingerprint")?.as_str()? != fingerprint {
        return None;
    }
    serde_json::from_value(json.get("measured")?.clone()).ok()
}

/// Keep `measured` in `dir` (written under a temporary name and renamed).
pub fn save_measured(dir: &Path, fingerprint: &str, measured: &Measured) -> Result<(), StudyError> {
    let path = dir.join(MEASURED_FILE);
    let fail = |e: &dyn std::fmt::Display| StudyError::Io {
        path: path.display().to_string(),
        message: e.to_string(),
    };
    let text = serde_json::to_string(&serde_json::json!({
        "fingerprint": fingerprint,
        "measured": measured,
    }))
    .map_err(|e| fail(&e))?;
    crate::atomic_file::write_atomic(&path, text).map_err(|e| fail(&e))
}
