//! Von Mises elastic–perfectly plastic model with undrained strength c: yield
//! when √J₂ > c (theory D4), radial return at fixed mean stress and the
//! consistent (algorithmic) tangent of the radial return (Simo & Hughes 1998,
//! *Computational Inelasticity*, §3.3, box 3.2, with no hardening).
//!
//! In plane strain the flow puts σzz at the mean of the in-plane principal
//! stresses, so the limit state is Tresca's with undrained strength c: the
//! material of the Prandtl (Tresca) validation scene of theory §8.4, whose
//! rough strip footing carries (2 + π) c.
//!
//! The elasticity is [`LinearElastic`]'s (theory D22). The strength does not
//! depend on the equivalent plastic strain (no softening), so the
//! [`StrengthVariable`] of an update is ignored; κ is still accumulated by
//! theory D27 for output and the dissipation metric.
//!
//! Notation: σ = σm·1 + s with σm = tr σ / 3 (tension positive, theory D1),
//! 1 = (1, 1, 1, 0), s the deviator (Voigt `[xx, yy, zz, xy]`, stress-like
//! shear component); strains carry engineering shear γxy = 2 εxy (theory D2).

use serde::{Deserialize, Serialize};

use super::flow_rule::strain_norm_f64;
use super::{
    mat4_mul_vec, ConstitutiveError, ConstitutiveModel, LinearElastic, Mat4, ParameterProblem,
    PointState, StrengthVariable, StressUpdate, Voigt,
};

/// Elastic-check tolerance: an update is elastic while √J₂(σ_tr) ≤ c (1 + 1e−10).
const ELASTIC_TOLERANCE: f64 = 1e-10;

/// The deviatoric projector I_dev mapping an engineering-shear strain to the
/// deviatoric part of the tensor strain, so that D = K 1⊗1 + 2G I_dev (theory D22):
/// the xy entry is ½ because εxy = γxy/2.
const DEVIATORIC_PROJECTOR: Mat4 = [
    [2.0 / 3.0, -1.0 / 3.0, -1.0 / 3.0, 0.0],
    [-1.0 / 3.0, 2.0 / 3.0, -1.0 / 3.0, 0.0],
    [-1.0 / 3.0, -1.0 / 3.0, 2.0 / 3.0, 0.0],
    [0.0, 0.0, 0.0, 0.5],
];

/// Material parameters of `model = "von_mises"`; TOML keys in brackets.
#[derive(Clone, Copy, Debug, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct VonMisesParameters {
    /// `E`: Young's modulus, kPa (theory D22).
    #[serde(rename = "E")]
    pub youngs_modulus: f64,
    /// `nu`: Poisson's ratio, in (−1, 0.5) (theory D22).
    #[serde(rename = "nu")]
    pub poisson_ratio: f64,
    /// `density`: mass density, t/m³.
    pub density: f64,
    /// `c`: undrained shear strength, kPa: yield when √J₂ > c (theory D4).
    #[serde(rename = "c")]
    pub undrained_strength: f64,
}

