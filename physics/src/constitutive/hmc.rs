//! Hyperbolic Mohr–Coulomb model with exponential strain softening (paper §2.2,
//! eqs. 3–5; theory §5): parameters, strength evolution and the return mapping
//! with its consistent tangent (theory D29–D32).
//!
//! The pieces are kept apart so a second model can reuse them:
//! yield criterion [`HyperbolicMohrCoulomb`] (D23–D25), flow rule
//! [`PressureScaledFlow`] (D26), softening law [`ThreeLevelSoftening`] (D28).
//! Second derivatives of the return mapping come from forward-mode dual numbers
//! (exact), see [`super::dual`].

use nalgebra::SVector;
use serde::{Deserialize, Serialize};

use super::dense_lu::DenseLu;
use super::dual::{Dual, Real};
use super::flow_rule::{strain_norm, PressureScaledFlow};
use super::softening::ThreeLevelSoftening;
use super::yield_surface::{FrictionShapeFit, HyperbolicMohrCoulomb, Invariants, SurfaceStrength};
use super::{
    mat4_mul_vec, ConstitutiveError, ConstitutiveModel, LinearElastic, Mat4, ParameterProblem,
    PointState, StrengthVariable, StressUpdate, Voigt,
};

/// Newton iterations per (sub)step before sub-stepping (theory §5.6 step 3).
const MAX_NEWTON_ITERATIONS: usize = 50;
/// Maximum number of line-search halvings (theory §5.6 step 2).
const MAX_LINE_SEARCH_HALVINGS: usize = 10;
/// Finest sub-stepping level: 2^6 = 64 sub-steps (theory §5.6 step 3).
const MAX_SUBSTEP_LEVEL: u32 = 6;
/// Elastic-check tolerance on f relative to c_ref (theory §5.6 step 1).
const ELASTIC_TOLERANCE: f64 = 1e-10;
/// Newton tolerance on ‖r_σ‖·E and |f| relative to c_ref (theory §5.6 step 2 says 1e−9; tightened so
/// that the converged stress is accurate enough for finite-difference tangent checks at η = 1e−6).
const NEWTON_TOLERANCE: f64 = 1e-11;
/// Newton tolerance on |r_κ| (absolute, theory §5.6 step 2).
const KAPPA_TOLERANCE: f64 = 1e-12;
/// Cohesion floor c_min = 1e−3 c_peak (theory §5.5).
const COHESION_FLOOR_FRACTION: f64 = 1e-3;
/// Below J = 1e−10 c_ref the Lode angle is undefined (theory D6).
const LODE_J_MIN_FRACTION: f64 = 1e-10;
/// A converged state with J < 1e−8 c_ref is "at the tip" (theory §5.6 step 4).
const TIP_J_FRACTION: f64 = 1e-8;
/// Largest admissible friction angle (degrees): the van Eekelen shape with Z = −0.229 is
/// convex only for |Y| ≤ 0.79, i.e. φ ≲ 46° (theory §5.3).
pub const MAX_FRICTION_ANGLE_DEG: f64 = 46.0;

fn default_density() -> f64 {
    2.0
}

/// Material parameters of the hyperbolic Mohr–Coulomb softening model (paper Table 1).
/// TOML keys in brackets; angles in degrees, stresses in kPa.
#[derive(Clone, Copy, Debug, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct HmcParameters {
    /// `E`: Young's modulus, kPa (theory D22).
    #[serde(rename = "E")]
    pub youngs_modulus: f64,
    /// `nu`: Poisson's ratio (theory D22).
    #[serde(rename = "nu")]
    pub poisson_ratio: f64,
    /// `density`: mass density, t/m³ (default 2.0).
    #[serde(default = "default_density")]
    pub density: f64,
    /// `phi_ini`: initial asymptotic friction angle φ*_ini, degrees (must equal φ_peak, theory §5.5).
    #[serde(rename = "phi_ini")]
    pub friction_angle_ini: f64,
    /// `phi_peak`: peak asymptotic friction angle φ*_peak, degrees (theory D28).
    #[serde(rename = "phi_peak")]
    pub friction_angle_peak: f64,
    /// `phi_res`: residual friction angle φ*_res, degrees (theory D28).
    #[serde(rename = "phi_res")]
    pub friction_angle_res: f64,
    /// `c_ini`: initial (= peak) asymptotic cohesion c*_ini, kPa (paper eq. 4).
    #[serde(rename = "c_ini")]
    pub cohesion_ini: f64,
    /// `c_post`: post-rupture asymptotic cohesion c*_post, kPa (paper eq. 4).
    #[serde(rename = "c_post")]
    pub cohesion_post: f64,
    /// `pt_ini`: initial tensile strength p_t,ini, kPa (theory D23, D28).
    #[serde(rename = "pt_ini")]
    pub tensile_strength_ini: f64,
    /// `pt_post`: post-rupture tensile strength p_t,post, kPa (theory D28).
    #[serde(rename = "pt_post")]
    pub tensile_strength_post: f64,
    /// `b_post`: post-rupture softening rate (dimensionless, paper eq. 4).
    #[serde(rename = "b_post")]
    pub softening_rate_post: f64,
    /// `b_res`: residual softening rate (dimensionless, paper eq. 4).
    #[serde(rename = "b_res")]
    pub softening_rate_res: f64,
    /// `omega`: non-associativity constant ω (theory D26).
    pub omega: f64,
    /// `apex_start`: a (sub)step whose return mapping from the trial state fails beyond the
    /// apex is tried once more from the apex before it is sub-stepped ([`Hmc`]'s
    /// `apex_start`; default `false`, theory §5.6 as written). A numerical option, not a
    /// material property: it leaves every update that converges from the trial state as it
    /// is and changes the few that sub-stepped.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub apex_start: bool,
}

impl HmcParameters {
    /// The paper's Table 1 (biaxial test): E = 20 000 kPa, ν = 0.2, φ_ini = φ_peak = 20°,
    /// φ_res = 15°, c_ini = 200 kPa, c_post = 0, p_t = 0, b_post = 10, b_res = 2, ω = 1, ρ = 2.0 t/m³.
    pub fn table1() -> Self {
        Self {
            youngs_modulus: 20_000.0,
            poisson_ratio: 0.2,
            density: 2.0,
            friction_angle_ini: 20.0,
            friction_angle_peak: 20.0,
            friction_angle_res: 15.0,
            cohesion_ini: 200.0,
            cohesion_post: 0.0,
            tensile_strength_ini: 0.0,
            tensile_strength_post: 0.0,
            softening_rate_post: 10.0,
            softening_rate_res: 2.0,
            omega: 1.0,
            apex_start: false,
        }
    }

