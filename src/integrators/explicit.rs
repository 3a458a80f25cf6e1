//! Explicit integrator (DESIGN §4): MUSL central difference, matrix-free,
//! with the same transfer kernels and stages as the implicit one.

use super::commit::{commit, NodalResults};
use super::g2p::{g2p, GridMotion, VelocityUpdate};
use super::p2g::external_force;
use super::stresses::converged_stresses;
use super::time_step::StableTimeStep;
use super::{evaluate_stresses, NonlocalStep, SolverUsage, StepReport, StepSetup, TrialStresses};
use crate::bc::DofConstraint;
use crate::error::StepError;
use crate::model::Model;
use crate::profile::{Profile, Stage, Work};
use crate::scene::{FieldError, SceneError};
use crate::transfer;

/// The explicit MUSL integrator and its time-step statistics.
#[derive(Default)]
pub struct ExplicitIntegrator {
    /// Time steps taken and what limited them.
    pub usage: SolverUsage,
}

/// P2G of a step: nodal mass, momentum and total force at t (DESIGN §4 step 1).
struct NodalMomentum {
    mass: Vec<f64>,
    momentum: Vec<[f64; 2]>,
    force: Vec<[f64; 2]>,
}

/// The grid after the momentum update (DESIGN §4 step 2).
struct UpdatedGrid {
    /// Nodal mass m_i.
    mass: Vec<f64>,
    /// Nodal acceleration f_i / m_i (with Dirichlet conditions).
    acceleration: Vec<[f64; 2]>,
    /// Nodal velocity p_i / m_i after the update.
    velocity: Vec<[f64; 2]>,
    /// Support reactions at constrained dofs.
    reaction: Vec<[f64; 2]>,
    /// Nodes at or below this mass carry nothing (1e−12 of the largest).
    tiny_mass: f64,
}

impl ExplicitIntegrator {
    /// The integrator for `model`. A fixed `scene.dt` above the stability
    /// limit of the material at rest in its initial configuration is refused
    /// before the run; the velocity term and later drops are checked every step.
    pub fn new(model: &Model) -> Result<Self, SceneError> {
        if let Some(dt) = model.scene.scene.dt {
            let Ok(setup) = StepSetup::new(model) else {
                return Ok(Self::default()); // points outside the grid are reported by the validation
            };
            let mass = nodal_mass(model, &setup);
            let stable = StableTimeStep::of(model, &mass, &setup.driven_shapes, false);
            if dt > stable.limit {
                return Err(SceneError::Invalid {
                    path: model.scene.scene.name.clone(),
                    errors: vec![FieldError {
                        field: "scene.dt".into(),
                        message: format!(
                            "{dt} s exceeds the explicit stability limit {:.4e} s of the initial configuration ({})",
                            stable.limit, stable.limited_by
                        ),
                    }],
                });
            }
        }
        Ok(Self::default())
    }

    /// One MUSL step (DESIGN §4), in the order of paper Fig. 1.
    pub fn step(&mut self, model: &mut Model, profile: &Profile) -> Result<StepReport, StepError> {
        let t = model.time;
        let setup = profile.time(Stage::Setup, || StepSetup::new(model))?;
        let mut nonlocal = NonlocalStep::start(model, true, profile)?;
        let nodal = profile.time(Stage::P2G, || map_to_grid(model, &setup, t, profile));
        let (dt, grid) = profile.time(Stage::TimeStep, || {
            let dt = self.time_step(model, &setup, &nodal)?;
            Ok::<_, StepError>((dt, update_momentum(model, nodal, dt)))
        })?;
        let motion = grid.motion(dt);
        profile.time(Stage::G2P, || {
            g2p(&mut model.particles, &setup.shapes, &motion)
        });
        let du = profile.time(Stage::Remap, || remap(model, &setup, &grid, dt));
        let trial = profile.time(Stage::StressUpdate, || {
            stress_update(model, &setup, &du, nonlocal.as_ref(), profile)
        })?;
        let converged = profile.time(Stage::Stresses, || {
            converged_stresses(model, &setup, &trial, nonlocal.as_mut(), profile)
        })?;
        let removed = profile.time(Stage::Commit, || {
            let contact_motion = contact_motion(model, &grid, dt);
            let nodal = NodalResults {
                reaction: &grid.reaction,
                increment: &du,
                contact_motion: &contact_motion,
            };
            commit(model, &setup, &trial, converged, nodal)
        })?;
        model.step += 1;
        model.time = t + dt;
        Ok(StepReport {
            step: model.step,
            time: model.time,
            dt,
            iterations: 0,
            substeps: 1,
            removed_points: removed.into_iter().collect(),
        })
    }

