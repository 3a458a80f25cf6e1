//! Hyperbolic Mohr–Coulomb yield criterion (theory D23, paper eq. 3) with the
//! van Eekelen deviatoric shape (theory D24–D25), invariants (D1–D6) and the
//! analytic gradient f_σ (D31).
//!
//! Everything is generic over [`Real`] so that the same code gives f64 values
//! and, evaluated with dual numbers, exact second derivatives.

use super::dual::Real;

/// van Eekelen exponent Z of theory D24 (chosen for convexity).
pub const VAN_EEKELEN_EXPONENT: f64 = -0.229;

/// 3√3/2, the factor of the Lode-angle definition (theory D6).
const LODE_FACTOR: f64 = 2.598_076_211_353_316;

/// Strength of the hyperbolic Mohr–Coulomb surface at one value of κ.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfaceStrength<T> {
    /// Asymptotic cohesion c* (kPa).
    pub cohesion: T,
    /// tan φ* of the asymptotic friction angle.
    pub tan_friction: T,
    /// Tensile strength p_t ≥ 0 (kPa, magnitude; the tip is at p = −p_t).
    pub tensile_strength: T,
    /// Hyperbola parameter a = c − p_t tanφ (kPa, theory D23).
    pub hyperbola_a: T,
    /// van Eekelen X (theory D25).
    pub shape_x: T,
    /// van Eekelen Y (theory D25).
    pub shape_y: T,
}

/// van Eekelen constants (X, Y) matching Mohr–Coulomb in triaxial compression and
/// extension for friction angle `friction_angle` (radians) (theory D25).
#[inline]
pub fn van_eekelen_shape<T: Real>(friction_angle: T) -> (T, T) {
    van_eekelen_shape_sin_cos(friction_angle.sin(), friction_angle.cos())
}

/// [`van_eekelen_shape`] from sin φ and cos φ (theory D25).
#[inline]
pub fn van_eekelen_shape_sin_cos<T: Real>(sin_phi: T, cos_phi: T) -> (T, T) {
    let three_minus = T::cst(3.0) - sin_phi;
    let ratio = three_minus / (sin_phi + 3.0); // k = r_e / r_c
    let t = ratio.powf(1.0 / VAN_EEKELEN_EXPONENT);
    let y = (T::cst(1.0) - t) / (t + 1.0);
    let r_compression = cos_phi * (2.0 * 3f64.sqrt()) / three_minus;
    let x = r_compression * (y + 1.0).powf(-VAN_EEKELEN_EXPONENT);
    (x, y)
}

/// Highest degree of a [`FrictionShapeFit`].
const FIT_MAX_DEGREE: usize = 24;
/// Accuracy a [`FrictionShapeFit`] must reach on every sample: relative for tanφ and X,
/// absolute for Y (|Y| < 1 enters as 1 + Y sin3θ), in units of f64's machine epsilon.
/// D25 evaluated directly carries a few of its own (the powers and quotients): a series of
/// degree 9 on the paper's 15–20° already sits at that floor (7 ε measured).
const FIT_TOLERANCE_ULP: f64 = 16.0;
/// Samples per interval on which a fit's accuracy is checked.
const FIT_CHECK_SAMPLES: usize = 2001;

/// tan φ and the van Eekelen constants X(φ), Y(φ) of D25 along a friction angle's
/// softening path φ ∈ [φ_res, φ_peak], as Chebyshev series in φ (theory §5.3, "evaluation
/// along the softening path"): a return mapping evaluates the strength at every Newton
/// iterate, and the series replaces the two powers and the sine and cosine of D25 by
/// three short polynomial sums. The degree is the lowest whose error on a dense sample of
/// the interval is at most 16 machine epsilons; a dual argument carries
/// the series' exact derivative.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FrictionShapeFit {
    centre: f64,
    inverse_half_width: f64,
    degree: usize,
    /// Chebyshev coefficients of (tan φ / φ, X, Y), lowest degree first (tan φ / φ keeps
    /// tan φ's relative accuracy at small angles).
    coefficients: [[f64; 3]; FIT_MAX_DEGREE + 1],
}

