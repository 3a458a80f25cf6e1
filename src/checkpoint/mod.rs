//! Checkpoint and restart: `mpm-geo run SCENE --checkpoint-every N` saves
//! the whole state of the run every N steps, `mpm-geo resume DIR` continues
//! it, and the resumed run writes the same bytes as an uninterrupted one.
//!
//! A run directory that writes checkpoints holds two files besides the outputs:
//! - `checkpoint_scene.json`: the scene text and its `--set` overrides (the
//!   run is rebuilt from them) and the checkpoint interval, written at the start;
//! - `checkpoint.bin`: the state after the last checkpointed step ([`SavedState`]:
//!   every material-point variable, boundary devices, time, step, energies,
//!   removed points, integrator counters, the monitors' points, the work
//!   counters, the stage profile and wall time so far, and the output
//!   cursors), replaced atomically (a temporary
//!   file in the same directory, renamed over it) so a kill leaves the
//!   previous one or the new one, whole.
//!
//! `checkpoint.bin` layout, little-endian:
//!
//! | bytes | content |
//! |---|---|
//! | 0..8 | magic `MPMGEOCK` |
//! | 8..12 | format version ([`FORMAT_VERSION`]) |
//! | 12..16 | reserved, 0 |
//! | 16..24 | scene fingerprint (FNV-1a of the scene text and overrides) |
//! | 24..32 | payload length, bytes |
//! | 32..36 | CRC-32 of bytes 12..32 and of the payload |
//! | 36.. | payload ([`codec`]: [`SavedState`] by its serde derive, `f64` by bit pattern) |
//!
//! Reading checks, in order: magic, version, length (truncation), checksum
//! (corruption), fingerprint against the directory's scene (a checkpoint of
//! another scene), then that the state fits the rebuilt run and that
//! `curve.csv` still begins with the bytes the checkpoint saw. Each refusal
//! is a [`CheckpointError`] with a stable identifier, and comes before the
//! resumed run changes anything in the directory.

pub mod codec;
mod state;

use std::io::{Read, Seek, Write};
use std::path::{Path, PathBuf};
use std::time::Instant;

use serde::{Deserialize, Serialize};

pub use state::{Misfit, SavedState};

use crate::error::RunError;
use crate::manifest::Manifest;
use crate::output::OutputCursor;
use crate::scene::{Scene, SceneError};
use crate::simulation::Simulation;
use bincode::Options;
use codec::fnv1a64;

/// Version of the checkpoint layout this build writes and reads.
pub const FORMAT_VERSION: u32 = 7;
/// First bytes of every checkpoint.
pub const MAGIC: [u8; 8] = *b"MPMGEOCK";
/// The checkpoint file in a run directory.
pub const CHECKPOINT_FILE: &str = "checkpoint.bin";
/// The scene source of a checkpointed run, beside the checkpoint.
pub const SOURCE_FILE: &str = "checkpoint_scene.json";
/// Header length, bytes.
const HEADER_LEN: usize = 36;

