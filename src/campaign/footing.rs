//! Footing-specific numbers of a campaign (paper Figs. 7–8, theory §8.2):
//! the soil that ends up inside the footing's outline (the footing's 3 m
//! height is not modelled, so nothing keeps soil from heaving over its base)
//! and how deep the deviatoric strain reaches under each corner (the paper's
//! "secondary vertical band below the footing corner").

use crate::scene::Scene;

/// Half-width of the strip under each corner in units of B (±0.15 B =
/// ±0.225 m for B = 1.5 m, about one coarse cell): fixed in metres, the same
/// on every mesh.
pub const CORNER_STRIP_HALF_WIDTH: f64 = 0.15;

/// Deviatoric strain εq that counts as part of a band in
/// [`corner_band_reach`]: 0.05, about 1/40 of the strain in the Prandtl
/// bands at δ = 0.3 m and 20 times the elastic strain under the footing.
pub const CORNER_BAND_STRAIN: f64 = 0.05;

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
/// penetration `delta`: Σ V_p⁰ over the points with x in the footprint and y
/// above the base y = surface − δ, V_p⁰ = m_p/ρ the point's undeformed
/// volume. The paper's footing is 3 m high, so this is soil that its sides
/// would have kept out. The undeformed volume counts the soil, not the room
/// it takes: a point softened to the apex of the yield surface carries no
/// tension and the grid stretches it freely (J = V/V⁰ up to 600 in the
/// local footing runs at δ = 0.3 m), so Σ V_p would count space between
/// torn-apart soil.
pub fn soil_inside_outline(
    footing: &FootingGeometry,
    delta: f64,
    positions: &[[f64; 2]],
    initial_volumes: &[f64],
) -> f64 {
    let base = footing.surface - delta;
    positions
        .iter()
        .zip(initial_volumes)
        .filter(|(x, _)| x[0] > footing.footprint[0] && x[0] < footing.footprint[1] && x[1] > base)
        // from +0 (`sum` starts at −0, which the report would print as −0)
        .fold(0.0, |area, (_, v)| area + v)
}

/// Reach of the deviatoric strain under each footing corner at penetration
/// `delta`: the depth below the base, in units of B, of the deepest point in
/// the strip |x − corner| ≤ [`CORNER_STRIP_HALF_WIDTH`] B with εq ≥
/// [`CORNER_BAND_STRAIN`]; `[left, right]`, 0 where no point qualifies. The
/// Prandtl mechanism alone reaches about 1.1 B under a corner (its outer
/// log-spiral; measured 1.03–1.09 B in the nonlocal runs at δ = 0.3 m); a
/// secondary band running straight down from the corner reaches deeper (local
/// runs: 1.09, 1.40 and 1.58 B at h = 0.25, 0.125 and 0.1 m).
pub fn corner_band_reach(
    footing: &FootingGeometry,
    delta: f64,
    positions: &[[f64; 2]],
    eps_q: &[f64],
) -> [f64; 2] {
    let b = footing.width();
    let base = footing.surface - delta;
    let half = CORNER_STRIP_HALF_WIDTH * b;
    let mut reach = [0.0f64; 2];
    for (x, &e) in positions.iter().zip(eps_q) {
        if x[1] >= base || e < CORNER_BAND_STRAIN {
            continue;
        }
        for (k, corner) in footing.footprint.iter().enumerate() {
            if (x[0] - corner).abs() <= half {
                reach[k] = reach[k].max((base - x[1]) / b);
            }
        }
    }
    reach
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
        let none = soil_inside_outline(&footing(), 0.0, &x, &v);
        assert!(none == 0.0 && none.is_sign_positive(), "{none}");
    }

    #[test]
    fn vertical_band_under_the_right_corner_deepens_its_reach_only() {
        // a Prandtl-like zone: strain 1 down to 1.5 m below the surface
        // across the footing's corners, elastic (0.002) below
        let mechanism = |p: [f64; 2]| if p[1] > 6.5 { 1.0 } else { 0.002 };
        let (x, _, e) = lattice(0.05, mechanism);
        let [l, r] = corner_band_reach(&footing(), 0.0, &x, &e);
        // deepest qualifying point: y = 6.525, 1.475 m = 0.9833 B deep
        assert!((l - 1.475 / 1.5).abs() < 1e-12, "{l}");
        assert_eq!(r, l);
        // a band 0.2 m wide down to y = 5 m under the right corner, faint
        // (εq = 0.06), and one just outside the strip under the left one
        let (x, _, e) = lattice(0.05, |p| {
            let right = (p[0] - 7.75).abs() < 0.1 && p[1] > 5.0;
            let outside_left = (p[0] - 5.9).abs() < 0.05 && p[1] > 4.0;
            if right || outside_left {
                0.06
            } else {
                mechanism(p)
            }
        });
        let [l2, r2] = corner_band_reach(&footing(), 0.0, &x, &e);
        assert!((r2 - 2.975 / 1.5).abs() < 1e-12, "{r2}");
        assert_eq!(l2, l);
        // measured from the base: 0.3 m of penetration shortens the reach
        let [_, r3] = corner_band_reach(&footing(), 0.3, &x, &e);
        assert!((r3 - 2.675 / 1.5).abs() < 1e-12, "{r3}");
    }
}
