//! What a checkpoint holds: every piece of a run's state that a step changes
//! (the model's material points, boundary devices, time, step, energies and
//! removed points; the integrator's counters; the monitors' points; the work
//! counters; the stage profile and the wall time so far) and the output
//! cursors, and how it is put back into a freshly built [`Simulation`] of the
//! same scene.
//!
//! What a fresh build of the scene gives again is not stored: the grid, the
//! materials, the Dirichlet conditions, the settings
//! ([`crate::settings::Settings`]), the Newmark parameters and Δt. The
//! implicit integrator's solver caches (sparsity pattern, symbolic
//! factorisation) are rebuilt at the first step after a resume; they depend
//! only on the pattern, so the numbers are the same.

use crate::integrators::{Integrator, SolverUsage};
use crate::model::State;
use crate::output::OutputCursor;
use crate::profile::{Stage, Work};
use crate::simulation::Simulation;

/// The state of a run after a completed step, as stored in a checkpoint:
/// the model's [`State`] whole, and what the run around the model changes.
/// Encoded by its serde derive ([`super::encode`]).
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct SavedState {
    /// What the steps changed in the model.
    pub model: State,
    /// The integrator's counters.
    pub usage: SolverUsage,
    /// Implicit runs: the last converged step's residual history and reference force.
    pub last_residuals: Option<(Vec<f64>, f64)>,
    /// The material point each monitor follows (`None` for the others).
    pub monitor_points: Vec<Option<usize>>,
    /// Work counters, in [`Work::ALL`] order.
    pub work: Vec<u64>,
    /// Calls and seconds per stage up to the checkpoint, in [`Stage::ALL`]
    /// order, the earlier processes' included.
    pub stages: Vec<(u64, f64)>,
    /// Wall time of the run up to the checkpoint, s, the earlier processes'
    /// included (each up to its last checkpoint).
    pub wall_seconds: f64,
    /// Where the outputs stood.
    pub cursor: OutputCursor,
}

/// Why a decoded state cannot be put into the simulation built from the scene.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Misfit(pub String);

impl SavedState {
    /// The state of `sim` now, `wall_seconds` into the run, with the output
    /// cursor `cursor`.
    pub fn of(sim: &Simulation, cursor: OutputCursor, wall_seconds: f64) -> Self {
        let model = &sim.model;
        let last_residuals = sim
            .integrator
            .implicit()
            .map(|implicit| implicit.last_residuals.clone());
        Self {
            model: model.state.clone(),
            usage: sim.integrator.usage().clone(),
            last_residuals,
            monitor_points: sim.monitors.iter().map(|m| m.particle()).collect(),
            work: Work::ALL
                .iter()
                .map(|&w| sim.profile.work_count(w))
                .collect(),
            stages: sim.profile.stage_entries(),
            wall_seconds,
            cursor,
        }
    }

    /// Check that the state fits `sim` (a fresh build of the same scene):
    /// array lengths, indices in range, the same boundary devices.
    pub fn check_fits(&self, sim: &Simulation) -> Result<(), Misfit> {
        let model = &sim.model;
        let p = &self.model.particles;
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
        if let Some(b) = p.body.iter().find(|&&b| b as usize >= sim.scene.body.len()) {
            return misfit(format!("body index {b} out of range"));
        }
        let nodes = model.grid.node_count();
        if self.model.reaction.len() != nodes || self.model.last_increment.len() != nodes {
            return misfit(format!(
                "nodal arrays of {} and {} values for a grid of {nodes} nodes",
                self.model.reaction.len(),
                self.model.last_increment.len()
            ));
        }
        let t = &self.model.traction;
        if t.position.len() != model.state.traction.position.len()
            || t.tangent.len() != t.position.len()
            || t.pressure.len() != t.position.len()
        {
            return misfit("traction points differ from the scene's".into());
        }
        let d = &self.model.driven;
        let count = model.state.driven.particle.len();
        let same_driven = [
            d.particle.len(),
            d.position.len(),
            d.position0.len(),
            d.rigid.len(),
            d.stiffness.len(),
        ]
        .iter()
        .all(|&len| len == count)
            && d.velocity.len() == model.state.driven.velocity.len()
            && d.names == model.state.driven.names
            && d.rigid.iter().all(|&r| r < d.velocity.len());
        if !same_driven {
            return misfit("rigid-body points differ from the scene's".into());
        }
        if d.particle.iter().flatten().any(|&i| i >= n)
            || self.model.pinned_points.iter().any(|&i| i >= n)
        {
            return misfit("a tied or pinned point index is out of range".into());
        }
        if self.model.rigid_force.len() > d.velocity.len() {
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
        if self.stages.len() != Stage::ALL.len() {
            return misfit(format!("{} profile stages", self.stages.len()));
        }
        Ok(())
    }

    /// Put the state into `sim`, a fresh build of the same scene (call
    /// [`Self::check_fits`] first). Returns the output cursor.
    pub fn restore(self, sim: &mut Simulation) -> OutputCursor {
        let model = &mut sim.model;
        // the start ramps are the scene's, not state: kept from the fresh build
        let ramp = std::mem::take(&mut model.state.driven.ramp);
        model.state = self.model;
        model.state.driven.ramp = ramp;
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
        // added to, not in place of, this process's own build: the run's
        // profile covers every process
        sim.profile.add_stage_entries(&self.stages);
        self.cursor
    }
}