    /// Check every parameter; one [`ParameterProblem`] per problem, naming the TOML key and the
    /// allowed range.
    ///
    /// Ranges: E > 0; −1 < ν < 0.5; density > 0; 0 < φ_peak ≤ 46° (van Eekelen convexity, §5.3);
    /// 0 < φ_res ≤ φ_peak; φ_ini = φ_peak (no pre-peak hardening, §5.5); c_ini > 0;
    /// 0 ≤ c_post ≤ c_ini; 0 ≤ p_t,ini ≤ c_ini cot φ_peak; 0 ≤ p_t,post ≤ c_post cot φ_peak (a ≥ 0,
    /// D23); b_post, b_res ≥ 0; 0 ≤ ω ≤ 1 (D26). All values must be finite.
    pub fn validate(&self) -> Vec<ParameterProblem> {
        let mut problems = Vec::new();
        let fields: [(&'static str, f64); 13] = [
            ("E", self.youngs_modulus),
            ("nu", self.poisson_ratio),
            ("density", self.density),
            ("phi_ini", self.friction_angle_ini),
            ("phi_peak", self.friction_angle_peak),
            ("phi_res", self.friction_angle_res),
            ("c_ini", self.cohesion_ini),
            ("c_post", self.cohesion_post),
            ("pt_ini", self.tensile_strength_ini),
            ("pt_post", self.tensile_strength_post),
            ("b_post", self.softening_rate_post),
            ("b_res", self.softening_rate_res),
            ("omega", self.omega),
        ];
        for (key, value) in fields {
            if !value.is_finite() {
                problems.push(ParameterProblem {
                    key,
                    message: format!("{value} must be a finite number"),
                });
            }
        }
        if !problems.is_empty() {
            return problems;
        }
        let mut check = |ok: bool, key: &'static str, value: f64, range: String| {
            if !ok {
                problems.push(ParameterProblem {
                    key,
                    message: format!("{value} is out of range: {range}"),
                });
            }
        };
        check(
            self.youngs_modulus > 0.0,
            "E",
            self.youngs_modulus,
            "E > 0 kPa".into(),
        );
        check(
            self.poisson_ratio > -1.0 && self.poisson_ratio < 0.5,
            "nu",
            self.poisson_ratio,
            "-1 < nu < 0.5".into(),
        );
        check(
            self.density > 0.0,
            "density",
            self.density,
            "density > 0 t/m³".into(),
        );
        let phi_peak = self.friction_angle_peak;
        check(
            phi_peak > 0.0 && phi_peak <= MAX_FRICTION_ANGLE_DEG,
            "phi_peak",
            phi_peak,
            format!("0 < phi_peak <= {MAX_FRICTION_ANGLE_DEG} degrees (convex van Eekelen shape)"),
        );
        check(
            self.friction_angle_res > 0.0 && self.friction_angle_res <= phi_peak,
            "phi_res",
            self.friction_angle_res,
            format!("0 < phi_res <= phi_peak = {phi_peak} degrees"),
        );
        check(
            self.friction_angle_ini == phi_peak,
            "phi_ini",
            self.friction_angle_ini,
            format!("phi_ini must equal phi_peak = {phi_peak} degrees (pre-peak hardening is not implemented)"),
        );
        check(
            self.cohesion_ini > 0.0,
            "c_ini",
            self.cohesion_ini,
            "c_ini > 0 kPa".into(),
        );
        check(
            self.cohesion_post >= 0.0 && self.cohesion_post <= self.cohesion_ini,
            "c_post",
            self.cohesion_post,
            format!("0 <= c_post <= c_ini = {} kPa", self.cohesion_ini),
        );
        let cot_peak = if phi_peak > 0.0 && phi_peak < 90.0 {
            1.0 / phi_peak.to_radians().tan()
        } else {
            f64::INFINITY
        };
        let pt_ini_max = self.cohesion_ini * cot_peak;
        check(
            self.tensile_strength_ini >= 0.0 && self.tensile_strength_ini <= pt_ini_max,
            "pt_ini",
            self.tensile_strength_ini,
            format!("0 <= pt_ini <= c_ini cot(phi_peak) = {pt_ini_max} kPa"),
        );
        let pt_post_max = self.cohesion_post * cot_peak;
        check(
            self.tensile_strength_post >= 0.0 && self.tensile_strength_post <= pt_post_max,
            "pt_post",
            self.tensile_strength_post,
            format!("0 <= pt_post <= c_post cot(phi_peak) = {pt_post_max} kPa"),
        );
        check(
            self.softening_rate_post >= 0.0,
            "b_post",
            self.softening_rate_post,
            "b_post >= 0".into(),
        );
        check(
            self.softening_rate_res >= 0.0,
            "b_res",
            self.softening_rate_res,
            "b_res >= 0".into(),
        );
        check(
            self.omega >= 0.0 && self.omega <= 1.0,
            "omega",
            self.omega,
            "0 <= omega <= 1".into(),
        );
        problems
    }
}

/// Strength parameters at one κ (theory D28 with floor and clamp), for output and tests.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StrengthAtKappa {
    /// Asymptotic cohesion c*(κ), kPa, floored at 1e−3 c_peak.
    pub cohesion: f64,
    /// Asymptotic friction angle φ*(κ), degrees.
    pub friction_angle_deg: f64,
    /// Tensile strength p_t(κ), kPa, clamped to [0, (c − c_min)/tanφ].
    pub tensile_strength: f64,
}

/// Hyperbolic Mohr–Coulomb softening model (paper §2.2; theory §5), ready to use:
/// elastic matrices and strength laws precomputed.
#[derive(Clone, Debug)]
pub struct Hmc {
    parameters: HmcParameters,
    elastic: LinearElastic,
    stiffness: Mat4,
    compliance: Mat4,
    cohesion_law: ThreeLevelSoftening,
    friction_law: ThreeLevelSoftening,
    tensile_law: ThreeLevelSoftening,
    cohesion_min: f64,
    strength_scale: f64,
    surface: HyperbolicMohrCoulomb,
    flow: PressureScaledFlow,
    softening: bool,
    fixed_strength: SurfaceStrength<f64>,
    /// tanφ, X, Y along [φ_res, φ_peak] (theory §5.3); `None`: D25 directly.
    friction_shape: Option<FrictionShapeFit>,
}

