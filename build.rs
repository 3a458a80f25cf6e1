//! Build-time provenance: the git commit the binary is built from and
//! whether the tree had uncommitted changes to tracked files, as the
//! environment variables MPM_GEO_GIT_COMMIT and MPM_GEO_GIT_DIRTY
//! (`src/provenance.rs`; empty outside a git checkout).

use std::process::Command;

fn git(args: &[&str]) -> Option<String> {
    let output = Command::new("git").args(args).output().ok()?;
    output
        .status
        .success()
        .then(|| String::from_utf8_lossy(&output.stdout).trim().to_string())
}

fn main() {
    // a new commit moves HEAD or its branch; an edit to the sources
    // changes the dirty flag (and rebuilds the crate anyway)
    for path in [
        ".git/HEAD",
        ".git/refs/heads",
        ".git/packed-refs",
        "src",
        "physics",
        "solvers",
        "Cargo.toml",
    ] {
        println!("cargo:rerun-if-changed={path}");
    }
    let commit = git(&["rev-parse", "HEAD"]).unwrap_or_default();
    let dirty = git(&["status", "--porcelain", "--untracked-files=no"])
        .map(|s| (!s.is_empty()).to_string())
        .unwrap_or_default();
    println!("cargo:rustc-env=MPM_GEO_GIT_COMMIT={commit}");
    println!("cargo:rustc-env=MPM_GEO_GIT_DIRTY={dirty}");
}
