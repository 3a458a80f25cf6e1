//! Tangent stiffness blocks of the implicit system (theory §3, D17, D19):
//! per material point V_p B_pᵀ D B_p, summed per active cell into node-patch
//! blocks, plus the background stiffness of reached cells and the spin term
//! of the Jaumann rotation. The P2G/G2P kernels they share with the explicit
//! path stay in [`crate::transfer`].

use rayon::prelude::*;

use crate::constitutive::{Mat4, Voigt};
use crate::grid::{Grid, ShapeAt, MAX_SUPPORT};
use crate::transfer::ParticleBins;
use crate::volumetric::{self, CellMeanGradients};

/// Stiffness contribution V_p B_pᵀ D B_p of one particle to its cell's patch
/// block (row-major, `dofs` = 2 × patch nodes, dof `2·place + direction`),
/// accumulated into `block` (theory §3).
#[inline]
pub fn add_particle_stiffness(
    block: &mut [f64],
    dofs: usize,
    shape: &ShapeAt,
    volume: f64,
    tangent: &Mat4,
) {
    // DB_b (4×2) for every node b of the support
    let mut db = [[[0.0; 2]; 4]; MAX_SUPPORT];
    for b in shape.support() {
        let [dx, dy] = shape.dn[b];
        for r in 0..4 {
            db[b][r] = [
                tangent[r][0] * dx + tangent[r][3] * dy,
                tangent[r][1] * dy + tangent[r][3] * dx,
            ];
        }
    }
    for a in shape.support() {
        let [dx, dy] = shape.dn[a];
        let row = 2 * shape.local[a] as usize;
        for b in shape.support() {
            let col = 2 * shape.local[b] as usize;
            for c in 0..2 {
                // rows of B_aᵀ: x-row = [dx, 0, 0, dy], y-row = [0, dy, 0, dx]
                let kx = dx * db[b][0][c] + dy * db[b][3][c];
                let ky = dy * db[b][1][c] + dx * db[b][3][c];
                block[row * dofs + col + c] += volume * kx;
                block[(row + 1) * dofs + col + c] += volume * ky;
            }
        }
    }
}

/// Number of dofs of a cell's patch block (2 × patch nodes).
pub fn patch_dofs(grid: &Grid) -> usize {
    2 * grid.patch_side() * grid.patch_side()
}

/// Which local dofs of a system element can be coupled (for
/// `Assembler::with_couplings`): in a GIMP cell patch (4 × 4 nodes) a point
/// reaches at most 3 consecutive nodes per direction, so nodes three apart
/// never share a point and their block entries are zero; dropping them halves
/// the pattern. Every other element is fully coupled, and so is every patch
/// with B-bar (`b_bar`: B̄ spans the whole patch, [`crate::volumetric`]).
pub fn patch_coupling(grid: &Grid, b_bar: bool) -> impl Fn(usize, usize, usize) -> bool {
    let side = grid.patch_side();
    let dofs = patch_dofs(grid);
    move |element_dofs, a, b| {
        if element_dofs != dofs || side < 4 || b_bar {
            return true;
        }
        let (pa, pb) = (a / 2, b / 2);
        (pa % side).abs_diff(pb % side) <= 2 && (pa / side).abs_diff(pb / side) <= 2
    }
}

/// Per-active-cell patch stiffness blocks Σ_{p ∈ cell} V_p B_pᵀ D_p B_p, in the
/// order of `bins.active_cells` (deterministic: particles summed in index
/// order); with `b_bar` (the cells' b̄), Σ_p V_p B̄_pᵀ D_p B̄_p
/// ([`crate::volumetric`] B3).
pub fn cell_stiffness_blocks(
    grid: &Grid,
    bins: &ParticleBins,
    shapes: &[ShapeAt],
    volume: &[f64],
    tangent: &[Mat4],
    spin_sensitivity: Option<&[Voigt]>,
    b_bar: Option<&CellMeanGradients>,
) -> Vec<Vec<f64>> {
    let mut blocks = Vec::new();
    let points = PointStiffness {
        shapes,
        volume,
        tangent,
        spin_sensitivity,
        b_bar,
    };
    cell_stiffness_blocks_into(grid, bins, &points, &mut blocks);
    let size = patch_dofs(grid).pow(2);
    blocks.chunks(size).map(<[f64]>::to_vec).collect()
}

