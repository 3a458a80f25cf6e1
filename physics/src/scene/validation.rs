//! The one place where a parsed scene is checked: [`Scene::validate`] returns
//! every problem with its field path and the allowed range; [`Scene::warnings`]
//! gives advice that does not stop a run.

use std::fmt;

use super::schema::*;
use super::{STEP_COLUMN, STEP_COLUMNS, TIME_COLUMN};
use crate::constitutive::ConstitutiveModel;

/// One problem found in a scene: the field path (`grid.cell_size`,
/// `body[0].box`, …) and what is wrong with it.
#[derive(Debug, Clone, PartialEq)]
pub struct FieldError {
    /// Dotted path of the offending field.
    pub field: String,
    /// What is wrong and what is allowed.
    pub message: String,
}

impl fmt::Display for FieldError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}: {}", self.field, self.message)
    }
}

impl MaterialSpec {
    fn validate(&self, prefix: &str, errors: &mut Vec<FieldError>) {
        match self {
            MaterialSpec::LinearElastic(e) => {
                check(
                    errors,
                    format!("{prefix}.E"),
                    e.youngs_modulus > 0.0,
                    format!("must be > 0 kPa (got {})", e.youngs_modulus),
                );
                check(
                    errors,
                    format!("{prefix}.nu"),
                    e.nu > -1.0 && e.nu < 0.5,
                    format!("must lie in (-1, 0.5) (got {})", e.nu),
                );
                check(
                    errors,
                    format!("{prefix}.density"),
                    e.density > 0.0,
                    format!("must be > 0 t/m³ (got {})", e.density),
                );
            }
            MaterialSpec::Hmc(h) => {
                errors.extend(h.validate().into_iter().map(|problem| FieldError {
                    field: format!("{prefix}.{}", problem.key),
                    message: problem.message,
                }));
            }
            MaterialSpec::VonMises(v) => {
                errors.extend(v.validate().into_iter().map(|problem| FieldError {
                    field: format!("{prefix}.{}", problem.key),
                    message: problem.message,
                }));
            }
        }
    }
}

fn check(
    errors: &mut Vec<FieldError>,
    field: impl Into<String>,
    ok: bool,
    message: impl Into<String>,
) {
    if !ok {
        errors.push(FieldError {
            field: field.into(),
            message: message.into(),
        });
    }
}

/// Number of whole cells of size `h` in `length`, if `length` is a multiple of `h`.
pub(super) fn whole_cells(length: f64, h: f64) -> Option<usize> {
    let n = (length / h).round();
    if n >= 1.0 && (length - n * h).abs() <= 1e-9 * length.abs().max(h) {
        Some(n as usize)
    } else {
        None
    }
}

/// Point-in-polygon test (crossing number); points on the boundary count as inside
/// only up to round-off, so callers seed strictly interior positions.
pub fn polygon_contains(polygon: &[[f64; 2]], x: [f64; 2]) -> bool {
    let mut inside = false;
    let n = polygon.len();
    for i in 0..n {
        let (a, b) = (polygon[i], polygon[(i + 1) % n]);
        if (a[1] > x[1]) != (b[1] > x[1]) {
            let t = (x[1] - a[1]) / (b[1] - a[1]);
            if x[0] < a[0] + t * (b[0] - a[0]) {
                inside = !inside;
            }
        }
    }
    inside
}

impl Scene {
    /// Every semantic problem of the scene (empty when valid).
    pub fn validate(&self) -> Vec<FieldError> {
        let mut e = Vec::new();
        self.validate_analysis(&mut e);
        self.solver
            .validate_linear(&self.output, self.scene.analysis, &mut e);
        let grid_ok = self.validate_grid(&mut e);
        for (name, m) in &self.materials {
            m.validate(&format!("materials.{name}"), &mut e);
        }
        check(
            &mut e,
            "materials",
            !self.materials.is_empty(),
            "at least one material is required",
        );
        self.validate_wave_speeds(&mut e);
        self.validate_solver(&mut e);
        self.validate_limits(&mut e);
        self.validate_bodies(&mut e, grid_ok);
        self.validate_loads(&mut e);
        if grid_ok {
            self.validate_bc(&mut e);
        }
        self.validate_monitors(&mut e, grid_ok);
        self.validate_output(&mut e);
        if let Some(nl) = &self.nonlocal {
            check(
                &mut e,
                "nonlocal.length_scale",
                nl.length_scale > 0.0 && nl.length_scale.is_finite(),
                format!("must be > 0 m (got {})", nl.length_scale),
            );
            check(
                &mut e,
                "nonlocal.cutoff_factor",
                nl.cutoff_factor >= 1.0 && nl.cutoff_factor <= 10.0,
                format!("must lie in [1, 10] (got {})", nl.cutoff_factor),
            );
            check(
                &mut e,
                "nonlocal.tolerance",
                nl.tolerance > 0.0 && nl.tolerance < 1.0,
                "must lie in (0, 1)",
            );
            check(
                &mut e,
                "nonlocal.over_nonlocal",
                (1.0..=3.0).contains(&nl.over_nonlocal),
                format!(
                    "must lie in [1, 3] (got {}; 1 is the plain nonlocal model of theory D35)",
                    nl.over_nonlocal
                ),
            );
            check(
                &mut e,
                "nonlocal.weight_cache_mb",
                nl.weight_cache_mb >= 0.0 && nl.weight_cache_mb <= 1.0e6,
                format!(
                    "must lie in [0, 1e6] MiB (got {}; 0 caches no weights)",
                    nl.weight_cache_mb
                ),
            );
            check(
                &mut e,
                "nonlocal.grid_spacing_factor",
                nl.grid_spacing_factor > 0.0 && nl.grid_spacing_factor <= 1.0,
                format!(
                    "must lie in (0, 1] (got {}; the grid averaging's spacing in units of l_s)",
                    nl.grid_spacing_factor
                ),
            );
            check(
                &mut e,
                "grid.cell_size",
                self.grid.cell_size <= nl.length_scale,
                format!("{} m exceeds the nonlocal length scale {} m: the averaging needs cells no larger than l_s", self.grid.cell_size, nl.length_scale),
            );
        }
        e
    }

