//! Isotropic linear (hypo)elasticity in plane strain (theory D22).

use super::{
    mat4_mul_vec, ConstitutiveError, ConstitutiveModel, Mat4, PointState, StrengthVariable,
    StressUpdate, Voigt,
};

/// Isotropic linear elasticity with Young's modulus `youngs_modulus` (kPa) and
/// Poisson's ratio `poisson_ratio`, fixed at construction ([`Self::new`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LinearElastic {
    /// Young's modulus E, kPa.
    pub youngs_modulus: f64,
    /// Poisson's ratio ν, in (−1, 0.5).
    pub poisson_ratio: f64,
    /// D of E and ν (theory D22), formed once: every stress update uses it.
    stiffness: Mat4,
}

impl LinearElastic {
    /// New elastic law; the caller (scene validation) guarantees E > 0 and −1 < ν < 0.5.
    pub fn new(youngs_modulus: f64, poisson_ratio: f64) -> Self {
        let mut law = Self {
            youngs_modulus,
            poisson_ratio,
            stiffness: [[0.0; 4]; 4],
        };
        law.stiffness = law.stiffness_of_moduli();
        law
    }

    /// Bulk modulus K = E / (3(1 − 2ν)), kPa.
    pub fn bulk_modulus(&self) -> f64 {
        self.youngs_modulus / (3.0 * (1.0 - 2.0 * self.poisson_ratio))
    }

    /// Shear modulus G = E / (2(1 + ν)), kPa.
    pub fn shear_modulus(&self) -> f64 {
        self.youngs_modulus / (2.0 * (1.0 + self.poisson_ratio))
    }

    /// The 4×4 plane-strain stiffness D of theory D22 (zz row kept: σzz evolves).
    pub fn stiffness(&self) -> Mat4 {
        self.stiffness
    }

    /// D formed from E and ν (theory D22).
    fn stiffness_of_moduli(&self) -> Mat4 {
        let g = self.shear_modulus();
        let lambda = self.bulk_modulus() - 2.0 * g / 3.0;
        let d = lambda + 2.0 * g;
        [
            [d, lambda, lambda, 0.0],
            [lambda, d, lambda, 0.0],
            [lambda, lambda, d, 0.0],
            [0.0, 0.0, 0.0, g],
        ]
    }

    /// The compliance C = D⁻¹ (theory D22).
    pub fn compliance(&self) -> Mat4 {
        let e = self.youngs_modulus;
        let nu = self.poisson_ratio;
        let g = self.shear_modulus();
        [
            [1.0 / e, -nu / e, -nu / e, 0.0],
            [-nu / e, 1.0 / e, -nu / e, 0.0],
            [-nu / e, -nu / e, 1.0 / e, 0.0],
            [0.0, 0.0, 0.0, 1.0 / g],
        ]
    }
}

impl ConstitutiveModel for LinearElastic {
    fn name(&self) -> &'static str {
        "linear_elastic"
    }

    fn elastic_stiffness(&self) -> Mat4 {
        self.stiffness()
    }

    fn p_wave_modulus(&self) -> f64 {
        self.bulk_modulus() + 4.0 * self.shear_modulus() / 3.0
    }

    fn is_elastic(&self) -> bool {
        true
    }

    fn has_symmetric_tangent(&self) -> bool {
        true
    }

    fn update(
        &self,
        stress_rotated: &Voigt,
        strain_increment: &Voigt,
        state_n: &PointState,
        _strength: StrengthVariable,
    ) -> Result<StressUpdate, ConstitutiveError> {
        Ok(StressUpdate {
            stress: self.stress_after(stress_rotated, strain_increment)?,
            state: *state_n,
            tangent: self.stiffness,
            yielded: false,
        })
    }

    fn update_stress(
        &self,
        stress_rotated: &Voigt,
        strain_increment: &Voigt,
        state_n: &PointState,
        _strength: StrengthVariable,
        (stress, state): (&mut Voigt, &mut PointState),
    ) -> Result<bool, ConstitutiveError> {
        *stress = self.stress_after(stress_rotated, strain_increment)?;
        *state = *state_n;
        Ok(false)
    }

    fn update_into(
        &self,
        stress_rotated: &Voigt,
        strain_increment: &Voigt,
        state_n: &PointState,
        _strength: StrengthVariable,
        (stress, state, tangent): (&mut Voigt, &mut PointState, &mut Mat4),
    ) -> Result<bool, ConstitutiveError> {
        *stress = self.stress_after(stress_rotated, strain_increment)?;
        *state = *state_n;
        *tangent = self.stiffness;
        Ok(false)
    }
}

impl LinearElastic {
    /// σ^R + D Δε (theory D22), refused when not finite.
    #[inline]
    fn stress_after(
        &self,
        stress_rotated: &Voigt,
        strain_increment: &Voigt,
    ) -> Result<Voigt, ConstitutiveError> {
        let increment = mat4_mul_vec(&self.stiffness, strain_increment);
        let mut stress = *stress_rotated;
        for (s, ds) in stress.iter_mut().zip(increment) {
            *s += ds;
        }
        if stress.iter().any(|s| !s.is_finite()) {
            return Err(ConstitutiveError::NonFinite(format!(
                "elastic stress {stress:?}"
            )));
        }
        Ok(stress)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// D · C = I to round-off (D22).
    #[test]
    fn compliance_inverts_stiffness() {
        let law = LinearElastic::new(20_000.0, 0.2);
        let (d, c) = (law.stiffness(), law.compliance());
        for i in 0..4 {
            for j in 0..4 {
                let dc: f64 = (0..4).map(|k| d[i][k] * c[k][j]).sum();
                let expected = if i == j { 1.0 } else { 0.0 };
                assert!((dc - expected).abs() < 1e-14, "DC[{i}][{j}] = {dc}");
            }
        }
    }

    /// The P-wave (constrained) modulus K + 4G/3 equals E(1−ν)/((1+ν)(1−2ν)),
    /// and D11; for ν = 0 it is E (the bar of theory §8.4).
    #[test]
    fn p_wave_modulus_is_the_constrained_modulus() {
        for (e, nu) in [(1000.0, 0.0), (20_000.0, 0.2), (50_000.0, 0.45)] {
            let law = LinearElastic::new(e, nu);
            let expected = e * (1.0 - nu) / ((1.0 + nu) * (1.0 - 2.0 * nu));
            assert!((law.p_wave_modulus() / expected - 1.0).abs() < 1e-13);
            assert!((law.stiffness()[0][0] / expected - 1.0).abs() < 1e-13);
        }
    }
}
