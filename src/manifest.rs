//! What a run wrote into its output directory, as the run records it in
//! `run.json` (the `manifest` key) *before* it writes each file: the file
//! names, the prefix of its temporary names (`.tmp.<pid>.`, one per process
//! that wrote the run: a resumed run adds its own) and the steps whose linear
//! systems it exports into `systems/`.
//!
//! `run --overwrite` removes what the earlier run's manifest lists and
//! nothing else ([`crate::output_dir::prepare`]), so a user's own files in the
//! directory stay whatever their names; `resume` removes the temporary files
//! of the processes the manifest names. Names that can be foreseen (the
//! fixed files, the next snapshots) are recorded ahead, so `run.json` is
//! rewritten only every [`SNAPSHOTS_AHEAD`] snapshots; when the run ends the
//! list is cut to the files that exist.

use std::collections::BTreeSet;
use std::path::{Component, Path};

use serde::{Deserialize, Serialize};

use crate::atomic_file::TEMP_PREFIX;

/// Snapshots recorded ahead of the step being written.
pub const SNAPSHOTS_AHEAD: usize = 64;

/// Name of the folder of exported linear systems in a run's directory.
pub const SYSTEMS_FOLDER: &str = "systems";

/// The linear systems a run exports (`[output] systems`): in `folder`, the
/// files `step<NNNNNN>_solve<NN>_it<NN>` + `_K.mtx`, `_rhs.mtx`, `_x.mtx`
/// or `.json` of the listed steps.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct SystemsRecord {
    /// The folder, relative to the run's directory.
    pub folder: String,
    /// The steps whose systems are written.
    pub steps: Vec<usize>,
}

impl SystemsRecord {
    /// Whether `name` (a file in the folder) is a system file of a listed step.
    pub fn holds(&self, name: &str) -> bool {
        system_file_step(name).is_some_and(|step| self.steps.contains(&step))
    }
}

/// The files a run wrote, or is about to write, into its directory.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Manifest {
    /// File names, relative to the directory.
    pub files: BTreeSet<String>,
    /// Its temporary files are the names that start with one of these.
    pub temporary_prefixes: Vec<String>,
    /// The exported linear systems, if any.
    pub systems: Option<SystemsRecord>,
}

/// Why a manifest cannot be trusted to name a directory's files.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct ManifestError(pub String);

impl Manifest {
    /// An empty manifest of this process (its temporary prefix recorded).
    pub fn new() -> Self {
        Self {
            files: BTreeSet::new(),
            temporary_prefixes: vec![own_temporary_prefix()],
            systems: None,
        }
    }

    /// Record `name`; true if it was not recorded yet.
    pub fn add(&mut self, name: &str) -> bool {
        self.files.insert(name.to_string())
    }

    /// Whether `name` is recorded.
    pub fn contains(&self, name: &str) -> bool {
        self.files.contains(name)
    }

    /// Whether `name` (a file of the directory) is one of the run's temporary files.
    pub fn is_temporary(&self, name: &str) -> bool {
        self.temporary_prefixes.iter().any(|p| name.starts_with(p))
    }

    /// Whether `name` (a file of the directory) is recorded, as a file or a
    /// temporary file.
    pub fn covers(&self, name: &str) -> bool {
        self.contains(name) || self.is_temporary(name)
    }

    /// Whether `name` (a file of the systems folder) is an exported system.
    pub fn covers_system(&self, name: &str) -> bool {
        self.systems.as_ref().is_some_and(|s| s.holds(name))
    }

    /// Record this process's temporary prefix (a resumed run's).
    pub fn add_own_temporary_prefix(&mut self) {
        let own = own_temporary_prefix();
        if !self.temporary_prefixes.contains(&own) {
            self.temporary_prefixes.push(own);
        }
    }

    /// The manifest of `run.json` `value`, checked: every name a plain file
    /// name of the directory, every prefix `.tmp.<pid>.`.
    pub fn from_run_json(value: &serde_json::Value) -> Result<Self, ManifestError> {
        let manifest = value.get("manifest").ok_or_else(|| {
            ManifestError("run.json lists no files (`manifest`): it was written by an mpm-geo that did not record them".into())
        })?;
        let manifest: Manifest = serde_json::from_value(manifest.clone())
            .map_err(|e| ManifestError(format!("run.json `manifest` cannot be read: {e}")))?;
        manifest.check()?;
        Ok(manifest)
    }

