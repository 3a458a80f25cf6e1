//! Constitutive interface: the stress update, its algorithmic tangent and the
//! state variables a material point carries (theory §5).
//!
//! The engine calls [`ConstitutiveModel::update`] once per material point per
//! Newton iteration (implicit) or per step (explicit). Models are stateless
//! values; everything that evolves lives in [`PointState`] and the stress.
//!
//! Sign convention (theory D1–D2): stress is tension-positive, Voigt order
//! `[xx, yy, zz, xy]`; strains carry engineering shear `γxy = 2 εxy`.

pub mod dense_lu;
pub mod dual;
pub mod elastic;
pub mod flow_rule;
pub mod hmc;
pub mod softening;
pub mod von_mises;
pub mod yield_surface;

use std::fmt::Debug;

pub use elastic::LinearElastic;
pub use hmc::{Hmc, HmcParameters};
pub use von_mises::{VonMises, VonMisesParameters};

/// Voigt 4-vector `[xx, yy, zz, xy]` (theory D2).
pub type Voigt = [f64; 4];
/// 4×4 matrix acting on Voigt vectors, row-major `m[row][col]`.
pub type Mat4 = [[f64; 4]; 4];

/// State variables carried by every material point.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PointState {
    /// Local equivalent plastic strain κ, accumulated by increments (theory D27).
    pub plastic_strain_eq: f64,
    /// Nonlocal equivalent plastic strain κ̄ (theory D35); equals κ in local runs.
    pub plastic_strain_eq_nonlocal: f64,
    /// Accumulated plastic strain (Voigt, engineering shear), for output and
    /// the dissipation metric (theory D43).
    pub plastic_strain: Voigt,
}

/// Result of one stress update.
#[derive(Clone, Copy, Debug)]
pub struct StressUpdate {
    /// Updated (tension-positive) stress σ_{n+1}.
    pub stress: Voigt,
    /// Updated state variables.
    pub state: PointState,
    /// Algorithmic tangent dσ_{n+1}/dΔε (theory D32); the elastic D on the elastic branch.
    pub tangent: Mat4,
    /// True when the return mapping was active (plastic flow in this update).
    pub yielded: bool,
}

/// Why a stress update could not be completed.
#[derive(Debug, Clone, thiserror::Error, PartialEq)]
pub enum ConstitutiveError {
    /// The return mapping did not converge even with the maximum sub-stepping.
    #[error("return mapping did not converge ({reason}); trial stress {trial_stress:?} kPa, κ = {kappa}")]
    ReturnMappingFailed {
        /// What failed (iteration limit, negative multiplier, ...).
        reason: String,
        /// The trial stress of the failed update (kPa).
        trial_stress: Voigt,
        /// The equivalent plastic strain at the start of the update.
        kappa: f64,
    },
    /// The input or the result contains a NaN or an infinite value.
    #[error("non-finite value in the stress update: {0}")]
    NonFinite(String),
}

/// One invalid material parameter: its TOML key and what is wrong with its
/// value, with the allowed range (`phi_peak`: "50 is out of range: 0 < phi_peak
/// <= 46 degrees …"). Callers add the key's path (`materials.soil.phi_peak`).
#[derive(Debug, Clone, thiserror::Error, PartialEq)]
#[error("{key} = {message}")]
pub struct ParameterProblem {
    /// The parameter's TOML key, e.g. `phi_peak`.
    pub key: &'static str,
    /// The offending value and the allowed range.
    pub message: String,
}

/// A constitutive law as seen by the MPM engine.
pub trait ConstitutiveModel: Send + Sync + Debug {
    /// Short model name (`"linear_elastic"`, `"hmc"`, `"von_mises"`), written to `run.json`.
    fn name(&self) -> &'static str;

    /// Elastic stiffness D (theory D22), kPa.
    fn elastic_stiffness(&self) -> Mat4;

    /// P-wave modulus K + 4G/3 (kPa), for the explicit stable time step (theory D20).
    fn p_wave_modulus(&self) -> f64;

    /// True when the model never yields: the engine then skips the return
    /// mapping and uses the constant elastic tangent.
    fn is_elastic(&self) -> bool;

    /// True when the algorithmic tangent is always symmetric (elastic, or
    /// associated perfectly plastic), so that sparse Cholesky may be used.
    fn has_symmetric_tangent(&self) -> bool;

    /// Stress update (theory §5.6).
    ///
    /// * `stress_rotated` – σ_n^R, the committed stress rotated by the incremental spin (D13);
    /// * `strain_increment` – Δε of the step so far (D12);
    /// * `state_n` – committed state at the start of the step;
    /// * `strength` – the equivalent plastic strain the strength is evaluated at:
    ///   the point's own κ (local runs) or the nonlocal κ̄ (theory §6).
    fn update(
        &self,
        stress_rotated: &Voigt,
        strain_increment: &Voigt,
        state_n: &PointState,
        strength: StrengthVariable,
    ) -> Result<StressUpdate, ConstitutiveError>;

