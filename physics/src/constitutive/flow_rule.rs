//! Plastic potential of the hyperbolic Mohr–Coulomb family with the
//! non-associativity constant ω (theory D26).
//!
//! G(σ) = sqrt(J²/fd(θ) + a²) − (c + ω p tanφ): the potential has the shape of
//! the yield function with its pressure term scaled by ω, so its gradient is
//! the yield gradient with the volumetric part −tanφ ∂p/∂σ scaled by ω. The
//! flow rule only needs the yield gradient and tanφ and is reusable by any
//! yield function of the form F(J, θ) − (c + p tanφ).

use super::dual::Real;
use super::Voigt;

/// Flow rule m = ∂G/∂σ of theory D26 (Voigt, engineering-shear strain-like).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PressureScaledFlow {
    /// Non-associativity constant ω ∈ [0, 1]: 1 associated, 0 no dilatancy on the asymptote.
    pub omega: f64,
}

impl PressureScaledFlow {
    /// m = f_σ + (1 − ω) tanφ ∂p/∂σ, ∂p/∂σ = −⅓·(1,1,1,0) (theory D26, D31).
    #[inline]
    pub fn direction<T: Real>(&self, yield_gradient: &[T; 4], tan_friction: T) -> [T; 4] {
        let shift = tan_friction * ((1.0 - self.omega) / 3.0);
        [
            yield_gradient[0] - shift,
            yield_gradient[1] - shift,
            yield_gradient[2] - shift,
            yield_gradient[3],
        ]
    }

    /// True for the associated rule (ω = 1): m = f_σ.
    pub fn is_associated(&self) -> bool {
        self.omega == 1.0
    }
}

/// Tensor norm ‖a‖ε = sqrt(a1² + a2² + a3² + a4²/2) of a strain-like Voigt vector (theory D3).
#[inline]
pub fn strain_norm<T: Real>(a: &[T; 4]) -> T {
    (a[0] * a[0] + a[1] * a[1] + a[2] * a[2] + a[3] * a[3] * 0.5).sqrt()
}

/// f64 shorthand of [`strain_norm`].
pub fn strain_norm_f64(a: &Voigt) -> f64 {
    strain_norm(a)
}
