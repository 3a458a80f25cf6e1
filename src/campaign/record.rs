//! What a finished campaign run leaves in its directory: `campaign_run.json`,
//! everything the report needs beyond `curve.csv` (final fields, snapshots,
//! effort, wall time), with a fingerprint of the scene as run.
//!
//! A record is written only by the process that ran the run to its end
//! (completed, or stopped by a failed step), while it still holds the run
//! directory's lock, and it names the run's end status and the length and
//! CRC-32 of its `curve.csv`.
//!
//! It is what lets a campaign be re-run, spread and collected:
//! - a re-run campaign skips every run whose record is present, readable,
//!   has the fingerprint of the scene it would run now (an edited scene or
//!   another `--set` is run again), and still matches the directory: its
//!   `run.json` says the same end status and its `curve.csv` has the same
//!   bytes (a run killed or interrupted later, or a changed curve, is run
//!   again);
//! - `--shard K/N` runs one part of the campaign and leaves the records;
//! - `--collect` builds the report from the records of all parts.
//!
//! A single-process campaign builds its report from the same records, so a
//! collected report equals the single-process one (wall times aside).

use std::path::Path;

use serde::{Deserialize, Serialize};

use super::{CampaignError, Effort};
pub use crate::provenance::fingerprint_text;
use crate::run::FieldSnapshot;
use crate::scene::Scene;

/// File name of a run's record in its output directory.
pub const RECORD_FILE: &str = "campaign_run.json";

/// Version of the record's layout; a record of another version is run again.
const RECORD_FORMAT: u32 = 2;

/// A finished run, as the report needs it (the curve is read from `curve.csv`).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct RunRecord {
    /// Version of the record layout that wrote it.
    pub format: u32,
    /// Fingerprint (the function `fingerprint`) of the scene the run was made from.
    pub fingerprint: String,
    /// The error that stopped the run, if any.
    pub error: Option<String>,
    /// Final material-point positions, m.
    pub positions: Vec<[f64; 2]>,
    /// Final deviatoric strain εq (theory D8) per point.
    pub eps_q: Vec<f64>,
    /// Final nonlocal κ̄ (D35) per point (nonlocal runs only).
    pub kappa_bar: Vec<f64>,
    /// Final volume of every point, m³ per m.
    pub volumes: Vec<f64>,
    /// Volume of every point before it deformed, m_p / ρ (its material's
    /// density), m³ per m: the amount of soil it stands for however far the
    /// grid stretched it. Empty in records written before it existed.
    #[serde(default)]
    pub initial_volumes: Vec<f64>,
    /// Fields at the scene's `[output] snapshot_times`.
    pub fields: Vec<FieldSnapshot>,
    /// Points removed on leaving the grid: (count, removed mass / initial mass).
    pub lost_points: (usize, f64),
    /// Wall time of the run, s.
    pub wall_seconds: f64,
    /// Per-stage profile table.
    pub profile: String,
    /// Steps, Newton iterations and halvings.
    pub effort: Effort,
    /// How the run ended, as its `run.json` says: `completed` or `failed`.
    pub status: String,
    /// Length of the run's `curve.csv` when it ended, bytes.
    pub curve_bytes: u64,
    /// CRC-32 of those bytes.
    pub curve_crc32: u32,
}

/// Length and CRC-32 of the file `path`.
fn curve_checksum(path: &Path) -> std::io::Result<(u64, u32)> {
    let bytes = std::fs::read(path)?;
    Ok((bytes.len() as u64, crc32fast::hash(&bytes)))
}

/// A stable fingerprint of `scene` run with `step_factor` times its steps:
/// FNV-1a (64 bit) of its JSON form, in hex. Any change of a value the run
/// depends on changes it.
pub fn fingerprint(scene: &Scene, step_factor: usize) -> String {
    let text = serde_json::to_string(scene).unwrap_or_default();
    fingerprint_text(&format!("{text}|{step_factor}|{RECORD_FORMAT}"))
}

