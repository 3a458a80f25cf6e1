//! The state of the model: grid, materials, material points, boundary
//! devices and time, plus what the committed steps have accumulated
//! (reactions, energies, removed points). Integrators advance it; the run
//! ([`crate::simulation`]) reads it for monitors and outputs.

use std::sync::Arc;

use rayon::prelude::*;

use crate::bc::{Constraints, DrivenPoints, TractionPoints};
use crate::constitutive::{
    invert4, ConstitutiveModel, Hmc, LinearElastic, Mat4, ParameterProblem, VonMises,
};
use crate::error::StepError;
use crate::grid::{Grid, ShapeFunctions};
use crate::particles::Particles;
use crate::scene::{
    AnalysisKind, DoubleMapping, FieldError, LostPointPolicy, MaterialSpec, Scene, SceneError,
    ShapeFunctionChoice,
};
use crate::seeding::seed_particles;
use crate::settings::Settings;
use crate::walls::Walls;

/// A material point dropped from the run after it left the grid
/// (`[grid] lost_points = "remove"`), as it was at that moment.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct LostPoint {
    /// Step during which the point left the grid.
    pub step: usize,
    /// Index of the point just before its removal (later points move down by one).
    pub index: usize,
    /// Position outside the grid, m.
    pub position: [f64; 2],
    /// Velocity, m/s.
    pub velocity: [f64; 2],
    /// Mass, t per metre run.
    pub mass: f64,
    /// Mean stress p = −tr σ / 3, kPa.
    pub mean_stress: f64,
    /// Local equivalent plastic strain κ.
    pub plastic_strain_eq: f64,
}

/// New index of every old material point after points were removed
/// (`None` for a removed point).
pub type PointRemap = Vec<Option<usize>>;

/// The model: what the scene fixes for the whole run (grid, materials,
/// Dirichlet conditions, walls) and the [`State`] the steps advance.
/// `Clone` copies the whole state (the material laws are shared):
/// `benches/step.rs` times one step from a fixed state.
#[derive(Clone)]
pub struct Model {
    /// The settings the physics reads, resolved from the scene.
    pub settings: Settings,
    /// Background grid.
    pub grid: Grid,
    /// Material laws, indexed by particle material id.
    pub materials: Vec<Arc<dyn ConstitutiveModel>>,
    /// Material names, same order.
    pub material_names: Vec<String>,
    /// Elastic compliance C = D⁻¹ of every material (D22), same order.
    pub compliances: Vec<Mat4>,
    /// Dirichlet conditions of every grid dof.
    pub constraints: Constraints,
    /// Nodes of the frictional edges (`[[bc.friction]]`); their normal dofs
    /// are held in `constraints`.
    pub friction: crate::friction::FrictionEdges,
    /// The grid edges the points cannot cross (theory eq. W1), from
    /// `constraints`.
    pub walls: Walls,
    /// What the steps change.
    pub state: State,
}

