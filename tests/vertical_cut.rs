//! The vertical cut on coarse meshes (issue 12 checks 3 and 4; DESIGN §8.3):
//! the scene files of `validation/vertical_cut/` at h = 0.25 m.
//!
//! Check 3: the collapse of A (first |u_A| > 5 cm) starts between 0.03 and
//! 0.12 s (DESIGN §8.3 expects 0.05–0.09 s from limit analysis with the
//! p_t = 0 hyperbola and softening), A has moved more than 0.5 m by t = 1 s
//! and the run completes (points thrown off the free surface that leave the
//! grid are removed and counted; none leaves at this resolution).
//! Check 4: implicit Newmark and explicit MUSL, the same scene through the
//! same kernels, agree on the onset within 0.01 s and on |u_A| at t = 0.3 s
//! within 15 %.
//! The explicit run keeps a usable stable step to t = 1 s: the point volume
//! bound of the scenes (`grid.max_point_volume`) stops the points softened
//! to the apex from stretching without limit (without it the step fell to
//! 1/1400 of its initial value at this resolution).

mod common;

use mpm_geo::metrics::{first_exceedance, interpolate};
use mpm_geo::scene::Scene;
use mpm_geo::simulation::Simulation;

/// Coarse mesh of the CI variants: 12 x 12 cells over the block.
const COARSE: &str = "grid.cell_size=0.25";

/// (t, |u_A|) after every step, and the points removed.
fn displacement_of_a(scene: Scene) -> (Vec<(f64, f64)>, usize) {
    let mut sim = Simulation::new(scene).unwrap_or_else(|e| panic!("{e}"));
    let a = common::column(&sim, "uA");
    let history = common::run_history(&mut sim)
        .into_iter()
        .map(|(t, values)| (t, values[a]))
        .collect();
    (history, sim.model.lost_points.len())
}

fn onset(history: &[(f64, f64)]) -> f64 {
    first_exceedance(history, 0.05).expect("A never moved 5 cm")
}

fn assert_collapses(file: &str) -> Vec<(f64, f64)> {
    let (history, lost) = displacement_of_a(common::scene(file, &[COARSE]));
    let (t_end, u_end) = history[history.len() - 1];
    let t0 = onset(&history);
    println!(
        "{file} h = 0.25 m: onset {t0:.4} s, |u_A(1 s)| = {u_end:.3} m, {lost} points removed"
    );
    assert!((t_end - 1.0).abs() < 1e-9, "the run ended at {t_end} s");
    assert!((0.03..=0.12).contains(&t0), "onset {t0} s");
    assert!(u_end > 0.5, "|u_A(1 s)| = {u_end} m");
    history
}

#[test]
fn coarse_local_cut_collapses_in_the_expected_window_and_runs_out() {
    assert_collapses("vertical_cut/local_h100.toml");
}

#[test]
fn coarse_nonlocal_cut_collapses_alike_with_both_integrators() {
    let implicit = assert_collapses("vertical_cut/nonlocal_h100.toml");
    let scene = common::scene(
        "vertical_cut/nonlocal_h100.toml",
        &[COARSE, "scene.steps=300"],
    );
    let (explicit, _) = displacement_of_a(scene.explicit_twin().unwrap());
    let (t_implicit, t_explicit) = (onset(&implicit), onset(&explicit));
    let u_implicit = interpolate(&implicit, 0.3).unwrap();
    let u_explicit = interpolate(&explicit, 0.3).unwrap();
    println!(
        "onset implicit {t_implicit:.4} s, explicit {t_explicit:.4} s; |u_A(0.3 s)| implicit {u_implicit:.4} m, explicit {u_explicit:.4} m ({:+.1} %)",
        100.0 * (u_explicit / u_implicit - 1.0)
    );
    assert!((t_explicit - t_implicit).abs() <= 0.01);
    assert!((u_explicit / u_implicit - 1.0).abs() <= 0.15);
}

