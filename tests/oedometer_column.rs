//! Oedometric column under self-weight (theory §8.4), quasi-static implicit.
//!
//! Exact answer (1D, confined, [`mpm_physics::closed_form::Column`]):
//! u_y(y) = −(ρg/M)(H y − y²/2), M = K + 4G/3, σyy(y) = −ρg(H − y). With
//! material points at the 2×2 Gauss positions the first step integrates
//! exactly like a Q4 FE mesh, whose nodal values are exact for this 1D
//! problem: tolerance 1e−6 relative (Newton tolerance 1e−10).
//! The points' σyy is the cell's constant value −ρg(H − y_mid), so within
//! ρgh/(2√3) of the exact profile (+1e−9 relative for round-off).

mod common;

const RHO: f64 = 2.0;
const G: f64 = 9.81;
const H: f64 = 1.0;

/// Largest nodal settlement error relative to the exact top settlement, and the
/// largest |σyy − exact| at the points, after the single gravity step.
fn column_errors(cell_size: f64, layout: &str, shift: [f64; 2]) -> (f64, f64) {
    let h = format!("grid.cell_size={cell_size}");
    let w = format!("grid.size=[{}, 1.0]", 2.0 * cell_size);
    let b = format!("body.0.box=[[0.0, 0.0], [{}, 1.0]]", 2.0 * cell_size);
    let r = format!("bc.fixed.1.line=\"x={}\"", 2.0 * cell_size);
    let l = format!("grid.point_layout=\"{layout}\"");
    let mut sim = common::simulation("elastic/oedometer.toml", &[&h, &w, &b, &r, &l]);
    for x in sim.model.state.particles.position.iter_mut() {
        x[0] += shift[0] * cell_size;
        x[1] += shift[1] * cell_size;
    }
    sim.step_once().unwrap();
    let column = common::elastic_column(&sim);
    let top = column.small_strain_displacement(H, G).abs();
    let mut nodal = 0.0f64;
    for (node, du) in sim.model.state.last_increment.iter().enumerate() {
        let y = sim.model.grid.node_position(node)[1];
        nodal = nodal.max((du[1] - column.small_strain_displacement(y, G)).abs() / top);
    }
    let mut stress = 0.0f64;
    for p in 0..sim.model.state.particles.len() {
        let y0 = sim.model.state.particles.position0[p][1] + shift[1] * cell_size;
        let exact = column.vertical_stress(y0, G);
        stress = stress.max((sim.model.state.particles.stress[p][1] - exact).abs());
    }
    (nodal, stress)
}

#[test]
fn gauss_points_give_exact_nodal_settlements_and_cell_stresses() {
    let h = 0.1;
    let (nodal, stress) = column_errors(h, "gauss", [0.0, 0.0]);
    assert!(
        nodal <= 1e-6,
        "nodal settlement error {nodal:e} (relative to the top settlement)"
    );
    let bound = RHO * G * h / (2.0 * 3f64.sqrt());
    assert!(
        stress <= bound * (1.0 + 1e-9),
        "stress error {stress} > ρgh/(2√3) = {bound}"
    );
}

#[test]
fn base_reaction_equals_the_weight() {
    let mut sim = common::simulation("elastic/oedometer.toml", &[]);
    sim.step_once().unwrap();
    let reaction = sim.monitor_values()[common::column(&sim, "base_reaction")];
    let weight = RHO * G * H * 0.2;
    assert!(
        (reaction - weight).abs() <= 1e-8 * weight,
        "reaction {reaction} vs weight {weight}"
    );
}

/// Points moved off the Gauss positions (each point shifted by (0.1 h, 0.2 h)
/// inside its cell, as after a drift): quadrature of stiffness and load is no
/// longer exact and the nodal settlements converge as the grid is refined. The
/// shift moves every cell's load and stiffness centroid by O(h) in the same
/// direction, so first-order convergence is expected: the observed rate is
/// printed and must be ≥ 0.9.
#[test]
fn points_off_gauss_positions_converge_under_refinement() {
    let sizes = [1.0 / 4.0, 1.0 / 8.0, 1.0 / 16.0, 1.0 / 32.0];
    let errors: Vec<f64> = sizes
        .iter()
        .map(|&h| column_errors(h, "gauss", [0.1, 0.2]).0)
        .collect();
    let rates: Vec<f64> = errors.windows(2).map(|e| (e[0] / e[1]).log2()).collect();
    println!("oedometer, uniform points: h = {sizes:?}\n  nodal errors {errors:?}\n  observed rates {rates:.3?}");
    assert!(
        errors.windows(2).all(|e| e[1] < e[0]),
        "errors must fall: {errors:?}"
    );
    let last = *rates.last().unwrap();
    assert!(last >= 0.9, "observed rate {last:.3} < 0.9");
}
