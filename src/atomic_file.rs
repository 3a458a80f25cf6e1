//! Files that are whole or absent: each is written under a temporary name in
//! its own directory (`.tmp.<pid>.<n>.<name>`, so the extension is kept) and
//! renamed to its name only once every byte is written. A process killed or a
//! disk filling up mid-write leaves the previous version (or nothing) under
//! the name, never a cut-off file; a temporary file left by a killed process
//! is removed by `resume` and, with the run's other files, by `--overwrite`:
//! the run records the prefix `.tmp.<pid>.` of its temporary names in its
//! manifest ([`crate::manifest`]).
//!
//! The rename is atomic against other processes and a killed writer; the data
//! is not `fsync`ed, so a power loss may still lose the newest versions.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

/// Prefix of temporary names (`.tmp.<pid>.<n>.<name>`).
pub const TEMP_PREFIX: &str = ".tmp.";

/// A temporary name beside `path`, removed on drop unless [`commit`](Self::commit)
/// renamed it to `path`. For writers that need a path (plotters' bitmap
/// backend); [`AtomicFile`] is the [`Write`] form.
#[derive(Debug)]
pub struct AtomicPath {
    path: PathBuf,
    temp: PathBuf,
    committed: bool,
}

impl AtomicPath {
    /// A fresh temporary name beside `path` (unique in this process).
    pub fn new(path: &Path) -> Self {
        static COUNTER: AtomicUsize = AtomicUsize::new(0);
        let n = COUNTER.fetch_add(1, Ordering::Relaxed);
        let name = path
            .file_name()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        let temp = path.with_file_name(format!("{TEMP_PREFIX}{}.{n}.{name}", std::process::id()));
        Self {
            path: path.to_path_buf(),
            temp,
            committed: false,
        }
    }

    /// The temporary name to write to.
    pub fn temp(&self) -> &Path {
        &self.temp
    }

    /// The final name.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Rename the temporary file to the final name (replacing it).
    pub fn commit(mut self) -> std::io::Result<()> {
        std::fs::rename(&self.temp, &self.path)?;
        self.committed = true;
        Ok(())
    }
}

impl Drop for AtomicPath {
    fn drop(&mut self) {
        if !self.committed {
            // absent already if nothing was written
            let _ = std::fs::remove_file(&self.temp);
        }
    }
}

/// A buffered file written under a temporary name and renamed to its name by
/// [`commit`](Self::commit); dropped uncommitted (an error on the way), the
/// temporary file is removed and the name keeps its previous content.
#[derive(Debug)]
pub struct AtomicFile {
    target: AtomicPath,
    writer: BufWriter<File>,
}

impl AtomicFile {
    /// Create the temporary file for `path`.
    pub fn create(path: &Path) -> std::io::Result<Self> {
        let target = AtomicPath::new(path);
        let file = File::create(target.temp())?;
        Ok(Self {
            target,
            writer: BufWriter::new(file),
        })
    }

    /// Flush everything and rename the file to its name.
    pub fn commit(self) -> std::io::Result<()> {
        let Self { target, writer } = self;
        let file = writer.into_inner().map_err(|e| e.into_error())?;
        drop(file);
        target.commit()
    }
}

impl Write for AtomicFile {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.writer.write(buf)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.writer.flush()
    }
}

/// Write `bytes` to `path` whole (temporary name, then rename).
pub fn write_atomic(path: &Path, bytes: impl AsRef<[u8]>) -> std::io::Result<()> {
    let mut file = AtomicFile::create(path)?;
    file.write_all(bytes.as_ref())?;
    file.commit()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(dir: &Path) -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        v.sort();
        v
    }

    #[test]
    fn the_name_shows_the_old_content_until_commit() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.vtu");
        std::fs::write(&path, "old").unwrap();
        let mut f = AtomicFile::create(&path).unwrap();
        f.write_all(b"new content, long enough to be flushed in parts")
            .unwrap();
        f.flush().unwrap();
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "old");
        f.commit().unwrap();
        assert_eq!(
            std::fs::read_to_string(&path).unwrap(),
            "new content, long enough to be flushed in parts"
        );
        assert_eq!(names(dir.path()), ["a.vtu"]);
    }

    #[test]
    fn an_abandoned_write_leaves_the_name_absent_and_no_temporary() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("b.vtu");
        let mut f = AtomicFile::create(&path).unwrap();
        f.write_all(b"half").unwrap();
        drop(f);
        assert!(names(dir.path()).is_empty());
    }

    #[test]
    fn a_killed_writer_leaves_only_a_temporary_name() {
        // a killed process runs no destructor: forget the writer mid-file
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("particles_000007.vtu");
        let mut f = AtomicFile::create(&path).unwrap();
        f.write_all(b"<VTKFile").unwrap();
        f.flush().unwrap();
        std::mem::forget(f);
        let left = names(dir.path());
        assert!(!path.exists());
        assert_eq!(left.len(), 1);
        assert!(
            left[0].starts_with(TEMP_PREFIX) && left[0].ends_with(".particles_000007.vtu"),
            "{left:?}"
        );
    }
}
