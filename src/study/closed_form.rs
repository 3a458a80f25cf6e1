//! Closed-form references of a study: the parameters given in the spec, or
//! read from each run's resolved scene after checking that the closed form
//! describes that scene (otherwise the run gets no reference, and the reason).

use serde::Deserialize;

use crate::closed_form::{constrained_modulus, Column};
use crate::scene::{
    AnalysisKind, BodySpec, Component, ElasticSpec, GridLine, LoadSpec, MaterialSpec, Scene,
    VelocityProfile,
};

/// Closed forms a spec can name.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum ClosedFormName {
    /// First mode of a fixed–free elastic bar (theory §8.4).
    BarVibration,
    /// Large-strain settlement of an elastic column under its own (ramped)
    /// weight, quasi-static (`validation/elastic/soft_column.toml`).
    ColumnSettlement,
}

/// Parameters of the bar closed form: u_top(t) = (v0/ω) sin ωt, ω = π c / (2H),
/// period T = 4H/c (initial velocity v0 sin(π y / 2H), theory §8.4).
#[derive(Clone, Copy, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct BarVibration {
    /// Bar height H, m.
    pub height: f64,
    /// Wave speed c = √(E/ρ), m/s.
    pub wave_speed: f64,
    /// Top velocity amplitude v0 of the initial profile, m/s.
    pub velocity: f64,
}

impl BarVibration {
    /// Angular frequency ω = π c / (2H), rad/s.
    pub fn omega(&self) -> f64 {
        std::f64::consts::PI * self.wave_speed / (2.0 * self.height)
    }

    /// Period T = 4H/c, s.
    pub fn period(&self) -> f64 {
        4.0 * self.height / self.wave_speed
    }

    /// Top displacement u(H, t) = (v0/ω) sin ωt, m.
    pub fn top_displacement(&self, t: f64) -> f64 {
        self.velocity / self.omega() * (self.omega() * t).sin()
    }

    /// Largest strain amplitude v0/c for which the small-strain closed form
    /// is used (at 0.04 the measured response differs from it by 8–35 %).
    pub const MAX_STRAIN: f64 = 1e-3;

    /// The parameters of a scene the closed form describes: one elastic box
    /// body in uniaxial strain (ν = 0, or rollers on both of its sides),
    /// fixed base, free top, no loads, the quarter-sine initial velocity of
    /// a small strain amplitude, integrated in time. The wave speed is the
    /// P-wave speed √(M/ρ), M = E(1 − ν)/((1 + ν)(1 − 2ν)) (√(E/ρ) at ν = 0).
    pub fn from_scene(scene: &Scene) -> Result<Self, String> {
        if scene.scene.analysis == AnalysisKind::QuasiStatic {
            return Err(
                "the bar closed form is a free vibration; the scene is quasi-static".into(),
            );
        }
        let (body, elastic) = uniaxial_elastic_column(scene)?;
        if body.velocity_profile != VelocityProfile::QuarterSineY {
            return Err("the bar closed form needs velocity_profile = \"quarter_sine_y\"".into());
        }
        let v0 = match body.velocity0 {
            Some([vx, vy]) if vx == 0.0 && vy != 0.0 => vy,
            _ => return Err("the bar closed form needs velocity0 = [0, v0] with v0 ≠ 0".into()),
        };
        if has_gravity(&scene.loads) {
            return Err("the bar closed form has no gravity".into());
        }
        let [lo, hi] = body.bounds();
        let c = (p_wave_modulus(elastic) / elastic.density).sqrt();
        let strain = v0.abs() / c;
        if strain > Self::MAX_STRAIN {
            return Err(format!(
                "the small-strain closed form needs the strain amplitude v0/c ≤ {:e}; here {strain:.3e} (v0 = {v0} m/s, c = {c:.4} m/s)",
                Self::MAX_STRAIN
            ));
        }
        Ok(Self {
            height: hi[1] - lo[1],
            wave_speed: c,
            velocity: v0,
        })
    }
}

/// The large-strain settlement of an elastic column under its own weight,
/// in uniaxial strain ([`Column::settlement`]), in static equilibrium at the
/// scene's gravity g(t) (quasi-static runs).
#[derive(Clone, Debug, PartialEq)]
pub struct ColumnSettlement {
    /// Height, constrained modulus and density of the column.
    pub column: Column,
    /// The scene's gravity, for g(t).
    pub loads: LoadSpec,
}

