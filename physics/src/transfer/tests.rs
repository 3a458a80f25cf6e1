//! Tests of the transfer kernels.

use super::*;
use crate::constitutive::Voigt;
use crate::grid::{Grid, ShapeAt, ShapeFunctions, Support};

pub(crate) type Cloud = (Grid, Vec<[f64; 2]>, Vec<f64>, Vec<[f64; 2]>);

/// Both kinds of shape functions (GIMP domains of a 2 × 2 point layout).
pub(crate) fn kinds() -> [ShapeFunctions; 2] {
    [
        ShapeFunctions::Bilinear,
        ShapeFunctions::Gimp { half_width: 0.0625 },
    ]
}

pub(crate) fn setup(kind: ShapeFunctions) -> Cloud {
    let grid = Grid {
        shape_functions: kind,
        ..Grid::bilinear([0.0, 0.0], 0.25, [6, 5])
    };
    // pseudo-random points (deterministic LCG) inside part of the grid
    let mut seed = 12345u64;
    let mut rnd = || {
        seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (seed >> 11) as f64 / (1u64 << 53) as f64
    };
    let n = 400;
    let pos: Vec<[f64; 2]> = (0..n)
        .map(|_| [0.1 + 1.2 * rnd(), 0.05 + 1.1 * rnd()])
        .collect();
    let mass: Vec<f64> = (0..n).map(|_| 0.5 + rnd()).collect();
    let vel: Vec<[f64; 2]> = (0..n).map(|_| [rnd() - 0.5, 2.0 * rnd() - 1.0]).collect();
    (grid, pos, mass, vel)
}

/// theory D10: Σ_i m_i = Σ_p m_p and Σ_i p_i = Σ_p m_p v_p (partition of unity),
/// and G2P of the nodal velocity field conserves momentum when mapped back
/// with the same weights (Σ_p m_p Σ_i N_ip v_i = Σ_i m_i v_i).
#[test]
fn p2g_conserves_mass_and_momentum() {
    for kind in kinds() {
        p2g_conserves_mass_and_momentum_with(kind);
    }
}

fn p2g_conserves_mass_and_momentum_with(kind: ShapeFunctions) {
    let (grid, pos, mass, vel) = setup(kind);
    let shapes = shapes_at(&grid, &pos).unwrap();
    let bins = ParticleBins::new(&grid, &shapes);
    let m_nodes = nodal_mass(&grid, &bins, &shapes, &mass);
    let p_nodes = nodal_mass_weighted(&grid, &bins, &shapes, &mass, &vel);
    let total_mass: f64 = mass.iter().sum();
    let grid_mass: f64 = m_nodes.iter().sum();
    assert!(
        (grid_mass - total_mass).abs() <= 1e-13 * total_mass,
        "mass {grid_mass} vs {total_mass}"
    );
    for c in 0..2 {
        let mp: f64 = (0..pos.len()).map(|p| mass[p] * vel[p][c]).sum();
        let mg: f64 = p_nodes.iter().map(|v| v[c]).sum();
        assert!(
            (mp - mg).abs() <= 1e-13 * total_mass,
            "momentum {c}: {mp} vs {mg}"
        );
    }
    // G2P of nodal velocity, then momentum of the particles
    let v_nodes: Vec<[f64; 2]> = p_nodes
        .iter()
        .zip(&m_nodes)
        .map(|(p, &m)| {
            if m > 0.0 {
                [p[0] / m, p[1] / m]
            } else {
                [0.0; 2]
            }
        })
        .collect();
    for c in 0..2 {
        let grid_momentum: f64 = p_nodes.iter().map(|v| v[c]).sum();
        let back: f64 = (0..pos.len())
            .map(|p| mass[p] * interpolate(&shapes[p], &v_nodes)[c])
            .sum();
        assert!(
            (grid_momentum - back).abs() <= 1e-12 * total_mass,
            "G2P momentum {c}"
        );
    }
}

