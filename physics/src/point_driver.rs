//! Homogeneous single-material-point tests of the HMC model (theory §5, §8.1):
//! plane-strain biaxial, "triaxial" (σxx = σzz held) and simple shear, with mixed
//! stress/strain control solved by Newton on the consistent tangent (theory D32).
//!
//! The loops are library functions ([`run_biaxial`], [`run_triaxial`],
//! [`run_simple_shear`]); the application's `point` subcommand
//! (`mpm_geo::point_command`) reads its options, calls them and writes the CSV.

use std::path::{Path, PathBuf};

use crate::constitutive::hmc::{Hmc, HmcParameters};
use crate::constitutive::{
    deviatoric_stress, mean_stress, ConstitutiveError, ConstitutiveModel, ParameterProblem,
    PointState, StrengthVariable, Voigt,
};

/// Width of the quarter biaxial specimen w (m, paper §3.1): load F = −σyy·w (kN/m).
pub const BIAXIAL_WIDTH: f64 = 0.03;
/// Height of the quarter biaxial specimen H (m, paper §3.1): εyy = −δ/H.
pub const BIAXIAL_HEIGHT: f64 = 0.05;

/// Newton iterations of the mixed-control loop per step.
const MIXED_CONTROL_ITERATIONS: usize = 50;

/// Errors of the material-point driver (all reported as messages).
#[derive(Debug, thiserror::Error)]
pub enum PointDriverError {
    /// The material file could not be read.
    #[error("cannot read material file {path}: {source}")]
    ReadMaterial {
        /// File given with `--material`.
        path: PathBuf,
        /// Underlying I/O error.
        source: std::io::Error,
    },
    /// The material file or the overrides do not form valid HmcParameters.
    #[error("invalid material definition: {0}")]
    ParseMaterial(String),
    /// A `--set` argument is not `KEY=NUMBER`.
    #[error("invalid --set {0:?}: expected KEY=VALUE with a numeric VALUE")]
    BadOverride(String),
    /// Parameter validation failed (every problem, keys prefixed `material.`).
    #[error("invalid material parameters:\n  {}", material_problems(.0))]
    InvalidParameters(Vec<ParameterProblem>),
    /// A driver option is out of range.
    #[error("invalid option: {0}")]
    InvalidOption(String),
    /// The stress update failed.
    #[error("step {step}: {source}")]
    Constitutive {
        /// Load step (1-based).
        step: usize,
        /// Constitutive error.
        source: ConstitutiveError,
    },
    /// The mixed-control Newton loop did not converge.
    #[error("step {step}: mixed stress/strain control did not converge (stress residual {residual:e} kPa)")]
    MixedControl {
        /// Load step (1-based).
        step: usize,
        /// Largest stress residual (kPa).
        residual: f64,
    },
    /// The CSV could not be written.
    #[error("cannot write {path}: {message}")]
    Write {
        /// Output path.
        path: PathBuf,
        /// Error text.
        message: String,
    },
}

/// One line per problem, `material.<key> = <value> ...`.
fn material_problems(problems: &[ParameterProblem]) -> String {
    problems
        .iter()
        .map(|problem| format!("material.{problem}"))
        .collect::<Vec<_>>()
        .join("\n  ")
}

/// One row of the stress–strain output.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PointRecord {
    /// Step number (0 = initial state).
    pub step: usize,
    /// Total strain [εxx, εyy, εzz, γxy] since the start.
    pub strain: Voigt,
    /// Stress [σxx, σyy, σzz, σxy] (kPa, tension positive).
    pub stress: Voigt,
    /// Mean stress p (kPa, compression positive, theory D1).
    pub mean_stress: f64,
    /// Deviatoric stress q = sqrt(3 J2) (kPa, theory D5).
    pub deviatoric_stress: f64,
    /// Equivalent plastic strain κ (theory D27).
    pub plastic_strain_eq: f64,
    /// Axial load of the quarter biaxial specimen F = −σyy·w (kN/m, w = 0.03 m).
    pub load: f64,
    /// True when the step was plastic.
    pub yielded: bool,
}

