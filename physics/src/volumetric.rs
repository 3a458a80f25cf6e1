//! The volumetric locking remedy: B-bar on the cell (`[grid] volumetric =
//! "b_bar"`), for both integrators.
//!
//! With 2 × 2 material points per cell the volumetric strain is constrained
//! at every point, as in a fully integrated 4-node element, and a nearly
//! incompressible material (ν → ½, or isochoric plastic flow) locks: the
//! displacements come out far too small and limit loads overshoot. B-bar
//! (Hughes, 1980) replaces each point's dilatation by the volume average over
//! the points of its cell, which leaves one volumetric constraint per cell
//! (the 4-node element with a constant pressure, Q1/P0).
//!
//! The dilatation is the three-dimensional one: in plane strain Δε_zz = 0 at
//! every point, but the averaged strain carries the volumetric correction in
//! its zz component too. With θ_p = Δε_xx + Δε_yy (+ Δε_zz = 0) at point p,
//! m = [1, 1, 1, 0] and V_c = Σ_{q∈c} V_q over the points q of p's cell c:
//!
//! ```text
//!   θ̄_c  = Σ_{q∈c} V_q θ_q / V_c                                   \[B1\]
//!   Δε̄_p = Δε_p + ⅓ (θ̄_c − θ_p) m                                  \[B2\]
//!   B̄_p  = B_p + ⅓ m ⊗ (b̄_c − b_p),  b̄_c = Σ_{q∈c} V_q b_q / V_c     \[B3\]
//! ```
//!
//! where b_p is the row of nodal dofs giving θ_p (b_p,(a,x) = ∂N_a/∂x,
//! b_p,(a,y) = ∂N_a/∂y). The internal force Σ_p V_p B̄_pᵀ σ_p equals the
//! standard force Σ_p V_p B_pᵀ σ̄_p of stresses whose mean part is the cell's
//! volume average,
//!
//! ```text
//!   σ̄_p = σ_p + (s̄_c − s_p) m,  s_p = tr σ_p / 3,  s̄_c = Σ_{q∈c} V_q s_q / V_c   \[B4\]
//! ```
//!
//! (sum \[B3\] over the cell), so the one internal-force kernel of
//! [`crate::transfer::internal_force`] serves both treatments. The consistent
//! tangent is Σ_p V_p B̄_pᵀ D_alg B̄_p (plus the spin term with B̄ on the
//! left); B̄_p spans the whole node patch of the cell, so with GIMP every
//! pair of patch nodes is coupled.
//!
//! The cell of a point is the cell that holds it ([`ShapeAt::cell`]); cells
//! are the active cells of [`ParticleBins`].

use rayon::prelude::*;

use crate::constitutive::{Mat4, Voigt};
use crate::grid::ShapeAt;
use crate::transfer::ParticleBins;

/// The dilatation θ = Δε_xx + Δε_yy of a displacement-increment gradient
/// `[L11, L12, L21, L22]` (plane strain: Δε_zz = 0).
#[inline]
fn dilatation(gradient: &[f64; 4]) -> f64 {
    gradient[0] + gradient[3]
}

/// ⅓ (θ̄_c − θ_p) for every point p (\[B1\]–\[B2\]): the amount added to the
/// xx, yy and zz components of its strain increment.
pub fn dilatation_corrections(
    bins: &ParticleBins,
    volume: &[f64],
    gradient: &[[f64; 4]],
) -> Vec<f64> {
    let theta: Vec<f64> = gradient.iter().map(dilatation).collect();
    let mut correction = vec![0.0; volume.len()];
    for (c, theta_bar) in cell_averages(bins, volume, &theta) {
        for &p in bins.particles_in(c) {
            let p = p as usize;
            correction[p] = (theta_bar - theta[p]) / 3.0;
        }
    }
    correction
}

/// The strain increment \[B2\]: `strain` with ⅓ (θ̄_c − θ_p) = `correction`
/// added to its normal components.
#[inline]
pub fn corrected_strain(strain: &Voigt, correction: f64) -> Voigt {
    [
        strain[0] + correction,
        strain[1] + correction,
        strain[2] + correction,
        strain[3],
    ]
}

/// The stresses whose standard internal force is the B-bar internal force
/// (\[B4\]): each point's mean stress replaced by its cell's volume average.
pub fn force_stresses(bins: &ParticleBins, volume: &[f64], stress: &[Voigt]) -> Vec<Voigt> {
    let mean: Vec<f64> = stress.iter().map(|s| (s[0] + s[1] + s[2]) / 3.0).collect();
    let mut out = stress.to_vec();
    for (c, mean_bar) in cell_averages(bins, volume, &mean) {
        for &p in bins.particles_in(c) {
            let p = p as usize;
            let shift = mean_bar - mean[p];
            for k in 0..3 {
                out[p][k] += shift;
            }
        }
    }
    out
}

