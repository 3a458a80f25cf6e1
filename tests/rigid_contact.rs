//! The rough rigid platen of the biaxial benchmark (`validation/biaxial/`),
//! elastic (c = 1e6 kPa), quasi-static, first step: with the platen tied to
//! the soil surface (`contact = "surface"`) the load per unit displacement of
//! the top equals that of a bilinear plane-strain FE model of the quarter
//! specimen with 2 × 2 Gauss points, rollers on the symmetry lines and the top
//! nodes fixed horizontally and pushed down together, on the same mesh.
//! Reference values from an independent FE code, `scripts/rough_top_fe.py`
//! (standard-library Python, banded Cholesky; `python3 scripts/rough_top_fe.py
//! 300 1000`): 12,635.3 (h = 1/300 m) and 12,631.6 kN/m per m (h = 1/1000 m);
//! theory §8.1 quotes 12,632–12,635 (h = 1/1000 … 1/300 m). Tying the top row of material points instead
//! (`contact = "top_points"`, theory §8.0) carries the soil above that row
//! with the platen and stiffens the specimen: measured +2.6 % at h = 1/300 m.

mod common;

/// F/δ of the first step, kN/m per m.
fn first_step_stiffness(cells_per_metre: usize, extra: &[&str]) -> f64 {
    let path = format!("biaxial/local_h{cells_per_metre}.toml");
    let mut overrides = vec![
        "materials.soil.c_ini=1e6",
        "scene.analysis=quasi_static",
        "scene.steps=1",
        "output.snapshots=[]",
    ];
    overrides.extend_from_slice(extra);
    let mut sim = common::simulation(&path, &overrides);
    let history = common::run_history(&mut sim);
    let (load, top) = (common::column(&sim, "load"), common::column(&sim, "top_uy"));
    let (first, last) = (&history[0].1, &history.last().unwrap().1);
    (last[load] - first[load]) / (first[top] - last[top])
}

const BILINEAR: [&str; 2] = ["grid.shape_functions=bilinear", "grid.point_layout=gauss"];

/// Within 0.05 % of the FE value on the same mesh (measured 4e-6 at h = 1/300 m).
#[test]
fn surface_contact_matches_the_rough_top_fe_model() {
    for (cells, reference) in [(300, 12_635.3), (1000, 12_631.6)] {
        let k = first_step_stiffness(cells, &BILINEAR);
        assert!(
            (k / reference - 1.0).abs() < 5e-4,
            "h = 1/{cells}: {k} vs FE {reference}"
        );
    }
    // GIMP with points on sub-cell centres: the same to 0.05 % (measured −7e-5)
    let gimp = first_step_stiffness(300, &[]);
    assert!((gimp / 12_635.3 - 1.0).abs() < 5e-4, "GIMP {gimp}");
}

/// theory §8.0's tie to the top point row is at least 1 % stiffer at h = 1/300 m.
#[test]
fn top_point_contact_stiffens_the_coarse_mesh() {
    let surface = first_step_stiffness(300, &BILINEAR);
    let mut overrides = BILINEAR.to_vec();
    overrides.push("bc.rigid.0.contact=top_points");
    let top_points = first_step_stiffness(300, &overrides);
    assert!(
        top_points > 1.01 * surface,
        "top points {top_points} vs surface {surface}"
    );
}

