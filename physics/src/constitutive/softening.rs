//! Three-level exponential softening law (theory D27–D28, paper eq. 4).
//!
//! One law per strength quantity (cohesion, friction angle, tensile strength):
//! the law is independent of the yield criterion and can be reused by any
//! model whose strength parameters soften with an equivalent plastic strain κ.

use super::dual::Real;

/// X(κ) = X_res + (X_post − X_res) e^{−b_res κ} + (X_peak − X_post) e^{−b_post κ}
/// (theory D28; paper eq. 4 when X_res = 0).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ThreeLevelSoftening {
    /// Value at κ = 0 (peak), in the quantity's unit.
    pub peak: f64,
    /// Post-rupture value reached at the fast rate `rate_post`.
    pub post: f64,
    /// Residual value reached at the slow rate `rate_res` (κ → ∞).
    pub residual: f64,
    /// Post-rupture softening rate b_post (dimensionless, ≥ 0).
    pub rate_post: f64,
    /// Residual softening rate b_res (dimensionless, ≥ 0).
    pub rate_res: f64,
}

impl ThreeLevelSoftening {
    /// A law that never changes (X ≡ value).
    pub fn constant(value: f64) -> Self {
        Self {
            peak: value,
            post: value,
            residual: value,
            rate_post: 0.0,
            rate_res: 0.0,
        }
    }

    /// X(κ) of theory D28, generic so that dX/dκ comes out of a dual evaluation.
    #[inline]
    pub fn value<T: Real>(&self, kappa: T) -> T {
        self.value_with_decays(self.decays(kappa))
    }

    /// The decay factors (e^{−b_res κ}, e^{−b_post κ}) of D28: laws with the same
    /// rates share them.
    #[inline]
    pub fn decays<T: Real>(&self, kappa: T) -> (T, T) {
        (
            (kappa * (-self.rate_res)).exp(),
            (kappa * (-self.rate_post)).exp(),
        )
    }

    /// X(κ) of D28 from decay factors (e^{−b_res κ}, e^{−b_post κ}) of this law's rates.
    #[inline]
    pub fn value_with_decays<T: Real>(&self, (decay_res, decay_post): (T, T)) -> T {
        let post_term = decay_res * (self.post - self.residual);
        let peak_term = decay_post * (self.peak - self.post);
        post_term + peak_term + self.residual
    }

    /// True when X(κ) can differ from X(0) for some κ > 0.
    pub fn can_change(&self) -> bool {
        let post_moves = self.peak != self.post && self.rate_post != 0.0;
        let res_moves = self.post != self.residual && self.rate_res != 0.0;
        post_moves || res_moves
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::constitutive::dual::Dual;

    /// D28 reproduces paper eq. 4 (X_res = 0) exactly (tolerance 1e-12 relative) and
    /// its κ-derivative from the dual evaluation equals the closed form.
    #[test]
    fn reproduces_paper_eq_4() {
        let law = ThreeLevelSoftening {
            peak: 200.0,
            post: 30.0,
            residual: 0.0,
            rate_post: 10.0,
            rate_res: 2.0,
        };
        for kappa in [0.0, 0.05, 0.3, 2.0] {
            let expected = (200.0 - 30.0) * (-10.0 * kappa).exp() + 30.0 * (-2.0 * kappa).exp();
            let slope =
                -10.0 * (200.0 - 30.0) * (-10.0 * kappa).exp() - 2.0 * 30.0 * (-2.0 * kappa).exp();
            let d = law.value(Dual::<1>::variable(kappa, 0));
            assert!(
                (d.re - expected).abs() <= 1e-12 * expected,
                "{} vs {expected}",
                d.re
            );
            assert!(
                (d.eps[0] - slope).abs() <= 1e-12 * slope.abs(),
                "{} vs {slope}",
                d.eps[0]
            );
        }
        assert!(law.can_change());
        assert!(!ThreeLevelSoftening::constant(3.0).can_change());
        assert_eq!(ThreeLevelSoftening::constant(3.0).value(5.0), 3.0);
    }
}
