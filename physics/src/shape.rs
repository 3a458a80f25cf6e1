//! Bilinear shape functions of the 4-node square cell (theory D9).
//!
//! Local node order (counter-clockwise from the lower-left corner):
//! 0 = (−1,−1), 1 = (+1,−1), 2 = (+1,+1), 3 = (−1,+1).

/// Local natural coordinates (ξ_a, η_a) of the four cell nodes.
pub const NODE_SIGNS: [[f64; 2]; 4] = [[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]];

/// Values N_a at natural coordinates (ξ, η) ∈ [−1, 1]² (theory D9).
#[inline]
pub fn values(xi: f64, eta: f64) -> [f64; 4] {
    let mut n = [0.0; 4];
    for (a, sign) in NODE_SIGNS.iter().enumerate() {
        n[a] = 0.25 * (1.0 + sign[0] * xi) * (1.0 + sign[1] * eta);
    }
    n
}

/// Cartesian gradients ∇N_a = (2/h)·∂N_a/∂(ξ, η) for a square cell of side `h` (theory D9).
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

/// `⌊v⌋` as an integer: the value of `v.floor() as i64` for every `f64` (NaN gives 0,
/// ±∞ and out-of-range values saturate), by truncation and a correction. On x86-64
/// without SSE4.1 `floor` is a library call: locating the points of an explicit step
/// called it twice a point (1.5 % of the step's time).
#[inline]
pub fn floor_int(v: f64) -> i64 {
    let truncated = v as i64;
    if (truncated as f64) > v {
        truncated.saturating_sub(1)
    } else {
        truncated
    }
}

/// `⌈v⌉` as an integer: the value of `v.ceil() as i64` for every `f64`, as [`floor_int`].
#[inline]
pub fn ceil_int(v: f64) -> i64 {
    let truncated = v as i64;
    if (truncated as f64) < v {
        truncated.saturating_add(1)
    } else {
        truncated
    }
}

/// uGIMP shape functions along one grid direction (Bardenhagen & Kober 2004):
/// the particle domain [x_p − l_p, x_p + l_p], clipped to `bounds` (grid lines
/// inside the grid) to give [a, b], and
/// for each node k whose hat function N_k reaches it with positive length
///
///   S_k = (1/(b − a)) ∫_a^b N_k dx,    S'_k = (1/(b − a)) ∫_a^b N_k' dx = (N_k(b) − N_k(a))/(b − a).
///
/// Σ S_k = 1, Σ S'_k = 0 and Σ S'_k x_k = 1 hold exactly (the hats sum to 1 on
/// the grid); Σ S_k x_k = (a + b)/2, which is x_p unless the domain is clipped.
/// Both are continuous in x_p while the bounds stay fixed, so nothing jumps
/// when a point crosses a cell edge. `origin`, `h`: first node and spacing.
pub fn gimp_1d(origin: f64, h: f64, xp: f64, half_width: f64, bounds: [f64; 2]) -> Gimp1d {
    let a = (xp - half_width).max(bounds[0]);
    let b = (xp + half_width).min(bounds[1]);
    let length = b - a;
    let first = floor_int((a - origin) / h).max(0) as usize;
    let last = ceil_int((b - origin) / h).max(0) as usize;
    let mut out = Gimp1d::default();
    for k in first..=last.min(first + 2) {
        let xk = origin + k as f64 * h;
        let (sa, sb) = ((a - xk) / h, (b - xk) / h);
        let (weight, gradient) = if length > 0.0 {
            (
                h * (hat_integral(sb) - hat_integral(sa)) / length,
                (hat(sb) - hat(sa)) / length,
            )
        } else {
            // a point domain (l_p = 0) is the bilinear hat itself
            let slope = if sa < 0.0 { 1.0 / h } else { -1.0 / h };
            (hat(sa), if sa.abs() < 1.0 { slope } else { 0.0 })
        };
        if weight > 0.0 {
            out.node[out.count] = k;
            out.weight[out.count] = weight;
            out.gradient[out.count] = gradient;
            out.count += 1;
        }
    }
    out
}

/// Result of [`gimp_1d`]: the first `count` nodes, weights S_k and gradients S'_k (1/m).
#[derive(Clone, Copy, Debug, Default)]
pub struct Gimp1d {
    /// Number of nodes reached (≤ 3 for l_p ≤ h/2).
    pub count: usize,
    /// Node indices along the direction.
    pub node: [usize; 3],
    /// S_k.
    pub weight: [f64; 3],
    /// S'_k, 1/m.
    pub gradient: [f64; 3],
}

/// The 1-D hat N(s) = max(0, 1 − |s|) in units of h.
#[inline]
fn hat(s: f64) -> f64 {
    (1.0 - s.abs()).max(0.0)
}

