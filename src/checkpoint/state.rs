//! What a checkpoint holds: every piece of a run's state that a step changes
//! (the model's material points, boundary devices, time, step, energies and
//! removed points; the integrator's counters; the monitors' points; the work
//! counters) and the output cursors, and how it is put back into a freshly
//! built [`Simulation`] of the same scene.
//!
//! What a fresh build of the scene gives again is not stored: the grid, the
//! materials, the Dirichlet conditions, the Newmark parameters and Δt. The
//! implicit integrator's solver caches (sparsity pattern, symbolic
//! factorisation) are rebuilt at the first step after a resume; they depend
//! only on the pattern, so the numbers are the same.

use crate::bc::{DrivenPoints, TractionPoints};
use crate::constitutive::PointState;
use crate::error::TimeStepLimit;
use crate::integrators::path::PathRecord;
use crate::integrators::step_control::StepControlRecord;
use crate::integrators::{Integrator, SolverUsage};
use crate::model::LostPoint;
use crate::output::{FieldSnapshot, OutputCursor};
use crate::particles::Particles;
use crate::profile::Work;
use crate::simulation::Simulation;

use super::codec::{Codec, DecodeError, Reader, Writer};

/// The state of a run after a completed step, as stored in a checkpoint.
#[derive(Clone, Debug)]
pub struct SavedState {
    /// Material points.
    pub particles: Particles,
    /// Follower-pressure points.
    pub traction: TractionPoints,
    /// Penalty-tied points of rigid bodies.
    pub driven: DrivenPoints,
    /// Points that must not be removed (monitored points).
    pub pinned_points: Vec<usize>,
    /// Time, s.
    pub time: f64,
    /// Completed steps.
    pub step: usize,
    /// Support reactions of the last step, kN/m.
    pub reaction: Vec<[f64; 2]>,
    /// Nodal displacement increment of the last (sub-)step, m.
    pub last_increment: Vec<[f64; 2]>,
    /// Plastic dissipation, kJ/m.
    pub dissipated_energy: f64,
    /// External work, kJ/m.
    pub external_work: f64,
    /// Internal work, kJ/m.
    pub internal_work: f64,
    /// Work removed at the fixed dofs, kJ/m.
    pub boundary_work: f64,
    /// Kinetic energy at t = 0, kJ/m.
    pub initial_kinetic_energy: f64,
    /// Points removed so far.
    pub lost_points: Vec<LostPoint>,
    /// Force of every rigid body on the soil after the last step, kN/m.
    pub rigid_force: Vec<[f64; 2]>,
    /// The integrator's counters.
    pub usage: SolverUsage,
    /// Implicit runs: the last converged step's residual history and reference force.
    pub last_residuals: Option<(Vec<f64>, f64)>,
    /// The material point each monitor follows (`None` for the others).
    pub monitor_points: Vec<Option<usize>>,
    /// Work counters, in [`Work::ALL`] order.
    pub work: Vec<u64>,
    /// Where the outputs stood.
    pub cursor: OutputCursor,
}

/// Why a decoded state cannot be put into the simulation built from the scene.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Misfit(pub String);

impl SavedState {
    /// The state of `sim` now, with the output cursor `cursor`.
    pub fn of(sim: &Simulation, cursor: OutputCursor) -> Self {
        let model = &sim.model;
        let last_residuals = sim
            .integrator
            .implicit()
            .map(|implicit| implicit.last_residuals.clone());
        Self {
            particles: model.particles.clone(),
            traction: model.traction.clone(),
            driven: model.driven.clone(),
            pinned_points: model.pinned_points.clone(),
            time: model.time,
            step: model.step,
            reaction: model.reaction.clone(),
            last_increment: model.last_increment.clone(),
            dissipated_energy: model.dissipated_energy,
            external_work: model.external_work,
            internal_work: model.internal_work,
            boundary_work: model.boundary_work,
            initial_kinetic_energy: model.initial_kinetic_energy,
            lost_points: model.lost_points.clone(),
            rigid_force: model.rigid_force.clone(),
            usage: sim.integrator.usage().clone(),
            last_residuals,
            monitor_points: sim.monitors.iter().map(|m| m.particle()).collect(),
            work: Work::ALL
                .iter()
                .map(|&w| sim.profile.work_count(w))
                .collect(),
            cursor,
        }
    }

