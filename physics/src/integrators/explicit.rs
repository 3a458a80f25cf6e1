//! Explicit integrator (theory §4): MUSL central difference, matrix-free,
//! with the same transfer kernels and stages as the implicit one.
//!
//! The integrator owns every buffer of its step (its workspace): shape
//! functions and bins, nodal fields, per-point increments and trial
//! stresses are refilled in place each step, so that a step allocates
//! nothing once the buffers have grown to the run's size (the kernel would
//! otherwise map fresh pages for them every step). With bilinear shape
//! functions and neither rigid bodies nor double mapping, the points' shape
//! functions are kept in compact form ([`crate::grid::BilinearShape`]), which
//! the stages stream several times a step. The P2G sums of a step (mass,
//! momentum, internal and body forces) are formed in one pass over the
//! points; the node passes visit the active nodes only
//! ([`crate::transfer::NodalField`]: a grid much larger than the body costs
//! nothing); and each stage runs in parallel over points or nodes with its
//! sums in the fixed order of [`crate::transfer`]: the results do not depend
//! on the number of threads, and are those of the full shape functions.

use rayon::prelude::*;

use super::boundary_work::fixed_dof_kinetic_energy;
use super::commit::{commit_swapping, NodalResults};
use super::converged_stresses::{converged_stresses_taking, ConvergedStresses};
use super::g2p::{g2p, GridMotion, VelocityUpdate};
use super::time_step::StableTimeStep;
use super::{
    evaluate_stresses_without_tangent, NonlocalStep, SolverUsage, StepReport, StepSetup,
    TrialStresses,
};
use crate::bc::DofConstraint;
use crate::error::StepError;
use crate::grid::{BilinearShape, Support};
use crate::model::{Model, PointRemap};
use crate::profile::{Profile, Stage, Work};
use crate::scene::{FieldError, SceneError};
use crate::transfer::{self, refill_fields, NodalField};

/// The explicit MUSL integrator and its time-step statistics.
#[derive(Default)]
pub struct ExplicitIntegrator {
    /// Time steps taken and what limited them.
    pub usage: SolverUsage,
    /// The step's buffers, reused from step to step (boxed: they are many).
    work: Box<Workspace>,
}

/// Nodal sums of the step's one P2G pass, per node (theory §4 step 1):
/// m_i, p_i = Σ N m v (x, y), f_i^int (x, y) and the body force's y
/// component Σ N m (−g) (its x component is zero).
type P2gSums = [f64; 6];

/// Places of the quantities in [`P2gSums`].
const MASS: usize = 0;
const MOMENTUM: usize = 1;
const INTERNAL: usize = 3;
const BODY: usize = 5;

/// Every buffer of the explicit step, owned by the integrator.
#[derive(Default)]
struct Workspace {
    /// Shape functions and bins of the step.
    setup: StepSetup,
    /// Whether the points' shape functions are kept in compact form,
    /// decided once when the integrator is built
    /// ([`StepSetup::compact_applies`]: bilinear shapes, no rigid body, no
    /// double mapping; none of these changes during a run).
    compact_form: bool,
    /// The points' shape functions in compact form, when `compact_form`
    /// (`setup.shapes` is then empty).
    compact: Vec<BilinearShape>,
    /// The nodal and per-point arrays of the step.
    buffers: Buffers,
}

/// The nodal and per-point arrays of the explicit step.
#[derive(Default)]
struct Buffers {
    /// Patch sums of the active cells, P2G pass.
    p2g_cells: Vec<P2gSums>,
    /// Nodal sums of the P2G pass.
    p2g: NodalField<P2gSums>,
    /// The grid after the momentum update.
    grid: UpdatedGrid,
    /// f_ext per node (body force, follower pressures, penalty springs).
    external: Vec<[f64; 2]>,
    /// Zero per node: the penalty springs' increment in an explicit step.
    zero: Vec<[f64; 2]>,
    /// Patch sums of the active cells, re-map pass.
    remap_cells: Vec<[f64; 2]>,
    /// Σ_p N_ip m_p v_p of the updated point velocities (MUSL re-map).
    remapped: NodalField<[f64; 2]>,
    /// Δu_i of the step.
    increment: NodalField<[f64; 2]>,
    /// Δt v_i at the nodes: moves the rigid bodies' surface points.
    contact_motion: Vec<[f64; 2]>,
    /// Trial stresses of the step.
    trial: TrialStresses,
    /// Converged stresses of the step; after the commit, the arrays of the
    /// step before.
    converged: ConvergedStresses,
}

