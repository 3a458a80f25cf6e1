//! The output directory of a run: locked while the run writes it (a lock
//! file created with `create_new` holding the process id, removed at the
//! end), and refused when it holds an earlier run's files unless the user
//! asked to overwrite them, which then removes the files that run recorded
//! in its `run.json` ([`crate::manifest`]) and nothing else.

use std::io::Write;
use std::path::{Path, PathBuf};

use crate::manifest::{self, Manifest};

/// Name of the lock file inside a locked output directory.
pub const LOCK_FILE: &str = ".mpm-geo.lock";

/// Why a run may not write into a directory.
#[derive(Debug, thiserror::Error)]
pub enum OutputDirError {
    /// Another live process holds the directory's lock.
    #[error(
        "output directory {dir} is locked by process {pid}, which is still running (another run is writing there); choose another --out, or remove {lock} if no run is writing there"
    )]
    Locked {
        /// The directory.
        dir: String,
        /// Process id in the lock file.
        pid: u32,
        /// The lock file.
        lock: String,
    },
    /// The lock file exists but names no process (being created, or damaged).
    #[error("output directory {dir} is locked ({lock} holds no process id); remove it if no run is writing there")]
    LockUnreadable {
        /// The directory.
        dir: String,
        /// The lock file.
        lock: String,
    },
    /// The directory holds an earlier run's files.
    #[error(
        "output directory {dir} holds an earlier run's files ({}); pass --overwrite to remove them, or choose another --out",
        files.join(", ")
    )]
    InUse {
        /// The directory.
        dir: String,
        /// Some of the run files found (at most a few).
        files: Vec<String>,
    },
    /// The directory holds an earlier run whose `run.json` does not list
    /// the files it wrote, so `--overwrite` cannot tell them from the user's.
    #[error(
        "output directory {dir} holds an earlier run whose files cannot be told from yours ({reason}); remove that run's files yourself, or choose another --out"
    )]
    Unlisted {
        /// The directory.
        dir: String,
        /// Why the list is missing or not trusted.
        reason: String,
    },
    /// The directory holds files this run would write over that no earlier
    /// run recorded writing (the user's own, or an unrecorded run's).
    #[error(
        "output directory {dir} holds files this run would write over that no earlier run recorded ({}); move them, or choose another --out",
        files.join(", ")
    )]
    Foreign {
        /// The directory.
        dir: String,
        /// Some of those files (at most a few).
        files: Vec<String>,
    },
    /// The directory could not be created, read or cleared.
    #[error("output directory {path}: {source}")]
    Io {
        /// The path.
        path: String,
        /// The I/O error.
        #[source]
        source: std::io::Error,
    },
}

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> OutputDirError + '_ {
    move |source| OutputDirError::Io {
        path: path.display().to_string(),
        source,
    }
}

/// A locked output directory; the lock file is removed on drop.
#[derive(Debug)]
pub struct DirLock {
    lock: PathBuf,
}

impl DirLock {
    /// Create `dir` if needed and lock it: create [`LOCK_FILE`] with
    /// `create_new` and write this process's id. A lock of a process that
    /// is no longer running is taken over with a warning on stderr.
    pub fn acquire(dir: &Path) -> Result<Self, OutputDirError> {
        std::fs::create_dir_all(dir).map_err(io(dir))?;
        let lock = dir.join(LOCK_FILE);
        match Self::create(&lock) {
            Err(OutputDirError::Io { source, .. })
                if source.kind() == std::io::ErrorKind::AlreadyExists => {}
            other => return other,
        }
        let text = std::fs::read_to_string(&lock).map_err(io(&lock))?;
        let Ok(pid) = text.trim().parse::<u32>() else {
            return Err(OutputDirError::LockUnreadable {
                dir: dir.display().to_string(),
                lock: lock.display().to_string(),
            });
        };
        if process_alive(pid) {
            return Err(OutputDirError::Locked {
                dir: dir.display().to_string(),
                pid,
                lock: lock.display().to_string(),
            });
        }
        eprintln!(
            "warning: taking over the lock of {} from process {pid}, which is no longer running (a run that was killed)",
            dir.display()
        );
        std::fs::remove_file(&lock).map_err(io(&lock))?;
        // a run starting at the same moment may win the new lock
        Self::create(&lock).map_err(|e| match e {
            OutputDirError::Io { source, .. }
                if source.kind() == std::io::ErrorKind::AlreadyExists =>
            {
                OutputDirError::Locked {
                    dir: dir.display().to_string(),
                    pid: std::fs::read_to_string(&lock)
                        .ok()
                        .and_then(|t| t.trim().parse().ok())
                        .unwrap_or(0),
                    lock: lock.display().to_string(),
                }
            }
            other => other,
        })
    }

