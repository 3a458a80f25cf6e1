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
    /// The points of a neighbourhood (never empty at the start).
    Group(Vec<usize>),
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
                    .state
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
            MonitorKind::NeighbourhoodStress => Target::Group(neighbourhood(spec, model)),
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
                        .state
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
    /// (`new_index[old]`; the caller keeps monitored points); a group keeps
    /// its members that remain.
    pub fn remap_particle(&mut self, new_index: &[Option<usize>]) {
        match &mut self.target {
            Target::Particle(p) => {
                if let Some(new) = new_index[*p] {
                    *p = new;
                }
            }
            Target::Group(members) => {
                *members = members.iter().filter_map(|&p| new_index[p]).collect();
            }
            _ => {}
        }
    }

    /// Gather a neighbourhood again from the points' starting positions
    /// (restoring a checkpoint: the same group, less its removed points).
    pub fn regroup(&mut self, model: &Model) {
        if let Target::Group(members) = &mut self.target {
            *members = neighbourhood(&self.spec, model);
        }
    }

    /// `quantity` of the points `members`, volume-weighted (one point: its
    /// own value): stresses of the mean stress tensor, the mean κ or κ̄, the
    /// centre; NaN for an empty group.
    fn quantity(&self, model: &Model, members: &[usize]) -> f64 {
        let p = &model.state.particles;
        let volume: f64 = members.iter().map(|&i| p.volume[i]).sum();
        let mean = |value: &dyn Fn(usize) -> f64| match members {
            [one] => value(*one),
            _ => members.iter().map(|&i| p.volume[i] * value(i)).sum::<f64>() / volume,
        };
        let mut stress = [0.0; 4];
        for (c, s) in stress.iter_mut().enumerate() {
            *s = mean(&|i| p.stress[i][c]);
        }
        match self.spec.quantity.unwrap_or(StressQuantity::Q) {
            StressQuantity::Sxx => stress[0],
            StressQuantity::Syy => stress[1],
            StressQuantity::Szz => stress[2],
            StressQuantity::Sxy => stress[3],
            StressQuantity::P => mean_stress(&stress),
            StressQuantity::Q => deviatoric_stress(&stress),
            StressQuantity::Kappa => mean(&|i| p.state[i].plastic_strain_eq),
            StressQuantity::KappaBar => mean(&|i| p.state[i].plastic_strain_eq_nonlocal),
            StressQuantity::X => mean(&|i| p.position[i][0]),
            StressQuantity::Y => mean(&|i| p.position[i][1]),
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
        let p = &model.state.particles;
        let raw = match (&self.target, self.spec.kind) {
            (Target::Particle(i), MonitorKind::PointDisplacement) => pick(p.displacement(*i)),
            (Target::Particle(i), MonitorKind::PointVelocity) => pick(p.velocity[*i]),
            (Target::Particle(i), MonitorKind::PointStress) => self.quantity(model, &[*i]),
            (Target::Group(members), _) => self.quantity(model, members),
            (Target::Nodes(nodes), _) => {
                let mut sum = [0.0; 2];
                for &n in nodes {
                    if let Some(r) = model.state.reaction.get(n) {
                        sum[0] += r[0];
                        sum[1] += r[1];
                    }
                }
                pick(sum)
            }
            (Target::Rigid(r), MonitorKind::RigidDisplacement) => {
                pick(model.state.driven.mean_displacement(*r, p))
            }
            (Target::Rigid(r), _) => {
                pick(model.state.driven.force_on_soil(*r, p, model.state.time))
            }
            (_, MonitorKind::KineticEnergy) => model.kinetic_energy(),
            (_, MonitorKind::StrainEnergy) => model.strain_energy(),
            (_, MonitorKind::ExternalWork) => model.state.external_work,
            (_, MonitorKind::InternalWork) => model.state.internal_work,
            (_, MonitorKind::MaxPlasticStrain) => p
                .state
                .iter()
                .map(|s| s.plastic_strain_eq)
                .fold(0.0, f64::max),
            (_, MonitorKind::DissipatedEnergy) => model.state.dissipated_energy,
            (_, MonitorKind::BoundaryWork) => model.state.boundary_work,
            (_, MonitorKind::EnergyRemainder) => crate::energy::remainder(model),
            (_, MonitorKind::Gravity) => model.settings.loads.gravity_at(model.state.time),
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

/// The points of `spec`'s neighbourhood: those whose starting position lies
/// within its radius (default one cell) of its point; the nearest one when
/// none does.
fn neighbourhood(spec: &MonitorSpec, model: &Model) -> Vec<usize> {
    let x = spec.point.unwrap_or_default();
    let radius = spec.radius.unwrap_or(model.grid.cell_size);
    let distance2 = |y: &[f64; 2]| (y[0] - x[0]).powi(2) + (y[1] - x[1]).powi(2);
    let start = &model.state.particles.position0;
    let members: Vec<usize> = (0..start.len())
        .filter(|&p| distance2(&start[p]) <= radius * radius)
        .collect();
    if !members.is_empty() {
        return members;
    }
    (0..start.len())
        .min_by(|&a, &b| distance2(&start[a]).total_cmp(&distance2(&start[b])))
        .into_iter()
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Scene;

    const CUT: &str = include_str!("../../validation/vertical_cut/local_h100.toml");

    /// The coarse cut (h = 0.25 m, four points per cell) with a neighbourhood
    /// monitor of `quantity` around B, radius `radius`.
    fn cut_with_group(quantity: StressQuantity, radius: Option<f64>) -> (Model, Monitor) {
        let cut =
            Scene::from_str_with_overrides(CUT, "cut", &["grid.cell_size=0.25".into()]).unwrap();
        let model = Model::new(&cut).unwrap();
        let spec = MonitorSpec {
            name: "group".into(),
            kind: MonitorKind::NeighbourhoodStress,
            point: Some([2.78, 0.34]),
            quantity: Some(quantity),
            radius,
            ..cut.monitor[0].clone()
        };
        let monitor = Monitor::resolve(&spec, &model);
        (model, monitor)
    }

    fn members(monitor: &Monitor) -> Vec<usize> {
        match &monitor.target {
            Target::Group(m) => m.clone(),
            other => panic!("{other:?}"),
        }
    }

    /// The group is the points that started within the radius (one cell by
    /// default); its stress is the volume-weighted mean tensor's, its centre
    /// the volume-weighted mean position.
    #[test]
    fn neighbourhood_averages_the_points_that_started_near_the_point() {
        let (mut model, q) = cut_with_group(StressQuantity::Q, None);
        let group = members(&q);
        let x = [2.78, 0.34];
        let p = &mut model.state.particles;
        let near = |i: usize| {
            let y = p.position0[i];
            (y[0] - x[0]).powi(2) + (y[1] - x[1]).powi(2) <= 0.25 * 0.25
        };
        let expected: Vec<usize> = (0..p.mass.len()).filter(|&i| near(i)).collect();
        assert_eq!(group, expected);
        assert!((9..=16).contains(&group.len()), "{} points", group.len());
        // σxx = −10 on the first member (twice the volume), −40 on the others
        for (k, &i) in group.iter().enumerate() {
            p.stress[i] = if k == 0 {
                [-10.0, 0.0, 0.0, 0.0]
            } else {
                [-40.0, 0.0, 0.0, 0.0]
            };
            p.volume[i] = if k == 0 { 2.0 } else { 1.0 };
        }
        let n = group.len() as f64;
        let sxx = (2.0 * -10.0 + (n - 1.0) * -40.0) / (n + 1.0);
        // q of a uniaxial tensor is |σxx|
        assert!((q.value(&model) - sxx.abs()).abs() < 1e-12);
        let (_, centre) = cut_with_group(StressQuantity::X, Some(0.25));
        let p = &model.state.particles;
        let volume: f64 = group.iter().map(|&i| p.volume[i]).sum();
        let x_mean = group
            .iter()
            .map(|&i| p.volume[i] * p.position[i][0])
            .sum::<f64>()
            / volume;
        assert!((centre.value(&model) - x_mean).abs() < 1e-12);
    }

    /// A removed member leaves the group; gathering it again from the
    /// starting positions of the remaining points gives the same group.
    #[test]
    fn neighbourhood_follows_removed_points() {
        let (mut model, mut monitor) = cut_with_group(StressQuantity::P, Some(0.3));
        let group = members(&monitor);
        let gone = group[1];
        let new_index: Vec<Option<usize>> = (0..model.state.particles.mass.len())
            .map(|i| match i.cmp(&gone) {
                std::cmp::Ordering::Less => Some(i),
                std::cmp::Ordering::Equal => None,
                std::cmp::Ordering::Greater => Some(i - 1),
            })
            .collect();
        monitor.remap_particle(&new_index);
        let remapped = members(&monitor);
        assert_eq!(remapped.len(), group.len() - 1);
        model.state.particles.position0.remove(gone);
        monitor.regroup(&model);
        assert_eq!(members(&monitor), remapped);
    }
}