/// Everything a step changes: the material points, the boundary devices
/// that move with them, time and step, the last step's nodal results, the
/// energy accounts and the removed points. A checkpoint stores it whole
/// (`src/checkpoint`), so a field added here is saved and restored without
/// further code. Every field is stored as it is, the derived ones too
/// ([`State::mass_height`], [`State::nodal_results_at`]), so a restored
/// state needs no recomputation; only the rigid bodies' start ramps
/// ([`DrivenPoints::ramp`], the scene's) and bearing flags (derived every
/// step) are left out of the encoding.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct State {
    /// Material points.
    pub particles: Particles,
    /// Follower-pressure points.
    pub traction: TractionPoints,
    /// Penalty-tied points of rigid bodies.
    pub driven: DrivenPoints,
    /// Points that must not be removed when they leave the grid (those the
    /// run's monitors follow); kept current when points are removed.
    pub pinned_points: Vec<usize>,
    /// Current time, s.
    pub time: f64,
    /// Completed steps.
    pub step: usize,
    /// Support reactions at the grid nodes after the last step (kN/m), f_int + M a − f_ext.
    pub reaction: Vec<[f64; 2]>,
    /// Nodal displacement increment of the last (sub-)step, per grid node, m.
    pub last_increment: Vec<[f64; 2]>,
    /// The nodes outside which `reaction` and `last_increment` are zero
    /// (increasing), when known; `None`: any node may hold a value. Lets
    /// the commit write the nodes of the body only.
    pub nodal_results_at: Option<Vec<u32>>,
    /// Accumulated plastic dissipation D (theory D43), kJ per metre run.
    pub dissipated_energy: f64,
    /// Work W of the external loads on the soil so far, kJ per metre run: the
    /// follower pressures (trapezoidal per step) and the rigid bodies (their
    /// force on the soil times their prescribed motion, trapezoidal per step;
    /// the penalty springs' own energy, ½ k gap², is left out) and gravity
    /// (−g Σ_p m_p Δy_p per step, with the step's g). Energy balance (theory
    /// §9, M5): W = W_int + ΔK + numerical losses.
    pub external_work: f64,
    /// Σ_p m_p y_p of the committed points (t·m/m), from which a step's
    /// gravity work follows.
    pub mass_height: f64,
    /// Work of the stresses on the strain increments so far (theory D43 with the
    /// total strain increment), kJ per metre run: elastic energy stored plus
    /// plastic dissipation.
    pub internal_work: f64,
    /// Energy taken at the boundary so far, kJ per metre run: the kinetic
    /// energy where the fixed dofs zero the nodal motion (the no-slip base,
    /// rollers; [`crate::integrators::boundary_work`] B1), the friction work
    /// (theory FR5) and the kinetic energy of the points put back on a wall
    /// ([`crate::walls`], theory B2).
    pub boundary_work: f64,
    /// Kinetic energy K0 of the points at t = 0, kJ per metre run.
    pub initial_kinetic_energy: f64,
    /// Points removed after leaving the grid (`[grid] lost_points = "remove"`).
    pub lost_points: Vec<LostPoint>,
    /// Force of every rigid body on the soil at the end of the last step, kN/m.
    pub rigid_force: Vec<[f64; 2]>,
}

/// Build a material law from its scene entry; the problems of an invalid
/// one name the scene field.
pub fn build_material(
    name: &str,
    spec: &MaterialSpec,
) -> Result<Arc<dyn ConstitutiveModel>, Vec<FieldError>> {
    let named = |problems: Vec<ParameterProblem>| {
        problems
            .into_iter()
            .map(|problem| FieldError {
                field: format!("materials.{name}.{}", problem.key),
                message: problem.message,
            })
            .collect::<Vec<_>>()
    };
    Ok(match spec {
        MaterialSpec::LinearElastic(e) => Arc::new(LinearElastic::new(e.youngs_modulus, e.nu)),
        MaterialSpec::Hmc(h) => Arc::new(Hmc::new(*h).map_err(named)?),
        MaterialSpec::VonMises(v) => Arc::new(VonMises::new(*v).map_err(named)?),
    })
}

/// Share of |σ₀| by which an initial stress may lie outside the yield
/// surface (measured by its projection onto the surface, theory D39).
const INITIAL_STRESS_TOLERANCE: f64 = 0.1;

/// An initial stress (`stress0`, `k0`) far outside the yield surface at the
/// start is refused, naming the body's key and the first such point: the
/// first step would return it to the surface in one jump.
fn check_initial_stresses(
    scene: &Scene,
    materials: &[Arc<dyn ConstitutiveModel>],
    particles: &Particles,
    errors: &mut Vec<FieldError>,
) {
    let norm = |s: &[f64; 4]| s.iter().map(|v| v * v).sum::<f64>().sqrt();
    let mut reported = vec![false; scene.body.len()];
    for i in 0..particles.len() {
        let b = particles.body[i] as usize;
        let Some(body) = scene.body.get(b) else {
            continue;
        };
        if reported[b] || (body.stress0.is_none() && body.k0.is_none()) {
            continue;
        }
        let Some(material) = materials.get(particles.material[i] as usize) else {
            continue;
        };
        let stress = &particles.stress[i];
        let projected = material.project_to_surface(stress, &particles.state[i], None);
        let distance = norm(&[
            stress[0] - projected[0],
            stress[1] - projected[1],
            stress[2] - projected[2],
            stress[3] - projected[3],
        ]);
        if distance > INITIAL_STRESS_TOLERANCE * norm(stress) || !distance.is_finite() {
            reported[b] = true;
            let key = if body.k0.is_some() { "k0" } else { "stress0" };
            let x = particles.position[i];
            errors.push(FieldError {
                field: format!("body[{b}].{key}"),
                message: format!(
                    "the initial stress {stress:?} kPa at ({:.4}, {:.4}) m lies far outside the yield surface of material `{}` (its projection onto the surface is {:.3e} kPa away, more than {INITIAL_STRESS_TOLERANCE} of |σ|)",
                    x[0], x[1], body.material, distance
                ),
            });
        }
    }
}

