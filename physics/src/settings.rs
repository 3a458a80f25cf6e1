//! The settings of a run that the physics reads, resolved once from the
//! validated scene when the model is built. The integrators, kernels and
//! monitors read these, never the scene; the scene itself stays with the
//! run ([`crate::simulation::Simulation::scene`]) for its outputs.

use crate::scene::{
    Analysis, LoadSpec, LostPointPolicy, NonlocalSpec, Scene, ShapeFunctionChoice, SmoothingSpec,
    SolverSpec, VolumetricTreatment,
};

/// The typed settings of a run ([`Settings::of`] a validated scene): time
/// stepping, solver, loads, grid policy, smoothing and nonlocal averaging.
/// The grid's geometry (origin, cell size, cells) is not here: the
/// [`crate::grid::Grid`] owns it.
#[derive(Debug, Clone)]
pub struct Settings {
    /// Analysis type, time step, step count, end time and the scene's name
    /// (`[scene]`).
    pub run: Analysis,
    /// Newton, linear-solver and explicit settings (`[solver]`).
    pub solver: SolverSpec,
    /// Most Newton iterations of a step: `solver.max_iterations`, or 60 with
    /// nonlocal averaging and 25 without.
    pub max_iterations: usize,
    /// Body forces (`[loads]`).
    pub loads: LoadSpec,
    /// How the grid treats the material points (`[grid]`).
    pub grid: GridPolicy,
    /// Stress smoothing and double mapping (`[smoothing]`).
    pub smoothing: SmoothingSpec,
    /// Nonlocal averaging of the equivalent plastic strain (`[nonlocal]`).
    pub nonlocal: Option<NonlocalSpec>,
    /// Young's modulus (kPa) and Poisson's ratio of the stiffest material,
    /// the reference of the background stiffness (theory D19); `None`
    /// without materials.
    pub stiffest_material: Option<(f64, f64)>,
}

/// The `[grid]` settings about the material points on the grid (its
/// geometry is the [`crate::grid::Grid`]'s).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GridPolicy {
    /// Material points per cell and direction at seeding.
    pub points_per_cell: usize,
    /// Bilinear or GIMP shape functions.
    pub shape_functions: ShapeFunctionChoice,
    /// What happens to a point that leaves the grid.
    pub lost_points: LostPointPolicy,
    /// Each point's own dilatation or its cell's average (B-bar).
    pub volumetric: VolumetricTreatment,
    /// Largest point volume, in cells (`None`: no bound).
    pub max_point_volume: Option<f64>,
}

impl Settings {
    /// The settings of the validated `scene`.
    pub fn of(scene: &Scene) -> Self {
        let grid = &scene.grid;
        Self {
            run: scene.scene.clone(),
            solver: scene.solver.clone(),
            max_iterations: scene.max_iterations(),
            loads: scene.loads.clone(),
            grid: GridPolicy {
                points_per_cell: grid.points_per_cell,
                shape_functions: grid.shape_functions,
                lost_points: grid.lost_points,
                volumetric: grid.volumetric,
                max_point_volume: grid.max_point_volume,
            },
            smoothing: scene.smoothing.clone(),
            nonlocal: scene.nonlocal,
            stiffest_material: scene
                .materials
                .values()
                .max_by(|a, b| a.youngs_modulus().total_cmp(&b.youngs_modulus()))
                .map(|m| (m.youngs_modulus(), m.poisson_ratio())),
        }
    }
}
