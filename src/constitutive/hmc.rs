//! Hyperbolic Mohr–Coulomb model with exponential strain softening (paper §2.2,
//! eqs. 3–5; DESIGN §5): parameters, strength evolution and the return mapping
//! with its consistent tangent (DESIGN D29–D32).
//!
//! The pieces are kept apart so a second model can reuse them:
//! yield criterion [`HyperbolicMohrCoulomb`] (D23–D25), flow rule
//! [`PressureScaledFlow`] (D26), softening law [`ThreeLevelSoftening`] (D28).
//! Second derivatives of the return mapping come from forward-mode dual numbers
//! (exact), see [`super::dual`].

use nalgebra::{SMatrix, SVector};
use serde::{Deserialize, Serialize};

use super::dual::{Dual, Real};
use super::flow_rule::{strain_norm, PressureScaledFlow};
use super::softening::ThreeLevelSoftening;
use super::yield_surface::{HyperbolicMohrCoulomb, Invariants, SurfaceStrength};
use super::{
    mat4_mul_vec, ConstitutiveError, ConstitutiveModel, LinearElastic, Mat4, PointState,
    StrengthVariable, StressUpdate, Voigt,
};

/// Newton iterations per (sub)step before sub-stepping (DESIGN §5.6 step 3).
const MAX_NEWTON_ITERATIONS: usize = 50;
/// Maximum number of line-search halvings (DESIGN §5.6 step 2).
const MAX_LINE_SEARCH_HALVINGS: usize = 10;
/// Finest sub-stepping level: 2^6 = 64 sub-steps (DESIGN §5.6 step 3).
const MAX_SUBSTEP_LEVEL: u32 = 6;
/// Elastic-check tolerance on f relative to c_ref (DESIGN §5.6 step 1).
const ELASTIC_TOLERANCE: f64 = 1e-10;
/// Newton tolerance on ‖r_σ‖·E and |f| relative to c_ref (DESIGN §5.6 step 2 says 1e−9; tightened so
/// that the converged stress is accurate enough for finite-difference tangent checks at η = 1e−6).
const NEWTON_TOLERANCE: f64 = 1e-11;
/// Newton tolerance on |r_κ| (absolute, DESIGN §5.6 step 2).
const KAPPA_TOLERANCE: f64 = 1e-12;
/// Cohesion floor c_min = 1e−3 c_peak (DESIGN §5.5).
const COHESION_FLOOR_FRACTION: f64 = 1e-3;
/// Below J = 1e−10 c_ref the Lode angle is undefined (DESIGN D6).
const LODE_J_MIN_FRACTION: f64 = 1e-10;
/// A converged state with J < 1e−8 c_ref is "at the tip" (DESIGN §5.6 step 4).
const TIP_J_FRACTION: f64 = 1e-8;
/// Largest admissible friction angle (degrees): the van Eekelen shape with Z = −0.229 is
/// convex only for |Y| ≤ 0.79, i.e. φ ≲ 46° (DESIGN §5.3).
pub const MAX_FRICTION_ANGLE_DEG: f64 = 46.0;

fn default_density() -> f64 {
    2.0
}

/// Material parameters of the hyperbolic Mohr–Coulomb softening model (paper Table 1).
/// TOML keys in brackets; angles in degrees, stresses in kPa.
#[derive(Clone, Copy, Debug, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct HmcParameters {
    /// `E`: Young's modulus, kPa (DESIGN D22).
    #[serde(rename = "E")]
    pub youngs_modulus: f64,
    /// `nu`: Poisson's ratio (DESIGN D22).
    #[serde(rename = "nu")]
    pub poisson_ratio: f64,
    /// `density`: mass density, t/m³ (default 2.0).
    #[serde(default = "default_density")]
    pub density: f64,
    /// `phi_ini`: initial asymptotic friction angle φ*_ini, degrees (must equal φ_peak, DESIGN §5.5).
    #[serde(rename = "phi_ini")]
    pub friction_angle_ini: f64,
    /// `phi_peak`: peak asymptotic friction angle φ*_peak, degrees (DESIGN D28).
    #[serde(rename = "phi_peak")]
    pub friction_angle_peak: f64,
    /// `phi_res`: residual friction angle φ*_res, degrees (DESIGN D28).
    #[serde(rename = "phi_res")]
    pub friction_angle_res: f64,
    /// `c_ini`: initial (= peak) asymptotic cohesion c*_ini, kPa (paper eq. 4).
    #[serde(rename = "c_ini")]
    pub cohesion_ini: f64,
    /// `c_post`: post-rupture asymptotic cohesion c*_post, kPa (paper eq. 4).
    #[serde(rename = "c_post")]
    pub cohesion_post: f64,
    /// `pt_ini`: initial tensile strength p_t,ini, kPa (DESIGN D23, D28).
    #[serde(rename = "pt_ini")]
    pub tensile_strength_ini: f64,
    /// `pt_post`: post-rupture tensile strength p_t,post, kPa (DESIGN D28).
    #[serde(rename = "pt_post")]
    pub tensile_strength_post: f64,
    /// `b_post`: post-rupture softening rate (dimensionless, paper eq. 4).
    #[serde(rename = "b_post")]
    pub softening_rate_post: f64,
    /// `b_res`: residual softening rate (dimensionless, paper eq. 4).
    #[serde(rename = "b_res")]
    pub softening_rate_res: f64,
    /// `omega`: non-associativity constant ω (DESIGN D26).
    pub omega: f64,
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
        }
    }

    /// Check every parameter; one message per problem, naming `{prefix}.{key}` and the allowed range.
    ///
    /// Ranges: E > 0; −1 < ν < 0.5; density > 0; 0 < φ_peak ≤ 46° (van Eekelen convexity, §5.3);
    /// 0 < φ_res ≤ φ_peak; φ_ini = φ_peak (no pre-peak hardening, §5.5); c_ini > 0;
    /// 0 ≤ c_post ≤ c_ini; 0 ≤ p_t,ini ≤ c_ini cot φ_peak; 0 ≤ p_t,post ≤ c_post cot φ_peak (a ≥ 0,
    /// D23); b_post, b_res ≥ 0; 0 ≤ ω ≤ 1 (D26). All values must be finite.
    pub fn validate(&self, prefix: &str) -> Vec<String> {
        let mut problems = Vec::new();
        let fields: [(&str, f64); 13] = [
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
                problems.push(format!("{prefix}.{key} = {value} must be a finite number"));
            }
        }
        if !problems.is_empty() {
            return problems;
        }
        let mut check = |ok: bool, key: &str, value: f64, range: String| {
            if !ok {
                problems.push(format!("{prefix}.{key} = {value} is out of range: {range}"));
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

/// Strength parameters at one κ (DESIGN D28 with floor and clamp), for output and tests.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StrengthAtKappa {
    /// Asymptotic cohesion c*(κ), kPa, floored at 1e−3 c_peak.
    pub cohesion: f64,
    /// Asymptotic friction angle φ*(κ), degrees.
    pub friction_angle_deg: f64,
    /// Tensile strength p_t(κ), kPa, clamped to [0, (c − c_min)/tanφ].
    pub tensile_strength: f64,
}

/// Hyperbolic Mohr–Coulomb softening model (paper §2.2; DESIGN §5), ready to use:
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
}