impl ColumnSettlement {
    /// Settlement s(g) of the top at gravity g, m (positive down).
    pub fn settlement(&self, g: f64) -> f64 {
        self.column.settlement(g)
    }

    /// Vertical displacement of the top at time t, −s(g(t)), m.
    pub fn top_displacement(&self, t: f64) -> f64 {
        -self.settlement(self.loads.gravity_at(t))
    }

    /// The parameters of a scene the closed form describes: a quasi-static
    /// scene of one elastic box body in uniaxial strain (ν = 0, or rollers
    /// on both of its sides), fixed base, loaded by gravity only, stress-free
    /// and at rest at the start.
    pub fn from_scene(scene: &Scene) -> Result<Self, String> {
        if scene.scene.analysis != AnalysisKind::QuasiStatic {
            return Err("the column closed form is the static equilibrium; the scene is dynamic (it oscillates about it)".into());
        }
        let (body, elastic) = uniaxial_elastic_column(scene)?;
        if body.velocity0.is_some_and(|v| v != [0.0, 0.0]) {
            return Err("the column closed form starts at rest".into());
        }
        if !has_gravity(&scene.loads) {
            return Err("the column closed form needs gravity".into());
        }
        let [lo, hi] = body.bounds();
        Ok(Self {
            column: Column {
                height: hi[1] - lo[1],
                modulus: p_wave_modulus(elastic),
                density: elastic.density,
            },
            loads: scene.loads.clone(),
        })
    }
}

/// A closed form with its parameters.
#[derive(Clone, Debug, PartialEq)]
pub enum ClosedForm {
    /// [`BarVibration`].
    Bar(BarVibration),
    /// [`ColumnSettlement`].
    Column(ColumnSettlement),
}

impl ClosedForm {
    /// The closed form `name` of `scene`, or why it does not describe it.
    pub fn from_scene(name: ClosedFormName, scene: &Scene) -> Result<Self, String> {
        match name {
            ClosedFormName::BarVibration => BarVibration::from_scene(scene).map(Self::Bar),
            ClosedFormName::ColumnSettlement => {
                ColumnSettlement::from_scene(scene).map(Self::Column)
            }
        }
    }

    /// The reference value at time t.
    pub fn value(&self, t: f64) -> f64 {
        match self {
            Self::Bar(b) => b.top_displacement(t),
            Self::Column(c) => c.top_displacement(t),
        }
    }

    /// The period, s (NaN: not periodic).
    pub fn period(&self) -> f64 {
        match self {
            Self::Bar(b) => b.period(),
            Self::Column(_) => f64::NAN,
        }
    }

    /// One line for the report.
    pub fn describe(&self) -> String {
        match self {
            Self::Bar(b) => format!(
                "closed form `bar_vibration` (H = {} m, c = {:.4} m/s, v0 = {} m/s, T = {:.4e} s)",
                b.height,
                b.wave_speed,
                b.velocity,
                b.period()
            ),
            Self::Column(c) => format!(
                "closed form `column_settlement` (H = {} m, M = {:.4} kPa, ρ = {} t/m³; s = {:.5} m at the final gravity {} m/s²)",
                c.column.height,
                c.column.modulus,
                c.column.density,
                c.settlement(c.loads.gravity_ramp.as_ref().map_or(c.loads.gravity, |r| r.max)),
                c.loads.gravity_ramp.as_ref().map_or(c.loads.gravity, |r| r.max),
            ),
        }
    }
}

fn p_wave_modulus(elastic: &ElasticSpec) -> f64 {
    constrained_modulus(elastic.youngs_modulus, elastic.nu)
}

fn has_gravity(loads: &LoadSpec) -> bool {
    loads.gravity != 0.0 || loads.gravity_ramp.as_ref().is_some_and(|r| r.max != 0.0)
}