    /// Advice that does not stop a run (printed by the CLI, written to `run.json`).
    pub fn warnings(&self) -> Vec<String> {
        let mut w = Vec::new();
        if let Some(nl) = &self.nonlocal {
            if self.grid.cell_size > 0.2 * nl.length_scale {
                w.push(format!(
                    "grid.cell_size {} m > 0.2 l_s = {} m: the paper finds nonlocal results mesh-objective only for h <= 0.2 l_s",
                    self.grid.cell_size,
                    0.2 * nl.length_scale
                ));
            }
        }
        w.extend(self.unused_key_warnings());
        w.extend(self.footprint_off_grid_warnings());
        let surface_contact = self
            .bc
            .rigid
            .iter()
            .any(|r| r.contact == ContactKind::Surface);
        if self.scene.analysis == AnalysisKind::Explicit && surface_contact && self.solver.cfl > 0.9
        {
            w.push(format!(
                "solver.cfl {} > 0.9 with a surface-tied rigid body: explicit runs with contact = \"surface\" were measured stable only up to CFL 0.9",
                self.solver.cfl
            ));
        }
        w
    }

    /// A surface-tied rigid body whose footprint edge lies inside a cell: the
    /// tie's bilinear interpolation holds every node of each cell it touches,
    /// so the body acts about as wide as the whole cells it covers (measured,
    /// elastic: a 1.5 m footing at h = 0.5 m loads within 0.4 % of a 2 m one,
    /// `tests/rigid_contact.rs`). Meshes of one study then differ in the
    /// body's width.
    fn footprint_off_grid_warnings(&self) -> Vec<String> {
        let (h, x0) = (self.grid.cell_size, self.grid.origin[0]);
        let off_grid = |x: f64| {
            let cells = (x - x0) / h;
            (cells - cells.round()).abs() > 1e-6
        };
        self.bc
            .rigid
            .iter()
            .enumerate()
            .filter(|(_, r)| r.contact == ContactKind::Surface)
            .filter(|(_, r)| r.footprint.iter().any(|&x| off_grid(x)))
            .map(|(k, r)| {
                let [lo, hi] = r.footprint;
                let acts_from = x0 + ((lo - x0) / h + 1e-6).floor() * h;
                let acts_to = x0 + ((hi - x0) / h - 1e-6).ceil() * h;
                format!(
                    "bc.rigid.{k}.footprint [{lo}, {hi}] m has an edge inside a cell of h = {h} m: the surface tie holds the whole cells it touches, so the body acts on [{acts_from:.6}, {acts_to:.6}] m ({:.6} m wide instead of {:.6} m); place the edges on grid lines (grid.origin, grid.cell_size)",
                    acts_to - acts_from,
                    hi - lo
                )
            })
            .collect()
    }

    /// Keys set to a non-default value that this analysis does not read
    /// (their range is still checked by [`Scene::validate`]).
    fn unused_key_warnings(&self) -> Vec<String> {
        let defaults = SolverSpec::default();
        let s = &self.solver;
        let mut unused: Vec<&str> = Vec::new();
        match self.scene.analysis {
            AnalysisKind::Explicit => {
                if self.scene.steps.is_some() {
                    unused.push("scene.steps");
                }
                if s.newmark_gamma.is_some() {
                    unused.push("solver.newmark_gamma");
                }
                if s.rho_infinity.is_some() {
                    unused.push("solver.rho_infinity");
                }
                if s.max_iterations.is_some() {
                    unused.push("solver.max_iterations");
                }
                if s.linear_solver != defaults.linear_solver {
                    unused.push("solver.linear_solver");
                }
                if s.predictor != defaults.predictor {
                    unused.push("solver.predictor");
                }
            }
            AnalysisKind::QuasiStatic | AnalysisKind::ImplicitDynamic => {
                if self.scene.end_time.is_some() && !s.adaptive() {
                    unused.push("scene.end_time");
                }
                if s.cfl != defaults.cfl {
                    unused.push("solver.cfl");
                }
                if s.damping != defaults.damping {
                    unused.push("solver.damping");
                }
                if self.scene.analysis == AnalysisKind::QuasiStatic && s.newmark_gamma.is_some() {
                    unused.push("solver.newmark_gamma");
                }
                if self.scene.analysis == AnalysisKind::QuasiStatic && s.rho_infinity.is_some() {
                    unused.push("solver.rho_infinity");
                }
                if self.scene.analysis == AnalysisKind::QuasiStatic
                    && s.predictor != defaults.predictor
                {
                    unused.push("solver.predictor");
                }
            }
        }
        unused
            .into_iter()
            .map(|key| {
                format!(
                    "{key} is set but not used with scene.analysis = \"{}\" (ignored)",
                    self.scene.analysis.key()
                )
            })
            .collect()
    }

