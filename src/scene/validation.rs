//! The one place where a parsed scene is checked: [`Scene::validate`] returns
//! every problem with its field path and the allowed range; [`Scene::warnings`]
//! gives advice that does not stop a run.

use std::fmt;

use super::schema::*;
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
        self.validate_solver(&mut e);
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
                    "must lie in [1, 3] (got {}; 1 is the plain nonlocal model of DESIGN D35)",
                    nl.over_nonlocal
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
        let gravity = self.loads.gravity != 0.0 || self.loads.gravity_ramp.is_some();
        for m in &self.monitor {
            if gravity && m.kind == MonitorKind::ExternalWork {
                w.push(format!(
                    "monitor {} (external_work) leaves out the work of gravity",
                    m.name
                ));
            }
        }
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
        match a.analysis {
            AnalysisKind::Explicit => {
                check(
                    e,
                    "scene.end_time",
                    a.end_time.is_some_and(|t| t > 0.0 && t.is_finite()),
                    "explicit runs need end_time > 0 s",
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
        check(
            e,
            "solver.newmark_gamma",
            (0.5..=1.0).contains(&s.newmark_gamma),
            format!("must lie in [0.5, 1] (got {})", s.newmark_gamma),
        );
        if self.scene.analysis == AnalysisKind::Explicit {
            if let Some(dt) = self.scene.dt {
                if let Some(limit) = self.critical_time_step() {
                    check(
                        e,
                        "scene.dt",
                        dt <= limit,
                        format!("{dt} s exceeds the explicit stability limit h/c_p = {limit:.4e} s (DESIGN D20)"),
                    );
                }
            }
        }
    }

    /// Smallest h / c_p over the materials in use (DESIGN D20 with α = 1, v = 0).
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
        }
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
        for (i, m) in self.monitor.iter().enumerate() {
            let f = format!("monitor[{i}]");
            check(
                e,
                format!("{f}.name"),
                !m.name.is_empty() && !seen.contains(&&m.name),
                "must be a non-empty, unique column name",
            );
            check(
                e,
                format!("{f}.name"),
                !matches!(m.name.as_str(), "step" | "time"),
                "`step` and `time` are reserved column names",
            );
            seen.push(&m.name);
            check(
                e,
                format!("{f}.scale"),
                m.scale.is_finite() && m.offset.is_finite(),
                "scale and offset must be finite",
            );
            match m.kind {
                MonitorKind::PointDisplacement
                | MonitorKind::PointVelocity
                | MonitorKind::PointStress => match m.point {
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
            if m.kind == MonitorKind::PointStress {
                check(
                    e,
                    format!("{f}.quantity"),
                    m.quantity.is_some(),
                    "`point_stress` needs `quantity` (sxx, syy, szz, sxy, p or q)",
                );
            }
        }
    }
}