/// Parameters from Table 1, overlaid with the keys of an optional TOML file and then with
/// `KEY=VALUE` overrides; validated (prefix `material`).
pub fn load_parameters(
    material: Option<&Path>,
    overrides: &[String],
) -> Result<HmcParameters, PointDriverError> {
    let mut table = match toml::Value::try_from(HmcParameters::table1()) {
        Ok(toml::Value::Table(t)) => t,
        _ => {
            return Err(PointDriverError::ParseMaterial(
                "cannot serialise Table 1".into(),
            ))
        }
    };
    if let Some(path) = material {
        let text =
            std::fs::read_to_string(path).map_err(|source| PointDriverError::ReadMaterial {
                path: path.to_path_buf(),
                source,
            })?;
        let file: toml::Table = toml::from_str(&text)
            .map_err(|e| PointDriverError::ParseMaterial(format!("{}: {e}", path.display())))?;
        for (key, value) in file {
            table.insert(key, value);
        }
    }
    for item in overrides {
        let (key, value) = item
            .split_once('=')
            .ok_or_else(|| PointDriverError::BadOverride(item.clone()))?;
        let value: f64 = value
            .trim()
            .parse()
            .map_err(|_| PointDriverError::BadOverride(item.clone()))?;
        table.insert(key.trim().to_string(), toml::Value::Float(value));
    }
    let parameters: HmcParameters =
        toml::Value::Table(table)
            .try_into()
            .map_err(|e: toml::de::Error| {
                PointDriverError::ParseMaterial(crate::scene::plain_toml_error(&e))
            })?;
    let problems = parameters.validate();
    if problems.is_empty() {
        Ok(parameters)
    } else {
        Err(PointDriverError::InvalidParameters(problems))
    }
}

/// Solve one load step under mixed control: components in `driven` take the prescribed
/// strain increment from `increment`; the other components are found by Newton on the
/// consistent tangent (theory D32) so that σ_i = `stress_target[i]`.
fn mixed_control_step(
    model: &Hmc,
    stress_n: &Voigt,
    state_n: &PointState,
    increment: &mut Voigt,
    free: &[usize],
    stress_target: &Voigt,
    step: usize,
) -> Result<crate::constitutive::StressUpdate, PointDriverError> {
    let tolerance = 1e-9
        * model
            .strength_scale()
            .max(stress_target.iter().fold(1.0, |a: f64, x| a.max(x.abs())));
    let mut residual = f64::INFINITY;
    for _ in 0..MIXED_CONTROL_ITERATIONS {
        let update = model
            .update(stress_n, increment, state_n, StrengthVariable::Local)
            .map_err(|source| PointDriverError::Constitutive { step, source })?;
        let r: Vec<f64> = free
            .iter()
            .map(|&i| update.stress[i] - stress_target[i])
            .collect();
        residual = r.iter().fold(0.0f64, |a, x| a.max(x.abs()));
        if residual <= tolerance {
            return Ok(update);
        }
        let t = &update.tangent;
        match free {
            [i] => {
                let k = t[*i][*i];
                if k.abs() < 1e-12 * model.parameters().youngs_modulus {
                    break;
                }
                increment[*i] -= r[0] / k;
            }
            [i, j] => {
                let (a, b, c, d) = (t[*i][*i], t[*i][*j], t[*j][*i], t[*j][*j]);
                let det = a * d - b * c;
                let e = model.parameters().youngs_modulus;
                if det.abs() < 1e-12 * e * e {
                    break;
                }
                increment[*i] -= (d * r[0] - b * r[1]) / det;
                increment[*j] -= (-c * r[0] + a * r[1]) / det;
            }
            _ => return Ok(update),
        }
    }
    Err(PointDriverError::MixedControl { step, residual })
}