impl RunRecord {
    /// A record of the current format for a run of the scene with `fingerprint`.
    pub fn new(fingerprint: String) -> Self {
        Self {
            format: RECORD_FORMAT,
            fingerprint,
            error: None,
            positions: Vec::new(),
            eps_q: Vec::new(),
            kappa_bar: Vec::new(),
            volumes: Vec::new(),
            initial_volumes: Vec::new(),
            fields: Vec::new(),
            lost_points: (0, 0.0),
            wall_seconds: 0.0,
            profile: String::new(),
            effort: Effort::default(),
            status: String::new(),
            curve_bytes: 0,
            curve_crc32: 0,
        }
    }

    /// Name the run's end (`completed`, or `failed` with `error`) and its
    /// `curve.csv` in `dir` as it is now.
    pub fn seal(&mut self, dir: &Path) -> Result<(), CampaignError> {
        let path = dir.join("curve.csv");
        let (bytes, crc) = curve_checksum(&path)
            .map_err(|e| CampaignError::Output(path.display().to_string(), e.to_string()))?;
        self.status = if self.error.is_some() {
            "failed"
        } else {
            "completed"
        }
        .into();
        self.curve_bytes = bytes;
        self.curve_crc32 = crc;
        Ok(())
    }

    /// The record in `dir` if it is there, readable, of this format and of
    /// the scene with `fingerprint`, and still matches the run's files;
    /// `None` means the run has to be made (again).
    pub fn load_matching(dir: &Path, fingerprint: &str) -> Option<Self> {
        Self::verify(dir, fingerprint).ok().flatten()
    }

    /// The record in `dir` checked against the run's files: `Ok(None)` when
    /// there is none, `Err(why)` when there is one that must not be reused
    /// (another scene or format, a `run.json` that does not say the end the
    /// record names — a run killed or interrupted after it — or a
    /// `curve.csv` other than the one the run ended with).
    pub fn verify(dir: &Path, fingerprint: &str) -> Result<Option<Self>, String> {
        let text = match std::fs::read_to_string(dir.join(RECORD_FILE)) {
            Ok(text) => text,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
            Err(e) => return Err(format!("its record cannot be read ({e})")),
        };
        let record: RunRecord = serde_json::from_str(&text)
            .map_err(|_| "its record is of another format or damaged".to_string())?;
        if record.format != RECORD_FORMAT {
            return Err("its record is of another format".into());
        }
        if record.fingerprint != fingerprint {
            return Err("its record is of another scene".into());
        }
        if !["completed", "failed"].contains(&record.status.as_str()) {
            return Err(format!("its record says `{}`", record.status));
        }
        let status = std::fs::read_to_string(dir.join("run.json"))
            .ok()
            .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok())
            .and_then(|v| Some(v.get("status")?.as_str()?.to_string()))
            .unwrap_or_else(|| "unreadable".into());
        if status != record.status {
            return Err(format!(
                "its run.json says `{status}`, its record `{}`",
                record.status
            ));
        }
        match curve_checksum(&dir.join("curve.csv")) {
            Ok((bytes, crc)) if bytes == record.curve_bytes && crc == record.curve_crc32 => {}
            Ok(_) => return Err("its curve.csv is not the one the run ended with".into()),
            Err(e) => return Err(format!("its curve.csv cannot be read ({e})")),
        }
        Ok(Some(record))
    }

    /// Write the record into `dir` under a temporary name and rename it, so
    /// that a record is whole or absent.
    pub fn save(&self, dir: &Path) -> Result<(), CampaignError> {
        let path = dir.join(RECORD_FILE);
        let fail = |e: &dyn std::fmt::Display| {
            CampaignError::Output(path.display().to_string(), e.to_string())
        };
        let text = serde_json::to_string(self).map_err(|e| fail(&e))?;
        crate::atomic_file::write_atomic(&path, text).map_err(|e| fail(&e))
    }
}

/// Which part of a campaign (or study) this process does.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Part {
    /// Every run (skipping those already complete), then the report.
    #[default]
    Whole,
    /// The `index`-th (1-based) of `count` disjoint parts, no report.
    Shard {
        /// 1 ..= count.
        index: usize,
        /// Number of parts.
        count: usize,
    },
    /// No run: the report from the records every part left.
    Collect,
}

impl Part {
    /// Parse `K/N` (1 ≤ K ≤ N).
    pub fn shard(text: &str) -> Result<Self, String> {
        let bad = || format!("--shard `{text}`: expected K/N with 1 <= K <= N, e.g. 2/3");
        let (k, n) = text.split_once('/').ok_or_else(bad)?;
        let (index, count): (usize, usize) = (
            k.trim().parse().map_err(|_| bad())?,
            n.trim().parse().map_err(|_| bad())?,
        );
        if index == 0 || index > count {
            return Err(bad());
        }
        Ok(Part::Shard { index, count })
    }

