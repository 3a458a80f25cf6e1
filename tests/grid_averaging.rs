//! The nonlocal average on a grid (theory §6.1, NG1–NG3; issue 43) in a whole
//! run: the nonlocal biaxial test at h = 1/500 m (l_s = 0.01 m, the grid at
//! Δ = 0.1 l_s) with `averaging = "grid"` against the same scene averaging
//! over point pairs (D34). Measured: the peak moves by 1.2e-5, the post-peak
//! curve by M1 = 2.1e-3 (theory D42), the εq band by 0.73 % and the κ̄ zone by
//! 0.36 %. Against the gap to the next finer mesh (h = 1/700 m: 7.2e-4,
//! 9.2e-3 and 7.0 %) that is 0.02, 0.22 and 0.10 of it: the approximation
//! rule of issue 43 (a tenth) holds for the peak, not for M1.

mod common;

use mpm_geo::metrics::{clip_outliers, post_peak_discrepancy, shear_band_width};
use mpm_geo::output::deviatoric_hencky_strain;
use mpm_physics::profile::Work;

struct Outcome {
    curve: Vec<(f64, f64)>,
    peak: f64,
    band_eps_q: f64,
    band_kappa_bar: f64,
    pair_denominators: u64,
}

fn run(scene: &str, averaging: &str) -> Outcome {
    let averaging = format!("nonlocal.averaging=\"{averaging}\"");
    let mut sim = common::simulation(scene, &["output.snapshots=[]", &averaging]);
    let history = common::run_history(&mut sim);
    let (load, top) = (common::column(&sim, "load"), common::column(&sim, "top_uy"));
    let curve: Vec<(f64, f64)> = history.iter().map(|(_, v)| (-v[top], v[load])).collect();
    let l_s = sim.scene.nonlocal.as_ref().unwrap().length_scale;
    let h = sim.model.grid.cell_size;
    let p = &sim.model.state.particles;
    let kappa_bar = common::kappa_bar(&sim);
    let eps_q = clip_outliers(
        &p.def_grad
            .iter()
            .map(deviatoric_hencky_strain)
            .collect::<Vec<_>>(),
        0.99,
    );
    let band = |field: &[f64]| shear_band_width(&p.position, field, h, l_s).unwrap().width;
    Outcome {
        peak: curve.iter().map(|c| c.1).fold(0.0, f64::max),
        band_eps_q: band(&eps_q),
        band_kappa_bar: band(&kappa_bar),
        pair_denominators: sim.profile.work_count(Work::NonlocalWeights),
        curve,
    }
}

fn m1(a: &Outcome, b: &Outcome) -> f64 {
    let end = a.curve.last().unwrap().0.min(b.curve.last().unwrap().0);
    post_peak_discrepancy(&a.curve, &b.curve, end).unwrap()
}

#[test]
fn grid_averaging_moves_the_biaxial_run_less_than_the_mesh_does() {
    let points = run("biaxial/nonlocal_h500.toml", "points");
    let grid = run("biaxial/nonlocal_h500.toml", "grid");
    // the grid run never formed the pair denominators (D34): the grid path ran
    assert!(points.pair_denominators > 0);
    assert_eq!(grid.pair_denominators, 0);
    let rel = |a: f64, b: f64| (a - b).abs() / b;
    let peak = rel(grid.peak, points.peak);
    let m1 = m1(&grid, &points);
    let band = rel(grid.band_eps_q, points.band_eps_q);
    let zone = rel(grid.band_kappa_bar, points.band_kappa_bar);
    println!("peak {peak:.2e}, M1 {m1:.2e}, εq band {band:.2e}, κ̄ zone {zone:.2e}");
    assert!(peak <= 1e-4, "peak moved by {peak:.2e}");
    assert!(m1 <= 1e-2, "post-peak curve moved by M1 = {m1:.2e}");
    assert!(band <= 3e-2, "εq band moved by {band:.2e}");
    assert!(zone <= 2e-2, "κ̄ zone moved by {zone:.2e}");
}
