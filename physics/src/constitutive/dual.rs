//! Forward-mode dual numbers with `N` derivative directions, used to obtain the
//! *exact* second derivatives m_σ, m_κ, f_κ, h_σ, h_κ of the return mapping
//! (theory D30–D31 allow central differences "or forward-mode hyper-dual
//! numbers as an exact alternative"; this is the exact alternative).
//!
//! The yield function, flow rule and softening laws are written once, generic
//! over [`Real`], and evaluated either with plain `f64` (cheap paths: elastic
//! check) or with [`Dual<N>`] (Jacobian of the return mapping).

use std::ops::{Add, Div, Mul, Neg, Sub};

/// Scalar arithmetic needed by the constitutive functions: `f64` or [`Dual`].
pub trait Real:
    Copy
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
    + Add<f64, Output = Self>
    + Sub<f64, Output = Self>
    + Mul<f64, Output = Self>
    + Div<f64, Output = Self>
{
    /// A constant (zero derivative).
    fn cst(value: f64) -> Self;
    /// The value part.
    fn re(self) -> f64;
    /// Square root.
    fn sqrt(self) -> Self;
    /// `self^exponent` with a constant exponent.
    fn powf(self, exponent: f64) -> Self;
    /// Exponential.
    fn exp(self) -> Self;
    /// Sine (radians).
    fn sin(self) -> Self;
    /// Cosine (radians).
    fn cos(self) -> Self;
    /// Sine and cosine together (radians).
    fn sin_cos(self) -> (Self, Self) {
        (self.sin(), self.cos())
    }
    /// Smaller of two values (derivative of the selected branch).
    fn min_by_value(self, other: Self) -> Self {
        if self.re() <= other.re() {
            self
        } else {
            other
        }
    }
    /// Larger of two values (derivative of the selected branch).
    fn max_by_value(self, other: Self) -> Self {
        if self.re() >= other.re() {
            self
        } else {
            other
        }
    }
}

impl Real for f64 {
    #[inline(always)]
    fn cst(value: f64) -> Self {
        value
    }
    #[inline(always)]
    fn re(self) -> f64 {
        self
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        f64::sqrt(self)
    }
    #[inline(always)]
    fn powf(self, exponent: f64) -> Self {
        f64::powf(self, exponent)
    }
    #[inline(always)]
    fn exp(self) -> Self {
        f64::exp(self)
    }
    #[inline(always)]
    fn sin(self) -> Self {
        f64::sin(self)
    }
    #[inline(always)]
    fn cos(self) -> Self {
        f64::cos(self)
    }
}

/// Dual number `re + Σ eps[i] ε_i` with ε_i ε_j = 0: first derivatives in `N` directions.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Dual<const N: usize> {
    /// Value.
    pub re: f64,
    /// Derivatives with respect to the `N` seeded variables.
    pub eps: [f64; N],
}

impl<const N: usize> Dual<N> {
    /// The independent variable number `index` with value `re` (∂/∂x_index = 1).
    #[inline(always)]
    pub fn variable(re: f64, index: usize) -> Self {
        let mut eps = [0.0; N];
        eps[index] = 1.0;
        Self { re, eps }
    }

    /// Chain rule for a unary function with value `value` and derivative `slope`.
    #[inline(always)]
    fn chain(self, value: f64, slope: f64) -> Self {
        let mut eps = self.eps;
        for e in eps.iter_mut() {
            *e *= slope;
        }
        Self { re: value, eps }
    }
}

impl<const N: usize> Add for Dual<N> {
    type Output = Self;
    #[inline(always)]
    fn add(self, o: Self) -> Self {
        let mut eps = self.eps;
        for (e, oe) in eps.iter_mut().zip(o.eps) {
            *e += oe;
        }
        Self {
            re: self.re + o.re,
            eps,
        }
    }
}

impl<const N: usize> Sub for Dual<N> {
    type Output = Self;
    #[inline(always)]
    fn sub(self, o: Self) -> Self {
        let mut eps = self.eps;
        for (e, oe) in eps.iter_mut().zip(o.eps) {
            *e -= oe;
        }
        Self {
            re: self.re - o.re,
            eps,
        }
    }
}