/// Why a run cannot be checkpointed or resumed. Every variant has a stable
/// identifier ([`CheckpointError::id`]) that its message starts with.
#[derive(Debug, thiserror::Error)]
pub enum CheckpointError {
    /// The directory has no checkpoint (or no scene source beside it).
    #[error("{path}: {message}; only a run started with `--checkpoint-every N` that passed a checkpointed step can be resumed")]
    Missing {
        /// The file looked for.
        path: String,
        /// What the system said.
        message: String,
    },
    /// The file does not start with the checkpoint header.
    #[error("{path} is not an mpm-geo checkpoint (its first bytes are not the checkpoint header)")]
    NotACheckpoint {
        /// The file.
        path: String,
    },
    /// Written in another format version.
    #[error("{path} has checkpoint format version {found}; this mpm-geo reads version {expected}: resume it with the mpm-geo that wrote it, or run the scene again")]
    Version {
        /// The file.
        path: String,
        /// Version in the file.
        found: u32,
        /// Version this build reads.
        expected: u32,
    },
    /// Shorter than its header says (a cut-off copy or a full disk).
    #[error("{path} is truncated: {found} bytes of {expected}; it cannot be resumed from, run the scene again")]
    Truncated {
        /// The file.
        path: String,
        /// Bytes present.
        found: u64,
        /// Bytes the header announces.
        expected: u64,
    },
    /// Checksum or content wrong.
    #[error("{path} is corrupted ({detail}); it cannot be resumed from, run the scene again")]
    Corrupt {
        /// The file.
        path: String,
        /// What was found wrong.
        detail: String,
    },
    /// Written by a run of another scene (or other overrides).
    #[error("{path} was written by a run of another scene (scene fingerprint {found:016x}; the scene of this directory has {expected:016x}); resume each run in its own directory")]
    Foreign {
        /// The file.
        path: String,
        /// Fingerprint in the checkpoint.
        found: u64,
        /// Fingerprint of the directory's scene.
        expected: u64,
    },
    /// The directory's outputs do not continue as the checkpoint expects.
    #[error(
        "{path}: {detail}; the outputs were changed after the checkpoint, run the scene again"
    )]
    Outputs {
        /// The output file or checkpoint.
        path: String,
        /// What does not match.
        detail: String,
    },
    /// The stored scene no longer loads or builds.
    #[error("the scene stored in {path} cannot be rebuilt: {source}")]
    Scene {
        /// The scene source file.
        path: String,
        /// Why.
        #[source]
        source: SceneError,
    },
    /// The run in the directory completed: there is nothing to resume.
    #[error("{path} says the run completed; there is nothing to resume (to repeat it, run the scene again with --overwrite)")]
    Completed {
        /// The run's `run.json`.
        path: String,
    },
    /// Reading or writing a checkpoint file failed.
    #[error("{path}: {message}")]
    Io {
        /// The file.
        path: String,
        /// What the system said.
        message: String,
    },
}

impl CheckpointError {
    /// Stable identifier of the refusal (docs/guide.md §11 lists what to do about each).
    pub fn id(&self) -> &'static str {
        mpm_physics::error_id::Identified::error_id(self).name()
    }
}

impl mpm_physics::error_id::Identified for CheckpointError {
    fn error_id(&self) -> mpm_physics::error_id::ErrorId {
        use mpm_physics::error_id::ErrorId;
        match self {
            Self::Missing { .. } => ErrorId::CheckpointMissing,
            Self::NotACheckpoint { .. } => ErrorId::CheckpointNotACheckpoint,
            Self::Version { .. } => ErrorId::CheckpointVersion,
            Self::Truncated { .. } => ErrorId::CheckpointTruncated,
            Self::Corrupt { .. } => ErrorId::CheckpointCorrupt,
            Self::Foreign { .. } => ErrorId::CheckpointForeign,
            Self::Outputs { .. } => ErrorId::CheckpointOutputs,
            Self::Scene { .. } => ErrorId::CheckpointScene,
            Self::Completed { .. } => ErrorId::CheckpointCompleted,
            Self::Io { .. } => ErrorId::CheckpointIo,
        }
    }
}

impl CheckpointError {
    /// The run error of this failure while checkpointing `step` at `time`.
    pub fn at(self, step: usize, time: f64) -> RunError {
        let path = match &self {
            Self::Missing { path, .. }
            | Self::NotACheckpoint { path }
            | Self::Version { path, .. }
            | Self::Truncated { path, .. }
            | Self::Corrupt { path, .. }
            | Self::Foreign { path, .. }
            | Self::Outputs { path, .. }
            | Self::Scene { path, .. }
            | Self::Completed { path }
            | Self::Io { path, .. } => path.clone(),
        };
        RunError::Output {
            step,
            time,
            path,
            message: self.to_string(),
        }
    }
}

pub(crate) fn io_error(path: &Path, e: impl std::fmt::Display) -> CheckpointError {
    CheckpointError::Io {
        path: path.display().to_string(),
        message: e.to_string(),
    }
}

/// A scene as the user gave it: its text and `--set` overrides, from which
/// a resumed run is rebuilt.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct SceneSource {
    /// Where the text came from (names the scene in messages).
    pub origin: String,
    /// The scene file's text.
    pub text: String,
    /// The `--set key=value` overrides, in order.
    pub overrides: Vec<String>,
}

