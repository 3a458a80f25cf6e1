//! Bar vibration (theory §8.4): elastic column, fixed base, free top, ν = 0,
//! initial velocity v₀ sin(πy/2H). Exact period T = 4H/c, c = sqrt(E/ρ)
//! (H = 1 m, E = 1e4 kPa, ρ = 1 t/m³: T = 0.04 s).
//!
//! Tolerances: period within 1 % (implicit Newmark and explicit MUSL);
//! Newmark trapezoidal total energy within 0.1 % over 10 periods (at Δt = T/200;
//! the P2G/G2P smoothing of the velocity update loses energy ∝ Δt·h², 1.0e-3 at T/100); explicit
//! stable at CFL 0.9 (energy stays within 5 % of its initial value);
//! both integrators give the same top displacement history within 2 % of the
//! amplitude over the first two periods.

mod common;

use mpm_physics::error::StepError;
use mpm_physics::scene::SceneError;

const PERIOD: f64 = 0.04;

/// Mean period from the zero crossings of a history (spacing of crossings = T/2).
fn period_from_crossings(history: &[(f64, Vec<f64>)], col: usize) -> f64 {
    let mut crossings = Vec::new();
    for w in history.windows(2) {
        let (t0, u0) = (w[0].0, w[0].1[col]);
        let (t1, u1) = (w[1].0, w[1].1[col]);
        if t0 > 0.0 && u0 * u1 < 0.0 {
            crossings.push(t0 + (t1 - t0) * u0 / (u0 - u1));
        }
    }
    assert!(
        crossings.len() >= 4,
        "too few zero crossings: {}",
        crossings.len()
    );
    2.0 * (crossings[crossings.len() - 1] - crossings[0]) / (crossings.len() - 1) as f64
}

fn energies(sim: &mpm_physics::simulation::Simulation, history: &[(f64, Vec<f64>)]) -> Vec<f64> {
    let (k, s) = (
        common::column(sim, "kinetic_energy"),
        common::column(sim, "strain_energy"),
    );
    history.iter().map(|(_, v)| v[k] + v[s]).collect()
}

#[test]
fn newmark_period_and_energy_conservation() {
    let mut sim = common::simulation("elastic/bar_implicit.toml", &[]);
    let history = common::run_history(&mut sim);
    let period = period_from_crossings(&history, common::column(&sim, "top_uy"));
    println!(
        "Newmark: period {period:.6e} s (exact {PERIOD:e}), rel. error {:.3e}",
        period / PERIOD - 1.0
    );
    assert!((period / PERIOD - 1.0).abs() <= 0.01);
    let e = energies(&sim, &history);
    let drift = e.iter().map(|v| (v / e[0] - 1.0).abs()).fold(0.0, f64::max);
    println!("Newmark: max relative energy drift over 10 periods {drift:.3e}");
    assert!(drift <= 1e-3, "energy drift {drift:e}");
}

fn explicit_period_and_energy(cfl: f64) -> (f64, f64) {
    explicit_period_and_energy_with(cfl, &[])
}

fn explicit_period_and_energy_with(cfl: f64, extra: &[&str]) -> (f64, f64) {
    let c = format!("solver.cfl={cfl}");
    let mut overrides = vec![c.as_str()];
    overrides.extend_from_slice(extra);
    let mut sim = common::simulation("elastic/bar_explicit.toml", &overrides);
    let history = common::run_history(&mut sim);
    let period = period_from_crossings(&history, common::column(&sim, "top_uy"));
    let e = energies(&sim, &history);
    let drift = e.iter().map(|v| (v / e[0] - 1.0).abs()).fold(0.0, f64::max);
    println!("explicit CFL {cfl}: period {period:.6e} s (rel. error {:.3e}), max energy change {drift:.3e}", period / PERIOD - 1.0);
    (period, drift)
}

/// The explicit MUSL path with GIMP shape functions (the same transfer
/// kernels): the bar's period within 1 % and its energy within 5 % at CFL 0.5,
/// the tolerances of the bilinear run (measured: period +0.08 %, energy 2.0 %,
/// as with bilinear cells).
#[test]
fn explicit_period_with_gimp_shape_functions() {
    let gimp = ["grid.shape_functions=gimp", "grid.point_layout=uniform"];
    let (period, drift) = explicit_period_and_energy_with(0.5, &gimp);
    assert!(
        (period / PERIOD - 1.0).abs() <= 0.01,
        "GIMP: period {period}"
    );
    assert!(drift <= 0.05, "GIMP: energy changed by {drift:e}");
}