impl Model {
    /// Build the model of a validated scene: seed material points, place
    /// traction and driven points. Geometry problems that only show once
    /// points are seeded (a body with no point, a platen touching none) are
    /// reported as field errors.
    pub fn new(scene: &Scene) -> Result<Self, SceneError> {
        let grid = build_grid(scene);
        let material_names: Vec<String> = scene.materials.keys().cloned().collect();
        let mut errors = Vec::new();
        let mut materials: Vec<Arc<dyn ConstitutiveModel>> = Vec::new();
        for (name, spec) in &scene.materials {
            match build_material(name, spec) {
                Ok(m) => materials.push(m),
                Err(problems) => {
                    errors.extend(problems);
                    materials.push(Arc::new(LinearElastic::new(1.0, 0.0)));
                }
            }
        }
        let particles = seed_particles(scene, &grid, &material_names, &mut errors);
        let driven = build_driven_points(scene, &particles, &mut errors);
        check_initial_stresses(scene, &materials, &particles, &mut errors);
        if !errors.is_empty() {
            return Err(SceneError::Invalid {
                path: scene.scene.name.clone(),
                errors,
            });
        }
        let n_nodes = grid.node_count();
        let constraints = Constraints::from_scene(scene, &grid);
        let state = State {
            traction: TractionPoints::from_scene(scene),
            particles,
            driven,
            pinned_points: Vec::new(),
            time: 0.0,
            step: 0,
            reaction: vec![[0.0; 2]; n_nodes],
            last_increment: vec![[0.0; 2]; n_nodes],
            nodal_results_at: Some(Vec::new()),
            dissipated_energy: 0.0,
            external_work: 0.0,
            internal_work: 0.0,
            boundary_work: 0.0,
            initial_kinetic_energy: 0.0,
            mass_height: 0.0,
            lost_points: Vec::new(),
            rigid_force: Vec::new(),
        };
        let mut model = Model {
            walls: Walls::of(&grid, &constraints),
            constraints,
            friction: crate::friction::FrictionEdges::from_scene(scene, &grid),
            compliances: materials
                .iter()
                .map(|m| invert4(&m.elastic_stiffness()))
                .collect(),
            grid,
            materials,
            material_names,
            state,
            settings: Settings::of(scene),
        };
        model.state.mass_height = model.current_mass_height();
        model.state.initial_kinetic_energy = model.kinetic_energy();
        Ok(model)
    }

    /// The analysis type.
    pub fn analysis(&self) -> AnalysisKind {
        self.settings.run.analysis
    }

    /// Whether the run has reached its last step / end time.
    pub fn finished(&self) -> bool {
        match self.analysis() {
            AnalysisKind::Explicit => {
                self.state.time >= self.settings.run.end_time.unwrap_or(0.0) * (1.0 - 1e-12)
            }
            AnalysisKind::ImplicitDynamic if self.settings.solver.adaptive() => {
                self.state.time >= self.settings.run.end_time_or_steps() * (1.0 - 1e-12)
            }
            // the last path step is displacement controlled to the end (PF5)
            AnalysisKind::QuasiStatic if self.settings.solver.follows_path() => {
                let dt = self.settings.run.dt.unwrap_or(1.0);
                self.state.time >= self.settings.run.end_time_or_steps() - 1e-6 * dt
            }
            _ => self.state.step >= self.settings.run.steps.unwrap_or(0),
        }
    }

    /// True when every material has a symmetric tangent (Cholesky allowed).
    pub fn symmetric_tangent(&self) -> bool {
        self.materials.iter().all(|m| m.has_symmetric_tangent())
    }

