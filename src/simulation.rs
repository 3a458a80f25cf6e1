//! A run: the model built from a scene (grid, materials, particles, boundary
//! conditions, monitors), its evolving state, and the time loop that calls
//! one of the integrators every step.

use std::sync::Arc;

use mpm_solvers::{DirectSolver, SolverPolicy};

use crate::bc::{Constraints, DrivenPoints, TractionPoints};
use crate::constitutive::{ConstitutiveModel, LinearElastic, Mat4, ParameterProblem};
use crate::error::RunError;
use crate::grid::{Grid, ShapeFunctions};
use crate::monitor::Monitor;
use crate::particles::Particles;
use crate::profile::Profile;
use crate::scene::{
    AnalysisKind, FieldError, LinearSolverChoice, LostPointPolicy, MaterialSpec, PointLayout,
    Scene, SceneError, ShapeFunctionChoice, VelocityProfile,
};
use crate::transfer;

/// What one completed step did.
#[derive(Clone, Debug, Default)]
pub struct StepReport {
    /// Step number (1-based) after the step.
    pub step: usize,
    /// Time after the step, s.
    pub time: f64,
    /// Time step used, s.
    pub dt: f64,
    /// Newton iterations (implicit; summed over sub-steps), 0 for explicit.
    pub iterations: usize,
    /// Number of sub-steps the step needed (1 without halving).
    pub substeps: usize,
}

/// Receives the run's progress; the CLI writes outputs and a progress bar here.
pub trait Observer {
    /// Called once before the first step (state at step 0).
    fn on_start(&mut self, sim: &Simulation) -> Result<(), RunError>;
    /// Called after every completed step.
    fn on_step(&mut self, sim: &Simulation, report: &StepReport) -> Result<(), RunError>;
}

/// An observer that does nothing (library use, tests).
pub struct NullObserver;

impl Observer for NullObserver {
    fn on_start(&mut self, _: &Simulation) -> Result<(), RunError> {
        Ok(())
    }
    fn on_step(&mut self, _: &Simulation, _: &StepReport) -> Result<(), RunError> {
        Ok(())
    }
}

/// Counts of what the linear solver did (written to `run.json`).
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct SolverUsage {
    /// Factorisations done with sparse Cholesky.
    pub cholesky: usize,
    /// Factorisations done with sparse LU.
    pub lu: usize,
    /// Largest system size, unknowns.
    pub max_unknowns: usize,
    /// Total Newton iterations.
    pub newton_iterations: usize,
    /// Step halvings.
    pub halvings: usize,
    /// Steps accepted on the force criterion alone because the residual had
    /// stagnated (the energy criterion of D18 cannot be met by iterating).
    pub stagnated_steps: usize,
    /// Explicit runs: smallest and largest time step taken, s (before the last
    /// step is shortened to end at `end_time`).
    pub explicit_time_step: Option<(f64, f64)>,
    /// Explicit runs: what limited the stable time step at the last step.
    pub time_step_limited_by: Option<String>,
}

/// A material point dropped from the run after it left the grid
/// (`[grid] lost_points = "remove"`), as it was at that moment.
#[derive(Debug, Clone, serde::Serialize)]
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

