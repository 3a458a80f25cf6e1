//! The output directory of a run: locked while the run writes it (an OS
//! lock on a lock file holding the process id, removed at the end: see
//! [`DirLock`]), and refused when it holds an earlier run's files unless the user
//! asked to overwrite them, which then removes the files that run recorded
//! in its `run.json` ([`crate::manifest`]) and nothing else.

use std::io::{Read, Seek, Write};
use std::path::{Path, PathBuf};

use crate::manifest::{self, Manifest};

/// Name of the lock file inside a locked output directory.
pub const LOCK_FILE: &str = ".mpm-geo.lock";

/// Why a run may not write into a directory.
#[derive(Debug, thiserror::Error)]
pub enum OutputDirError {
    /// Another live process holds the directory's lock.
    #[error(
        "output directory {dir} is locked by {}, which is still running (another run is writing there); wait for it, or choose another --out",
        match pid { Some(pid) => format!("process {pid}"), None => "another process".to_string() }
    )]
    Locked {
        /// The directory.
        dir: String,
        /// The holder's process id, if its lock file names it yet.
        pid: Option<u32>,
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

/// A locked output directory: the open lock file [`LOCK_FILE`], holding an
/// exclusive OS advisory lock (`flock` on Unix, `LockFileEx` on Windows,
/// through [`std::fs::File::try_lock`]) for as long as this value lives, and
/// this process's id as its text (for the message of a refused run). On drop
/// the file is removed, then closed.
///
/// Why an OS lock rather than "create the file, take over a dead process's":
/// the kernel drops the lock when its process ends however it ends (`kill
/// -9` too), so a lock file left by a killed run is simply not locked and the
/// next run locks it. Nobody removes another process's file, so there is no
/// takeover to race: when several runs start at once on a left-over lock,
/// `try_lock` lets exactly one through. The one race left, a run that opened
/// the file just before its holder removed it and locks the removed file, is
/// closed by checking after locking that the name still points at the file
/// locked (same device and inode), and opening again if not. (On network
/// file systems this is as good as their lock support: NFSv4 has it.)
#[derive(Debug)]
pub struct DirLock {
    lock: PathBuf,
    /// Holds the OS lock until dropped (after `lock` is removed).
    _file: std::fs::File,
}

/// How many times [`DirLock::acquire`] opens the lock file again after the
/// file it locked was removed by the run that held it.
const LOCK_ATTEMPTS: usize = 100;

/// How long a refused run waits for the holder to write its process id (it
/// writes it right after locking).
const HOLDER_WAIT: std::time::Duration = std::time::Duration::from_secs(1);

impl DirLock {
    /// Create `dir` if needed and lock it: open (or create) [`LOCK_FILE`],
    /// take its OS lock without waiting, and write this process's id into
    /// it. Another live holder gives [`OutputDirError::Locked`] naming its
    /// process; a lock file that no process holds (one left by a killed run)
    /// is taken, with a warning on stderr naming the process it names.
    pub fn acquire(dir: &Path) -> Result<Self, OutputDirError> {
        std::fs::create_dir_all(dir).map_err(io(dir))?;
        let lock = dir.join(LOCK_FILE);
        for _ in 0..LOCK_ATTEMPTS {
            let file = std::fs::OpenOptions::new()
                .read(true)
                .write(true)
                .create(true)
                .truncate(false)
                .open(&lock)
                .map_err(io(&lock))?;
            match file.try_lock() {
                Ok(()) => {}
                Err(std::fs::TryLockError::WouldBlock) => {
                    return Err(OutputDirError::Locked {
                        dir: dir.display().to_string(),
                        pid: holder(&lock),
                    })
                }
                Err(std::fs::TryLockError::Error(e)) => return Err(io(&lock)(e)),
            }
            if !names_file(&lock, &file).map_err(io(&lock))? {
                // its holder removed it as we opened it: open the new one
                continue;
            }
            // from here on the file is ours: on failure the guard removes it
            let guard = Self {
                lock: lock.clone(),
                _file: file,
            };
            let mut file = &guard._file;
            let mut earlier = String::new();
            file.read_to_string(&mut earlier)
                .and_then(|_| file.set_len(0))
                .and_then(|()| file.seek(std::io::SeekFrom::Start(0)))
                .and_then(|_| write!(file, "{}", std::process::id()))
                .map_err(io(&lock))?;
            if let Ok(pid) = earlier.trim().parse::<u32>() {
                eprintln!(
                    "warning: taking over the lock of {} from process {pid}, which is no longer running (a run that was killed)",
                    dir.display()
                );
            }
            return Ok(guard);
        }
        Err(OutputDirError::Locked {
            dir: dir.display().to_string(),
            pid: holder(&lock),
        })
    }
}

/// Whether `path` names the open `file` (the same device and inode; on
/// other systems, whether it exists).
fn names_file(path: &Path, file: &std::fs::File) -> std::io::Result<bool> {
    let named = match std::fs::metadata(path) {
        Ok(m) => m,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(false),
        Err(e) => return Err(e),
    };
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        let open = file.metadata()?;
        Ok(named.dev() == open.dev() && named.ino() == open.ino())
    }
    #[cfg(not(unix))]
    {
        let _ = (named, file);
        Ok(true)
    }
}

/// The process id a held lock file names, waiting up to [`HOLDER_WAIT`]
/// for the holder to write it (`None`: still not written, or the file is
/// gone).
fn holder(lock: &Path) -> Option<u32> {
    let start = std::time::Instant::now();
    loop {
        let pid = std::fs::read_to_string(lock)
            .ok()
            .and_then(|t| t.trim().parse::<u32>().ok());
        // a dead process's id is the text of a left-over file not yet rewritten
        if let Some(pid) = pid.filter(|&p| process_alive(p)) {
            return Some(pid);
        }
        if start.elapsed() > HOLDER_WAIT {
            return None;
        }
        std::thread::sleep(std::time::Duration::from_millis(10));
    }
}

impl Drop for DirLock {
    fn drop(&mut self) {
        // removed while still locked: whoever locks the file next sees that
        // its name is gone ([`names_file`]) and opens a new one
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

use mpm_physics::error_id::{ErrorId, Identified};

impl Identified for OutputDirError {
    fn error_id(&self) -> ErrorId {
        match self {
            OutputDirError::Locked { .. } => ErrorId::OutputLocked,
            OutputDirError::InUse { .. } => ErrorId::OutputReused,
            OutputDirError::Unlisted { .. } => ErrorId::OutputUnlisted,
            OutputDirError::Foreign { .. } => ErrorId::OutputForeign,
            OutputDirError::Io { .. } => ErrorId::OutputDirectory,
        }
    }
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
            Err(OutputDirError::Locked { pid, .. }) => assert_eq!(pid, Some(std::process::id())),
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