/// ∫_{−∞}^{s} N(t) dt of the unit hat.
#[inline]
fn hat_integral(s: f64) -> f64 {
    if s <= -1.0 {
        0.0
    } else if s <= 0.0 {
        0.5 * (1.0 + s) * (1.0 + s)
    } else if s <= 1.0 {
        1.0 - 0.5 * (1.0 - s) * (1.0 - s)
    } else {
        1.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `floor_int` and `ceil_int` give exactly `floor() as i64` and `ceil() as i64`:
    /// at and next to integers, at ±0, NaN, ±∞, beyond the i64 range, and on
    /// 100,000 values spread over 40 binades of both signs.
    #[test]
    fn integer_floor_and_ceil_agree_with_the_library() {
        let mut values = vec![
            0.0,
            -0.0,
            f64::NAN,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::MAX,
            f64::MIN,
            9.3e18,
            -9.3e18,
            (1u64 << 53) as f64,
            f64::MIN_POSITIVE,
            -f64::MIN_POSITIVE,
        ];
        for k in -5..=5 {
            let x = k as f64;
            values.extend([x, x.next_up(), x.next_down(), x + 0.5]);
        }
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        for _ in 0..100_000 {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            let mantissa = (state >> 11) as f64 / (1u64 << 53) as f64;
            let exponent = (state % 40) as i32 - 8;
            let sign = if state & 1 == 0 { 1.0 } else { -1.0 };
            values.push(sign * mantissa * 2f64.powi(exponent));
        }
        for v in values {
            assert_eq!(floor_int(v), v.floor() as i64, "floor of {v:e}");
            assert_eq!(ceil_int(v), v.ceil() as i64, "ceil of {v:e}");
        }
    }

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

    /// GIMP along one direction: partition of unity, linear completeness of
    /// the gradient, x_p reproduced when the domain is not clipped, the
    /// gradient equal to the finite difference of the weights, continuity
    /// across a grid line, and the bilinear hat recovered for l_p → 0.
    #[test]
    fn gimp_1d_completeness_and_continuity() {
        let (origin, h, lp) = (-0.3, 0.2, 0.05);
        let bounds = [origin, origin + 7.0 * h];
        for &xp in &[-0.3, -0.27, -0.12, -0.1001, -0.1, 0.0437, 0.97, 1.1] {
            let g = gimp_1d(origin, h, xp, lp, bounds);
            let xk = |k: usize| origin + k as f64 * h;
            let sum: f64 = g.weight[..g.count].iter().sum();
            let gsum: f64 = g.gradient[..g.count].iter().sum();
            let gx: f64 = (0..g.count).map(|k| g.gradient[k] * xk(g.node[k])).sum();
            let x: f64 = (0..g.count).map(|k| g.weight[k] * xk(g.node[k])).sum();
            assert!((sum - 1.0).abs() < 1e-14 && gsum.abs() < 1e-12, "{xp}");
            assert!((gx - 1.0).abs() < 1e-12, "{xp}: {gx}");
            let clipped = xp - lp < origin || xp + lp > origin + 7.0 * h;
            if !clipped {
                assert!((x - xp).abs() < 1e-14, "{xp}: {x}");
            }
            // central difference of the weights (away from the clipped ends)
            if !clipped && xp - lp - 1e-6 > origin {
                let step = 1e-7;
                let (gp, gm) = (
                    gimp_1d(origin, h, xp + step, lp, bounds),
                    gimp_1d(origin, h, xp - step, lp, bounds),
                );
                let weight_of = |g: &Gimp1d, node: usize| {
                    (0..g.count)
                        .find(|&k| g.node[k] == node)
                        .map_or(0.0, |k| g.weight[k])
                };
                for k in 0..g.count {
                    let fd = (weight_of(&gp, g.node[k]) - weight_of(&gm, g.node[k])) / (2.0 * step);
                    assert!(
                        (fd - g.gradient[k]).abs() < 1e-6,
                        "{xp}: {fd} vs {}",
                        g.gradient[k]
                    );
                }
            }
        }
        // a point 1e-12 either side of the grid line x = −0.1 has the same weights
        let (l, r) = (
            gimp_1d(origin, h, -0.1 - 1e-12, lp, bounds),
            gimp_1d(origin, h, -0.1 + 1e-12, lp, bounds),
        );
        assert_eq!(l.count, 3);
        for k in 0..3 {
            assert_eq!(l.node[k], r.node[k]);
            assert!((l.weight[k] - r.weight[k]).abs() < 1e-10);
            assert!((l.gradient[k] - r.gradient[k]).abs() < 1e-8);
        }
        // l_p = 0 is the bilinear hat: weights 0.7 / 0.3 and gradients ∓1/h
        let g = gimp_1d(origin, h, origin + 0.3 * h, 0.0, bounds);
        assert_eq!(g.count, 2);
        assert!((g.weight[0] - 0.7).abs() < 1e-14 && (g.weight[1] - 0.3).abs() < 1e-14);
        assert!((g.gradient[0] + 1.0 / h).abs() < 1e-12 && (g.gradient[1] - 1.0 / h).abs() < 1e-12);
    }
}