    /// `[solver] time_step = "adaptive"` and its tolerance and bounds.
    fn validate_step_control(&self, e: &mut Vec<FieldError>) {
        let s = &self.solver;
        check(
            e,
            "solver.error_tolerance",
            s.error_tolerance > 0.0 && s.error_tolerance < 1.0,
            format!("must lie in (0, 1) (got {})", s.error_tolerance),
        );
        for (field, value) in [("solver.dt_min", s.dt_min), ("solver.dt_max", s.dt_max)] {
            if let Some(v) = value {
                check(
                    e,
                    field,
                    v > 0.0 && v.is_finite(),
                    format!("must be > 0 s (got {v})"),
                );
            }
        }
        if let Some(v) = s.max_correction {
            check(
                e,
                "solver.max_correction",
                v > 0.0 && v.is_finite(),
                format!("must be > 0 cell sizes (got {v})"),
            );
            check(
                e,
                "solver.max_correction",
                !s.follows_path() && self.scene.analysis != AnalysisKind::Explicit,
                "applies to implicit Newton steps without path following (its bordered correction is solved whole)"
                    .to_string(),
            );
        }
        check(
            e,
            "solver.remember_halvings",
            !s.remember_halvings
                || (!s.adaptive()
                    && !s.follows_path()
                    && self.scene.analysis != AnalysisKind::Explicit),
            "applies to fixed implicit steps only (not with time_step = \"adaptive\", path following or explicit runs)"
                .to_string(),
        );
        if !s.adaptive() {
            return;
        }
        check(
            e,
            "solver.time_step",
            self.scene.analysis == AnalysisKind::ImplicitDynamic,
            format!(
                "\"adaptive\" needs scene.analysis = \"implicit_dynamic\" (got \"{}\"; explicit runs take the CFL step)",
                self.scene.analysis.key()
            ),
        );
        if let Some(dt) = self.scene.dt.filter(|dt| *dt > 0.0) {
            let (dt_min, dt_max) = s.step_bounds(dt);
            check(
                e,
                "solver.dt_max",
                dt_min <= dt && dt <= dt_max,
                format!("scene.dt = {dt} s must lie in [dt_min, dt_max] = [{dt_min}, {dt_max}] s"),
            );
        }
    }

    /// `[solver] path_following = "dissipation"` (theory §3.7): a quasi-static
    /// run whose only loading that moves is its rigid bodies, each starting
    /// at full velocity (the travel, not the time, is the unknown).
    fn validate_path_following(&self, e: &mut Vec<FieldError>) {
        let s = &self.solver;
        if let Some(n) = s.path_max_steps {
            check(e, "solver.path_max_steps", n >= 1, "must be >= 1");
        }
        if !s.follows_path() {
            return;
        }
        let field = "solver.path_following";
        check(
            e,
            field,
            self.scene.analysis == AnalysisKind::QuasiStatic,
            format!(
                "\"dissipation\" needs scene.analysis = \"quasi_static\" (got \"{}\"; a dynamic run has time as its parameter)",
                self.scene.analysis.key()
            ),
        );
        check(
            e,
            field,
            !self.bc.rigid.is_empty(),
            "\"dissipation\" follows the travel of rigid bodies, and the scene has no [[bc.rigid]]",
        );
        let moving = [
            ("bc.prescribed", !self.bc.prescribed.is_empty()),
            ("bc.friction", !self.bc.friction.is_empty()),
            ("loads.gravity_ramp", self.loads.gravity_ramp.is_some()),
        ];
        for (key, present) in moving {
            check(
                e,
                key,
                !present,
                "cannot be combined with solver.path_following = \"dissipation\", whose only moving load is the rigid bodies' travel",
            );
        }
        check(
            e,
            "solver.linear_solver",
            matches!(s.linear_solver, LinearSolverChoice::Auto | LinearSolverChoice::Lu),
            format!("must be \"auto\" or \"lu\" with solver.path_following = \"dissipation\" (got {:?}): its bordered system is unsymmetric", s.linear_solver),
        );
        for (i, r) in self.bc.rigid.iter().enumerate() {
            check(
                e,
                format!("bc.rigid[{i}].velocity"),
                r.velocity != [0.0, 0.0],
                "must not be zero with solver.path_following = \"dissipation\": the path is the rigid bodies' travel",
            );
            check(
                e,
                format!("bc.rigid[{i}].ramp_time"),
                r.ramp_time == 0.0,
                format!("must be 0 with solver.path_following = \"dissipation\" (got {}; a quasi-static path has no inertia to start smoothly)", r.ramp_time),
            );
        }
    }

    fn validate_analysis(&self, e: &mut Vec<FieldError>) {
        let a = &self.scene;
        if let Some(dt) = a.dt {
            check(
                e,
                "scene.dt",
                dt > 0.0 && dt.is_finite(),
                format!("must be > 0 s (got {dt})"),
            );
        }
        if let Some(t) = a.end_time {
            check(
                e,
                "scene.end_time",
                t > 0.0 && t.is_finite(),
                format!("must be > 0 s (got {t})"),
            );
        }
        match a.analysis {
            AnalysisKind::Explicit => {
                check(
                    e,
                    "scene.end_time",
                    a.end_time.is_some_and(|t| t > 0.0 && t.is_finite()),
                    "explicit runs need end_time > 0 s",
                );
            }
            AnalysisKind::ImplicitDynamic if self.solver.adaptive() => {
                check(
                    e,
                    "scene.end_time",
                    a.end_time.is_some() || a.steps.is_some_and(|n| n >= 1),
                    "adaptive steps need end_time (or steps >= 1: end at steps × dt)",
                );
                check(
                    e,
                    "scene.dt",
                    a.dt.is_some(),
                    "adaptive steps need a first time step dt > 0 s",
                );
            }
            AnalysisKind::ImplicitDynamic => {
                check(
                    e,
                    "scene.steps",
                    a.steps.is_some_and(|n| n >= 1),
                    "implicit runs need steps >= 1",
                );
                check(
                    e,
                    "scene.dt",
                    a.dt.is_some(),
                    "implicit dynamic runs need a time step dt > 0 s",
                );
                if let Some(dt) = a.dt.filter(|dt| *dt > 0.0) {
                    // the Newmark mass term 4 M / Δt² must stay finite (D15)
                    check(
                        e,
                        "scene.dt",
                        (4.0 / (dt * dt)).is_finite(),
                        format!("{dt} s is too small: the Newmark term 4/Δt² overflows"),
                    );
                }
            }
            AnalysisKind::QuasiStatic => {
                check(
                    e,
                    "scene.steps",
                    a.steps.is_some_and(|n| n >= 1),
                    "implicit runs need steps >= 1",
                );
            }
        }
    }