    /// Check that the state fits `sim` (a fresh build of the same scene):
    /// array lengths, indices in range, the same boundary devices.
    pub fn check_fits(&self, sim: &Simulation) -> Result<(), Misfit> {
        let model = &sim.model;
        let p = &self.particles;
        let n = p.len();
        let lengths = [
            ("position0", p.position0.len()),
            ("mass", p.mass.len()),
            ("volume", p.volume.len()),
            ("def_grad", p.def_grad.len()),
            ("stress", p.stress.len()),
            ("strain", p.strain.len()),
            ("velocity", p.velocity.len()),
            ("acceleration", p.acceleration.len()),
            ("force_per_mass", p.force_per_mass.len()),
            ("state", p.state.len()),
            ("material", p.material.len()),
            ("body", p.body.len()),
        ];
        let misfit = |what: String| Err(Misfit(what));
        if let Some((name, len)) = lengths.iter().find(|(_, len)| *len != n) {
            return misfit(format!(
                "material points: {len} values of {name} for {n} points"
            ));
        }
        if n == 0 {
            return misfit("no material point".into());
        }
        if let Some(m) = p
            .material
            .iter()
            .find(|&&m| m as usize >= model.materials.len())
        {
            return misfit(format!("material index {m} out of range"));
        }
        if let Some(b) = p
            .body
            .iter()
            .find(|&&b| b as usize >= model.scene.body.len())
        {
            return misfit(format!("body index {b} out of range"));
        }
        let nodes = model.grid.node_count();
        if self.reaction.len() != nodes || self.last_increment.len() != nodes {
            return misfit(format!(
                "nodal arrays of {} and {} values for a grid of {nodes} nodes",
                self.reaction.len(),
                self.last_increment.len()
            ));
        }
        let t = &self.traction;
        if t.position.len() != model.traction.position.len()
            || t.tangent.len() != t.position.len()
            || t.pressure.len() != t.position.len()
        {
            return misfit("traction points differ from the scene's".into());
        }
        let d = &self.driven;
        let count = model.driven.particle.len();
        let same_driven = [
            d.particle.len(),
            d.position.len(),
            d.position0.len(),
            d.rigid.len(),
            d.stiffness.len(),
        ]
        .iter()
        .all(|&len| len == count)
            && d.velocity.len() == model.driven.velocity.len()
            && d.names == model.driven.names
            && d.rigid.iter().all(|&r| r < d.velocity.len());
        if !same_driven {
            return misfit("rigid-body points differ from the scene's".into());
        }
        if d.particle.iter().flatten().any(|&i| i >= n)
            || self.pinned_points.iter().any(|&i| i >= n)
        {
            return misfit("a tied or pinned point index is out of range".into());
        }
        if self.rigid_force.len() > d.velocity.len() {
            return misfit("more rigid-body forces than rigid bodies".into());
        }
        if self.monitor_points.len() != sim.monitors.len()
            || self.monitor_points.iter().flatten().any(|&i| i >= n)
            || self
                .monitor_points
                .iter()
                .zip(&sim.monitors)
                .any(|(saved, m)| saved.is_some() != m.particle().is_some())
        {
            return misfit("monitors differ from the scene's".into());
        }
        if self.last_residuals.is_some() != sim.integrator.implicit().is_some() {
            return misfit("the integrator differs from the scene's".into());
        }
        if self.work.len() != Work::ALL.len() {
            return misfit(format!("{} work counters", self.work.len()));
        }
        Ok(())
    }