impl SceneSource {
    /// Read the scene file `path`; the overrides are applied by [`Self::scene`].
    pub fn read(path: &Path, overrides: &[String]) -> Result<Self, SceneError> {
        let text = std::fs::read_to_string(path).map_err(|source| SceneError::Io {
            path: path.display().to_string(),
            source,
        })?;
        Ok(Self {
            origin: path.display().to_string(),
            text,
            overrides: overrides.to_vec(),
        })
    }

    /// The validated scene.
    pub fn scene(&self) -> Result<Scene, SceneError> {
        Scene::from_str_with_overrides(&self.text, &self.origin, &self.overrides)
    }

    /// Fingerprint of the text and overrides (not of the file's path, so a
    /// moved scene file is the same scene).
    pub fn fingerprint(&self) -> u64 {
        let mut parts: Vec<&[u8]> = vec![self.text.as_bytes()];
        parts.extend(self.overrides.iter().map(|o| o.as_bytes()));
        fnv1a64(&parts)
    }
}

/// `checkpoint_scene.json`.
#[derive(Serialize, Deserialize)]
struct SourceRecord {
    format_version: u32,
    checkpoint_every: usize,
    scene: SceneSource,
}

/// Replace `path` by `bytes` atomically: write a temporary file in the same
/// directory (named as [`crate::atomic_file`] names them, so the run's
/// manifest covers it), flush it to disk, rename it over `path`.
pub fn write_atomically(path: &Path, bytes: &[u8]) -> Result<(), CheckpointError> {
    let dir = path.parent().unwrap_or(Path::new("."));
    let target = crate::atomic_file::AtomicPath::new(path);
    let written = (|| {
        let mut file = std::fs::File::create(target.temp())?;
        file.write_all(bytes)?;
        file.sync_all()?;
        drop(file);
        // an uncommitted target removes its temporary file
        target.commit()
    })();
    if let Err(e) = written {
        return Err(io_error(path, e));
    }
    // make the rename itself durable where the platform allows
    if let Ok(d) = std::fs::File::open(dir) {
        let _ = d.sync_all();
    }
    Ok(())
}

/// The bytes of a checkpoint file holding `state` of the scene `fingerprint`.
pub fn encode(fingerprint: u64, state: &SavedState) -> Vec<u8> {
    let payload = codec::options()
        .serialize(state)
        .expect("a checkpoint state is plain data and always encodes");
    let mut bytes = Vec::with_capacity(HEADER_LEN + payload.len());
    bytes.extend_from_slice(&MAGIC);
    bytes.extend_from_slice(&FORMAT_VERSION.to_le_bytes());
    bytes.extend_from_slice(&0u32.to_le_bytes());
    bytes.extend_from_slice(&fingerprint.to_le_bytes());
    bytes.extend_from_slice(&(payload.len() as u64).to_le_bytes());
    let mut crc = crc32fast::Hasher::new();
    crc.update(&bytes[12..32]);
    crc.update(&payload);
    bytes.extend_from_slice(&crc.finalize().to_le_bytes());
    bytes.extend_from_slice(&payload);
    bytes
}