/// The grid of a step: P2G results, then their momentum update (theory §4
/// steps 1–2). Every field is zero at the nodes no point reaches, and the
/// passes visit the active nodes only ([`NodalField`]).
#[derive(Default)]
struct UpdatedGrid {
    /// Nodal mass m_i.
    mass: NodalField<f64>,
    /// Nodal momentum p_i at t.
    momentum: NodalField<[f64; 2]>,
    /// Total nodal force f_ext + f_pen − f_int at t.
    force: NodalField<[f64; 2]>,
    /// Nodal acceleration f_i / m_i (with Dirichlet conditions).
    acceleration: NodalField<[f64; 2]>,
    /// Nodal velocity (p_i + Δt f_i) / m_i after the update.
    velocity: NodalField<[f64; 2]>,
    /// Support reactions at constrained dofs.
    reaction: NodalField<[f64; 2]>,
    /// Per active node, p_i and f_i while they are refilled.
    staging_p2g: Vec<[[f64; 2]; 2]>,
    /// Per active node, a_i, v_i and the reaction while they are refilled.
    staging_update: Vec<[[f64; 2]; 3]>,
    /// Nodes at or below this mass carry nothing (1e−12 of the largest).
    tiny_mass: f64,
}

impl ExplicitIntegrator {
    /// The integrator for `model`. A fixed `scene.dt` above the stability
    /// limit of the material at rest in its initial configuration is refused
    /// before the run; the velocity term and later drops are checked every step.
    pub fn new(model: &Model) -> Result<Self, SceneError> {
        let mut integrator = Self::default();
        integrator.work.compact_form = StepSetup::compact_applies(model);
        if let Some(dt) = model.settings.run.dt {
            let Ok(setup) = StepSetup::new(model) else {
                return Ok(integrator); // points outside the grid are reported by the validation
            };
            let mass = transfer::nodal_mass(
                &model.grid,
                &setup.bins,
                &setup.shapes,
                &model.state.particles.mass,
            );
            let stable = StableTimeStep::of(model, &mass, &setup.driven_shapes, false);
            if dt > stable.limit {
                return Err(SceneError::Invalid {
                    path: model.settings.run.name.clone(),
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
        Ok(integrator)
    }

    /// One MUSL step (theory §4), in the order of paper Fig. 1.
    pub fn step(&mut self, model: &mut Model, profile: &Profile) -> Result<StepReport, StepError> {
        let t = model.state.time;
        let work = &mut *self.work;
        let compact = profile.time(Stage::Setup, || work.refresh(model))?;
        let Workspace {
            setup,
            compact: compact_shapes,
            buffers,
            ..
        } = work;
        let usage = &mut self.usage;
        let (dt, removed) = if compact {
            buffers.advance(model, setup, compact_shapes.as_slice(), usage, profile)
        } else {
            buffers.advance(model, setup, &setup.shapes, usage, profile)
        }?;
        model.state.step += 1;
        model.state.time = t + dt;
        Ok(StepReport {
            step: model.state.step,
            time: model.state.time,
            dt,
            iterations: 0,
            substeps: 1,
            removed_points: removed.into_iter().collect(),
            ..Default::default()
        })
    }
}

impl Workspace {
    /// The step's shape functions and bins at the start-of-step positions;
    /// returns whether the points' shapes are the compact ones.
    fn refresh(&mut self, model: &Model) -> Result<bool, StepError> {
        if self.compact_form {
            self.setup.refresh_compact(model, &mut self.compact)?;
        } else {
            self.setup.refresh(model)?;
        }
        Ok(self.compact_form)
    }
}

impl Buffers {
    /// The stages of the step after the setup (points' shape functions
    /// `shapes`): P2G, time step and momentum update, G2P, re-map, stress
    /// update, stresses, commit. Returns Δt and the index remap of the
    /// points removed.
    fn advance<S: Support>(
        &mut self,
        model: &mut Model,
        setup: &StepSetup,
        shapes: &[S],
        usage: &mut SolverUsage,
        profile: &Profile,
    ) -> Result<(f64, Option<PointRemap>), StepError> {
        let t = model.state.time;
        let mut nonlocal = NonlocalStep::start(model, true, profile)?;
        profile.time(Stage::P2G, || {
            self.map_to_grid(model, setup, shapes, t, profile)
        });
        let (dt, boundary_work) = profile.time(Stage::TimeStep, || {
            let dt = time_step(usage, model, setup, &self.grid.mass)?;
            self.grid
                .update_momentum(model, &setup.bins.active_nodes, dt);
            let removed = self
                .grid
                .fixed_dof_kinetic_energy(model, &setup.bins.active_nodes, dt);
            Ok::<_, StepError>((dt, removed))
        })?;
        profile.time(Stage::G2P, || {
            g2p(&mut model.state.particles, shapes, &self.grid.motion(dt))
        });
        profile.time(Stage::Remap, || self.remap(model, setup, shapes, dt));
        profile.time(Stage::StressUpdate, || {
            self.stress_update(model, setup, shapes, nonlocal.as_ref(), profile)
        })?;
        let Buffers {
            grid,
            increment,
            contact_motion,
            trial,
            converged,
            ..
        } = self;
        profile.time(Stage::Stresses, || {
            converged_stresses_taking(model, setup, trial, nonlocal.as_mut(), profile, converged)
        })?;
        let removed = profile.time(Stage::Commit, || {
            grid.contact_motion(model, dt, contact_motion);
            let nodal = NodalResults {
                reaction: &grid.reaction,
                increment,
                contact_motion,
                gravity: model.settings.loads.gravity_at(t),
                end_time: t + dt,
                nonzero_at: Some(&setup.bins.active_nodes),
                boundary_work,
            };
            commit_swapping(model, setup, trial, converged, nodal)
        })?;
        Ok((dt, removed))
    }
}

/// Δt of the step: α_CFL times the stable limit (theory D20), or the
/// scene's fixed `dt` if it is still below the limit; the last step ends
/// at `end_time`. Recorded in `usage`.
fn time_step(
    usage: &mut SolverUsage,
    model: &Model,
    setup: &StepSetup,
    nodal_mass: &[f64],
) -> Result<f64, StepError> {
    let stable = StableTimeStep::of(model, nodal_mass, &setup.driven_shapes, true);
    let dt = match model.settings.run.dt {
        Some(fixed) if fixed > stable.limit => {
            return Err(StepError::UnstableTimeStep {
                dt: fixed,
                limit: stable.limit,
                limited_by: stable.limited_by,
            })
        }
        Some(fixed) => fixed,
        None => stable.with_cfl(model.settings.solver.cfl),
    };
    usage.explicit_time_step = Some(match usage.explicit_time_step {
        Some((lo, hi)) => (lo.min(dt), hi.max(dt)),
        None => (dt, dt),
    });
    usage.time_step_limited_by = Some(stable.limited_by);
    let end = model.settings.run.end_time.unwrap_or(f64::INFINITY);
    let dt = dt.min(end - model.state.time).max(0.0);
    if dt <= 0.0 || !dt.is_finite() {
        return Err(StepError::InvalidTimeStep { dt });
    }
    Ok(dt)
}

impl Buffers {
    /// P2G: m_i, p_i = Σ N_ip m_p v_p, f_i = f_ext + f_pen − f_int at t
    /// (theory D10–D11), the point sums in one pass; the nodal mass is
    /// counted in `profile`.
    fn map_to_grid<S: Support>(
        &mut self,
        model: &Model,
        setup: &StepSetup,
        shapes: &[S],
        t: f64,
        profile: &Profile,
    ) {
        let p = &model.state.particles;
        let stress = model.force_stresses(&setup.bins, &p.stress);
        let g = model.settings.loads.gravity_at(t);
        let (mass, velocity, volume) = (&p.mass, &p.velocity, &p.volume);
        let add = |p: usize, s: &S, patch: &mut [P2gSums]| {
            let (m, v, vol, sig) = (mass[p], velocity[p], volume[p], &stress[p]);
            for a in 0..s.support_size() {
                let nm = s.value(a) * m;
                let [dx, dy] = s.gradient(a);
                let sum = &mut patch[s.place(a)];
                sum[MASS] += nm;
                sum[MOMENTUM] += nm * v[0];
                sum[MOMENTUM + 1] += nm * v[1];
                sum[INTERNAL] += vol * (dx * sig[0] + dy * sig[3]);
                sum[INTERNAL + 1] += vol * (dy * sig[1] + dx * sig[3]);
                sum[BODY] += nm * -g;
            }
        };
        transfer::scatter_into_field(
            &model.grid,
            &setup.bins,
            shapes,
            add,
            &mut self.p2g_cells,
            &mut self.p2g,
        );
        profile.count(Work::ExplicitNodalMass, 1);
        let nodes = self.p2g.len();
        // f_ext of the boundary devices: follower pressures, springs
        let devices = !model.state.traction.is_empty() || !model.state.driven.is_empty();
        self.external.clear();
        if devices {
            self.external.extend(self.p2g.iter().map(|sums| {
                if g != 0.0 {
                    [0.0, sums[BODY]]
                } else {
                    [0.0; 2]
                }
            }));
            model
                .state
                .traction
                .add_forces(&setup.traction_shapes, &mut self.external);
            if !model.state.driven.is_empty() {
                self.zero.clear();
                self.zero.resize(nodes, [0.0; 2]);
                model.state.driven.add_forces(
                    p,
                    &setup.driven_shapes,
                    &setup.bins,
                    &self.zero,
                    t,
                    &mut self.external,
                );
            }
        }
        // m_i, p_i and f_i = f_ext − f_int, f_ext the body force alone
        // without devices, at the active nodes
        let (sums, external) = (&self.p2g, &self.external);
        let active = &setup.bins.active_nodes;
        let grid = &mut self.grid;
        grid.mass.refill(nodes, active, |node| sums[node][MASS]);
        refill_fields(
            [&mut grid.momentum, &mut grid.force],
            nodes,
            active,
            &mut grid.staging_p2g,
            |node| {
                let s = &sums[node];
                let e = if devices {
                    external[node]
                } else if g != 0.0 {
                    [0.0, s[BODY]]
                } else {
                    [0.0; 2]
                };
                [
                    [s[MOMENTUM], s[MOMENTUM + 1]],
                    [e[0] - s[INTERNAL], e[1] - s[INTERNAL + 1]],
                ]
            },
        );
    }

    /// MUSL re-map (theory §4 step 4): p_i = Σ_p N_ip m_p v_p of the updated
    /// point velocities, Dirichlet again (the normal dof of a frictional edge
    /// takes the update's velocity, as a prescribed dof does, theory eq.
    /// FR3); Δu_i = Δt p_i / m_i into `self.increment`.
    fn remap<S: Support>(&mut self, model: &Model, setup: &StepSetup, shapes: &[S], dt: f64) {
        let p = &model.state.particles;
        let (mass, velocity) = (&p.mass, &p.velocity);
        let add = |p: usize, s: &S, patch: &mut [[f64; 2]]| {
            let (m, v) = (mass[p], velocity[p]);
            for a in 0..s.support_size() {
                let nm = s.value(a) * m;
                let sum = &mut patch[s.place(a)];
                sum[0] += nm * v[0];
                sum[1] += nm * v[1];
            }
        };
        transfer::scatter_into_field(
            &model.grid,
            &setup.bins,
            shapes,
            add,
            &mut self.remap_cells,
            &mut self.remapped,
        );
        let (grid, remapped) = (&self.grid, &self.remapped);
        let dof = &model.constraints.dof;
        let (node_count, active) = (model.grid.node_count(), &setup.bins.active_nodes);
        self.increment.refill(node_count, active, |node| {
            let mut u = [0.0; 2];
            if grid.mass[node] > grid.tiny_mass {
                let contact = model.friction.at(node);
                for (c, uc) in u.iter_mut().enumerate() {
                    if contact.is_some_and(|f| f.normal == c) {
                        // the update's decision: held where it stopped the
                        // approach, the update's velocity where it let the
                        // node leave, as the points moved in G2P
                        *uc = dt * grid.velocity[node][c];
                        continue;
                    }
                    *uc = match dof[2 * node + c] {
                        DofConstraint::Fixed => 0.0,
                        DofConstraint::Prescribed { .. } => dt * grid.velocity[node][c],
                        DofConstraint::Free => dt * remapped[node][c] / grid.mass[node],
                    };
                }
            }
            u
        });
    }

    /// Δε from the re-mapped increment and the stress update (theory §4
    /// step 5) into `self.trial`, strengths at κ̄(n); the updates are
    /// counted in `profile`. No tangent is formed.
    fn stress_update<S: Support>(
        &mut self,
        model: &Model,
        setup: &StepSetup,
        shapes: &[S],
        nonlocal: Option<&NonlocalStep>,
        profile: &Profile,
    ) -> Result<(), StepError> {
        evaluate_stresses_without_tangent(
            model,
            setup,
            shapes,
            &self.increment,
            nonlocal.map(|n| n.strength()),
            &mut self.trial,
        )
        .counted(profile)
        .map_err(|(particle, source)| StepError::Constitutive { particle, source })
    }
}

/// The velocity of a free node of mass `m` after the step's force `force`
/// with local damping (D21): (p + Δt f_damped)/m per component.
fn free_velocity(momentum: [f64; 2], force: [f64; 2], m: f64, damping: f64, dt: f64) -> [f64; 2] {
    let mut v = [0.0; 2];
    for c in 0..2 {
        let (v0, mut f) = (momentum[c] / m, force[c]);
        if v0 != 0.0 {
            f -= damping * f.abs() * v0.signum();
        }
        v[c] = (momentum[c] + dt * f) / m;
    }
    v
}

/// [acceleration, velocity, reaction] of a node on a frictional edge whose
/// velocity after the step's forces would be `free` (theory eq. FR2): the
/// approach stopped, the slide limited by Coulomb's law; a tangential dof
/// also fixed by another condition (a corner) is held. The reaction is the
/// edge's force m (v − v_free)/Δt.
fn frictional_node(
    model: &Model,
    contact: &crate::friction::FrictionNode,
    momentum: [f64; 2],
    free: [f64; 2],
    m: f64,
    dt: f64,
) -> [[f64; 2]; 3] {
    let mut v = contact.stop_and_slide(free);
    let t = contact.tangent();
    if model.constraints.dof[2 * contact.node + t] == DofConstraint::Fixed {
        v[t] = 0.0;
    }
    let (mut acceleration, mut reaction) = ([0.0; 2], [0.0; 2]);
    for c in 0..2 {
        acceleration[c] = (v[c] - momentum[c] / m) / dt;
        reaction[c] = m * (v[c] - free[c]) / dt;
    }
    [acceleration, v, reaction]
}

impl UpdatedGrid {
    /// p_i ← p_i + Δt f_i with local damping (D21) and Dirichlet conditions;
    /// then the accelerations, velocities and reactions of the nodes
    /// (`active`: the active nodes, the others carry nothing).
    fn update_momentum(&mut self, model: &Model, active: &[u32], dt: f64) {
        // a maximum: the same whatever the order
        let largest = active.par_iter().map(|&node| self.mass[node as usize]);
        self.tiny_mass = 1e-12 * largest.reduce(|| 0.0, f64::max);
        let damping = model.settings.solver.damping;
        let t = model.state.time;
        let (tiny_mass, mass, momentum, force) =
            (self.tiny_mass, &self.mass, &self.momentum, &self.force);
        refill_fields(
            [
                &mut self.acceleration,
                &mut self.velocity,
                &mut self.reaction,
            ],
            mass.len(),
            active,
            &mut self.staging_update,
            |node| {
                let (mut acceleration, mut reaction) = ([0.0; 2], [0.0; 2]);
                let m = mass[node];
                if m <= tiny_mass {
                    return [[0.0; 2]; 3];
                }
                if let Some(contact) = model.friction.at(node) {
                    let free = free_velocity(momentum[node], force[node], m, damping, dt);
                    return frictional_node(model, contact, momentum[node], free, m, dt);
                }
                let mut momentum = momentum[node];
                for c in 0..2 {
                    let v = momentum[c] / m;
                    let mut f = force[node][c];
                    match model.constraints.dof[2 * node + c] {
                        DofConstraint::Fixed => {
                            reaction[c] = -f;
                            momentum[c] = 0.0;
                            acceleration[c] = -v / dt;
                        }
                        DofConstraint::Prescribed {
                            rate,
                            gradient,
                            ramp,
                        } => {
                            // the mean velocity of the step, so that the re-map's
                            // Δt v moves the node by u(t + Δt) − u(t) (StartRamp)
                            let x = model.grid.node_position(node);
                            let factor = ramp.mean_velocity_factor(t, t + dt);
                            let target = factor * (rate + gradient[0] * x[0] + gradient[1] * x[1]);
                            reaction[c] = -f;
                            acceleration[c] = (target - v) / dt;
                            momentum[c] = m * target;
                        }
                        DofConstraint::Free => {
                            if v != 0.0 {
                                f -= damping * f.abs() * v.signum();
                            }
                            momentum[c] += dt * f;
                            acceleration[c] = f / m;
                        }
                    }
                }
                let velocity = [momentum[0] / m, momentum[1] / m];
                [acceleration, velocity, reaction]
            },
        );
    }

    /// The kinetic energy of the P2G momentum that the update zeroed at the
    /// fixed dofs of the `active` nodes ([`super::boundary_work`] B1), and
    /// the work the frictional edges took in the step `dt`: −T v_t Δt at each
    /// frictional node (T the edge's tangential force, v_t the node's new
    /// tangential velocity), as the implicit −T Δu_t, kJ/m. (Kinetic-energy
    /// forms, ½ m (v*² − v²), counted the stop of tiny nodal masses against
    /// their own static load: 10× the work of gravity on the cut.)
    fn fixed_dof_kinetic_energy(&self, model: &Model, active: &[u32], dt: f64) -> f64 {
        let (mass, momentum) = (&self.mass, &self.momentum);
        let frictional = |node: usize| model.friction.at(node).is_some();
        let friction: f64 = active
            .iter()
            .map(|&node| node as usize)
            .filter(|&node| frictional(node) && mass[node] > self.tiny_mass)
            .map(|node| {
                let (v, r) = (self.velocity[node], self.reaction[node]);
                let t = model.friction.at(node).map_or(0, |c| c.tangent());
                -r[t] * v[t] * dt
            })
            .sum();
        friction
            + fixed_dof_kinetic_energy(
                |d| model.constraints.dof[d] == DofConstraint::Fixed,
                active
                    .iter()
                    .map(|&node| node as usize)
                    .filter(|&node| !frictional(node)),
                self.tiny_mass,
                |node| mass[node],
                |node| {
                    [
                        momentum[node][0] / mass[node],
                        momentum[node][1] / mass[node],
                    ]
                },
            )
    }

    /// G2P of the updated grid (theory §4 step 3): v_p += Δt Σ N a_i,
    /// x_p += Δt Σ N p_i/m_i.
    fn motion(&self, dt: f64) -> GridMotion<'_> {
        GridMotion {
            dt,
            displacement: &self.velocity,
            scale: dt,
            acceleration: Some((&self.acceleration, VelocityUpdate::Forward)),
            force_per_mass: None,
            velocity_removed: None,
        }
    }

    /// Surface contact points move with the nodal velocity that moved the
    /// material points (G2P), not with the re-mapped increment: measured,
    /// following the re-mapped increment they drift off the surface and the
    /// platen load swings by ±8 %. Left empty without rigid bodies.
    fn contact_motion(&self, model: &Model, dt: f64, motion: &mut Vec<[f64; 2]>) {
        motion.clear();
        if !model.state.driven.is_empty() {
            motion.extend(self.velocity.iter().map(|v| [dt * v[0], dt * v[1]]));
        }
    }
}
