//! Footing-specific numbers of a campaign (paper Figs. 7–8, DESIGN §8.2):
//! the soil that ends up inside the footing's outline (the footing's 3 m
//! height is not modelled, so nothing keeps soil from heaving over its base)
//! and the share of deviatoric strain in a vertical strip under each corner
//! (the paper's "secondary vertical band below the footing corner").

use crate::scene::Scene;

/// Depth range of the corner strip below the footing base, in units of the
/// footing width B: from 0.1 B to 0.8 B. The strip ends above the depth where
/// the main Prandtl band crosses the vertical under the corner (the outer
/// log-spiral, ≈ 1.1 B below the base for φ = 20°), so it holds only a band
/// that runs straight down from the corner.
pub const CORNER_STRIP_DEPTH: (f64, f64) = (0.1, 0.8);

/// Half-width of the corner strip in units of B (±0.15 B = ±0.225 m for
/// B = 1.5 m, about one coarse cell): fixed in metres, the same on every mesh.
pub const CORNER_STRIP_HALF_WIDTH: f64 = 0.15;

/// Where the footing is: its footprint and the initial soil surface under it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FootingGeometry {
    /// Left and right edges of the footprint, m.
    pub footprint: [f64; 2],
    /// Initial height of the soil surface (top of the bodies), m.
    pub surface: f64,
}

impl FootingGeometry {
    /// The first rigid body of `scene` over the top of its bodies.
    pub fn of_scene(scene: &Scene) -> Option<Self> {
        let rigid = scene.bc.rigid.first()?;
        let surface = scene
            .body
            .iter()
            .flat_map(|b| b.outline())
            .map(|corner| corner[1])
            .fold(f64::NEG_INFINITY, f64::max);
        surface.is_finite().then_some(Self {
            footprint: rigid.footprint,
            surface,
        })
    }

    /// Footing width B, m.
    pub fn width(&self) -> f64 {
        self.footprint[1] - self.footprint[0]
    }
}

/// Soil area (m² per m) inside the footing's outline above its base at
/// penetration `delta`: Σ V_p over the points with x in the footprint and y
/// above the base y = surface − δ. The paper's footing is 3 m high, so this
/// is soil that its sides would have kept out.
pub fn soil_inside_outline(
    footing: &FootingGeometry,
    delta: f64,
    positions: &[[f64; 2]],
    volumes: &[f64],
) -> f64 {
    let base = footing.surface - delta;
    positions
        .iter()
        .zip(volumes)
        .filter(|(x, _)| x[0] > footing.footprint[0] && x[0] < footing.footprint[1] && x[1] > base)
        .map(|(_, v)| v)
        .sum()
}

/// Share of the deviatoric strain Σ V_p εq_p that lies in the strip under
/// each footing corner (`CORNER_STRIP_DEPTH`, `CORNER_STRIP_HALF_WIDTH`),
/// at penetration `delta`: `[left, right]`. A secondary vertical band under a
/// corner raises its share; a Prandtl mechanism alone crosses the strip only
/// with its fan near the corner.
pub fn corner_band_share(
    footing: &FootingGeometry,
    delta: f64,
    positions: &[[f64; 2]],
    volumes: &[f64],
    eps_q: &[f64],
) -> [f64; 2] {
    let b = footing.width();
    let base = footing.surface - delta;
    let (top, bottom) = (
        base - CORNER_STRIP_DEPTH.0 * b,
        base - CORNER_STRIP_DEPTH.1 * b,
    );
    let half = CORNER_STRIP_HALF_WIDTH * b;
    let mut total = 0.0;
    let mut strips = [0.0; 2];
    for ((x, v), e) in positions.iter().zip(volumes).zip(eps_q) {
        let w = v * e;
        total += w;
        if x[1] <= top && x[1] >= bottom {
            for (k, corner) in footing.footprint.iter().enumerate() {
                if (x[0] - corner).abs() <= half {
                    strips[k] += w;
                }
            }
        }
    }
    if total > 0.0 {
        strips.map(|s| s / total)
    } else {
        [0.0; 2]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn footing() -> FootingGeometry {
        FootingGeometry {
            footprint: [6.25, 7.75],
            surface: 8.0,
        }
    }

    /// Points on a regular lattice of spacing `s` over the soil, unit strain.
    fn lattice(s: f64, strain: impl Fn([f64; 2]) -> f64) -> (Vec<[f64; 2]>, Vec<f64>, Vec<f64>) {
        let (nx, ny) = ((14.0 / s) as usize, (8.0 / s) as usize);
        let mut x = Vec::new();
        for j in 0..ny {
            for i in 0..nx {
                x.push([(i as f64 + 0.5) * s, (j as f64 + 0.5) * s]);
            }
        }
        let e = x.iter().map(|p| strain(*p)).collect();
        (x.clone(), vec![s * s; x.len()], e)
    }

    #[test]
    fn heaved_soil_over_the_base_is_counted_inside_the_footprint_only() {
        // a 0.5 m x 0.2 m block of soil over the base at delta = 0.3 m, inside
        // the footprint, and the same block beside it
        let s = 0.05;
        let mut x = Vec::new();
        for j in 0..4 {
            for i in 0..10 {
                let p = [6.3 + (i as f64 + 0.5) * s, 7.7 + (j as f64 + 0.5) * s];
                x.push(p);
                x.push([p[0] + 3.0, p[1]]);
            }
        }
        let v = vec![s * s; x.len()];
        let area = soil_inside_outline(&footing(), 0.3, &x, &v);
        assert!((area - 0.1).abs() < 1e-12, "{area}");
        assert_eq!(soil_inside_outline(&footing(), 0.0, &x, &v), 0.0);
    }

    #[test]
    fn vertical_band_under_the_right_corner_raises_its_share_only() {
        let uniform = lattice(0.05, |_| 1.0);
        let [l, r] = corner_band_share(&footing(), 0.0, &uniform.0, &uniform.1, &uniform.2);
        // strip area 0.45 m x 1.05 m over 14 m x 8 m of unit strain
        let expected = 0.45 * 1.05 / 112.0;
        assert!((l - expected).abs() < 0.05 * expected, "{l} vs {expected}");
        assert!((r - l).abs() < 1e-12);
        let band = lattice(0.05, |p| {
            if (p[0] - 7.75).abs() < 0.1 && p[1] > 6.0 && p[1] < 8.0 {
                20.0
            } else {
                1.0
            }
        });
        let [l2, r2] = corner_band_share(&footing(), 0.0, &band.0, &band.1, &band.2);
        assert!(r2 > 5.0 * r, "band share {r2} vs uniform {r}");
        assert!(
            l2 < l,
            "left share {l2} must fall as strain concentrates right"
        );
    }
}