    /// Put the state into `sim`, a fresh build of the same scene (call
    /// [`Self::check_fits`] first). Returns the output cursor.
    pub fn restore(self, sim: &mut Simulation) -> OutputCursor {
        let model = &mut sim.model;
        model.particles = self.particles;
        model.traction = self.traction;
        // the start ramps are the scene's, not state: kept from the fresh build
        let ramp = std::mem::take(&mut model.driven.ramp);
        model.driven = self.driven;
        model.driven.ramp = ramp;
        model.pinned_points = self.pinned_points;
        model.time = self.time;
        model.step = self.step;
        model.reaction = self.reaction;
        model.last_increment = self.last_increment;
        model.nodal_results_at = None;
        model.dissipated_energy = self.dissipated_energy;
        model.external_work = self.external_work;
        model.internal_work = self.internal_work;
        model.boundary_work = self.boundary_work;
        model.initial_kinetic_energy = self.initial_kinetic_energy;
        model.lost_points = self.lost_points;
        model.rigid_force = self.rigid_force;
        model.mass_height = model.current_mass_height();
        match &mut sim.integrator {
            Integrator::Implicit(implicit) => {
                implicit.usage = self.usage;
                if let Some(residuals) = self.last_residuals {
                    implicit.last_residuals = residuals;
                }
            }
            Integrator::Explicit(explicit) => explicit.usage = self.usage,
        }
        for (monitor, point) in sim.monitors.iter_mut().zip(self.monitor_points) {
            if let Some(p) = point {
                monitor.set_particle(p);
            }
            monitor.regroup(&sim.model);
        }
        for (&work, saved) in Work::ALL.iter().zip(self.work) {
            let now = sim.profile.work_count(work);
            sim.profile.count(work, saved.saturating_sub(now));
        }
        self.cursor
    }
}

impl Codec for SavedState {
    const MIN_SIZE: usize = 0;
    fn encode(&self, w: &mut Writer) {
        w.put(&self.particles);
        w.put(&self.traction);
        w.put(&self.driven);
        w.put(&self.pinned_points);
        w.put(&self.time);
        w.put(&self.step);
        w.put(&self.reaction);
        w.put(&self.last_increment);
        w.put(&self.dissipated_energy);
        w.put(&self.external_work);
        w.put(&self.internal_work);
        w.put(&self.boundary_work);
        w.put(&self.initial_kinetic_energy);
        w.put(&self.lost_points);
        w.put(&self.rigid_force);
        w.put(&self.usage);
        w.put(&self.last_residuals);
        w.put(&self.monitor_points);
        w.put(&self.work);
        w.put(&self.cursor);
    }
    fn decode(r: &mut Reader) -> Result<Self, DecodeError> {
        Ok(Self {
            particles: r.get()?,
            traction: r.get()?,
            driven: r.get()?,
            pinned_points: r.get()?,
            time: r.get()?,
            step: r.get()?,
            reaction: r.get()?,
            last_increment: r.get()?,
            dissipated_energy: r.get()?,
            external_work: r.get()?,
            internal_work: r.get()?,
            boundary_work: r.get()?,
            initial_kinetic_energy: r.get()?,
            lost_points: r.get()?,
            rigid_force: r.get()?,
            usage: r.get()?,
            last_residuals: r.get()?,
            monitor_points: r.get()?,
            work: r.get()?,
            cursor: r.get()?,
        })
    }
}

impl Codec for PointState {
    const MIN_SIZE: usize = 6 * 8;
    fn encode(&self, w: &mut Writer) {
        w.put(&self.plastic_strain_eq);
        w.put(&self.plastic_strain_eq_nonlocal);
        w.put(&self.plastic_strain);
    }
    fn decode(r: &mut Reader) -> Result<Self, DecodeError> {
        Ok(Self {
            plastic_strain_eq: r.get()?,
            plastic_strain_eq_nonlocal: r.get()?,
            plastic_strain: r.get()?,
        })
    }
}