/// A surface contact point whose cell the soil has left bears on nothing:
/// it adds no penalty force, no stiffness and no share of the reported
/// rigid force, so the tangent stays the derivative of the residual (a
/// force without its stiffness made Newton diverge at δ = 0.28 m on the
/// footing at h = 0.1 m), and it moves with the footing, not with the soil
/// beside it. The footing scene at h = 0.5 m with the material of the first
/// tied point's cell removed: force, stiffness and reported load come from
/// the same points, the others.
#[test]
fn tied_points_over_emptied_cells_carry_neither_force_nor_stiffness() {
    use mpm_physics::bc::DrivenPoints;
    use mpm_physics::integrators::setup::StepSetup;
    let mut sim = common::simulation("footing/local_h250.toml", &["grid.cell_size=0.5"]);
    let model = &mut sim.model;
    let first = StepSetup::new(model).unwrap();
    let (ci, cj) = model.grid.cell_ij(first.driven_shapes[0].cell as usize);
    let (h, origin) = (model.grid.cell_size, model.grid.origin);
    let in_cell = |x: [f64; 2]| {
        ((x[0] - origin[0]) / h).floor() as usize == ci
            && ((x[1] - origin[1]) / h).floor() as usize == cj
    };
    let keep: Vec<bool> = model
        .state
        .particles
        .position
        .iter()
        .map(|&x| !in_cell(x))
        .collect();
    assert!(
        keep.iter().any(|k| !k),
        "no material in the first tied point's cell"
    );
    model.state.particles.retain(&keep);
    let setup = StepSetup::new(model).unwrap();
    let driven = &model.state.driven;
    let bears: Vec<bool> = setup
        .driven_shapes
        .iter()
        .map(|s| DrivenPoints::bears_on_soil(s, &setup.bins))
        .collect();
    assert!(
        !bears[0] && bears.iter().filter(|&&b| b).count() >= 2,
        "{bears:?}"
    );

    // the footing has moved 0.125 m down at t = 1 s: every gap is (0, −0.125)
    let (t, nodes) = (1.0, model.grid.node_count());
    let zero = vec![[0.0; 2]; nodes];
    let mut force = vec![[0.0; 2]; nodes];
    driven.add_forces(
        &model.state.particles,
        &setup.driven_shapes,
        &setup.bins,
        &zero,
        t,
        &mut force,
    );
    let expected: f64 = (0..driven.len())
        .filter(|&k| bears[k])
        .map(|k| {
            driven.stiffness[k]
                * driven.gap(k, &model.state.particles, &setup.driven_shapes[k], &zero, t)[1]
        })
        .sum();
    let total: f64 = force.iter().map(|f| f[1]).sum();
    assert!(
        (total / expected - 1.0).abs() < 1e-12,
        "force {total}, bearing points {expected}"
    );

    // Σ_ab k N_a N_b = k per direction and point
    let dofs = mpm_physics::stiffness::patch_dofs(&model.grid);
    let mut blocks = vec![0.0; setup.bins.active_cells.len() * dofs * dofs];
    driven.add_stiffness(&setup.driven_shapes, &setup.bins, dofs, &mut blocks);
    let stiffness: f64 = blocks.iter().sum();
    let bearing_k: f64 = (0..driven.len())
        .filter(|&k| bears[k])
        .map(|k| driven.stiffness[k])
        .sum();
    assert!(
        (stiffness / (2.0 * bearing_k) - 1.0).abs() < 1e-12,
        "{stiffness} against {bearing_k}"
    );

    // the reported force on the soil: the same points after the step's commit
    let mut moved = model.state.driven.clone();
    moved.advect(&setup.driven_shapes, &setup.bins, &zero, (t, t));
    let reported = moved.force_on_soil(0, &model.state.particles, t)[1];
    assert!(
        (reported / expected - 1.0).abs() < 1e-12,
        "reported {reported}, expected {expected}"
    );

    // over a step from t to t + 0.5 s in which the soil rises 0.05 m, the points over
    // soil rise with it and the one over the emptied cell moves with the footing
    // (the scene's 0.0125 m/s down): soil coming back under it is tied where the footing is
    let mut stepped = model.state.driven.clone();
    let rising = vec![[0.0, 0.05]; nodes];
    stepped.advect(&setup.driven_shapes, &setup.bins, &rising, (t, t + 0.5));
    for (k, &bears) in bears.iter().enumerate() {
        let moved = [
            stepped.position[k][0] - driven.position[k][0],
            stepped.position[k][1] - driven.position[k][1],
        ];
        let expected = if bears { 0.05 } else { -0.0125 * 0.5 };
        assert!(
            moved[0].abs() < 1e-12 && (moved[1] - expected).abs() < 1e-12,
            "point {k} (bears: {bears}) moved {moved:?}, expected (0, {expected})"
        );
    }
}

/// Load of the footing scene at h = 0.5 m, elastic (c = 1e6 kPa), after one
/// quasi-static step (0.0025 m/s × the scene's dt = 0.02 s: only ratios of
/// these loads are used), with footprint `[lo, hi]`, and the scene's warnings.
fn elastic_footing_load(lo: f64, hi: f64) -> (f64, Vec<String>) {
    let footprint = format!(
        r#"bc.rigid=[{{ name = "footing", footprint = [{lo}, {hi}], velocity = [0.0, -0.0025], contact = "surface" }}]"#
    );
    let overrides = [
        "grid.cell_size=0.5",
        "materials.soil.c_ini=1e6",
        "scene.analysis=quasi_static",
        "scene.steps=1",
        "output.snapshots=[]",
        footprint.as_str(),
    ];
    let mut sim = common::simulation("footing/local_h250.toml", &overrides);
    let warnings = sim.scene.warnings();
    let history = common::run_history(&mut sim);
    (history[1].1[common::column(&sim, "load")], warnings)
}

/// A footprint edge inside a cell: the surface tie holds every node of the
/// cells it touches, so the 1.5 m footing ([6.25, 7.75] m) at h = 0.5 m acts
/// nearly as the 2 m one ([6, 8] m, edges on grid lines; measured −0.4 %: the
/// outer nodes are held by one penalty point each, at weight 0.29), and the
/// scene says so; the 1 m footing of whole cells ([6.5, 7.5] m) is far softer
/// (measured −25 %).
#[test]
fn footprint_edges_inside_cells_widen_the_tie_to_whole_cells() {
    let (off_grid, warnings) = elastic_footing_load(6.25, 7.75);
    let (wide, wide_warnings) = elastic_footing_load(6.0, 8.0);
    let (narrow, _) = elastic_footing_load(6.5, 7.5);
    println!("loads: [6.25, 7.75] {off_grid:.2}, [6, 8] {wide:.2}, [6.5, 7.5] {narrow:.2} kN/m");
    assert!(
        (off_grid / wide - 1.0).abs() < 1e-2,
        "{off_grid} against {wide}"
    );
    assert!(narrow < 0.85 * wide, "{narrow} against {wide}");
    assert!(
        warnings
            .iter()
            .any(|w| w.starts_with("bc.rigid.0.footprint") && w.contains("[6.000000, 8.000000]")),
        "{warnings:?}"
    );
    assert!(
        !wide_warnings.iter().any(|w| w.contains("footprint")),
        "{wide_warnings:?}"
    );
}