/// What the stiffness of the material points is formed from
/// ([`cell_stiffness_blocks`]).
pub struct PointStiffness<'a> {
    /// N_ip, ∇N_ip of every point.
    pub shapes: &'a [ShapeAt],
    /// V_p.
    pub volume: &'a [f64],
    /// D_p (the algorithmic tangents).
    pub tangent: &'a [Mat4],
    /// dσ/dω per point, for the spin term (unsymmetric tangents).
    pub spin_sensitivity: Option<&'a [Voigt]>,
    /// The cells' b̄ (B-bar).
    pub b_bar: Option<&'a CellMeanGradients>,
}

/// [`cell_stiffness_blocks`] into one flat array `blocks`: `dofs²` values a
/// block, one block per active cell in the order of `bins.active_cells`,
/// each zeroed and summed by the task that forms it. The same values; no
/// allocation once `blocks` has grown (GIMP: 8 KB a cell).
pub fn cell_stiffness_blocks_into(
    grid: &Grid,
    bins: &ParticleBins,
    points: &PointStiffness,
    blocks: &mut Vec<f64>,
) {
    let dofs = patch_dofs(grid);
    let PointStiffness {
        shapes,
        volume,
        tangent,
        spin_sensitivity,
        b_bar,
    } = *points;
    blocks.resize(bins.active_cells.len() * dofs * dofs, 0.0);
    blocks
        .par_chunks_mut(dofs * dofs)
        .zip(bins.active_cells.par_iter())
        .enumerate()
        .for_each_init(Vec::new, |b_bar_p, (slot, (block, &c))| {
            block.fill(0.0);
            for &p in bins.particles_in(c as usize) {
                let p = p as usize;
                let spin = spin_sensitivity.map(|s| &s[p]);
                if let Some(means) = b_bar {
                    volumetric::b_bar_matrix(&shapes[p], means.of_slot(slot), b_bar_p);
                    volumetric::add_particle_stiffness_b_bar(
                        block,
                        &shapes[p],
                        b_bar_p,
                        volume[p],
                        &tangent[p],
                        spin,
                    );
                    continue;
                }
                add_particle_stiffness(block, dofs, &shapes[p], volume[p], &tangent[p]);
                if let Some(s) = spin {
                    add_spin_stiffness(block, dofs, &shapes[p], volume[p], s);
                }
            }
        });
}

/// The elements of the linear system: every active cell's patch block (with
/// `cell_block` added on the cell's own 2 × 2 nodes), then, for GIMP, one
/// 8-dof element per reached cell carrying `cell_block` alone. `cell_block`
/// is an 8×8 block over the cell's nodes in row-major order (lower-left,
/// lower-right, upper-left, upper-right), e.g. the background stiffness of
/// theory D19; `None` adds nothing. Matches `DofMap::element_dofs`.
pub fn system_blocks(
    grid: &Grid,
    bins: &ParticleBins,
    mut patch_blocks: Vec<Vec<f64>>,
    cell_block: Option<&[f64; 64]>,
) -> Vec<Vec<f64>> {
    if let Some(extra) = cell_block {
        for block in patch_blocks.iter_mut() {
            add_own_cell_block(grid, block, extra);
        }
    }
    let reached = cell_block.copied().unwrap_or([0.0; 64]).to_vec();
    patch_blocks.extend(bins.reached_cells.iter().map(|_| reached.clone()));
    patch_blocks
}

