//! What a record says about where it came from and what it found: the
//! provenance of a run (`run.json` → `provenance`: the build, the command,
//! the scene, the machine, when) and its summary (`run.json` → `summary`,
//! printed at the end of `run` and `resume`: the status, the steps, each
//! monitor's final and peak value, where the files are).

use std::path::Path;

use crate::output::TIME_COLUMN;
use serde::Serialize;

/// Where a run came from (`run.json` → `provenance`).
#[derive(Clone, Debug, Serialize)]
pub struct Provenance {
    /// The crate version.
    pub version: &'static str,
    /// The git commit the binary was built from (`None` outside a checkout).
    pub git_commit: Option<&'static str>,
    /// Whether tracked files differed from that commit at the build.
    pub git_dirty: Option<bool>,
    /// The command line of the process that ran the scene (a campaign's
    /// for its runs).
    pub command_line: Vec<String>,
    /// The `--set` overrides `run` applied to the scene file, in order (a
    /// campaign's are in its command line, beside the integrator variant it
    /// made of the file).
    pub overrides: Vec<String>,
    /// The scene file (or, for a campaign run, its scene file).
    pub scene_path: Option<String>,
    /// When the process started this run, UTC, RFC 3339.
    pub started_at: String,
    /// Host name.
    pub host: String,
    /// CPU model.
    pub cpu: String,
    /// Threads of the parallel loops.
    pub threads: usize,
}

impl Provenance {
    /// The provenance of a run this process starts now from the scene file
    /// `scene_path` with `overrides`.
    pub fn now(scene_path: Option<&Path>, overrides: &[String]) -> Self {
        Self {
            version: env!("CARGO_PKG_VERSION"),
            git_commit: Some(env!("MPM_GEO_GIT_COMMIT")).filter(|c| !c.is_empty()),
            git_dirty: env!("MPM_GEO_GIT_DIRTY").parse().ok(),
            command_line: std::env::args().collect(),
            overrides: overrides.to_vec(),
            scene_path: scene_path.map(|p| p.display().to_string()),
            started_at: timestamp(),
            host: host_name(),
            cpu: cpu_model(),
            threads: rayon::current_num_threads(),
        }
    }
}

/// The current time, UTC, RFC 3339 to the second.
pub fn timestamp() -> String {
    humantime::format_rfc3339_seconds(std::time::SystemTime::now()).to_string()
}

/// The host's name (`unknown` where the system does not say).
fn host_name() -> String {
    std::fs::read_to_string("/proc/sys/kernel/hostname")
        .ok()
        .or_else(|| std::env::var("HOSTNAME").ok())
        .map(|s| s.trim().to_string())
        .filter(|s| !s.is_empty())
        .unwrap_or_else(|| "unknown".into())
}

/// The CPU's model name (`unknown` where the system does not say).
fn cpu_model() -> String {
    std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|info| {
            info.lines()
                .find(|l| l.starts_with("model name"))
                .and_then(|l| l.split_once(':'))
                .map(|(_, name)| name.trim().to_string())
        })
        .unwrap_or_else(|| "unknown".into())
}

/// One monitor over a run (`run.json` → `summary.monitors`).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct MonitorSummary {
    /// The monitor's name.
    pub name: String,
    /// Its `curve.csv` column: the name and the unit (`load_kN_per_m`).
    pub column: String,
    /// Its value at the last row.
    pub last: f64,
    /// Its value of largest magnitude over the rows, and the time of it.
    pub peak: f64,
    /// Time of `peak`, s.
    pub peak_time: f64,
}

/// The monitors `(name, column)` over the rows of a `curve.csv` (its
/// `time_s` column and theirs); `None` when the file cannot be read or has
/// no rows.
pub fn monitor_summaries(
    curve: &Path,
    monitors: &[(String, String)],
) -> Option<Vec<MonitorSummary>> {
    let mut reader = csv::Reader::from_path(curve).ok()?;
    let header = reader.headers().ok()?.clone();
    let time = header.iter().position(|h| h == TIME_COLUMN)?;
    let columns: Vec<(usize, &(String, String))> = monitors
        .iter()
        .filter_map(|m| header.iter().position(|h| *h == m.1).map(|i| (i, m)))
        .collect();
    let mut out: Vec<MonitorSummary> = columns
        .iter()
        .map(|(_, (name, column))| MonitorSummary {
            name: name.clone(),
            column: column.clone(),
            last: f64::NAN,
            peak: 0.0,
            peak_time: 0.0,
        })
        .collect();
    let mut rows = 0;
    for record in reader.records() {
        let record = record.ok()?;
        let t: f64 = record.get(time)?.parse().ok()?;
        for (summary, &(i, _)) in out.iter_mut().zip(&columns) {
            let Some(v) = record.get(i).and_then(|s| s.parse::<f64>().ok()) else {
                continue;
            };
            summary.last = v;
            if rows == 0 || v.abs() > summary.peak.abs() {
                summary.peak = v;
                summary.peak_time = t;
            }
        }
        rows += 1;
    }
    (rows > 0).then_some(out)
}

/// FNV-1a (64 bit) of `text`, in hex: the fingerprint of a run's inputs.
pub fn fingerprint_text(text: &str) -> String {
    let mut hash: u64 = 0xcbf2_9ce4_8422_2325;
    for byte in text.bytes() {
        hash ^= u64::from(byte);
        hash = hash.wrapping_mul(0x0100_0000_01b3);
    }
    format!("{hash:016x}")
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The last value and the value of largest magnitude with its time, per
    /// monitor; a column that is not a monitor is left out.
    #[test]
    fn summaries_hold_last_and_peak_values() {
        let dir = tempfile::tempdir().unwrap();
        let curve = dir.path().join("curve.csv");
        std::fs::write(
            &curve,
            "step_1,time_s,load_kN_per_m,u_m\n0,0e0,0e0,0e0\n1,1e-1,5e0,-2e0\n2,2e-1,3e0,-1e0\n",
        )
        .unwrap();
        let names: Vec<(String, String)> = [
            ("load", "load_kN_per_m"),
            ("u", "u_m"),
            ("missing", "missing_m"),
        ]
        .map(|(n, c)| (n.to_string(), c.to_string()))
        .into();
        let s = monitor_summaries(&curve, &names).unwrap();
        let expected = [("load", 3.0, 5.0, 0.1), ("u", -1.0, -2.0, 0.1)];
        assert_eq!(s.len(), 2);
        for (m, (name, last, peak, t)) in s.iter().zip(expected) {
            assert_eq!(
                (m.name.as_str(), m.last, m.peak, m.peak_time),
                (name, last, peak, t)
            );
        }
        assert!(monitor_summaries(&dir.path().join("none.csv"), &names).is_none());
    }

    #[test]
    fn provenance_names_the_build_and_the_machine() {
        let p = Provenance::now(Some(Path::new("a.toml")), &["grid.cell_size=1".into()]);
        assert_eq!(p.version, env!("CARGO_PKG_VERSION"));
        assert_eq!(p.scene_path.as_deref(), Some("a.toml"));
        assert!(
            p.started_at.ends_with('Z') && p.started_at.len() == 20,
            "{}",
            p.started_at
        );
        assert!(p.threads >= 1 && !p.host.is_empty() && !p.cpu.is_empty());
    }
}