    /// The stress update of [`Self::update`] without its tangent (a step
    /// that forms none: explicit), written into `stress` and `state` (left
    /// as they were on error); returns whether the point yielded. A law
    /// whose tangent costs work of its own may form only the stress.
    fn update_stress(
        &self,
        stress_rotated: &Voigt,
        strain_increment: &Voigt,
        state_n: &PointState,
        strength: StrengthVariable,
        (stress, state): (&mut Voigt, &mut PointState),
    ) -> Result<bool, ConstitutiveError> {
        let update = self.update(stress_rotated, strain_increment, state_n, strength)?;
        *stress = update.stress;
        *state = update.state;
        Ok(update.yielded)
    }

    /// [`Self::update`] written into `stress`, `state` and `tangent` (left
    /// as they were on error); returns whether the point yielded. The
    /// implicit stress update's form: a law may write its result in place
    /// rather than return it by value.
    fn update_into(
        &self,
        stress_rotated: &Voigt,
        strain_increment: &Voigt,
        state_n: &PointState,
        strength: StrengthVariable,
        (stress, state, tangent): (&mut Voigt, &mut PointState, &mut Mat4),
    ) -> Result<bool, ConstitutiveError> {
        let update = self.update(stress_rotated, strain_increment, state_n, strength)?;
        *stress = update.stress;
        *state = update.state;
        *tangent = update.tangent;
        Ok(update.yielded)
    }

    /// True when the strength can decrease with plastic strain (softening):
    /// double mapping is then on by default (theory §7).
    fn can_soften(&self) -> bool {
        false
    }

    /// Return a stress that lies outside the yield surface to it at fixed mean
    /// stress and Lode angle, without changing the state (theory D39, used after
    /// double mapping). Elastic models return the stress unchanged.
    fn project_to_surface(
        &self,
        stress: &Voigt,
        _state: &PointState,
        _strength_kappa: Option<f64>,
    ) -> Voigt {
        *stress
    }
}

/// The equivalent plastic strain κ_s at which a point's strength is evaluated
/// during its stress update.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum StrengthVariable {
    /// Local runs: the point's own κ = κ_n + Δκ (theory §5.6; the return mapping
    /// solves for Δκ).
    Local,
    /// Nonlocal runs (theory D36, with the over-nonlocal factor m):
    /// κ_s = `neighbours` + `own_weight`·Δκ, where `neighbours` = κ̄_n + m Σ_q W_pq Δκ_q
    /// is frozen during the update and `own_weight` = 1 − m. For m = 1 (D35)
    /// the strength is frozen at κ_s = `neighbours`; for m > 1 the point's own
    /// plastic strain enters with a negative weight and the return mapping
    /// solves for it together with the stress.
    Nonlocal {
        /// κ̄_n + m Σ_q W_pq Δκ_q, the frozen part.
        neighbours: f64,
        /// 1 − m, the weight of the point's own increment Δκ.
        own_weight: f64,
    },
}

impl StrengthVariable {
    /// The strength frozen at κ̄ (theory D36, m = 1).
    pub fn frozen(kappa_bar: f64) -> Self {
        Self::Nonlocal {
            neighbours: kappa_bar,
            own_weight: 0.0,
        }
    }
}

impl From<Option<f64>> for StrengthVariable {
    /// `None`: local; `Some(κ̄)`: strength frozen at κ̄.
    fn from(frozen: Option<f64>) -> Self {
        frozen.map_or(Self::Local, Self::frozen)
    }
}

/// `D · a` for a 4×4 matrix and a Voigt vector.
pub fn mat4_mul_vec(m: &Mat4, a: &Voigt) -> Voigt {
    let mut out = [0.0; 4];
    for (row, o) in m.iter().zip(out.iter_mut()) {
        *o = row[0] * a[0] + row[1] * a[1] + row[2] * a[2] + row[3] * a[3];
    }
    out
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

/// Compression-positive mean stress p = −(σxx + σyy + σzz)/3 (theory D1), kPa.
pub fn mean_stress(stress: &Voigt) -> f64 {
    -(stress[0] + stress[1] + stress[2]) / 3.0
}

/// Second deviatoric invariant J2 (theory D4), kPa².
pub fn j2(stress: &Voigt) -> f64 {
    let p = mean_stress(stress);
    let (sx, sy, sz) = (stress[0] + p, stress[1] + p, stress[2] + p);
    0.5 * (sx * sx + sy * sy + sz * sz) + stress[3] * stress[3]
}

/// Deviatoric stress q = sqrt(3 J2) (theory D5, paper eq. 7), kPa.
pub fn deviatoric_stress(stress: &Voigt) -> f64 {
    (3.0 * j2(stress)).sqrt()
}