    /// Which of `costs.len()` runs (by index) this part runs: all for
    /// [`Part::Whole`], none for [`Part::Collect`]; for a shard, the runs are
    /// ranked by estimated cost (largest first, ties by index) and dealt out
    /// in turn, so the parts are disjoint, cover every run and take about
    /// the same time.
    pub fn selects(&self, costs: &[f64]) -> Vec<bool> {
        match *self {
            Part::Whole => vec![true; costs.len()],
            Part::Collect => vec![false; costs.len()],
            Part::Shard { index, count } => {
                let mut order: Vec<usize> = (0..costs.len()).collect();
                order.sort_by(|&a, &b| costs[b].total_cmp(&costs[a]).then(a.cmp(&b)));
                let mut selected = vec![false; costs.len()];
                for (rank, run) in order.into_iter().enumerate() {
                    selected[run] = rank % count == index - 1;
                }
                selected
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shards_are_disjoint_and_cover_every_run() {
        let costs = [4.0, 1.0, 9.0, 9.0, 2.0, 0.5, 7.0];
        let parts: Vec<Vec<bool>> = (1..=3)
            .map(|k| Part::Shard { index: k, count: 3 }.selects(&costs))
            .collect();
        for run in 0..costs.len() {
            assert_eq!(parts.iter().filter(|p| p[run]).count(), 1, "run {run}");
        }
        // the two most costly runs go to different shards
        assert!(parts.iter().all(|p| !(p[2] && p[3])));
        assert_eq!(Part::Whole.selects(&costs), vec![true; 7]);
        assert_eq!(Part::Collect.selects(&costs), vec![false; 7]);
    }

    #[test]
    fn shard_text_is_checked() {
        assert_eq!(Part::shard("2/3"), Ok(Part::Shard { index: 2, count: 3 }));
        for bad in ["0/3", "4/3", "3", "a/b", "1/0"] {
            assert!(Part::shard(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn a_record_is_reused_only_for_the_same_scene_and_the_same_end() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        let status = |s: &str| {
            std::fs::write(d.join("run.json"), format!(r#"{{"status": "{s}"}}"#)).unwrap()
        };
        std::fs::write(d.join("curve.csv"), "step,time\n0,0\n1,0.1\n").unwrap();
        status("completed");
        let mut record = RunRecord::new("00ff".into());
        record.eps_q = vec![0.1 + 0.2, 1.0 / 3.0, 5e-324];
        record.seal(d).unwrap();
        record.save(d).unwrap();
        let read = RunRecord::load_matching(d, "00ff").unwrap();
        assert_eq!(read.eps_q, record.eps_q, "f64 round trip");
        assert_eq!(read.status, "completed");
        assert!(RunRecord::load_matching(d, "00fe").is_none());
        // the run was started again and killed, or interrupted
        for later in ["running", "interrupted", "failed"] {
            status(later);
            assert!(RunRecord::verify(d, "00ff").unwrap_err().contains(later));
        }
        status("completed");
        // a curve cut or changed after the run ended
        std::fs::write(d.join("curve.csv"), "step,time\n0,0\n").unwrap();
        assert!(RunRecord::load_matching(d, "00ff").is_none());
        std::fs::write(d.join("curve.csv"), "step,time\n0,0\n1,0.2\n").unwrap();
        assert!(RunRecord::load_matching(d, "00ff").is_none());
        std::fs::write(d.join("curve.csv"), "step,time\n0,0\n1,0.1\n").unwrap();
        assert!(RunRecord::load_matching(d, "00ff").is_some());
        std::fs::remove_file(d.join("curve.csv")).unwrap();
        assert!(RunRecord::load_matching(d, "00ff").is_none());
        std::fs::write(d.join(RECORD_FILE), "{\"format\": 2").unwrap();
        assert!(RunRecord::load_matching(d, "00ff").is_none());
        assert!(matches!(
            RunRecord::verify(tempfile::tempdir().unwrap().path(), "00ff"),
            Ok(None)
        ));
    }
}
