//! Explicit integrator (DESIGN §4): MUSL central difference, matrix-free,
//! with the same transfer kernels and stress-update stage as the implicit one.
//!
//! Per step: P2G of mass, momentum and forces → nodal momentum update with
//! Dirichlet conditions → G2P of velocity and position → re-map of the
//! particle momentum → strain increment from the re-mapped nodal velocity and
//! stress update → grid reset.

use super::{evaluate_stresses, NonlocalStep, TrialStresses};
use crate::bc::DofConstraint;
use crate::error::RunError;
use crate::integrators::implicit::update_kinematics;
use crate::profile::Stage;
use crate::scene::LostPointPolicy;
use crate::simulation::{Simulation, StepReport};
use crate::transfer::{self, ParticleBins};

impl Simulation {
    /// Stable time step Δt = α_CFL · min_p h / (c_p + |v_p|) (DESIGN D20), and the
    /// limit at α = 1. At nodes tied to driven points the penalty limit
    /// 2·sqrt(m_i/k_i) combines with it as 1/Δt² = 1/Δt_wave² + 1/Δt_pen².
    /// `with_velocity = false` gives the limit of the material at rest (the
    /// check before the run; the velocity term is checked every step).
    pub(crate) fn explicit_time_step(
        &self,
        nodal_mass: &[f64],
        driven_shapes: &[crate::grid::ShapeAt],
        with_velocity: bool,
    ) -> (f64, f64, String) {
        let p = &self.particles;
        let h = self.grid.cell_size;
        let mut limit = f64::INFINITY;
        let mut reason = String::from("wave speed, DESIGN D20");
        for i in 0..p.len() {
            let density = p.mass[i] / p.volume[i];
            let c = (self.materials[p.material[i] as usize].p_wave_modulus() / density).sqrt();
            let speed = if with_velocity {
                (p.velocity[i][0].powi(2) + p.velocity[i][1].powi(2)).sqrt()
            } else {
                0.0
            };
            limit = limit.min(h / (c + speed));
        }
        if !self.driven.is_empty() {
            let mut spring = vec![0.0; nodal_mass.len()];
            for (k, s) in driven_shapes.iter().enumerate() {
                for a in s.support() {
                    spring[s.nodes[a] as usize] += self.driven.stiffness[k] * s.n[a];
                }
            }
            // At a node tied by springs the material and spring frequencies add,
            // ω² ≤ ω_wave² + k_i/m_i (Gershgorin on M⁻¹(K + K_pen)), so the two
            // limits combine as 1/Δt² = 1/Δt_wave² + 1/Δt_pen². Local damping
            // (D21) raises the restoring force by up to (1 + α_d) in the half
            // cycle where it opposes the velocity, so the spring frequency is
            // taken as (1 + α_d) k_i/m_i (measured: without the factor, springs
            // with α_d = 0.7 were unstable from 0.6–0.8 of the estimate).
            let wave_limit = limit;
            let damping_factor = 1.0 + self.scene.solver.damping;
            for (node, &k) in spring.iter().enumerate() {
                if k > 0.0 && nodal_mass[node] > 0.0 {
                    let penalty_limit = 2.0 * (nodal_mass[node] / (damping_factor * k)).sqrt();
                    let combined = 1.0
                        / (1.0 / (wave_limit * wave_limit) + 1.0 / (penalty_limit * penalty_limit))
                            .sqrt();
                    if combined < limit {
                        limit = combined;
                        reason =
                            "wave speed and penalty springs of driven points, DESIGN §4".into();
                    }
                }
            }
        }
        (self.scene.solver.cfl * limit, limit, reason)
    }

