//! The `paper` command end to end on one short scene per benchmark (copies
//! of the coarsest validation scenes with their campaign specs, 4 steps):
//! the three campaigns write their reports (each naming every run's scheme),
//! the index links each beside its figures, and a second command resumes: no finished run is run again.
//! The campaigns share one queue: with two jobs the footing's run starts
//! while the biaxial one still runs, and every line names its campaign.

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

/// `mpm-geo paper` from `root` into `out`, 4 steps a run, `jobs` runs at a
/// time: its exit status and what it printed to stderr.
fn paper(root: &Path, out: &Path, jobs: usize) -> (std::process::ExitStatus, String) {
    let output = Command::new(env!("CARGO_BIN_EXE_mpm-geo"))
        .args(["paper", "--from", root.to_str().unwrap(), "--out"])
        .arg(out)
        .args(["--jobs", &jobs.to_string()])
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
    let (status, progress) = paper(&root, &out, 2);
    assert!(status.success(), "{progress}");
    // the progress names each benchmark in the paper's order; each
    // campaign's lines carry its folder's name, and its end follows them
    let names = ["biaxial", "footing", "vertical_cut", "vertical_cut_late"];
    let mut from = 0;
    for (k, name) in names.iter().enumerate() {
        let announced = format!("paper: {name} ({} of 4,", k + 1);
        let at = progress[from..]
            .find(&announced)
            .unwrap_or_else(|| panic!("no {announced:?} after byte {from}:\n{progress}"));
        from += at;
        let label = format!("campaign-{name}: ");
        let last_line = progress.rfind(&label).expect("the campaign's lines");
        let done = progress
            .find(&format!("paper: {name} done in "))
            .expect("done line");
        assert!(last_line < done, "{progress}");
    }
    // one queue: the second job takes the footing's run while the biaxial
    // run (the first job's) is still running
    let footing_started = progress
        .find("campaign-footing: local_h250 started")
        .expect("the footing's start");
    let biaxial_ended = progress
        .find("campaign-biaxial: local_h300 finished in")
        .expect("the biaxial run's end");
    assert!(footing_started < biaxial_ended, "{progress}");
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
    assert!(paper(&root, &out, 1).0.success());
    assert_eq!(written(&out), first, "a finished run was run again");
}
