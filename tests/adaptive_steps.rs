//! Issue 39, check 2: error-controlled steps on the elastic bar
//! (`validation/elastic/bar_implicit.toml`, two periods). Each adaptive run is
//! measured against a run of the same mesh with a fixed step 20× below the
//! smallest the controller takes at the finest tolerance (Δt = 1e-5 s), so the
//! spatial error cancels. Over two decades of `solver.error_tolerance`:
//! - the largest top-displacement error over the run, relative to the
//!   amplitude, falls in proportion to the tolerance: log–log slope within
//!   ±0.3 of 1 (measured 0.91; 0.92 down to 1e-5);
//! - the step count grows no faster than tolerance^(−1/2) (measured
//!   exponent −0.47: 36, 103, 313 steps).

mod common;

use mpm_geo::study::log_log_slope;

const SCENE: &str = "elastic/bar_implicit.toml";

/// (time, top displacement) after every step of `overrides`.
fn top_history(overrides: &[&str]) -> Vec<(f64, f64)> {
    let mut sim = common::simulation(SCENE, overrides);
    let top = common::column(&sim, "top_uy");
    common::run_history(&mut sim)
        .into_iter()
        .map(|(t, v)| (t, v[top]))
        .collect()
}

/// Linear interpolation of `history` at `t`.
fn at(history: &[(f64, f64)], t: f64) -> f64 {
    let i = history
        .partition_point(|(ti, _)| *ti < t)
        .clamp(1, history.len() - 1);
    let ((t0, u0), (t1, u1)) = (history[i - 1], history[i]);
    u0 + (u1 - u0) * (t - t0) / (t1 - t0)
}

#[test]
fn adaptive_error_falls_with_the_tolerance_at_no_more_than_its_square_root_in_steps() {
    let reference = top_history(&["scene.steps=8000", "scene.dt=1e-5"]);
    let amplitude = reference.iter().map(|(_, u)| u.abs()).fold(0.0, f64::max);
    let (mut errors, mut steps) = (Vec::new(), Vec::new());
    for tolerance in [1e-2, 1e-3, 1e-4] {
        let history = top_history(&[
            "scene.steps=400",
            "solver.time_step=\"adaptive\"",
            &format!("solver.error_tolerance={tolerance}"),
        ]);
        assert!(
            (history.last().unwrap().0 - 0.08).abs() < 1e-12,
            "ends at steps × dt"
        );
        let error = history
            .iter()
            .map(|&(t, u)| (u - at(&reference, t)).abs())
            .fold(0.0, f64::max)
            / amplitude;
        println!(
            "tolerance {tolerance:e}: {} steps, error {error:.3e}",
            history.len() - 1
        );
        errors.push((tolerance, error));
        steps.push((tolerance, (history.len() - 1) as f64));
    }
    let error_slope = log_log_slope(&errors).expect("slope");
    let step_slope = log_log_slope(&steps).expect("slope");
    println!("error slope {error_slope:.3}, step-count slope {step_slope:.3}");
    assert!(
        (error_slope - 1.0).abs() <= 0.3,
        "error slope {error_slope}"
    );
    assert!(step_slope >= -0.5, "steps grow as tolerance^{step_slope}");
}
