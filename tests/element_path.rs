//! Element path (theory §8.4; issue 4 checks 5–6): one cell with four material
//! points of the Table 1 material, driven through the full MPM engine along the
//! homogeneous plane-strain biaxial path.
//!
//! * The engine reproduces the material-point driver's σyy history, fed with the
//!   engine's own strain history, within 0.5 % of the peak stress.
//! * First yield at Δσyy = −552.26 kPa (theory §5.6) within 0.1 %.
//! * The plastic dissipation accumulated by the engine (D43) equals the
//!   driver's path integral within 0.5 %.
//! * Newton with the consistent tangent converges quadratically on a softening
//!   step: r_{k+1}/r_k² (residuals normalised by the D18 reference force) stays
//!   ≤ 100 for every iteration whose new residual is above round-off (> 1e−11;
//!   measured ≈ 9), and the step needs at most 6 iterations.

mod common;

use mpm_physics::constitutive::hmc::{Hmc, HmcParameters};
use mpm_physics::constitutive::LinearElastic;
use mpm_physics::point_driver::run_biaxial;

#[test]
fn engine_reproduces_the_driver_and_first_yield() {
    let mut sim = common::simulation("hmc/element_path.toml", &[]);
    let mut strains = Vec::new();
    let mut stresses = Vec::new();
    let mut volumes = vec![sim.model.state.particles.volume.iter().sum::<f64>()];
    while !sim.finished() {
        sim.step_once().unwrap_or_else(|e| panic!("{e}"));
        // all four points carry the same homogeneous state
        let p = &sim.model.state.particles;
        for i in 1..p.len() {
            assert!(
                (p.stress[i][1] - p.stress[0][1]).abs() <= 1e-6 * p.stress[0][1].abs(),
                "not homogeneous"
            );
        }
        strains.push(p.strain[0][1]);
        stresses.push(p.stress[0][1]);
        volumes.push(p.volume.iter().sum::<f64>());
    }
    let driver = run_biaxial(&Hmc::new(HmcParameters::table1()).unwrap(), 100.0, &strains).unwrap();
    let driver_syy: Vec<f64> = driver.iter().skip(1).map(|r| r.stress[1]).collect();
    assert_eq!(driver_syy.len(), stresses.len());
    let peak = stresses.iter().fold(0.0f64, |m, s| m.max(-s));
    let worst = stresses
        .iter()
        .zip(&driver_syy)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    println!(
        "element path: max |σyy(engine) − σyy(driver)| = {worst:.3e} kPa ({:.3e} of the peak)",
        worst / peak
    );
    assert!(worst <= 5e-3 * peak);
    // M5 (theory D43): the engine's dissipation equals the driver's path integral
    // Σ_n V(n) σ_{n+1}·(Δε − C Δσ) with the engine's volumes, within 0.5 %.
    let compliance =
        mpm_physics::constitutive::invert4(&LinearElastic::new(20000.0, 0.2).stiffness());
    let mut dissipation = 0.0;
    for n in 0..driver.len() - 1 {
        let (a, b) = (&driver[n], &driver[n + 1]);
        let ds: [f64; 4] = std::array::from_fn(|k| b.stress[k] - a.stress[k]);
        let elastic = mpm_physics::constitutive::mat4_mul_vec(&compliance, &ds);
        let work: f64 = (0..4)
            .map(|k| b.stress[k] * (b.strain[k] - a.strain[k] - elastic[k]))
            .sum();
        dissipation += volumes[n] * work;
    }
    println!(
        "element path: dissipation engine {:.6e} vs driver {dissipation:.6e} kJ/m",
        sim.model.state.dissipated_energy
    );
    assert!(dissipation > 0.0);
    assert!((sim.model.state.dissipated_energy / dissipation - 1.0).abs() <= 5e-3);
    let first_yield = peak - 100.0;
    println!("element path: first yield Δσyy = −{first_yield:.3} kPa (theory −552.26)");
    assert!((first_yield / 552.26 - 1.0).abs() <= 1e-3);
}

#[test]
fn newton_converges_quadratically_on_a_softening_step() {
    let mut sim = common::simulation(
        "hmc/element_path.toml",
        &["scene.steps=160", "solver.tolerance_force=1e-12"],
    );
    while !sim.finished() {
        sim.step_once().unwrap_or_else(|e| panic!("{e}"));
    }
    assert!(
        sim.model.state.particles.state[0].plastic_strain_eq > 0.0,
        "the last step must be plastic"
    );
    let (history, reference) = sim
        .integrator
        .implicit()
        .expect("an implicit run")
        .last_residuals
        .clone();
    let normalised: Vec<f64> = history.iter().map(|r| r / reference).collect();
    println!(
        "softening step {}: ‖R‖/F_ref per iteration {normalised:?}",
        sim.model.state.step
    );
    assert!(
        normalised.len() >= 3 && normalised.len() <= 7,
        "{} iterations",
        normalised.len() - 1
    );
    let mut checked = 0;
    for w in normalised.windows(2) {
        if w[1] > 1e-11 {
            let ratio = w[1] / (w[0] * w[0]);
            println!("  r_k+1 / r_k^2 = {ratio:.3e}");
            assert!(ratio <= 100.0, "not quadratic: {ratio:e}");
            checked += 1;
        }
    }
    assert!(checked >= 1, "no iteration pair above round-off");
}