impl FrictionShapeFit {
    /// The fit on the interval from `lowest` to `highest` (radians), or `None` when no degree
    /// up to 24 reaches the accuracy (a wide path reaching down to about 1°): the caller then
    /// evaluates D25 directly.
    pub fn new(lowest: f64, highest: f64) -> Option<Self> {
        let exact = |phi: f64| {
            let (x, y) = van_eekelen_shape(phi);
            [phi.tan() / phi, x, y]
        };
        let centre = 0.5 * (lowest + highest);
        let half_width = 0.5 * (highest - lowest);
        let inverse_half_width = if half_width > 0.0 {
            1.0 / half_width
        } else {
            0.0
        };
        (0..=FIT_MAX_DEGREE).find_map(|degree| {
            let fit = Self {
                centre,
                inverse_half_width,
                degree,
                coefficients: chebyshev_coefficients(degree, |u| exact(centre + half_width * u)),
            };
            let accurate = (0..FIT_CHECK_SAMPLES).all(|k| {
                let phi = lowest + (highest - lowest) * k as f64 / (FIT_CHECK_SAMPLES - 1) as f64;
                let (mut want, got) = (exact(phi), fit.evaluate(phi));
                want[0] *= phi;
                let scales = [want[0].abs(), want[1].abs(), 1.0];
                (0..3).all(|i| {
                    (got[i] - want[i]).abs() <= FIT_TOLERANCE_ULP * f64::EPSILON * scales[i]
                })
            });
            accurate.then_some(fit)
        })
    }

    /// The series' degree.
    pub fn degree(&self) -> usize {
        self.degree
    }

    /// (tan φ, X, Y) at φ (radians) by Clenshaw's recurrence, generic so that a dual φ
    /// carries the derivatives.
    #[inline]
    pub fn evaluate<T: Real>(&self, phi: T) -> [T; 3] {
        let u = (phi - self.centre) * self.inverse_half_width;
        let two_u = u * 2.0;
        let zero = T::cst(0.0);
        let (mut next, mut after) = ([zero; 3], [zero; 3]);
        for c in self.coefficients[1..=self.degree].iter().rev() {
            let current: [T; 3] = std::array::from_fn(|i| two_u * next[i] - after[i] + c[i]);
            after = next;
            next = current;
        }
        let c0 = self.coefficients[0];
        let [tan_over_phi, x, y] = std::array::from_fn(|i| u * next[i] - after[i] + c0[i]);
        [tan_over_phi * phi, x, y]
    }
}

/// Chebyshev coefficients up to `degree` of the interpolant of `f` on [−1, 1] at the
/// Chebyshev points of the first kind (three components at once).
fn chebyshev_coefficients(
    degree: usize,
    f: impl Fn(f64) -> [f64; 3],
) -> [[f64; 3]; FIT_MAX_DEGREE + 1] {
    let n = degree + 1;
    let angle = |k: usize| std::f64::consts::PI * (k as f64 + 0.5) / n as f64;
    let samples: Vec<[f64; 3]> = (0..n).map(|k| f(angle(k).cos())).collect();
    let mut coefficients = [[0.0; 3]; FIT_MAX_DEGREE + 1];
    for (j, c) in coefficients.iter_mut().enumerate().take(n) {
        let weight = if j == 0 { 1.0 } else { 2.0 } / n as f64;
        for (k, value) in samples.iter().enumerate() {
            let t = (j as f64 * angle(k)).cos();
            for i in 0..3 {
                c[i] += weight * value[i] * t;
            }
        }
    }
    coefficients
}

/// Mohr–Coulomb radius r_MC(θ) = cosφ / (cosθ − sinθ sinφ/√3) (theory D7), θ and φ in radians.
pub fn mohr_coulomb_radius(lode_angle: f64, friction_angle: f64) -> f64 {
    friction_angle.cos()
        / (lode_angle.cos() - lode_angle.sin() * friction_angle.sin() / 3f64.sqrt())
}

impl<T: Real> SurfaceStrength<T> {
    /// Strength from cohesion (kPa), friction angle (radians) and tensile strength (kPa).
    #[inline]
    pub fn new(cohesion: T, friction_angle: T, tensile_strength: T) -> Self {
        let (sin_phi, cos_phi) = friction_angle.sin_cos();
        Self::from_sin_cos(cohesion, sin_phi, cos_phi, tensile_strength)
    }