    /// Every name is one plain file name (no folder, no `..`) and every
    /// temporary prefix is `.tmp.<digits>.`: a damaged or edited `run.json`
    /// cannot make `--overwrite` remove anything outside the run's files.
    fn check(&self) -> Result<(), ManifestError> {
        let names = self
            .files
            .iter()
            .chain(self.systems.as_ref().map(|s| &s.folder));
        for name in names {
            if !is_plain_name(name) {
                return Err(ManifestError(format!(
                    "run.json `manifest` lists `{name}`, which is not a file name of the directory"
                )));
            }
        }
        for prefix in &self.temporary_prefixes {
            let pid = prefix
                .strip_prefix(TEMP_PREFIX)
                .and_then(|p| p.strip_suffix('.'));
            if !pid.is_some_and(|p| !p.is_empty() && p.bytes().all(|b| b.is_ascii_digit())) {
                return Err(ManifestError(format!(
                    "run.json `manifest` gives `{prefix}` as a temporary prefix (expected {TEMP_PREFIX}<pid>.)"
                )));
            }
        }
        Ok(())
    }

    /// The recorded entries present in `dir`, sorted: files, temporary
    /// files, and `systems/<file>` for the exported systems.
    pub fn present(&self, dir: &Path) -> std::io::Result<Vec<String>> {
        let mut found: Vec<String> = names_in(dir)?
            .into_iter()
            .filter(|n| self.covers(n))
            .collect();
        if let Some(systems) = &self.systems {
            let folder = dir.join(&systems.folder);
            for name in names_in(&folder)? {
                if systems.holds(&name) {
                    found.push(format!("{}/{name}", systems.folder));
                }
            }
        }
        found.sort();
        Ok(found)
    }

    /// Remove from `dir` what the manifest records: the exported systems
    /// (and their folder if that leaves it empty), the temporary files, the
    /// files, and `run.json` last (so an error on the way leaves it listing
    /// what is left). Files already gone are skipped; nothing else is touched.
    pub fn remove_from(&self, dir: &Path) -> Result<(), (std::path::PathBuf, std::io::Error)> {
        if let Some(systems) = &self.systems {
            let folder = dir.join(&systems.folder);
            let names = names_in(&folder).map_err(|e| (folder.clone(), e))?;
            for name in names.iter().filter(|n| systems.holds(n)) {
                remove_file(&folder.join(name))?;
            }
            if folder.is_dir() {
                // kept if the user put something else in it
                let _ = std::fs::remove_dir(&folder);
            }
        }
        self.remove_temporaries(dir, &self.temporary_prefixes)?;
        for name in self.files.iter().filter(|n| n.as_str() != "run.json") {
            remove_file(&dir.join(name))?;
        }
        if self.contains("run.json") {
            remove_file(&dir.join("run.json"))?;
        }
        Ok(())
    }

    /// Remove the files of `dir` whose names start with one of `prefixes`
    /// (the temporary files of those processes).
    pub fn remove_temporaries(
        &self,
        dir: &Path,
        prefixes: &[String],
    ) -> Result<(), (std::path::PathBuf, std::io::Error)> {
        if prefixes.is_empty() {
            return Ok(());
        }
        let names = names_in(dir).map_err(|e| (dir.to_path_buf(), e))?;
        for name in names
            .iter()
            .filter(|n| prefixes.iter().any(|p| n.starts_with(p.as_str())))
        {
            let path = dir.join(name);
            if path.is_file() {
                remove_file(&path)?;
            }
        }
        Ok(())
    }

    /// Keep only the files that exist in `dir` (names recorded ahead but
    /// never written are dropped when the run ends).
    pub fn retain_existing(&mut self, dir: &Path) {
        self.files.retain(|name| dir.join(name).exists());
    }
}

/// `.tmp.<pid>.`: the prefix of this process's temporary names
/// ([`crate::atomic_file`]).
pub fn own_temporary_prefix() -> String {
    format!("{TEMP_PREFIX}{}.", std::process::id())
}

/// The name of a run's snapshot of `step`.
pub fn snapshot_name(step: usize) -> String {
    format!("particles_{step:06}.vtu")
}

/// Whether `name` has the form of a snapshot name (`particles_<digits>.vtu`).
pub fn is_snapshot_name(name: &str) -> bool {
    snapshot_step(name).is_some()
}

/// The step of snapshot name `name`.
pub fn snapshot_step(name: &str) -> Option<usize> {
    let digits = name.strip_prefix("particles_")?.strip_suffix(".vtu")?;
    if digits.is_empty() || !digits.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    digits.parse().ok()
}

/// The step of an exported system file `step<N>_solve<N>_it<N>{_K.mtx,
/// _rhs.mtx, _x.mtx, .json}`.
pub fn system_file_step(name: &str) -> Option<usize> {
    let stem = ["_K.mtx", "_rhs.mtx", "_x.mtx", ".json"]
        .iter()
        .find_map(|suffix| name.strip_suffix(suffix))?;
    let mut parts = stem.split('_');
    let number = |part: Option<&str>, prefix: &str| {
        let digits = part?.strip_prefix(prefix)?;
        (!digits.is_empty() && digits.bytes().all(|b| b.is_ascii_digit()))
            .then(|| digits.parse::<usize>().ok())
            .flatten()
    };
    let step = number(parts.next(), "step")?;
    number(parts.next(), "solve")?;
    number(parts.next(), "it")?;
    parts.next().is_none().then_some(step)
}

