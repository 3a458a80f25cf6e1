//! `[solver] remember_halvings` (theory §3.3): a fixed step that needed
//! halvings starts the next at the depth it reached. Scene:
//! `validation/lost_points/block_leaves_grid.toml` as implicit Newmark on a
//! grid widened to 1 m, a free elastic block translating at 1 m/s: its
//! motion is uniform, so every substep's predictor is exact and only the
//! motion limit h/2 = 0.025 m decides the halvings. A step of 0.06 s moves
//! it 0.06 m: 0.03 m substeps fail too, 0.015 m ones pass (depth 2).

mod common;

const SCENE: &str = "lost_points/block_leaves_grid.toml";
const STEPS: usize = 8;
const DT: f64 = 0.06;

/// Halvings, remembered substeps and the final x displacements of the points.
fn run(remember: bool) -> (usize, usize, Vec<f64>) {
    let overrides = [
        "scene.analysis=\"implicit_dynamic\"".to_string(),
        "scene.end_time=".to_string(),
        "solver.cfl=".to_string(),
        "grid.size=[1.0, 0.2]".to_string(),
        format!("scene.steps={STEPS}"),
        format!("scene.dt={DT}"),
        format!("solver.remember_halvings={remember}"),
    ];
    let overrides: Vec<&str> = overrides.iter().map(String::as_str).collect();
    let mut sim = common::simulation(SCENE, &overrides);
    while !sim.finished() {
        sim.step_once().unwrap_or_else(|e| panic!("{e}"));
    }
    let usage = sim.integrator.usage();
    let p = &sim.model.state.particles;
    let u = (0..p.len()).map(|i| p.displacement(i)[0]).collect();
    (usage.halvings, usage.remembered_substeps, u)
}

/// Without the option every step fails whole and at each half (3 halvings a
/// step, 24 in all). With it the first step does the same and leaves depth
/// 2; a step that passes at its depth lets the next try depth 1, whose two
/// halves fail once each: 3 + 3 × 2 = 9 halvings; the four steps at depth 2
/// (steps 2, 4, 6, 8) and the three at depth 1 start split into
/// 4 × 4 + 3 × 2 = 22 pieces. Both end at u = v t = 0.48 m (to 5e-15 m;
/// measured 4.4e-16).
#[test]
fn a_remembered_depth_skips_the_failed_whole_steps_and_keeps_the_motion() {
    let (halvings_whole, remembered_whole, u_whole) = run(false);
    let (halvings, remembered, u) = run(true);
    assert_eq!(halvings_whole, 3 * STEPS);
    assert_eq!(remembered_whole, 0);
    assert_eq!(halvings, 9);
    assert_eq!(remembered, 22);
    let expected = DT * STEPS as f64;
    for (a, b) in u.iter().zip(&u_whole) {
        assert!((a - expected).abs() < 5e-15, "remembered: u = {a}");
        assert!((b - expected).abs() < 5e-15, "whole: u = {b}");
    }
}