/// A strength with its κ-derivative (one lane) as five-lane duals whose lane 4 is κ
/// ([`Hmc::linearise`] seeds σ in lanes 0–3).
#[inline]
fn kappa_lane_of_five(s: &SurfaceStrength<Dual<1>>) -> SurfaceStrength<Dual<5>> {
    let widen = |d: Dual<1>| Dual {
        re: d.re,
        eps: [0.0, 0.0, 0.0, 0.0, d.eps[0]],
    };
    SurfaceStrength {
        cohesion: widen(s.cohesion),
        tan_friction: widen(s.tan_friction),
        tensile_strength: widen(s.tensile_strength),
        hyperbola_a: widen(s.hyperbola_a),
        shape_x: widen(s.shape_x),
        shape_y: widen(s.shape_y),
    }
}

/// h = ‖m‖ε (D3); the tiny shift keeps a dual derivative finite where m = 0 (ω = 0 at the
/// tip). One function for the f64 and dual evaluations, so that their values agree bit for bit.
#[inline]
fn flow_norm<T: Real>(m: &[T; 4]) -> T {
    (m[0] * m[0] + m[1] * m[1] + m[2] * m[2] + m[3] * m[3] * 0.5 + 1e-300).sqrt()
}

/// The strength argument κ_s as an affine function of the point's own κ, fixed
/// for one stress update ([`StrengthVariable`]): local κ_s = κ; nonlocal
/// κ_s = max(0, κ̄_nb + w (κ − κ_n)) with w = 1 − m the weight of the own
/// increment (κ̄ is a non-negative average: the clamp guards round-off and
/// m > 1). With w = 0 the κ row of D29 is dropped (theory §5.6, nonlocal) and
/// κ follows from Δλ afterwards.
#[derive(Clone, Copy, Debug)]
struct StrengthArg {
    offset: f64,
    slope: f64,
    nonlocal: bool,
}

impl StrengthArg {
    const LOCAL: Self = Self {
        offset: 0.0,
        slope: 1.0,
        nonlocal: false,
    };

    fn new(strength: StrengthVariable, kappa_n: f64) -> Self {
        match strength {
            StrengthVariable::Local => Self::LOCAL,
            StrengthVariable::Nonlocal {
                neighbours,
                own_weight,
            } => Self {
                offset: neighbours - own_weight * kappa_n,
                slope: own_weight,
                nonlocal: true,
            },
        }
    }

    /// κ_s depends on the update's own plastic flow: the κ row of D29 is solved.
    fn couples_kappa(&self) -> bool {
        self.slope != 0.0
    }

    /// κ_s at own κ.
    fn at(&self, kappa: f64) -> f64 {
        self.at_generic(kappa)
    }

    /// κ_s at own κ, generic for exact κ-derivatives.
    fn at_generic<T: Real>(&self, kappa: T) -> T {
        if self.nonlocal {
            (T::cst(self.offset) + kappa * T::cst(self.slope)).max_by_value(T::cst(0.0))
        } else {
            kappa
        }
    }

    fn is_finite(&self) -> bool {
        self.offset.is_finite() && self.slope.is_finite()
    }
}

/// Second-order information at one (σ, κ) of the return mapping (theory D30–D31).
#[derive(Clone, Copy, Debug)]
struct Linearisation {
    f: f64,
    f_sigma: [f64; 4],
    f_kappa: f64,
    m: [f64; 4],
    m_sigma: [[f64; 4]; 4],
    m_kappa: [f64; 4],
    h: f64,
    h_sigma: [f64; 4],
    h_kappa: f64,
}

type Mat6 = [[f64; 6]; 6];
type Vec6 = SVector<f64, 6>;

/// Starting point y⁰ = (σ, κ, Δλ) of the Newton iteration on D29.
#[derive(Clone, Copy, Debug)]
struct NewtonStart {
    stress: Voigt,
    kappa: f64,
    multiplier: f64,
}

/// A converged plastic (sub)step.
struct PlasticStep {
    stress: Voigt,
    kappa: f64,
    plastic_multiplier: f64,
    flow_direction: Voigt,
    /// The factorised Jacobian of D30 at the solution, for the tangent (D32); `None`
    /// where none was asked for.
    jacobian: Option<DenseLu<6>>,
}

/// Result of integrating the whole increment with `n` sub-steps.
struct Integrated {
    stress: Voigt,
    kappa: f64,
    plastic_strain_increment: Voigt,
    tangent: Mat4,
    yielded: bool,
}

impl Hmc {
    /// Build the model; returns every parameter problem if the parameters are invalid.
    pub fn new(parameters: HmcParameters) -> Result<Self, Vec<ParameterProblem>> {
        let problems = parameters.validate();
        if !problems.is_empty() {
            return Err(problems);
        }
        let elastic = LinearElastic::new(parameters.youngs_modulus, parameters.poisson_ratio);
        let p = &parameters;
        let cohesion_law = ThreeLevelSoftening {
            peak: p.cohesion_ini,
            post: p.cohesion_post,
            residual: 0.0,
            rate_post: p.softening_rate_post,
            rate_res: p.softening_rate_res,
        };
        // φ_post := φ_peak (theory §5.5 choice), angles in radians.
        let friction_law = ThreeLevelSoftening {
            peak: p.friction_angle_peak.to_radians(),
            post: p.friction_angle_peak.to_radians(),
            residual: p.friction_angle_res.to_radians(),
            rate_post: p.softening_rate_post,
            rate_res: p.softening_rate_res,
        };
        let tensile_law = ThreeLevelSoftening {
            peak: p.tensile_strength_ini,
            post: p.tensile_strength_post,
            residual: 0.0,
            rate_post: p.softening_rate_post,
            rate_res: p.softening_rate_res,
        };
        let softening =
            cohesion_law.can_change() || friction_law.can_change() || tensile_law.can_change();
        let strength_scale = p.cohesion_ini;
        let mut model = Self {
            parameters,
            elastic,
            stiffness: elastic.stiffness(),
            compliance: elastic.compliance(),
            cohesion_law,
            friction_law,
            tensile_law,
            cohesion_min: COHESION_FLOOR_FRACTION * p.cohesion_ini,
            strength_scale,
            surface: HyperbolicMohrCoulomb {
                j_min: LODE_J_MIN_FRACTION * strength_scale,
            },
            flow: PressureScaledFlow { omega: p.omega },
            softening: true,
            fixed_strength: SurfaceStrength::new(0.0, 0.1, 0.0),
            friction_shape: FrictionShapeFit::new(friction_law.residual, friction_law.peak),
        };
        model.fixed_strength = model.strength(0.0);
        model.softening = softening;
        Ok(model)
    }