    fn validate_grid(&self, e: &mut Vec<FieldError>) -> bool {
        let g = &self.grid;
        let before = e.len();
        check(
            e,
            "grid.cell_size",
            g.cell_size > 0.0 && g.cell_size.is_finite(),
            format!("must be > 0 m (got {})", g.cell_size),
        );
        check(
            e,
            "grid.origin",
            g.origin.iter().all(|v| v.is_finite()),
            "must be finite",
        );
        for (c, axis) in ["x", "y"].iter().enumerate() {
            check(
                e,
                format!("grid.size[{c}]"),
                g.size[c] > 0.0 && g.size[c].is_finite(),
                format!("{axis}-size must be > 0 m (got {})", g.size[c]),
            );
        }
        check(
            e,
            "grid.points_per_cell",
            (1..=4).contains(&g.points_per_cell),
            format!("must be 1, 2, 3 or 4 (got {})", g.points_per_cell),
        );
        check(
            e,
            "grid.point_layout",
            g.shape_functions == ShapeFunctionChoice::Bilinear
                || g.point_layout == PointLayout::Uniform,
            "shape_functions = \"gimp\" needs point_layout = \"uniform\" \
             (the point domains must tile the cells)"
                .to_string(),
        );
        check(
            e,
            "grid.volumetric",
            g.volumetric == VolumetricTreatment::Standard || !self.smoothing.restore_forces,
            "volumetric = \"b_bar\" cannot be combined with smoothing.restore_forces = true \
             (the force-restoring correction uses the standard strain operator)"
                .to_string(),
        );
        if let Some(cap) = g.max_point_volume {
            let initial = 1.0 / (g.points_per_cell * g.points_per_cell) as f64;
            check(
                e,
                "grid.max_point_volume",
                cap.is_finite() && cap >= initial,
                format!(
                    "must be a finite number of cell areas no smaller than a point's initial \
                     volume, 1/points_per_cell² = {initial} (got {cap})"
                ),
            );
        }
        if e.len() == before {
            for (c, axis) in ["x", "y"].iter().enumerate() {
                check(
                    e,
                    format!("grid.size[{c}]"),
                    whole_cells(g.size[c], g.cell_size).is_some(),
                    format!(
                        "the {axis}-size {} m is not a whole number of cells of size {} m",
                        g.size[c], g.cell_size
                    ),
                );
            }
            let cells = [g.size[0] / g.cell_size, g.size[1] / g.cell_size];
            check(
                e,
                "grid.cell_size",
                cells[0] * cells[1] <= 5.0e7,
                "the grid would have more than 5e7 cells",
            );
        }
        e.len() == before
    }

    fn validate_solver(&self, e: &mut Vec<FieldError>) {
        let s = &self.solver;
        check(
            e,
            "solver.tolerance_force",
            s.tolerance_force > 0.0 && s.tolerance_force < 1.0,
            "must lie in (0, 1)",
        );
        check(
            e,
            "solver.tolerance_energy",
            s.tolerance_energy > 0.0 && s.tolerance_energy < 1.0,
            "must lie in (0, 1)",
        );
        check(
            e,
            "solver.max_iterations",
            s.max_iterations.is_none_or(|n| n >= 1),
            "must be >= 1",
        );
        check(
            e,
            "solver.max_halvings",
            s.max_halvings <= 10,
            "must be <= 10",
        );
        check(
            e,
            "solver.background_stiffness",
            s.background_stiffness >= 0.0 && s.background_stiffness < 1.0,
            "must lie in [0, 1)",
        );
        if let Some(b) = s.penalty_factor {
            check(
                e,
                "solver.penalty_factor",
                b > 0.0 && b.is_finite(),
                format!("must be > 0 (got {b})"),
            );
        }
        check(
            e,
            "solver.cfl",
            s.cfl > 0.0 && s.cfl <= 1.0,
            format!("must lie in (0, 1] (got {})", s.cfl),
        );
        check(
            e,
            "solver.damping",
            s.damping >= 0.0 && s.damping < 1.0,
            format!("must lie in [0, 1) (got {})", s.damping),
        );
        if let Some(gamma) = s.newmark_gamma {
            check(
                e,
                "solver.newmark_gamma",
                (0.5..=1.0).contains(&gamma),
                format!("must lie in [0.5, 1] (got {gamma})"),
            );
        }
        self.validate_step_control(e);
        self.validate_path_following(e);
        if let Some(rho) = s.rho_infinity {
            check(
                e,
                "solver.rho_infinity",
                (0.0..=1.0).contains(&rho),
                format!("must lie in [0, 1] (got {rho})"),
            );
            check(
                e,
                "solver.rho_infinity",
                s.newmark_gamma.is_none(),
                "selects the generalised-α scheme, which sets its own γ: remove solver.newmark_gamma"
                    .to_string(),
            );
        }
        if self.scene.analysis == AnalysisKind::Explicit {
            if let Some(dt) = self.scene.dt {
                if let Some(limit) = self.critical_time_step() {
                    check(
                        e,
                        "scene.dt",
                        dt <= limit,
                        format!("{dt} s exceeds the explicit stability limit h/c_p = {limit:.4e} s (theory D20)"),
                    );
                }
            }
        }
    }