/// The explicit twin of the coarse nonlocal cut runs to t = 1 s without
/// its stable step collapsing: every step (but the last, cut to end at
/// t = 1 s) at least 1/4 of the first. Measured: 0.39 with the scenes'
/// bound `max_point_volume = 1`, 7e-4 without it (points stretched to
/// 5e5 cells, 166,000 steps instead of 1,600).
#[test]
fn coarse_explicit_cut_keeps_its_stable_step_to_the_end() {
    let scene = common::scene("vertical_cut/nonlocal_h100.toml", &[COARSE]);
    let mut sim = Simulation::new(scene.explicit_twin().unwrap()).unwrap();
    let a = common::column(&sim, "uA");
    let history = common::run_history(&mut sim);
    let steps: Vec<f64> = history.windows(2).map(|w| w[1].0 - w[0].0).collect();
    let first = steps[0];
    let smallest = steps[..steps.len() - 1]
        .iter()
        .copied()
        .fold(f64::INFINITY, f64::min);
    let (t_end, values) = &history[history.len() - 1];
    println!(
        "explicit h = 0.25 m: {} steps, smallest step {smallest:.3e} s = {:.3} of the first, |u_A({t_end})| = {:.2} m",
        steps.len(),
        smallest / first,
        values[a]
    );
    assert!((t_end - 1.0).abs() < 1e-9, "the run ended at {t_end} s");
    assert!(
        smallest >= 0.25 * first,
        "smallest step {smallest} s, first {first} s"
    );
    assert!(values[a] > 0.5, "|u_A(1 s)| = {} m", values[a]);
}

/// The largest difference of two |u_A| histories over t ∈ [0.05, 0.5] s
/// (every 10 ms), relative to the largest |u_A| of `b` there.
fn history_gap(a: &[(f64, f64)], b: &[(f64, f64)]) -> f64 {
    let times = (5..=50).map(|k| 0.01 * k as f64);
    let (mut gap, mut scale) = (0.0_f64, 0.0_f64);
    for t in times {
        let (ua, ub) = (interpolate(a, t).unwrap(), interpolate(b, t).unwrap());
        gap = gap.max((ua - ub).abs());
        scale = scale.max(ub.abs());
    }
    gap / scale
}

/// Issue 39, check 3 on u_A (the run-out at 0.5 s and the energy remainder
/// are not yet met: 12 % apart, 60–90 % of W). The friction-base
/// twin of the local cut (`validation/vertical_cut_friction/`) at h = 0.25 m
/// to t = 0.5 s, implicit generalised-α with adaptive steps (tolerance 1e-2
/// and 5e-3) and explicit MUSL (CFL 0.25 and 0.125): the finest of each agree
/// on the u_A history within 5 %, and each changes by less than 3 % when its
/// tolerance or step is halved. Measured: 1.3 % between the integrators;
/// 1.2 % implicit, 1.7 % explicit on halving.
#[test]
fn friction_base_cut_integrators_agree_on_the_crest_displacement() {
    let file = "vertical_cut_friction/local_h100.toml";
    let implicit = |tolerance: f64| {
        let tolerance = format!("solver.error_tolerance={tolerance}");
        let overrides = [
            COARSE,
            "scene.steps=500",
            "solver.time_step=\"adaptive\"",
            &tolerance,
        ];
        displacement_of_a(common::scene(file, &overrides)).0
    };
    let explicit = |cfl: f64| {
        let cfl = format!("solver.cfl={cfl}");
        let scene = common::scene(file, &[COARSE, "scene.steps=500", &cfl]);
        displacement_of_a(scene.explicit_twin().unwrap()).0
    };
    let (implicit_coarse, implicit_fine) = (implicit(1e-2), implicit(5e-3));
    let (explicit_coarse, explicit_fine) = (explicit(0.25), explicit(0.125));
    let between = history_gap(&explicit_fine, &implicit_fine);
    let implicit_halving = history_gap(&implicit_coarse, &implicit_fine);
    let explicit_halving = history_gap(&explicit_coarse, &explicit_fine);
    println!(
        "u_A(0.5 s): implicit {:.3} / {:.3} m, explicit {:.3} / {:.3} m; gaps: integrators {between:.4}, implicit halving {implicit_halving:.4}, explicit halving {explicit_halving:.4}",
        interpolate(&implicit_coarse, 0.5).unwrap(),
        interpolate(&implicit_fine, 0.5).unwrap(),
        interpolate(&explicit_coarse, 0.5).unwrap(),
        interpolate(&explicit_fine, 0.5).unwrap(),
    );
    assert!(between <= 0.05, "integrators differ by {between}");
    assert!(
        implicit_halving <= 0.03,
        "implicit halving {implicit_halving}"
    );
    assert!(
        explicit_halving <= 0.03,
        "explicit halving {explicit_halving}"
    );
}