impl Codec for Particles {
    const MIN_SIZE: usize = 13 * 8;
    fn encode(&self, w: &mut Writer) {
        w.put(&self.position);
        w.put(&self.position0);
        w.put(&self.mass);
        w.put(&self.volume);
        w.put(&self.def_grad);
        w.put(&self.stress);
        w.put(&self.strain);
        w.put(&self.velocity);
        w.put(&self.acceleration);
        w.put(&self.force_per_mass);
        w.put(&self.state);
        w.put(&self.material);
        w.put(&self.body);
    }
    fn decode(r: &mut Reader) -> Result<Self, DecodeError> {
        Ok(Self {
            position: r.get()?,
            position0: r.get()?,
            mass: r.get()?,
            volume: r.get()?,
            def_grad: r.get()?,
            stress: r.get()?,
            strain: r.get()?,
            velocity: r.get()?,
            acceleration: r.get()?,
            force_per_mass: r.get()?,
            state: r.get()?,
            material: r.get()?,
            body: r.get()?,
        })
    }
}

impl Codec for TractionPoints {
    const MIN_SIZE: usize = 3 * 8;
    fn encode(&self, w: &mut Writer) {
        w.put(&self.position);
        w.put(&self.tangent);
        w.put(&self.pressure);
    }
    fn decode(r: &mut Reader) -> Result<Self, DecodeError> {
        Ok(Self {
            position: r.get()?,
            tangent: r.get()?,
            pressure: r.get()?,
        })
    }
}

impl Codec for DrivenPoints {
    const MIN_SIZE: usize = 7 * 8;
    fn encode(&self, w: &mut Writer) {
        w.put(&self.particle);
        w.put(&self.position);
        w.put(&self.position0);
        w.put(&self.rigid);
        w.put(&self.stiffness);
        w.put(&self.velocity);
        w.put(&self.names);
    }
    fn decode(r: &mut Reader) -> Result<Self, DecodeError> {
        Ok(Self {
            particle: r.get()?,
            position: r.get()?,
            position0: r.get()?,
            rigid: r.get()?,
            stiffness: r.get()?,
            velocity: r.get()?,
            names: r.get()?,
            ramp: Vec::new(),
            bearing: Vec::new(),
        })
    }
}

impl Codec for LostPoint {
    const MIN_SIZE: usize = 9 * 8;
    fn encode(&self, w: &mut Writer) {
        w.put(&self.step);
        w.put(&self.index);
        w.put(&self.position);
        w.put(&self.velocity);
        w.put(&self.mass);
        w.put(&self.mean_stress);
        w.put(&self.plastic_strain_eq);
    }
    fn decode(r: &mut Reader) -> Result<Self, DecodeError> {
        Ok(Self {
            step: r.get()?,
            index: r.get()?,
            position: r.get()?,
            velocity: r.get()?,
            mass: r.get()?,
            mean_stress: r.get()?,
            plastic_strain_eq: r.get()?,
        })
    }
}

impl Codec for TimeStepLimit {
    const MIN_SIZE: usize = 1;
    fn encode(&self, w: &mut Writer) {
        w.put(&match self {
            TimeStepLimit::WaveSpeed => 0u8,
            TimeStepLimit::WaveSpeedAndSprings => 1u8,
        });
    }
    fn decode(r: &mut Reader) -> Result<Self, DecodeError> {
        let at = r.remaining();
        match r.get::<u8>()? {
            0 => Ok(TimeStepLimit::WaveSpeed),
            1 => Ok(TimeStepLimit::WaveSpeedAndSprings),
            _ => Err(DecodeError {
                what: "unknown time-step limit",
                at,
            }),
        }
    }
}