/// Read the state in the checkpoint `bytes` (from `path`), refusing a file
/// that is not a checkpoint, of another format version, truncated,
/// corrupted, or of a scene other than `fingerprint`.
pub fn decode(path: &Path, bytes: &[u8], fingerprint: u64) -> Result<SavedState, CheckpointError> {
    let path_text = path.display().to_string();
    let u32_at =
        |i: usize| u32::from_le_bytes([bytes[i], bytes[i + 1], bytes[i + 2], bytes[i + 3]]);
    let u64_at = |i: usize| {
        let mut b = [0u8; 8];
        b.copy_from_slice(&bytes[i..i + 8]);
        u64::from_le_bytes(b)
    };
    let truncated = |expected: u64| CheckpointError::Truncated {
        path: path_text.clone(),
        found: bytes.len() as u64,
        expected,
    };
    let magic_len = bytes.len().min(MAGIC.len());
    if bytes[..magic_len] != MAGIC[..magic_len] {
        return Err(CheckpointError::NotACheckpoint { path: path_text });
    }
    if bytes.len() < 12 {
        return Err(truncated(HEADER_LEN as u64));
    }
    let version = u32_at(8);
    if version != FORMAT_VERSION {
        return Err(CheckpointError::Version {
            path: path_text,
            found: version,
            expected: FORMAT_VERSION,
        });
    }
    if bytes.len() < HEADER_LEN {
        return Err(truncated(HEADER_LEN as u64));
    }
    let length = u64_at(24);
    let expected = (HEADER_LEN as u64).saturating_add(length);
    if (bytes.len() as u64) < expected {
        return Err(truncated(expected));
    }
    let corrupt = |detail: String| CheckpointError::Corrupt {
        path: path_text.clone(),
        detail,
    };
    if bytes.len() as u64 > expected {
        return Err(corrupt(format!(
            "{} bytes after the announced end",
            bytes.len() as u64 - expected
        )));
    }
    let payload = &bytes[HEADER_LEN..];
    let mut crc = crc32fast::Hasher::new();
    crc.update(&bytes[12..32]);
    crc.update(payload);
    let (stored, actual) = (u32_at(32), crc.finalize());
    if stored != actual {
        return Err(corrupt(format!(
            "checksum {actual:08x}, the header says {stored:08x}"
        )));
    }
    let found = u64_at(16);
    if found != fingerprint {
        return Err(CheckpointError::Foreign {
            path: path_text,
            found,
            expected: fingerprint,
        });
    }
    codec::options()
        .with_limit(payload.len() as u64)
        .deserialize(payload)
        .map_err(|e| corrupt(format!("payload: {e}")))
}

/// CRC-32 and length of `curve.csv` as far as a checkpoint has seen it
/// (the file only grows between checkpoints, so each reads the new bytes).
pub(crate) struct CurveTracker {
    bytes: u64,
    crc: crc32fast::Hasher,
}

impl CurveTracker {
    /// Read `path` from where the tracker stands up to `until` (its end if `None`).
    fn advance(&mut self, path: &Path, until: Option<u64>) -> Result<(), CheckpointError> {
        let mut file = std::fs::File::open(path).map_err(|e| io_error(path, e))?;
        file.seek(std::io::SeekFrom::Start(self.bytes))
            .map_err(|e| io_error(path, e))?;
        let mut rest = Vec::new();
        match until {
            Some(end) => file
                .take(end.saturating_sub(self.bytes))
                .read_to_end(&mut rest),
            None => file.read_to_end(&mut rest),
        }
        .map_err(|e| io_error(path, e))?;
        self.crc.update(&rest);
        self.bytes += rest.len() as u64;
        Ok(())
    }
}

/// Writes a run's checkpoints (held by the [`OutputObserver`](crate::run::OutputObserver)).
pub struct Checkpointer {
    pub(crate) dir: PathBuf,
    pub(crate) every: usize,
    pub(crate) fingerprint: u64,
    pub(crate) curve: CurveTracker,
    /// When the run began (for a resumed run: moved back by the wall time
    /// its checkpoint carried), for the wall time a checkpoint records.
    pub(crate) run_start: Instant,
}

impl Checkpointer {
    /// Checkpoints every `every` steps into `dir` (a new run; `every = 0`:
    /// only when asked): creates `dir`, writes the scene source there and
    /// removes a checkpoint an earlier run left.
    pub fn start(
        dir: &Path,
        source: &SceneSource,
        every: usize,
        run_start: Instant,
    ) -> Result<Self, CheckpointError> {
        let record = SourceRecord {
            format_version: FORMAT_VERSION,
            checkpoint_every: every,
            scene: source.clone(),
        };
        let text = serde_json::to_string_pretty(&record).map_err(|e| io_error(dir, e))?;
        std::fs::create_dir_all(dir).map_err(|e| io_error(dir, e))?;
        let stale = dir.join(CHECKPOINT_FILE);
        match std::fs::remove_file(&stale) {
            Err(e) if e.kind() != std::io::ErrorKind::NotFound => return Err(io_error(&stale, e)),
            _ => {}
        }
        write_atomically(&dir.join(SOURCE_FILE), text.as_bytes())?;
        Ok(Self {
            dir: dir.to_path_buf(),
            every,
            fingerprint: source.fingerprint(),
            curve: CurveTracker {
                bytes: 0,
                crc: crc32fast::Hasher::new(),
            },
            run_start,
        })
    }