impl VonMisesParameters {
    /// Check every parameter; one [`ParameterProblem`] per problem, naming the TOML key and the
    /// allowed range: E > 0; −1 < ν < 0.5; density > 0; c > 0; all values finite.
    pub fn validate(&self) -> Vec<ParameterProblem> {
        let fields: [(&'static str, f64, bool, &str); 4] = [
            (
                "E",
                self.youngs_modulus,
                self.youngs_modulus > 0.0,
                "E > 0 kPa",
            ),
            (
                "nu",
                self.poisson_ratio,
                self.poisson_ratio > -1.0 && self.poisson_ratio < 0.5,
                "-1 < nu < 0.5",
            ),
            (
                "density",
                self.density,
                self.density > 0.0,
                "density > 0 t/m³",
            ),
            (
                "c",
                self.undrained_strength,
                self.undrained_strength > 0.0,
                "c > 0 kPa",
            ),
        ];
        fields
            .into_iter()
            .filter_map(|(key, value, in_range, range)| {
                if !value.is_finite() {
                    Some(ParameterProblem {
                        key,
                        message: format!("{value} must be a finite number"),
                    })
                } else if !in_range {
                    Some(ParameterProblem {
                        key,
                        message: format!("{value} is out of range: {range}"),
                    })
                } else {
                    None
                }
            })
            .collect()
    }
}

/// Von Mises elastic–perfectly plastic model, ready to use: elastic matrices precomputed.
#[derive(Clone, Debug)]
pub struct VonMises {
    parameters: VonMisesParameters,
    elastic: LinearElastic,
    stiffness: Mat4,
    compliance: Mat4,
}

/// Mean stress σm = tr σ / 3 (tension positive) and deviator s = σ − σm·1 of a Voigt stress.
fn split(stress: &Voigt) -> (f64, Voigt) {
    let mean = (stress[0] + stress[1] + stress[2]) / 3.0;
    (
        mean,
        [
            stress[0] - mean,
            stress[1] - mean,
            stress[2] - mean,
            stress[3],
        ],
    )
}

/// √J₂ of a deviator s (theory D4): J₂ = ½(sx² + sy² + sz²) + sxy².
fn deviator_radius(s: &Voigt) -> f64 {
    (0.5 * (s[0] * s[0] + s[1] * s[1] + s[2] * s[2]) + s[3] * s[3]).sqrt()
}

impl VonMises {
    /// Build the model; returns every parameter problem if the parameters are invalid.
    pub fn new(parameters: VonMisesParameters) -> Result<Self, Vec<ParameterProblem>> {
        let problems = parameters.validate();
        if !problems.is_empty() {
            return Err(problems);
        }
        let elastic = LinearElastic::new(parameters.youngs_modulus, parameters.poisson_ratio);
        Ok(Self {
            parameters,
            elastic,
            stiffness: elastic.stiffness(),
            compliance: elastic.compliance(),
        })
    }

    /// The parameters the model was built from.
    pub fn parameters(&self) -> &VonMisesParameters {
        &self.parameters
    }

    /// Undrained strength c, kPa.
    pub fn undrained_strength(&self) -> f64 {
        self.parameters.undrained_strength
    }

    /// Yield function f(σ) = √J₂ − c (kPa, theory D4); f ≤ 0 admissible.
    pub fn yield_function(&self, stress: &Voigt) -> f64 {
        deviator_radius(&split(stress).1) - self.parameters.undrained_strength
    }

    /// Consistent tangent of the radial return, dσ/dΔε with Δε in engineering shear:
    ///
    /// D_alg = K 1⊗1 + 2G β I_dev − 2G β n⊗n,
    ///
    /// β = c/√J₂(s_tr), n = s_tr/‖s_tr‖ = s_tr/√(2 J₂(s_tr)) the unit deviatoric direction in
    /// stress-like components (tensor norm, n:n = nx² + ny² + nz² + 2 nxy² = 1), I_dev the
    /// projector [`DEVIATORIC_PROJECTOR`] (xy entry ½).
    ///
    /// Derivation: s = β s_tr, ds_tr = 2G I_dev dΔε, and dJ₂(s_tr) = s_tr : ds_tr = 2G s_tr·dΔε
    /// (plain Voigt dot: sxy dγxy = 2 sxy dεxy), so dβ = −β G (s_tr·dΔε)/J₂ and
    /// s_tr dβ = −2Gβ n (n·dΔε). Both n-factors enter with their stress-like xy component; the
    /// engineering shear of dΔε needs no further factor. Symmetric by construction.
    fn algorithmic_tangent(&self, trial_deviator: &Voigt, trial_radius: f64) -> Mat4 {
        let k = self.elastic.bulk_modulus();
        let g = self.elastic.shear_modulus();
        let beta = self.parameters.undrained_strength / trial_radius;
        let norm = std::f64::consts::SQRT_2 * trial_radius;
        let n = trial_deviator.map(|x| x / norm);
        let volumetric = [1.0, 1.0, 1.0, 0.0];
        std::array::from_fn(|i| {
            std::array::from_fn(|j| {
                k * volumetric[i] * volumetric[j]
                    + 2.0 * g * beta * (DEVIATORIC_PROJECTOR[i][j] - n[i] * n[j])
            })
        })
    }
}

impl ConstitutiveModel for VonMises {
    fn name(&self) -> &'static str {
        "von_mises"
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