/// Add the 8×8 `cell_block` (over the cell's nodes in row-major order) on
/// a cell's own 2 × 2 nodes of its patch block `block` ([`system_blocks`]).
pub fn add_own_cell_block(grid: &Grid, block: &mut [f64], cell_block: &[f64; 64]) {
    let dofs = patch_dofs(grid);
    let side = grid.patch_side();
    let own = side / 2 - 1;
    let dof_of = |k: usize| {
        let (node, dir) = (k / 2, k % 2);
        2 * ((node / 2 + own) * side + node % 2 + own) + dir
    };
    for r in 0..8 {
        for c in 0..8 {
            block[dof_of(r) * dofs + dof_of(c)] += cell_block[8 * r + c];
        }
    }
}

/// Force `cell_block · Δu` of the GIMP-reached cells' elements (see
/// [`system_blocks`]), added into `force`. The background stiffness of theory
/// D19 enters the tangent only; on a reached cell it is kept consistent by
/// this residual term: a node that a point's domain barely overlaps has a
/// true stiffness of order (overlap/h)², far below ε_bg E, and a tangent-only
/// term there would make Newton converge linearly. The term resists only the
/// step's increment of those nodes, 1e-6 of an elastic cell.
pub fn add_reached_cells_force(
    grid: &Grid,
    bins: &ParticleBins,
    cell_block: &[f64; 64],
    du: &[[f64; 2]],
    force: &mut [[f64; 2]],
) {
    for &c in &bins.reached_cells {
        let (ci, cj) = grid.cell_ij(c as usize);
        let nodes = grid.cell_nodes_row_major(ci, cj).map(|n| n as usize);
        for (a, &na) in nodes.iter().enumerate() {
            for r in 0..2 {
                let row = &cell_block[8 * (2 * a + r)..8 * (2 * a + r + 1)];
                force[na][r] += nodes
                    .iter()
                    .enumerate()
                    .map(|(b, &nb)| row[2 * b] * du[nb][0] + row[2 * b + 1] * du[nb][1])
                    .sum::<f64>();
            }
        }
    }
}

