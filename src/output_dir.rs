//! The output directory of a run: locked while the run writes it (a lock
//! file created with `create_new` holding the process id, removed at the
//! end), and refused when it holds an earlier run's files unless the user
//! asked to overwrite them, which then removes those files (and only those).

use std::io::Write;
use std::path::{Path, PathBuf};

use crate::atomic_file::TEMP_PREFIX;

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

/// Whether `name` is a file a run writes into its directory: `run.json`,
/// `curve.csv`, `particles_*.vtu`, `*.pvd`, `checkpoint*` and temporary
/// files of [`crate::atomic_file`].
pub fn is_run_file(name: &str) -> bool {
    name == "run.json"
        || name == "curve.csv"
        || name == crate::campaign::RECORD_FILE
        || (name.starts_with("particles_") && name.ends_with(".vtu"))
        || name.ends_with(".pvd")
        || name.starts_with("checkpoint")
        || name.starts_with(TEMP_PREFIX)
}

/// The run files in `dir` (sorted); none if it does not exist.
pub fn run_files(dir: &Path) -> Result<Vec<PathBuf>, OutputDirError> {
    let entries = match std::fs::read_dir(dir) {
        Ok(e) => e,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Vec::new()),
        Err(e) => return Err(io(dir)(e)),
    };
    let mut files = Vec::new();
    for entry in entries {
        let entry = entry.map_err(io(dir))?;
        if is_run_file(&entry.file_name().to_string_lossy()) {
            files.push(entry.path());
        }
    }
    files.sort();
    Ok(files)
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

/// Lock `dir` for a run and make sure it holds no earlier run's files: with
/// `overwrite` they are removed ([`is_run_file`]: nothing else the user put
/// there), without it the directory is refused ([`OutputDirError::InUse`]).
pub fn prepare(dir: &Path, overwrite: bool) -> Result<DirLock, OutputDirError> {
    let lock = DirLock::acquire(dir)?;
    let files = run_files(dir)?;
    if !files.is_empty() {
        if !overwrite {
            let mut names: Vec<String> = files
                .iter()
                .filter_map(|f| f.file_name())
                .map(|n| n.to_string_lossy().into_owned())
                .collect();
            if names.len() > 4 {
                let more = names.len() - 3;
                names.truncate(3);
                names.push(format!("and {more} more"));
            }
            return Err(OutputDirError::InUse {
                dir: dir.display().to_string(),
                files: names,
            });
        }
        for file in &files {
            let removed = if file.is_dir() {
                std::fs::remove_dir_all(file)
            } else {
                std::fs::remove_file(file)
            };
            removed.map_err(io(file))?;
        }
    }
    Ok(lock)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn run_files_are_told_from_the_users_files() {
        for name in [
            "run.json",
            "curve.csv",
            "particles_000012.vtu",
            "particles.pvd",
            "checkpoint_000100.bin",
            ".tmp.123.4.run.json",
        ] {
            assert!(is_run_file(name), "{name}");
        }
        for name in ["notes.txt", "scene.toml", "curve.csv.bak", "particles.png"] {
            assert!(!is_run_file(name), "{name}");
        }
    }

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

    #[test]
    fn overwrite_removes_only_run_files() {
        let dir = tempfile::tempdir().unwrap();
        for name in ["run.json", "curve.csv", "particles_000001.vtu", "notes.txt"] {
            std::fs::write(dir.path().join(name), "x").unwrap();
        }
        match prepare(dir.path(), false) {
            Err(OutputDirError::InUse { files, .. }) => {
                assert_eq!(files, ["curve.csv", "particles_000001.vtu", "run.json"])
            }
            other => panic!("{other:?}"),
        }
        // the refusal released the lock and removed nothing
        assert!(!dir.path().join(LOCK_FILE).exists());
        assert!(dir.path().join("run.json").exists());
        let lock = prepare(dir.path(), true).unwrap();
        let mut left: Vec<String> = std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        left.sort();
        assert_eq!(left, [LOCK_FILE, "notes.txt"]);
        drop(lock);
    }
}