/// The one body of `scene` if it is an elastic box in uniaxial strain with a
/// fixed base and no other boundary loads.
fn uniaxial_elastic_column(scene: &Scene) -> Result<(&BodySpec, &ElasticSpec), String> {
    let [body] = scene.body.as_slice() else {
        return Err(format!(
            "one body needed, the scene has {}",
            scene.body.len()
        ));
    };
    if body.rectangle.is_none() {
        return Err("the body must be a box".into());
    }
    if body.stress0.is_some() || body.k0.is_some() {
        return Err("the body must start stress-free".into());
    }
    let Some(MaterialSpec::LinearElastic(elastic)) = scene.materials.get(&body.material) else {
        return Err(format!(
            "material `{}` is not linear_elastic",
            body.material
        ));
    };
    let bc = &scene.bc;
    if !(bc.pressure.is_empty() && bc.rigid.is_empty() && bc.prescribed.is_empty()) {
        return Err("no pressures, rigid bodies or prescribed displacements allowed".into());
    }
    let [lo, hi] = body.bounds();
    let tol = 1e-9 * scene.grid.cell_size;
    let fixed = |axis: usize, value: f64, dof: Component| {
        bc.fixed.iter().any(|f| {
            GridLine::parse(&f.line).is_ok_and(|l| l.axis == axis && (l.value - value).abs() <= tol)
                && f.dofs.contains(&dof)
        })
    };
    if !fixed(1, lo[1], Component::Y) {
        return Err(format!("the base y = {} must be fixed in y", lo[1]));
    }
    if elastic.nu != 0.0 && !(fixed(0, lo[0], Component::X) && fixed(0, hi[0], Component::X)) {
        return Err(format!(
            "uniaxial strain needs ν = 0 or rollers (x fixed) on both sides x = {} and x = {}",
            lo[0], hi[0]
        ));
    }
    Ok((body, elastic))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scene(path: &str, overrides: &[&str]) -> Scene {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(path);
        let overrides: Vec<String> = overrides.iter().map(|s| s.to_string()).collect();
        Scene::load(&path, &overrides).unwrap()
    }

    /// The bar's parameters from its scene: c = √(E/ρ) at ν = 0, the P-wave
    /// speed otherwise; a large amplitude or a quasi-static scene is refused
    /// with the reason.
    #[test]
    fn bar_parameters_from_the_scene() {
        let bar =
            BarVibration::from_scene(&scene("validation/elastic/bar_implicit.toml", &[])).unwrap();
        assert_eq!((bar.height, bar.velocity), (1.0, 0.01));
        assert!((bar.wave_speed - 100.0).abs() < 1e-12);
        let nu = BarVibration::from_scene(&scene(
            "validation/elastic/bar_explicit.toml",
            &["materials.bar.nu=0.49"],
        ))
        .unwrap();
        let m: f64 = 1e4 * 0.51 / (1.49 * 0.02);
        assert!((nu.wave_speed / m.sqrt() - 1.0).abs() < 1e-12);
        let large = BarVibration::from_scene(&scene(
            "validation/elastic/bar_implicit.toml",
            &["body.0.velocity0=[0.0, 4.0]"],
        ))
        .unwrap_err();
        assert!(large.contains("strain amplitude"), "{large}");
        let column = BarVibration::from_scene(&scene("validation/elastic/soft_column.toml", &[]))
            .unwrap_err();
        assert!(column.contains("quasi-static"), "{column}");
    }

    /// The soft column settles 0.11219 m at 9.81 m/s² (tests/gimp_column.rs),
    /// along the scene's gravity ramp; a dynamic scene has no such reference.
    #[test]
    fn column_settlement_from_the_scene() {
        let column =
            ColumnSettlement::from_scene(&scene("validation/elastic/soft_column.toml", &[]))
                .unwrap();
        assert!((column.settlement(9.81) - 0.11219).abs() < 1e-5);
        assert!((column.top_displacement(1.0) + column.settlement(9.81)).abs() < 1e-15);
        assert_eq!(column.top_displacement(0.0), 0.0);
        // t = 0.5 s: ten of the twenty gravity increments
        assert!((column.top_displacement(0.5) + column.settlement(4.905)).abs() < 1e-12);
        let dynamic = ColumnSettlement::from_scene(&scene(
            "validation/elastic/soft_column.toml",
            &["scene.analysis=implicit_dynamic"],
        ))
        .unwrap_err();
        assert!(dynamic.contains("dynamic"), "{dynamic}");
        let bar = ColumnSettlement::from_scene(&scene(
            "validation/elastic/bar_implicit.toml",
            &["scene.analysis=quasi_static"],
        ))
        .unwrap_err();
        assert!(bar.contains("rest"), "{bar}");
        let weightless = ColumnSettlement::from_scene(&scene(
            "validation/elastic/soft_column.toml",
            &["loads.gravity_ramp.max=0.0"],
        ))
        .unwrap_err();
        assert!(weightless.contains("gravity"), "{weightless}");
    }
}