    /// The stresses whose internal force (theory D11) the grid receives:
    /// `stress` itself, or with B-bar each point's mean stress replaced by its
    /// cell's volume average ([`crate::volumetric`] B4).
    pub fn force_stresses<'a>(
        &self,
        bins: &crate::transfer::ParticleBins,
        stress: &'a [crate::constitutive::Voigt],
    ) -> std::borrow::Cow<'a, [crate::constitutive::Voigt]> {
        if self.b_bar() {
            std::borrow::Cow::Owned(crate::volumetric::force_stresses(
                bins,
                &self.state.particles.volume,
                stress,
            ))
        } else {
            std::borrow::Cow::Borrowed(stress)
        }
    }

    /// True when the scene takes each point's dilatation as its cell's
    /// average (`[grid] volumetric = "b_bar"`, [`crate::volumetric`]).
    pub fn b_bar(&self) -> bool {
        self.settings.grid.volumetric == crate::scene::VolumetricTreatment::BBar
    }

    /// Largest Young's modulus of the materials, kPa.
    pub fn max_youngs_modulus(&self) -> f64 {
        self.settings.stiffest_material.map_or(0.0, |(e, _)| e)
    }

    /// The double-mapping mode in force: `auto` means `increment` with
    /// bilinear cells when some material can soften (the paper's use), else
    /// `off`: GIMP has no cell-crossing error to smooth, and theory decision
    /// 27 keeps the mapping off there (it made the biaxial bands irregular,
    /// and it adds stress without work, on which an explicit run can feed).
    pub fn double_mapping(&self) -> DoubleMapping {
        let bilinear = self.settings.grid.shape_functions == ShapeFunctionChoice::Bilinear;
        match self.settings.smoothing.double_mapping {
            DoubleMapping::Auto if bilinear && self.materials.iter().any(|m| m.can_soften()) => {
                DoubleMapping::Increment
            }
            DoubleMapping::Auto => DoubleMapping::Off,
            mode => mode,
        }
    }

    /// Material points a cell needs to carry traction points (half the seeding count).
    pub fn traction_min_points(&self) -> usize {
        (self.settings.grid.points_per_cell.pow(2) / 2).max(1)
    }

    /// Σ ½ m_p |v_p|², kJ per metre run.
    pub fn kinetic_energy(&self) -> f64 {
        let p = &self.state.particles;
        (0..p.len())
            .map(|i| 0.5 * p.mass[i] * (p.velocity[i][0].powi(2) + p.velocity[i][1].powi(2)))
            .sum()
    }

    /// Elastic strain energy Σ ½ V_p σ_pᵀ C σ_p, kJ per metre run (C = D⁻¹ of the
    /// particle's material).
    pub fn strain_energy(&self) -> f64 {
        let p = &self.state.particles;
        let compliance: Vec<Mat4> = p
            .material
            .iter()
            .map(|&m| self.compliances[m as usize])
            .collect();
        crate::metrics::elastic_energy(
            &p.volume,
            &p.stress,
            crate::metrics::ComplianceSource::PerPoint(&compliance),
        )
        .unwrap_or(f64::NAN)
    }

    /// Σ_p m_p y_p over the material points, t·m per metre run.
    pub fn current_mass_height(&self) -> f64 {
        let p = &self.state.particles;
        p.mass.iter().zip(&p.position).map(|(m, x)| m * x[1]).sum()
    }

    /// Add the work of gravity `g` (along −y) over the step that moved the
    /// points from [`State::mass_height`] to their present positions:
    /// −g Σ_p m_p Δy_p, which equals Σ_i f_i^g · Δu_i of the body forces
    /// (theory D10) because a point moves by Σ_i N_ip Δu_i.
    pub(crate) fn account_gravity_work(&mut self, g: f64) {
        let now = self.current_mass_height();
        self.state.external_work -= g * (now - self.state.mass_height);
        self.state.mass_height = now;
    }

    /// Add the work of the rigid bodies on the soil over the step that began at
    /// `start`: ½ (R_n + R_n+1)·(X̄_n+1 − X̄_n) per body (R and the anchor X̄ of
    /// theory D40), the anchor's motion being (D(t_n+1) − D(t_n)) v with the
    /// start ramp's D (v Δt without ramp).
    pub fn account_rigid_work(&mut self, start: f64) {
        let bodies = self.state.driven.velocity.len();
        self.state.rigid_force.resize(bodies, [0.0; 2]);
        for r in 0..bodies {
            let now = self
                .state
                .driven
                .force_on_soil(r, &self.state.particles, self.state.time);
            let before = self.state.rigid_force[r];
            let v = self.state.driven.velocity[r];
            let travel = self.state.driven.travel(r, start, self.state.time);
            self.state.external_work +=
                0.5 * travel * ((before[0] + now[0]) * v[0] + (before[1] + now[1]) * v[1]);
            self.state.rigid_force[r] = now;
        }
    }

    /// With `[grid] lost_points = "remove"`, drop every material point outside
    /// the grid and record it in [`State::lost_points`]; the rigid-body ties and
    /// [`State::pinned_points`] follow, and the remap is returned for whoever
    /// else holds point indices (`None` when no point was removed). A point a
    /// rigid body is tied to or that is pinned is not dropped, nor is the last
    /// point of the run: the first such point is reported as having left the
    /// grid. With `stop` this does nothing.
    pub fn drop_lost_points(&mut self) -> Result<Option<PointRemap>, StepError> {
        if self.settings.grid.lost_points == LostPointPolicy::Stop {
            return Ok(None);
        }
        let p = &self.state.particles;
        let grid = &self.grid;
        if p.position.par_iter().all(|&x| grid.contains(x)) {
            return Ok(None);
        }
        let keep: Vec<bool> = p.position.iter().map(|&x| grid.contains(x)).collect();
        let held = |i: usize| {
            self.state.driven.particle.contains(&Some(i)) || self.state.pinned_points.contains(&i)
        };
        // A run with no material left has nothing to compute: report the first point out.
        let nothing_left = !keep.iter().any(|&k| k);
        if let Some(i) = (0..keep.len()).find(|&i| !keep[i] && (nothing_left || held(i))) {
            return Err(StepError::ParticleLeftGrid {
                particle: i,
                position: p.position[i],
            });
        }
        for (removed, i) in (0..keep.len()).filter(|&i| !keep[i]).enumerate() {
            self.state.lost_points.push(LostPoint {
                step: self.state.step + 1,
                index: i - removed,
                position: p.position[i],
                velocity: p.velocity[i],
                mass: p.mass[i],
                mean_stress: crate::constitutive::mean_stress(&p.stress[i]),
                plastic_strain_eq: p.state[i].plastic_strain_eq,
            });
        }
        let remap = remap_of(&keep);
        for tie in self.state.driven.particle.iter_mut().flatten() {
            *tie = remap[*tie].unwrap_or(*tie);
        }
        for pinned in &mut self.state.pinned_points {
            *pinned = remap[*pinned].unwrap_or(*pinned);
        }
        self.state.particles.retain(&keep);
        Ok(Some(remap))
    }
}