    /// [`SurfaceStrength::new`] from sin φ and cos φ of the friction angle.
    #[inline]
    pub fn from_sin_cos(cohesion: T, sin_phi: T, cos_phi: T, tensile_strength: T) -> Self {
        let shape = van_eekelen_shape_sin_cos(sin_phi, cos_phi);
        Self::from_shape(cohesion, sin_phi / cos_phi, shape, tensile_strength)
    }

    /// The strength from cohesion, tan φ, the van Eekelen constants (X, Y) of D25 and the
    /// tensile strength; a = c − p_t tanφ (D23).
    #[inline]
    pub fn from_shape(
        cohesion: T,
        tan_friction: T,
        (shape_x, shape_y): (T, T),
        tensile_strength: T,
    ) -> Self {
        Self {
            cohesion,
            tan_friction,
            tensile_strength,
            hyperbola_a: cohesion - tensile_strength * tan_friction,
            shape_x,
            shape_y,
        }
    }
}

impl SurfaceStrength<f64> {
    /// The same strength as constants of another scalar type.
    #[inline]
    pub fn lift<T: Real>(&self) -> SurfaceStrength<T> {
        SurfaceStrength {
            cohesion: T::cst(self.cohesion),
            tan_friction: T::cst(self.tan_friction),
            tensile_strength: T::cst(self.tensile_strength),
            hyperbola_a: T::cst(self.hyperbola_a),
            shape_x: T::cst(self.shape_x),
            shape_y: T::cst(self.shape_y),
        }
    }
}

/// Stress invariants of theory D1–D6.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Invariants {
    /// Compression-positive mean stress p (kPa, D1).
    pub mean_stress: f64,
    /// J = sqrt(J2) (kPa, D4).
    pub j: f64,
    /// sin 3θ ∈ [−1, 1] (D6); +1 triaxial compression, −1 triaxial extension.
    pub sin_3theta: f64,
}

impl Invariants {
    /// Invariants of a tension-positive Voigt stress; sin3θ = 0 when J < `j_min` (kPa).
    pub fn of(stress: &[f64; 4], j_min: f64) -> Self {
        let p = -(stress[0] + stress[1] + stress[2]) / 3.0;
        let (sx, sy, sz, txy) = (stress[0] + p, stress[1] + p, stress[2] + p, stress[3]);
        let j2 = 0.5 * (sx * sx + sy * sy + sz * sz) + txy * txy;
        let j = j2.sqrt();
        let sin_3theta = if j < j_min {
            0.0
        } else {
            let j3 = sz * (sx * sy - txy * txy);
            (-LODE_FACTOR * j3 / (j2 * j)).clamp(-1.0, 1.0)
        };
        Self {
            mean_stress: p,
            j,
            sin_3theta,
        }
    }

    /// Lode angle θ (radians, D6).
    pub fn lode_angle(&self) -> f64 {
        self.sin_3theta.asin() / 3.0
    }
}

/// The hyperbolic Mohr–Coulomb yield criterion (theory D23–D25).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HyperbolicMohrCoulomb {
    /// Below this J (kPa) the Lode angle is undefined: sin3θ = 0 and the θ-term of f_σ is dropped (D6, D31).
    pub j_min: f64,
}

impl HyperbolicMohrCoulomb {
    /// Deviatoric radius r(θ) = X (1 + Y sin3θ)^Z (theory D24).
    #[inline]
    pub fn shape_radius<T: Real>(strength: &SurfaceStrength<T>, sin_3theta: T) -> T {
        strength.shape_x * (strength.shape_y * sin_3theta + 1.0).powf(VAN_EEKELEN_EXPONENT)
    }

    /// f(σ) = sqrt(J²/fd(θ) + a²) − (c + p tanφ) (theory D23), kPa.
    #[inline]
    pub fn value<T: Real>(&self, stress: &[T; 4], strength: &SurfaceStrength<T>) -> T {
        let p = -(stress[0] + stress[1] + stress[2]) / 3.0;
        let (sx, sy, sz, txy) = (stress[0] + p, stress[1] + p, stress[2] + p, stress[3]);
        let j2 = (sx * sx + sy * sy + sz * sz) * 0.5 + txy * txy;
        let r = if j2.re() < self.j_min * self.j_min {
            strength.shape_x
        } else {
            let j3 = sz * (sx * sy - txy * txy);
            let sin_3theta = clamp_lode(-(j3 / (j2 * j2.sqrt())) * LODE_FACTOR);
            Self::shape_radius(strength, sin_3theta)
        };
        let a = strength.hyperbola_a;
        (j2 / (r * r) + a * a).sqrt() - (strength.cohesion + p * strength.tan_friction)
    }

