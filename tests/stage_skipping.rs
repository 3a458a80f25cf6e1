//! A scene skips what it does not need: the work counters of `run.json`
//! (counted where each structure is built or operation done, see
//! `mpm_geo::profile::Work`) show that a quasi-static scene builds no mass
//! matrix, a local one no neighbour lists and no averages, an elastic one no
//! yield checks or return mappings, a run without double mapping no
//! smoothing pass, an explicit run no assembly or factorisation, and a scene
//! of symmetric tangents no LU factorisation. Each "does" twin is checked
//! too (> 0), so a counter that is never incremented cannot pass.
//!
//! Coarse and short runs of the `validation/` scenes (release: a few seconds
//! in all); the nonlocal biaxial run goes past its first plastic step (≈ 115).

mod common;

use mpm_geo::profile::Work;
use mpm_geo::run::run_scene;
use serde_json::Value;

/// Steps of the biaxial runs: the first return mappings are near step 115.
const BIAXIAL_STEPS: u64 = 135;

/// A completed run's `run.json`.
struct Run {
    label: String,
    json: Value,
}

/// Run `scene` with `overrides` into a temporary directory and read its `run.json`.
fn run(scene: &str, overrides: &[&str]) -> Run {
    let dir = tempfile::tempdir().unwrap();
    let outcome = run_scene(common::scene(scene, overrides), dir.path(), false).unwrap();
    assert!(outcome.error.is_none(), "{scene}: {:?}", outcome.error);
    let text = std::fs::read_to_string(dir.path().join("run.json")).unwrap();
    let run = Run {
        label: format!("{scene} {overrides:?}"),
        json: serde_json::from_str(&text).unwrap(),
    };
    println!("{}: {}", run.label, run.json["work"]);
    println!("  factorisation {}", run.json["solver"]["factorisation"]);
    run
}

impl Run {
    /// Counter `name` of the `"work"` object (every counter is always written).
    fn work(&self, name: &str) -> u64 {
        self.json["work"][name]
            .as_u64()
            .unwrap_or_else(|| panic!("{}: no work.{name} in run.json", self.label))
    }

    /// Entry `name` of `"solver"."factorisation"`.
    fn factorisation(&self, name: &str) -> u64 {
        self.json["solver"]["factorisation"][name]
            .as_u64()
            .unwrap_or_else(|| panic!("{}: no solver.factorisation.{name}", self.label))
    }

    fn steps(&self) -> u64 {
        self.json["steps_completed"].as_u64().unwrap()
    }

    /// Each named counter is 0.
    fn assert_none(&self, names: &[&str]) {
        for name in names {
            let n = self.work(name);
            assert_eq!(n, 0, "{}: work.{name} = {n}, expected 0", self.label);
        }
    }

    /// Each named counter is positive.
    fn assert_some(&self, names: &[&str]) {
        for name in names {
            let n = self.work(name);
            assert!(n > 0, "{}: work.{name} = {n}, expected > 0", self.label);
        }
    }
}

/// `validation/elastic/bar_implicit.toml`, 5 steps: implicit dynamic, elastic, symmetric.
fn bar_implicit() -> Run {
    run("elastic/bar_implicit.toml", &["scene.steps=5"])
}

/// `validation/elastic/bar_explicit.toml` to 2 ms (9 CFL steps).
fn bar_explicit() -> Run {
    run("elastic/bar_explicit.toml", &["scene.end_time=0.002"])
}

#[test]
fn every_counter_is_written_zeros_included() {
    let bar = bar_explicit();
    let work = bar.json["work"].as_object().unwrap();
    assert_eq!(work.len(), Work::ALL.len(), "{work:?}");
    for w in Work::ALL {
        assert!(work[w.name()].is_u64(), "work.{} missing", w.name());
    }
}

#[test]
fn quasi_static_scene_builds_no_mass_matrix() {
    let oedometer = run("elastic/oedometer.toml", &[]);
    assert_eq!(oedometer.json["solver"]["analysis"], "quasi_static");
    oedometer.assert_none(&["mass_matrix", "mass_diagonals", "explicit_nodal_mass"]);
    oedometer.assert_some(&["assemblies"]);

    let bar = bar_implicit();
    assert_eq!(bar.json["solver"]["analysis"], "implicit_dynamic");
    let (mass, steps) = (bar.work("mass_matrix"), bar.steps());
    assert!(
        mass >= steps && steps > 0,
        "{}: work.mass_matrix = {mass}, expected one per step ({steps} steps)",
        bar.label
    );
    // the mass diagonal M/(βΔt²) enters every assembly of a dynamic run
    let (diagonals, assemblies) = (bar.work("mass_diagonals"), bar.work("assemblies"));
    assert!(
        diagonals == assemblies && diagonals > 0,
        "{}: work.mass_diagonals = {diagonals}, work.assemblies = {assemblies}",
        bar.label
    );
    bar.assert_none(&["explicit_nodal_mass"]);
}