/// A run in progress.
pub struct Simulation {
    /// The validated scene.
    pub scene: Scene,
    /// Background grid.
    pub grid: Grid,
    /// Material laws, indexed by particle material id.
    pub materials: Vec<Arc<dyn ConstitutiveModel>>,
    /// Material names, same order.
    pub material_names: Vec<String>,
    /// Material points.
    pub particles: Particles,
    /// Dirichlet conditions of every grid dof.
    pub constraints: Constraints,
    /// Follower-pressure points.
    pub traction: TractionPoints,
    /// Penalty-tied material points of rigid bodies.
    pub driven: DrivenPoints,
    /// Monitors (curve columns).
    pub monitors: Vec<Monitor>,
    /// Current time, s.
    pub time: f64,
    /// Completed steps.
    pub step: usize,
    /// Support reactions at the grid nodes after the last step (kN/m), f_int + M a − f_ext.
    pub reaction: Vec<[f64; 2]>,
    /// Nodal displacement increment of the last (sub-)step, per grid node, m.
    pub last_increment: Vec<[f64; 2]>,
    /// ‖R‖ per Newton iteration of the last converged (sub-)step, kN/m, and the
    /// reference force of DESIGN D18 it was compared with.
    pub last_residuals: (Vec<f64>, f64),
    /// Accumulated plastic dissipation D (DESIGN D43), kJ per metre run.
    pub dissipated_energy: f64,
    /// Points removed after leaving the grid (`[grid] lost_points = "remove"`).
    pub lost_points: Vec<LostPoint>,
    /// Work W of the external loads on the soil so far, kJ per metre run: the
    /// follower pressures (trapezoidal per step) and the rigid bodies (their
    /// force on the soil times their prescribed motion, trapezoidal per step;
    /// the penalty springs' own energy, ½ k gap², is left out). Gravity is not
    /// included. Energy balance (DESIGN §9, M5): W = W_int + ΔK + numerical losses.
    pub external_work: f64,
    /// Work of the stresses on the strain increments so far (DESIGN D43 with the
    /// total strain increment), kJ per metre run: elastic energy stored plus
    /// plastic dissipation.
    pub internal_work: f64,
    /// Force of every rigid body on the soil at the end of the last step, kN/m.
    rigid_force: Vec<[f64; 2]>,
    /// Stage timings.
    pub profile: Profile,
    /// Linear-solver usage counts.
    pub solver_usage: SolverUsage,
    pub(crate) solver: DirectSolver,
    pub(crate) assembler: Option<(Vec<Vec<u32>>, mpm_solvers::Assembler)>,
    /// ε_bg · K_cell^el (DESIGN D19), added to every active cell's tangent block.
    pub(crate) background_block: [f64; 64],
    /// True when every material has a symmetric tangent (Cholesky allowed).
    pub(crate) symmetric_tangent: bool,
    /// Elastic compliance C = D⁻¹ of every material (D22).
    pub(crate) compliances: Vec<Mat4>,
}

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

/// Build a material law from its scene entry (every parameter problem if it is invalid).
pub fn build_material(
    spec: &MaterialSpec,
) -> Result<Arc<dyn ConstitutiveModel>, Vec<ParameterProblem>> {
    Ok(match spec {
        MaterialSpec::LinearElastic(e) => Arc::new(LinearElastic::new(e.youngs_modulus, e.nu)),
        MaterialSpec::Hmc(h) => Arc::new(crate::constitutive::hmc::Hmc::new(*h)?),
    })
}

