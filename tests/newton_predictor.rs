//! `[solver] predictor`: where Newton starts an implicit dynamic step. Scene:
//! `validation/lost_points/block_leaves_grid.toml` run as implicit Newmark for
//! 0.05 s (10 steps of 5 ms), a free elastic block translating at 1 m/s that
//! stays on the grid: its motion is uniform, so the exact step increment is
//! Δu = Δt v at every free dof.

mod common;

const SCENE: &str = "lost_points/block_leaves_grid.toml";
const SPEED: f64 = 1.0;
const STEPS: usize = 10;
const DT: f64 = 5e-3;

/// Newton iterations of every step and the final x displacements of the points.
fn run(predictor: &str) -> (Vec<usize>, Vec<f64>) {
    let overrides = [
        "scene.analysis=\"implicit_dynamic\"".to_string(),
        format!("scene.steps={STEPS}"),
        format!("scene.dt={DT}"),
        format!("solver.predictor=\"{predictor}\""),
    ];
    let overrides: Vec<&str> = overrides.iter().map(String::as_str).collect();
    let mut sim = common::simulation(SCENE, &overrides);
    let mut iterations = Vec::new();
    while !sim.finished() {
        let report = sim.step_once().unwrap_or_else(|e| panic!("{e}"));
        iterations.push(report.iterations);
    }
    let p = &sim.model.state.particles;
    let u = (0..p.len()).map(|i| p.displacement(i)[0]).collect();
    (iterations, u)
}

/// The motion predictor Δu⁰ = Δt v + ½ Δt² a is the exact increment of uniform
/// motion: the first residual is already converged (0 iterations in every step),
/// while from zero Newton needs at least one correction per step. Both end at
/// u = v t = 0.05 m (to 5e-15 m; measured 4e-17 and 4e-16).
#[test]
fn the_motion_predictor_is_the_exact_increment_of_uniform_motion() {
    let (from_motion, u_motion) = run("motion");
    let (from_zero, u_zero) = run("zero");
    assert_eq!(from_motion.len(), STEPS);
    assert!(
        from_motion.iter().all(|&i| i == 0),
        "motion: {from_motion:?}"
    );
    assert!(from_zero.iter().all(|&i| i >= 1), "zero: {from_zero:?}");
    let expected = SPEED * DT * STEPS as f64;
    for (a, b) in u_motion.iter().zip(&u_zero) {
        assert!(
            (a - expected).abs() < 5e-15,
            "motion: u = {a}, expected {expected}"
        );
        assert!(
            (b - expected).abs() < 5e-15,
            "zero: u = {b}, expected {expected}"
        );
    }
}

/// theory §3 motion limit h/2 = 0.025 m: one step of 0.03 s moves the block at
/// 1 m/s by 0.03 m. Without halvings the step fails, naming the point and its
/// motion, and reports the residual history of the converged solve it rejected
/// (one entry: the predictor is exact) instead of an empty one.
#[test]
fn a_step_beyond_the_motion_limit_reports_its_residual_history() {
    let overrides = [
        "scene.analysis=\"implicit_dynamic\"",
        "scene.steps=1",
        "scene.dt=0.03",
        "solver.max_halvings=0",
    ];
    let mut sim = common::simulation(SCENE, &overrides);
    let error = sim
        .step_once()
        .expect_err("0.03 m > h/2 in one step")
        .to_string();
    assert!(error.contains("moved 3.000e-2 m > h/2"), "{error}");
    let history = error
        .split("residual history [")
        .nth(1)
        .and_then(|rest| rest.split(']').next())
        .unwrap_or_else(|| panic!("no history in: {error}"));
    let norms: Vec<f64> = history
        .split(", ")
        .map(|v| v.parse().unwrap_or_else(|_| panic!("{history}")))
        .collect();
    assert_eq!(norms.len(), 1, "{error}");
}