/// Volume average of `value` over the points of every active cell:
/// `(cell, Σ V_q value_q / Σ V_q)`.
fn cell_averages<'a>(
    bins: &'a ParticleBins,
    volume: &'a [f64],
    value: &'a [f64],
) -> impl Iterator<Item = (usize, f64)> + 'a {
    bins.active_cells.iter().map(move |&c| {
        let c = c as usize;
        let (mut sum, mut v) = (0.0, 0.0);
        for &p in bins.particles_in(c) {
            let p = p as usize;
            sum += volume[p] * value[p];
            v += volume[p];
        }
        (c, if v > 0.0 { sum / v } else { 0.0 })
    })
}

/// b̄_c of \[B3\] for every active cell (in the order of
/// `bins.active_cells`): the volume-averaged gradient row of the dilatation
/// over the cell's node patch, `[∂x, ∂y]` per patch place.
#[derive(Clone, Debug, Default)]
pub struct CellMeanGradients {
    /// Patch places per cell (`side²`).
    places: usize,
    /// `gradients[slot * places + place]`.
    gradients: Vec<[f64; 2]>,
}

impl CellMeanGradients {
    /// b̄_c for the points binned in `bins`, with `places` nodes per patch.
    pub fn new(bins: &ParticleBins, shapes: &[ShapeAt], volume: &[f64], places: usize) -> Self {
        let mut gradients = vec![[0.0; 2]; places * bins.active_cells.len()];
        gradients
            .par_chunks_mut(places)
            .zip(&bins.active_cells)
            .for_each(|(mean, &c)| {
                let mut v_cell = 0.0;
                for &p in bins.particles_in(c as usize) {
                    let (s, v) = (&shapes[p as usize], volume[p as usize]);
                    v_cell += v;
                    for a in s.support() {
                        let place = s.local[a] as usize;
                        mean[place][0] += v * s.dn[a][0];
                        mean[place][1] += v * s.dn[a][1];
                    }
                }
                if v_cell > 0.0 {
                    for g in mean.iter_mut() {
                        g[0] /= v_cell;
                        g[1] /= v_cell;
                    }
                }
            });
        Self { places, gradients }
    }

    /// b̄ of the active cell in `slot`.
    pub fn of_slot(&self, slot: usize) -> &[[f64; 2]] {
        &self.gradients[slot * self.places..(slot + 1) * self.places]
    }
}

/// B̄_p of \[B3\] as a dense 4 × `2·places` matrix over the cell's patch dofs
/// (dof `2·place + direction`), row-major in `out` (resized).
pub fn b_bar_matrix(shape: &ShapeAt, mean_gradient: &[[f64; 2]], out: &mut Vec<f64>) {
    let dofs = 2 * mean_gradient.len();
    out.clear();
    out.resize(4 * dofs, 0.0);
    // ⅓ m ⊗ b̄: rows xx, yy, zz
    for (place, g) in mean_gradient.iter().enumerate() {
        for r in 0..3 {
            out[r * dofs + 2 * place] += g[0] / 3.0;
            out[r * dofs + 2 * place + 1] += g[1] / 3.0;
        }
    }
    for a in shape.support() {
        let [dx, dy] = shape.dn[a];
        let (x, y) = (2 * shape.local[a] as usize, 2 * shape.local[a] as usize + 1);
        // B_p − ⅓ m ⊗ b_p
        out[x] += dx - dx / 3.0;
        out[y] -= dy / 3.0;
        out[dofs + x] -= dx / 3.0;
        out[dofs + y] += dy - dy / 3.0;
        out[2 * dofs + x] -= dx / 3.0;
        out[2 * dofs + y] -= dy / 3.0;
        out[3 * dofs + x] += dy;
        out[3 * dofs + y] += dx;
    }
}