    /// The parameters the model was built from.
    pub fn parameters(&self) -> &HmcParameters {
        &self.parameters
    }

    /// True when some strength parameter can soften with κ (theory D28).
    pub fn can_soften(&self) -> bool {
        self.softening
    }

    /// Strength scale c_ref = c_peak (kPa) used for tolerances (theory §5.6).
    pub fn strength_scale(&self) -> f64 {
        self.strength_scale
    }

    /// The yield criterion (theory D23–D25).
    pub fn yield_criterion(&self) -> &HyperbolicMohrCoulomb {
        &self.surface
    }

    /// The flow rule (theory D26).
    pub fn flow_rule(&self) -> &PressureScaledFlow {
        &self.flow
    }

    /// Surface strength at κ: D28 with the c floor c ≥ 1e−3 c_peak and the clamp
    /// 0 ≤ p_t ≤ (c − c_min)/tanφ (theory §5.2, §5.5); tanφ, X and Y from the series along
    /// the softening path (theory §5.3) where it reached its accuracy; generic for exact
    /// κ-derivatives.
    #[inline]
    fn strength<T: Real>(&self, kappa: T) -> SurfaceStrength<T> {
        if !self.softening {
            return self.fixed_strength.lift();
        }
        // the three laws share b_post and b_res (paper eq. 4): two exponentials, not six
        let decays = self.cohesion_law.decays(kappa);
        let cohesion = self
            .cohesion_law
            .value_with_decays(decays)
            .max_by_value(T::cst(self.cohesion_min));
        let friction = self.friction_law.value_with_decays(decays);
        let tensile = |tan_friction: T| {
            let tensile_max = (cohesion - self.cohesion_min) / tan_friction;
            self.tensile_law
                .value_with_decays(decays)
                .min_by_value(tensile_max)
                .max_by_value(T::cst(0.0))
        };
        let Some(fit) = &self.friction_shape else {
            let (sin_phi, cos_phi) = friction.sin_cos();
            let tensile_strength = tensile(sin_phi / cos_phi);
            return SurfaceStrength::from_sin_cos(cohesion, sin_phi, cos_phi, tensile_strength);
        };
        let [tan_friction, shape_x, shape_y] = fit.evaluate(friction);
        let tensile_strength = tensile(tan_friction);
        SurfaceStrength::from_shape(cohesion, tan_friction, (shape_x, shape_y), tensile_strength)
    }

    /// Strength parameters at equivalent plastic strain κ (theory D28, floor and clamp included).
    pub fn strength_at(&self, kappa: f64) -> StrengthAtKappa {
        let cohesion = self.cohesion_law.value(kappa).max(self.cohesion_min);
        let friction = self.friction_law.value(kappa);
        let tensile = self
            .tensile_law
            .value(kappa)
            .min((cohesion - self.cohesion_min) / friction.tan())
            .max(0.0);
        StrengthAtKappa {
            cohesion,
            friction_angle_deg: friction.to_degrees(),
            tensile_strength: tensile,
        }
    }

    /// Yield function f(σ, κ) of theory D23 (kPa); f ≤ 0 admissible.
    pub fn yield_function(&self, stress: &Voigt, kappa: f64) -> f64 {
        self.surface.value(stress, &self.strength(kappa))
    }

    /// Plastic flow direction m = ∂G/∂σ at (σ, κ) (theory D26, D31).
    pub fn flow_direction(&self, stress: &Voigt, kappa: f64) -> Voigt {
        let strength = self.strength(kappa);
        let (_, gradient) = self.surface.value_and_gradient(stress, &strength);
        self.flow.direction(&gradient, strength.tan_friction)
    }

    /// f, f_σ, m, m_σ, h = ‖m‖ε and their κ-derivatives by one dual-number evaluation
    /// (exact; theory D30–D31), with the strength at κ_s = `arg`(κ); the κ-derivatives
    /// are zero when κ_s does not depend on κ (strength frozen, nonlocal m = 1).
    #[inline]
    fn linearise(&self, stress: &Voigt, kappa: f64, arg: StrengthArg) -> Linearisation {
        type D5 = Dual<5>;
        let sigma: [D5; 4] = std::array::from_fn(|i| D5::variable(stress[i], i));
        // The strength depends on κ alone: one derivative lane gives its κ-lane bit for bit,
        // without carrying the four zero σ-lanes through the softening laws.
        let strength = if arg.couples_kappa() {
            let with_slope = self.strength(arg.at_generic(Dual::<1>::variable(kappa, 0)));
            kappa_lane_of_five(&with_slope)
        } else {
            self.strength(arg.at(kappa)).lift()
        };
        let (f, gradient) = self.surface.value_and_gradient(&sigma, &strength);
        let m = self.flow.direction(&gradient, strength.tan_friction);
        let h = flow_norm(&m);
        Linearisation {
            f: f.re,
            f_sigma: std::array::from_fn(|i| gradient[i].re),
            f_kappa: f.eps[4],
            m: std::array::from_fn(|i| m[i].re),
            m_sigma: std::array::from_fn(|i| std::array::from_fn(|j| m[i].eps[j])),
            m_kappa: std::array::from_fn(|i| m[i].eps[4]),
            h: h.re,
            h_sigma: std::array::from_fn(|j| h.eps[j]),
            h_kappa: h.eps[4],
        }
    }

    /// f, m and h = ‖m‖ε at (σ, κ) from f64 evaluations only: the value part of
    /// [`Self::linearise`], bit for bit.
    #[inline]
    fn evaluate(&self, stress: &Voigt, kappa: f64, arg: StrengthArg) -> (f64, Voigt, f64) {
        let strength = self.strength_f64(arg.at(kappa));
        let (f, gradient) = self.surface.value_and_gradient(stress, &strength);
        let m = self.flow.direction(&gradient, strength.tan_friction);
        (f, m, flow_norm(&m))
    }

    /// Residual of D29 (strain-like components) at y = (σ, κ, Δλ) from f64 evaluations
    /// only, with f, m and h.
    #[inline]
    fn residual(
        &self,
        (stress, kappa, multiplier): (&Voigt, f64, f64),
        trial: &Voigt,
        kappa_n: f64,
        arg: StrengthArg,
    ) -> (Vec6, f64, Voigt, f64) {
        let (f, m, h) = self.evaluate(stress, kappa, arg);
        let r = self.assemble_residual(
            stress,
            kappa,
            multiplier,
            trial,
            kappa_n,
            arg.couples_kappa(),
            &m,
            h,
            f,
        );
        (r, f, m, h)
    }