    fn create(lock: &Path) -> Result<Self, OutputDirError> {
        let mut file = std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(lock)
            .map_err(io(lock))?;
        let guard = Self {
            lock: lock.to_path_buf(),
        };
        // on failure the guard removes the empty lock again
        write!(file, "{}", std::process::id()).map_err(io(lock))?;
        Ok(guard)
    }
}

impl Drop for DirLock {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.lock);
    }
}

/// Whether process `pid` is running (Unix: `kill(pid, 0)`; elsewhere every
/// lock is taken as held).
fn process_alive(pid: u32) -> bool {
    #[cfg(unix)]
    {
        let Ok(pid) = libc::pid_t::try_from(pid) else {
            return false;
        };
        if pid <= 0 {
            return false;
        }
        // SAFETY: signal 0 only checks that the process exists.
        let r = unsafe { libc::kill(pid, 0) };
        r == 0 || std::io::Error::last_os_error().raw_os_error() == Some(libc::EPERM)
    }
    #[cfg(not(unix))]
    {
        let _ = pid;
        true
    }
}

/// Lock `dir` for a run that will write the files of `planned` and make
/// sure it holds no earlier run's files. An earlier run is one whose
/// `run.json` is there: without `overwrite` the directory is refused
/// ([`OutputDirError::InUse`]); with it, the files that run's manifest lists
/// are removed, and nothing else ([`Manifest::remove_from`]). A file this run
/// would write over that no earlier run recorded (a user's `curve.csv`) is
/// refused either way ([`OutputDirError::Foreign`]).
pub fn prepare(dir: &Path, overwrite: bool, planned: &Manifest) -> Result<DirLock, OutputDirError> {
    let lock = DirLock::acquire(dir)?;
    let earlier = earlier_run(dir)?;
    match &earlier {
        Some(Ok(manifest)) if !overwrite => {
            let present = manifest.present(dir).map_err(io(dir))?;
            return Err(in_use(dir, present));
        }
        Some(Err(_)) if !overwrite => return Err(in_use(dir, vec!["run.json".into()])),
        Some(Err(e)) => {
            return Err(OutputDirError::Unlisted {
                dir: dir.display().to_string(),
                reason: e.to_string(),
            })
        }
        _ => {}
    }
    let earlier = earlier.and_then(Result::ok).unwrap_or_default();
    let foreign = foreign_files(dir, planned, &earlier)?;
    if !foreign.is_empty() {
        return Err(OutputDirError::Foreign {
            dir: dir.display().to_string(),
            files: first_few(foreign),
        });
    }
    earlier.remove_from(dir).map_err(|(path, e)| io(&path)(e))?;
    Ok(lock)
}

/// The manifest of the run whose `run.json` is in `dir` (`None`: no
/// `run.json`; `Some(Err)`: one that does not list its files).
fn earlier_run(
    dir: &Path,
) -> Result<Option<Result<Manifest, manifest::ManifestError>>, OutputDirError> {
    let path = dir.join("run.json");
    let text = match std::fs::read_to_string(&path) {
        Ok(text) => text,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(io(&path)(e)),
    };
    let parsed = serde_json::from_str::<serde_json::Value>(&text)
        .map_err(|e| manifest::ManifestError(format!("run.json is not JSON: {e}")))
        .and_then(|value| Manifest::from_run_json(&value));
    Ok(Some(parsed))
}

/// The files in `dir` a run recording `planned` may write over that
/// `earlier` does not cover: its fixed names, snapshot names and exported
/// systems.
fn foreign_files(
    dir: &Path,
    planned: &Manifest,
    earlier: &Manifest,
) -> Result<Vec<String>, OutputDirError> {
    let mut found = Vec::new();
    for name in names(dir)? {
        let ours = planned.contains(&name) || manifest::is_snapshot_name(&name);
        if ours && !earlier.covers(&name) && dir.join(&name).is_file() {
            found.push(name);
        }
    }
    if let Some(systems) = &planned.systems {
        for name in names(&dir.join(&systems.folder))? {
            if manifest::system_file_step(&name).is_some() && !earlier.covers_system(&name) {
                found.push(format!("{}/{name}", systems.folder));
            }
        }
    }
    Ok(found)
}

/// The names in `dir`, sorted (none if it does not exist).
fn names(dir: &Path) -> Result<Vec<String>, OutputDirError> {
    let entries = match std::fs::read_dir(dir) {
        Ok(e) => e,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Vec::new()),
        Err(e) => return Err(io(dir)(e)),
    };
    let mut names = Vec::new();
    for entry in entries {
        names.push(
            entry
                .map_err(io(dir))?
                .file_name()
                .to_string_lossy()
                .into_owned(),
        );
    }
    names.sort();
    Ok(names)
}

