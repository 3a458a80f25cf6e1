//! The checkpoint file format: exact round trip of the state, and every
//! damaged file refused with its identifier.

use super::*;
use crate::output::OutputCursor;

const BAR: &str = include_str!("../../validation/elastic/bar_explicit.toml");

fn source() -> SceneSource {
    SceneSource {
        origin: "bar_explicit.toml".into(),
        text: BAR.into(),
        overrides: vec!["scene.end_time=0.01".into()],
    }
}

fn simulation(steps: usize) -> Simulation {
    let mut sim = Simulation::new(source().scene().unwrap()).unwrap();
    for _ in 0..steps {
        sim.step_once().unwrap();
    }
    sim
}

fn cursor() -> OutputCursor {
    OutputCursor {
        last_row_step: Some(3),
        pending_times: vec![0.5, 0.25],
        fields: Vec::new(),
        snapshots: vec![(0.0, "particles_000000.vtu".into())],
        curve_bytes: 1234,
        curve_checksum: 0xdead_beef,
    }
}

fn file() -> Vec<u8> {
    encode(
        source().fingerprint(),
        &SavedState::of(&simulation(3), cursor(), 12.5),
    )
}

fn bits(sim: &Simulation) -> Vec<u64> {
    let p = &sim.model.state.particles;
    p.position
        .iter()
        .chain(&p.velocity)
        .flatten()
        .chain(p.stress.iter().flatten())
        .chain(&p.volume)
        .map(|v| v.to_bits())
        .collect()
}

#[test]
fn a_restored_state_steps_on_bit_identically() {
    let mut straight = simulation(3);
    let bytes = encode(
        source().fingerprint(),
        &SavedState::of(&straight, cursor(), 12.5),
    );
    let state = decode(Path::new("c"), &bytes, source().fingerprint()).unwrap();
    let mut resumed = simulation(0);
    state.check_fits(&resumed).unwrap();
    let back = state.restore(&mut resumed);
    assert_eq!(back.last_row_step, Some(3));
    assert_eq!(back.pending_times, vec![0.5, 0.25]);
    assert_eq!((back.curve_bytes, back.curve_checksum), (1234, 0xdead_beef));
    assert_eq!(resumed.model.state.step, 3);
    assert_eq!(bits(&resumed), bits(&straight));
    for _ in 0..3 {
        straight.step_once().unwrap();
        resumed.step_once().unwrap();
    }
    assert_eq!(
        resumed.model.state.time.to_bits(),
        straight.model.state.time.to_bits()
    );
    assert_eq!(bits(&resumed), bits(&straight));
    assert_eq!(resumed.monitor_values(), straight.monitor_values());
    // the state is the whole payload: encoding the restored run gives the
    // same file, but for the time it took (its profile covers both builds)
    // and for its second build
    let untimed = |sim: &Simulation| {
        let mut state = SavedState::of(sim, cursor(), 0.0);
        state
            .stages
            .iter_mut()
            .for_each(|(_, seconds)| *seconds = 0.0);
        state.stages[crate::profile::Stage::Build as usize] = (0, 0.0);
        encode(source().fingerprint(), &state)
    };
    assert_eq!(untimed(&resumed), untimed(&straight));
}

#[test]
fn truncated_files_are_refused_as_truncated() {
    let bytes = file();
    for keep in [
        0,
        5,
        11,
        20,
        HEADER_LEN,
        HEADER_LEN + 1,
        bytes.len() / 2,
        bytes.len() - 1,
    ] {
        let err = decode(Path::new("c"), &bytes[..keep], source().fingerprint()).unwrap_err();
        assert_eq!(err.id(), "CHECKPOINT_TRUNCATED", "{keep} bytes: {err}");
    }
}

#[test]
fn a_flipped_bit_anywhere_after_the_version_is_refused_as_corrupt() {
    let bytes = file();
    let fingerprint = source().fingerprint();
    // every header byte after the version, and a spread of payload bytes
    let positions: Vec<usize> = (12..HEADER_LEN)
        .chain((HEADER_LEN..bytes.len()).step_by(97))
        .collect();
    for i in positions {
        let mut damaged = bytes.clone();
        damaged[i] ^= 0x10;
        let err = decode(Path::new("c"), &damaged, fingerprint).unwrap_err();
        let expected = if (24..32).contains(&i) {
            // a length that grew reads as a cut-off file
            ["CHECKPOINT_CORRUPT", "CHECKPOINT_TRUNCATED"]
        } else {
            ["CHECKPOINT_CORRUPT", "CHECKPOINT_CORRUPT"]
        };
        assert!(expected.contains(&err.id()), "byte {i}: {err}");
    }
    let mut longer = bytes.clone();
    longer.push(0);
    let err = decode(Path::new("c"), &longer, fingerprint).unwrap_err();
    assert_eq!(err.id(), "CHECKPOINT_CORRUPT", "{err}");
}

#[test]
fn other_versions_scenes_and_files_are_refused_with_their_identifiers() {
    let bytes = file();
    let mut newer = bytes.clone();
    newer[8..12].copy_from_slice(&(FORMAT_VERSION + 1).to_le_bytes());
    let err = decode(Path::new("c"), &newer, source().fingerprint()).unwrap_err();
    assert_eq!(err.id(), "CHECKPOINT_VERSION");
    assert!(err.to_string().contains("format version"), "{err}");
    assert!(err
        .to_string()
        .contains(&format!("version {}", FORMAT_VERSION + 1)));

    let mut other = source();
    other.overrides.push("solver.cfl=0.4".into());
    assert_ne!(other.fingerprint(), source().fingerprint());
    let err = decode(Path::new("c"), &bytes, other.fingerprint()).unwrap_err();
    assert_eq!(err.id(), "CHECKPOINT_FOREIGN", "{err}");

    let err = decode(Path::new("c"), b"step,time\n0,0\n", 0).unwrap_err();
    assert_eq!(err.id(), "CHECKPOINT_NOT_A_CHECKPOINT", "{err}");
}

#[test]
fn a_moved_scene_file_is_the_same_scene() {
    let mut moved = source();
    moved.origin = "elsewhere/bar.toml".into();
    assert_eq!(moved.fingerprint(), source().fingerprint());
    let mut edited = source();
    edited.text.push_str("\n# a comment\n");
    assert_ne!(edited.fingerprint(), source().fingerprint());
}

#[test]
fn every_checkpoint_error_has_a_listed_checkpoint_identifier() {
    let errors = [
        CheckpointError::Missing {
            path: "p".into(),
            message: "m".into(),
        },
        CheckpointError::NotACheckpoint { path: "p".into() },
        CheckpointError::Outputs {
            path: "p".into(),
            detail: "d".into(),
        },
        CheckpointError::Io {
            path: "p".into(),
            message: "m".into(),
        },
    ];
    for e in errors {
        let id = mpm_physics::error_id::Identified::error_id(&e);
        assert!(mpm_physics::error_id::ErrorId::ALL.contains(&id));
        assert!(
            e.id().starts_with("CHECKPOINT_") && e.id() == id.name(),
            "{e}"
        );
    }
}