impl Simulation {
    /// Build a run from a validated scene: seed material points, place traction
    /// and driven points, resolve monitors. Geometry problems that only show
    /// once points are seeded (a body with no point, a platen touching none) are
    /// reported as field errors.
    pub fn new(scene: Scene) -> Result<Self, SceneError> {
        let shape_functions = match scene.grid.shape_functions {
            ShapeFunctionChoice::Bilinear => ShapeFunctions::Bilinear,
            ShapeFunctionChoice::Gimp => ShapeFunctions::Gimp {
                half_width: 0.5 * scene.grid.cell_size / scene.grid.points_per_cell as f64,
            },
        };
        let grid = Grid {
            origin: scene.grid.origin,
            cell_size: scene.grid.cell_size,
            cells: scene.grid_cells(),
            shape_functions,
        };
        let material_names: Vec<String> = scene.materials.keys().cloned().collect();
        let mut errors = Vec::new();
        let mut materials: Vec<Arc<dyn ConstitutiveModel>> = Vec::new();
        for (name, spec) in &scene.materials {
            match build_material(spec) {
                Ok(m) => materials.push(m),
                Err(problems) => {
                    errors.extend(problems.into_iter().map(|problem| FieldError {
                        field: format!("materials.{name}.{}", problem.key),
                        message: problem.message,
                    }));
                    materials.push(Arc::new(LinearElastic::new(1.0, 0.0)));
                }
            }
        }
        let particles = seed_particles(&scene, &grid, &material_names, &mut errors);
        let youngs: Vec<f64> = scene
            .materials
            .values()
            .map(|m| m.youngs_modulus())
            .collect();
        let explicit = scene.scene.analysis == AnalysisKind::Explicit;
        let penalty_factor =
            scene
                .solver
                .penalty_factor
                .unwrap_or(if explicit { 10.0 } else { 1e3 });
        let driven = DrivenPoints::from_scene(&scene, &particles, penalty_factor, &youngs)
            .unwrap_or_else(|r| {
                errors.push(FieldError {
                    field: format!("bc.rigid[{r}].footprint"),
                    message: "must be a non-empty range on the top of its body that selects points"
                        .into(),
                });
                DrivenPoints::default()
            });
        if !errors.is_empty() {
            return Err(SceneError::Invalid {
                path: scene.scene.name.clone(),
                errors,
            });
        }
        let constraints = Constraints::from_scene(&scene, &grid);
        let traction = TractionPoints::from_scene(&scene);
        let symmetric_tangent = materials.iter().all(|m| m.has_symmetric_tangent());
        let compliances: Vec<Mat4> = materials
            .iter()
            .map(|m| invert4(&m.elastic_stiffness()))
            .collect();
        let policy = match scene.solver.linear_solver {
            LinearSolverChoice::Auto => SolverPolicy::Auto,
            LinearSolverChoice::Cholesky => SolverPolicy::Cholesky,
            LinearSolverChoice::Lu => SolverPolicy::Lu,
        };
        let background_block = background_block(&scene, &grid);
        let n_nodes = grid.node_count();
        let mut sim = Simulation {
            grid,
            materials,
            material_names,
            particles,
            constraints,
            traction,
            driven,
            monitors: Vec::new(),
            time: 0.0,
            step: 0,
            reaction: vec![[0.0; 2]; n_nodes],
            last_increment: vec![[0.0; 2]; n_nodes],
            last_residuals: (Vec::new(), 0.0),
            dissipated_energy: 0.0,
            lost_points: Vec::new(),
            external_work: 0.0,
            internal_work: 0.0,
            rigid_force: Vec::new(),
            profile: Profile::default(),
            solver_usage: SolverUsage::default(),
            solver: DirectSolver::new(policy),
            assembler: None,
            background_block,
            symmetric_tangent,
            compliances,
            scene,
        };
        sim.monitors = sim
            .scene
            .monitor
            .iter()
            .map(|m| Monitor::resolve(m, &sim))
            .collect();
        sim.check_fixed_explicit_step()?;
        Ok(sim)
    }

    /// A fixed explicit `scene.dt` above the stability limit of the material
    /// at rest in its initial configuration (wave speed and driven-point
    /// springs, DESIGN D20 and §4) is refused before the run; the velocity term
    /// h/(c + |v|) and later drops are checked every step during the run.
    fn check_fixed_explicit_step(&self) -> Result<(), SceneError> {
        let (AnalysisKind::Explicit, Some(dt)) = (self.analysis(), self.scene.scene.dt) else {
            return Ok(());
        };
        let Ok(shapes) = crate::transfer::shapes_at(&self.grid, &self.particles.position) else {
            return Ok(()); // points outside the grid are reported by the validation
        };
        let bins = crate::transfer::ParticleBins::new(&self.grid, &shapes);
        let mass = crate::transfer::nodal_mass(&self.grid, &bins, &shapes, &self.particles.mass);
        let Ok(driven_shapes) =
            self.driven
                .shapes(&self.grid, &bins, self.traction_min_points(), &shapes)
        else {
            return Ok(());
        };
        let (_, limit, reason) = self.explicit_time_step(&mass, &driven_shapes, false);
        if dt > limit {
            return Err(SceneError::Invalid {
                path: self.scene.scene.name.clone(),
                errors: vec![FieldError {
                    field: "scene.dt".into(),
                    message: format!(
                        "{dt} s exceeds the explicit stability limit {limit:.4e} s of the initial configuration ({reason})"
                    ),
                }],
            });
        }
        Ok(())
    }

