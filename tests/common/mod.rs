//! Helpers shared by the scene-level tests: load the scene files of
//! `validation/` (the same files users run) with overrides.

#![allow(dead_code)]

use std::path::PathBuf;

use mpm_geo::scene::Scene;
use mpm_geo::simulation::Simulation;

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

/// Run to the end, recording (time, monitor values) after every step (and at t = 0).
pub fn run_history(sim: &mut Simulation) -> Vec<(f64, Vec<f64>)> {
    let mut history = vec![(sim.model.time, sim.monitor_values())];
    while !sim.finished() {
        sim.step_once().unwrap_or_else(|e| panic!("{e}"));
        history.push((sim.model.time, sim.monitor_values()));
    }
    history
}

/// Column index of monitor `name`.
pub fn column(sim: &Simulation, name: &str) -> usize {
    sim.monitors
        .iter()
        .position(|m| m.name == name)
        .unwrap_or_else(|| panic!("no monitor {name}"))
}