/// [`OutputDirError::InUse`] naming the first few of `files`.
fn in_use(dir: &Path, files: Vec<String>) -> OutputDirError {
    OutputDirError::InUse {
        dir: dir.display().to_string(),
        files: first_few(files),
    }
}

/// At most four names: three and "and N more".
fn first_few(mut names: Vec<String>) -> Vec<String> {
    if names.len() > 4 {
        let more = names.len() - 3;
        names.truncate(3);
        names.push(format!("and {more} more"));
    }
    names
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_lock_is_exclusive_and_released_on_drop() {
        let dir = tempfile::tempdir().unwrap();
        let lock = DirLock::acquire(dir.path()).unwrap();
        let text = std::fs::read_to_string(dir.path().join(LOCK_FILE)).unwrap();
        assert_eq!(text, std::process::id().to_string());
        match DirLock::acquire(dir.path()) {
            Err(OutputDirError::Locked { pid, .. }) => assert_eq!(pid, std::process::id()),
            other => panic!("second lock: {other:?}"),
        }
        drop(lock);
        assert!(!dir.path().join(LOCK_FILE).exists());
        DirLock::acquire(dir.path()).unwrap();
    }

    /// A manifest of `names` written as the `run.json` of `dir`.
    fn earlier_run(dir: &Path, names: &[&str]) -> Manifest {
        let mut m = Manifest::new();
        for name in names {
            m.add(name);
            std::fs::write(dir.join(name), "x").unwrap();
        }
        m.add("run.json");
        let json = serde_json::json!({"status": "completed", "manifest": m});
        std::fs::write(dir.join("run.json"), json.to_string()).unwrap();
        m
    }

    fn listing(dir: &Path) -> Vec<String> {
        names(dir).unwrap()
    }

    #[test]
    fn overwrite_removes_only_the_recorded_files() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        let planned = earlier_run(d, &["curve.csv", "particles_000001.vtu"]);
        // the user's files, named like a run's
        std::fs::create_dir_all(d.join("checkpoints")).unwrap();
        std::fs::write(d.join("checkpoints/notes.txt"), "mine").unwrap();
        for name in ["notes.txt", "mine.pvd", "checkpoint_plan.txt", ".tmp.mine"] {
            std::fs::write(d.join(name), "mine").unwrap();
        }
        match prepare(d, false, &planned) {
            Err(OutputDirError::InUse { files, .. }) => {
                assert_eq!(files, ["curve.csv", "particles_000001.vtu", "run.json"])
            }
            other => panic!("{other:?}"),
        }
        // the refusal released the lock and removed nothing
        assert!(!d.join(LOCK_FILE).exists());
        assert!(d.join("run.json").exists());
        let lock = prepare(d, true, &planned).unwrap();
        assert_eq!(
            listing(d),
            [
                ".mpm-geo.lock",
                ".tmp.mine",
                "checkpoint_plan.txt",
                "checkpoints",
                "mine.pvd",
                "notes.txt"
            ]
        );
        assert_eq!(listing(&d.join("checkpoints")), ["notes.txt"]);
        drop(lock);
    }

    #[test]
    fn a_file_the_run_would_write_over_is_refused_unless_recorded() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        let mut planned = Manifest::new();
        planned.add("curve.csv");
        std::fs::write(d.join("curve.csv"), "my own curve").unwrap();
        std::fs::write(d.join("particles_000010.vtu"), "my own snapshot").unwrap();
        for overwrite in [false, true] {
            match prepare(d, overwrite, &planned) {
                Err(OutputDirError::Foreign { files, .. }) => {
                    assert_eq!(files, ["curve.csv", "particles_000010.vtu"])
                }
                other => panic!("{other:?}"),
            }
        }
        assert_eq!(
            std::fs::read_to_string(d.join("curve.csv")).unwrap(),
            "my own curve"
        );
        // a run.json that lists nothing cannot be overwritten
        std::fs::remove_file(d.join("curve.csv")).unwrap();
        std::fs::remove_file(d.join("particles_000010.vtu")).unwrap();
        std::fs::write(d.join("run.json"), r#"{"status": "completed"}"#).unwrap();
        assert!(matches!(
            prepare(d, true, &planned),
            Err(OutputDirError::Unlisted { .. })
        ));
        assert!(matches!(
            prepare(d, false, &planned),
            Err(OutputDirError::InUse { .. })
        ));
        assert!(d.join("run.json").exists());
    }
}