    /// Residual vector of D29 from already evaluated m, h = ‖m‖ε and f.
    #[allow(clippy::too_many_arguments)]
    #[inline]
    fn assemble_residual(
        &self,
        stress: &Voigt,
        kappa: f64,
        multiplier: f64,
        trial: &Voigt,
        kappa_n: f64,
        local: bool,
        m: &Voigt,
        h: f64,
        f: f64,
    ) -> Vec6 {
        let diff: Voigt = std::array::from_fn(|i| stress[i] - trial[i]);
        let c_diff = mat4_mul_vec(&self.compliance, &diff);
        let mut r = Vec6::zeros();
        for i in 0..4 {
            r[i] = c_diff[i] + multiplier * m[i];
        }
        if local {
            r[4] = kappa - kappa_n - multiplier * h;
        }
        r[5] = f / self.parameters.youngs_modulus;
        r
    }

    /// f64 strength at κ, with the κ = 0 (peak) strength precomputed.
    #[inline]
    fn strength_f64(&self, kappa: f64) -> SurfaceStrength<f64> {
        if kappa == 0.0 {
            self.fixed_strength
        } else {
            self.strength(kappa)
        }
    }

    /// Jacobian A of theory D30 (nonlocal: κ row and column replaced by the identity).
    #[inline]
    fn jacobian(&self, lin: &Linearisation, multiplier: f64, local: bool) -> Mat6 {
        let e = self.parameters.youngs_modulus;
        let mut a: Mat6 = [[0.0; 6]; 6];
        for i in 0..4 {
            for j in 0..4 {
                a[i][j] = self.compliance[i][j] + multiplier * lin.m_sigma[i][j];
            }
            a[i][5] = lin.m[i];
            a[5][i] = lin.f_sigma[i] / e;
        }
        if local {
            for i in 0..4 {
                a[i][4] = multiplier * lin.m_kappa[i];
                a[4][i] = -multiplier * lin.h_sigma[i];
            }
            a[4][4] = 1.0 - multiplier * lin.h_kappa;
            a[4][5] = -lin.h;
            a[5][4] = lin.f_kappa / e;
        } else {
            a[4][4] = 1.0;
        }
        a
    }

    /// A second start for a (sub)step from `stress_start` by `increment` (trial stress
    /// `trial`) whose Newton iteration from the trial state failed, when the trial stress lies
    /// on the tension side of the apex (p_trial < −p_t at κ): the tip return's state (theory
    /// §5.6 step 4, [`Self::tip_return`]), σ⁰ = p_t (1,1,1,0) and κ⁰ from the plastic strain
    /// Δε^p that carries the trial stress there, with Δλ⁰ = ‖Δε^p‖ε / ‖m‖ε for m at σ⁰.
    /// From the trial state, where the surface near the apex has a radius of curvature ~a and
    /// the strength softens with κ, the iteration can creep towards the apex by line-search
    /// steps of a few per cent each and exhaust its iterations; started at the apex it is near
    /// its solution. `None` where the trial stress does not lie beyond the apex (the
    /// sub-stepping of step 3 follows).
    fn apex_start(
        &self,
        (stress_start, increment, trial): (&Voigt, &Voigt, &Voigt),
        kappa: f64,
        arg: StrengthArg,
    ) -> Option<NewtonStart> {
        let trial_mean = -(trial[0] + trial[1] + trial[2]) / 3.0;
        if trial_mean >= -self.strength_f64(arg.at(kappa)).tensile_strength {
            return None;
        }
        let tip = self.tip_return(stress_start, increment, kappa, arg);
        let strength = self.strength_f64(arg.at(tip.kappa));
        let (_, gradient) = self.surface.value_and_gradient(&tip.stress, &strength);
        let flow = self.flow.direction(&gradient, strength.tan_friction);
        let multiplier = strain_norm(&tip.plastic_strain_increment) / strain_norm(&flow);
        multiplier.is_finite().then_some(NewtonStart {
            stress: tip.stress,
            // nonlocal: κ is not an unknown of the iteration (D29 without its κ row)
            kappa: if arg.couples_kappa() {
                tip.kappa
            } else {
                kappa
            },
            multiplier,
        })
    }

