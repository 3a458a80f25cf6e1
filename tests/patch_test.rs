//! Patch test (theory §8.4): a homogeneous strain imposed through the boundary
//! nodes is reproduced at every material point, σ = D ε, to 1e−10 relative
//! (Newton tolerance 1e−13), for Gauss and for non-Gauss point layouts.

mod common;

use mpm_physics::constitutive::{mat4_mul_vec, LinearElastic};

fn check_patch(overrides: &[&str]) {
    let mut sim = common::simulation("elastic/patch.toml", overrides);
    sim.step_once().unwrap();
    // ε from the scene's gradients: u_x = 1e-3 x + 0.75e-3 y, u_y = 0.75e-3 x − 2e-3 y
    let strain = [1.0e-3, -2.0e-3, 0.0, 1.5e-3];
    let expected = mat4_mul_vec(&LinearElastic::new(20000.0, 0.2).stiffness(), &strain);
    let scale = expected.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    for (p, s) in sim.model.state.particles.stress.iter().enumerate() {
        for k in 0..4 {
            let err = (s[k] - expected[k]).abs() / scale;
            assert!(
                err <= 1e-10,
                "point {p} component {k}: {} vs {} (rel {err:e})",
                s[k],
                expected[k]
            );
        }
    }
}

#[test]
fn homogeneous_strain_is_reproduced_with_gauss_points() {
    check_patch(&[]);
}

#[test]
fn homogeneous_strain_is_reproduced_with_uniform_and_3x3_points() {
    check_patch(&["grid.point_layout=\"uniform\""]);
    check_patch(&["grid.points_per_cell=3"]);
}