/// V_p B̄_pᵀ D B̄_p (and, with `spin_sensitivity` s, the spin term
/// V_p B̄_pᵀ s w_bᵀ of [`crate::stiffness::add_spin_stiffness`]) added to a
/// patch block of `dofs` = 2 × places (row-major). `b_bar` is
/// [`b_bar_matrix`]'s output.
pub fn add_particle_stiffness_b_bar(
    block: &mut [f64],
    shape: &ShapeAt,
    b_bar: &[f64],
    volume: f64,
    tangent: &Mat4,
    spin_sensitivity: Option<&Voigt>,
) {
    let dofs = b_bar.len() / 4;
    // D B̄ (4 × dofs)
    let mut db = vec![0.0; 4 * dofs];
    for r in 0..4 {
        for k in 0..4 {
            let d = tangent[r][k];
            if d != 0.0 {
                for j in 0..dofs {
                    db[r * dofs + j] += d * b_bar[k * dofs + j];
                }
            }
        }
    }
    for i in 0..dofs {
        let column = [
            b_bar[i],
            b_bar[dofs + i],
            b_bar[2 * dofs + i],
            b_bar[3 * dofs + i],
        ];
        if column.iter().all(|&v| v == 0.0) {
            continue;
        }
        let row = &mut block[i * dofs..(i + 1) * dofs];
        for (j, out) in row.iter_mut().enumerate() {
            let k: f64 = (0..4).map(|r| column[r] * db[r * dofs + j]).sum();
            *out += volume * k;
        }
        if let Some(s) = spin_sensitivity {
            let bs: f64 = (0..4).map(|r| column[r] * s[r]).sum();
            for b in shape.support() {
                let [dxb, dyb] = shape.dn[b];
                let col = 2 * shape.local[b] as usize;
                row[col] += volume * bs * 0.5 * dyb;
                row[col + 1] -= volume * bs * 0.5 * dxb;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::constitutive::{mat4_mul_vec, LinearElastic};
    use crate::stiffness::cell_stiffness_blocks;
    use crate::stiffness::tests::blocks_times;
    use crate::transfer::tests::{kinds, setup};
    use crate::transfer::{gradient, internal_force, shapes_at, strain_and_spin};

    fn nodal_field(n: usize) -> Vec<[f64; 2]> {
        (0..n)
            .map(|k| {
                [
                    (0.37 * k as f64).sin() * 0.01,
                    (0.91 * k as f64).cos() * 0.02,
                ]
            })
            .collect()
    }

    /// B̄_p u equals the averaged strain \[B2\] of the point's own gradient,
    /// for arbitrary nodal values: checks \[B3\] against \[B1\]–\[B2\].
    #[test]
    fn b_bar_matrix_gives_the_averaged_strain() {
        for kind in kinds() {
            let (grid, pos, vol, _) = setup(kind);
            let shapes = shapes_at(&grid, &pos).unwrap();
            let bins = ParticleBins::new(&grid, &shapes);
            let u = nodal_field(grid.node_count());
            let l: Vec<[f64; 4]> = shapes.iter().map(|s| gradient(s, &u)).collect();
            let corr = dilatation_corrections(&bins, &vol, &l);
            let side = grid.patch_side();
            let means = CellMeanGradients::new(&bins, &shapes, &vol, side * side);
            let mut b = Vec::new();
            for (p, s) in shapes.iter().enumerate() {
                let slot = bins.cell_slot[s.cell as usize] as usize;
                b_bar_matrix(s, means.of_slot(slot), &mut b);
                let (ci, cj) = grid.cell_ij(s.cell as usize);
                let nodes = grid.patch_nodes(ci, cj);
                let dofs = 2 * nodes.len();
                let mut strain = [0.0; 4];
                for (place, node) in nodes.iter().enumerate() {
                    let Some(node) = node else { continue };
                    for r in 0..4 {
                        for d in 0..2 {
                            strain[r] += b[r * dofs + 2 * place + d] * u[*node as usize][d];
                        }
                    }
                }
                let expected = corrected_strain(&strain_and_spin(&l[p]).0, corr[p]);
                for r in 0..4 {
                    assert!(
                        (strain[r] - expected[r]).abs() < 1e-14,
                        "{kind:?} p {p} r {r}"
                    );
                }
            }
        }
    }

    /// The averaged strain of every point of a cell has the cell's mean
    /// dilatation, and the volume-weighted sum of the corrections vanishes.
    #[test]
    fn corrections_average_the_dilatation_per_cell() {
        for kind in kinds() {
            let (grid, pos, vol, _) = setup(kind);
            let shapes = shapes_at(&grid, &pos).unwrap();
            let bins = ParticleBins::new(&grid, &shapes);
            let u = nodal_field(grid.node_count());
            let l: Vec<[f64; 4]> = shapes.iter().map(|s| gradient(s, &u)).collect();
            let corr = dilatation_corrections(&bins, &vol, &l);
            for &c in &bins.active_cells {
                let points = bins.particles_in(c as usize);
                let trace = |p: usize| {
                    let e = corrected_strain(&strain_and_spin(&l[p]).0, corr[p]);
                    e[0] + e[1] + e[2]
                };
                let first = trace(points[0] as usize);
                let weighted: f64 = points
                    .iter()
                    .map(|&p| vol[p as usize] * corr[p as usize])
                    .sum();
                let size: f64 = points
                    .iter()
                    .map(|&p| (vol[p as usize] * corr[p as usize]).abs())
                    .sum();
                for &p in points {
                    assert!((trace(p as usize) - first).abs() < 1e-15);
                }
                assert!(weighted.abs() <= 1e-14 * size, "{weighted} of {size}");
            }
        }
    }

    /// Σ_p V_p B̄_pᵀ σ_p (dense B̄) equals the standard force of the
    /// averaged-mean stresses \[B4\].
    #[test]
    fn force_of_averaged_mean_stress_is_the_b_bar_force() {
        for kind in kinds() {
            let (grid, pos, vol, _) = setup(kind);
            let shapes = shapes_at(&grid, &pos).unwrap();
            let bins = ParticleBins::new(&grid, &shapes);
            let stress: Vec<Voigt> = (0..pos.len())
                .map(|p| {
                    let x = p as f64;
                    [
                        (0.3 * x).sin(),
                        (0.7 * x).cos(),
                        0.5 * (1.1 * x).sin(),
                        0.2 * x.cos(),
                    ]
                })
                .collect();
            let f = internal_force(
                &grid,
                &bins,
                &shapes,
                &vol,
                &force_stresses(&bins, &vol, &stress),
            );
            let side = grid.patch_side();
            let means = CellMeanGradients::new(&bins, &shapes, &vol, side * side);
            let mut dense = vec![[0.0; 2]; grid.node_count()];
            let mut b = Vec::new();
            for (p, s) in shapes.iter().enumerate() {
                let slot = bins.cell_slot[s.cell as usize] as usize;
                b_bar_matrix(s, means.of_slot(slot), &mut b);
                let (ci, cj) = grid.cell_ij(s.cell as usize);
                let nodes = grid.patch_nodes(ci, cj);
                let dofs = 2 * nodes.len();
                for (place, node) in nodes.iter().enumerate() {
                    let Some(node) = node else { continue };
                    for d in 0..2 {
                        let bt_sigma: f64 = (0..4)
                            .map(|r| b[r * dofs + 2 * place + d] * stress[p][r])
                            .sum();
                        dense[*node as usize][d] += vol[p] * bt_sigma;
                    }
                }
            }
            let scale = f
                .iter()
                .fold(0.0f64, |m, v| m.max(v[0].abs()).max(v[1].abs()));
            for (a, b) in f.iter().zip(&dense) {
                for d in 0..2 {
                    assert!((a[d] - b[d]).abs() < 1e-13 * scale, "{kind:?}");
                }
            }
        }
    }

    /// The B-bar patch block times nodal displacements is the B-bar force of
    /// the stresses D Δε̄ those displacements produce (K u = f_int(u)).
    #[test]
    fn b_bar_stiffness_matches_b_bar_force() {
        for kind in kinds() {
            let (grid, pos, vol, _) = setup(kind);
            let shapes = shapes_at(&grid, &pos).unwrap();
            let bins = ParticleBins::new(&grid, &shapes);
            let d = LinearElastic::new(500.0, 0.45).stiffness();
            let u = nodal_field(grid.node_count());
            let l: Vec<[f64; 4]> = shapes.iter().map(|s| gradient(s, &u)).collect();
            let corr = dilatation_corrections(&bins, &vol, &l);
            let stress: Vec<Voigt> = (0..pos.len())
                .map(|p| mat4_mul_vec(&d, &corrected_strain(&strain_and_spin(&l[p]).0, corr[p])))
                .collect();
            let f = internal_force(
                &grid,
                &bins,
                &shapes,
                &vol,
                &force_stresses(&bins, &vol, &stress),
            );
            let side = grid.patch_side();
            let means = CellMeanGradients::new(&bins, &shapes, &vol, side * side);
            // the production assembly of the B-bar blocks (B3)
            let tangents = vec![d; pos.len()];
            let blocks =
                cell_stiffness_blocks(&grid, &bins, &shapes, &vol, &tangents, None, Some(&means));
            let ku = blocks_times(&grid, &bins.active_cells, &blocks, &u);
            let scale = f
                .iter()
                .fold(0.0f64, |m, v| m.max(v[0].abs()).max(v[1].abs()));
            for (a, b) in ku.iter().zip(&f) {
                for r in 0..2 {
                    assert!(
                        (a[r] - b[r]).abs() < 1e-12 * scale,
                        "{kind:?}: {} vs {}",
                        a[r],
                        b[r]
                    );
                }
            }
        }
    }
}