/// New indices of the kept points, in order.
fn remap_of(keep: &[bool]) -> PointRemap {
    let mut next = 0;
    keep.iter()
        .map(|&k| {
            k.then(|| {
                next += 1;
                next - 1
            })
        })
        .collect()
}

fn build_grid(scene: &Scene) -> Grid {
    let shape_functions = match scene.grid.shape_functions {
        ShapeFunctionChoice::Bilinear => ShapeFunctions::Bilinear,
        ShapeFunctionChoice::Gimp => ShapeFunctions::Gimp {
            half_width: 0.5 * scene.grid.cell_size / scene.grid.points_per_cell as f64,
        },
    };
    Grid {
        origin: scene.grid.origin,
        cell_size: scene.grid.cell_size,
        cells: scene.grid_cells(),
        shape_functions,
    }
}

/// The rigid bodies' tied points, with the penalty factor of the analysis
/// (theory §8.0: β_pen = 1e3 implicit, 10 explicit).
fn build_driven_points(
    scene: &Scene,
    particles: &Particles,
    errors: &mut Vec<FieldError>,
) -> DrivenPoints {
    let youngs: Vec<f64> = scene
        .materials
        .values()
        .map(|m| m.youngs_modulus())
        .collect();
    let explicit = scene.scene.analysis == AnalysisKind::Explicit;
    let penalty_factor = scene
        .solver
        .penalty_factor
        .unwrap_or(if explicit { 10.0 } else { 1e3 });
    DrivenPoints::from_scene(scene, particles, penalty_factor, &youngs).unwrap_or_else(|r| {
        errors.push(FieldError {
            field: format!("bc.rigid[{r}].footprint"),
            message: "must be a non-empty range on the top of its body that selects points".into(),
        });
        DrivenPoints::default()
    })
}
