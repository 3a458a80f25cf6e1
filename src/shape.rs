//! Bilinear shape functions of the 4-node square cell (DESIGN D9).
//!
//! Local node order (counter-clockwise from the lower-left corner):
//! 0 = (−1,−1), 1 = (+1,−1), 2 = (+1,+1), 3 = (−1,+1).

/// Local natural coordinates (ξ_a, η_a) of the four cell nodes.
pub const NODE_SIGNS: [[f64; 2]; 4] = [[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]];

/// Values N_a at natural coordinates (ξ, η) ∈ [−1, 1]² (DESIGN D9).
#[inline]
pub fn values(xi: f64, eta: f64) -> [f64; 4] {
    let mut n = [0.0; 4];
    for (a, sign) in NODE_SIGNS.iter().enumerate() {
        n[a] = 0.25 * (1.0 + sign[0] * xi) * (1.0 + sign[1] * eta);
    }
    n
}

/// Cartesian gradients ∇N_a = (2/h)·∂N_a/∂(ξ, η) for a square cell of side `h` (DESIGN D9).
#[inline]
pub fn gradients(xi: f64, eta: f64, h: f64) -> [[f64; 2]; 4] {
    let scale = 2.0 / h;
    let mut dn = [[0.0; 2]; 4];
    for (a, sign) in NODE_SIGNS.iter().enumerate() {
        dn[a][0] = scale * 0.25 * sign[0] * (1.0 + sign[1] * eta);
        dn[a][1] = scale * 0.25 * sign[1] * (1.0 + sign[0] * xi);
    }
    dn
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Partition of unity and zero-sum gradients at arbitrary points.
    #[test]
    fn partition_of_unity_and_linear_completeness() {
        for &(xi, eta) in &[(0.0, 0.0), (0.3, -0.7), (-1.0, 1.0), (0.99, 0.12)] {
            let n = values(xi, eta);
            let dn = gradients(xi, eta, 0.5);
            assert!((n.iter().sum::<f64>() - 1.0).abs() < 1e-15);
            let gx: f64 = dn.iter().map(|g| g[0]).sum();
            let gy: f64 = dn.iter().map(|g| g[1]).sum();
            assert!(gx.abs() < 1e-14 && gy.abs() < 1e-14);
            // Σ ∇N_a x_a = I with x_a = (h/2) ξ_a
            let h = 0.5;
            let mut jac = [[0.0; 2]; 2];
            for a in 0..4 {
                for i in 0..2 {
                    for j in 0..2 {
                        jac[i][j] += 0.5 * h * NODE_SIGNS[a][i] * dn[a][j];
                    }
                }
            }
            assert!((jac[0][0] - 1.0).abs() < 1e-14 && (jac[1][1] - 1.0).abs() < 1e-14);
            assert!(jac[0][1].abs() < 1e-14 && jac[1][0].abs() < 1e-14);
        }
    }
}
