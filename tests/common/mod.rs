//! Helpers shared by the scene-level tests: load the scene files of
//! `validation/` (the same files users run) with overrides.

#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::Child;
use std::time::{Duration, Instant};

use mpm_physics::closed_form::{constrained_modulus, Column};
use mpm_physics::scene::{MaterialSpec, Scene};
use mpm_physics::simulation::Simulation;

/// Path of a file under `validation/`.
pub fn validation(path: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("validation")
        .join(path)
}

/// Load a validation scene with `overrides` (`key=value`).
pub fn scene(path: &str, overrides: &[&str]) -> Scene {
    let overrides: Vec<String> = overrides.iter().map(|s| s.to_string()).collect();
    Scene::load(&validation(path), &overrides).unwrap_or_else(|e| panic!("{e}"))
}

/// Build a simulation of a validation scene with `overrides`.
pub fn simulation(path: &str, overrides: &[&str]) -> Simulation {
    Simulation::new(scene(path, overrides)).unwrap_or_else(|e| panic!("{e}"))
}

/// The nonlocal strength variable κ̄ of every point (theory D35).
pub fn kappa_bar(sim: &Simulation) -> Vec<f64> {
    sim.model
        .state
        .particles
        .state
        .iter()
        .map(|s| s.plastic_strain_eq_nonlocal)
        .collect()
}

/// Run to the end, recording (time, monitor values) after every step (and at t = 0).
pub fn run_history(sim: &mut Simulation) -> Vec<(f64, Vec<f64>)> {
    let mut history = vec![(sim.model.state.time, sim.monitor_values())];
    while !sim.finished() {
        sim.step_once().unwrap_or_else(|e| panic!("{e}"));
        history.push((sim.model.state.time, sim.monitor_values()));
    }
    history
}

/// The closed-form column of a scene whose first body is an elastic box
/// standing on y = 0 (`elastic/oedometer.toml`, `elastic/soft_column.toml`).
pub fn elastic_column(sim: &Simulation) -> Column {
    let body = &sim.scene.body[0];
    let MaterialSpec::LinearElastic(elastic) = &sim.scene.materials[&body.material] else {
        panic!("material `{}` is not linear_elastic", body.material)
    };
    Column {
        height: body.bounds()[1][1],
        modulus: constrained_modulus(elastic.youngs_modulus, elastic.nu),
        density: elastic.density,
    }
}

/// RMS over the material points of σyy − [`Column::vertical_stress`] at
/// gravity `g`, kPa.
pub fn column_stress_rms(sim: &Simulation, g: f64) -> f64 {
    let column = elastic_column(sim);
    let p = &sim.model.state.particles;
    let sum: f64 = (0..p.len())
        .map(|i| (p.stress[i][1] - column.vertical_stress(p.position0[i][1], g)).powi(2))
        .sum();
    (sum / p.len() as f64).sqrt()
}

/// Column index of monitor `name`.
pub fn column(sim: &Simulation, name: &str) -> usize {
    sim.monitors
        .iter()
        .position(|m| m.name == name)
        .unwrap_or_else(|| panic!("no monitor {name}"))
}

/// Wait until `curve.csv` of the run folder `dir` has more than `rows`
/// lines, while `child` (the process writing it) runs; panics if it ends
/// first or after a minute without them.
pub fn wait_for_rows(dir: &Path, rows: usize, child: &mut Child) {
    let start = Instant::now();
    loop {
        let n = std::fs::read_to_string(dir.join("curve.csv"))
            .map(|t| t.lines().count())
            .unwrap_or(0);
        if n > rows {
            return;
        }
        if let Some(status) = child.try_wait().unwrap() {
            panic!("ended early: {status}");
        }
        assert!(start.elapsed() < Duration::from_secs(60), "no rows");
        std::thread::sleep(Duration::from_millis(5));
    }
}

/// Wait for `child`, killing it (and failing) if it has not ended after
/// `limit` (a guard against a hang, not a timing assertion).
pub fn wait(child: &mut Child, limit: Duration) -> std::process::ExitStatus {
    let start = Instant::now();
    loop {
        if let Some(status) = child.try_wait().unwrap() {
            return status;
        }
        if start.elapsed() > limit {
            let _ = child.kill();
            panic!("process did not end within {limit:?}");
        }
        std::thread::sleep(Duration::from_millis(10));
    }
}