    /// The analysis type.
    pub fn analysis(&self) -> AnalysisKind {
        self.scene.scene.analysis
    }

    /// Whether the run has reached its last step / end time.
    pub fn finished(&self) -> bool {
        match self.analysis() {
            AnalysisKind::Explicit => {
                self.time >= self.scene.scene.end_time.unwrap_or(0.0) * (1.0 - 1e-12)
            }
            _ => self.step >= self.scene.scene.steps.unwrap_or(0),
        }
    }

    /// Implicit time step (quasi-static default 1 pseudo-second).
    pub fn implicit_dt(&self) -> f64 {
        self.scene.scene.dt.unwrap_or(1.0)
    }

    /// Advance one step with the scene's integrator.
    pub fn step_once(&mut self) -> Result<StepReport, RunError> {
        let start = self.time;
        let report = match self.analysis() {
            AnalysisKind::QuasiStatic | AnalysisKind::ImplicitDynamic => self.implicit_step(),
            AnalysisKind::Explicit => self.explicit_step(),
        }?;
        self.add_rigid_work(start);
        Ok(report)
    }

    /// Work of the rigid bodies on the soil over the step from `start`:
    /// ½ (R_n + R_n+1)·v Δt per body (R of DESIGN D40).
    fn add_rigid_work(&mut self, start: f64) {
        let bodies = self.driven.velocity.len();
        self.rigid_force.resize(bodies, [0.0; 2]);
        let dt = self.time - start;
        for r in 0..bodies {
            let now = self.driven.force_on_soil(r, &self.particles, self.time);
            let before = self.rigid_force[r];
            let v = self.driven.velocity[r];
            self.external_work +=
                0.5 * dt * ((before[0] + now[0]) * v[0] + (before[1] + now[1]) * v[1]);
            self.rigid_force[r] = now;
        }
    }

    /// Run to the end, reporting every step to `observer`. On a failure the
    /// error names step, time and cause; everything the observer wrote stays.
    pub fn run(&mut self, observer: &mut dyn Observer) -> Result<(), RunError> {
        observer.on_start(self)?;
        while !self.finished() {
            let report = self.step_once()?;
            observer.on_step(self, &report)?;
        }
        Ok(())
    }

    /// With `[grid] lost_points = "remove"`, drop every material point outside
    /// the grid after a (sub-)step and record it in [`Self::lost_points`];
    /// indices held by rigid-body ties and monitors follow. A point that a rigid
    /// body is tied to or a monitor follows is not dropped, nor is the last
    /// point of the run: `Err((index, position))` of the first such point (the
    /// caller reports it as having left the grid). With `stop` this does nothing.
    pub(crate) fn drop_lost_points(&mut self) -> Result<(), (usize, [f64; 2])> {
        if self.scene.grid.lost_points == LostPointPolicy::Stop {
            return Ok(());
        }
        let p = &self.particles;
        let keep: Vec<bool> = p.position.iter().map(|&x| self.grid.contains(x)).collect();
        if keep.iter().all(|&k| k) {
            return Ok(());
        }
        let mut new_index = vec![None; keep.len()];
        let mut next = 0;
        for (old, &k) in keep.iter().enumerate() {
            if k {
                new_index[old] = Some(next);
                next += 1;
            }
        }
        let tied_or_monitored = |i: usize| {
            self.driven.particle.contains(&Some(i))
                || self.monitors.iter().any(|m| m.particle() == Some(i))
        };
        // A run with no material left has nothing to compute: report the first point out.
        let nothing_left = !keep.iter().any(|&k| k);
        if let Some(i) =
            (0..keep.len()).find(|&i| !keep[i] && (nothing_left || tied_or_monitored(i)))
        {
            return Err((i, p.position[i]));
        }
        for (removed, i) in (0..keep.len()).filter(|&i| !keep[i]).enumerate() {
            self.lost_points.push(LostPoint {
                step: self.step + 1,
                index: i - removed,
                position: p.position[i],
                velocity: p.velocity[i],
                mass: p.mass[i],
                mean_stress: crate::constitutive::mean_stress(&p.stress[i]),
                plastic_strain_eq: p.state[i].plastic_strain_eq,
            });
        }
        for tie in self.driven.particle.iter_mut().flatten() {
            if let Some(new) = new_index[*tie] {
                *tie = new;
            }
        }
        for monitor in &mut self.monitors {
            monitor.remap_particle(&new_index);
        }
        self.particles.retain(&keep);
        Ok(())
    }

