//! Nodal mass, body force and internal force (theory D10–D11).

use super::bins::ParticleBins;
use super::nodal_field::NodalField;
use super::scatter::{scatter, scatter_into_field};
use crate::constitutive::Voigt;
use crate::grid::{Grid, ShapeAt, MAX_SUPPORT};

/// Lumped nodal mass m_i = Σ_p N_ip m_p (theory D10).
pub fn nodal_mass(grid: &Grid, bins: &ParticleBins, shapes: &[ShapeAt], mass: &[f64]) -> Vec<f64> {
    scatter::<1, _>(grid, bins, shapes, |p| {
        let s = &shapes[p];
        let mut c = [[0.0; 1]; MAX_SUPPORT];
        for a in s.support() {
            c[a] = [s.n[a] * mass[p]];
        }
        c
    })
    .into_iter()
    .map(|v| v[0])
    .collect()
}

/// Mass-weighted nodal sum Σ_p N_ip m_p q_p of a particle vector field (momentum
/// when `q = v`, theory D10). Divide by the nodal mass to get the nodal field.
pub fn nodal_mass_weighted(
    grid: &Grid,
    bins: &ParticleBins,
    shapes: &[ShapeAt],
    mass: &[f64],
    field: &[[f64; 2]],
) -> Vec<[f64; 2]> {
    scatter::<2, _>(grid, bins, shapes, |p| {
        let s = &shapes[p];
        let (m, q) = (mass[p], field[p]);
        let mut c = [[0.0; 2]; MAX_SUPPORT];
        for a in s.support() {
            c[a] = [s.n[a] * m * q[0], s.n[a] * m * q[1]];
        }
        c
    })
}

/// Body force f_i = Σ_p N_ip m_p b (theory D10), for a uniform acceleration `b` (m/s²).
pub fn body_force(
    grid: &Grid,
    bins: &ParticleBins,
    shapes: &[ShapeAt],
    mass: &[f64],
    b: [f64; 2],
) -> Vec<[f64; 2]> {
    let uniform = vec![b; mass.len()];
    nodal_mass_weighted(grid, bins, shapes, mass, &uniform)
}

/// Internal force f_i^int = Σ_p V_p B_ipᵀ σ_p (theory D11), kN per metre run.
pub fn internal_force(
    grid: &Grid,
    bins: &ParticleBins,
    shapes: &[ShapeAt],
    volume: &[f64],
    stress: &[Voigt],
) -> Vec<[f64; 2]> {
    let mut nodal = NodalField::default();
    internal_force_into(
        grid,
        bins,
        shapes,
        volume,
        stress,
        &mut Vec::new(),
        &mut nodal,
    );
    nodal.into_vec()
}

/// [`internal_force`] into `nodal`, with `cell_sums` as the buffer of the
/// patch sums ([`scatter_into_field`]): the same values, no allocation once
/// both buffers have grown to the run's size, and work in proportion to the
/// active nodes.
pub fn internal_force_into(
    grid: &Grid,
    bins: &ParticleBins,
    shapes: &[ShapeAt],
    volume: &[f64],
    stress: &[Voigt],
    cell_sums: &mut Vec<[f64; 2]>,
    nodal: &mut NodalField<[f64; 2]>,
) {
    let add = |p: usize, s: &ShapeAt, patch: &mut [[f64; 2]]| {
        let (v, sig) = (volume[p], &stress[p]);
        for a in s.support() {
            let [dx, dy] = s.dn[a];
            let place = s.local[a] as usize;
            patch[place][0] += v * (dx * sig[0] + dy * sig[3]);
            patch[place][1] += v * (dy * sig[1] + dx * sig[3]);
        }
    };
    scatter_into_field(grid, bins, shapes, add, cell_sums, nodal);
}
