//! Seeding the material points of a scene's bodies (theory §2): positions,
//! volumes, masses, initial stresses and velocities.

use crate::grid::Grid;
use crate::particles::Particles;
use crate::scene::{BodySpec, FieldError, PointLayout, Scene, VelocityProfile};

/// Gauss–Legendre abscissae and weights on [−1, 1] for n = 1…4.
fn gauss_rule(n: usize) -> (Vec<f64>, Vec<f64>) {
    match n {
        1 => (vec![0.0], vec![2.0]),
        2 => {
            let a = 1.0 / 3f64.sqrt();
            (vec![-a, a], vec![1.0, 1.0])
        }
        3 => {
            let a = (0.6f64).sqrt();
            (vec![-a, 0.0, a], vec![5.0 / 9.0, 8.0 / 9.0, 5.0 / 9.0])
        }
        _ => {
            let (a, b) = (0.339_981_043_584_856_3, 0.861_136_311_594_052_6);
            let (wa, wb) = (0.652_145_154_862_546_1, 0.347_854_845_137_453_9);
            (vec![-b, -a, a, b], vec![wb, wa, wa, wb])
        }
    }
}

/// Fill every body with n×n points per grid cell (theory §2): Gauss–Legendre
/// positions with volumes h² w_i w_j / 4, or sub-cell centres with h²/n².
/// A position belongs to the first body whose outline contains it.
pub fn seed_particles(
    scene: &Scene,
    grid: &Grid,
    material_names: &[String],
    errors: &mut Vec<FieldError>,
) -> Particles {
    let mut particles = Particles::default();
    let n = scene.grid.points_per_cell;
    let h = grid.cell_size;
    let (abscissae, weights) = match scene.grid.point_layout {
        PointLayout::Gauss => gauss_rule(n),
        PointLayout::Uniform => (
            (0..n)
                .map(|k| -1.0 + (2 * k + 1) as f64 / n as f64)
                .collect(),
            vec![2.0 / n as f64; n],
        ),
    };
    let outlines: Vec<Vec<[f64; 2]>> = scene.body.iter().map(|b| b.outline()).collect();
    let mut counts = vec![0usize; scene.body.len()];
    for cj in 0..grid.cells[1] {
        for ci in 0..grid.cells[0] {
            let xc = grid.origin[0] + (ci as f64 + 0.5) * h;
            let yc = grid.origin[1] + (cj as f64 + 0.5) * h;
            for (&eta, &wy) in abscissae.iter().zip(&weights) {
                for (&xi, &wx) in abscissae.iter().zip(&weights) {
                    let x = [xc + 0.5 * h * xi, yc + 0.5 * h * eta];
                    let Some(b) = outlines
                        .iter()
                        .position(|o| crate::scene::polygon_contains(o, x))
                    else {
                        continue;
                    };
                    let body = &scene.body[b];
                    let material = material_names
                        .iter()
                        .position(|m| *m == body.material)
                        .unwrap_or(0);
                    let volume = 0.25 * h * h * wx * wy;
                    let density = scene.materials[&body.material].density();
                    let stress = initial_stress(body, x);
                    particles.push(
                        x,
                        density * volume,
                        volume,
                        stress,
                        material as u16,
                        b as u16,
                    );
                    let p = particles.len() - 1;
                    particles.velocity[p] = initial_velocity(body, x);
                    counts[b] += 1;
                }
            }
        }
    }
    for (b, &count) in counts.iter().enumerate() {
        if count == 0 {
            let key = if scene.body[b].rectangle.is_some() {
                "box"
            } else {
                "polygon"
            };
            errors.push(FieldError {
                field: format!("body[{b}].{key}"),
                message: "contains no material point position (is it smaller than a cell, or covered by an earlier body?)".into(),
            });
        }
    }
    particles
}

fn initial_stress(body: &BodySpec, x: [f64; 2]) -> [f64; 4] {
    let mut s = body.stress0.unwrap_or([0.0; 4]);
    if let Some(k0) = &body.k0 {
        let syy = -k0.unit_weight * (k0.surface_y - x[1]).max(0.0);
        s[0] += k0.k0 * syy;
        s[1] += syy;
        s[2] += k0.k0 * syy;
    }
    s
}

fn initial_velocity(body: &BodySpec, x: [f64; 2]) -> [f64; 2] {
    let v = body.velocity0.unwrap_or([0.0; 2]);
    match body.velocity_profile {
        VelocityProfile::Uniform => v,
        VelocityProfile::QuarterSineY => {
            let [lo, hi] = body.bounds();
            let factor = (std::f64::consts::FRAC_PI_2 * (x[1] - lo[1]) / (hi[1] - lo[1])).sin();
            [v[0] * factor, v[1] * factor]
        }
    }
}