    /// Whether a checkpoint is due after the step `sim` has just completed
    /// (every `every` steps, not at the end: a finished run has its outputs).
    pub fn due(&self, sim: &Simulation) -> bool {
        let step = sim.model.state.step;
        self.every > 0 && step > 0 && step.is_multiple_of(self.every) && !sim.finished()
    }

    /// Write the checkpoint of `sim` now, with the output cursor `cursor`
    /// (whose `curve.csv` length and checksum are filled in here).
    pub fn write(
        &mut self,
        sim: &Simulation,
        mut cursor: OutputCursor,
    ) -> Result<(), CheckpointError> {
        self.curve.advance(&self.dir.join("curve.csv"), None)?;
        cursor.curve_bytes = self.curve.bytes;
        cursor.curve_checksum = self.curve.crc.clone().finalize();
        let wall_seconds = self.run_start.elapsed().as_secs_f64();
        let bytes = encode(self.fingerprint, &SavedState::of(sim, cursor, wall_seconds));
        write_atomically(&self.dir.join(CHECKPOINT_FILE), &bytes)
    }
}

/// How to continue a run.
#[derive(Clone, Debug, Default)]
pub struct ResumeOptions {
    /// Checkpoint interval instead of the one the run was started with.
    pub checkpoint_every: Option<usize>,
    /// Test hook: end the run after this step as a kill would.
    pub stop_after: Option<usize>,
    /// Seconds between plain progress lines (see [`RunOptions`](crate::run::RunOptions)).
    pub progress_every: Option<f64>,
    /// Files the caller writes into the directory after the run (a
    /// campaign's record), recorded in `run.json` with the run's own.
    pub extra_files: Vec<String>,
}

/// A checkpointed run directory, locked, checked and ready to continue.
pub struct Resumable {
    pub(crate) _lock: crate::output_dir::DirLock,
    pub(crate) dir: PathBuf,
    pub(crate) source: SceneSource,
    pub(crate) every: usize,
    pub(crate) simulation: Simulation,
    pub(crate) state: SavedState,
    pub(crate) curve: CurveTracker,
    /// The run's `run.json` as found (put back if the resume fails before
    /// its time loop), if there is one.
    pub(crate) earlier: Option<Vec<u8>>,
    /// The run's files as its `run.json` records them.
    pub(crate) manifest: Manifest,
    /// When this process began to build the run again (its wall time
    /// goes on from there).
    pub(crate) opened: Instant,
}

impl Resumable {
    /// Lock `dir` and read and check everything in it without changing
    /// anything: the scene source, the checkpoint (version, length,
    /// checksum, scene), the fit of its state to the rebuilt run and the
    /// `curve.csv` it continues. The lock is held until the resumed run ends.
    pub fn open(dir: &Path) -> Result<Self, Box<dyn std::error::Error + Send + Sync>> {
        if !dir.join(SOURCE_FILE).is_file() {
            // nothing to resume: refuse before the lock creates anything
            let path = dir.join(SOURCE_FILE);
            return Err(CheckpointError::Missing {
                path: path.display().to_string(),
                message: "no such file".into(),
            }
            .into());
        }
        let lock = crate::output_dir::DirLock::acquire(dir)?;
        Ok(Self::check(dir, lock)?)
    }