    /// Smallest h / c_p over the materials in use (theory D20 with α = 1, v = 0).
    pub fn critical_time_step(&self) -> Option<f64> {
        self.materials
            .values()
            .map(|m| {
                let modulus =
                    crate::constitutive::LinearElastic::new(m.youngs_modulus(), m.poisson_ratio())
                        .p_wave_modulus();
                self.grid.cell_size / (modulus / m.density()).sqrt()
            })
            .filter(|v| v.is_finite() && *v > 0.0)
            .min_by(f64::total_cmp)
    }

    fn validate_bodies(&self, e: &mut Vec<FieldError>, grid_ok: bool) {
        check(
            e,
            "body",
            !self.body.is_empty(),
            "at least one [[body]] is required",
        );
        let lo = self.grid.origin;
        let hi = [lo[0] + self.grid.size[0], lo[1] + self.grid.size[1]];
        let tol = 1e-9 * self.grid.cell_size.abs();
        for (i, b) in self.body.iter().enumerate() {
            let f = format!("body[{i}]");
            check(
                e,
                format!("{f}.material"),
                self.materials.contains_key(&b.material),
                format!("unknown material `{}`", b.material),
            );
            match (&b.rectangle, &b.polygon) {
                (Some(_), Some(_)) => e.push(FieldError {
                    field: f.clone(),
                    message: "give either `box` or `polygon`, not both".into(),
                }),
                (None, None) => e.push(FieldError {
                    field: f.clone(),
                    message: "needs a `box` or a `polygon`".into(),
                }),
                (Some([a, c]), None) => {
                    check(
                        e,
                        format!("{f}.box"),
                        a[0] < c[0] && a[1] < c[1],
                        "must be [[x_min, y_min], [x_max, y_max]] with min < max",
                    );
                }
                (None, Some(p)) => {
                    check(
                        e,
                        format!("{f}.polygon"),
                        p.len() >= 3,
                        "needs at least 3 vertices",
                    );
                    if p.len() >= 3 {
                        if let Some(message) = polygon_defect(p) {
                            e.push(FieldError {
                                field: format!("{f}.polygon"),
                                message,
                            });
                        }
                    }
                }
            }
            let outline = b.outline();
            if grid_ok && !outline.is_empty() {
                let inside = outline.iter().all(|p| {
                    p[0] >= lo[0] - tol
                        && p[1] >= lo[1] - tol
                        && p[0] <= hi[0] + tol
                        && p[1] <= hi[1] + tol
                });
                let key = if b.rectangle.is_some() {
                    "box"
                } else {
                    "polygon"
                };
                check(
                    e,
                    format!("{f}.{key}"),
                    inside,
                    format!(
                        "the body lies (partly) outside the grid [{}, {}] × [{}, {}] m",
                        lo[0], hi[0], lo[1], hi[1]
                    ),
                );
            }
            if let Some(k0) = &b.k0 {
                check(e, format!("{f}.k0.k0"), k0.k0 >= 0.0, "must be >= 0");
                check(
                    e,
                    format!("{f}.k0.unit_weight"),
                    k0.unit_weight >= 0.0,
                    "must be >= 0 kN/m³",
                );
            }
            if let Some(s) = b.stress0 {
                check(
                    e,
                    format!("{f}.stress0"),
                    s.iter().all(|v| v.is_finite()),
                    "must be finite",
                );
            }
            let names: Vec<String> = self
                .body
                .iter()
                .enumerate()
                .map(|(j, b)| b.name_or_default(j))
                .collect();
            check(
                e,
                format!("{f}.name"),
                names.iter().filter(|n| **n == names[i]).count() == 1,
                "body names must be unique",
            );
        }
    }

    fn validate_loads(&self, e: &mut Vec<FieldError>) {
        check(
            e,
            "loads.gravity",
            self.loads.gravity.is_finite(),
            "must be finite",
        );
        if let Some(r) = &self.loads.gravity_ramp {
            check(
                e,
                "loads.gravity_ramp.interval",
                r.interval > 0.0,
                "must be > 0 s",
            );
            check(
                e,
                "loads.gravity_ramp.increment",
                r.increment.is_finite(),
                "must be finite",
            );
            check(
                e,
                "loads.gravity_ramp.max",
                r.max.is_finite(),
                "must be finite",
            );
        }
    }

    /// Check a grid line reference: it parses, lies on a grid line inside the grid.
    fn check_line(&self, e: &mut Vec<FieldError>, field: String, text: &str) -> Option<GridLine> {
        match GridLine::parse(text) {
            Err(m) => {
                e.push(FieldError { field, message: m });
                None
            }
            Ok(line) => {
                let h = self.grid.cell_size;
                let offset = (line.value - self.grid.origin[line.axis]) / h;
                let on_line = (offset - offset.round()).abs() < 1e-6
                    && offset.round() >= 0.0
                    && offset.round() <= self.grid_cells()[line.axis] as f64;
                check(e, field, on_line, format!("`{text}` selects no grid node: it must be a grid line inside the grid (cell size {h} m)"));
                on_line.then_some(line)
            }
        }
    }

