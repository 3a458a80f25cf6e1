//! The explicit stable time step (theory D20, §4), the one place it is
//! computed: before the run for a fixed `scene.dt`, and every step.

use rayon::prelude::*;

use crate::error::TimeStepLimit;
use crate::grid::ShapeAt;
use crate::model::Model;

/// The stability limit of the explicit step at α_CFL = 1, and what sets it.
#[derive(Clone, Copy, Debug)]
pub struct StableTimeStep {
    /// Largest stable Δt, s.
    pub limit: f64,
    /// What limits it.
    pub limited_by: TimeStepLimit,
}

impl StableTimeStep {
    /// Δt = min_p h / (c_p + |v_p|) (theory D20). At nodes tied to driven
    /// points the penalty limit 2·sqrt(m_i/((1 + α_d) k_i)) combines with it as
    /// 1/Δt² = 1/Δt_wave² + 1/Δt_pen². `moving = false` gives the limit of the
    /// material at rest (the check before the run; the velocity term is
    /// checked every step).
    pub fn of(model: &Model, nodal_mass: &[f64], driven_shapes: &[ShapeAt], moving: bool) -> Self {
        let wave = wave_limit(model, moving);
        let mut step = Self {
            limit: wave,
            limited_by: TimeStepLimit::WaveSpeed,
        };
        if model.state.driven.is_empty() {
            return step;
        }
        // At a node tied by springs the material and spring frequencies add,
        // ω² ≤ ω_wave² + k_i/m_i (Gershgorin on M⁻¹(K + K_pen)), so the two
        // limits combine as 1/Δt² = 1/Δt_wave² + 1/Δt_pen². Local damping
        // (D21) raises the restoring force by up to (1 + α_d) in the half
        // cycle where it opposes the velocity, so the spring frequency is
        // taken as (1 + α_d) k_i/m_i (measured: without the factor, springs
        // with α_d = 0.7 were unstable from 0.6–0.8 of the estimate).
        let damping_factor = 1.0 + model.settings.solver.damping;
        for (node, &k) in nodal_spring_stiffness(model, nodal_mass.len(), driven_shapes)
            .iter()
            .enumerate()
        {
            if k > 0.0 && nodal_mass[node] > 0.0 {
                let penalty = 2.0 * (nodal_mass[node] / (damping_factor * k)).sqrt();
                let combined = 1.0 / (1.0 / (wave * wave) + 1.0 / (penalty * penalty)).sqrt();
                if combined < step.limit {
                    step = Self {
                        limit: combined,
                        limited_by: TimeStepLimit::WaveSpeedAndSprings,
                    };
                }
            }
        }
        step
    }

    /// The step taken: α_CFL times the limit (theory D20).
    pub fn with_cfl(&self, cfl: f64) -> f64 {
        cfl * self.limit
    }
}

/// min_p h / (c_p + |v_p|), c_p = sqrt((K + 4G/3)/ρ_p), formed as
/// h / max_p (c_p + |v_p|): division by a positive number is monotone in
/// IEEE arithmetic, so this is the same value with one division instead of
/// one per point. In parallel over the points (a maximum: the same whatever
/// the order).
fn wave_limit(model: &Model, moving: bool) -> f64 {
    let p = &model.state.particles;
    let h = model.grid.cell_size;
    let moduli: Vec<f64> = model.materials.iter().map(|m| m.p_wave_modulus()).collect();
    let fastest = (0..p.len())
        .into_par_iter()
        .with_min_len(1024)
        .map(|i| {
            let density = p.mass[i] / p.volume[i];
            let c = (moduli[p.material[i] as usize] / density).sqrt();
            let speed = if moving {
                (p.velocity[i][0].powi(2) + p.velocity[i][1].powi(2)).sqrt()
            } else {
                0.0
            };
            c + speed
        })
        .reduce(|| 0.0, f64::max);
    // no points, or none with a speed: h / 0 = ∞, as the minimum over none was
    h / fastest
}

/// k_i = Σ_{p∈D} k_p N_ip at every node.
fn nodal_spring_stiffness(model: &Model, nodes: usize, driven_shapes: &[ShapeAt]) -> Vec<f64> {
    let mut spring = vec![0.0; nodes];
    for (k, s) in driven_shapes.iter().enumerate() {
        for a in s.support() {
            spring[s.nodes[a] as usize] += model.state.driven.stiffness[k] * s.n[a];
        }
    }
    spring
}
