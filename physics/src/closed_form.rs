//! Closed-form solutions the validation tests and the studies compare runs
//! against (theory §8.4's table), written once. Units: m, kPa, t/m³, m/s².

use crate::constitutive::{ConstitutiveModel, LinearElastic};

/// Constrained (P-wave) modulus M = E(1 − ν)/((1 + ν)(1 − 2ν)) = K + 4G/3, kPa.
pub fn constrained_modulus(youngs_modulus: f64, nu: f64) -> f64 {
    LinearElastic::new(youngs_modulus, nu).p_wave_modulus()
}

/// An elastic column of height H in uniaxial strain under its own weight:
/// constrained modulus M, initial density ρ0 (theory §8.4, the oedometer and
/// soft columns).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Column {
    /// Height H, m.
    pub height: f64,
    /// Constrained modulus M, kPa.
    pub modulus: f64,
    /// Initial density ρ0, t/m³.
    pub density: f64,
}

impl Column {
    /// Vertical stress at initial height Y under gravity g, exact for any
    /// deformation (the weight of the material above): σyy = −ρ0 g (H − Y), kPa.
    pub fn vertical_stress(&self, y0: f64, g: f64) -> f64 {
        -self.density * g * (self.height - y0)
    }

    /// Small-strain vertical displacement at height y under gravity g:
    /// u_y = −(ρ0 g/M)(H y − y²/2), m (the top settles ρ0 g H²/(2M)).
    pub fn small_strain_displacement(&self, y: f64, g: f64) -> f64 {
        -(self.density * g / self.modulus) * (self.height * y - 0.5 * y * y)
    }

    /// Large-strain settlement of the top under gravity g, m (positive
    /// down): hypoelastic with the Jaumann rate (= logarithmic strain), the
    /// stretch at initial height Y is λ = exp(−ρ0 g (H − Y)/M), so
    /// s = H − (M/ρ0 g)(1 − exp(−ρ0 g H/M)); 0 without gravity.
    pub fn settlement(&self, g: f64) -> f64 {
        if g <= 0.0 {
            return 0.0;
        }
        let scale = self.modulus / (self.density * g);
        self.height - scale * (1.0 - (-self.height / scale).exp())
    }
}

/// Lamé's thick-walled cylinder in plane strain under internal pressure
/// (theory §8.4).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LameCylinder {
    /// Inner radius a, m.
    pub inner: f64,
    /// Outer radius b, m.
    pub outer: f64,
    /// Internal pressure p, kPa.
    pub pressure: f64,
    /// Young's modulus E, kPa.
    pub youngs_modulus: f64,
    /// Poisson's ratio ν.
    pub nu: f64,
}

impl LameCylinder {
    /// Radial displacement at radius r:
    /// u_r = (1 + ν) p a² / (E (b² − a²)) [(1 − 2ν) r + b²/r], m.
    pub fn radial_displacement(&self, r: f64) -> f64 {
        let (a, b, nu) = (self.inner, self.outer, self.nu);
        (1.0 + nu) * self.pressure * a * a / (self.youngs_modulus * (b * b - a * a))
            * ((1.0 - 2.0 * nu) * r + b * b / r)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The soft column of `validation/elastic/soft_column.toml` (E = 60 kPa,
    /// ν = 0.3, ρ = 2 t/m³, H = 1 m): s = 0.1121919 m at g = 9.81 (theory
    /// §8.4). A small load x = ρgH/M gives the small-strain settlement
    /// ρgH²/(2M) times 1 − x/3 + x²/12 − …: at g = 0.01 m/s² (x = 2.5e-4) the
    /// ratio less 1 − x/3 measured 4.3e-9 (the x² term 5.1e-9), bound 1e-8.
    #[test]
    fn column_settlement_tends_to_the_small_strain_one() {
        let modulus = constrained_modulus(60.0, 0.3);
        assert!((modulus - 60.0 * 0.7 / (1.3 * 0.4)).abs() < 1e-12);
        let column = Column {
            height: 1.0,
            modulus,
            density: 2.0,
        };
        assert!((column.settlement(9.81) - 0.1121919).abs() < 1e-7);
        let g = 0.01;
        let x = column.density * g * column.height / column.modulus;
        let small = -column.small_strain_displacement(1.0, g);
        assert!((column.settlement(g) / small - (1.0 - x / 3.0)).abs() < 1e-8);
        assert_eq!(column.settlement(0.0), 0.0);
    }

    /// Lamé's u_r satisfies the plane-strain boundary conditions σ_r(a) = −p
    /// and σ_r(b) = 0 (σ_r = (λ + 2G) du/dr + λ u/r, derivative by central
    /// differences of step 1e-3 m, whose truncation error dominates:
    /// measured 2.3e-6 p at a and 1.5e-7 p at b, bounds 5e-6 p and 3e-7 p).
    #[test]
    fn lame_displacement_meets_the_boundary_tractions() {
        let c = LameCylinder {
            inner: 1.0,
            outer: 2.0,
            pressure: 100.0,
            youngs_modulus: 1e6,
            nu: 0.3,
        };
        let shear = c.youngs_modulus / (2.0 * (1.0 + c.nu));
        let lambda = constrained_modulus(c.youngs_modulus, c.nu) - 2.0 * shear;
        let radial_stress = |r: f64| {
            let du = (c.radial_displacement(r + 1e-3) - c.radial_displacement(r - 1e-3)) / 2e-3;
            (lambda + 2.0 * shear) * du + lambda * c.radial_displacement(r) / r
        };
        assert!((radial_stress(c.inner) + c.pressure).abs() < 5e-6 * c.pressure);
        assert!(radial_stress(c.outer).abs() < 3e-7 * c.pressure);
    }
}