    /// `[[bc.friction]]`: μ ≥ 0, a line on the grid's edge that no fixed or
    /// prescribed condition also holds.
    fn validate_friction(&self, e: &mut Vec<FieldError>) {
        for (i, f) in self.bc.friction.iter().enumerate() {
            let field = format!("bc.friction[{i}]");
            check(
                e,
                format!("{field}.mu"),
                f.mu >= 0.0 && f.mu.is_finite(),
                format!("must be >= 0 (got {})", f.mu),
            );
            let Some(line) = self.check_line(e, format!("{field}.line"), &f.line) else {
                continue;
            };
            let cells = self.grid_cells()[line.axis] as f64;
            let index = ((line.value - self.grid.origin[line.axis]) / self.grid.cell_size).round();
            check(
                e,
                format!("{field}.line"),
                index == 0.0 || index == cells,
                format!(
                    "`{}` must be an edge of the grid (the soil lies on one side of it)",
                    f.line
                ),
            );
            let same = |text: &str| GridLine::parse(text).is_ok_and(|l| l == line);
            let others = self
                .bc
                .fixed
                .iter()
                .enumerate()
                .filter(|(_, x)| same(&x.line));
            for (k, _) in others {
                e.push(FieldError {
                    field: format!("{field}.line"),
                    message: format!(
                        "`{}` is also held by bc.fixed[{k}]: a line is either fixed or frictional",
                        f.line
                    ),
                });
            }
            for (k, _) in self
                .bc
                .prescribed
                .iter()
                .enumerate()
                .filter(|(_, x)| same(&x.line))
            {
                e.push(FieldError {
                    field: format!("{field}.line"),
                    message: format!("`{}` is also driven by bc.prescribed[{k}]", f.line),
                });
            }
        }
    }

    fn validate_bc(&self, e: &mut Vec<FieldError>) {
        for (i, f) in self.bc.fixed.iter().enumerate() {
            self.check_line(e, format!("bc.fixed[{i}].line"), &f.line);
            check(
                e,
                format!("bc.fixed[{i}].dofs"),
                !f.dofs.is_empty(),
                "must list at least one of \"x\", \"y\"",
            );
        }
        for (i, p) in self.bc.prescribed.iter().enumerate() {
            self.check_line(e, format!("bc.prescribed[{i}].line"), &p.line);
            check(
                e,
                format!("bc.prescribed[{i}].rate"),
                p.rate.is_finite() && p.gradient.iter().all(|g| g.is_finite()),
                "must be finite",
            );
            check_ramp_time(e, format!("bc.prescribed[{i}].ramp_time"), p.ramp_time);
        }
        self.validate_friction(e);
        self.validate_dof_conflicts(e);
        self.validate_rigid_line_conflicts(e);
        self.validate_pressure_duplicates(e);
        for (i, p) in self.bc.pressure.iter().enumerate() {
            let f = format!("bc.pressure[{i}]");
            match self.body_index(p.body.as_deref()) {
                None => e.push(FieldError {
                    field: format!("{f}.body"),
                    message: format!("no body named `{}`", p.body.clone().unwrap_or_default()),
                }),
                Some(b) => self.validate_pressure_place(e, &f, p, &self.body[b]),
            }
            check(e, format!("{f}.p"), p.p.is_finite(), "must be finite");
        }
        let mut names = Vec::new();
        for (i, r) in self.bc.rigid.iter().enumerate() {
            let f = format!("bc.rigid[{i}]");
            check(
                e,
                format!("{f}.name"),
                !names.contains(&&r.name),
                format!("duplicate rigid body name `{}`", r.name),
            );
            names.push(&r.name);
            match self.body_index(r.body.as_deref()) {
                None => e.push(FieldError {
                    field: format!("{f}.body"),
                    message: format!("no body named `{}`", r.body.clone().unwrap_or_default()),
                }),
                Some(b) => {
                    let bounds = self.body[b].bounds();
                    let fp = r.footprint;
                    check(
                        e,
                        format!("{f}.footprint"),
                        fp[0] < fp[1] && fp[0] < bounds[1][0] && fp[1] > bounds[0][0],
                        format!("[{}, {}] must be an interval (min < max) overlapping the body's x-range [{}, {}] m", fp[0], fp[1], bounds[0][0], bounds[1][0]),
                    );
                }
            }
            check(
                e,
                format!("{f}.velocity"),
                r.velocity.iter().all(|v| v.is_finite()),
                "must be finite",
            );
            check_ramp_time(e, format!("{f}.ramp_time"), r.ramp_time);
        }
    }

    /// A pressure names a side of a `box` body or edges of a `polygon` body.
    fn validate_pressure_place(
        &self,
        e: &mut Vec<FieldError>,
        field: &str,
        p: &PressureSpec,
        body: &BodySpec,
    ) {
        match (p.side, p.edges, &body.polygon) {
            (Some(_), None, _) => check(
                e,
                format!("{field}.side"),
                body.rectangle.is_some(),
                "`side` needs a `box` body (use `edges` on a polygon body)",
            ),
            (None, Some([first, last]), Some(polygon)) => check(
                e,
                format!("{field}.edges"),
                first <= last && last < polygon.len(),
                format!(
                    "[{first}, {last}] must satisfy first <= last < {} (the polygon's edge count)",
                    polygon.len()
                ),
            ),
            (None, Some(_), None) => check(
                e,
                format!("{field}.edges"),
                false,
                "`edges` needs a `polygon` body (use `side` on a box body)",
            ),
            _ => check(
                e,
                field,
                false,
                "give exactly one of `side` (box body) or `edges` (polygon body)",
            ),
        }
    }