    /// f (kPa) and its analytic gradient f_σ = ∂f/∂σ (Voigt, theory D31).
    #[inline]
    pub fn value_and_gradient<T: Real>(
        &self,
        stress: &[T; 4],
        strength: &SurfaceStrength<T>,
    ) -> (T, [T; 4]) {
        let p = -(stress[0] + stress[1] + stress[2]) / 3.0;
        let (sx, sy, sz, txy) = (stress[0] + p, stress[1] + p, stress[2] + p, stress[3]);
        let j2 = (sx * sx + sy * sy + sz * sz) * 0.5 + txy * txy;
        let a = strength.hyperbola_a;
        let tan_third = strength.tan_friction / 3.0;
        let pressure_strength = strength.cohesion + p * strength.tan_friction;
        if j2.re() < self.j_min * self.j_min {
            // Lode angle undefined: sin3θ = 0 (D6), r = X; θ-term dropped (D31).
            let fd = strength.shape_x * strength.shape_x;
            let big_r = (j2 / fd + a * a).sqrt();
            let f = big_r - pressure_strength;
            let k = T::cst(0.5) / (fd * big_r);
            let g = [
                sx * k + tan_third,
                sy * k + tan_third,
                sz * k + tan_third,
                txy * k * 2.0,
            ];
            return (f, g);
        }
        let j = j2.sqrt();
        let j3 = sz * (sx * sy - txy * txy);
        let sin_3theta = clamp_lode(-(j3 / (j2 * j)) * LODE_FACTOR);
        let base = strength.shape_y * sin_3theta + 1.0;
        let base_to_z = base.powf(VAN_EEKELEN_EXPONENT);
        let r = strength.shape_x * base_to_z;
        let fd = r * r;
        let big_r = (j2 / fd + a * a).sqrt();
        let f = big_r - pressure_strength;
        // ∂f/∂J2 at fixed θ, times ∂J2/∂σ = [sx, sy, sz, 2σxy].
        let k = T::cst(0.5) / (fd * big_r);
        let mut g = [
            sx * k + tan_third,
            sy * k + tan_third,
            sz * k + tan_third,
            txy * k * 2.0,
        ];
        // f_s ∂(sin3θ)/∂σ with f_s = −J² r'/(r³ R), r' = X Z Y base^{Z−1} (D31); written with
        // fewer inverse powers of J:
        // f_s ∂s3/∂σ = (3√3/2) r'/(r³ R) [∂J3/∂σ / J − (3/2) J3 [s] / J³].
        // base^{Z−1} as base^Z / base (base = 1 + Y sin3θ > 0 for |Y| < 1): one power
        let r_prime =
            strength.shape_x * strength.shape_y * (base_to_z / base) * VAN_EEKELEN_EXPONENT;
        let coef = r_prime / (fd * r * big_r) * LODE_FACTOR;
        let two_thirds_j2 = j2 * (2.0 / 3.0);
        let txy2 = txy * txy;
        let dj3 = [
            sx * sx + txy2 - two_thirds_j2,
            sy * sy + txy2 - two_thirds_j2,
            sz * sz - two_thirds_j2,
            txy * (sx + sy) * 2.0,
        ];
        let inv_j = T::cst(1.0) / j;
        let c1 = coef * inv_j;
        let c2 = coef * j3 * 1.5 / (j2 * j);
        let s = [sx, sy, sz, txy * 2.0];
        for i in 0..4 {
            g[i] = g[i] + c1 * dj3[i] - c2 * s[i];
        }
        (f, g)
    }
}

