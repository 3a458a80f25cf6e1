//! The paper's central claim with regularisation (§3.1, Figs. 3 and 5; issue 5
//! check 4): nonlocal biaxial runs (l_s = 0.01 m) on two meshes that both obey
//! the paper's resolution rule h ≤ 0.2 l_s — h = 1/500 and 1/700 m, the
//! cheapest pair that does (a coarser pair would need l_s ≥ 16.7 mm, which on
//! this 30 mm wide specimen spreads κ̄ over the whole specimen and no longer
//! sets a band width at all). Asserted: post-peak load curves within 5 % (M1,
//! relative L2, theory D42); shear-band widths (M4 on εq, theory §9) within
//! 15 % of each other and, as the paper reports, close to l_s (M4's range
//! 0.7–1.5 l_s); the regularised softening zone (M4 on κ̄) within 15 %.
//! Measured with the scenes as they are (GIMP, surface contact, over-nonlocal
//! m = 1.1): M1 = 0.93 %, εq bands 10.2 and 10.9 mm, κ̄ zones 28.3 and
//! 28.1 mm. With theory D35's m = 1 the εq bands are 7.5 and 6.2 mm (22 % apart,
//! 0.75 and 0.62 l_s) while M1 (0.88 %) and the κ̄ zones still agree.

mod common;

/// l_s of the scenes, m.
const LENGTH_SCALE: f64 = 0.01;

use mpm_geo::metrics::{clip_outliers, post_peak_discrepancy, shear_band_width};
use mpm_geo::output::deviatoric_hencky_strain;

struct Outcome {
    curve: Vec<(f64, f64)>,
    band_kappa_bar: f64,
    band_eps_q: f64,
}

fn run(cells_per_metre: usize) -> Outcome {
    let path = format!("biaxial/nonlocal_h{cells_per_metre}.toml");
    let mut sim = common::simulation(&path, &["output.snapshots=[]"]);
    let history = common::run_history(&mut sim);
    let (load, top) = (common::column(&sim, "load"), common::column(&sim, "top_uy"));
    let curve: Vec<(f64, f64)> = history.iter().map(|(_, v)| (-v[top], v[load])).collect();
    let l_s = sim.scene.nonlocal.as_ref().unwrap().length_scale;
    assert_eq!(l_s, LENGTH_SCALE);
    let h = sim.model.grid.cell_size;
    let p = &sim.model.state.particles;
    let kappa_bar = common::kappa_bar(&sim);
    let eps_q: Vec<f64> = p.def_grad.iter().map(deviatoric_hencky_strain).collect();
    let eps_q = clip_outliers(&eps_q, 0.99);
    let band_kappa_bar = shear_band_width(&p.position, &kappa_bar, h, l_s)
        .expect("a κ̄ band")
        .width;
    let band_eps_q = shear_band_width(&p.position, &eps_q, h, l_s)
        .expect("an εq band")
        .width;
    println!(
        "nonlocal h = 1/{cells_per_metre} m: F_end = {:.3} kN/m, κ̄ zone {:.2} mm, εq band {:.2} mm",
        curve.last().unwrap().1,
        band_kappa_bar * 1e3,
        band_eps_q * 1e3
    );
    Outcome {
        curve,
        band_kappa_bar,
        band_eps_q,
    }
}

#[test]
fn nonlocal_runs_on_two_meshes_within_the_resolution_rule_agree() {
    let coarse = run(500);
    let fine = run(700);
    let delta_end = fine
        .curve
        .last()
        .unwrap()
        .0
        .min(coarse.curve.last().unwrap().0);
    let m1 = post_peak_discrepancy(&coarse.curve, &fine.curve, delta_end).unwrap();
    let zone_ratio = coarse.band_kappa_bar / fine.band_kappa_bar;
    println!(
        "M1 = {:.2} %, κ̄ zone ratio {zone_ratio:.3}, εq band ratio {:.3}",
        100.0 * m1,
        coarse.band_eps_q / fine.band_eps_q
    );
    assert!(m1 <= 0.05, "post-peak discrepancy {m1}");
    let band_ratio = coarse.band_eps_q / fine.band_eps_q;
    assert!(
        (band_ratio - 1.0).abs() <= 0.15,
        "εq bands {} vs {} m",
        coarse.band_eps_q,
        fine.band_eps_q
    );
    for band in [coarse.band_eps_q, fine.band_eps_q] {
        let relative = band / LENGTH_SCALE;
        assert!(
            (0.7..=1.5).contains(&relative),
            "εq band {band} m = {relative:.2} l_s"
        );
    }
    assert!(
        (zone_ratio - 1.0).abs() <= 0.15,
        "κ̄ zones {} vs {} m",
        coarse.band_kappa_bar,
        fine.band_kappa_bar
    );
}