/// A [`NodalField`] refilled over the active nodes of clouds that move
/// across the grid holds, after every refill, what a field built afresh
/// for that cloud holds (bit for bit: nothing of the earlier refills
/// stays), zero at every node no point reaches, and at the others the
/// point-by-point sums Σ_p N_ip m_p (1, v_p) to round-off (1e-13 of the
/// total mass; the patch sums add in another order).
#[test]
fn nodal_field_follows_a_moving_cloud() {
    for kind in kinds() {
        let (grid, pos, mass, vel) = setup(kind);
        let total_mass: f64 = mass.iter().sum();
        let mut field = NodalField::default();
        let mut cell_sums = Vec::new();
        // the cloud shifted right and up, then back over part of its path
        for shift in [[0.0, 0.0], [0.2, 0.1], [0.05, -0.03], [0.0, 0.0]] {
            let moved: Vec<[f64; 2]> = pos
                .iter()
                .map(|x| [x[0] + shift[0], x[1] + shift[1]])
                .collect();
            let shapes = shapes_at(&grid, &moved).unwrap();
            let bins = ParticleBins::new(&grid, &shapes);
            let add = |p: usize, s: &ShapeAt, patch: &mut [[f64; 3]]| {
                for a in s.support() {
                    let place = s.local[a] as usize;
                    let nm = s.n[a] * mass[p];
                    patch[place][0] += nm;
                    patch[place][1] += nm * vel[p][0];
                    patch[place][2] += nm * vel[p][1];
                }
            };
            scatter_into_field(&grid, &bins, &shapes, add, &mut cell_sums, &mut field);
            let mut fresh = NodalField::default();
            scatter_into_field(&grid, &bins, &shapes, add, &mut Vec::new(), &mut fresh);
            let mut by_point = vec![[0.0; 3]; grid.node_count()];
            for (p, s) in shapes.iter().enumerate() {
                for a in s.support() {
                    let nm = s.n[a] * mass[p];
                    let sum = &mut by_point[s.node(a)];
                    sum[0] += nm;
                    sum[1] += nm * vel[p][0];
                    sum[2] += nm * vel[p][1];
                }
            }
            assert_eq!(field.len(), grid.node_count());
            assert_eq!(field.written(), bins.active_nodes.as_slice());
            for node in 0..grid.node_count() {
                let active = bins.node_active[node];
                assert_eq!(
                    bins.active_nodes.binary_search(&(node as u32)).is_ok(),
                    active
                );
                assert_eq!(field[node].map(f64::to_bits), fresh[node].map(f64::to_bits));
                if !active {
                    assert_eq!(field[node], [0.0; 3], "node {node} after shift {shift:?}");
                }
                for k in 0..3 {
                    assert!(
                        (field[node][k] - by_point[node][k]).abs() <= 1e-13 * total_mass,
                        "node {node}, component {k}, shift {shift:?}"
                    );
                }
            }
        }
    }
}

/// Every public field of two bins equal.
fn same_bins(a: &ParticleBins, b: &ParticleBins) -> bool {
    a.cell_start == b.cell_start
        && a.order == b.order
        && a.active_cells == b.active_cells
        && a.reached_cells == b.reached_cells
        && a.cell_slot == b.cell_slot
        && a.node_active == b.node_active
        && a.active_nodes == b.active_nodes
}