/// sin3θ brought back into [−1, 1] where round-off put it outside (D6), its derivatives
/// kept: the surface is smooth at θ = ±30° (D24), so the curvature of sin3θ still enters
/// the second derivatives there (the consistent tangent at triaxial states, D32).
#[inline]
fn clamp_lode<T: Real>(sin_3theta: T) -> T {
    let value = sin_3theta.re();
    if value.abs() > 1.0 {
        sin_3theta - (value - value.signum())
    } else {
        sin_3theta
    }
}

/// Principal (σxy = 0) tension-positive Voigt stress with compression-positive mean stress `p` (kPa),
/// deviatoric radius `j` = sqrt(J2) (kPa) and Lode angle `theta` (radians, theory D6); the most
/// compressive principal stress is σxx.
pub fn stress_from_invariants(p: f64, j: f64, theta: f64) -> [f64; 4] {
    // Compression-positive principal deviators c_i = k cos(θ − π/6 − 2πi/3), k = 2J/√3:
    // their product is k³ sin3θ / 4, which with D6 gives back θ.
    let k = 2.0 / 3f64.sqrt() * j;
    let a = theta - std::f64::consts::FRAC_PI_6;
    let third = 2.0 * std::f64::consts::PI / 3.0;
    let (s1, s2, s3) = (k * a.cos(), k * (a - third).cos(), k * (a + third).cos());
    [-(p + s1), -(p + s2), -(p + s3), 0.0]
}

#[cfg(test)]
mod tests {
    use super::*;

    fn strength(c: f64, phi_deg: f64, pt: f64) -> SurfaceStrength<f64> {
        SurfaceStrength::new(c, phi_deg.to_radians(), pt)
    }

    /// D25's printed constants: φ = 20°: X = 1.06255, Y = −0.46213; φ = 15°: X = 1.10181,
    /// Y = −0.36069 (tolerance 1e-5, the printed precision) and fd at TC/TE = 1.4999 / 0.9487 (1e-4).
    #[test]
    fn van_eekelen_printed_constants() {
        let (x20, y20) = van_eekelen_shape(20f64.to_radians());
        let (x15, y15) = van_eekelen_shape(15f64.to_radians());
        assert!((x20 - 1.06255).abs() < 1e-5, "X(20) = {x20}");
        assert!((y20 + 0.46213).abs() < 1e-5, "Y(20) = {y20}");
        assert!((x15 - 1.10181).abs() < 1e-5, "X(15) = {x15}");
        assert!((y15 + 0.36069).abs() < 1e-5, "Y(15) = {y15}");
        let s = strength(200.0, 20.0, 0.0);
        let fd_tc = HyperbolicMohrCoulomb::shape_radius(&s, 1.0).powi(2);
        let fd_te = HyperbolicMohrCoulomb::shape_radius(&s, -1.0).powi(2);
        assert!((fd_tc - 1.4999).abs() < 1e-4, "fd(TC) = {fd_tc}");
        assert!((fd_te - 0.9487).abs() < 1e-4, "fd(TE) = {fd_te}");
    }

    /// The friction-shape series (theory §5.3) equals D25 at points between its check
    /// samples to 16 machine epsilons (relative for tanφ and X, absolute for Y), and its
    /// φ-derivative equals the derivative of D25 by central differences (step 1e-6, whose
    /// rounding is ~1e-10) to 3e-9 relative (3.4e-10 measured), on
    /// the paper's path 15–20° (degree 8), on a wide one (5–46°, degree 19), on small angles
    /// and on a constant angle (degree 0). (On 1–46° no degree up to 24 reaches the accuracy: the model then
    /// evaluates D25 directly.)
    #[test]
    fn friction_shape_fit_matches_d25() {
        use super::super::dual::Dual;
        for (lowest, highest) in [(15.0f64, 20.0f64), (5.0, 46.0), (0.1, 10.0), (30.0, 30.0)] {
            let (lo, hi) = (lowest.to_radians(), highest.to_radians());
            let fit = FrictionShapeFit::new(lo, hi).expect("fit");
            let mut worst: f64 = 0.0;
            for k in 0..997 {
                let phi = lo + (hi - lo) * (k as f64 + 0.37) / 997.0;
                let (x, y) = van_eekelen_shape(phi);
                let want = [phi.tan(), x, y];
                let got = fit.evaluate(phi);
                let scales = [want[0], want[1], 1.0];
                for i in 0..3 {
                    worst = worst.max((got[i] - want[i]).abs() / scales[i] / f64::EPSILON);
                }
                if hi == lo {
                    continue; // a constant angle: no path to differentiate along
                }
                let dual = fit.evaluate(Dual::<1>::variable(phi, 0));
                let h = 1e-6;
                let (xp, yp) = van_eekelen_shape(phi + h);
                let (xm, ym) = van_eekelen_shape(phi - h);
                let slope = [
                    ((phi + h).tan() - (phi - h).tan()) / (2.0 * h),
                    (xp - xm) / (2.0 * h),
                    (yp - ym) / (2.0 * h),
                ];
                for i in 0..3 {
                    let scale = slope[i].abs().max(1.0);
                    assert!(
                        (dual[i].eps[0] - slope[i]).abs() <= 3e-9 * scale,
                        "φ = {phi}: d{i}/dφ = {} against {}",
                        dual[i].eps[0],
                        slope[i]
                    );
                }
            }
            assert!(worst <= 16.0, "[{lowest}°, {highest}°]: {worst} ulp");
        }
    }

