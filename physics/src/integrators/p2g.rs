//! Particle-to-grid stage pieces both integrators use (theory D10–D11): the
//! external nodal forces, and the implicit dynamic step's nodal mass, momentum
//! and m a in one pass. The kernels themselves are in [`crate::transfer`].

use rayon::prelude::*;

use super::step_system::NodalKinematics;
use super::StepSetup;
use crate::grid::ShapeAt;
use crate::model::Model;
use crate::transfer::{self, NodalField, NODES_PER_TASK};

/// f_i^ext at time `t` into `external`: body force Σ_p N_ip m_p b(t) (when
/// gravity is on) plus the follower pressures of the traction points, per
/// grid node (theory D10). Without gravity the buffer is refilled in place.
pub fn external_force_into(model: &Model, setup: &StepSetup, t: f64, external: &mut Vec<[f64; 2]>) {
    let grid = &model.grid;
    let p = &model.state.particles;
    let g = model.settings.loads.gravity_at(t);
    if g != 0.0 {
        *external = transfer::body_force(grid, &setup.bins, &setup.shapes, &p.mass, [0.0, -g]);
    } else {
        external.clear();
        external.resize(grid.node_count(), [0.0; 2]);
    }
    model
        .state
        .traction
        .add_forces(&setup.traction_shapes, external);
}

/// Nodal sums of the implicit dynamic step's P2G pass, per node: m_i,
/// Σ N m v (x, y), Σ N m a (x, y), the body force's y component
/// Σ N m (−g) (its x component is zero) and Σ N m q (x, y) of the points'
/// force per mass (generalised-α).
type KinematicSums = [f64; 8];

/// Places of the quantities in [`KinematicSums`].
const MASS: usize = 0;
const MOMENTUM: usize = 1;
const MASS_ACCELERATION: usize = 3;
const BODY: usize = 5;
const FORCE_PER_MASS: usize = 6;

/// The buffers of [`nodal_kinematics`], kept from step to step.
#[derive(Default)]
pub struct KinematicsBuffers {
    /// Patch sums of the active cells.
    cells: Vec<KinematicSums>,
    /// The nodal sums.
    sums: NodalField<KinematicSums>,
}

/// The nodal mass, velocity, acceleration and external force at time `t` of
/// an implicit dynamic step, per grid node (zero at the nodes no point
/// reaches), the point sums in one pass: the same values, bit for bit, as
/// [`transfer::nodal_mass`], [`transfer::nodal_mass_weighted`] of v and a
/// divided by the mass, and [`external_force_into`]; with `carry_force` also the
/// points' force per mass q, mass-weighted (generalised-α). Refills `nodal`
/// in place.
pub fn nodal_kinematics(
    model: &Model,
    setup: &StepSetup,
    t: f64,
    carry_force: bool,
    buffers: &mut KinematicsBuffers,
    nodal: &mut NodalKinematics,
) {
    let p = &model.state.particles;
    let g = model.settings.loads.gravity_at(t);
    let (mass, velocity, acceleration) = (&p.mass, &p.velocity, &p.acceleration);
    let force_per_mass = &p.force_per_mass;
    let add = |p: usize, s: &ShapeAt, patch: &mut [KinematicSums]| {
        let (m, v, a) = (mass[p], velocity[p], acceleration[p]);
        for node in s.support() {
            let nm = s.n[node] * m;
            let sum = &mut patch[s.local[node] as usize];
            sum[MASS] += nm;
            sum[MOMENTUM] += nm * v[0];
            sum[MOMENTUM + 1] += nm * v[1];
            sum[MASS_ACCELERATION] += nm * a[0];
            sum[MASS_ACCELERATION + 1] += nm * a[1];
            sum[BODY] += nm * -g;
            if carry_force {
                let q = force_per_mass[p];
                sum[FORCE_PER_MASS] += nm * q[0];
                sum[FORCE_PER_MASS + 1] += nm * q[1];
            }
        }
    };
    let KinematicsBuffers { cells, sums } = buffers;
    transfer::scatter_into_field(&model.grid, &setup.bins, &setup.shapes, add, cells, sums);
    let per_node = |f: fn(&KinematicSums) -> [f64; 2], out: &mut Vec<[f64; 2]>| {
        sums.par_iter()
            .with_min_len(NODES_PER_TASK)
            .map(f)
            .collect_into_vec(out)
    };
    if g != 0.0 {
        per_node(|s| [0.0, s[BODY]], &mut nodal.external);
    } else {
        nodal.external.clear();
        nodal.external.resize(sums.len(), [0.0; 2]);
    }
    model
        .state
        .traction
        .add_forces(&setup.traction_shapes, &mut nodal.external);
    sums.par_iter()
        .with_min_len(NODES_PER_TASK)
        .map(|s| s[MASS])
        .collect_into_vec(&mut nodal.mass);
    per_node(|s| per_mass(s, MOMENTUM), &mut nodal.velocity);
    per_node(|s| per_mass(s, MASS_ACCELERATION), &mut nodal.acceleration);
    if carry_force {
        per_node(|s| per_mass(s, FORCE_PER_MASS), &mut nodal.force_per_mass);
    } else {
        nodal.force_per_mass.clear();
    }
    nodal.removed_velocity.clear();
    nodal.removed_energy = 0.0;
}