/// The bins a [`ParticleBins::rebuild_bilinear`] or a [`ParticleBins::rebuild`]
/// on a bilinear grid keeps or rebuilds are those binned afresh: after
/// moves within the cells (kept), a move of one point into the next cell,
/// the loss of a point.
#[test]
fn kept_bilinear_bins_are_the_fresh_ones() {
    let (grid, pos, _, _) = setup(ShapeFunctions::Bilinear);
    let cells_of = |x: &[[f64; 2]]| -> Vec<u32> {
        let (mut shapes, mut cells) = (Vec::new(), Vec::new());
        bilinear_shapes_into(&grid, x, &mut shapes, &mut cells).unwrap();
        cells
    };
    let mut kept = ParticleBins::default();
    let mut moved = pos.clone();
    // 0: first binning; 1: every point moved by 1e-9 m (no cell changes);
    // 2: point 7 moved by a cell; 3: the last point lost; 4: point 3 moved
    // by a cell and binned from its full shape functions first
    for stage in 0..5 {
        match stage {
            1 => moved.iter_mut().for_each(|x| x[0] += 1e-9),
            2 => moved[7][0] += grid.cell_size,
            3 => {
                moved.pop();
            }
            4 => {
                moved[3][1] += grid.cell_size;
                let shapes = shapes_at(&grid, &moved).unwrap();
                kept.rebuild(&grid, &shapes);
                let mut fresh = ParticleBins::default();
                fresh.rebuild_bilinear(&grid, &cells_of(&moved));
                assert!(same_bins(&kept, &fresh), "full rebuild");
            }
            _ => {}
        }
        let cells = cells_of(&moved);
        kept.rebuild_bilinear(&grid, &cells);
        let mut fresh = ParticleBins::default();
        fresh.rebuild_bilinear(&grid, &cells);
        assert!(same_bins(&kept, &fresh), "stage {stage}");
    }
    assert_ne!(
        cells_of(&pos)[7],
        cells_of(&moved)[7],
        "point 7 changed cells"
    );
}

/// GIMP shapes formed with one scratch for clouds in turn are those of
/// a fresh scratch: the cells marked as holding points for one cloud
/// clip no domain of the next.
#[test]
fn gimp_shapes_with_a_kept_scratch_are_the_fresh_ones() {
    let (grid, pos, _, _) = setup(kinds()[1]);
    let mut scratch = ShapeScratch::default();
    let mut shapes = Vec::new();
    let half: Vec<[f64; 2]> = pos.iter().copied().filter(|x| x[0] < 0.6).collect();
    for cloud in [&pos, &half, &pos] {
        shapes_into(&grid, cloud, &mut scratch, &mut shapes).unwrap();
        assert_eq!(shapes, shapes_at(&grid, cloud).unwrap());
    }
    assert!(scratch.holds_points.iter().all(|&filled| !filled));
}

/// Bins rebuilt in place while a small body moves about a large grid
/// (within its cells, far across the grid, with a point lost, with a
/// point flung to the far corner and back) are the fresh bins of the
/// points where they are, field for field, bilinear and GIMP: the
/// rebuild's visit of the cells of the body (last and present) misses
/// nothing and leaves nothing behind.
#[test]
fn bins_rebuilt_in_place_are_the_fresh_ones() {
    for kind in kinds() {
        let grid = Grid {
            shape_functions: kind,
            ..Grid::bilinear([0.0, 0.0], 0.25, [40, 20])
        };
        let block: Vec<[f64; 2]> = (0..64)
            .map(|k| [1.0 + 0.13 * (k % 8) as f64, 1.0 + 0.11 * (k / 8) as f64])
            .collect();
        let mut kept = ParticleBins::default();
        let mut moved = block.clone();
        for stage in 0..7 {
            let shift = |points: &mut Vec<[f64; 2]>, dx: f64, dy: f64| {
                points.iter_mut().for_each(|x| *x = [x[0] + dx, x[1] + dy]);
            };
            match stage {
                1 => shift(&mut moved, 1e-9, 0.0),
                2 => shift(&mut moved, 3.1, 0.0),
                3 => {
                    moved.pop();
                }
                4 => shift(&mut moved, -2.0, 1.5),
                5 => moved[10] = [9.9, 4.9],
                6 => moved[10] = [2.0, 2.6],
                _ => {}
            }
            let shapes = shapes_at(&grid, &moved).unwrap();
            kept.rebuild(&grid, &shapes);
            let fresh = ParticleBins::new(&grid, &shapes);
            assert!(same_bins(&kept, &fresh), "{kind:?}, stage {stage}");
            assert!(!fresh.active_cells.is_empty());
        }
    }
}