    /// At triaxial states (θ = ±30°, where round-off may put sin3θ just outside [−1, 1]) the
    /// dual second derivatives of f equal central differences of the analytic gradient
    /// (step 1e-6 of the largest stress) to 2e-9 relative to the Hessian's largest entry
    /// (1.6e-10 measured; 0.18 when the Lode term was dropped wherever round-off clamped
    /// sin3θ: the gradient then jumped across the triaxial states).
    #[test]
    fn hessian_at_triaxial_states_matches_finite_differences() {
        use super::super::dual::Dual;
        let surface = HyperbolicMohrCoulomb { j_min: 1e-8 };
        let s = strength(50.0, 25.0, 10.0);
        let states = [
            stress_from_invariants(80.0, 40.0, 30f64.to_radians()),
            stress_from_invariants(80.0, 40.0, -30f64.to_radians()),
            [
                -53676.179752110635,
                -91345.4306888792,
                -53676.179752110635,
                0.0,
            ],
            [-120.0, -120.0, -300.0, 0.0],
        ];
        let mut worst: f64 = 0.0;
        for sigma in states {
            let dual: [Dual<4>; 4] = std::array::from_fn(|i| Dual::variable(sigma[i], i));
            let (_, g) = surface.value_and_gradient(&dual, &s.lift());
            let largest = g
                .iter()
                .flat_map(|gi| gi.eps)
                .fold(0.0f64, |a, x| a.max(x.abs()));
            let h = 1e-6 * sigma.iter().fold(1.0f64, |a, x| a.max(x.abs()));
            for j in 0..4 {
                let (mut sp, mut sm) = (sigma, sigma);
                sp[j] += h;
                sm[j] -= h;
                let (_, gp) = surface.value_and_gradient(&sp, &s);
                let (_, gm) = surface.value_and_gradient(&sm, &s);
                for i in 0..4 {
                    let fd = (gp[i] - gm[i]) / (2.0 * h);
                    worst = worst.max((fd - g[i].eps[j]).abs() / largest);
                }
            }
        }
        assert!(worst <= 2e-9, "Hessian error {worst:e}");
    }

    /// The Lode angle convention of D6: the helper stress at θ = +30° is triaxial compression.
    #[test]
    fn lode_angle_convention() {
        let s = stress_from_invariants(100.0, 50.0, 30f64.to_radians());
        // σ1 (most compressive) alone, σ2 = σ3: triaxial compression.
        assert!((s[1] - s[2]).abs() < 1e-9 && s[0] < s[1]);
        let inv = Invariants::of(&s, 1e-10);
        assert!((inv.sin_3theta - 1.0).abs() < 1e-9);
        assert!((inv.j - 50.0).abs() < 1e-9 && (inv.mean_stress - 100.0).abs() < 1e-9);
        let inv = Invariants::of(&stress_from_invariants(100.0, 50.0, 0.2), 1e-10);
        assert!((inv.lode_angle() - 0.2).abs() < 1e-9);
    }