#[test]
fn local_scene_builds_no_neighbour_lists_and_does_no_averaging() {
    let steps = format!("scene.steps={BIAXIAL_STEPS}");
    let local = run("biaxial/local_h300.toml", &[&steps]);
    let nonlocal = run("biaxial/nonlocal_h300.toml", &[&steps]);
    local.assert_none(&[
        "neighbour_lists",
        "nonlocal_weights",
        "weight_caches",
        "nonlocal_averages",
    ]);
    // the nonlocal twin has yielded, so its averages had something to average
    nonlocal.assert_some(&[
        "return_mappings",
        "neighbour_lists",
        "nonlocal_weights",
        "weight_caches",
        "nonlocal_averages",
    ]);
    // one neighbour list per (sub-)step, built from its start configuration
    let (lists, steps) = (nonlocal.work("neighbour_lists"), nonlocal.steps());
    assert!(
        lists >= steps,
        "{}: work.neighbour_lists = {lists} for {steps} steps",
        nonlocal.label
    );
    // both use a plastic material: every stress update checks the yield function
    for r in [&local, &nonlocal] {
        let (checks, updates) = (r.work("yield_checks"), r.work("stress_updates"));
        assert!(
            checks == updates && checks > 0,
            "{}: work.yield_checks = {checks}, work.stress_updates = {updates}",
            r.label
        );
    }
}

/// The last row of `curve.csv` of a run of `scene` with `overrides`, and its `run.json`.
fn final_row(scene: &str, overrides: &[&str]) -> (Vec<f64>, Value) {
    let dir = tempfile::tempdir().unwrap();
    let outcome = run_scene(common::scene(scene, overrides), dir.path(), false).unwrap();
    assert!(outcome.error.is_none(), "{scene}: {:?}", outcome.error);
    let curve = std::fs::read_to_string(dir.path().join("curve.csv")).unwrap();
    let last = curve.lines().last().unwrap();
    let row = last.split(',').map(|v| v.parse().unwrap()).collect();
    let json = std::fs::read_to_string(dir.path().join("run.json")).unwrap();
    (row, serde_json::from_str(&json).unwrap())
}

#[test]
fn nonlocal_weight_cache_changes_the_work_not_the_result() {
    let steps = format!("scene.steps={BIAXIAL_STEPS}");
    let (cached, cached_json) = final_row("biaxial/nonlocal_h300.toml", &[&steps]);
    let (uncached, uncached_json) = final_row(
        "biaxial/nonlocal_h300.toml",
        &[&steps, "nonlocal.weight_cache_mb=0"],
    );
    let caches = |json: &Value| json["work"]["weight_caches"].as_u64().unwrap();
    assert!(
        caches(&cached_json) > 0,
        "the default run cached no weights"
    );
    assert_eq!(caches(&uncached_json), 0);
    // the same operator summed in another order: equal to round-off
    // (measured 3.4e-14)
    let difference = cached
        .iter()
        .zip(&uncached)
        .map(|(a, b)| (a - b).abs() / a.abs().max(1e-12))
        .fold(0.0, f64::max);
    println!("largest relative difference of the final monitors: {difference:.1e}");
    assert!(
        difference <= 5e-13,
        "cached {cached:?} against uncached {uncached:?}"
    );
}

#[test]
fn elastic_scene_does_no_yield_checks_or_return_mapping() {
    for bar in [bar_implicit(), bar_explicit()] {
        bar.assert_none(&["yield_checks", "return_mappings"]);
        bar.assert_some(&["stress_updates"]);
    }
}