    fn validate_output(&self, e: &mut Vec<FieldError>) {
        for (i, t) in self.output.snapshot_times.iter().enumerate() {
            check(
                e,
                format!("output.snapshot_times[{i}]"),
                t.is_finite() && *t >= 0.0,
                format!("must be a time >= 0 s (got {t})"),
            );
        }
    }

    fn validate_monitors(&self, e: &mut Vec<FieldError>, grid_ok: bool) {
        let lo = self.grid.origin;
        let hi = [lo[0] + self.grid.size[0], lo[1] + self.grid.size[1]];
        let mut seen = Vec::new();
        let mut columns: Vec<String> = [STEP_COLUMN, TIME_COLUMN]
            .iter()
            .chain(STEP_COLUMNS.iter())
            .map(|c| c.to_string())
            .collect();
        for (i, m) in self.monitor.iter().enumerate() {
            let f = format!("monitor[{i}]");
            let unique = !m.name.is_empty() && !seen.contains(&&m.name);
            check(
                e,
                format!("{f}.name"),
                unique,
                "must be a non-empty, unique column name",
            );
            let free = !matches!(m.name.as_str(), "step" | "time");
            check(
                e,
                format!("{f}.name"),
                free,
                "`step` and `time` are reserved column names",
            );
            // another name can still end in the same column (`load_kN_per`
            // of a length beside `load` of a force)
            let column = m.column();
            check(
                e,
                format!("{f}.name"),
                !(unique && free && columns.contains(&column)),
                format!("its curve.csv column `{column}` (the name and the unit) is taken by another column"),
            );
            seen.push(&m.name);
            columns.push(column);
            check(
                e,
                format!("{f}.scale"),
                m.scale.is_finite() && m.offset.is_finite(),
                "scale and offset must be finite",
            );
            match m.kind {
                MonitorKind::PointDisplacement
                | MonitorKind::PointVelocity
                | MonitorKind::PointStress
                | MonitorKind::NeighbourhoodStress => match m.point {
                    None => e.push(FieldError {
                        field: format!("{f}.point"),
                        message: "this monitor kind needs `point = [x, y]`".into(),
                    }),
                    Some(p) => check(
                        e,
                        format!("{f}.point"),
                        p[0] >= lo[0] && p[0] <= hi[0] && p[1] >= lo[1] && p[1] <= hi[1],
                        format!("{p:?} lies outside the grid"),
                    ),
                },
                MonitorKind::Reaction => match &m.line {
                    None => e.push(FieldError {
                        field: format!("{f}.line"),
                        message: "`reaction` needs `line = \"x=<value>\"` or `\"y=<value>\"`"
                            .into(),
                    }),
                    Some(l) => {
                        if grid_ok {
                            self.check_line(e, format!("{f}.line"), l);
                        }
                    }
                },
                MonitorKind::RigidForce | MonitorKind::RigidDisplacement => {
                    let ok = m
                        .rigid
                        .as_ref()
                        .is_some_and(|r| self.bc.rigid.iter().any(|b| &b.name == r));
                    check(
                        e,
                        format!("{f}.rigid"),
                        ok,
                        "must name a [[bc.rigid]] entry",
                    );
                }
                _ => {}
            }
            let group = m.kind == MonitorKind::NeighbourhoodStress;
            if m.kind == MonitorKind::PointStress || group {
                check(
                    e,
                    format!("{f}.quantity"),
                    m.quantity.is_some(),
                    "this monitor kind needs `quantity` (sxx, syy, szz, sxy, p, q, kappa, kappa_bar, x or y)",
                );
            }
            if let Some(radius) = m.radius {
                check(
                    e,
                    format!("{f}.radius"),
                    group,
                    "only `neighbourhood_stress` takes a radius",
                );
                check(
                    e,
                    format!("{f}.radius"),
                    radius.is_finite() && radius > 0.0,
                    "must be a length > 0 (m)",
                );
            }
        }
    }
}

/// Why a polygon is not a simple outline (`None` when it is): two edges
/// that are not neighbours cross or touch (a bow-tie), or the area is zero.
fn polygon_defect(p: &[[f64; 2]]) -> Option<String> {
    let n = p.len();
    let twice_area: f64 = (0..n)
        .map(|i| {
            let (a, c) = (p[i], p[(i + 1) % n]);
            a[0] * c[1] - c[0] * a[1]
        })
        .sum();
    if twice_area == 0.0 || !twice_area.is_finite() {
        return Some("the polygon encloses no area".into());
    }
    for i in 0..n {
        for j in i + 1..n {
            let adjacent = j == i + 1 || (i == 0 && j == n - 1);
            let (a, b) = (p[i], p[(i + 1) % n]);
            let (c, d) = (p[j], p[(j + 1) % n]);
            if adjacent {
                // neighbours share a vertex; they must not fold back onto each other
                let shared = if j == i + 1 { b } else { a };
                let (u, w) = if j == i + 1 { (a, d) } else { (b, c) };
                if orientation(u, shared, w) == 0.0
                    && (u[0] - shared[0]) * (w[0] - shared[0])
                        + (u[1] - shared[1]) * (w[1] - shared[1])
                        > 0.0
                {
                    return Some(format!(
                        "edges {i} and {j} fold back onto each other at vertex ({}, {}): the outline must be a simple polygon",
                        shared[0], shared[1]
                    ));
                }
                continue;
            }
            if segments_meet(a, b, c, d) {
                return Some(format!(
                    "edge {i} ({:?} → {:?}) meets edge {j} ({:?} → {:?}): the outline crosses itself (a bow-tie); give the vertices in order around a simple polygon",
                    a, b, c, d
                ));
            }
        }
    }
    None
}

