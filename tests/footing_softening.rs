//! The strip footing with softening (issue 12 checks 1 and 2; theory §8.2),
//! from the scene files of `validation/footing/` on coarse meshes.
//!
//! Check 1 (second half): at h = 0.25 m the local run's peak lies below
//! theory §8.2's no-softening reference curve for p_t = 0 at the same
//! penetration (measured with the scenes' loading at 0.0125 m/s: 2128 kN/m at
//! δ = 0.065 m against 2409, −11.7 %; 2215 against 2550 at 0.125 m/s).
//! Check 2: between h = 1/3 m and h = 1/4 m the local post-peak curves differ
//! more than the nonlocal ones (l_s = 0.8 m), by the post-peak discrepancy M1
//! [D42] of the coarser curve against the finer, at least twice (theory §9
//! target; the test drives the footing at the earlier rate of 0.125 m/s,
//! whose inertia holds the local post-peak loads up: measured local 0.245,
//! nonlocal 0.113; at the scenes' 0.0125 m/s 0.594 against 0.100). At the
//! earlier rate the coarser pair h = 0.5
//! and 1/3 m (h up to 0.63 l_s, the nonlocal band spans one or two cells)
//! gave local 0.352 against nonlocal 0.222 without double mapping, and
//! 0.33 against 0.12 with the increment mapping that the scenes had before
//! they took the biaxial formulation (theory decision 27). These meshes run a
//! footing B = 2 m wide, footprint [6, 8] m: the scene's edges 6.25 and
//! 7.75 m lie inside cells at h = 1/3 m (and 0.5 m), where the tied surface reaches the
//! nodes of the partly covered cells and the effective width is rounded to
//! whole cells (measured at h = 0.5 m: the 1.5 m footing peaks at 2914 kN/m,
//! exactly as the 2 m one), so the meshes would differ in footing width.

mod common;

use mpm_physics::metrics::{interpolate, peak, post_peak_discrepancy};

/// (δ, F) of a footing scene with `overrides`, δ = −(footing displacement).
fn load_curve(file: &str, overrides: &[&str]) -> Vec<(f64, f64)> {
    let mut sim = common::simulation(file, overrides);
    let (load, top) = (
        common::column(&sim, "load"),
        common::column(&sim, "footing_uy"),
    );
    common::run_history(&mut sim)
        .into_iter()
        .map(|(_, values)| (-values[top], values[load]))
        .collect()
}

/// theory §8.2's reference FE curve without softening, p_t = 0.
const NO_SOFTENING: [(f64, f64); 6] = [
    (0.0, 0.0),
    (0.016, 803.0),
    (0.050, 2041.0),
    (0.070, 2532.0),
    (0.097, 2729.0),
    (0.111, 2774.0),
];

#[test]
fn softening_peak_lies_below_the_no_softening_curve() {
    // to δ = 0.1 m: past the peak (δ ≈ 0.07 m) and within the reference curve
    let curve = load_curve("footing/local_h250.toml", &["scene.steps=40"]);
    let (delta, load) = peak(&curve).unwrap();
    let reference = interpolate(&NO_SOFTENING, delta).unwrap();
    println!(
        "local h = 0.25 m: peak {load:.0} kN/m at δ = {delta:.4} m, no-softening reference {reference:.0} kN/m ({:+.1} %)",
        100.0 * (load / reference - 1.0)
    );
    assert!(delta < 0.1, "no peak before δ = 0.1 m");
    assert!(load < reference);
}

/// The footing 2 m wide, its edges on grid lines of both coarse meshes,
/// driven at the earlier rate of 0.125 m/s in 0.02 s steps (the same 2.5 mm
/// a step): at the scenes' 0.0125 m/s the local runs' post-peak snap takes up
/// to 8 step halvings and this test 5–7× longer (there: local 0.594 against
/// nonlocal 0.100).
const WIDE_FOOTING: &str = r#"bc.rigid=[{ name = "footing", footprint = [6.0, 8.0], velocity = [0.0, -0.125], contact = "surface" }]"#;

/// M1 of the h = 1/3 m curve against the h = 1/4 m curve of one family.
fn mesh_discrepancy(file: &str) -> f64 {
    let rate = "scene.dt=0.02";
    let coarse = load_curve(
        file,
        &["grid.cell_size=0.3333333333333333", WIDE_FOOTING, rate],
    );
    let fine = load_curve(file, &["grid.cell_size=0.25", WIDE_FOOTING, rate]);
    let end = coarse.last().unwrap().0.min(fine.last().unwrap().0);
    post_peak_discrepancy(&coarse, &fine, end).unwrap()
}

#[test]
fn local_post_peak_curves_differ_more_between_meshes_than_nonlocal_ones() {
    // the two families side by side (one thread each)
    let (local, nonlocal) = std::thread::scope(|scope| {
        let local = scope.spawn(|| mesh_discrepancy("footing/local_h250.toml"));
        let nonlocal = mesh_discrepancy("footing/nonlocal_h250.toml");
        (local.join().unwrap(), nonlocal)
    });
    println!("post-peak M1, h = 1/3 m against h = 1/4 m: local {local:.3}, nonlocal {nonlocal:.3}");
    // theory §9 target: the local S at least twice the nonlocal S
    assert!(local > 2.0 * nonlocal);
}