#[test]
fn double_mapping_off_does_no_smoothing() {
    // as written: `[smoothing] double_mapping = "off"`
    let off = run("biaxial/local_h300.toml", &["scene.steps=10"]);
    assert_eq!(off.json["scene"]["smoothing"]["double_mapping"], "off");
    off.assert_none(&["smoothing_passes", "force_restorations"]);
    // `auto` (the default) is off for a material that cannot soften
    let bar = bar_implicit();
    assert_eq!(bar.json["scene"]["smoothing"]["double_mapping"], "auto");
    bar.assert_none(&["smoothing_passes", "force_restorations"]);
    // `auto` with a softening material: on with bilinear cells (the paper's
    // use), off with GIMP (theory decision 27)
    let auto = |shapes: &str| {
        let shapes = format!("grid.shape_functions=\"{shapes}\"");
        run(
            "biaxial/local_h300.toml",
            &[
                "scene.steps=5",
                "smoothing.double_mapping=\"auto\"",
                &shapes,
            ],
        )
    };
    auto("gimp").assert_none(&["smoothing_passes"]);
    let bilinear = auto("bilinear");
    assert_eq!(bilinear.work("smoothing_passes"), bilinear.steps());
    // on: one pass (and restoration) per step
    let on = run(
        "biaxial/local_h300.toml",
        &[
            "scene.steps=10",
            "smoothing.double_mapping=\"increment\"",
            "smoothing.restore_forces=true",
        ],
    );
    for name in ["smoothing_passes", "force_restorations"] {
        let n = on.work(name);
        assert_eq!(
            n,
            on.steps(),
            "{}: work.{name} = {n}, expected one per step",
            on.label
        );
    }
}

#[test]
fn explicit_integrator_assembles_and_factorises_nothing() {
    let nothing = [
        "assemblies",
        "factorisations_cholesky",
        "factorisations_lu",
        "symbolic_factorisations",
        "mass_matrix",
        "mass_diagonals",
    ];
    let explicit = bar_explicit();
    explicit.assert_none(&nothing);
    explicit.assert_some(&["explicit_nodal_mass", "stress_updates"]);
    for name in ["symbolic", "numeric", "solves"] {
        let n = explicit.factorisation(name);
        assert_eq!(
            n, 0,
            "{}: solver.factorisation.{name} = {n}",
            explicit.label
        );
    }
    // the explicit stress update is counted too: a plastic explicit run
    // (nonlocal biaxial hit by the platen at 2 m/s) yields, and still
    // assembles nothing
    let plastic = run(
        "biaxial/nonlocal_h300.toml",
        &[
            "scene.analysis=\"explicit\"",
            "scene.dt=5e-6",
            "scene.end_time=0.001",
            "bc.rigid.0.velocity=[0.0,-2.0]",
            "bc.rigid.0.ramp_time=0",
            "solver.damping=0.7",
        ],
    );
    plastic.assert_none(&nothing);
    plastic.assert_some(&[
        "explicit_nodal_mass",
        "yield_checks",
        "return_mappings",
        "neighbour_lists",
        "nonlocal_averages",
    ]);

    let implicit = bar_implicit();
    implicit.assert_some(&[
        "assemblies",
        "factorisations_cholesky",
        "symbolic_factorisations",
    ]);
    implicit.assert_none(&["explicit_nodal_mass"]);
}

#[test]
fn symmetric_tangents_never_fall_to_lu() {
    let bar = bar_implicit();
    let materials = bar.json["materials"].as_array().unwrap();
    assert!(materials.iter().all(|m| m["symmetric_tangent"] == true));
    bar.assert_none(&["factorisations_lu"]);
    bar.assert_some(&["factorisations_cholesky"]);
    for (name, expected) in [("cholesky_fallbacks", 0), ("numeric_lu", 0)] {
        let n = bar.factorisation(name);
        assert_eq!(
            n, expected,
            "{}: solver.factorisation.{name} = {n}",
            bar.label
        );
    }
    // the work counters and the solver's own statistics agree, and the
    // symbolic factorisation of the first step is reused by the others
    let (cholesky, numeric) = (
        bar.work("factorisations_cholesky"),
        bar.factorisation("numeric"),
    );
    assert_eq!(cholesky, numeric, "{}: Cholesky vs numeric", bar.label);
    let (symbolic, reuses) = (
        bar.factorisation("symbolic"),
        bar.factorisation("symbolic_reuses"),
    );
    assert_eq!(symbolic, bar.work("symbolic_factorisations"));
    assert!(
        reuses == numeric - symbolic && reuses > 0,
        "{}: solver.factorisation.symbolic_reuses = {reuses}, numeric {numeric}, symbolic {symbolic}",
        bar.label
    );
}