    /// Material points a cell needs to carry traction points (half the seeding count).
    pub(crate) fn traction_min_points(&self) -> usize {
        (self.scene.grid.points_per_cell.pow(2) / 2).max(1)
    }

    /// Current monitor values, in column order.
    pub fn monitor_values(&self) -> Vec<f64> {
        self.monitors.iter().map(|m| m.value(self)).collect()
    }

    /// Σ ½ m_p |v_p|², kJ per metre run.
    pub fn kinetic_energy(&self) -> f64 {
        let p = &self.particles;
        (0..p.len())
            .map(|i| 0.5 * p.mass[i] * (p.velocity[i][0].powi(2) + p.velocity[i][1].powi(2)))
            .sum()
    }

    /// Elastic strain energy Σ ½ V_p σ_pᵀ C σ_p, kJ per metre run (C = D⁻¹ of the
    /// particle's material).
    pub fn strain_energy(&self) -> f64 {
        let p = &self.particles;
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
}

/// Inverse of a 4×4 matrix (nalgebra LU); zero matrix if singular.
pub fn invert4(m: &Mat4) -> Mat4 {
    let a = nalgebra::Matrix4::from_fn(|i, j| m[i][j]);
    let inv = a.try_inverse().unwrap_or_else(nalgebra::Matrix4::zeros);
    let mut out = [[0.0; 4]; 4];
    for (i, row) in out.iter_mut().enumerate() {
        for (j, v) in row.iter_mut().enumerate() {
            *v = inv[(i, j)];
        }
    }
    out
}

/// ε_bg times the 2×2-Gauss bilinear elastic stiffness of a full cell with the
/// stiffest material's E and its ν (DESIGN D19), over the cell's nodes in
/// row-major order (see `transfer::system_blocks`).
fn background_block(scene: &Scene, grid: &Grid) -> [f64; 64] {
    let mut block = [0.0; 64];
    let reference = scene
        .materials
        .values()
        .max_by(|a, b| a.youngs_modulus().total_cmp(&b.youngs_modulus()));
    let Some(reference) = reference else {
        return block;
    };
    let d = LinearElastic::new(reference.youngs_modulus(), reference.poisson_ratio()).stiffness();
    let h = grid.cell_size;
    let grid = Grid::bilinear(grid.origin, h, grid.cells);
    let g = 0.5 / 3f64.sqrt();
    for (gx, gy) in [(-g, -g), (g, -g), (g, g), (-g, g)] {
        let x = [
            grid.origin[0] + (0.5 + gx) * h,
            grid.origin[1] + (0.5 + gy) * h,
        ];
        let shape = grid.shape_in_cell(0, 0, x);
        transfer::add_particle_stiffness(&mut block, 8, &shape, 0.25 * h * h, &d);
    }
    block
        .iter_mut()
        .for_each(|v| *v *= scene.solver.background_stiffness);
    block
}

/// Fill every body with n×n points per grid cell (DESIGN §2): Gauss–Legendre
/// positions with volumes h² w_i w_j / 4, or sub-cell centres with h²/n².
/// A position belongs to the first body whose outline contains it.
fn seed_particles(
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

fn initial_stress(body: &crate::scene::BodySpec, x: [f64; 2]) -> [f64; 4] {
    let mut s = body.stress0.unwrap_or([0.0; 4]);
    if let Some(k0) = &body.k0 {
        let syy = -k0.unit_weight * (k0.surface_y - x[1]).max(0.0);
        s[0] += k0.k0 * syy;
        s[1] += syy;
        s[2] += k0.k0 * syy;
    }
    s
}

fn initial_velocity(body: &crate::scene::BodySpec, x: [f64; 2]) -> [f64; 2] {
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