impl<const N: usize> Mul for Dual<N> {
    type Output = Self;
    #[inline(always)]
    fn mul(self, o: Self) -> Self {
        let mut eps = self.eps;
        for (e, oe) in eps.iter_mut().zip(o.eps) {
            *e = *e * o.re + self.re * oe;
        }
        Self {
            re: self.re * o.re,
            eps,
        }
    }
}

impl<const N: usize> Div for Dual<N> {
    type Output = Self;
    #[inline(always)]
    fn div(self, o: Self) -> Self {
        // the value as f64 divides it (not times 1/o): a dual evaluation's value
        // part is then the f64 evaluation's, bit for bit
        let inv = 1.0 / o.re;
        let re = self.re / o.re;
        let mut eps = self.eps;
        for (e, oe) in eps.iter_mut().zip(o.eps) {
            *e = (*e - re * oe) * inv;
        }
        Self { re, eps }
    }
}

impl<const N: usize> Neg for Dual<N> {
    type Output = Self;
    #[inline(always)]
    fn neg(self) -> Self {
        self.chain(-self.re, -1.0)
    }
}

impl<const N: usize> Add<f64> for Dual<N> {
    type Output = Self;
    #[inline(always)]
    fn add(self, o: f64) -> Self {
        Self {
            re: self.re + o,
            eps: self.eps,
        }
    }
}

impl<const N: usize> Sub<f64> for Dual<N> {
    type Output = Self;
    #[inline(always)]
    fn sub(self, o: f64) -> Self {
        Self {
            re: self.re - o,
            eps: self.eps,
        }
    }
}

impl<const N: usize> Mul<f64> for Dual<N> {
    type Output = Self;
    #[inline(always)]
    fn mul(self, o: f64) -> Self {
        self.chain(self.re * o, o)
    }
}

impl<const N: usize> Div<f64> for Dual<N> {
    type Output = Self;
    #[inline(always)]
    fn div(self, o: f64) -> Self {
        self.chain(self.re / o, 1.0 / o)
    }
}

impl<const N: usize> Real for Dual<N> {
    #[inline(always)]
    fn cst(value: f64) -> Self {
        Self {
            re: value,
            eps: [0.0; N],
        }
    }
    #[inline(always)]
    fn re(self) -> f64 {
        self.re
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        let s = self.re.sqrt();
        self.chain(s, 0.5 / s)
    }
    #[inline(always)]
    fn powf(self, exponent: f64) -> Self {
        let v = self.re.powf(exponent);
        self.chain(v, exponent * v / self.re)
    }
    #[inline(always)]
    fn exp(self) -> Self {
        let v = self.re.exp();
        self.chain(v, v)
    }
    #[inline(always)]
    fn sin(self) -> Self {
        let (s, c) = self.re.sin_cos();
        self.chain(s, c)
    }
    #[inline(always)]
    fn cos(self) -> Self {
        let (s, c) = self.re.sin_cos();
        self.chain(c, -s)
    }
    #[inline(always)]
    fn sin_cos(self) -> (Self, Self) {
        let (s, c) = self.re.sin_cos();
        (self.chain(s, c), self.chain(c, -s))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample<T: Real>(x: T, y: T) -> T {
        (x * y + x.sin() * y.cos()).sqrt() / (x.exp() + 2.0) + (y * y + 1.0).powf(-0.229) - x * 3.0
    }

    /// Dual derivatives equal central differences of the f64 evaluation (tolerance 1e-8 relative).
    #[test]
    fn dual_matches_central_differences() {
        let (x, y) = (0.7, 1.3);
        let d = sample(Dual::<2>::variable(x, 0), Dual::<2>::variable(y, 1));
        let h = 1e-6;
        let dx = (sample(x + h, y) - sample(x - h, y)) / (2.0 * h);
        let dy = (sample(x, y + h) - sample(x, y - h)) / (2.0 * h);
        assert!((d.re - sample(x, y)).abs() < 1e-15);
        assert!(
            (d.eps[0] - dx).abs() <= 1e-8 * dx.abs().max(1.0),
            "{} vs {dx}",
            d.eps[0]
        );
        assert!(
            (d.eps[1] - dy).abs() <= 1e-8 * dy.abs().max(1.0),
            "{} vs {dy}",
            d.eps[1]
        );
    }
}