/// Whether `name` is one plain file name (no folder, no `.` or `..`).
fn is_plain_name(name: &str) -> bool {
    let mut components = Path::new(name).components();
    matches!(components.next(), Some(Component::Normal(_))) && components.next().is_none()
}

/// The names in `dir` (none if it does not exist).
fn names_in(dir: &Path) -> std::io::Result<Vec<String>> {
    let entries = match std::fs::read_dir(dir) {
        Ok(e) => e,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Vec::new()),
        Err(e) => return Err(e),
    };
    let mut names = Vec::new();
    for entry in entries {
        names.push(entry?.file_name().to_string_lossy().into_owned());
    }
    names.sort();
    Ok(names)
}

/// Remove the file `path` (not a folder); one already gone is no error.
fn remove_file(path: &Path) -> Result<(), (std::path::PathBuf, std::io::Error)> {
    if path.is_dir() {
        // a recorded name that is now a folder is not the run's file
        return Ok(());
    }
    match std::fs::remove_file(path) {
        Err(e) if e.kind() != std::io::ErrorKind::NotFound => Err((path.to_path_buf(), e)),
        _ => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_are_told_apart() {
        assert_eq!(snapshot_step("particles_000012.vtu"), Some(12));
        assert_eq!(snapshot_step("particles_1234567.vtu"), Some(1_234_567));
        for other in ["particles_.vtu", "particles_plot.vtu", "particles.pvd"] {
            assert!(!is_snapshot_name(other), "{other}");
        }
        assert_eq!(system_file_step("step000003_solve00_it01_K.mtx"), Some(3));
        assert_eq!(system_file_step("step000003_solve01_it12.json"), Some(3));
        for other in ["notes.txt", "step3.json", "step000003_solve00_it01_K.txt"] {
            assert_eq!(system_file_step(other), None, "{other}");
        }
    }

    #[test]
    fn a_manifest_naming_files_outside_the_directory_is_refused() {
        let good = serde_json::json!({"manifest": {
            "files": ["run.json", "curve.csv"],
            "temporary_prefixes": [".tmp.42."],
            "systems": null,
        }});
        assert!(Manifest::from_run_json(&good).is_ok());
        for (files, prefix) in [
            (serde_json::json!(["../notes.txt"]), ".tmp.42."),
            (serde_json::json!(["sub/curve.csv"]), ".tmp.42."),
            (serde_json::json!(["/etc/passwd"]), ".tmp.42."),
            (serde_json::json!(["curve.csv"]), ""),
            (serde_json::json!(["curve.csv"]), ".tmp."),
        ] {
            let bad = serde_json::json!({"manifest": {
                "files": files, "temporary_prefixes": [prefix], "systems": null,
            }});
            assert!(Manifest::from_run_json(&bad).is_err(), "{bad}");
        }
        assert!(Manifest::from_run_json(&serde_json::json!({"status": "completed"})).is_err());
    }

    #[test]
    fn removal_takes_the_recorded_files_and_nothing_else() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        let mut m = Manifest::new();
        m.temporary_prefixes = vec![".tmp.42.".into()];
        for name in [
            "run.json",
            "curve.csv",
            "particles_000000.vtu",
            "never_written.vtu",
        ] {
            m.add(name);
        }
        m.systems = Some(SystemsRecord {
            folder: SYSTEMS_FOLDER.into(),
            steps: vec![2],
        });
        for name in [
            "run.json",
            "curve.csv",
            "particles_000000.vtu",
            "particles_000001.vtu",
            ".tmp.42.3.particles_000002.vtu",
            ".tmp.43.0.run.json",
            "mine.pvd",
        ] {
            std::fs::write(d.join(name), "x").unwrap();
        }
        std::fs::create_dir_all(d.join("systems")).unwrap();
        std::fs::write(d.join("systems/step000002_solve00_it00_K.mtx"), "x").unwrap();
        std::fs::write(d.join("systems/notes.txt"), "x").unwrap();
        assert_eq!(
            m.present(d).unwrap(),
            [
                ".tmp.42.3.particles_000002.vtu",
                "curve.csv",
                "particles_000000.vtu",
                "run.json",
                "systems/step000002_solve00_it00_K.mtx"
            ]
        );
        m.remove_from(d).unwrap();
        assert_eq!(
            names_in(d).unwrap(),
            [
                ".tmp.43.0.run.json",
                "mine.pvd",
                "particles_000001.vtu",
                "systems"
            ]
        );
        assert_eq!(names_in(&d.join("systems")).unwrap(), ["notes.txt"]);
    }
}