fn record(
    step: usize,
    strain: Voigt,
    stress: Voigt,
    state: &PointState,
    yielded: bool,
) -> PointRecord {
    PointRecord {
        step,
        strain,
        stress,
        mean_stress: mean_stress(&stress),
        deviatoric_stress: deviatoric_stress(&stress),
        plastic_strain_eq: state.plastic_strain_eq,
        load: -stress[1] * BIAXIAL_WIDTH,
        yielded,
    }
}

/// Generic homogeneous path from σ0 = −confinement·(1,1,1,0): the `driven` strain component
/// follows `targets` (total values), the `free` components hold σ_i = −confinement.
fn run_path(
    model: &Hmc,
    confinement: f64,
    driven: usize,
    targets: &[f64],
    free: &[usize],
) -> Result<Vec<PointRecord>, PointDriverError> {
    let stress_target: Voigt = [-confinement, -confinement, -confinement, 0.0];
    let mut stress = stress_target;
    let mut state = PointState::default();
    let mut strain = [0.0; 4];
    let mut records = Vec::with_capacity(targets.len() + 1);
    records.push(record(0, strain, stress, &state, false));
    let mut guess = [0.0; 4];
    for (k, &target) in targets.iter().enumerate() {
        let step = k + 1;
        let mut increment = [0.0; 4];
        for &i in free {
            increment[i] = guess[i];
        }
        increment[driven] = target - strain[driven];
        let update = mixed_control_step(
            model,
            &stress,
            &state,
            &mut increment,
            free,
            &stress_target,
            step,
        )?;
        // Predictor for the next step: same ratio of free to driven increments.
        let driven_inc = increment[driven];
        for &i in free {
            guess[i] = increment[i];
        }
        if let Some(&next) = targets.get(k + 1) {
            let ratio = if driven_inc != 0.0 {
                (next - target) / driven_inc
            } else {
                0.0
            };
            for &i in free {
                guess[i] *= ratio;
            }
        }
        for i in 0..4 {
            strain[i] += increment[i];
        }
        stress = update.stress;
        state = update.state;
        records.push(record(step, strain, stress, &state, update.yielded));
    }
    Ok(records)
}

/// Plane-strain biaxial test (theory §8.1 homogeneous reference): εzz = γxy = 0,
/// σxx = −confinement (kPa) held, εyy follows `axial_strains` (total values, negative in
/// compression). Initial stress −confinement·(1,1,1,0).
pub fn run_biaxial(
    model: &Hmc,
    confinement: f64,
    axial_strains: &[f64],
) -> Result<Vec<PointRecord>, PointDriverError> {
    run_path(model, confinement, 1, axial_strains, &[0])
}

/// "Triaxial" compression in the 4-component Voigt setting: σxx = σzz = −confinement held
/// (kPa), εyy follows `axial_strains` (negative in compression), γxy = 0 — a triaxial
/// compression stress path (θ = +30°).
pub fn run_triaxial(
    model: &Hmc,
    confinement: f64,
    axial_strains: &[f64],
) -> Result<Vec<PointRecord>, PointDriverError> {
    run_path(model, confinement, 1, axial_strains, &[0, 2])
}

/// Simple shear: γxy follows `shear_strains`, εxx = εyy = εzz = 0, from
/// σ0 = −confinement·(1,1,1,0).
pub fn run_simple_shear(
    model: &Hmc,
    confinement: f64,
    shear_strains: &[f64],
) -> Result<Vec<PointRecord>, PointDriverError> {
    run_path(model, confinement, 3, shear_strains, &[])
}

use crate::error_id::{ErrorId, Identified};