/// Second-order information at one (σ, κ) of the return mapping (DESIGN D30–D31).
/// The strength argument κ_s as an affine function of the point's own κ, fixed
/// for one stress update ([`StrengthVariable`]): local κ_s = κ; nonlocal
/// κ_s = max(0, κ̄_nb + w (κ − κ_n)) with w = 1 − m the weight of the own
/// increment (κ̄ is a non-negative average: the clamp guards round-off and
/// m > 1). With w = 0 the κ row of D29 is dropped (DESIGN §5.6, nonlocal) and
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

type Mat6 = SMatrix<f64, 6, 6>;
type Vec6 = SVector<f64, 6>;

/// A converged plastic (sub)step.
struct PlasticStep {
    stress: Voigt,
    kappa: f64,
    plastic_multiplier: f64,
    flow_direction: Voigt,
    jacobian: nalgebra::LU<f64, nalgebra::Const<6>, nalgebra::Const<6>>,
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
    /// Build the model; returns the validation messages (prefix `material`) if the parameters are invalid.
    pub fn new(parameters: HmcParameters) -> Result<Self, Vec<String>> {
        let problems = parameters.validate("material");
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
        // φ_post := φ_peak (DESIGN §5.5 choice), angles in radians.
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
        };
        model.fixed_strength = model.strength(0.0);
        model.softening = softening;
        Ok(model)
    }

    /// The parameters the model was built from.
    pub fn parameters(&self) -> &HmcParameters {
        &self.parameters
    }

    /// True when some strength parameter can soften with κ (DESIGN D28).
    pub fn can_soften(&self) -> bool {
        self.softening
    }

    /// Strength scale c_ref = c_peak (kPa) used for tolerances (DESIGN §5.6).
    pub fn strength_scale(&self) -> f64 {
        self.strength_scale
    }

    /// The yield criterion (DESIGN D23–D25).
    pub fn yield_criterion(&self) -> &HyperbolicMohrCoulomb {
        &self.surface
    }

    /// The flow rule (DESIGN D26).
    pub fn flow_rule(&self) -> &PressureScaledFlow {
        &self.flow
    }

    /// Surface strength at κ: D28 with the c floor c ≥ 1e−3 c_peak and the clamp
    /// 0 ≤ p_t ≤ (c − c_min)/tanφ (DESIGN §5.2, §5.5); generic for exact κ-derivatives.
    #[inline]
    fn strength<T: Real>(&self, kappa: T) -> SurfaceStrength<T> {
        if !self.softening {
            return self.fixed_strength.lift();
        }
        let cohesion = self
            .cohesion_law
            .value(kappa)
            .max_by_value(T::cst(self.cohesion_min));
        let (sin_phi, cos_phi) = self.friction_law.value(kappa).sin_cos();
        let tensile_max = (cohesion - self.cohesion_min) * cos_phi / sin_phi;
        let tensile = self
            .tensile_law
            .value(kappa)
            .min_by_value(tensile_max)
            .max_by_value(T::cst(0.0));
        SurfaceStrength::from_sin_cos(cohesion, sin_phi, cos_phi, tensile)
    }

    /// Strength parameters at equivalent plastic strain κ (DESIGN D28, floor and clamp included).
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

    /// Yield function f(σ, κ) of DESIGN D23 (kPa); f ≤ 0 admissible.
    pub fn yield_function(&self, stress: &Voigt, kappa: f64) -> f64 {
        self.surface.value(stress, &self.strength(kappa))
    }

    /// Plastic flow direction m = ∂G/∂σ at (σ, κ) (DESIGN D26, D31).
    pub fn flow_direction(&self, stress: &Voigt, kappa: f64) -> Voigt {
        let strength = self.strength(kappa);
        let (_, gradient) = self.surface.value_and_gradient(stress, &strength);
        self.flow.direction(&gradient, strength.tan_friction)
    }

    /// f, f_σ, m, m_σ, h = ‖m‖ε and their κ-derivatives by one dual-number evaluation
    /// (exact; DESIGN D30–D31), with the strength at κ_s = `arg`(κ); the κ-derivatives
    /// are zero when κ_s does not depend on κ (strength frozen, nonlocal m = 1).
    #[inline]
    fn linearise(&self, stress: &Voigt, kappa: f64, arg: StrengthArg) -> Linearisation {
        type D5 = Dual<5>;
        let sigma: [D5; 4] = std::array::from_fn(|i| D5::variable(stress[i], i));
        let kappa = if arg.couples_kappa() {
            arg.at_generic(D5::variable(kappa, 4))
        } else {
            D5::cst(arg.at(kappa))
        };
        let strength = self.strength(kappa);
        let (f, gradient) = self.surface.value_and_gradient(&sigma, &strength);
        let m = self.flow.direction(&gradient, strength.tan_friction);
        // ‖m‖ε (D3); the tiny shift keeps the dual derivative finite if m = 0 (ω = 0 at the tip).
        let h = (m[0] * m[0] + m[1] * m[1] + m[2] * m[2] + m[3] * m[3] * 0.5 + 1e-300).sqrt();
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

    /// Residual of D29 (strain-like components) at y = (σ, κ, Δλ) from f64 evaluations only.
    #[inline]
    fn residual(
        &self,
        stress: &Voigt,
        kappa: f64,
        multiplier: f64,
        trial: &Voigt,
        kappa_n: f64,
        arg: StrengthArg,
    ) -> (Vec6, f64) {
        let strength = self.strength_f64(arg.at(kappa));
        let (f, gradient) = self.surface.value_and_gradient(stress, &strength);
        let m = self.flow.direction(&gradient, strength.tan_friction);
        let r = self.assemble_residual(
            stress,
            kappa,
            multiplier,
            trial,
            kappa_n,
            arg.couples_kappa(),
            &m,
            strain_norm(&m),
            f,
        );
        (r, f)
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

    /// Jacobian A of DESIGN D30 (nonlocal: κ row and column replaced by the identity).
    #[inline]
    fn jacobian(&self, lin: &Linearisation, multiplier: f64, local: bool) -> Mat6 {
        let e = self.parameters.youngs_modulus;
        let mut a = Mat6::zeros();
        for i in 0..4 {
            for j in 0..4 {
                a[(i, j)] = self.compliance[i][j] + multiplier * lin.m_sigma[i][j];
            }
            a[(i, 5)] = lin.m[i];
            a[(5, i)] = lin.f_sigma[i] / e;
        }
        if local {
            for i in 0..4 {
                a[(i, 4)] = multiplier * lin.m_kappa[i];
                a[(4, i)] = -multiplier * lin.h_sigma[i];
            }
            a[(4, 4)] = 1.0 - multiplier * lin.h_kappa;
            a[(4, 5)] = -lin.h;
            a[(5, 4)] = lin.f_kappa / e;
        } else {
            a[(4, 4)] = 1.0;
        }
        a
    }

    /// Closest-point projection of one (sub)step from the trial stress (DESIGN D29–D30).
    fn plastic_step(
        &self,
        trial: &Voigt,
        kappa_n: f64,
        arg: StrengthArg,
        tolerance: f64,
    ) -> Result<PlasticStep, &'static str> {
        let local = arg.couples_kappa();
        let e = self.parameters.youngs_modulus;
        let mut stress = *trial;
        let mut kappa = kappa_n;
        let mut multiplier = 0.0;
        let mut lin = self.linearise(&stress, kappa, arg);
        for _ in 0..MAX_NEWTON_ITERATIONS {
            let r = self.assemble_residual(
                &stress, kappa, multiplier, trial, kappa_n, local, &lin.m, lin.h, lin.f,
            );
            let r_sigma = r[0].abs().max(r[1].abs()).max(r[2].abs()).max(r[3].abs());
            let jacobian = self.jacobian(&lin, multiplier, local);
            let lu = jacobian.lu();
            if r_sigma * e <= tolerance && lin.f.abs() <= tolerance && r[4].abs() <= KAPPA_TOLERANCE
            {
                if multiplier < 0.0 {
                    return Err("negative plastic multiplier");
                }
                if !lu.is_invertible() {
                    return Err("singular Jacobian at the converged state");
                }
                let kappa_new = if local {
                    kappa
                } else {
                    kappa_n + multiplier * lin.h
                };
                return Ok(PlasticStep {
                    stress,
                    kappa: kappa_new,
                    plastic_multiplier: multiplier,
                    flow_direction: lin.m,
                    jacobian: lu,
                });
            }
            let step = lu.solve(&(-r)).ok_or("singular Jacobian")?;
            if step.iter().any(|x| !x.is_finite()) {
                return Err("non-finite Newton step");
            }
            // Backtracking line search on ‖r‖ (DESIGN §5.6 step 2). The full step is evaluated
            // with the dual linearisation, which is reused by the next iteration when accepted.
            let norm0 = r.norm();
            let point = |alpha: f64| {
                let s_try: Voigt = std::array::from_fn(|i| stress[i] + alpha * step[i]);
                let k_try = if local {
                    kappa + alpha * step[4]
                } else {
                    kappa
                };
                (s_try, k_try, multiplier + alpha * step[5])
            };
            let (s_full, k_full, l_full) = point(1.0);
            let lin_full = self.linearise(&s_full, k_full, arg);
            let r_full = self.assemble_residual(
                &s_full,
                k_full,
                l_full,
                trial,
                kappa_n,
                local,
                &lin_full.m,
                lin_full.h,
                lin_full.f,
            );
            let norm_full = r_full.norm();
            if norm_full.is_finite() && norm_full <= (1.0 - 1e-4) * norm0 {
                (stress, kappa, multiplier, lin) = (s_full, k_full, l_full, lin_full);
                continue;
            }
            let mut alpha = 1.0;
            for halving in 1..=MAX_LINE_SEARCH_HALVINGS {
                alpha *= 0.5;
                let (s_try, k_try, l_try) = point(alpha);
                let (r_try, _) = self.residual(&s_try, k_try, l_try, trial, kappa_n, arg);
                let norm = r_try.norm();
                if (norm.is_finite() && norm <= (1.0 - 1e-4 * alpha) * norm0)
                    || halving == MAX_LINE_SEARCH_HALVINGS
                {
                    if !norm.is_finite() {
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

    /// Integrate the whole increment with `substeps` equal sub-steps; the tangent is the
    /// exact derivative of the sub-stepped update (chain rule through the sub-steps,
    /// which reduces to D32 for one step).
    fn integrate(
        &self,
        stress_n: &Voigt,
        strain_increment: &Voigt,
        kappa_n: f64,
        arg: StrengthArg,
        substeps: u32,
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
        let mut s_sigma = SMatrix::<f64, 4, 4>::zeros();
        let mut s_kappa = SMatrix::<f64, 1, 4>::zeros();
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
                for i in 0..4 {
                    for j in 0..4 {
                        s_sigma[(i, j)] += self.stiffness[i][j] / n;
                    }
                }
                continue;
            }
            let trial_scale = trial.iter().fold(0.0f64, |acc, x| acc.max(x.abs()));
            // Round-off floor for very large stresses (~500 ulp of the trial stress).
            let tolerance = tolerance_base.max(1e-13 * trial_scale);
            let step = self.plastic_step(&trial, kappa, arg, tolerance)?;
            // Sensitivity: A dy = [C dσ_k + dΔε/n; dκ_k; 0] (linearised D29).
            let mut rhs = SMatrix::<f64, 6, 4>::zeros();
            for i in 0..4 {
                for j in 0..4 {
                    let mut c_s = 0.0;
                    for k in 0..4 {
                        c_s += self.compliance[i][k] * s_sigma[(k, j)];
                    }
                    rhs[(i, j)] = c_s + if i == j { 1.0 / n } else { 0.0 };
                }
                if local {
                    rhs[(4, i)] = s_kappa[(0, i)];
                }
            }
            let sol = step
                .jacobian
                .solve(&rhs)
                .ok_or("singular Jacobian in the tangent")?;
            s_sigma = sol.fixed_view::<4, 4>(0, 0).into_owned();
            if local {
                s_kappa = sol.fixed_view::<1, 4>(4, 0).into_owned();
            }
            for (p, m) in plastic.iter_mut().zip(step.flow_direction) {
                *p += step.plastic_multiplier * m;
            }
            stress = step.stress;
            kappa = step.kappa;
            yielded = true;
        }
        let tangent = std::array::from_fn(|i| std::array::from_fn(|j| s_sigma[(i, j)]));
        Ok(Integrated {
            stress,
            kappa,
            plastic_strain_increment: plastic,
            tangent,
            yielded,
        })
    }

    /// Tip return σ = p_t (1,1,1,0), Δε^p = Δε − C(σ − σ_n), Δκ = ‖Δε^p‖ε, D_alg = 0 (DESIGN §5.6 step 4).
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
        let kappa_n = state_n.plastic_strain_eq;
        let arg = StrengthArg::new(strength, kappa_n);
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
        let d_eps = mat4_mul_vec(&self.stiffness, strain_increment);
        let trial: Voigt = std::array::from_fn(|i| stress_rotated[i] + d_eps[i]);
        let trial_mean = -(trial[0] + trial[1] + trial[2]) / 3.0;
        let tip_applies = |kappa: f64| trial_mean < -self.strength(arg.at(kappa)).tensile_strength;
        let mut outcome = None;
        let mut failure = "";
        for level in 0..=MAX_SUBSTEP_LEVEL {
            match self.integrate(stress_rotated, strain_increment, kappa_n, arg, 1 << level) {
                Ok(result) => {
                    outcome = Some((result, 1u32 << level));
                    break;
                }
                Err(reason) => failure = reason,
            }
        }
        let (mut result, substeps) = match outcome {
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
                    trial_stress: trial,
                    kappa: kappa_n,
                })
            }
        };
        if substeps > 1 && self.has_symmetric_tangent() {
            // The chained tangent of several sub-steps is not exactly symmetric even for associated
            // perfect plasticity; keep the promise of has_symmetric_tangent (Cholesky) with its
            // symmetric part (an approximation only in sub-stepped updates).
            for i in 0..4 {
                for j in 0..i {
                    let mean = 0.5 * (result.tangent[i][j] + result.tangent[j][i]);
                    result.tangent[i][j] = mean;
                    result.tangent[j][i] = mean;
                }
            }
        }
        let mut state = *state_n;
        state.plastic_strain_eq = result.kappa;
        if strength == StrengthVariable::Local {
            state.plastic_strain_eq_nonlocal = result.kappa;
        }
        for i in 0..4 {
            state.plastic_strain[i] += result.plastic_strain_increment[i];
        }
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
        // Never hand back a stress outside the surface (elastic results passed the check already).
        let f = if result.yielded {
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
                trial_stress: trial,
                kappa: kappa_n,
            });
        }
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

    /// Symmetric only for associated flow (ω = 1) without any softening (DESIGN D32); sub-stepped
    /// updates of such a model return the symmetric part of their chained tangent.
    fn has_symmetric_tangent(&self) -> bool {
        self.flow.is_associated() && !self.softening
    }

    fn can_soften(&self) -> bool {
        self.softening
    }

    /// DESIGN D39: a smoothed stress outside the surface is scaled back onto it at
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

    /// Return mapping of DESIGN D29–D32 with sub-stepping and tip treatment.
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
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::constitutive::flow_rule::strain_norm_f64;
    use crate::constitutive::yield_surface::stress_from_invariants;

    /// (label, model, σ_n, Δε, κ_n, strength variable) of the tangent check.
    type TangentCase<'a> = (String, &'a Hmc, Voigt, Voigt, f64, StrengthVariable);

    fn model(edit: impl FnOnce(&mut HmcParameters)) -> Hmc {
        let mut p = HmcParameters::table1();
        edit(&mut p);
        Hmc::new(p).expect("valid parameters")
    }

    /// Table 1 without any softening (c_post = c_ini, φ_res = φ_peak).
    fn perfectly_plastic(omega: f64) -> Hmc {
        model(|p| {
            p.cohesion_post = p.cohesion_ini;
            p.friction_angle_res = p.friction_angle_peak;
            p.softening_rate_post = 0.0;
            p.softening_rate_res = 0.0;
            p.omega = omega;
        })
    }

    fn isotropic(p: f64) -> Voigt {
        [-p, -p, -p, 0.0]
    }

    fn add(a: &Voigt, b: &Voigt) -> Voigt {
        std::array::from_fn(|i| a[i] + b[i])
    }

    fn scale(a: &Voigt, k: f64) -> Voigt {
        a.map(|x| x * k)
    }

    /// Smallest factor t such that σ0 + D (t·dir) reaches f = 0 (bisection on the elastic trial).
    fn elastic_limit(model: &Hmc, stress0: &Voigt, direction: &Voigt) -> f64 {
        let d = model.elastic_stiffness();
        let f = |t: f64| {
            model.yield_function(&add(stress0, &mat4_mul_vec(&d, &scale(direction, t))), 0.0)
        };
        let (mut lo, mut hi) = (0.0, 1.0);
        while f(hi) < 0.0 {
            hi *= 2.0;
        }
        for _ in 0..100 {
            let mid = 0.5 * (lo + hi);
            if f(mid) < 0.0 {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        hi
    }

    /// Run a proportional strain path in `n` equal increments (local mode).
    fn proportional_path(
        model: &Hmc,
        stress0: &Voigt,
        total: &Voigt,
        n: usize,
    ) -> (Voigt, PointState) {
        let mut stress = *stress0;
        let mut state = PointState::default();
        let inc = scale(total, 1.0 / n as f64);
        for _ in 0..n {
            let u = model
                .update(&stress, &inc, &state, StrengthVariable::Local)
                .expect("update converges");
            stress = u.stress;
            state = u.state;
        }
        (stress, state)
    }

    /// Table 1 values (paper) and TOML keys; deny_unknown_fields rejects typos.
    #[test]
    fn table1_and_toml_keys() {
        let text = "E = 20000.0\nnu = 0.2\nphi_ini = 20.0\nphi_peak = 20.0\nphi_res = 15.0\nc_ini = 200.0\n\
                    c_post = 0.0\npt_ini = 0.0\npt_post = 0.0\nb_post = 10.0\nb_res = 2.0\nomega = 1.0\n";
        let parsed: HmcParameters = toml::from_str(text).expect("parse");
        assert_eq!(parsed, HmcParameters::table1());
        assert!(toml::from_str::<HmcParameters>(&format!("{text}phi_post = 3.0\n")).is_err());
        assert!(HmcParameters::table1().validate("m").is_empty());
    }

    /// validate() names each bad field as `{prefix}.{key}`.
    #[test]
    fn validation_messages_name_fields() {
        let mut p = HmcParameters::table1();
        p.youngs_modulus = -1.0;
        p.poisson_ratio = 0.5;
        p.friction_angle_ini = 25.0;
        p.friction_angle_res = 21.0;
        p.cohesion_post = 300.0;
        p.tensile_strength_ini = 1e4;
        p.omega = 1.5;
        let problems = p.validate("material.soil");
        for key in ["E", "nu", "phi_ini", "phi_res", "c_post", "pt_ini", "omega"] {
            assert!(
                problems
                    .iter()
                    .any(|m| m.starts_with(&format!("material.soil.{key} "))),
                "no message for {key}: {problems:?}"
            );
        }
        assert_eq!(problems.len(), 7, "{problems:?}");
        p = HmcParameters::table1();
        p.density = f64::NAN;
        assert_eq!(p.validate("x").len(), 1);
        assert!(Hmc::new(p).is_err());
    }

    /// D28 for Table 1: c = 200 e^{−10κ} (floored at 0.2 kPa), φ = 15° + 5° e^{−2κ}, p_t = 0, at three κ
    /// (tolerance 1e-12 relative), and with p_t > 0 the three-level law of D28 for p_t.
    #[test]
    fn strength_follows_d28() {
        let m = model(|_| {});
        for kappa in [0.0, 0.1, 0.5, 2.0] {
            let s = m.strength_at(kappa);
            let c = (200.0 * (-10.0 * kappa).exp()).max(0.2);
            let phi = 15.0 + 5.0 * (-2.0 * kappa).exp();
            assert!(
                (s.cohesion - c).abs() <= 1e-12 * c,
                "κ = {kappa}: c = {}",
                s.cohesion
            );
            assert!(
                (s.friction_angle_deg - phi).abs() <= 1e-12 * phi,
                "κ = {kappa}: φ = {}",
                s.friction_angle_deg
            );
            assert_eq!(s.tensile_strength, 0.0);
        }
        let m = model(|p| {
            p.cohesion_post = 50.0;
            p.tensile_strength_ini = 100.0;
            p.tensile_strength_post = 40.0;
        });
        for kappa in [0.0, 0.1, 0.5] {
            let s = m.strength_at(kappa);
            let c = 50.0 * (-2.0 * kappa).exp() + 150.0 * (-10.0 * kappa).exp();
            let pt = 40.0 * (-2.0 * kappa).exp() + 60.0 * (-10.0 * kappa).exp();
            let phi = (15.0 + 5.0 * (-2.0 * kappa).exp()).to_radians();
            let pt = pt.min((c - 0.2) / phi.tan());
            assert!((s.cohesion - c).abs() <= 1e-12 * c);
            assert!(
                (s.tensile_strength - pt).abs() <= 1e-12 * pt,
                "κ = {kappa}: p_t = {} vs {pt}",
                s.tensile_strength
            );
        }
    }

    /// Symmetric tangent only for ω = 1 without softening; never elastic.
    #[test]
    fn tangent_symmetry_flag() {
        assert!(perfectly_plastic(1.0).has_symmetric_tangent());
        assert!(!perfectly_plastic(0.5).has_symmetric_tangent());
        assert!(!model(|_| {}).has_symmetric_tangent());
        // Softening possible only through p_t:
        let pt_only = model(|p| {
            p.cohesion_post = p.cohesion_ini;
            p.friction_angle_res = p.friction_angle_peak;
            p.tensile_strength_ini = 10.0;
        });
        assert!(!pt_only.has_symmetric_tangent());
        assert!(!model(|_| {}).is_elastic());
        // and the returned tangent is then symmetric (1e-10 relative), with and without sub-steps.
        let m = perfectly_plastic(1.0);
        for factor in [3.0, 300.0] {
            let dir = [0.2, -1.0, 0.0, 0.3];
            let inc = scale(&dir, factor * elastic_limit(&m, &isotropic(100.0), &dir));
            let u = m
                .update(
                    &isotropic(100.0),
                    &inc,
                    &PointState::default(),
                    StrengthVariable::Local,
                )
                .unwrap();
            assert!(u.yielded);
            let big = u
                .tangent
                .iter()
                .flatten()
                .fold(0.0f64, |a, x| a.max(x.abs()));
            for i in 0..4 {
                for j in 0..4 {
                    assert!((u.tangent[i][j] - u.tangent[j][i]).abs() <= 1e-10 * big);
                }
            }
        }
    }

    /// After a plastic update |f| ≤ 1e-8 c_ref, Δε^p = Δε − C Δσ is parallel to m(σ_{n+1}, κ_{n+1})
    /// (|cos − 1| ≤ 1e-10), Δκ = ‖Δε^p‖ε (1e-12), for several models, directions and both modes.
    #[test]
    fn return_is_on_surface_and_flow_is_normal() {
        let models = [
            model(|_| {}),
            perfectly_plastic(1.0),
            model(|p| p.omega = 0.3),
            model(|p| {
                p.cohesion_post = 50.0;
                p.tensile_strength_ini = 50.0;
                p.tensile_strength_post = 20.0;
            }),
        ];
        let directions = [
            [0.002, -0.01, 0.0, 0.0],
            [0.0, 0.0, 0.0, 0.02],
            [0.004, 0.003, 0.0, 0.001],
            [-0.003, 0.004, 0.0, 0.003],
        ];
        for m in &models {
            for dir in &directions {
                for frozen in [None, Some(0.05)] {
                    let stress0 = isotropic(100.0);
                    let state0 = PointState {
                        plastic_strain_eq: 0.02,
                        plastic_strain_eq_nonlocal: 0.02,
                        ..Default::default()
                    };
                    let dir = &scale(dir, 3.0 * elastic_limit(m, &stress0, dir));
                    let u = m
                        .update(&stress0, dir, &state0, frozen.into())
                        .expect("converges");
                    assert!(u.yielded, "direction {dir:?} should yield");
                    let kappa_strength = frozen.unwrap_or(u.state.plastic_strain_eq);
                    let f = m.yield_function(&u.stress, kappa_strength);
                    assert!(f.abs() <= 1e-8 * m.strength_scale(), "f = {f}");
                    let dsig: Voigt = std::array::from_fn(|i| u.stress[i] - stress0[i]);
                    let c_dsig = mat4_mul_vec(&m.compliance, &dsig);
                    let dep: Voigt = std::array::from_fn(|i| dir[i] - c_dsig[i]);
                    let recorded: Voigt = std::array::from_fn(|i| u.state.plastic_strain[i]);
                    for i in 0..4 {
                        assert!((dep[i] - recorded[i]).abs() <= 1e-10 * strain_norm_f64(&dep));
                    }
                    if u.state.plastic_strain_eq == state0.plastic_strain_eq {
                        continue;
                    }
                    let flow = m.flow_direction(&u.stress, kappa_strength);
                    let dot: f64 = (0..4).map(|i| dep[i] * flow[i]).sum();
                    let cos = dot
                        / (dep.iter().map(|x| x * x).sum::<f64>().sqrt()
                            * flow.iter().map(|x| x * x).sum::<f64>().sqrt());
                    assert!((cos - 1.0).abs() <= 1e-10, "cos = {cos} for {dir:?}");
                    let dk = u.state.plastic_strain_eq - state0.plastic_strain_eq;
                    assert!((dk - strain_norm_f64(&dep)).abs() <= 1e-12, "Δκ = {dk}");
                    match frozen {
                        None => assert_eq!(
                            u.state.plastic_strain_eq_nonlocal,
                            u.state.plastic_strain_eq
                        ),
                        Some(_) => assert_eq!(
                            u.state.plastic_strain_eq_nonlocal,
                            state0.plastic_strain_eq_nonlocal
                        ),
                    }
                }
            }
        }
    }

    /// A strain increment 100× the elastic limit converges (through sub-stepping if needed) with
    /// |f| ≤ 1e-8 c_ref, for compression, shear and extension directions, Table 1 softening.
    #[test]
    fn huge_increment_converges() {
        let m = model(|_| {});
        let stress0 = isotropic(100.0);
        for dir in [
            [0.0, -1.0, 0.0, 0.0],
            [0.0, 0.0, 0.0, 1.0],
            [0.5, -1.0, 0.0, 0.3],
            [1.0, 0.0, 0.0, 0.0],
        ] {
            let t = elastic_limit(&m, &stress0, &dir);
            let inc = scale(&dir, 100.0 * t);
            let (u, substeps) = m
                .update_with_substeps(
                    &stress0,
                    &inc,
                    &PointState::default(),
                    StrengthVariable::Local,
                )
                .expect("converges");
            let f = m.yield_function(&u.stress, u.state.plastic_strain_eq);
            assert!(f.abs() <= 1e-8 * m.strength_scale(), "f = {f}");
            assert!(u.stress.iter().all(|x| x.is_finite()));
            eprintln!(
                "direction {dir:?}: 100× elastic limit used {substeps} sub-step(s), κ = {}",
                u.state.plastic_strain_eq
            );
        }
    }

    /// Isotropic tension beyond the tip returns to the tip σ = p_t(1,1,1,0) with D_alg = 0.
    #[test]
    fn tip_return_in_tension() {
        let m = model(|p| {
            p.cohesion_post = 50.0;
            p.tensile_strength_ini = 30.0;
            p.tensile_strength_post = 30.0;
        });
        let u = m
            .update(
                &isotropic(10.0),
                &[0.01, 0.01, 0.01, 0.0],
                &PointState::default(),
                StrengthVariable::frozen(0.0),
            )
            .expect("tip");
        let pt = m.strength_at(0.0).tensile_strength;
        for i in 0..3 {
            assert!(
                (u.stress[i] - pt).abs() <= 1e-8 * m.strength_scale(),
                "{:?}",
                u.stress
            );
        }
        assert!(u.stress[3].abs() <= 1e-8 * m.strength_scale());
        assert!(u.tangent.iter().flatten().all(|&x| x == 0.0));
    }

    /// Without softening, one increment and 100 increments of the same proportional strain (10× the
    /// elastic limit) agree within 1 % (relative to ‖σ‖∞). Paths: isochoric triaxial compression and
    /// extension strain (θ = ±30° throughout) from σ0 = −1000(1,1,1,0) kPa, where the surface is close to
    /// its straight asymptotic cone and backward Euler is exact for a straight cone (constant normal).
    /// On strongly curved parts of the hyperbola the one-step closest-point projection differs more
    /// (it is only first-order accurate in the path); see the softening test for the order.
    #[test]
    fn one_versus_many_increments_without_softening() {
        for omega in [1.0, 0.3] {
            let m = perfectly_plastic(omega);
            let stress0 = isotropic(1000.0);
            for dir in [[0.5, -1.0, 0.5, 0.0], [-0.5, 1.0, -0.5, 0.0]] {
                let total = scale(&dir, 10.0 * elastic_limit(&m, &stress0, &dir));
                let (one, _) = proportional_path(&m, &stress0, &total, 1);
                let (many, _) = proportional_path(&m, &stress0, &total, 100);
                let norm = many.iter().fold(0.0f64, |a, x| a.max(x.abs()));
                let diff = (0..4).fold(0.0f64, |a, i| a.max((one[i] - many[i]).abs()));
                eprintln!(
                    "ω = {omega}, direction {dir:?}: relative difference {:.3e}",
                    diff / norm
                );
                assert!(
                    diff <= 0.01 * norm,
                    "ω = {omega}, {dir:?}: one {one:?} vs many {many:?}"
                );
            }
        }
    }

    /// With softening (Table 1, local) the path error shrinks at first order (backward Euler):
    /// e_N = ‖σ_N − σ_2N‖∞ for N = 8 … 128; the observed orders log2(e_N/e_2N) of the finest
    /// three refinements lie in [0.8, 1.2].
    #[test]
    fn softening_path_converges_at_first_order() {
        let m = model(|_| {});
        let stress0 = isotropic(100.0);
        let total = [0.004, -0.08, 0.0, 0.0];
        let ns = [8usize, 16, 32, 64, 128];
        let results: Vec<Voigt> = ns
            .iter()
            .map(|&n| proportional_path(&m, &stress0, &total, n).0)
            .collect();
        let errors: Vec<f64> = results
            .windows(2)
            .map(|w| (0..4).fold(0.0f64, |a, i| a.max((w[0][i] - w[1][i]).abs())))
            .collect();
        let orders: Vec<f64> = errors.windows(2).map(|w| (w[0] / w[1]).log2()).collect();
        eprintln!("softening path: differences {errors:?}, observed orders {orders:?}");
        for order in &orders[orders.len() - 3..] {
            assert!((0.8..=1.2).contains(order), "orders {orders:?}");
        }
    }

    /// Consistent tangent (D32, chained through sub-steps) equals central differences of the full
    /// update (η = 1e-6 ‖Δε‖-scaled) to 1e-5 relative (max-norm over the matrix) at ≥ 20 states:
    /// elastic, plastic without softening, softening, near the tip, θ near ±30°, ω ∈ {1, 0.3},
    /// local and nonlocal.
    #[test]
    fn consistent_tangent_matches_finite_differences() {
        let softening = model(|_| {});
        let soft_omega = model(|p| p.omega = 0.3);
        let ideal = perfectly_plastic(1.0);
        let ideal_omega = perfectly_plastic(0.3);
        let tensile = model(|p| {
            p.cohesion_post = 50.0;
            p.tensile_strength_ini = 40.0;
            p.tensile_strength_post = 20.0;
        });
        let models: [(&str, &Hmc); 5] = [
            ("table1", &softening),
            ("ω=0.3 soft", &soft_omega),
            ("ideal", &ideal),
            ("ideal ω=0.3", &ideal_omega),
            ("p_t", &tensile),
        ];
        let mut cases: Vec<TangentCase> = Vec::new();
        for (name, m) in models {
            for theta_deg in [29.9f64, -29.9, 0.0, 12.0] {
                let over_nonlocal = StrengthVariable::Nonlocal {
                    neighbours: 0.03,
                    own_weight: -0.3,
                };
                for strength in [
                    StrengthVariable::Local,
                    StrengthVariable::frozen(0.03),
                    over_nonlocal,
                ] {
                    // Start on (just inside) the surface at p = 150 kPa and push along the flow direction + shear.
                    let theta = theta_deg.to_radians();
                    let kappa0 = 0.01;
                    let strength_k = match strength {
                        StrengthVariable::Local => kappa0,
                        StrengthVariable::Nonlocal { neighbours, .. } => neighbours,
                    };
                    let p = 150.0;
                    let (mut lo, mut hi) = (0.0, 2000.0);
                    for _ in 0..100 {
                        let mid = 0.5 * (lo + hi);
                        if m.yield_function(&stress_from_invariants(p, mid, theta), strength_k)
                            > 0.0
                        {
                            hi = mid;
                        } else {
                            lo = mid;
                        }
                    }
                    let stress0 = stress_from_invariants(p, 0.98 * lo, theta);
                    let flow = m.flow_direction(&stress0, strength_k);
                    let inc: Voigt = std::array::from_fn(|i| {
                        2e-3 * flow[i] / strain_norm_f64(&flow) + [1e-4, -2e-4, 0.0, 3e-4][i]
                    });
                    cases.push((
                        format!("{name} θ={theta_deg} {strength:?}"),
                        m,
                        stress0,
                        inc,
                        kappa0,
                        strength,
                    ));
                }
            }
            // Near the tip: small stress, expansion with some shear.
            let pt = m.strength_at(0.0).tensile_strength;
            cases.push((
                format!("{name} near tip"),
                m,
                [pt - 1.0, pt - 1.5, pt - 1.2, 0.2],
                [2e-4, 1.5e-4, 0.0, 1e-4],
                0.0,
                StrengthVariable::Local,
            ));
            // Elastic unloading.
            cases.push((
                format!("{name} elastic"),
                m,
                isotropic(100.0),
                [1e-4, -2e-4, 0.0, 1e-4],
                0.0,
                StrengthVariable::Local,
            ));
        }
        // A large increment that needs sub-stepping (the tangent is chained through the sub-steps).
        let big: Voigt = [0.0, -3.0, 0.0, 0.0];
        let t = elastic_limit(&softening, &isotropic(100.0), &big);
        cases.push((
            "sub-stepped".into(),
            &softening,
            isotropic(100.0),
            scale(&big, 100.0 * t),
            0.0,
            StrengthVariable::Local,
        ));
        assert!(cases.len() >= 20);
        let mut plastic_cases = 0;
        let mut worst_overall: f64 = 0.0;
        for (label, m, stress0, inc, kappa0, strength) in &cases {
            let state0 = PointState {
                plastic_strain_eq: *kappa0,
                plastic_strain_eq_nonlocal: *kappa0,
                ..Default::default()
            };
            let u = m.update(stress0, inc, &state0, *strength).expect("update");
            if u.yielded {
                plastic_cases += 1;
            }
            let eta = 1e-6 * strain_norm_f64(inc).max(1e-4);
            let mut worst: f64 = 0.0;
            let dmax = u
                .tangent
                .iter()
                .flatten()
                .fold(0.0f64, |a, x| a.max(x.abs()));
            for j in 0..4 {
                let (mut ip, mut im) = (*inc, *inc);
                ip[j] += eta;
                im[j] -= eta;
                let up = m
                    .update(stress0, &ip, &state0, *strength)
                    .expect("update +");
                let um = m
                    .update(stress0, &im, &state0, *strength)
                    .expect("update −");
                for i in 0..4 {
                    let fd = (up.stress[i] - um.stress[i]) / (2.0 * eta);
                    worst = worst.max((fd - u.tangent[i][j]).abs());
                }
            }
            let rel = worst / dmax;
            worst_overall = worst_overall.max(rel);
            assert!(
                rel <= 1e-5,
                "{label}: tangent error {rel:e} (yielded {})",
                u.yielded
            );
        }
        let (_, substeps) = softening
            .update_with_substeps(
                &isotropic(100.0),
                &scale(&big, 100.0 * t),
                &PointState::default(),
                StrengthVariable::Local,
            )
            .unwrap();
        eprintln!("tangent check: {} cases, worst relative error {worst_overall:.2e}; large case used {substeps} sub-steps", cases.len());
        assert!(substeps > 1);
        assert!(plastic_cases >= 20, "only {plastic_cases} plastic cases");
    }

    /// DESIGN's alternative: second derivatives by central differences of the analytic m
    /// (η = 1e−6 max(‖σ‖∞, c_ref)) and of f, m, h in κ (η_κ = 1e−7 max(κ, 1e−4)).
    fn linearise_fd(m: &Hmc, stress: &Voigt, kappa: f64) -> ([[f64; 4]; 4], Voigt, f64) {
        let eta = 1e-6
            * stress
                .iter()
                .fold(m.strength_scale(), |a, x| a.max(x.abs()));
        let mut m_sigma = [[0.0; 4]; 4];
        for j in 0..4 {
            let (mut sp, mut sm) = (*stress, *stress);
            sp[j] += eta;
            sm[j] -= eta;
            let (mp, mm) = (m.flow_direction(&sp, kappa), m.flow_direction(&sm, kappa));
            for i in 0..4 {
                m_sigma[i][j] = (mp[i] - mm[i]) / (2.0 * eta);
            }
        }
        let eta_k = 1e-7 * kappa.max(1e-4);
        let (mp, mm) = (
            m.flow_direction(stress, kappa + eta_k),
            m.flow_direction(stress, kappa - eta_k),
        );
        let m_kappa = std::array::from_fn(|i| (mp[i] - mm[i]) / (2.0 * eta_k));
        let f_kappa = (m.yield_function(stress, kappa + eta_k)
            - m.yield_function(stress, kappa - eta_k))
            / (2.0 * eta_k);
        (m_sigma, m_kappa, f_kappa)
    }

    /// The exact dual-number second derivatives agree with DESIGN's central differences to 1e-5
    /// (relative to the largest entry) at several states; also prints the cost of both.
    #[test]
    fn dual_second_derivatives_match_central_differences() {
        let models = [model(|_| {}), model(|p| p.omega = 0.3)];
        let states = [
            ([-100.0, -650.0, -210.0, 0.0], 0.05),
            ([-80.0, -300.0, -150.0, 60.0], 0.2),
            (
                stress_from_invariants(200.0, 150.0, 29.5f64.to_radians()),
                0.01,
            ),
            (
                stress_from_invariants(200.0, 150.0, -29.5f64.to_radians()),
                0.3,
            ),
        ];
        for m in &models {
            for (stress, kappa) in &states {
                let lin = m.linearise(stress, *kappa, StrengthArg::LOCAL);
                let (m_sigma, m_kappa, f_kappa) = linearise_fd(m, stress, *kappa);
                let big = lin
                    .m_sigma
                    .iter()
                    .flatten()
                    .fold(0.0f64, |a, x| a.max(x.abs()));
                for (dual_row, fd_row) in lin.m_sigma.iter().zip(&m_sigma) {
                    for (exact, fd) in dual_row.iter().zip(fd_row) {
                        assert!((exact - fd).abs() <= 1e-5 * big);
                    }
                }
                let big_k = lin.m_kappa.iter().fold(1e-12f64, |a, x| a.max(x.abs()));
                for (exact, fd) in lin.m_kappa.iter().zip(&m_kappa) {
                    assert!((exact - fd).abs() <= 1e-5 * big_k);
                }
                assert!((lin.f_kappa - f_kappa).abs() <= 1e-5 * f_kappa.abs().max(1e-9));
            }
        }
        let m = &models[0];
        let (stress, kappa) = states[1];
        let n = 20_000;
        let start = std::time::Instant::now();
        let mut acc = 0.0;
        for k in 0..n {
            acc += m
                .linearise(&stress, kappa + 1e-9 * k as f64, StrengthArg::LOCAL)
                .m_sigma[1][1];
        }
        let dual = start.elapsed().as_secs_f64() / n as f64;
        let start = std::time::Instant::now();
        for k in 0..n {
            let (ms, mk, fk) = linearise_fd(m, &stress, kappa + 1e-9 * k as f64);
            acc += ms[1][1] + mk[0] + fk + m.flow_direction(&stress, kappa)[0];
        }
        let fd = start.elapsed().as_secs_f64() / n as f64;
        eprintln!("second derivatives: dual {:.0} ns, central differences {:.0} ns per evaluation ({acc:e})", dual * 1e9, fd * 1e9);
    }

    /// Robustness sweep: 4000 pseudo-random admissible start states and increments (up to 20× the
    /// elastic strain scale, tension and compression, local and nonlocal, four models) all return a
    /// finite stress with f ≤ 1e-8 c_ref (or, in the allowed cases, a ReturnMappingFailed error; the
    /// count of those must be 0 here).
    #[test]
    fn robustness_sweep() {
        let models = [
            model(|_| {}),
            model(|p| p.omega = 0.0),
            model(|p| {
                p.cohesion_post = 50.0;
                p.tensile_strength_ini = 100.0;
                p.tensile_strength_post = 40.0;
            }),
            perfectly_plastic(0.5),
        ];
        let mut seed: u64 = 12345;
        let mut uniform = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((seed >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
        };
        let mut failures = Vec::new();
        for k in 0..4000 {
            let m = &models[k % models.len()];
            let kappa0 = 0.5 * (uniform() + 1.0) * if k % 3 == 0 { 0.0 } else { 0.4 };
            let frozen = if k % 2 == 0 {
                None
            } else {
                Some(kappa0 + 0.1 * (uniform() + 1.0))
            };
            // Start: a random stress scaled back onto or inside the surface at κ̄ (or κ).
            let p0 = 300.0 * (uniform() + 1.0);
            let mut stress0 = [
                -p0 + 150.0 * uniform(),
                -p0 + 150.0 * uniform(),
                -p0 + 150.0 * uniform(),
                100.0 * uniform(),
            ];
            let kappa_strength = frozen.unwrap_or(kappa0);
            let tip = m.strength_at(kappa_strength).tensile_strength;
            let mut shrink = 1.0;
            while m.yield_function(&stress0, kappa_strength) > 0.0 && shrink > 1e-6 {
                shrink *= 0.8;
                stress0 = std::array::from_fn(|i| {
                    (stress0[i] - if i < 3 { tip } else { 0.0 }) * 0.8
                        + if i < 3 { tip } else { 0.0 }
                });
            }
            let size = 0.02 * (uniform() + 1.0);
            let inc = [
                size * uniform(),
                size * uniform(),
                0.5 * size * uniform(),
                size * uniform(),
            ];
            let state0 = PointState {
                plastic_strain_eq: kappa0,
                plastic_strain_eq_nonlocal: kappa0,
                ..Default::default()
            };
            match m.update(&stress0, &inc, &state0, frozen.into()) {
                Ok(u) => {
                    let f =
                        m.yield_function(&u.stress, frozen.unwrap_or(u.state.plastic_strain_eq));
                    assert!(f <= 1e-8 * m.strength_scale(), "case {k}: f = {f}");
                    assert!(u
                        .stress
                        .iter()
                        .chain(u.tangent.iter().flatten())
                        .all(|x| x.is_finite()));
                    assert!(u.state.plastic_strain_eq >= kappa0);
                }
                Err(e) => failures.push((k, e)),
            }
        }
        assert!(
            failures.is_empty(),
            "{} failures, first: {:?}",
            failures.len(),
            failures.first()
        );
    }

    /// D22 elastic branch: tangent = D, stress = σ + DΔε, state unchanged.
    #[test]
    fn elastic_branch_is_exact() {
        let m = model(|_| {});
        let inc = [1e-5, -2e-5, 0.0, 1e-5];
        let u = m
            .update(
                &isotropic(100.0),
                &inc,
                &PointState::default(),
                StrengthVariable::Local,
            )
            .unwrap();
        assert!(!u.yielded);
        assert_eq!(u.tangent, m.elastic_stiffness());
        let expected = add(
            &isotropic(100.0),
            &mat4_mul_vec(&m.elastic_stiffness(), &inc),
        );
        assert_eq!(u.stress, expected);
        assert_eq!(u.state, PointState::default());
        assert!(matches!(
            m.update(
                &[f64::NAN, 0.0, 0.0, 0.0],
                &inc,
                &PointState::default(),
                StrengthVariable::Local
            ),
            Err(ConstitutiveError::NonFinite(_))
        ));
    }

    /// DESIGN D39: a stress outside the surface is returned onto it (|f| ≤ 1e−9 of
    /// the strength scale) with its mean stress and Lode angle unchanged; a stress
    /// inside is untouched; beyond the apex it goes to the tip.
    #[test]
    fn projection_after_double_mapping_keeps_p_and_theta() {
        let hmc = Hmc::new(HmcParameters::table1()).unwrap();
        let state = PointState {
            plastic_strain_eq: 0.05,
            ..Default::default()
        };
        let outside = [-900.0, -150.0, -300.0, 120.0];
        let projected = hmc.project_to_surface(&outside, &state, None);
        let f = hmc.yield_function(&projected, 0.05);
        assert!(f.abs() <= 1e-9 * hmc.strength_scale(), "f = {f}");
        let (a, b) = (
            Invariants::of(&outside, 1e-10),
            Invariants::of(&projected, 1e-10),
        );
        assert!((a.mean_stress - b.mean_stress).abs() < 1e-9 * a.mean_stress.abs());
        assert!((a.sin_3theta - b.sin_3theta).abs() < 1e-9);
        assert!(b.j < a.j);
        let inside = [-200.0, -210.0, -205.0, 1.0];
        assert_eq!(hmc.project_to_surface(&inside, &state, None), inside);
        let tension = [50.0, 40.0, 45.0, 3.0];
        let pt = hmc.strength_at(0.05).tensile_strength;
        assert_eq!(
            hmc.project_to_surface(&tension, &state, None),
            [pt, pt, pt, 0.0]
        );
    }
}
