//! Vector norms and residuals shared by the iterative solvers, the tests and the bench.

use crate::SparseMatrix;

/// `aᵀb`.
pub(crate) fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// `‖v‖₂`.
pub(crate) fn norm(v: &[f64]) -> f64 {
    dot(v, v).sqrt()
}

/// The position of the largest |v_i| (of the first non-finite entry where
/// there is one); `None` for an empty vector.
pub(crate) fn largest_entry(v: &[f64]) -> Option<usize> {
    if let Some(i) = v.iter().position(|x| !x.is_finite()) {
        return Some(i);
    }
    (0..v.len()).reduce(|best, i| if v[i].abs() > v[best].abs() { i } else { best })
}

/// `‖b − K x‖ / norm_b`.
pub(crate) fn true_residual(k: &SparseMatrix, x: &[f64], b: &[f64], norm_b: f64) -> f64 {
    let mut kx = vec![0.0; b.len()];
    k.mul_vec(x, &mut kx);
    let r2: f64 = kx.iter().zip(b).map(|(a, b)| (b - a) * (b - a)).sum();
    r2.sqrt() / norm_b
}

/// ‖b − Kx‖ / ‖b‖ (0 when b = 0 and x solves it).
#[cfg(any(test, feature = "study"))]
pub fn relative_residual(k: &SparseMatrix, x: &[f64], b: &[f64]) -> f64 {
    let mut kx = vec![0.0; b.len()];
    k.mul_vec(x, &mut kx);
    let r: Vec<f64> = kx.iter().zip(b).map(|(a, b)| b - a).collect();
    norm(&r) / norm(b).max(f64::MIN_POSITIVE)
}

/// ‖x − y‖ / ‖y‖.
#[cfg(any(test, feature = "study"))]
pub fn relative_difference(x: &[f64], y: &[f64]) -> f64 {
    let d: Vec<f64> = x.iter().zip(y).map(|(a, b)| a - b).collect();
    norm(&d) / norm(y).max(f64::MIN_POSITIVE)
}
