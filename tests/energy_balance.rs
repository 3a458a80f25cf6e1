//! Energy balance (DESIGN §9, M5) on the biaxial benchmark with an elastic
//! soil (cohesion raised so nothing yields): the work of the pressures and the
//! platen on the soil (`external_work`), the work of the stresses on the
//! strain increments (`internal_work`) and the kinetic energy are summed
//! independently (pressure points, rigid-body force and prescribed motion,
//! material points), so their balance W = W_int + K checks all three. Measured
//! at δ = 1.5 mm (h = 1/300 m, GIMP, surface-tied platen): W − W_int − K is
//! 2.4e-5 W quasi-static and 2.7e-5 W implicit dynamic (γ = 0.6).

mod common;

fn balance(analysis: &str) -> (f64, f64, f64) {
    let analysis = format!("scene.analysis={analysis}");
    let mut sim = common::simulation(
        "biaxial/local_h300.toml",
        &[
            "materials.soil.c_ini=1e6",
            analysis.as_str(),
            "scene.steps=150",
            "output.snapshots=[]",
        ],
    );
    let history = common::run_history(&mut sim);
    let last = &history.last().unwrap().1;
    let value = |name: &str| last[common::column(&sim, name)];
    (
        value("external_work"),
        value("internal_work"),
        value("kinetic_energy"),
    )
}

#[test]
fn external_work_equals_internal_work_plus_kinetic_energy_in_an_elastic_run() {
    for analysis in ["quasi_static", "implicit_dynamic"] {
        let (external, internal, kinetic) = balance(analysis);
        // W = ∫F dδ-sized: about 1.8e-2 kJ/m at δ = 1.5 mm
        assert!(external > 1e-2, "{analysis}: W = {external}");
        let loss = (external - internal - kinetic) / external;
        println!("{analysis}: W = {external:.6e}, W_int = {internal:.6e}, K = {kinetic:.2e}, loss {loss:.2e}");
        // the Newmark damping (γ = 0.6) of the start-up oscillation is the largest
        // physical loss here, ~1e-5 W; trapezoidal follower work adds less
        assert!(loss.abs() <= 2e-4, "{analysis}: relative imbalance {loss}");
    }
}