/// [`refill_fields`] writes component k of every node's value to field k
/// and clears the nodes of the refill before, whichever field they were in.
#[test]
fn refill_fields_splits_and_clears() {
    let mut fields = [NodalField::<f64>::default(), NodalField::default()];
    let mut staging = Vec::new();
    let [a, b] = &mut fields;
    refill_fields([a, b], 10, &[1, 4, 7], &mut staging, |n| {
        [n as f64, -(n as f64)]
    });
    let [a, b] = &mut fields;
    refill_fields([a, b], 10, &[2, 4], &mut staging, |n| {
        [10.0 * n as f64, 0.5]
    });
    let expect_a = [0.0, 0.0, 20.0, 0.0, 40.0, 0.0, 0.0, 0.0, 0.0, 0.0];
    let expect_b = [0.0, 0.0, 0.5, 0.0, 0.5, 0.0, 0.0, 0.0, 0.0, 0.0];
    assert_eq!(&fields[0][..], &expect_a);
    assert_eq!(&fields[1][..], &expect_b);
}

/// GIMP: a point near a cell edge reaches the nodes beyond it when the
/// cell beyond holds points, and not when it is empty (the domain is
/// clipped at the body's cells); the clipped point keeps the partition of
/// unity and the linear completeness of its gradient.
#[test]
fn gimp_domains_reach_filled_neighbours_only() {
    let grid = Grid {
        shape_functions: ShapeFunctions::Gimp { half_width: 0.125 },
        ..Grid::bilinear([0.0, 0.0], 0.5, [4, 4])
    };
    // a point just left of the line x = 1.0, in cell (1, 1)
    let near_edge = [0.95, 0.75];
    let alone = shapes_at(&grid, &[near_edge]).unwrap();
    assert_eq!(alone[0].count, 4);
    let with_neighbour = shapes_at(&grid, &[near_edge, [1.2, 0.7]]).unwrap();
    assert_eq!(with_neighbour[0].count, 6);
    for s in [&alone[0], &with_neighbour[0]] {
        let sum: f64 = s.support().map(|a| s.n[a]).sum();
        let mut jac = [[0.0; 2]; 2];
        for a in s.support() {
            let xa = grid.node_position(s.nodes[a] as usize);
            for (r, row) in jac.iter_mut().enumerate() {
                for (c, v) in row.iter_mut().enumerate() {
                    *v += xa[r] * s.dn[a][c];
                }
            }
        }
        assert!((sum - 1.0).abs() < 1e-14);
        assert!((jac[0][0] - 1.0).abs() < 1e-12 && (jac[1][1] - 1.0).abs() < 1e-12);
        assert!(jac[0][1].abs() < 1e-12 && jac[1][0].abs() < 1e-12);
    }
    let bins = ParticleBins::new(&grid, &with_neighbour);
    assert_eq!(bins.active_cells, vec![5, 6]);
    assert!(bins.reached_cells.is_empty());
    // a point near the corner of an L-shaped body reaches the empty
    // diagonal cell: a reached cell, whose nodes are active
    let corner = shapes_at(&grid, &[[0.95, 0.95], [1.2, 0.7], [0.7, 1.2]]).unwrap();
    assert_eq!(corner[0].count, 9);
    let bins = ParticleBins::new(&grid, &corner);
    assert_eq!(bins.reached_cells, vec![10]);
    for a in corner[0].support() {
        assert!(bins.node_active[corner[0].nodes[a] as usize]);
    }
}

/// In-plane invariants of a stress: mean, deviatoric radius, σzz.
fn invariants(s: &Voigt) -> [f64; 3] {
    let radius = (0.25 * (s[0] - s[1]).powi(2) + s[3] * s[3]).sqrt();
    [0.5 * (s[0] + s[1]), radius, s[2]]
}

