//! `[grid] lost_points`: material points that leave the grid are dropped
//! (`remove`) or stop the run (`stop`, the default). Scene:
//! `validation/lost_points/block_leaves_grid.toml`, a free block translating
//! rigidly at 1 m/s across the grid's right edge at x = 0.4 m, with two of
//! the points that stay followed by monitors.

mod common;

use mpm_physics::error::{RunError, StepError};

const SCENE: &str = "lost_points/block_leaves_grid.toml";
const SPEED: f64 = 1.0;
const EDGE: f64 = 0.4;

#[test]
fn points_crossing_the_edge_are_removed_and_the_rest_translate_rigidly() {
    let mut sim = common::simulation(SCENE, &[]);
    let initial_mass: f64 = sim.model.state.particles.mass.iter().sum();
    let initial_count = sim.model.state.particles.len();
    let history = common::run_history(&mut sim);
    let end_time = sim.model.state.time;
    let dt = end_time / sim.model.state.step as f64;

    // Ballistic prediction: a point leaves iff x0 + v t_end > 0.4, i.e. the
    // points seeded right of x = 0.2 (half of the 8 columns, 16 of 32).
    assert_eq!(initial_count, 32);
    assert_eq!(
        sim.model.state.lost_points.len(),
        16,
        "{:?}",
        sim.model.state.lost_points
    );
    let lost_mass: f64 = sim.model.state.lost_points.iter().map(|l| l.mass).sum();
    let kept_mass: f64 = sim.model.state.particles.mass.iter().sum();
    assert!(((lost_mass + kept_mass) / initial_mass - 1.0).abs() < 1e-12);
    assert!((lost_mass / initial_mass - 0.5).abs() < 1e-12);

    // Each point is removed in the step it crosses the edge, still moving at v.
    for lost in &sim.model.state.lost_points {
        let overshoot = lost.position[0] - EDGE;
        assert!(
            overshoot > 0.0 && overshoot <= SPEED * dt * (1.0 + 1e-9),
            "{lost:?}, dt {dt}"
        );
        assert!((lost.velocity[0] - SPEED).abs() < 1e-9, "{lost:?}");
        assert!(lost.velocity[1].abs() < 1e-9, "{lost:?}");
    }

    // The points that stay translate rigidly: displacement v t_end, velocity v, no stress.
    for p in 0..sim.model.state.particles.len() {
        assert!(sim.model.state.particles.position0[p][0] < 0.2);
        let u = sim.model.state.particles.displacement(p);
        assert!((u[0] - SPEED * end_time).abs() < 1e-9, "point {p}: {u:?}");
        assert!(u[1].abs() < 1e-9, "point {p}: {u:?}");
        assert!((sim.model.state.particles.velocity[p][0] - SPEED).abs() < 1e-9);
        let stress = sim.model.state.particles.stress[p];
        assert!(stress.iter().all(|s| s.abs() < 1e-9), "{stress:?}");
    }

    // Kinetic energy follows the mass that is left: ½ m v² before and after.
    let kinetic = common::column(&sim, "kinetic_energy");
    let first = history.first().unwrap().1[kinetic];
    let last = history.last().unwrap().1[kinetic];
    assert!((first / (0.5 * initial_mass * SPEED * SPEED) - 1.0).abs() < 1e-12);
    assert!((last / (0.5 * kept_mass * SPEED * SPEED) - 1.0).abs() < 1e-9);
}

/// The monitors follow their points across the removals, whichever points
/// go: at every step a monitored point has moved v t. Moving left, the
/// points that leave are the first half of the arrays, so the followed
/// points' indices shift by 16; a stale index would read another point or
/// one past the end of the shortened arrays (a panic, before the fix).
#[test]
fn monitors_follow_their_points_when_earlier_points_are_removed() {
    let leftward = [
        "body.0.velocity0=[-1.0, 0.0]",
        "monitor.1.point=[0.3, 0.15]",
        "monitor.2.point=[0.3, 0.05]",
    ];
    for (velocity, overrides) in [(SPEED, &[][..]), (-SPEED, &leftward[..])] {
        let mut sim = common::simulation(SCENE, overrides);
        let history = common::run_history(&mut sim);
        assert_eq!(sim.model.state.lost_points.len(), 16, "v = {velocity}");
        for name in ["u_top_left", "u_bottom_left"] {
            let column = common::column(&sim, name);
            for (t, values) in &history {
                let u = values[column];
                assert!(
                    (u - velocity * t).abs() < 1e-9,
                    "v = {velocity}: {name} at t = {t}: {u}"
                );
            }
        }
    }
}

#[test]
fn with_stop_the_first_point_to_cross_ends_the_run() {
    let mut sim = common::simulation(SCENE, &["grid.lost_points=\"stop\""]);
    let first_crossing = loop {
        match sim.step_once() {
            Ok(_) => assert!(!sim.finished(), "the block never left the grid"),
            Err(e) => break e,
        }
    };
    match first_crossing {
        RunError::Step {
            time,
            cause: StepError::ParticleLeftGrid { position, .. },
            ..
        } => {
            // first out: the right-most column, seeded at x0 = 0.275 + 0.025/√3
            let x0 = 0.275 + 0.025 / 3f64.sqrt();
            let dt = sim.model.state.time / sim.model.state.step as f64;
            assert!(position[0] > EDGE);
            assert!(
                (time - (EDGE - x0) / SPEED).abs() <= dt * (1.0 + 1e-9),
                "t = {time}"
            );
        }
        other => panic!("unexpected error {other}"),
    }
    assert!(sim.model.state.lost_points.is_empty());
}
