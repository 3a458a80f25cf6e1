//! Issue 13, check 2: the extreme-case study
//! (`validation/studies/extreme_cases.toml`) runs to the end through the
//! study framework and every case ends in a stated outcome: completed (with
//! a finite error where it has a reference, else the reason there is none),
//! or stopped / refused with the reason. A panic, a hang (killed at the
//! spec's time-out) or a signal fails the test.
//!
//! Coarse variant of the shipped spec, the same cases with shorter runs: the
//! bar two periods instead of ten, the biaxial tests to δ = 1.6 mm instead of
//! 2.2 mm, the vertical cut at h = 0.25 m for 0.15 s; about 30 s of CPU.
//! Also checks the stated physics where it is cheap: the explicit step count
//! grows as c_p (√E: ×31.6 for E × 1000, within 10 %), the implicit one does
//! not; implicit Newmark completes at Δt = 10 and 100 × the explicit limit,
//! where the explicit run is refused; GIMP follows the soft column's closed
//! form within 1 %.

mod common;

use mpm_geo::study::{run_spec, ReferenceSpec, RunReference, StudyOptions, StudyRow, StudySpec};

/// The shipped spec with the coarse overrides.
fn coarse_spec() -> StudySpec {
    let mut spec =
        StudySpec::load(&common::validation("studies/extreme_cases.toml")).expect("spec loads");
    // a hang must end the test, not block it
    spec.study.timeout = Some(120.0);
    for case in &mut spec.case {
        let scene = case
            .scene
            .as_ref()
            .map(|p| p.display().to_string())
            .unwrap_or_default();
        if case.scene.is_none() {
            // the bar: two periods (the explicit E × 1000 run: ~10,000 steps)
            case.set.push("scene.steps=400".into());
        } else if scene.contains("biaxial") {
            // δ = 1.6 mm: past the peak, where the local run cuts back
            case.set.push("scene.steps=16".into());
            if let Some(ReferenceSpec::Run { set, .. }) = &mut case.reference {
                set.push("scene.steps=160".into());
            }
        } else if scene.contains("vertical_cut") {
            case.set
                .extend(["grid.cell_size=0.25".into(), "scene.steps=150".into()]);
        }
    }
    spec
}

fn find<'a>(rows: &'a [StudyRow], case: &str, explicit: bool) -> &'a StudyRow {
    rows.iter()
        .find(|r| {
            r.planned.case.as_deref() == Some(case)
                && (r.planned.integrator == mpm_geo::campaign::IntegratorChoice::Explicit)
                    == explicit
        })
        .unwrap_or_else(|| panic!("no run of case `{case}` (explicit {explicit})"))
}

#[test]
fn every_extreme_case_has_a_stated_outcome() {
    let spec = coarse_spec();
    let out = tempfile::tempdir().expect("temp dir");
    let options = StudyOptions {
        executable: env!("CARGO_BIN_EXE_mpm-geo").into(),
        repeats: Some(1),
        verbose: true,
        part: mpm_geo::campaign::Part::Whole,
    };
    let rows = run_spec(&spec, out.path(), &options).expect("the study runs to the end");
    assert_eq!(
        rows.len(),
        spec.case.len() * 2,
        "every case × 2 integrators"
    );

    // every run: a stated outcome, with an error where there is a reference
    for r in &rows {
        let (name, m) = (&r.planned.name, &r.measured);
        assert!(
            m.stated(),
            "{name}: no stated outcome (panic, time-out or signal): {}",
            m.status
        );
        if m.completed() {
            match &r.planned.reference {
                RunReference::Unavailable(why) => {
                    assert!(!why.trim().is_empty(), "{name}: no reference, no reason")
                }
                _ => {
                    let e = r.error().unwrap_or(f64::NAN);
                    assert!(e.is_finite(), "{name}: no finite error ({:?})", r.errors);
                }
            }
        }
    }
    for file in ["study.csv", "report.md"] {
        assert!(out.path().join(file).exists(), "{file} written");
    }
    let report = std::fs::read_to_string(out.path().join("report.md")).unwrap();
    assert!(
        report.contains("| case | integrator | outcome | error | steps | wall time (s) |"),
        "{report}"
    );
    let csv = std::fs::read_to_string(out.path().join("study.csv")).unwrap();
    assert_eq!(csv.lines().count(), rows.len() + 1);
    eprintln!("{report}");

    // E × 1000: the explicit step count grows as √E = 31.6 (±10 %), the
    // implicit one (same Δt) does not
    let steps = |case: &str, explicit: bool| find(&rows, case, explicit).measured.steps as f64;
    let (base, stiff) = ("bar, ν = 0", "bar, E × 1000");
    let ratio = steps(stiff, true) / steps(base, true);
    assert!(
        (ratio / 1000f64.sqrt() - 1.0).abs() < 0.1,
        "explicit steps ×{ratio} for E × 1000"
    );
    assert_eq!(steps(stiff, false), steps(base, false));
    assert!(find(&rows, stiff, false).measured.completed());
    // ν → ½: the explicit steps grow as the P-wave speed (c_p/c at ν = 0 is
    // 4.14, 12.9 and 40.8), the implicit ones stay
    for nu in [0.49f64, 0.499, 0.4999] {
        let case = format!("bar, ν = {nu}");
        let c_ratio = ((1.0 - nu) / ((1.0 + nu) * (1.0 - 2.0 * nu))).sqrt();
        let ratio = steps(&case, true) / steps(base, true);
        assert!(
            (ratio / c_ratio - 1.0).abs() < 0.1,
            "{case}: explicit steps ×{ratio}, c_p ×{c_ratio}"
        );
        assert_eq!(steps(&case, false), steps(base, false), "{case}");
    }
    // Δt = 10 and 100 × h/c_p: Newmark completes (unconditionally stable;
    // its error is recorded), the explicit scheme refuses the step
    for (case, factor) in [("bar, Δt = 10 h/c_p", 10.0), ("bar, Δt = 100 h/c_p", 100.0)] {
        let implicit = find(&rows, case, false);
        let scene = &implicit.planned.scene;
        let limit = scene.critical_time_step().unwrap();
        assert!((scene.scene.dt.unwrap() / limit / factor - 1.0).abs() < 1e-9);
        assert!(
            implicit.measured.completed(),
            "{case}: {}",
            implicit.measured.status
        );
        let explicit = &find(&rows, case, true).measured.status;
        assert!(
            explicit.starts_with("refused: ") && explicit.contains("stability limit"),
            "{case}: {explicit}"
        );
    }
    // points crossing into nearly empty cells: the column's settlement with
    // GIMP within 1 % of the large-strain closed form (measured 0.42 %)
    let gimp = find(&rows, "soft column, GIMP", false);
    let e = gimp.error().expect("GIMP column error");
    assert!(e < 0.01, "GIMP column error {e}");
    // zero cohesion is refused naming the parameter, in both integrators
    for explicit in [false, true] {
        let status = &find(&rows, "vertical cut, c = 0, p_t = 0", explicit)
            .measured
            .status;
        assert!(
            status.starts_with("refused: ") && status.contains("c_ini"),
            "{status}"
        );
    }
}