    /// Closest-point projection of one (sub)step of trial stress `trial` (theory D29–D30), the
    /// Newton iteration started at `start`. With `want_jacobian` false (explicit steps) the
    /// Jacobian at the solution is not formed, and an iterate that the quadratic convergence
    /// of the last two predicts to be the solution is first checked with the f64 residual,
    /// whose values are the linearisation's bit for bit (the same iterates and solution).
    fn plastic_step(
        &self,
        (trial, kappa_n): (&Voigt, f64),
        arg: StrengthArg,
        tolerance: f64,
        start: NewtonStart,
        want_jacobian: bool,
    ) -> Result<PlasticStep, &'static str> {
        let local = arg.couples_kappa();
        let e = self.parameters.youngs_modulus;
        // residual in units of the tolerance: converged at ≤ 1
        let error = |r: &Vec6, f: f64| {
            let r_sigma = r[0].abs().max(r[1].abs()).max(r[2].abs()).max(r[3].abs());
            (r_sigma * e / tolerance)
                .max(f.abs() / tolerance)
                .max(r[4].abs() / KAPPA_TOLERANCE)
        };
        let solution = |(stress, kappa, multiplier): (Voigt, f64, f64), m: Voigt, h: f64| {
            if multiplier < 0.0 {
                return Err("negative plastic multiplier");
            }
            Ok(PlasticStep {
                stress,
                kappa: if local {
                    kappa
                } else {
                    kappa_n + multiplier * h
                },
                plastic_multiplier: multiplier,
                flow_direction: m,
                jacobian: None,
            })
        };
        let NewtonStart {
            mut stress,
            mut kappa,
            mut multiplier,
        } = start;
        let mut lin = self.linearise(&stress, kappa, arg);
        let mut previous_error = 0.0;
        // a full Newton step was refused in an earlier iteration
        let mut searched = false;
        for _ in 0..MAX_NEWTON_ITERATIONS {
            let r = self.assemble_residual(
                &stress, kappa, multiplier, trial, kappa_n, local, &lin.m, lin.h, lin.f,
            );
            let current_error = error(&r, lin.f);
            if current_error <= 1.0 {
                let mut step = solution((stress, kappa, multiplier), lin.m, lin.h)?;
                if want_jacobian {
                    let lu = DenseLu::new(self.jacobian(&lin, multiplier, local));
                    if !lu.is_invertible() {
                        return Err("singular Jacobian at the converged state");
                    }
                    step.jacobian = Some(lu);
                }
                return Ok(step);
            }
            let lu = DenseLu::new(self.jacobian(&lin, multiplier, local));
            let step = lu
                .solve(std::array::from_fn(|i| -r[i]))
                .ok_or("singular Jacobian")?;
            if step.iter().any(|x| !x.is_finite()) {
                return Err("non-finite Newton step");
            }
            // Backtracking line search on ‖r‖ (theory §5.6 step 2).
            let norm0 = r.norm();
            // sufficient decrease at the fraction `alpha` of the step
            let takes = |r: &Vec6, alpha: f64| {
                let norm = r.norm();
                norm.is_finite() && norm <= (1.0 - 1e-4 * alpha) * norm0
            };
            let point = |alpha: f64| {
                let s_try: Voigt = std::array::from_fn(|i| stress[i] + alpha * step[i]);
                let k_try = if local {
                    kappa + alpha * step[4]
                } else {
                    kappa
                };
                (s_try, k_try, multiplier + alpha * step[5])
            };
            let full = point(1.0);
            // quadratic convergence: e_{k+1} ≈ e_k² (e_k / e_{k−1}²)
            let predicted_last = current_error.powi(3) <= previous_error * previous_error;
            previous_error = current_error;
            // The full step is judged by the f64 residual (the linearisation's values bit
            // for bit, so the same iterates) where it may be the solution of an explicit
            // step, or where a full step was refused already: its dual linearisation is
            // then formed only when the step is taken.
            if (!want_jacobian && predicted_last) || searched {
                let (r_full, f_full, m_full, h_full) =
                    self.residual((&full.0, full.1, full.2), trial, kappa_n, arg);
                if takes(&r_full, 1.0) {
                    if !want_jacobian && error(&r_full, f_full) <= 1.0 {
                        return solution(full, m_full, h_full);
                    }
                    (stress, kappa, multiplier) = full;
                    lin = self.linearise(&stress, kappa, arg);
                    continue;
                }
            } else {
                let lin_full = self.linearise(&full.0, full.1, arg);
                let r_full = self.assemble_residual(
                    &full.0,
                    full.1,
                    full.2,
                    trial,
                    kappa_n,
                    local,
                    &lin_full.m,
                    lin_full.h,
                    lin_full.f,
                );
                if takes(&r_full, 1.0) {
                    (stress, kappa, multiplier, lin) = (full.0, full.1, full.2, lin_full);
                    continue;
                }
            }
            searched = true;
            let mut alpha = 1.0;
            for halving in 1..=MAX_LINE_SEARCH_HALVINGS {
                alpha *= 0.5;
                let (s_try, k_try, l_try) = point(alpha);
                let (r_try, ..) = self.residual((&s_try, k_try, l_try), trial, kappa_n, arg);
                if takes(&r_try, alpha) || halving == MAX_LINE_SEARCH_HALVINGS {
                    if !r_try.norm().is_finite() {
                        return Err("non-finite residual in the line search");
                    }
                    (stress, kappa, multiplier) = (s_try, k_try, l_try);
                    break;
                }
            }
            lin = self.linearise(&stress, kappa, arg);
        }
        Err("Newton iteration limit reached")
    }

    /// Integrate the whole increment with `substeps` equal sub-steps; with `want_tangent`
    /// the tangent is the exact derivative of the sub-stepped update (chain rule through the
    /// sub-steps, which reduces to D32 for one step), else it is left zero (explicit steps:
    /// the stress and κ are the same bits either way).
    fn integrate(
        &self,
        stress_n: &Voigt,
        strain_increment: &Voigt,
        kappa_n: f64,
        arg: StrengthArg,
        substeps: u32,
        want_tangent: bool,
    ) -> Result<Integrated, &'static str> {
        let local = arg.couples_kappa();
        let n = f64::from(substeps);
        let sub_increment = strain_increment.map(|x| x / n);
        let d_sub = mat4_mul_vec(&self.stiffness, &sub_increment);
        let mut stress = *stress_n;
        let mut kappa = kappa_n;
        let mut plastic = [0.0; 4];
        let mut yielded = false;
        // Sensitivities dσ/dΔε (4×4) and dκ/dΔε (1×4) of the total increment.
        let mut s_sigma = [[0.0; 4]; 4];
        let mut s_kappa = [0.0; 4];
        let tolerance_base = NEWTON_TOLERANCE * self.strength_scale;
        let elastic_tolerance = ELASTIC_TOLERANCE * self.strength_scale;
        for _ in 0..substeps {
            let trial = [
                stress[0] + d_sub[0],
                stress[1] + d_sub[1],
                stress[2] + d_sub[2],
                stress[3] + d_sub[3],
            ];
            let strength = self.strength_f64(arg.at(kappa));
            let f_trial = self.surface.value(&trial, &strength);
            if f_trial <= elastic_tolerance {
                stress = trial;
                if want_tangent {
                    for i in 0..4 {
                        for j in 0..4 {
                            s_sigma[i][j] += self.stiffness[i][j] / n;
                        }
                    }
                }
                continue;
            }
            let trial_scale = trial.iter().fold(0.0f64, |acc, x| acc.max(x.abs()));
            // Round-off floor for very large stresses (~500 ulp of the trial stress).
            let tolerance = tolerance_base.max(1e-13 * trial_scale);
            let from_trial = NewtonStart {
                stress: trial,
                kappa,
                multiplier: 0.0,
            };
            // theory §5.6 step 2 from y⁰ = (σ_trial, κ, 0); where that fails beyond the apex,
            // with the `apex_start` option once more from the apex before the sub-stepping of
            // step 3
            let step = match self.plastic_step(
                (&trial, kappa),
                arg,
                tolerance,
                from_trial,
                want_tangent,
            ) {
                Ok(step) => step,
                Err(reason) if !self.parameters.apex_start => return Err(reason),
                Err(reason) => {
                    let from_apex = self
                        .apex_start((&stress, &sub_increment, &trial), kappa, arg)
                        .ok_or(reason)?;
                    self.plastic_step((&trial, kappa), arg, tolerance, from_apex, want_tangent)?
                }
            };
            for (p, m) in plastic.iter_mut().zip(step.flow_direction) {
                *p += step.plastic_multiplier * m;
            }
            stress = step.stress;
            kappa = step.kappa;
            yielded = true;
            if !want_tangent {
                continue;
            }
            // Sensitivity: A dy = [C dσ_k + dΔε/n; dκ_k; 0] (linearised D29).
            let mut rhs = [[0.0; 4]; 6];
            for i in 0..4 {
                for j in 0..4 {
                    let mut c_s = 0.0;
                    for k in 0..4 {
                        c_s += self.compliance[i][k] * s_sigma[k][j];
                    }
                    rhs[i][j] = c_s + if i == j { 1.0 / n } else { 0.0 };
                }
                if local {
                    rhs[4][i] = s_kappa[i];
                }
            }
            let sol = step
                .jacobian
                .ok_or("no Jacobian for the tangent")?
                .solve_columns(&rhs)
                .ok_or("singular Jacobian in the tangent")?;
            s_sigma = [sol[0], sol[1], sol[2], sol[3]];
            if local {
                s_kappa = sol[4];
            }
        }
        let tangent = s_sigma;
        Ok(Integrated {
            stress,
            kappa,
            plastic_strain_increment: plastic,
            tangent,
            yielded,
        })
    }

    /// Tip return σ = p_t (1,1,1,0), Δε^p = Δε − C(σ − σ_n), Δκ = ‖Δε^p‖ε, D_alg = 0 (theory §5.6 step 4).
    fn tip_return(
        &self,
        stress_n: &Voigt,
        strain_increment: &Voigt,
        kappa_n: f64,
        arg: StrengthArg,
    ) -> Integrated {
        let mut kappa = kappa_n;
        let mut stress = [0.0; 4];
        let mut plastic = [0.0; 4];
        for _ in 0..50 {
            let tensile = self.strength_f64(arg.at(kappa)).tensile_strength;
            stress = [tensile, tensile, tensile, 0.0];
            let diff = [
                stress[0] - stress_n[0],
                stress[1] - stress_n[1],
                stress[2] - stress_n[2],
                stress[3] - stress_n[3],
            ];
            let elastic = mat4_mul_vec(&self.compliance, &diff);
            plastic = std::array::from_fn(|i| strain_increment[i] - elastic[i]);
            let kappa_new = kappa_n + strain_norm(&plastic);
            let change = (kappa_new - kappa).abs();
            kappa = kappa_new;
            if !arg.couples_kappa() || change <= KAPPA_TOLERANCE {
                break;
            }
        }
        Integrated {
            stress,
            kappa,
            plastic_strain_increment: plastic,
            tangent: [[0.0; 4]; 4],
            yielded: true,
        }
    }

    /// The stress update with diagnostics: also returns the number of sub-steps used
    /// (0 = tip return). Same semantics as [`ConstitutiveModel::update`].
    pub fn update_with_substeps(
        &self,
        stress_rotated: &Voigt,
        strain_increment: &Voigt,
        state_n: &PointState,
        strength: StrengthVariable,
    ) -> Result<(StressUpdate, u32), ConstitutiveError> {
        self.return_map(stress_rotated, strain_increment, state_n, strength, true)
    }

    /// [`Self::update_with_substeps`]; without `want_tangent` the tangent is left zero
    /// and its sensitivity solves are skipped (the same stress and state bits).
    fn return_map(
        &self,
        stress_rotated: &Voigt,
        strain_increment: &Voigt,
        state_n: &PointState,
        strength: StrengthVariable,
        want_tangent: bool,
    ) -> Result<(StressUpdate, u32), ConstitutiveError> {
        let kappa_n = state_n.plastic_strain_eq;
        let arg = StrengthArg::new(strength, kappa_n);
        check_input(stress_rotated, strain_increment, kappa_n, arg, strength)?;
        let d_eps = mat4_mul_vec(&self.stiffness, strain_increment);
        let trial: Voigt = std::array::from_fn(|i| stress_rotated[i] + d_eps[i]);
        let start = (stress_rotated, strain_increment, kappa_n, arg);
        let (mut result, substeps) = self.substepped_or_tip(start, &trial, want_tangent)?;
        if substeps > 1 && self.has_symmetric_tangent() {
            symmetrise(&mut result.tangent);
        }
        let state = updated_state(state_n, &result, strength);
        self.check_returned(&result, substeps, arg, (&trial, kappa_n))?;
        Ok((
            StressUpdate {
                stress: result.stress,
                state,
                tangent: result.tangent,
                yielded: result.yielded,
            },
            substeps,
        ))
    }

    /// The integration with 1, 2, 4, … sub-steps, the first that succeeds
    /// (up to 2^[`MAX_SUBSTEP_LEVEL`]), and its number of sub-steps; or the
    /// tip return (0 sub-steps) where the trial mean stress lies beyond the
    /// tensile strength and the integration failed or ended at the apex.
    fn substepped_or_tip(
        &self,
        (stress_rotated, strain_increment, kappa_n, arg): (&Voigt, &Voigt, f64, StrengthArg),
        trial: &Voigt,
        want_tangent: bool,
    ) -> Result<(Integrated, u32), ConstitutiveError> {
        let trial_mean = -(trial[0] + trial[1] + trial[2]) / 3.0;
        let tip_applies = |kappa: f64| trial_mean < -self.strength(arg.at(kappa)).tensile_strength;
        let mut outcome = None;
        let mut failure = "";
        for level in 0..=MAX_SUBSTEP_LEVEL {
            let substeps: u32 = 1 << level;
            match self.integrate(
                stress_rotated,
                strain_increment,
                kappa_n,
                arg,
                substeps,
                want_tangent,
            ) {
                Ok(result) => {
                    outcome = Some((result, substeps));
                    break;
                }
                Err(reason) => failure = reason,
            }
        }
        Ok(match outcome {
            Some((result, substeps)) => {
                let at_tip = result.yielded
                    && Invariants::of(&result.stress, 0.0).j < TIP_J_FRACTION * self.strength_scale
                    && tip_applies(result.kappa);
                if at_tip {
                    (
                        self.tip_return(stress_rotated, strain_increment, kappa_n, arg),
                        0,
                    )
                } else {
                    (result, substeps)
                }
            }
            None if tip_applies(kappa_n) => (
                self.tip_return(stress_rotated, strain_increment, kappa_n, arg),
                0,
            ),
            None => {
                return Err(ConstitutiveError::ReturnMappingFailed {
                    reason: format!("{failure} after {} sub-steps", 1 << MAX_SUBSTEP_LEVEL),
                    trial_stress: *trial,
                    kappa: kappa_n,
                })
            }
        })
    }

    /// The returned stress and tangent are finite and the stress is not outside
    /// the surface (`trial`: the trial stress and κ_n, for the error).
    fn check_returned(
        &self,
        result: &Integrated,
        substeps: u32,
        arg: StrengthArg,
        (trial, kappa_n): (&Voigt, f64),
    ) -> Result<(), ConstitutiveError> {
        let finite = result
            .stress
            .iter()
            .chain(result.tangent.iter().flatten())
            .all(|x| x.is_finite())
            && result.kappa.is_finite();
        if !finite {
            return Err(ConstitutiveError::NonFinite(format!(
                "stress {:?}, κ = {}",
                result.stress, result.kappa
            )));
        }
        // Never hand back a stress outside the surface. A sub-stepped result already holds it:
        // its last sub-step ended elastic with f ≤ 1e-10 c_ref or converged with
        // |f| ≤ max(1e-11 c_ref, 1e-13 |σ_trial|), far inside the bound below, at the same
        // strength (κ_s at the returned κ). So only a tip return (sub-steps 0) is evaluated.
        let f = if result.yielded && substeps == 0 {
            self.surface
                .value(&result.stress, &self.strength_f64(arg.at(result.kappa)))
        } else {
            f64::NEG_INFINITY
        };
        let scale = self
            .strength_scale
            .max(1e-6 * trial.iter().fold(0.0f64, |acc, x| acc.max(x.abs())));
        if f > 1e-6 * scale {
            return Err(ConstitutiveError::ReturnMappingFailed {
                reason: format!("returned stress violates the yield condition (f = {f} kPa)"),
                trial_stress: *trial,
                kappa: kappa_n,
            });
        }
        Ok(())
    }
}

