//! The `paper` command end to end on one short scene per benchmark (copies
//! of the coarsest validation scenes with their campaign specs, 4 steps):
//! the three campaigns write their reports (each naming every run's scheme),
//! the index links each beside its figures, and a second command resumes: no finished run is run again.

mod common;

use std::path::Path;
use std::process::Command;

/// A root folder like `validation/` holding, per benchmark, one scene and
/// the benchmark's `campaign.toml`.
fn short_root(dir: &Path) {
    for (benchmark, scene) in [
        ("biaxial", "local_h300.toml"),
        ("footing", "local_h250.toml"),
        ("vertical_cut", "local_h100.toml"),
        ("vertical_cut_late", "local_h100.toml"),
    ] {
        let to = dir.join(benchmark);
        std::fs::create_dir_all(&to).unwrap();
        for file in [scene, "campaign.toml"] {
            let from = common::validation(&format!("{benchmark}/{file}"));
            std::fs::copy(from, to.join(file)).unwrap();
        }
    }
}

/// `mpm-geo paper` from `root` into `out`, 4 steps a run: its exit status
/// and what it printed to stderr.
fn paper(root: &Path, out: &Path) -> (std::process::ExitStatus, String) {
    let output = Command::new(env!("CARGO_BIN_EXE_mpm-geo"))
        .args(["paper", "--from", root.to_str().unwrap(), "--out"])
        .arg(out)
        .args(["--set", "scene.steps=4", "--set", "output.snapshots=[]"])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr).into_owned();
    (output.status, stderr)
}

#[test]
fn paper_runs_three_campaigns_indexes_them_and_resumes() {
    let dir = tempfile::tempdir().unwrap();
    let (root, out) = (dir.path().join("root"), dir.path().join("out"));
    short_root(&root);
    let (status, progress) = paper(&root, &out);
    assert!(status.success(), "{progress}");
    // the progress names each benchmark before its campaign's lines, in the
    // paper's order, and says when it is done
    let mut from = 0;
    for (k, name) in ["biaxial", "footing", "vertical_cut", "vertical_cut_late"]
        .iter()
        .enumerate()
    {
        let announced = format!("paper: {name} ({} of 4,", k + 1);
        let at = progress[from..]
            .find(&announced)
            .unwrap_or_else(|| panic!("no {announced:?} after byte {from}:\n{progress}"));
        from += at;
        let campaign = progress[from..]
            .find("campaign: ")
            .expect("the campaign's lines");
        let done = progress[from..]
            .find(&format!("paper: {name} done in "))
            .expect("done line");
        assert!(campaign < done, "{progress}");
    }
    let index = std::fs::read_to_string(out.join("README.md")).unwrap();
    for (name, figures) in [
        ("biaxial", "Figs. 3–5"),
        ("footing", "Figs. 7–8"),
        ("vertical_cut", "Figs. 10–12"),
        ("vertical_cut_late", "Figs. 10–12, late reading"),
    ] {
        let row = index
            .lines()
            .find(|l| l.starts_with(&format!("| {name} |")))
            .unwrap_or_else(|| panic!("no row for {name}:\n{index}"));
        assert!(row.contains(figures), "{row}");
        assert!(
            row.contains(&format!("[report](campaign-{name}/report.md)")),
            "{row}"
        );
        assert!(out.join(format!("campaign-{name}/report.md")).is_file());
    }
    // each report says which scheme each run used
    let cut = std::fs::read_to_string(out.join("campaign-vertical_cut/report.md")).unwrap();
    assert!(
        cut.contains("implicit dynamic, generalised-α ρ∞ = 0.8"),
        "{cut}"
    );
    assert!(cut.contains("explicit MUSL, CFL"), "{cut}");
    // the cut's campaign runs each scene with both integrators
    let runs = [
        "campaign-biaxial/local_h300",
        "campaign-footing/local_h250",
        "campaign-vertical_cut/local_h100",
        "campaign-vertical_cut/local_h100_explicit",
    ];
    // a run done again would write its run.json anew
    let written = |out: &Path| -> Vec<std::time::SystemTime> {
        runs.iter()
            .map(|r| {
                out.join(r)
                    .join("run.json")
                    .metadata()
                    .unwrap()
                    .modified()
                    .unwrap()
            })
            .collect()
    };
    let first = written(&out);
    assert!(paper(&root, &out).0.success());
    assert_eq!(written(&out), first, "a finished run was run again");
}
