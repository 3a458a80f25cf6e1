//! `[output] snapshot_times`: an explicit run (steps of its own choosing)
//! writes a snapshot and captures the fields at the end of the first step that
//! reaches each requested time, and only then.

mod common;

use mpm_geo::run::run_scene;

#[test]
fn explicit_run_captures_the_first_step_past_each_requested_time() {
    let scene = common::scene(
        "elastic/bar_explicit.toml",
        &["output.snapshot_times=[0.25, 0.1]", "scene.end_time=0.3"],
    );
    let dir = tempfile::tempdir().unwrap();
    let outcome = run_scene(scene, dir.path(), false).unwrap();
    assert!(outcome.error.is_none());
    let dt_max = outcome
        .simulation
        .integrator
        .usage()
        .explicit_time_step
        .unwrap()
        .1;
    let fields = &outcome.fields;
    assert_eq!(fields.len(), 2);
    for (field, requested) in fields.iter().zip([0.1, 0.25]) {
        assert_eq!(field.requested_time, requested);
        assert!(
            field.time >= requested && field.time < requested + dt_max * (1.0 + 1e-9),
            "captured at {} for {requested} (dt {dt_max})",
            field.time
        );
        assert_eq!(
            field.positions.len(),
            outcome.simulation.model.state.particles.len()
        );
    }
    let snapshots = std::fs::read_dir(dir.path())
        .unwrap()
        .filter(|e| {
            e.as_ref()
                .is_ok_and(|e| e.file_name().to_string_lossy().ends_with(".vtu"))
        })
        .count();
    assert_eq!(snapshots, 2);
}