    /// One MUSL step (DESIGN §4).
    pub(crate) fn explicit_step(&mut self) -> Result<StepReport, RunError> {
        let step = self.step + 1;
        let t = self.time;
        let grid = self.grid.clone();
        let n_nodes = grid.node_count();
        let setup = self.profile.time(Stage::Setup, || {
            let shapes = transfer::shapes_at(&grid, &self.particles.position).map_err(|o| {
                RunError::ParticleLeftGrid {
                    step,
                    time: t,
                    particle: o.particle,
                    position: o.position,
                }
            })?;
            let bins = ParticleBins::new(&grid, &shapes);
            let traction_shapes = self
                .traction
                .shapes(&grid, &bins, self.traction_min_points())
                .map_err(|o| RunError::BoundaryPointLeftGrid {
                    step,
                    time: t,
                    kind: "traction",
                    point: o.particle,
                    position: o.position,
                })?;
            let driven_shapes = self
                .driven
                .shapes(&grid, &bins, self.traction_min_points(), &shapes)
                .map_err(|o| RunError::BoundaryPointLeftGrid {
                    step,
                    time: t,
                    kind: "contact",
                    point: o.particle,
                    position: o.position,
                })?;
            Ok((shapes, bins, traction_shapes, driven_shapes))
        })?;
        let (shapes, bins, traction_shapes, driven_shapes) = setup;
        // Nonlocal weights from the start-of-step configuration; explicit runs
        // update κ̄ once per step (DESIGN §4, mode "step").
        let mut nonlocal = match &self.scene.nonlocal {
            Some(spec) => Some(NonlocalStep::new(spec, &self.particles, true).map_err(|e| {
                RunError::NonFinite {
                    step,
                    time: t,
                    what: format!("nonlocal weights: {e}"),
                }
            })?),
            None => None,
        };
        let p = &self.particles;

        // 1. P2G: mass, momentum, forces at t.
        let (mass, mut momentum, force) = self.profile.time(Stage::P2G, || {
            let mass = transfer::nodal_mass(&grid, &bins, &shapes, &p.mass);
            let momentum =
                transfer::nodal_mass_weighted(&grid, &bins, &shapes, &p.mass, &p.velocity);
            let internal = transfer::internal_force(&grid, &bins, &shapes, &p.volume, &p.stress);
            let g = self.scene.loads.gravity_at(t);
            let mut external = if g != 0.0 {
                transfer::body_force(&grid, &bins, &shapes, &p.mass, [0.0, -g])
            } else {
                vec![[0.0; 2]; n_nodes]
            };
            self.traction.add_forces(&traction_shapes, &mut external);
            self.driven.add_forces(
                p,
                &driven_shapes,
                &vec![[0.0; 2]; n_nodes],
                t,
                &mut external,
            );
            let force: Vec<[f64; 2]> = external
                .iter()
                .zip(&internal)
                .map(|(e, i)| [e[0] - i[0], e[1] - i[1]])
                .collect();
            (mass, momentum, force)
        });

        // Time step, checked every step as the points move.
        let (cfl_dt, limit, reason) = self.explicit_time_step(&mass, &driven_shapes, true);
        let dt = match self.scene.scene.dt {
            Some(fixed) if fixed > limit => {
                return Err(RunError::UnstableTimeStep {
                    step,
                    time: t,
                    dt: fixed,
                    limit,
                    reason,
                })
            }
            Some(fixed) => fixed,
            None => cfl_dt,
        };
        let usage = &mut self.solver_usage;
        usage.explicit_time_step = Some(match usage.explicit_time_step {
            Some((lo, hi)) => (lo.min(dt), hi.max(dt)),
            None => (dt, dt),
        });
        usage.time_step_limited_by = Some(reason);
        let end = self.scene.scene.end_time.unwrap_or(f64::INFINITY);
        let dt = dt.min(end - t).max(0.0);
        if dt <= 0.0 || !dt.is_finite() {
            return Err(RunError::NonFinite {
                step,
                time: t,
                what: format!("explicit time step {dt}"),
            });
        }

        // 2. Nodal update with damping (D21) and Dirichlet conditions.
        let max_mass = mass.iter().cloned().fold(0.0, f64::max);
        let tiny = 1e-12 * max_mass;
        let damping = self.scene.solver.damping;
        let mut rate = vec![[0.0; 2]; n_nodes]; // f_i / m_i, the nodal acceleration
        let mut reaction = vec![[0.0; 2]; n_nodes];
        for node in 0..n_nodes {
            if mass[node] <= tiny {
                momentum[node] = [0.0; 2];
                continue;
            }
            for c in 0..2 {
                let d = 2 * node + c;
                let v = momentum[node][c] / mass[node];
                let mut f = force[node][c];
                match self.constraints.dof[d] {
                    DofConstraint::Fixed => {
                        reaction[node][c] = -f;
                        momentum[node][c] = 0.0;
                        rate[node][c] = -v / dt;
                    }
                    DofConstraint::Prescribed { rate: r, gradient } => {
                        let x = grid.node_position(node);
                        let target = r + gradient[0] * x[0] + gradient[1] * x[1];
                        reaction[node][c] = -f;
                        rate[node][c] = (target - v) / dt;
                        momentum[node][c] = mass[node] * target;
                    }
                    DofConstraint::Free => {
                        if v != 0.0 {
                            f -= damping * f.abs() * v.signum();
                        }
                        momentum[node][c] += dt * f;
                        rate[node][c] = f / mass[node];
                    }
                }
            }
        }

        // 3. G2P: v_p += Δt Σ N a_i, x_p += Δt Σ N p_i/m_i.
        let velocity_nodes: Vec<[f64; 2]> = momentum
            .iter()
            .zip(&mass)
            .map(|(q, &m)| {
                if m > tiny {
                    [q[0] / m, q[1] / m]
                } else {
                    [0.0; 2]
                }
            })
            .collect();
        let start = std::time::Instant::now();
        {
            let p = &mut self.particles;
            for i in 0..p.len() {
                let a = transfer::interpolate(&shapes[i], &rate);
                let v = transfer::interpolate(&shapes[i], &velocity_nodes);
                p.velocity[i][0] += dt * a[0];
                p.velocity[i][1] += dt * a[1];
                p.acceleration[i] = a;
                p.position[i][0] += dt * v[0];
                p.position[i][1] += dt * v[1];
            }
        }
        self.profile.add(Stage::G2P, start.elapsed().as_secs_f64());

        // 4. Re-map the updated particle momentum (MUSL), Dirichlet again.
        let du: Vec<[f64; 2]> = self.profile.time(Stage::P2G, || {
            let p = &self.particles;
            let remapped =
                transfer::nodal_mass_weighted(&grid, &bins, &shapes, &p.mass, &p.velocity);
            (0..n_nodes)
                .map(|node| {
                    let mut u = [0.0; 2];
                    if mass[node] > tiny {
                        for (c, uc) in u.iter_mut().enumerate() {
                            *uc = match self.constraints.dof[2 * node + c] {
                                DofConstraint::Fixed => 0.0,
                                DofConstraint::Prescribed { .. } => dt * velocity_nodes[node][c],
                                DofConstraint::Free => dt * remapped[node][c] / mass[node],
                            };
                        }
                    }
                    u
                })
                .collect()
        });

        // 5. Strain increment and stress update; F, V (positions already moved).
        let mut trial = TrialStresses::default();
        self.profile
            .time(Stage::StressUpdate, || {
                evaluate_stresses(
                    &self.particles,
                    &self.materials,
                    &shapes,
                    &du,
                    nonlocal.as_ref().map(|n| n.strength()),
                    None,
                    &mut trial,
                )
            })
            .map_err(|(particle, source)| RunError::Constitutive {
                step,
                time: t + dt,
                particle,
                source,
            })?;
        let start = std::time::Instant::now();
        let (internal_work, dissipation) = self.step_energies(&trial);
        self.internal_work += internal_work;
        self.dissipated_energy += dissipation;
        let (stress, state) = self
            .finalize_stresses(&bins, &shapes, &trial, nonlocal.as_mut())
            .map_err(|e| RunError::NonFinite {
                step,
                time: t + dt,
                what: format!("nonlocal average: {e}"),
            })?;
        let stop = self.scene.grid.lost_points == LostPointPolicy::Stop;
        {
            let p = &mut self.particles;
            for i in 0..p.len() {
                update_kinematics(p, i, [0.0; 2], &trial.gradient[i]);
                p.stress[i] = stress[i];
                p.state[i] = state[i];
            }
            if stop {
                if let Some(i) = (0..p.len()).find(|&i| !grid.contains(p.position[i])) {
                    return Err(RunError::ParticleLeftGrid {
                        step,
                        time: t + dt,
                        particle: i,
                        position: p.position[i],
                    });
                }
            }
            if let Some(i) = (0..p.len()).find(|&i| p.stress[i].iter().any(|s| !s.is_finite())) {
                return Err(RunError::NonFinite {
                    step,
                    time: t + dt,
                    what: format!("stress of material point {i}"),
                });
            }
        }
        self.external_work += self.traction.advect(&traction_shapes, &du);
        // Surface contact points move with the nodal velocity that moved the
        // material points (step 3), not with the remapped increment `du`:
        // measured, following `du` they drift off the surface and the platen
        // load swings by ±8 %.
        if !self.driven.is_empty() {
            let motion: Vec<[f64; 2]> = velocity_nodes
                .iter()
                .map(|v| [dt * v[0], dt * v[1]])
                .collect();
            self.driven.advect(&driven_shapes, &motion);
        }
        self.profile.add(Stage::G2P, start.elapsed().as_secs_f64());
        self.reaction = reaction;
        self.last_increment = du;
        self.drop_lost_points()
            .map_err(|(particle, position)| RunError::ParticleLeftGrid {
                step,
                time: t + dt,
                particle,
                position,
            })?;
        self.step = step;
        self.time = t + dt;
        Ok(StepReport {
            step,
            time: self.time,
            dt,
            iterations: 0,
            substeps: 1,
        })
    }
}