/// Twice the signed area of the triangle a, b, c.
fn orientation(a: [f64; 2], b: [f64; 2], c: [f64; 2]) -> f64 {
    (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
}

/// Whether the closed segments ab and cd share a point.
fn segments_meet(a: [f64; 2], b: [f64; 2], c: [f64; 2], d: [f64; 2]) -> bool {
    let on = |p: [f64; 2], q: [f64; 2], r: [f64; 2]| {
        r[0] >= p[0].min(q[0])
            && r[0] <= p[0].max(q[0])
            && r[1] >= p[1].min(q[1])
            && r[1] <= p[1].max(q[1])
    };
    let (o1, o2) = (orientation(a, b, c), orientation(a, b, d));
    let (o3, o4) = (orientation(c, d, a), orientation(c, d, b));
    if o1 * o2 < 0.0 && o3 * o4 < 0.0 {
        return true;
    }
    (o1 == 0.0 && on(a, b, c))
        || (o2 == 0.0 && on(a, b, d))
        || (o3 == 0.0 && on(c, d, a))
        || (o4 == 0.0 && on(c, d, b))
}

/// A start ramp's time must be a finite number ≥ 0 (0: no ramp).
fn check_ramp_time(e: &mut Vec<FieldError>, field: String, ramp_time: f64) {
    check(
        e,
        field,
        ramp_time.is_finite() && ramp_time >= 0.0,
        format!("must be a finite time >= 0 (got {ramp_time})"),
    );
}

impl Scene {
    /// Every material's wave speed c_p = sqrt((K + 4G/3)/ρ) must be a positive
    /// finite number (it sets the explicit step and the dynamic mass term):
    /// refuses e.g. E = 1e300 with density 1e-300.
    fn validate_wave_speeds(&self, e: &mut Vec<FieldError>) {
        for (name, m) in &self.materials {
            let (young, nu, rho) = (m.youngs_modulus(), m.poisson_ratio(), m.density());
            if !(young > 0.0 && rho > 0.0 && nu > -1.0 && nu < 0.5) {
                continue; // reported by the material's own checks
            }
            let modulus = crate::constitutive::LinearElastic::new(young, nu).p_wave_modulus();
            let speed = (modulus / rho).sqrt();
            check(
                e,
                format!("materials.{name}.E"),
                modulus.is_finite() && speed.is_finite() && speed > 0.0,
                format!(
                    "E = {young} kPa with density = {rho} t/m³ gives the wave speed sqrt((K + 4G/3)/ρ) = {speed} m/s: out of range"
                ),
            );
            let penalty = self.solver.penalty_factor.unwrap_or(1e3) * young;
            check(
                e,
                format!("materials.{name}.E"),
                penalty.is_finite(),
                format!("E = {young} kPa times solver.penalty_factor overflows"),
            );
        }
    }

    fn validate_limits(&self, e: &mut Vec<FieldError>) {
        if let Some(gb) = self.limits.max_memory_gb {
            check(
                e,
                "limits.max_memory_gb",
                gb > 0.0 && gb.is_finite(),
                format!("must be > 0 GB (got {gb})"),
            );
        }
        if let Some(n) = self.limits.max_steps {
            check(e, "limits.max_steps", n >= 1, "must be >= 1");
        }
    }

    /// Two Dirichlet entries that give one dof different values (two
    /// prescribed rates, or fixed and prescribed ≠ 0) are refused naming
    /// both: on a shared line compared at both ends, on crossing lines at
    /// their node.
    fn validate_dof_conflicts(&self, e: &mut Vec<FieldError>) {
        let entries = self.line_conditions();
        let lo = self.grid.origin;
        let hi = [lo[0] + self.grid.size[0], lo[1] + self.grid.size[1]];
        let tol = 1e-9 * self.grid.cell_size;
        let mut reported = Vec::new();
        for (k, b) in entries.iter().enumerate() {
            for a in &entries[..k] {
                if a.component != b.component || a.field == b.field {
                    continue;
                }
                // the nodes the two entries share
                let shared: Vec<[f64; 2]> = if a.line.axis == b.line.axis {
                    if (a.line.value - b.line.value).abs() > tol {
                        continue;
                    }
                    let (axis, v) = (a.line.axis, a.line.value);
                    let other = 1 - axis;
                    let mut ends = [[0.0; 2]; 2];
                    ends[0][axis] = v;
                    ends[1][axis] = v;
                    ends[0][other] = lo[other];
                    ends[1][other] = hi[other];
                    ends.to_vec()
                } else {
                    let mut node = [0.0; 2];
                    node[a.line.axis] = a.line.value;
                    node[b.line.axis] = b.line.value;
                    vec![node]
                };
                let conflict = shared.iter().find(|x| {
                    let (va, vb) = (a.rate_at(**x), b.rate_at(**x));
                    let moving = va != 0.0 || vb != 0.0;
                    (va - vb).abs() > 1e-9 * (va.abs() + vb.abs())
                        || !(va - vb).is_finite()
                        || (moving && a.ramp_time != b.ramp_time)
                });
                if let Some(x) = conflict {
                    if reported.contains(&b.field) {
                        continue;
                    }
                    reported.push(b.field.clone());
                    let dof = match b.component {
                        Component::X => "x",
                        Component::Y => "y",
                    };
                    e.push(FieldError {
                        field: b.field.clone(),
                        message: format!(
                            "contradicts {} on the {dof} displacement of the node at ({}, {}) m: rates {} and {} per unit time, ramp times {} and {} (one dof takes one condition)",
                            a.field,
                            x[0],
                            x[1],
                            a.rate_at(*x),
                            b.rate_at(*x),
                            a.ramp_time,
                            b.ramp_time
                        ),
                    });
                }
            }
        }
    }
}