    /// Δt of the step: α_CFL times the stable limit (DESIGN D20), or the
    /// scene's fixed `dt` if it is still below the limit; the last step ends
    /// at `end_time`.
    fn time_step(
        &mut self,
        model: &Model,
        setup: &StepSetup,
        nodal: &NodalMomentum,
    ) -> Result<f64, StepError> {
        let stable = StableTimeStep::of(model, &nodal.mass, &setup.driven_shapes, true);
        let dt = match model.scene.scene.dt {
            Some(fixed) if fixed > stable.limit => {
                return Err(StepError::UnstableTimeStep {
                    dt: fixed,
                    limit: stable.limit,
                    limited_by: stable.limited_by,
                })
            }
            Some(fixed) => fixed,
            None => stable.with_cfl(model.scene.solver.cfl),
        };
        let usage = &mut self.usage;
        usage.explicit_time_step = Some(match usage.explicit_time_step {
            Some((lo, hi)) => (lo.min(dt), hi.max(dt)),
            None => (dt, dt),
        });
        usage.time_step_limited_by = Some(stable.limited_by);
        let end = model.scene.scene.end_time.unwrap_or(f64::INFINITY);
        let dt = dt.min(end - model.time).max(0.0);
        if dt <= 0.0 || !dt.is_finite() {
            return Err(StepError::InvalidTimeStep { dt });
        }
        Ok(dt)
    }
}

impl UpdatedGrid {
    /// G2P of the updated grid (DESIGN §4 step 3): v_p += Δt Σ N a_i,
    /// x_p += Δt Σ N p_i/m_i.
    fn motion(&self, dt: f64) -> GridMotion<'_> {
        GridMotion {
            dt,
            displacement: &self.velocity,
            scale: dt,
            acceleration: Some((&self.acceleration, VelocityUpdate::Forward)),
        }
    }
}

fn nodal_mass(model: &Model, setup: &StepSetup) -> Vec<f64> {
    transfer::nodal_mass(
        &model.grid,
        &setup.bins,
        &setup.shapes,
        &model.particles.mass,
    )
}

/// P2G: m_i, p_i = Σ N_ip m_p v_p, f_i = f_ext + f_pen − f_int at t (the
/// nodal mass counted in `profile`).
fn map_to_grid(model: &Model, setup: &StepSetup, t: f64, profile: &Profile) -> NodalMomentum {
    let (grid, p) = (&model.grid, &model.particles);
    let (bins, shapes) = (&setup.bins, &setup.shapes);
    let mass = nodal_mass(model, setup);
    profile.count(Work::ExplicitNodalMass, 1);
    let momentum = transfer::nodal_mass_weighted(grid, bins, shapes, &p.mass, &p.velocity);
    let stress = model.force_stresses(bins, &p.stress);
    let internal = transfer::internal_force(grid, bins, shapes, &p.volume, &stress);
    let mut external = external_force(model, setup, t);
    let no_increment = vec![[0.0; 2]; grid.node_count()];
    model
        .driven
        .add_forces(p, &setup.driven_shapes, &no_increment, t, &mut external);
    let force = external
        .iter()
        .zip(&internal)
        .map(|(e, i)| [e[0] - i[0], e[1] - i[1]])
        .collect();
    NodalMomentum {
        mass,
        momentum,
        force,
    }
}