/// The inputs of a return mapping are finite.
fn check_input(
    stress_rotated: &Voigt,
    strain_increment: &Voigt,
    kappa_n: f64,
    arg: StrengthArg,
    strength: StrengthVariable,
) -> Result<(), ConstitutiveError> {
    if stress_rotated
        .iter()
        .chain(strain_increment.iter())
        .any(|x| !x.is_finite())
        || !kappa_n.is_finite()
        || !arg.is_finite()
    {
        return Err(ConstitutiveError::NonFinite(format!(
            "input stress {stress_rotated:?}, strain increment {strain_increment:?}, κ = {kappa_n}, strength variable {strength:?}",
        )));
    }
    Ok(())
}

/// The symmetric part of a sub-stepped tangent. The chained tangent of several
/// sub-steps is not exactly symmetric even for associated perfect plasticity;
/// this keeps the promise of `has_symmetric_tangent` (Cholesky) (an
/// approximation only in sub-stepped updates).
fn symmetrise(tangent: &mut Mat4) {
    for i in 0..4 {
        for j in 0..i {
            let mean = 0.5 * (tangent[i][j] + tangent[j][i]);
            tangent[i][j] = mean;
            tangent[j][i] = mean;
        }
    }
}

/// The point's state after the update: κ (and κ̄ of a local run) and the
/// plastic strain increment added.
fn updated_state(
    state_n: &PointState,
    result: &Integrated,
    strength: StrengthVariable,
) -> PointState {
    let mut state = *state_n;
    state.plastic_strain_eq = result.kappa;
    if strength == StrengthVariable::Local {
        state.plastic_strain_eq_nonlocal = result.kappa;
    }
    for i in 0..4 {
        state.plastic_strain[i] += result.plastic_strain_increment[i];
    }
    state
}