    fn check(dir: &Path, lock: crate::output_dir::DirLock) -> Result<Self, CheckpointError> {
        let read = |name: &str| {
            let path = dir.join(name);
            std::fs::read(&path).map_err(|e| match e.kind() {
                std::io::ErrorKind::NotFound => CheckpointError::Missing {
                    path: path.display().to_string(),
                    message: e.to_string(),
                },
                _ => io_error(&path, e),
            })
        };
        let source_path = dir.join(SOURCE_FILE);
        let record: SourceRecord =
            serde_json::from_slice(&read(SOURCE_FILE)?).map_err(|e| CheckpointError::Corrupt {
                path: source_path.display().to_string(),
                detail: e.to_string(),
            })?;
        if record.format_version != FORMAT_VERSION {
            return Err(CheckpointError::Version {
                path: source_path.display().to_string(),
                found: record.format_version,
                expected: FORMAT_VERSION,
            });
        }
        let source = record.scene;
        let (earlier, manifest) = earlier_run(dir)?;
        let checkpoint_path = dir.join(CHECKPOINT_FILE);
        let bytes = read(CHECKPOINT_FILE)?;
        let state = decode(&checkpoint_path, &bytes, source.fingerprint())?;
        let scene_error = |source| CheckpointError::Scene {
            path: source_path.display().to_string(),
            source,
        };
        let scene = source.scene().map_err(scene_error)?;
        let opened = Instant::now();
        let simulation = Simulation::new(scene).map_err(scene_error)?;
        state
            .check_fits(&simulation)
            .map_err(|Misfit(detail)| CheckpointError::Corrupt {
                path: checkpoint_path.display().to_string(),
                detail: format!("the state does not fit the scene: {detail}"),
            })?;
        let curve_path = dir.join("curve.csv");
        let mut curve = CurveTracker {
            bytes: 0,
            crc: crc32fast::Hasher::new(),
        };
        curve
            .advance(&curve_path, Some(state.cursor.curve_bytes))
            .map_err(|e| CheckpointError::Outputs {
                path: curve_path.display().to_string(),
                detail: format!("cannot be read ({e})"),
            })?;
        if curve.bytes != state.cursor.curve_bytes
            || curve.crc.clone().finalize() != state.cursor.curve_checksum
        {
            return Err(CheckpointError::Outputs {
                path: curve_path.display().to_string(),
                detail: format!(
                    "its first {} bytes are not the ones the checkpoint of step {} saw",
                    state.cursor.curve_bytes, state.model.step
                ),
            });
        }
        let manifest = manifest.unwrap_or_else(|| unlisted_run_files(&state.cursor));
        Ok(Self {
            _lock: lock,
            dir: dir.to_path_buf(),
            every: record.checkpoint_every,
            source,
            simulation,
            state,
            curve,
            earlier,
            manifest,
            opened,
        })
    }

    /// The scene the run was started with.
    pub fn source(&self) -> &SceneSource {
        &self.source
    }

    /// The scene, as rebuilt.
    pub fn scene(&self) -> &Scene {
        &self.simulation.scene
    }

    /// The step the checkpoint was written after.
    pub fn step(&self) -> usize {
        self.state.model.step
    }
}

/// The `run.json` of `dir` (its bytes) and the files it records, if it is
/// there and lists them; a run that says it completed is refused.
fn earlier_run(dir: &Path) -> Result<(Option<Vec<u8>>, Option<Manifest>), CheckpointError> {
    let path = dir.join("run.json");
    let bytes = match std::fs::read(&path) {
        Ok(bytes) => bytes,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok((None, None)),
        Err(e) => return Err(io_error(&path, e)),
    };
    let value: Option<serde_json::Value> = serde_json::from_slice(&bytes).ok();
    if value.as_ref().and_then(|v| v.get("status")?.as_str()) == Some("completed") {
        return Err(CheckpointError::Completed {
            path: path.display().to_string(),
        });
    }
    let manifest = value.and_then(|v| Manifest::from_run_json(&v).ok());
    Ok((Some(bytes), manifest))
}

/// The files of a checkpointed run whose `run.json` lists none (written by
/// an mpm-geo that did not record them): its fixed files and the snapshots
/// the checkpoint knows.
fn unlisted_run_files(cursor: &OutputCursor) -> Manifest {
    let mut manifest = Manifest::new();
    manifest.temporary_prefixes.clear();
    for name in [
        "run.json",
        "curve.csv",
        crate::output::PVD_FILE,
        CHECKPOINT_FILE,
        SOURCE_FILE,
    ] {
        manifest.add(name);
    }
    for (_, name) in &cursor.snapshots {
        manifest.add(name);
    }
    manifest
}

#[cfg(test)]
mod tests;