    /// f = 0 at the tip (p = −p_t, J = 0) to 1e-12 relative; the surface with c = p_t = 0 passes
    /// through the origin (f = 0 to 1e-12).
    #[test]
    fn tip_and_origin() {
        let surface = HyperbolicMohrCoulomb { j_min: 1e-8 };
        for (c, phi, pt) in [
            (200.0, 20.0, 0.0),
            (50.0, 30.0, 40.0),
            (10.0, 15.0, 10.0 / 15f64.to_radians().tan()),
        ] {
            let s = strength(c, phi, pt);
            let f = surface.value(&[pt, pt, pt, 0.0], &s);
            assert!(
                f.abs() <= 1e-12 * c,
                "f(tip) = {f} for c = {c}, φ = {phi}, pt = {pt}"
            );
            // Slightly off the tip, in tension, outside; in compression at J = 0 inside.
            assert!(surface.value(&[pt + 1.0, pt + 1.0, pt + 1.0, 0.0], &s) > 0.0);
            assert!(surface.value(&[pt - 1.0, pt - 1.0, pt - 1.0, 0.0], &s) < 0.0);
        }
        let s = strength(0.0, 20.0, 0.0);
        let f = surface.value(&[0.0; 4], &s);
        assert!(f.abs() <= 1e-12, "f(origin) = {f}");
        // and a small deviator at zero pressure is outside (no strength at p = 0).
        assert!(surface.value(&stress_from_invariants(0.0, 1e-3, 0.1), &s) > 0.0);
    }

    /// At large p the surface tends to the MC line J = r_MC(θ)(c + p tanφ) (D7) in triaxial
    /// compression and extension: relative difference in J below 0.1 % at p = 1e3·c.
    #[test]
    fn asymptote_is_mohr_coulomb_in_compression_and_extension() {
        let surface = HyperbolicMohrCoulomb { j_min: 1e-8 };
        for (c, phi_deg, pt) in [(200.0, 20.0, 0.0), (10.0, 35.0, 5.0), (100.0, 15.0, 0.0)] {
            let phi = f64::to_radians(phi_deg);
            let s = strength(c, phi_deg, pt);
            let p = 1e3 * c;
            for theta_deg in [30.0f64, -30.0] {
                let theta = theta_deg.to_radians();
                let j_mc = mohr_coulomb_radius(theta, phi) * (c + p * phi.tan());
                // Find J on the surface by bisection along the meridian.
                let (mut lo, mut hi) = (0.0, 2.0 * j_mc);
                for _ in 0..200 {
                    let mid = 0.5 * (lo + hi);
                    if surface.value(&stress_from_invariants(p, mid, theta), &s) > 0.0 {
                        hi = mid;
                    } else {
                        lo = mid;
                    }
                }
                let rel = (lo - j_mc).abs() / j_mc;
                assert!(
                    rel < 1e-3,
                    "θ = {theta_deg}: J = {lo} vs MC {j_mc} (rel {rel})"
                );
            }
        }
    }

    /// The analytic gradient (D31) equals central differences of f (step 1e-5 kPa,
    /// tolerance 1e-6 relative to ‖f_σ‖) at assorted states, including θ near ±30°.
    #[test]
    fn gradient_matches_finite_differences() {
        let surface = HyperbolicMohrCoulomb { j_min: 1e-8 };
        let s = strength(50.0, 25.0, 10.0);
        let states = [
            [-100.0, -300.0, -150.0, 40.0],
            [-10.0, -12.0, -11.0, 0.5],
            stress_from_invariants(80.0, 40.0, 29.9f64.to_radians()),
            stress_from_invariants(80.0, 40.0, -29.9f64.to_radians()),
            [5.0, 4.0, 6.0, 0.0],
        ];
        for sigma in states {
            let (_, g) = surface.value_and_gradient(&sigma, &s);
            let norm = g.iter().map(|x| x * x).sum::<f64>().sqrt();
            for j in 0..4 {
                let h = 1e-5;
                let (mut sp, mut sm) = (sigma, sigma);
                sp[j] += h;
                sm[j] -= h;
                let fd = (surface.value(&sp, &s) - surface.value(&sm, &s)) / (2.0 * h);
                assert!(
                    (fd - g[j]).abs() <= 1e-6 * norm,
                    "σ = {sigma:?}, j = {j}: {} vs {fd}",
                    g[j]
                );
            }
        }
    }
}