/// p_i ← p_i + Δt f_i with local damping (D21) and Dirichlet conditions.
fn update_momentum(model: &Model, nodal: NodalMomentum, dt: f64) -> UpdatedGrid {
    let NodalMomentum {
        mass,
        mut momentum,
        force,
    } = nodal;
    let n_nodes = mass.len();
    let tiny_mass = 1e-12 * mass.iter().cloned().fold(0.0, f64::max);
    let damping = model.scene.solver.damping;
    let mut acceleration = vec![[0.0; 2]; n_nodes];
    let mut reaction = vec![[0.0; 2]; n_nodes];
    for node in 0..n_nodes {
        if mass[node] <= tiny_mass {
            momentum[node] = [0.0; 2];
            continue;
        }
        for c in 0..2 {
            let v = momentum[node][c] / mass[node];
            let mut f = force[node][c];
            match model.constraints.dof[2 * node + c] {
                DofConstraint::Fixed => {
                    reaction[node][c] = -f;
                    momentum[node][c] = 0.0;
                    acceleration[node][c] = -v / dt;
                }
                DofConstraint::Prescribed { rate, gradient } => {
                    let x = model.grid.node_position(node);
                    let target = rate + gradient[0] * x[0] + gradient[1] * x[1];
                    reaction[node][c] = -f;
                    acceleration[node][c] = (target - v) / dt;
                    momentum[node][c] = mass[node] * target;
                }
                DofConstraint::Free => {
                    if v != 0.0 {
                        f -= damping * f.abs() * v.signum();
                    }
                    momentum[node][c] += dt * f;
                    acceleration[node][c] = f / mass[node];
                }
            }
        }
    }
    let velocity = momentum
        .iter()
        .zip(&mass)
        .map(|(q, &m)| {
            if m > tiny_mass {
                [q[0] / m, q[1] / m]
            } else {
                [0.0; 2]
            }
        })
        .collect();
    UpdatedGrid {
        mass,
        acceleration,
        velocity,
        reaction,
        tiny_mass,
    }
}

/// MUSL re-map (DESIGN §4 step 4): p_i = Σ_p N_ip m_p v_p of the updated
/// point velocities, Dirichlet again; returns Δu_i = Δt p_i / m_i.
fn remap(model: &Model, setup: &StepSetup, grid: &UpdatedGrid, dt: f64) -> Vec<[f64; 2]> {
    let p = &model.particles;
    let mass = &grid.mass;
    let remapped = transfer::nodal_mass_weighted(
        &model.grid,
        &setup.bins,
        &setup.shapes,
        &p.mass,
        &p.velocity,
    );
    (0..mass.len())
        .map(|node| {
            let mut u = [0.0; 2];
            if mass[node] > grid.tiny_mass {
                for (c, uc) in u.iter_mut().enumerate() {
                    *uc = match model.constraints.dof[2 * node + c] {
                        DofConstraint::Fixed => 0.0,
                        DofConstraint::Prescribed { .. } => dt * grid.velocity[node][c],
                        DofConstraint::Free => dt * remapped[node][c] / mass[node],
                    };
                }
            }
            u
        })
        .collect()
}

/// Δε from the re-mapped increment and the stress update (DESIGN §4 step 5),
/// strengths at κ̄(n); the updates are counted in `profile`.
fn stress_update(
    model: &Model,
    setup: &StepSetup,
    du: &[[f64; 2]],
    nonlocal: Option<&NonlocalStep>,
    profile: &Profile,
) -> Result<TrialStresses, StepError> {
    let mut trial = TrialStresses::default();
    evaluate_stresses(
        model,
        setup,
        du,
        nonlocal.map(|n| n.strength()),
        false,
        &mut trial,
    )
    .counted(profile)
    .map_err(|(particle, source)| StepError::Constitutive { particle, source })?;
    Ok(trial)
}

/// Surface contact points move with the nodal velocity that moved the
/// material points (G2P), not with the re-mapped increment: measured,
/// following the re-mapped increment they drift off the surface and the
/// platen load swings by ±8 %.
fn contact_motion(model: &Model, grid: &UpdatedGrid, dt: f64) -> Vec<[f64; 2]> {
    if model.driven.is_empty() {
        return Vec::new();
    }
    grid.velocity
        .iter()
        .map(|v| [dt * v[0], dt * v[1]])
        .collect()
}
