//! The paper's central observation without regularisation (§3.1, Figs. 3–4;
//! issue 5 check 3), on the two coarsest meshes of the biaxial benchmark
//! (h = 1/300 and 1/500 m, local, to δ = 2.0 mm): the finer mesh is more
//! brittle — a lower load at the final displacement — and localises in a
//! narrower band (M4 of theory §9, measured on εq of D8 clipped at its 99th
//! percentile, see `metrics::clip_outliers`). Both are strict
//! inequalities between the two runs; the measured values are printed.

mod common;

use mpm_geo::metrics::{clip_outliers, shear_band_width};
use mpm_geo::output::deviatoric_hencky_strain;

/// (load at the last step, band width) of a local biaxial run to 200 steps.
fn run(cells_per_metre: usize) -> (f64, f64) {
    let path = format!("biaxial/local_h{cells_per_metre}.toml");
    let mut sim = common::simulation(&path, &["scene.steps=200", "output.snapshots=[]"]);
    while !sim.finished() {
        sim.step_once().unwrap_or_else(|e| panic!("{path}: {e}"));
    }
    let load = sim.monitor_values()[common::column(&sim, "load")];
    let eps_q: Vec<f64> = sim
        .model
        .particles
        .def_grad
        .iter()
        .map(deviatoric_hencky_strain)
        .collect();
    let eps_q = clip_outliers(&eps_q, 0.99);
    let band = shear_band_width(
        &sim.model.particles.position,
        &eps_q,
        sim.model.grid.cell_size,
        0.0,
    )
    .expect("a band");
    println!(
        "local h = 1/{cells_per_metre} m: F(δ = 2 mm) = {load:.3} kN/m, band width {:.2} mm",
        band.width * 1e3
    );
    (load, band.width)
}

#[test]
fn finer_local_mesh_is_more_brittle_with_a_narrower_band() {
    let (load_coarse, band_coarse) = run(300);
    let (load_fine, band_fine) = run(500);
    assert!(
        load_fine < load_coarse,
        "F: h=1/500 {load_fine} vs h=1/300 {load_coarse}"
    );
    assert!(
        band_fine < band_coarse,
        "band: h=1/500 {band_fine} vs h=1/300 {band_coarse}"
    );
}
