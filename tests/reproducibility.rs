//! Reproducibility (issue 3, check 8): the same scene run with 1 and with 2
//! rayon threads writes a bit-identical `curve.csv` (all nodal sums are
//! reduced in a fixed order, see `transfer`).

mod common;

use mpm_geo::run::run_scene;

fn curve_with_threads(path: &str, overrides: &[&str], threads: usize) -> String {
    let scene = common::scene(path, overrides);
    let dir = tempfile::tempdir().unwrap();
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    let outcome = pool
        .install(|| run_scene(scene, dir.path(), false))
        .unwrap();
    assert!(outcome.error.is_none(), "{:?}", outcome.error);
    std::fs::read_to_string(dir.path().join("curve.csv")).unwrap()
}

fn assert_identical(path: &str, overrides: &[&str]) {
    let one = curve_with_threads(path, overrides, 1);
    let two = curve_with_threads(path, overrides, 2);
    assert!(one.lines().count() > 2, "{path}: curve too short");
    assert_eq!(
        one, two,
        "{path}: curve.csv differs between 1 and 2 threads"
    );
}

#[test]
fn implicit_runs_are_bit_identical_across_thread_counts() {
    assert_identical("elastic/platen.toml", &[]);
    assert_identical("elastic/bar_implicit.toml", &["scene.steps=200"]);
}

#[test]
fn explicit_runs_are_bit_identical_across_thread_counts() {
    assert_identical("elastic/bar_explicit.toml", &["scene.end_time=0.05"]);
}