#[test]
fn explicit_period_at_cfl_half_and_stability_at_cfl_09() {
    for cfl in [0.5, 0.9] {
        let (period, drift) = explicit_period_and_energy(cfl);
        assert!(
            (period / PERIOD - 1.0).abs() <= 0.01,
            "CFL {cfl}: period {period}"
        );
        assert!(drift <= 0.05, "CFL {cfl}: energy changed by {drift:e}");
    }
}

#[test]
fn explicit_time_step_above_the_limit_is_refused_before_the_run() {
    // h / c = 0.05 / 100 = 5e-4 s
    let overrides = vec!["scene.dt=6.0e-4".to_string()];
    let err = mpm_physics::scene::Scene::load(
        &common::validation("elastic/bar_explicit.toml"),
        &overrides,
    )
    .unwrap_err();
    let SceneError::Invalid { errors, .. } = &err else {
        panic!("expected a validation error, got {err}")
    };
    assert!(
        errors
            .iter()
            .any(|e| e.field == "scene.dt" && e.message.contains("stability limit")),
        "{err}"
    );
}

#[test]
fn explicit_time_step_above_the_moving_limit_is_detected_during_the_run() {
    // 0.99999 h/c passes the static check but exceeds h/(c + |v|) once the bar moves.
    let mut sim = common::simulation("elastic/bar_explicit.toml", &["scene.dt=4.99995e-4"]);
    let err = loop {
        match sim.step_once() {
            Ok(_) if sim.finished() => panic!("the unstable step was not detected"),
            Ok(_) => continue,
            Err(e) => break e,
        }
    };
    assert!(
        matches!(err.cause(), Some(StepError::UnstableTimeStep { .. })),
        "{err}"
    );
    assert!(err.to_string().contains("stability limit"), "{err}");
}

#[test]
fn implicit_and_explicit_histories_agree() {
    let mut implicit = common::simulation(
        "elastic/bar_implicit.toml",
        &["scene.steps=400", "scene.dt=2.0e-4"],
    );
    let mut explicit = common::simulation("elastic/bar_explicit.toml", &["scene.end_time=0.08"]);
    let hi = common::run_history(&mut implicit);
    let he = common::run_history(&mut explicit);
    let (ci, ce) = (
        common::column(&implicit, "top_uy"),
        common::column(&explicit, "top_uy"),
    );
    let amplitude = hi.iter().map(|(_, v)| v[ci].abs()).fold(0.0, f64::max);
    let mut worst = 0.0f64;
    for (t, v) in &hi {
        let k = he.partition_point(|(te, _)| te < t).clamp(1, he.len() - 1);
        let (t0, t1) = (he[k - 1].0, he[k].0);
        let s = if t1 > t0 { (t - t0) / (t1 - t0) } else { 0.0 };
        let ue = he[k - 1].1[ce] * (1.0 - s) + he[k].1[ce] * s;
        worst = worst.max((v[ci] - ue).abs());
    }
    println!(
        "implicit vs explicit: max |Δu_top| = {worst:.3e} m, amplitude {amplitude:.3e} m ({:.2} %)",
        100.0 * worst / amplitude
    );
    assert!(worst <= 0.02 * amplitude);
}

/// Newmark with γ > ½ (β = (γ + ½)²/4) damps numerically: for a mode of
/// frequency ω at step Δt the algorithmic damping ratio is (γ − ½)ωΔt/2 to
/// leading order, so the energy of the bar's first mode decays as
/// exp(−(γ − ½) ω² Δt t). At γ = 0.6 over 10 periods that predicts 17.9 %;
/// the measured decay must match within 2 % of the logarithmic decrement (the
/// next-order term is O((ωΔt)²) ≈ 1e-3 and the P2G/G2P loss 5e-4 of 0.197),
/// the energy must never increase, and the period stays within 1 %.
#[test]
fn newmark_gamma_above_half_damps_at_the_predicted_rate() {
    let gamma = 0.6;
    let mut sim = common::simulation(
        "elastic/bar_implicit.toml",
        &[&format!("solver.newmark_gamma={gamma}")],
    );
    let history = common::run_history(&mut sim);
    let period = period_from_crossings(&history, common::column(&sim, "top_uy"));
    assert!((period / PERIOD - 1.0).abs() <= 0.01, "period {period}");
    let e = energies(&sim, &history);
    for w in e.windows(2) {
        assert!(
            w[1] <= w[0] * (1.0 + 1e-9),
            "energy rose: {} → {}",
            w[0],
            w[1]
        );
    }
    let omega = 2.0 * std::f64::consts::PI / PERIOD;
    let (dt, t_end) = (
        sim.integrator.implicit().expect("an implicit run").dt(),
        history.last().unwrap().0,
    );
    let predicted = (gamma - 0.5) * omega * omega * dt * t_end;
    let measured = -(e.last().unwrap() / e[0]).ln();
    println!("γ = {gamma}: log energy decrement {measured:.4} (predicted {predicted:.4})");
    assert!(
        (measured / predicted - 1.0).abs() <= 0.02,
        "decrement {measured} vs {predicted}"
    );
}