    /// Associated perfect plasticity: the radial-return tangent is symmetric.
    fn has_symmetric_tangent(&self) -> bool {
        true
    }

    /// Fixed strength (theory D39 double mapping stays off under `auto`).
    fn can_soften(&self) -> bool {
        false
    }

    /// theory D39 for this surface: a stress outside it has its deviator scaled to √J₂ = c at
    /// fixed mean stress; a stress inside is returned unchanged.
    fn project_to_surface(
        &self,
        stress: &Voigt,
        _state: &PointState,
        _strength_kappa: Option<f64>,
    ) -> Voigt {
        let c = self.parameters.undrained_strength;
        let (mean, s) = split(stress);
        let radius = deviator_radius(&s);
        if radius <= c * (1.0 + ELASTIC_TOLERANCE) {
            return *stress;
        }
        let beta = c / radius;
        [
            mean + beta * s[0],
            mean + beta * s[1],
            mean + beta * s[2],
            beta * s[3],
        ]
    }

    /// Elastic trial σ_tr = σ_n^R + D Δε; if √J₂(σ_tr) > c, radial return s = s_tr c/√J₂(s_tr)
    /// at unchanged mean stress, Δε^p = C (σ_tr − σ) (deviatoric), Δκ = ‖Δε^p‖ε (theory D27).
    fn update(
        &self,
        stress_rotated: &Voigt,
        strain_increment: &Voigt,
        state_n: &PointState,
        strength: StrengthVariable,
    ) -> Result<StressUpdate, ConstitutiveError> {
        if stress_rotated
            .iter()
            .chain(strain_increment.iter())
            .any(|x| !x.is_finite())
            || !state_n.plastic_strain_eq.is_finite()
        {
            return Err(ConstitutiveError::NonFinite(format!(
                "input stress {stress_rotated:?}, strain increment {strain_increment:?}, κ = {}",
                state_n.plastic_strain_eq
            )));
        }
        let d_eps = mat4_mul_vec(&self.stiffness, strain_increment);
        let trial: Voigt = std::array::from_fn(|i| stress_rotated[i] + d_eps[i]);
        let (mean, s_trial) = split(&trial);
        let radius = deviator_radius(&s_trial);
        if !radius.is_finite() {
            return Err(ConstitutiveError::NonFinite(format!(
                "trial stress {trial:?}"
            )));
        }
        let c = self.parameters.undrained_strength;
        if radius <= c * (1.0 + ELASTIC_TOLERANCE) {
            return Ok(StressUpdate {
                stress: trial,
                state: *state_n,
                tangent: self.stiffness,
                yielded: false,
            });
        }
        let beta = c / radius;
        let stress = [
            mean + beta * s_trial[0],
            mean + beta * s_trial[1],
            mean + beta * s_trial[2],
            beta * s_trial[3],
        ];
        // σ_tr − σ = (1 − β) s_tr, exactly deviatoric, so the flow is isochoric.
        let relaxed = s_trial.map(|x| (1.0 - beta) * x);
        let plastic_increment = mat4_mul_vec(&self.compliance, &relaxed);
        let mut state = *state_n;
        state.plastic_strain_eq += strain_norm_f64(&plastic_increment);
        if strength == StrengthVariable::Local {
            state.plastic_strain_eq_nonlocal = state.plastic_strain_eq;
        }
        for (total, increment) in state.plastic_strain.iter_mut().zip(plastic_increment) {
            *total += increment;
        }
        Ok(StressUpdate {
            stress,
            state,
            tangent: self.algorithmic_tangent(&s_trial, radius),
            yielded: true,
        })
    }
}

#[cfg(test)]
mod tests;