fn per_mass(sums: &KinematicSums, place: usize) -> [f64; 2] {
    let m = sums[MASS];
    if m > 0.0 {
        [sums[place] / m, sums[place + 1] / m]
    } else {
        [0.0; 2]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Scene;

    const BIAXIAL: &str = include_str!("../../../validation/biaxial/local_h300.toml");

    /// The biaxial specimen (follower pressures on two sides) under gravity,
    /// its points given velocities and accelerations that vary from point to
    /// point, with the scene's GIMP or with bilinear shape functions.
    fn moving_specimen(bilinear: bool) -> (Model, StepSetup) {
        let mut overrides = vec!["loads.gravity=9.81".to_string()];
        if bilinear {
            overrides.push("grid.shape_functions=\"bilinear\"".into());
            overrides.push("grid.point_layout=\"gauss\"".into());
        }
        let scene = Scene::from_str_with_overrides(BIAXIAL, "biaxial", &overrides).unwrap();
        let mut model = Model::new(&scene).unwrap();
        let p = &mut model.state.particles;
        for i in 0..p.mass.len() {
            let s = (i as f64 * 0.37).sin();
            p.velocity[i] = [0.1 * s, -0.03 + 0.2 * s * s];
            p.acceleration[i] = [2.0 * (i as f64 * 1.3).cos(), -9.81 * s];
        }
        let setup = StepSetup::new(&model).unwrap();
        (model, setup)
    }

    /// The one-pass P2G of the implicit dynamic step gives, bit for bit, the
    /// nodal mass, the mass-weighted sums of v and a divided by it, and the
    /// external force of the separate kernels, for both kinds of shape
    /// functions, in two calls of which the second reuses the buffers.
    #[test]
    fn one_pass_equals_the_separate_kernels() {
        for bilinear in [false, true] {
            let (model, setup) = moving_specimen(bilinear);
            let (grid, bins, shapes) = (&model.grid, &setup.bins, &setup.shapes);
            let p = &model.state.particles;
            let mass = transfer::nodal_mass(grid, bins, shapes, &p.mass);
            let per_mass = |q: &[[f64; 2]]| -> Vec<[f64; 2]> {
                let weighted = transfer::nodal_mass_weighted(grid, bins, shapes, &p.mass, q);
                weighted
                    .iter()
                    .zip(&mass)
                    .map(|(w, &m)| {
                        if m > 0.0 {
                            [w[0] / m, w[1] / m]
                        } else {
                            [0.0; 2]
                        }
                    })
                    .collect()
            };
            let (velocity, acceleration) = (per_mass(&p.velocity), per_mass(&p.acceleration));
            assert!(mass.iter().filter(|&&m| m > 0.0).count() > 100);
            let mut buffers = KinematicsBuffers::default();
            // the second time refills the buffers of the first
            let (mut one_pass, mut external) = (NodalKinematics::default(), Vec::new());
            for t in [0.001, 0.002] {
                external_force_into(&model, &setup, t, &mut external);
                assert!(external.iter().any(|f| f[0] != 0.0), "pressures act");
                nodal_kinematics(&model, &setup, t, false, &mut buffers, &mut one_pass);
                assert_eq!(one_pass.mass, mass);
                assert_eq!(one_pass.velocity, velocity);
                assert_eq!(one_pass.acceleration, acceleration);
                assert_eq!(one_pass.external, external);
            }
        }
    }
}