impl Codec for SolverUsage {
    const MIN_SIZE: usize = 9 * 8 + 2;
    fn encode(&self, w: &mut Writer) {
        w.put(&self.cholesky);
        w.put(&self.lu);
        w.put(&self.pcg);
        w.put(&self.ldl);
        w.put(&self.max_unknowns);
        w.put(&self.newton_iterations);
        w.put(&self.halvings);
        w.put(&self.contact_resolves);
        w.put(&self.stagnated_steps);
        w.put(&self.explicit_time_step);
        w.put(&self.time_step_limited_by);
        w.put(&self.step_control);
        w.put(&self.path);
    }
    fn decode(r: &mut Reader) -> Result<Self, DecodeError> {
        Ok(Self {
            cholesky: r.get()?,
            lu: r.get()?,
            pcg: r.get()?,
            ldl: r.get()?,
            max_unknowns: r.get()?,
            newton_iterations: r.get()?,
            halvings: r.get()?,
            contact_resolves: r.get()?,
            stagnated_steps: r.get()?,
            explicit_time_step: r.get()?,
            time_step_limited_by: r.get()?,
            step_control: r.get()?,
            path: r.get()?,
        })
    }
}

impl Codec for PathRecord {
    const MIN_SIZE: usize = 8 * 8;
    fn encode(&self, w: &mut Writer) {
        w.put(&self.last_step);
        w.put(&self.plastic_travel);
        w.put(&self.load_scale);
        w.put(&self.plastic_steps);
        w.put(&self.cuts);
        w.put(&self.jumps);
        w.put(&self.reversals);
    }
    fn decode(r: &mut Reader) -> Result<Self, DecodeError> {
        Ok(Self {
            last_step: r.get()?,
            plastic_travel: r.get()?,
            load_scale: r.get()?,
            plastic_steps: r.get()?,
            cuts: r.get()?,
            jumps: r.get()?,
            reversals: r.get()?,
        })
    }
}

impl Codec for StepControlRecord {
    const MIN_SIZE: usize = 6 * 8 + 1;
    fn encode(&self, w: &mut Writer) {
        w.put(&self.next_dt);
        w.put(&self.accepted);
        w.put(&self.rejected_error);
        w.put(&self.rejected_newton);
        w.put(&self.accepted_at_min);
        w.put(&self.dt_range);
        w.put(&self.velocity_scale);
    }
    fn decode(r: &mut Reader) -> Result<Self, DecodeError> {
        Ok(Self {
            next_dt: r.get()?,
            accepted: r.get()?,
            rejected_error: r.get()?,
            rejected_newton: r.get()?,
            accepted_at_min: r.get()?,
            dt_range: r.get()?,
            velocity_scale: r.get()?,
        })
    }
}

impl Codec for FieldSnapshot {
    const MIN_SIZE: usize = 5 * 8;
    fn encode(&self, w: &mut Writer) {
        w.put(&self.requested_time);
        w.put(&self.time);
        w.put(&self.positions);
        w.put(&self.eps_q);
        w.put(&self.volumes);
    }
    fn decode(r: &mut Reader) -> Result<Self, DecodeError> {
        Ok(Self {
            requested_time: r.get()?,
            time: r.get()?,
            positions: r.get()?,
            eps_q: r.get()?,
            volumes: r.get()?,
        })
    }
}

impl Codec for OutputCursor {
    const MIN_SIZE: usize = 4 * 8 + 1;
    fn encode(&self, w: &mut Writer) {
        w.put(&self.last_row_step);
        w.put(&self.pending_times);
        w.put(&self.fields);
        w.put(&self.snapshots);
        w.put(&self.curve_bytes);
        w.put(&self.curve_checksum);
    }
    fn decode(r: &mut Reader) -> Result<Self, DecodeError> {
        Ok(Self {
            last_row_step: r.get()?,
            pending_times: r.get()?,
            fields: r.get()?,
            snapshots: r.get()?,
            curve_bytes: r.get()?,
            curve_checksum: r.get()?,
        })
    }
}