/// Generalised-α with ρ∞ = 1 is the trapezoidal rule (α_m = α_f = ½, γ = ½,
/// β = ¼, and the points' force per mass equals their acceleration): the
/// top displacement and the energies of two periods agree with Newmark γ = ½
/// to round-off (measured: identical top displacements, energies 1e-16 apart).
#[test]
fn generalised_alpha_with_rho_one_is_the_trapezoidal_rule() {
    let steps = "scene.steps=400";
    let mut trapezoidal = common::simulation("elastic/bar_implicit.toml", &[steps]);
    let mut alpha = common::simulation(
        "elastic/bar_implicit.toml",
        &[steps, "solver.rho_infinity=1"],
    );
    let (a, b) = (
        common::run_history(&mut trapezoidal),
        common::run_history(&mut alpha),
    );
    let scale = a
        .iter()
        .flat_map(|(_, v)| v.iter().map(|x| x.abs()))
        .fold(0.0, f64::max);
    let gap = a
        .iter()
        .zip(&b)
        .flat_map(|((_, u), (_, v))| u.iter().zip(v).map(|(x, y)| (x - y).abs()))
        .fold(0.0, f64::max);
    println!("ρ∞ = 1 against γ = ½: largest monitor difference {gap:e} of {scale:e}");
    assert!(gap <= 1e-12 * scale, "ρ∞ = 1 differs by {gap:e}");
}

/// Least-squares fit of ln √E_n = c + n ln ρ + k ln n over the steps `steps`:
/// the decay ρ per step of a state whose amplification has a repeated
/// eigenvalue (amplitude n^k ρⁿ).
fn fitted_decay(energy: &[f64], steps: std::ops::Range<usize>) -> f64 {
    let rows: Vec<[f64; 3]> = steps
        .clone()
        .map(|n| [1.0, n as f64, (n as f64).ln()])
        .collect();
    let y: Vec<f64> = steps.map(|n| 0.5 * energy[n].ln()).collect();
    let mut normal = nalgebra::Matrix3::<f64>::zeros();
    let mut rhs = nalgebra::Vector3::<f64>::zeros();
    for (row, yi) in rows.iter().zip(&y) {
        let r = nalgebra::Vector3::from_row_slice(row);
        normal += r * r.transpose();
        rhs += r * *yi;
    }
    let coefficients = normal.lu().solve(&rhs).expect("a regular fit");
    coefficients[1].exp()
}

/// Issue 39, check 1: on a bar stiff against its step (E = 1e8 kPa, Δt = 0.4 s,
/// i.e. ωΔt ≈ 6,300 for the first mode) every mode is a high-frequency
/// one, and generalised-α must damp the whole motion by ρ∞ per step. At infinite
/// frequency Chung and Hulbert's amplification matrix has the triple eigenvalue −ρ∞,
/// so the amplitude goes as n^k ρ∞ⁿ: ρ is fitted with that form (the plain
/// step ratio tends to ρ∞ only as 1 + k/n). Fitted within 5 % of ρ∞ (measured
/// 0.503 for 0.5 and 0.784 for 0.8), over the steps before the energy reaches
/// 1e-8 of its start, where Newton's tolerance begins to show.
#[test]
fn generalised_alpha_damps_the_highest_frequencies_by_rho_infinity() {
    for (rho, steps) in [(0.5, 2..16), (0.8, 2..40)] {
        let mut sim = common::simulation(
            "elastic/bar_implicit.toml",
            &[
                &format!("solver.rho_infinity={rho}"),
                "scene.steps=40",
                "scene.dt=0.4",
                "materials.bar.E=1e8",
                "body.0.velocity0=[0.0, 1.0]",
            ],
        );
        let history = common::run_history(&mut sim);
        let energy = energies(&sim, &history);
        assert!(
            energy[steps.end - 1] > 1e-8 * energy[0],
            "the fit window stays above Newton's tolerance"
        );
        let decay = fitted_decay(&energy, steps);
        println!("ρ∞ = {rho}: fitted decay per step {decay:.4}");
        assert!(
            (decay / rho - 1.0).abs() <= 0.05,
            "ρ∞ = {rho}: decay {decay}"
        );
    }
}