fn stresses_and_spins() -> Vec<(Voigt, f64)> {
    let mut out = Vec::new();
    for (k, spin) in [-2.0, -0.3, -1e-3, 0.0, 1e-4, 0.05, 0.7, 3.0]
        .into_iter()
        .enumerate()
    {
        let k = k as f64;
        out.push((
            [-120.0 + 7.0 * k, 35.0 - 11.0 * k, -40.0, 18.0 + 3.0 * k],
            spin,
        ));
    }
    // components that are not short binary fractions ((a + b)/2 + (a − b)/2 ≠ a here)
    out.push(([0.1, 0.7, 0.3, 0.2], 0.02));
    out
}

/// The rotation of the stored stress (D13) keeps the mean stress, the in-plane deviatoric
/// radius and σzz to round-off (1e−13 relative) for any spin; D13's linear form would
/// grow the radius by √(1 + 4ω²) (checked here too, so the test tells the two apart).
#[test]
fn stress_rotation_keeps_the_invariants() {
    for (stress, spin) in stresses_and_spins() {
        let rotated = rotate_stress(&stress, spin);
        let scale = stress.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        for (a, b) in invariants(&stress).iter().zip(invariants(&rotated)) {
            assert!((a - b).abs() <= 1e-13 * scale, "spin {spin}: {a} vs {b}");
        }
        let [sxx, syy, szz, sxy] = stress;
        let linear = [
            sxx + 2.0 * spin * sxy,
            syy - 2.0 * spin * sxy,
            szz,
            sxy + spin * (syy - sxx),
        ];
        let growth = invariants(&linear)[1] / invariants(&stress)[1];
        assert!((growth - (1.0 + 4.0 * spin * spin).sqrt()).abs() < 1e-12);
    }
}

/// The rotation agrees with D13's linear form to second order in ω: the difference over
/// ω² stays bounded as ω → 0 (by 4 max|σ| = 480; measured 155 = 2 × the deviatoric radius),
/// and vanishes at ω = 0.
#[test]
fn stress_rotation_is_d13_to_first_order() {
    let stress = [-120.0, 35.0, -40.0, 18.0];
    let [sxx, syy, _, sxy] = stress;
    for spin in [1e-1, 1e-2, 1e-3, 1e-4] {
        let rotated = rotate_stress(&stress, spin);
        let linear = [
            sxx + 2.0 * spin * sxy,
            syy - 2.0 * spin * sxy,
            sxy + spin * (syy - sxx),
        ];
        let difference = [rotated[0], rotated[1], rotated[3]]
            .iter()
            .zip(linear)
            .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
        assert!(
            difference <= 4.0 * 120.0 * spin * spin,
            "spin {spin}: {difference}"
        );
    }
    for (stress, _) in stresses_and_spins() {
        assert_eq!(rotate_stress(&stress, 0.0), stress);
    }
}

/// `rotate_stress_derivative` against central differences of `rotate_stress`
/// (step 1e−6: round-off ~1e−8 of the differences; tolerance 1e−9 relative to |σ| = 120,
/// i.e. 1.2e−7; measured 1.3e−8).
#[test]
fn stress_rotation_derivative_matches_finite_differences() {
    for (stress, spin) in stresses_and_spins() {
        let step = 1e-6;
        let (plus, minus) = (
            rotate_stress(&stress, spin + step),
            rotate_stress(&stress, spin - step),
        );
        let derivative = rotate_stress_derivative(&stress, spin);
        for c in 0..4 {
            let fd = (plus[c] - minus[c]) / (2.0 * step);
            assert!(
                (fd - derivative[c]).abs() <= 1e-9 * 120.0,
                "spin {spin}, c {c}: {fd} vs {}",
                derivative[c]
            );
        }
    }
}