/// The linearisation of the stress rotation (theory D13, [`crate::transfer::rotate_stress`])
/// through the stress update: σ_{n+1} depends on the spin ω = ½ Σ_b (u_bx ∂yN_b − u_by ∂xN_b)
/// via σ^R, with dσ_{n+1}/dω = D_alg C g, g = dσ^R/dω
/// ([`crate::transfer::rotate_stress_derivative`]; `[2σxy, −2σxy, 0, σyy − σxx]` at ω = 0)
/// (`spin_sensitivity`). Adds V_p B_aᵀ (D_alg C g) w_bᵀ, w_b = ½[∂yN_b, −∂xN_b],
/// to the patch block: an unsymmetric term that makes the tangent consistent
/// for prestressed, rotating material.
#[inline]
pub fn add_spin_stiffness(
    block: &mut [f64],
    dofs: usize,
    shape: &ShapeAt,
    volume: f64,
    spin_sensitivity: &Voigt,
) {
    let s = spin_sensitivity;
    for a in shape.support() {
        let [dxa, dya] = shape.dn[a];
        let bx = dxa * s[0] + dya * s[3];
        let by = dya * s[1] + dxa * s[3];
        let row = 2 * shape.local[a] as usize;
        for b in shape.support() {
            let [dxb, dyb] = shape.dn[b];
            let col = 2 * shape.local[b] as usize;
            let (wx, wy) = (0.5 * dyb, -0.5 * dxb);
            block[row * dofs + col] += volume * bx * wx;
            block[row * dofs + col + 1] += volume * bx * wy;
            block[(row + 1) * dofs + col] += volume * by * wx;
            block[(row + 1) * dofs + col + 1] += volume * by * wy;
        }
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// Σ over the active `cells` of each patch block times the nodal
    /// displacements `u` of its patch: the assembled K u, per node.
    pub(crate) fn blocks_times(
        grid: &Grid,
        cells: &[u32],
        blocks: &[Vec<f64>],
        u: &[[f64; 2]],
    ) -> Vec<[f64; 2]> {
        let dofs = patch_dofs(grid);
        let mut ku = vec![[0.0; 2]; grid.node_count()];
        for (block, &c) in blocks.iter().zip(cells) {
            let (ci, cj) = grid.cell_ij(c as usize);
            let nodes = grid.patch_nodes(ci, cj);
            for (ra, node_a) in nodes.iter().enumerate() {
                for (rb, node_b) in nodes.iter().enumerate() {
                    let (Some(na), Some(nb)) = (node_a, node_b) else {
                        continue;
                    };
                    for r in 0..2 {
                        for e in 0..2 {
                            ku[*na as usize][r] +=
                                block[(2 * ra + r) * dofs + 2 * rb + e] * u[*nb as usize][e];
                        }
                    }
                }
            }
        }
        ku
    }
    use crate::transfer::tests::{kinds, setup};
    use crate::transfer::{gradient, internal_force, shapes_at, strain_and_spin};

    /// The internal force of a uniform stress sums to zero over the grid
    /// (Σ_i ∇N_i = 0) and the patch stiffness blocks are symmetric for symmetric D.
    #[test]
    fn internal_force_and_stiffness_consistency() {
        for kind in kinds() {
            let (grid, pos, mass, _) = setup(kind);
            let shapes = shapes_at(&grid, &pos).unwrap();
            let bins = ParticleBins::new(&grid, &shapes);
            let stress = vec![[-3.0, 5.0, 1.0, 2.0]; pos.len()];
            let f = internal_force(&grid, &bins, &shapes, &mass, &stress);
            let (fx, fy) = f
                .iter()
                .fold((0.0, 0.0), |acc, v| (acc.0 + v[0], acc.1 + v[1]));
            assert!(fx.abs() < 1e-12 && fy.abs() < 1e-12, "{kind:?}");
            let d = crate::constitutive::LinearElastic::new(1000.0, 0.3).stiffness();
            let dofs = patch_dofs(&grid);
            let blocks = cell_stiffness_blocks(
                &grid,
                &bins,
                &shapes,
                &mass,
                &vec![d; pos.len()],
                None,
                None,
            );
            for b in &blocks {
                let scale = b.iter().fold(1.0f64, |m, v| m.max(v.abs()));
                for i in 0..dofs {
                    for j in 0..dofs {
                        assert!((b[i * dofs + j] - b[j * dofs + i]).abs() < 1e-12 * scale);
                    }
                }
            }
        }
    }

    /// The patch blocks times arbitrary nodal displacements equal the internal
    /// force of the stress D·Δε those displacements produce (K u = f_int(u),
    /// linear elasticity): checks every point's patch places.
    #[test]
    fn stiffness_blocks_match_internal_force() {
        for kind in kinds() {
            let (grid, pos, vol, _) = setup(kind);
            let shapes = shapes_at(&grid, &pos).unwrap();
            let bins = ParticleBins::new(&grid, &shapes);
            let d = crate::constitutive::LinearElastic::new(500.0, 0.25).stiffness();
            let u: Vec<[f64; 2]> = (0..grid.node_count())
                .map(|k| {
                    [
                        (0.37 * k as f64).sin() * 0.01,
                        (0.91 * k as f64).cos() * 0.02,
                    ]
                })
                .collect();
            let stress: Vec<Voigt> = shapes
                .iter()
                .map(|s| {
                    let (eps, _) = strain_and_spin(&gradient(s, &u));
                    crate::constitutive::mat4_mul_vec(&d, &eps)
                })
                .collect();
            let f = internal_force(&grid, &bins, &shapes, &vol, &stress);
            let blocks =
                cell_stiffness_blocks(&grid, &bins, &shapes, &vol, &vec![d; pos.len()], None, None);
            let ku = blocks_times(&grid, &bins.active_cells, &blocks, &u);
            let scale = f
                .iter()
                .fold(0.0f64, |m, v| m.max(v[0].abs()).max(v[1].abs()));
            for (node, (a, b)) in ku.iter().zip(&f).enumerate() {
                for r in 0..2 {
                    assert!(
                        (a[r] - b[r]).abs() < 1e-12 * scale,
                        "{kind:?} node {node}: {} vs {}",
                        a[r],
                        b[r]
                    );
                }
            }
        }
    }
}
