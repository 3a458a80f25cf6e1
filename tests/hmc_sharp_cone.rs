//! The sharp-cone HMC strip footing (issue 13, check 5, second half; theory
//! §8.2), `validation/prandtl/hmc_sharp_cone.toml`: GIMP, B-bar, h = 0.0625 m,
//! associated flow, p_t = 0.999 c cot φ, softening off.
//!
//! - On one material point, the plane-strain biaxial path (εzz = 0, σxx held)
//!   fails on a straight line in (σ3, σ1): Mohr–Coulomb with φ_ps = 22.90°
//!   and c_ps = 116.0 kPa, as theory §8.2 computed, so the Prandtl limit load
//!   c_ps Nc(φ_ps) B is 3120 kN/m (measured 3119.4).
//! - The footing load levels off (it rises by less than 3 % between δ = 1.4
//!   and 2.0 cm; measured +1.4 %) within 10 % of 3120 kN/m (measured mean
//!   3,368 kN/m, +8.0 %).

mod common;

use mpm_physics::constitutive::hmc::Hmc;
use mpm_physics::point_driver::run_biaxial;
use mpm_physics::scene::MaterialSpec;

const SCENE: &str = "prandtl/hmc_sharp_cone.toml";
const FOOTING_WIDTH: f64 = 1.5;

/// Prandtl's bearing capacity factor Nc = (Nq − 1) cot φ, Nq = e^{π tan φ} tan²(45° + φ/2).
fn prandtl_nc(phi: f64) -> f64 {
    let nq = (std::f64::consts::PI * phi.tan()).exp()
        * (std::f64::consts::FRAC_PI_4 + phi / 2.0).tan().powi(2);
    (nq - 1.0) / phi.tan()
}

/// (σ3, σ1) at the end of a plane-strain biaxial path at confinement σ3, compression positive.
fn failure_stresses(model: &Hmc, confinement: f64) -> (f64, f64) {
    let strains: Vec<f64> = (1..=600).map(|k| -0.03 * k as f64 / 600.0).collect();
    let records = run_biaxial(model, confinement, &strains).unwrap();
    let last = records.last().unwrap();
    let before = &records[records.len() - 50];
    // at failure: perfectly plastic, σ1 no longer changes
    assert!((last.stress[1] - before.stress[1]).abs() <= 1e-6 * last.stress[1].abs());
    (-last.stress[0], -last.stress[1])
}

/// The scene's soil: the HMC material of theory §8.2 with the sharp cone.
fn soil() -> Hmc {
    match &common::scene(SCENE, &[]).materials["soil"] {
        MaterialSpec::Hmc(parameters) => Hmc::new(*parameters).unwrap(),
        other => panic!("soil is not HMC: {other:?}"),
    }
}

#[test]
fn sharp_cone_is_mohr_coulomb_with_phi_22_90_in_plane_strain() {
    let model = soil();
    let points: Vec<(f64, f64)> = [50.0, 200.0, 800.0]
        .iter()
        .map(|&s| failure_stresses(&model, s))
        .collect();
    // σ1 = Nφ σ3 + 2 c √Nφ between each pair of confinements
    for pair in points.windows(2) {
        let ((s3a, s1a), (s3b, s1b)) = (pair[0], pair[1]);
        let n_phi = (s1b - s1a) / (s3b - s3a);
        let phi = ((n_phi - 1.0) / (n_phi + 1.0)).asin();
        let c = (s1a - n_phi * s3a) / (2.0 * n_phi.sqrt());
        let load = c * prandtl_nc(phi) * FOOTING_WIDTH;
        println!(
            "σ3 {s3a:.0}–{s3b:.0} kPa: φ_ps = {:.4}°, c_ps = {c:.3} kPa, c_ps Nc B = {load:.1} kN/m",
            phi.to_degrees()
        );
        assert!((phi.to_degrees() - 22.90).abs() <= 0.01, "φ_ps");
        assert!((c - 116.0).abs() <= 0.1, "c_ps");
        assert!((load / 3120.0 - 1.0).abs() <= 1e-3, "limit load");
    }
}

#[test]
fn sharp_cone_footing_levels_off_within_10_percent_of_3120() {
    let mut sim = common::simulation(SCENE, &["scene.steps=20"]);
    let (load, top) = (common::column(&sim, "load"), common::column(&sim, "top_uy"));
    let tail: Vec<f64> = common::run_history(&mut sim)
        .into_iter()
        .filter(|(_, v)| -v[top] >= 0.0139)
        .map(|(_, v)| v[load])
        .collect();
    let mean = tail.iter().sum::<f64>() / tail.len() as f64;
    let rise = (tail[tail.len() - 1] - tail[0]) / mean;
    println!(
        "sharp cone: load {:.0}–{:.0} kN/m over δ = 1.4–2.0 cm, mean {mean:.1} = {:+.2} % of 3120, rise {:+.2} %",
        tail[0],
        tail[tail.len() - 1],
        100.0 * (mean / 3120.0 - 1.0),
        100.0 * rise
    );
    assert!(tail.len() >= 6);
    assert!(rise.abs() <= 0.03, "the load does not level off");
    assert!((mean / 3120.0 - 1.0).abs() <= 0.10, "plateau {mean:.1}");
}
