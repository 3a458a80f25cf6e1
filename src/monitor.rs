//! Monitored quantities: one column of `curve.csv` each (scene `[[monitor]]`).

use crate::bc::nodes_on_line;
use crate::constitutive::{deviatoric_stress, mean_stress};
use crate::model::Model;
use crate::scene::{GridLine, MonitorKind, MonitorSpec, StressQuantity, VectorComponent};

/// A monitor with its target resolved against the seeded model.
#[derive(Clone, Debug)]
pub struct Monitor {
    /// Column name.
    pub name: String,
    /// The scene entry.
    pub spec: MonitorSpec,
    target: Target,
}

#[derive(Clone, Debug)]
enum Target {
    Particle(usize),
    Nodes(Vec<usize>),
    Rigid(usize),
    Global,
}

impl Monitor {
    /// Resolve `spec`: the material point initially nearest `point`, the grid
    /// nodes of `line`, or the rigid body named `rigid`.
    pub fn resolve(spec: &MonitorSpec, model: &Model) -> Self {
        let target = match spec.kind {
            MonitorKind::PointDisplacement
            | MonitorKind::PointVelocity
            | MonitorKind::PointStress => {
                let x = spec.point.unwrap_or_default();
                let p = model
                    .particles
                    .position0
                    .iter()
                    .enumerate()
                    .map(|(p, y)| (p, (y[0] - x[0]).powi(2) + (y[1] - x[1]).powi(2)))
                    .min_by(|a, b| a.1.total_cmp(&b.1))
                    .map(|(p, _)| p)
                    .unwrap_or(0);
                Target::Particle(p)
            }
            MonitorKind::Reaction => {
                let line = spec.line.as_deref().and_then(|l| GridLine::parse(l).ok());
                Target::Nodes(
                    line.map(|l| nodes_on_line(&model.grid, l))
                        .unwrap_or_default(),
                )
            }
            MonitorKind::RigidForce | MonitorKind::RigidDisplacement => {
                let name = spec.rigid.clone().unwrap_or_default();
                Target::Rigid(
                    model
                        .driven
                        .names
                        .iter()
                        .position(|n| *n == name)
                        .unwrap_or(0),
                )
            }
            _ => Target::Global,
        };
        Self {
            name: spec.name.clone(),
            spec: spec.clone(),
            target,
        }
    }

    /// Index of the monitored material point, if the monitor follows one.
    pub fn particle(&self) -> Option<usize> {
        match self.target {
            Target::Particle(p) => Some(p),
            _ => None,
        }
    }

    /// Follow material point `p` (restoring a checkpoint); a monitor that
    /// follows no point is left as it is.
    pub fn set_particle(&mut self, p: usize) {
        if let Target::Particle(i) = &mut self.target {
            *i = p;
        }
    }

    /// Follow the monitored point to its index after points were removed
    /// (`new_index[old]`; the caller keeps monitored points).
    pub fn remap_particle(&mut self, new_index: &[Option<usize>]) {
        if let Target::Particle(p) = &mut self.target {
            if let Some(new) = new_index[*p] {
                *p = new;
            }
        }
    }

    /// Current value (scale · raw + offset).
    pub fn value(&self, model: &Model) -> f64 {
        let component = self.spec.component.unwrap_or(VectorComponent::Y);
        let pick = |v: [f64; 2]| match component {
            VectorComponent::X => v[0],
            VectorComponent::Y => v[1],
            VectorComponent::Norm => (v[0] * v[0] + v[1] * v[1]).sqrt(),
        };
        let p = &model.particles;
        let raw = match (&self.target, self.spec.kind) {
            (Target::Particle(i), MonitorKind::PointDisplacement) => pick(p.displacement(*i)),
            (Target::Particle(i), MonitorKind::PointVelocity) => pick(p.velocity[*i]),
            (Target::Particle(i), MonitorKind::PointStress) => {
                let s = &p.stress[*i];
                match self.spec.quantity.unwrap_or(StressQuantity::Q) {
                    StressQuantity::Sxx => s[0],
                    StressQuantity::Syy => s[1],
                    StressQuantity::Szz => s[2],
                    StressQuantity::Sxy => s[3],
                    StressQuantity::P => mean_stress(s),
                    StressQuantity::Q => deviatoric_stress(s),
                }
            }
            (Target::Nodes(nodes), _) => {
                let mut sum = [0.0; 2];
                for &n in nodes {
                    if let Some(r) = model.reaction.get(n) {
                        sum[0] += r[0];
                        sum[1] += r[1];
                    }
                }
                pick(sum)
            }
            (Target::Rigid(r), MonitorKind::RigidDisplacement) => {
                pick(model.driven.mean_displacement(*r, p))
            }
            (Target::Rigid(r), _) => pick(model.driven.force_on_soil(*r, p, model.time)),
            (_, MonitorKind::KineticEnergy) => model.kinetic_energy(),
            (_, MonitorKind::StrainEnergy) => model.strain_energy(),
            (_, MonitorKind::ExternalWork) => model.external_work,
            (_, MonitorKind::InternalWork) => model.internal_work,
            (_, MonitorKind::MaxPlasticStrain) => p
                .state
                .iter()
                .map(|s| s.plastic_strain_eq)
                .fold(0.0, f64::max),
            (_, MonitorKind::DissipatedEnergy) => model.dissipated_energy,
            (_, MonitorKind::BoundaryWork) => model.boundary_work,
            (_, MonitorKind::EnergyRemainder) => crate::energy::remainder(model),
            (_, MonitorKind::Gravity) => model.scene.loads.gravity_at(model.time),
            (_, MonitorKind::RunOut) => p
                .position
                .iter()
                .map(|x| x[0])
                .fold(f64::NEG_INFINITY, f64::max),
            _ => f64::NAN,
        };
        self.spec.scale * raw + self.spec.offset
    }
}