impl ConstitutiveModel for Hmc {
    fn name(&self) -> &'static str {
        "hmc"
    }

    fn elastic_stiffness(&self) -> Mat4 {
        self.stiffness
    }

    fn p_wave_modulus(&self) -> f64 {
        self.elastic.p_wave_modulus()
    }

    fn is_elastic(&self) -> bool {
        false
    }

    /// Symmetric only for associated flow (ω = 1) without any softening (theory D32); sub-stepped
    /// updates of such a model return the symmetric part of their chained tangent.
    fn has_symmetric_tangent(&self) -> bool {
        self.flow.is_associated() && !self.softening
    }

    fn can_soften(&self) -> bool {
        self.softening
    }

    /// theory D39: a smoothed stress outside the surface is scaled back onto it at
    /// fixed p and θ (deviator scaled), or set to the tip p_t·(1,1,1,0) when the
    /// pressure lies beyond the apex. The strength is taken at κ̄ (nonlocal) or κ.
    fn project_to_surface(
        &self,
        stress: &Voigt,
        state: &PointState,
        strength_kappa: Option<f64>,
    ) -> Voigt {
        let kappa = strength_kappa.unwrap_or(state.plastic_strain_eq);
        let strength: SurfaceStrength<f64> = self.strength(kappa);
        if self.surface.value(stress, &strength) <= 1e-10 * self.strength_scale() {
            return *stress;
        }
        let inv = Invariants::of(stress, self.surface.j_min);
        let p = inv.mean_stress;
        let capacity = strength.cohesion + p * strength.tan_friction;
        if capacity < strength.hyperbola_a || inv.j <= 0.0 {
            let pt = strength.tensile_strength;
            return [pt, pt, pt, 0.0];
        }
        let radius = HyperbolicMohrCoulomb::shape_radius(&strength, inv.sin_3theta);
        let j_new =
            radius * (capacity * capacity - strength.hyperbola_a * strength.hyperbola_a).sqrt();
        let scale = j_new / inv.j;
        [
            -p + scale * (stress[0] + p),
            -p + scale * (stress[1] + p),
            -p + scale * (stress[2] + p),
            scale * stress[3],
        ]
    }

    /// Return mapping of theory D29–D32 with sub-stepping and tip treatment.
    fn update(
        &self,
        stress_rotated: &Voigt,
        strain_increment: &Voigt,
        state_n: &PointState,
        strength: StrengthVariable,
    ) -> Result<StressUpdate, ConstitutiveError> {
        self.update_with_substeps(stress_rotated, strain_increment, state_n, strength)
            .map(|(u, _)| u)
    }

    /// The return mapping without its tangent (explicit steps): no sensitivity solves.
    fn update_stress(
        &self,
        stress_rotated: &Voigt,
        strain_increment: &Voigt,
        state_n: &PointState,
        strength: StrengthVariable,
        (stress, state): (&mut Voigt, &mut PointState),
    ) -> Result<bool, ConstitutiveError> {
        let (update, _) =
            self.return_map(stress_rotated, strain_increment, state_n, strength, false)?;
        *stress = update.stress;
        *state = update.state;
        Ok(update.yielded)
    }
}

#[cfg(test)]
mod tests;