impl Identified for PointDriverError {
    fn error_id(&self) -> ErrorId {
        match self {
            PointDriverError::ReadMaterial { .. }
            | PointDriverError::ParseMaterial(_)
            | PointDriverError::BadOverride(_)
            | PointDriverError::InvalidParameters(_)
            | PointDriverError::InvalidOption(_) => ErrorId::PointInput,
            PointDriverError::Constitutive { .. } | PointDriverError::MixedControl { .. } => {
                ErrorId::PointFailed
            }
            PointDriverError::Write { .. } => ErrorId::PointWrite,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::constitutive::yield_surface::{HyperbolicMohrCoulomb, Invariants, SurfaceStrength};

    fn table1() -> Hmc {
        Hmc::new(HmcParameters::table1()).unwrap()
    }

    /// Closed-form triaxial-compression (θ = +30°) strength of the hyperbola D23 with p_t = 0:
    /// q²/(3 r_c²) + c² = (c + p tanφ)², p = confinement + q/3, r_c = 2√3 cosφ/(3 − sinφ) (D25).
    fn triaxial_strength(cohesion: f64, friction_deg: f64, confinement: f64) -> f64 {
        let phi = friction_deg.to_radians();
        let rc = 2.0 * 3f64.sqrt() * phi.cos() / (3.0 - phi.sin());
        let t = phi.tan();
        let a0 = cohesion + confinement * t;
        let alpha = t * t / 9.0 - 1.0 / (3.0 * rc * rc);
        let beta = 2.0 * a0 * t / 3.0;
        let gamma = a0 * a0 - cohesion * cohesion;
        (-beta - (beta * beta - 4.0 * alpha * gamma).sqrt()) / (2.0 * alpha)
    }

    /// theory §5.6 check values: first yield on the plane-strain path at Δσyy = −552.26 kPa (0.1 %),
    /// σzz = −210.45 kPa (0.1 %), p = 320.9 kPa, q = 506.2 kPa (0.1 %), θ = +19.1° (±0.1°);
    /// F = 19.57 kN/m at δ = 1.325 mm (0.1 %).
    #[test]
    fn biaxial_first_yield() {
        let m = table1();
        let (mut lo, mut hi) = (0.0, 0.1);
        for _ in 0..60 {
            let mid = 0.5 * (lo + hi);
            let r = run_biaxial(&m, 100.0, &[-mid]).unwrap();
            if r[1].yielded {
                hi = mid;
            } else {
                lo = mid;
            }
        }
        let r = run_biaxial(&m, 100.0, &[-lo]).unwrap()[1];
        let rel = |x: f64, y: f64| (x - y).abs() / y.abs();
        assert!(
            rel(r.stress[1] + 100.0, -552.26) < 1e-3,
            "Δσyy = {}",
            r.stress[1] + 100.0
        );
        assert!(rel(r.stress[2], -210.45) < 1e-3, "σzz = {}", r.stress[2]);
        assert!((r.stress[0] + 100.0).abs() < 1e-6);
        assert!(rel(r.mean_stress, 320.9) < 1e-3, "p = {}", r.mean_stress);
        assert!(
            rel(r.deviatoric_stress, 506.2) < 1e-3,
            "q = {}",
            r.deviatoric_stress
        );
        let theta = Invariants::of(&r.stress, 1e-8).lode_angle().to_degrees();
        assert!((theta - 19.1).abs() < 0.1, "θ = {theta}");
        assert!(rel(r.load, 19.57) < 1e-3, "F = {}", r.load);
        assert!(
            rel(-r.strain[1] * BIAXIAL_HEIGHT * 1e3, 1.325) < 1e-3,
            "δ = {} mm",
            -r.strain[1] * 50.0
        );
    }

    /// theory §8.1 homogeneous softening branch: F = 19.46, 18.32, 16.66, 15.15, 13.94 kN/m at
    /// δ = 1.4 … 2.2 mm (1 %), with δ steps of 1 µm; the peak is the first-yield load 19.57 kN/m
    /// (0.2 %).
    #[test]
    fn biaxial_softening_branch() {
        let m = table1();
        let step = 1e-6;
        let targets: Vec<f64> = (1..=2200)
            .map(|k| -(k as f64) * step / BIAXIAL_HEIGHT)
            .collect();
        let records = run_biaxial(&m, 100.0, &targets).unwrap();
        for (delta_mm, expected) in [
            (1.4, 19.46),
            (1.6, 18.32),
            (1.8, 16.66),
            (2.0, 15.15),
            (2.2, 13.94),
        ] {
            let k = (delta_mm * 1e-3 / step).round() as usize;
            let f = records[k].load;
            eprintln!("δ = {delta_mm} mm: F = {f:.4} kN/m (theory {expected})");
            assert!(
                (f - expected).abs() <= 0.01 * expected,
                "δ = {delta_mm} mm: F = {f} vs {expected}"
            );
        }
        let peak = records.iter().map(|r| r.load).fold(0.0, f64::max);
        assert!((peak - 19.57).abs() <= 0.002 * 19.57, "peak F = {peak}");
    }

    /// At large strain the biaxial stress reaches the residual strength: c = c_min = 0.2 kPa and
    /// φ = 15° within 1 %, the load is stationary (change < 1 % over the last 20 % of the path), and
    /// the stress lies on the residual surface (|f_res| ≤ 1e-6 (c + p tanφ_res)).
    #[test]
    fn biaxial_tends_to_residual_strength() {
        let m = table1();
        let targets: Vec<f64> = (1..=3000).map(|k| -3.0 * k as f64 / 3000.0).collect();
        let records = run_biaxial(&m, 100.0, &targets).unwrap();
        let last = records.last().unwrap();
        let s = m.strength_at(last.plastic_strain_eq);
        assert!(s.cohesion <= 1.01 * 0.2, "c = {}", s.cohesion);
        assert!(
            (s.friction_angle_deg - 15.0).abs() <= 0.01 * 15.0,
            "φ = {}",
            s.friction_angle_deg
        );
        let earlier = records[2400].load;
        assert!(
            (last.load - earlier).abs() <= 0.01 * last.load,
            "F {earlier} → {}",
            last.load
        );
        let residual = SurfaceStrength::new(0.2, 15f64.to_radians(), 0.0);
        let f = HyperbolicMohrCoulomb { j_min: 1e-8 }.value(&last.stress, &residual);
        let scale = 0.2 + last.mean_stress * 15f64.to_radians().tan();
        assert!(f.abs() <= 1e-6 * scale, "f_res = {f}");
    }

    /// Triaxial compression path (θ = +30°): first yield and large-strain residual deviator q equal
    /// the closed-form strength of D23/D25 at TC (peak c = 200, φ = 20°: 0.1 %; residual c = 0.2,
    /// φ = 15°: 1 %).
    #[test]
    fn triaxial_matches_closed_form() {
        let m = table1();
        let q_peak = triaxial_strength(200.0, 20.0, 100.0);
        let (mut lo, mut hi) = (0.0, 0.1);
        for _ in 0..60 {
            let mid = 0.5 * (lo + hi);
            if run_triaxial(&m, 100.0, &[-mid]).unwrap()[1].yielded {
                hi = mid;
            } else {
                lo = mid;
            }
        }
        let first = run_triaxial(&m, 100.0, &[-lo]).unwrap()[1];
        assert!(
            (first.deviatoric_stress - q_peak).abs() <= 1e-3 * q_peak,
            "q = {} vs {q_peak}",
            first.deviatoric_stress
        );
        assert!((first.stress[0] + 100.0).abs() < 1e-6 && (first.stress[2] + 100.0).abs() < 1e-6);
        let targets: Vec<f64> = (1..=2000).map(|k| -4.0 * k as f64 / 2000.0).collect();
        let last = *run_triaxial(&m, 100.0, &targets).unwrap().last().unwrap();
        let q_res = triaxial_strength(0.2, 15.0, 100.0);
        assert!(
            (last.deviatoric_stress - q_res).abs() <= 0.01 * q_res,
            "q = {} vs {q_res}",
            last.deviatoric_stress
        );
    }
}
