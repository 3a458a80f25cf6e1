//! Numerical tests of assembly and direct solves (run in release: faer is slow in debug).

use crate::*;

/// xorshift64* pseudo-random generator (deterministic, no dependency).
struct Rng(u64);
impl Rng {
    fn next_u64(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    /// uniform in [-1, 1)
    fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next_u64() % n as u64) as usize
    }
}

/// 8x8 plane-strain stiffness (row-major) of a square bilinear cell of side `h`, 2x2 Gauss.
/// Local nodes counter-clockwise from the lower-left corner, dofs (ux, uy) per node.
fn q4_stiffness(e: f64, nu: f64, h: f64) -> [f64; 64] {
    let c = e / ((1.0 + nu) * (1.0 - 2.0 * nu));
    let d = [
        [c * (1.0 - nu), c * nu, 0.0],
        [c * nu, c * (1.0 - nu), 0.0],
        [0.0, 0.0, c * (1.0 - 2.0 * nu) / 2.0],
    ];
    let xi_n = [-1.0, 1.0, 1.0, -1.0];
    let eta_n = [-1.0, -1.0, 1.0, 1.0];
    let g = 1.0 / 3.0f64.sqrt();
    let det_j = h * h / 4.0;
    let mut k = [0.0; 64];
    for &xi in &[-g, g] {
        for &eta in &[-g, g] {
            let mut b = [[0.0; 8]; 3];
            for a in 0..4 {
                let dx = 0.25 * xi_n[a] * (1.0 + eta * eta_n[a]) * 2.0 / h;
                let dy = 0.25 * eta_n[a] * (1.0 + xi * xi_n[a]) * 2.0 / h;
                b[0][2 * a] = dx;
                b[1][2 * a + 1] = dy;
                b[2][2 * a] = dy;
                b[2][2 * a + 1] = dx;
            }
            for r in 0..8 {
                for s in 0..8 {
                    let mut v = 0.0;
                    for i in 0..3 {
                        for j in 0..3 {
                            v += b[i][r] * d[i][j] * b[j][s];
                        }
                    }
                    k[8 * r + s] += v * det_j; // Gauss weights are 1
                }
            }
        }
    }
    k
}

/// Element dof lists of an `nx x ny` cell grid; with `fix_bottom` the nodes of row 0 are fully
/// constrained (NO_DOF). Returns (n_dofs, element dofs).
fn grid_dofs(nx: usize, ny: usize, fix_bottom: bool) -> (usize, Vec<[u32; 8]>) {
    let mut node_dof = vec![NO_DOF; (nx + 1) * (ny + 1)];
    let mut n = 0u32;
    for j in 0..=ny {
        for i in 0..=nx {
            if !(fix_bottom && j == 0) {
                node_dof[j * (nx + 1) + i] = n;
                n += 2;
            }
        }
    }
    let mut elems = Vec::new();
    for j in 0..ny {
        for i in 0..nx {
            let nodes = [
                j * (nx + 1) + i,
                j * (nx + 1) + i + 1,
                (j + 1) * (nx + 1) + i + 1,
                (j + 1) * (nx + 1) + i,
            ];
            let mut d = [NO_DOF; 8];
            for (a, &nd) in nodes.iter().enumerate() {
                if node_dof[nd] != NO_DOF {
                    d[2 * a] = node_dof[nd];
                    d[2 * a + 1] = node_dof[nd] + 1;
                }
            }
            elems.push(d);
        }
    }
    (n as usize, elems)
}

fn norm(v: &[f64]) -> f64 {
    v.iter().map(|x| x * x).sum::<f64>().sqrt()
}

/// ||b - K x|| / ||b||
fn rel_residual(k: &SparseMatrix, x: &[f64], b: &[f64]) -> f64 {
    let mut kx = vec![0.0; k.n()];
    k.mul_vec(x, &mut kx);
    let r: Vec<f64> = kx.iter().zip(b).map(|(a, c)| c - a).collect();
    norm(&r) / norm(b)
}

fn rel_diff(a: &[f64], b: &[f64]) -> f64 {
    let d: Vec<f64> = a.iter().zip(b).map(|(x, y)| x - y).collect();
    norm(&d) / norm(b)
}

/// Elastic grid stiffness (E = 3e4 kPa, nu = 0.25, h = 0.5 m), bottom edge fixed.
fn elastic_system(nx: usize, ny: usize) -> (Assembler, Vec<[f64; 64]>, SparseMatrix) {
    let (n, elems) = grid_dofs(nx, ny, true);
    let asm = Assembler::new(n, &elems).unwrap();
    let blocks = vec![q4_stiffness(3e4, 0.25, 0.5); elems.len()];
    let k = asm.assemble(&blocks).unwrap();
    (asm, blocks, k)
}

fn random_rhs(n: usize, seed: u64) -> Vec<f64> {
    let mut rng = Rng(seed);
    (0..n).map(|_| rng.uniform()).collect()
}

#[test]
fn assembly_equals_dense_sum_and_nnz_counts_couplings() {
    let mut rng = Rng(0x1234_5678);
    let n = 40;
    let n_el = 30;
    let mut elems = Vec::new();
    for _ in 0..n_el {
        let mut d = [NO_DOF; 8];
        for a in 0..8 {
            if rng.below(5) != 0 {
                // distinct dofs within an element
                loop {
                    let c = rng.below(n) as u32;
                    if !d.contains(&c) {
                        d[a] = c;
                        break;
                    }
                }
            }
        }
        elems.push(d);
    }
    let blocks: Vec<[f64; 64]> = (0..n_el)
        .map(|_| std::array::from_fn(|_| rng.uniform()))
        .collect();
    let diag: Vec<f64> = (0..n).map(|_| rng.uniform()).collect();
    let asm = Assembler::new(n, &elems).unwrap();
    let k = asm.assemble_with_diagonal(&blocks, Some(&diag)).unwrap();

    let mut dense = vec![0.0; n * n];
    let mut coupled = std::collections::BTreeSet::new();
    for (d, blk) in elems.iter().zip(&blocks) {
        for a in 0..8 {
            for b in 0..8 {
                if d[a] != NO_DOF && d[b] != NO_DOF {
                    let (r, c) = (d[a] as usize, d[b] as usize);
                    dense[r * n + c] += blk[8 * a + b];
                    coupled.insert((r, c));
                }
            }
        }
    }
    for i in 0..n {
        dense[i * n + i] += diag[i];
        coupled.insert((i, i)); // the pattern always holds the full diagonal
    }
    let scale = dense.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    for r in 0..n {
        for c in 0..n {
            let err = (k.get(r, c) - dense[r * n + c]).abs();
            assert!(err <= 1e-14 * scale, "({r},{c}): error {err:e}");
        }
    }
    assert_eq!(k.nnz(), coupled.len());
    assert_eq!(asm.nnz(), coupled.len());
    // every stored entry is a coupling (or diagonal)
    for c in 0..n {
        for p in k.col_ptr()[c]..k.col_ptr()[c + 1] {
            assert!(coupled.contains(&(k.row_idx()[p], c)));
        }
    }
    // deterministic: a second assembly is bit-identical
    let k2 = asm.assemble_with_diagonal(&blocks, Some(&diag)).unwrap();
    assert_eq!(k.values(), k2.values());
    // in-place reassembly into the same matrix gives the same bits
    let mut k3 = asm.assemble(&blocks).unwrap();
    asm.reassemble(&mut k3, &blocks, Some(&diag)).unwrap();
    assert_eq!(k.values(), k3.values());
}

#[test]
fn grid_nnz_is_number_of_distinct_couplings() {
    // Q4 grid, bottom fixed: each free node couples with its (up to 9) neighbouring free
    // nodes, 2 x 2 dofs each.
    let (nx, ny) = (5, 4);
    let (_, _, k) = elastic_system(nx, ny);
    let mut expected = 0;
    for j in 1..=ny {
        for i in 0..=nx {
            let nx_count = 1 + (i > 0) as usize + (i < nx) as usize;
            let ny_count = 1 + (j > 1) as usize + (j < ny) as usize;
            expected += 4 * nx_count * ny_count;
        }
    }
    assert_eq!(k.nnz(), expected);
}

#[test]
fn assembler_rejects_bad_input() {
    assert_eq!(
        Assembler::new(0, &[] as &[[u32; 8]]).unwrap_err(),
        SolverError::EmptySystem
    );
    let e = Assembler::new(4, &[[0, 1, 2, 3, 4, NO_DOF, NO_DOF, NO_DOF]]).unwrap_err();
    assert!(matches!(e, SolverError::DofOutOfRange { dof: 4, .. }));
    let asm = Assembler::new(4, &[[0, 1, 2, 3, NO_DOF, NO_DOF, NO_DOF, NO_DOF]]).unwrap();
    assert!(matches!(
        asm.assemble(&[] as &[[f64; 64]]),
        Err(SolverError::DimensionMismatch { .. })
    ));
    assert!(matches!(
        asm.assemble_with_diagonal(&[[1.0; 64]], Some(&[1.0; 3])),
        Err(SolverError::DimensionMismatch { .. })
    ));
}

#[test]
fn from_triplets_sums_duplicates_and_checks_range() {
    let k = SparseMatrix::from_triplets(3, &[(0, 0, 1.0), (2, 1, 2.0), (0, 0, 0.5), (1, 2, -1.0)])
        .unwrap();
    assert_eq!(k.nnz(), 3);
    assert_eq!(k.get(0, 0), 1.5);
    assert_eq!(k.get(2, 1), 2.0);
    assert_eq!(k.get(1, 1), 0.0);
    assert!(matches!(
        SparseMatrix::from_triplets(3, &[(3, 0, 1.0)]),
        Err(SolverError::IndexOutOfRange { .. })
    ));
    assert_eq!(
        SparseMatrix::from_triplets(0, &[]).unwrap_err(),
        SolverError::EmptySystem
    );
}

/// A bordered matrix holds K and its border where they belong, and a
/// border that controls K's zero-energy mode makes a singular K regular:
/// the floating elastic strip (rigid translation along x free) pinned by
/// the border row "mean x displacement = value" is solved by LU to round-off.
#[test]
fn bordered_matrix_places_the_border_and_regularises_a_mechanism() {
    // the strip on vertical springs along its base: free to slide along x
    let (nx, ny) = (8, 3);
    let (n, elems) = grid_dofs(nx, ny, false);
    let k = Assembler::new(n, &elems)
        .unwrap()
        .assemble(&vec![q4_stiffness(3e4, 0.25, 0.5); elems.len()])
        .unwrap();
    let mut t = Vec::new();
    for j in 0..n {
        for p in k.col_ptr()[j]..k.col_ptr()[j + 1] {
            t.push((k.row_idx()[p], j, k.values()[p]));
        }
    }
    t.extend((0..=nx).map(|i| (2 * i + 1, 2 * i + 1, 3e4)));
    let free_strip = SparseMatrix::from_triplets(n, &t).unwrap();
    let x_dofs: Vec<usize> = (0..n).step_by(2).collect();
    let row: Vec<(usize, f64)> = x_dofs.iter().map(|&i| (i, 1.0)).collect();
    let column: Vec<(usize, f64)> = x_dofs.iter().map(|&i| (i, -1e-3)).collect();
    let a = free_strip.bordered(&column, &row, 0.5).unwrap();
    assert_eq!(a.n(), n + 1);
    assert_eq!(a.nnz(), free_strip.nnz() + 2 * x_dofs.len() + 1);
    assert_eq!(a.get(5, 7), free_strip.get(5, 7));
    assert_eq!((a.get(n, 2), a.get(2, n), a.get(n, n)), (1.0, -1e-3, 0.5));
    assert_eq!((a.get(n, 1), a.get(1, n)), (0.0, 0.0));
    let b = random_rhs(n + 1, 11);
    let mut lu = DirectSolver::new(SolverPolicy::Lu);
    lu.factorize(&a, false).unwrap();
    let mut x = b.clone();
    lu.solve_in_place(&mut x).unwrap();
    let r = rel_residual(&a, &x, &b);
    assert!(r <= 1e-10, "bordered LU residual {r:e}");
    let unsorted = [(3, 1.0), (1, 1.0)];
    assert!(free_strip.bordered(&unsorted, &row, 0.0).is_err());
    assert!(free_strip.bordered(&[(n, 1.0)], &row, 0.0).is_err());
}

#[test]
fn spd_cholesky_and_lu_agree() {
    // small grid (simplicial path likely) and a larger one (supernodal path likely)
    for &(nx, ny) in &[(6, 4), (60, 40)] {
        let (_, _, k) = elastic_system(nx, ny);
        assert!(k.is_symmetric(1e-14));
        let b = random_rhs(k.n(), 7);
        let mut chol = DirectSolver::new(SolverPolicy::Cholesky);
        let mut lu = DirectSolver::new(SolverPolicy::Lu);
        assert_eq!(chol.factorize(&k, true).unwrap(), FactorKind::Cholesky);
        assert_eq!(lu.factorize(&k, true).unwrap(), FactorKind::Lu);
        let mut xc = b.clone();
        chol.solve_in_place(&mut xc).unwrap();
        let mut xl = b.clone();
        lu.solve_in_place(&mut xl).unwrap();
        let (rc, rl) = (rel_residual(&k, &xc, &b), rel_residual(&k, &xl, &b));
        assert!(rc <= 1e-12, "Cholesky residual {rc:e} ({nx}x{ny})");
        assert!(rl <= 1e-12, "LU residual {rl:e} ({nx}x{ny})");
        let d = rel_diff(&xc, &xl);
        assert!(d <= 1e-10, "Cholesky vs LU differ by {d:e} ({nx}x{ny})");
        assert_eq!(chol.stats().cholesky_fallbacks, 0);
        // Auto + symmetric picks Cholesky; Auto + unsymmetric picks LU
        let mut auto = DirectSolver::new(SolverPolicy::Auto);
        assert_eq!(auto.factorize(&k, true).unwrap(), FactorKind::Cholesky);
        assert_eq!(auto.factorize(&k, false).unwrap(), FactorKind::Lu);
    }
}

#[test]
fn unsymmetric_system_by_lu() {
    let (asm, mut blocks, _) = elastic_system(40, 25);
    let mut rng = Rng(99);
    let scale = blocks[0][0];
    for blk in blocks.iter_mut() {
        for a in 0..8 {
            for b in (a + 1)..8 {
                blk[8 * a + b] += 0.2 * scale * rng.uniform();
            }
        }
    }
    let k = asm.assemble(&blocks).unwrap();
    assert!(!k.is_symmetric(1e-3));
    let b = random_rhs(k.n(), 3);
    let mut s = DirectSolver::new(SolverPolicy::Auto);
    assert_eq!(s.factorize(&k, false).unwrap(), FactorKind::Lu);
    let mut x = b.clone();
    s.solve_in_place(&mut x).unwrap();
    let r = rel_residual(&k, &x, &b);
    assert!(r <= 1e-12, "LU residual {r:e}");
}

#[test]
fn auto_falls_back_to_lu_on_indefinite_symmetric() {
    let (asm, blocks, k0) = elastic_system(30, 20);
    // K - sigma I with sigma between eigenvalues: symmetric, indefinite, nonsingular.
    let sigma = 0.37 * k0.get(0, 0);
    let shift = vec![-sigma; asm.n_dofs()];
    let k = asm.assemble_with_diagonal(&blocks, Some(&shift)).unwrap();
    assert!(k.is_symmetric(1e-14));
    let b = random_rhs(k.n(), 11);
    let mut s = DirectSolver::new(SolverPolicy::Auto);
    assert_eq!(s.factorize(&k, true).unwrap(), FactorKind::Lu);
    let mut x = b.clone();
    s.solve_in_place(&mut x).unwrap();
    let r = rel_residual(&k, &x, &b);
    assert!(r <= 1e-12, "residual after fallback {r:e}");
    assert_eq!(s.stats().cholesky_fallbacks, 1);
    assert_eq!(s.stats().last_factor, Some(FactorKind::Lu));
    // the failed Cholesky attempt and the LU are both numeric factorisations
    assert_eq!((s.stats().numeric_cholesky, s.stats().numeric_lu), (1, 1));
    assert_eq!(s.stats().numeric, 2);
}

#[test]
fn refactorisation_reuses_symbolic() {
    for policy in [SolverPolicy::Cholesky, SolverPolicy::Lu] {
        let (asm, blocks, k1) = elastic_system(30, 20);
        let mut s = DirectSolver::new(policy);
        s.factorize(&k1, true).unwrap();
        // new values, same pattern (a stiffer, slightly different tangent plus a mass term)
        let mut rng = Rng(5);
        let blocks2: Vec<[f64; 64]> = blocks
            .iter()
            .map(|b| {
                let f = 1.0 + 0.5 * rng.uniform().abs();
                b.map(|v| v * f)
            })
            .collect();
        let mass: Vec<f64> = (0..asm.n_dofs()).map(|i| 10.0 + (i % 3) as f64).collect();
        let k2 = asm.assemble_with_diagonal(&blocks2, Some(&mass)).unwrap();
        let b = random_rhs(k2.n(), 21);
        s.factorize(&k2, true).unwrap();
        let mut x = b.clone();
        s.solve_in_place(&mut x).unwrap();
        assert_eq!(s.stats().symbolic, 1, "{policy:?}");
        assert_eq!(s.stats().numeric, 2, "{policy:?}");

        let mut fresh = DirectSolver::new(policy);
        let xf = fresh.solve(&k2, true, &b).unwrap();
        let d = rel_diff(&x, &xf);
        assert!(d <= 1e-13, "{policy:?}: reused vs fresh differ by {d:e}");

        // an equal pattern from another Assembler (different Arc) is still recognised
        let (_, _, k3) = elastic_system(30, 20);
        assert!(!k3.shares_pattern_with(&k1));
        s.factorize(&k3, true).unwrap();
        assert_eq!(s.stats().symbolic, 1, "{policy:?}");
        // a changed pattern triggers a new symbolic factorisation
        let (_, _, k4) = elastic_system(31, 20);
        s.factorize(&k4, true).unwrap();
        assert_eq!(s.stats().symbolic, 2, "{policy:?}");
        assert_eq!(s.stats().numeric, 4, "{policy:?}");
        let by_kind = match policy {
            SolverPolicy::Lu => (0, 4),
            _ => (4, 0),
        };
        let stats = s.stats();
        assert_eq!(
            (stats.numeric_cholesky, stats.numeric_lu),
            by_kind,
            "{policy:?}"
        );
    }
}

#[test]
fn singular_systems_are_errors() {
    // floating body: no constraints, rigid-body modes in the null space
    let (n, elems) = grid_dofs(8, 6, false);
    let asm = Assembler::new(n, &elems).unwrap();
    let k = asm
        .assemble(&vec![q4_stiffness(3e4, 0.25, 0.5); elems.len()])
        .unwrap();
    for policy in [SolverPolicy::Auto, SolverPolicy::Cholesky, SolverPolicy::Lu] {
        for symmetric in [true, false] {
            let mut s = DirectSolver::new(policy);
            let e = s.factorize(&k, symmetric).unwrap_err();
            assert!(
                matches!(e, SolverError::Singular { .. }),
                "{policy:?}/{symmetric}: {e}"
            );
            let mut x = vec![1.0; n];
            assert_eq!(s.solve_in_place(&mut x), Err(SolverError::NotFactorized));
        }
    }
    // zero column block: an element whose block is all zero and whose dofs no other
    // element touches
    let (n, mut elems) = grid_dofs(6, 4, true);
    elems.push([
        n as u32,
        n as u32 + 1,
        NO_DOF,
        NO_DOF,
        NO_DOF,
        NO_DOF,
        NO_DOF,
        NO_DOF,
    ]);
    let asm = Assembler::new(n + 2, &elems).unwrap();
    let mut blocks = vec![q4_stiffness(3e4, 0.25, 0.5); elems.len()];
    *blocks.last_mut().unwrap() = [0.0; 64];
    let k = asm.assemble(&blocks).unwrap();
    for policy in [SolverPolicy::Auto, SolverPolicy::Lu] {
        let mut s = DirectSolver::new(policy);
        let e = s.factorize(&k, true).unwrap_err();
        assert!(matches!(e, SolverError::Singular { .. }), "{policy:?}: {e}");
    }
    // a structurally empty column (from_triplets without the diagonal)
    let k = SparseMatrix::from_triplets(3, &[(0, 0, 1.0), (1, 1, 1.0), (2, 1, 1.0)]).unwrap();
    for symmetric in [true, false] {
        let e = DirectSolver::new(SolverPolicy::Auto)
            .factorize(&k, symmetric)
            .unwrap_err();
        assert!(matches!(e, SolverError::Singular { .. }), "{e}");
    }
}

/// A numerically singular LU is located: in a well-conditioned tridiagonal
/// system with a nearly singular 2 × 2 block on unknowns 4 and 5 (null
/// vector (1, −1) there, condition ~1e15), the probe solve's error exceeds
/// its tolerance and is largest at one of those two unknowns.
#[test]
fn a_singular_probe_names_its_unknown() {
    let n = 10;
    let mut triplets = Vec::new();
    for i in 0..n {
        triplets.push((i, i, 4.0));
        if i + 1 < n && !(3..=5).contains(&i) {
            triplets.push((i, i + 1, -1.0));
            triplets.push((i + 1, i, -1.0));
        }
    }
    // unknowns 4 and 5: [[1, 1], [1, 1 + 1e-15]] instead of 4 on the diagonal
    for (i, j, v) in [(4, 4, -3.0), (5, 5, -3.0 + 1e-15), (4, 5, 1.0), (5, 4, 1.0)] {
        triplets.push((i, j, v));
    }
    let k = SparseMatrix::from_triplets(n, &triplets).unwrap();
    let e = DirectSolver::new(SolverPolicy::Lu)
        .factorize(&k, false)
        .unwrap_err();
    match e {
        SolverError::Singular {
            unknown: Some(u), ..
        } => assert!(u == 4 || u == 5, "named unknown {u}"),
        e => panic!("not a located singular matrix: {e}"),
    }
}

#[test]
fn non_finite_input_is_an_error() {
    let (_, _, mut k) = elastic_system(6, 4);
    let mut s = DirectSolver::new(SolverPolicy::Auto);
    s.factorize(&k, true).unwrap();
    let mut rhs = vec![0.0; k.n()];
    rhs[3] = f64::NAN;
    assert!(matches!(
        s.solve_in_place(&mut rhs),
        Err(SolverError::NonFinite { index: 3, .. })
    ));
    let mut short = vec![0.0; 2];
    assert!(matches!(
        s.solve_in_place(&mut short),
        Err(SolverError::RhsMismatch { .. })
    ));
    k.values_mut()[10] = f64::NAN;
    assert!(matches!(
        s.factorize(&k, true),
        Err(SolverError::NonFinite { index: 10, .. })
    ));
    assert!(!k.is_symmetric(1.0));
}

#[test]
fn is_symmetric_detects_small_asymmetry() {
    let (_, _, mut k) = elastic_system(10, 8);
    assert!(k.is_symmetric(1e-14));
    // perturb one off-diagonal entry by 1e-6 relative
    // the largest off-diagonal entry of column 7
    let c = 7;
    let p = (k.col_ptr()[c]..k.col_ptr()[c + 1])
        .filter(|&p| k.row_idx()[p] != c)
        .max_by(|&a, &b| k.values()[a].abs().total_cmp(&k.values()[b].abs()))
        .unwrap();
    assert!(k.values()[p].abs() > 0.0);
    k.values_mut()[p] *= 1.0 + 1e-6;
    assert!(!k.is_symmetric(1e-8));
    assert!(!k.is_symmetric(1e-7));
    assert!(k.is_symmetric(1e-5));
}

#[test]
fn weak_regularised_cells_are_not_flagged_singular() {
    // [D19]-like: the upper half of the grid holds only the background stiffness
    // eps_bg * K_el (eps_bg = 1e-6); a few cells are 1e4 times stiffer (penalty-like).
    let (nx, ny) = (40, 30);
    let (n, elems) = grid_dofs(nx, ny, true);
    let asm = Assembler::new(n, &elems).unwrap();
    let kel = q4_stiffness(3e4, 0.25, 0.5);
    let blocks: Vec<[f64; 64]> = (0..elems.len())
        .map(|e| {
            let (i, j) = (e % nx, e / nx);
            let f = if j >= ny / 2 {
                1e-6
            } else if j == 0 && i % 10 == 0 {
                1e4
            } else {
                1.0
            };
            kel.map(|v| v * f)
        })
        .collect();
    let k = asm.assemble(&blocks).unwrap();
    let b = random_rhs(n, 17);
    for policy in [SolverPolicy::Cholesky, SolverPolicy::Lu] {
        let mut s = DirectSolver::new(policy);
        let x = s.solve(&k, true, &b).unwrap();
        let r = rel_residual(&k, &x, &b);
        assert!(r <= 1e-10, "{policy:?}: residual {r:e}");
        let st = s.stats();
        assert!(st.last_pivot_ratio.is_none_or(|p| p > 1e-13), "{st:?}");
        assert!(st.last_probe_error.is_none_or(|e| e < 1e-6), "{st:?}");
    }
}

/// Elements of different sizes (a 4-dof and a 2-dof one sharing two dofs) sum into one
/// pattern; a block whose size is not the element's d² is refused.
#[test]
fn mixed_element_sizes_sum_and_check_block_size() {
    let elems: Vec<Vec<u32>> = vec![vec![0, 1, 2, 3], vec![2, NO_DOF, 3]];
    let asm = Assembler::new(4, &elems).unwrap();
    let big: Vec<f64> = (0..16).map(|k| k as f64).collect();
    let small: Vec<f64> = (0..9).map(|k| 100.0 * (k + 1) as f64).collect();
    let k = asm.assemble(&[big.clone(), small.clone()]).unwrap();
    // (row 2, col 3): big[4·2 + 3] + small[3·0 + 2]; (row 3, col 3): big[15] + small[8]
    assert_eq!(k.get(2, 3), 11.0 + 300.0);
    assert_eq!(k.get(3, 3), 15.0 + 900.0);
    assert_eq!(k.get(0, 1), 1.0);
    assert!(matches!(
        asm.assemble(&[big, small[..4].to_vec()]),
        Err(SolverError::DimensionMismatch { .. })
    ));
}

/// A coupling filter drops the listed entries from the pattern and from the assembly, and
/// keeps the rest (here: dofs 0 and 3 of a 4-dof element are never coupled).
#[test]
fn coupling_filter_shrinks_the_pattern() {
    let elems = vec![vec![0u32, 1, 2, 3]];
    let full = Assembler::new(4, &elems).unwrap();
    let far = |_: usize, a: usize, b: usize| a.abs_diff(b) <= 2;
    let thin = Assembler::with_couplings(4, &elems, far).unwrap();
    assert_eq!(full.nnz(), 16);
    assert_eq!(thin.nnz(), 14);
    let block: Vec<f64> = (0..16).map(|k| 1.0 + k as f64).collect();
    let k = thin.assemble(&[block]).unwrap();
    assert_eq!(k.get(0, 3), 0.0);
    assert_eq!(k.get(3, 0), 0.0);
    assert_eq!(k.get(1, 2), 7.0);
    assert_eq!(k.get(3, 3), 16.0);
}

// ---- LinearSolver: every method, fallbacks, Matrix Market round trip (issue 16) ----

#[cfg(feature = "study")]
use crate::bench::{solver_configs, BenchOptions};

/// Unsymmetric perturbation of the elastic grid system (as a softening tangent is).
fn unsymmetric_system(nx: usize, ny: usize) -> SparseMatrix {
    let (asm, mut blocks, _) = elastic_system(nx, ny);
    let mut rng = Rng(7);
    let scale = blocks[0][0];
    for blk in blocks.iter_mut() {
        for a in 0..8 {
            for b in (a + 1)..8 {
                blk[8 * a + b] += 0.2 * scale * rng.uniform();
            }
        }
    }
    asm.assemble(&blocks).unwrap()
}

fn lu_reference(k: &SparseMatrix, b: &[f64]) -> Vec<f64> {
    let mut s = DirectSolver::new(SolverPolicy::Lu);
    s.solve(k, false, b).unwrap()
}

/// Every configuration the bench runs (all orderings and variants, PCG, LDLᵀ with the
/// feature) agrees with faer LU to 1e-8 relative on an SPD elastic system; PCG to its
/// tolerance (error ≤ cond-bounded: checked through its true residual ≤ tol and the
/// solution difference ≤ 1e-6). Feature `study` (the bench's configurations).
#[cfg(feature = "study")]
#[test]
fn every_solver_agrees_with_lu_on_spd_system() {
    let (_, _, k) = elastic_system(24, 16);
    let b = random_rhs(k.n(), 5);
    let x_lu = lu_reference(&k, &b);
    let bench = BenchOptions {
        pcg_tolerance: 1e-12,
        ..Default::default()
    };
    let configs = solver_configs(true, k.n(), &bench);
    assert!(configs.len() >= 11, "{} configurations", configs.len());
    for (label, options) in configs {
        let mut s = LinearSolver::new(options).unwrap();
        s.factorize(&k, true).unwrap();
        let mut x = b.clone();
        let used = s.solve_in_place(&mut x).unwrap();
        let d = rel_diff(&x, &x_lu);
        let r = rel_residual(&k, &x, &b);
        assert!(s.warnings().is_empty(), "{label}: {:?}", s.warnings());
        assert_eq!(s.stats().fallbacks, 0, "{label}");
        if options.method == Method::Pcg {
            assert_eq!(used, Used::Pcg);
            assert!(r <= 1e-12, "{label}: residual {r:e}");
            assert!(d <= 1e-6, "{label}: difference to LU {d:e}");
            assert!(s.stats().pcg_iterations > 0);
        } else {
            assert!(d <= 1e-8, "{label}: difference to LU {d:e}");
            assert!(r <= 1e-10, "{label}: residual {r:e}");
        }
    }
}

/// Fill of the orderings: no reordering of a grid numbered row by row fills the band, AMD
/// and COLAMD much less; IC(0) keeps exactly the lower triangle of K; the simplicial
/// LU's L + U is at least the Cholesky factor's size (L + Lᵀ minus the diagonal).
#[test]
fn orderings_change_fill_not_the_answer() {
    let (_, _, k) = elastic_system(30, 30);
    let fill = |method, factorization, ordering| {
        let mut s = LinearSolver::new(LinearOptions {
            method,
            direct: SolverOptions {
                factorization,
                ordering,
                ..Default::default()
            },
            ..Default::default()
        })
        .unwrap();
        s.factorize(&k, true).unwrap();
        s.stats().factor_nnz.unwrap()
    };
    let amd = fill(Method::Cholesky, Factorization::Simplicial, Ordering::Amd);
    let identity = fill(
        Method::Cholesky,
        Factorization::Simplicial,
        Ordering::Identity,
    );
    let colamd = fill(
        Method::Cholesky,
        Factorization::Simplicial,
        Ordering::Colamd,
    );
    assert!(2 * identity > 3 * amd, "identity {identity} vs AMD {amd}");
    assert!(colamd < identity, "COLAMD {colamd} vs identity {identity}");
    let lu = fill(Method::Lu, Factorization::Simplicial, Ordering::Amd);
    assert!(lu >= 2 * amd - k.n(), "LU {lu} vs Cholesky {amd}");
    let lower = (k.nnz() + k.n()) / 2;
    let mut s = LinearSolver::new(LinearOptions {
        method: Method::Pcg,
        pcg: PcgOptions {
            preconditioner: Preconditioner::IncompleteCholesky,
            ..Default::default()
        },
        ..Default::default()
    })
    .unwrap();
    s.factorize(&k, true).unwrap();
    assert_eq!(s.stats().factor_nnz, Some(lower));
}

/// IC(0) of a tridiagonal SPD matrix is its exact Cholesky factor (no fill is dropped), so
/// PCG converges in one iteration.
#[test]
fn ic0_is_exact_without_fill() {
    let n = 50;
    let mut t = Vec::new();
    for i in 0..n {
        t.push((i, i, 4.0 + i as f64 * 0.01));
        if i + 1 < n {
            t.push((i, i + 1, -1.0));
            t.push((i + 1, i, -1.0));
        }
    }
    let k = SparseMatrix::from_triplets(n, &t).unwrap();
    let b = random_rhs(n, 3);
    let pcg = Pcg::new(
        &k,
        PcgOptions {
            preconditioner: Preconditioner::IncompleteCholesky,
            tolerance: 1e-12,
            max_iterations: 100,
        },
    )
    .unwrap();
    let out = pcg.solve(&k, &b).unwrap();
    assert_eq!(out.iterations, 1);
    assert!(out.residual <= 1e-12);
}

/// Check 3 at the solver level: PCG on a symmetric indefinite K breaks down (pᵀKp ≤ 0 or a
/// non-positive IC(0) pivot) with an error, and `LinearSolver` falls back to LU, counts it and
/// says so; Cholesky, PCG and LDLᵀ on an unsymmetric K are never applied (LU instead,
/// recorded), so every answer solves the system.
#[test]
fn inapplicable_methods_fall_back_with_a_warning() {
    let (asm, blocks, k0) = elastic_system(20, 12);
    let sigma = 0.37 * k0.get(0, 0);
    let k_indef = asm
        .assemble_with_diagonal(&blocks, Some(&vec![-sigma; asm.n_dofs()]))
        .unwrap();
    let b = random_rhs(k_indef.n(), 9);
    for preconditioner in [Preconditioner::Jacobi, Preconditioner::IncompleteCholesky] {
        let options = PcgOptions {
            preconditioner,
            tolerance: 1e-10,
            max_iterations: 5000,
        };
        let direct = Pcg::new(&k_indef, options).and_then(|p| p.solve(&k_indef, &b));
        assert!(
            matches!(direct, Err(SolverError::NotPositiveDefinite { .. })),
            "{preconditioner:?}: {direct:?}"
        );
        let mut s = LinearSolver::new(LinearOptions {
            method: Method::Pcg,
            pcg: options,
            ..Default::default()
        })
        .unwrap();
        s.factorize(&k_indef, true).unwrap();
        let mut x = b.clone();
        assert_eq!(s.solve_in_place(&mut x).unwrap(), Used::Lu);
        assert!(rel_residual(&k_indef, &x, &b) <= 1e-10);
        assert_eq!(s.stats().fallbacks, 1);
        assert!(
            s.warnings()[0].contains("not positive definite"),
            "{:?}",
            s.warnings()
        );
    }
    let k_unsym = unsymmetric_system(20, 12);
    let b = random_rhs(k_unsym.n(), 4);
    let mut methods = vec![Method::Cholesky, Method::Pcg];
    if Method::Ldl.available() {
        methods.push(Method::Ldl);
    }
    for method in methods {
        let mut s = LinearSolver::new(LinearOptions {
            method,
            ..Default::default()
        })
        .unwrap();
        assert_eq!(
            s.factorize(&k_unsym, false).unwrap(),
            Used::Lu,
            "{method:?}"
        );
        let mut x = b.clone();
        s.solve_in_place(&mut x).unwrap();
        assert!(rel_residual(&k_unsym, &x, &b) <= 1e-10, "{method:?}");
        assert_eq!(s.stats().fallbacks, 1, "{method:?}");
        assert!(
            s.warnings()[0].contains("unsymmetric"),
            "{:?}",
            s.warnings()
        );
    }
    // the unsymmetric system by every LU variant of the bench: agreement with faer LU
    #[cfg(feature = "study")]
    every_lu_variant_agrees_with_lu(&k_unsym, &b);
}

/// Every LU variant the bench runs (feature `study`) agrees with faer's LU on `k_unsym`.
#[cfg(feature = "study")]
fn every_lu_variant_agrees_with_lu(k_unsym: &SparseMatrix, b: &[f64]) {
    let x_lu = lu_reference(k_unsym, b);
    for (label, options) in solver_configs(false, k_unsym.n(), &BenchOptions::default()) {
        assert!(
            matches!(options.method, Method::Lu | Method::Multifrontal),
            "{label}"
        );
        let mut s = LinearSolver::new(options).unwrap();
        s.factorize(k_unsym, false).unwrap();
        let mut x = b.to_vec();
        s.solve_in_place(&mut x).unwrap();
        let d = rel_diff(&x, &x_lu);
        assert!(d <= 1e-8, "{label}: difference to LU {d:e}");
    }
}

/// Unsupported combinations are refused up front, naming the reason.
#[test]
fn lu_with_amd_needs_the_simplicial_variant() {
    let err = LinearSolver::new(LinearOptions {
        method: Method::Lu,
        direct: SolverOptions {
            ordering: Ordering::Amd,
            factorization: Factorization::Supernodal,
            ..Default::default()
        },
        ..Default::default()
    })
    .unwrap_err();
    assert!(matches!(err, SolverError::Unsupported(m) if m.contains("simplicial")));
    if !Method::Ldl.available() {
        assert!(LinearSolver::new(LinearOptions {
            method: Method::Ldl,
            ..Default::default()
        })
        .is_err());
    }
}

/// A system written in Matrix Market format reads back bit-identical (pattern, explicit
/// zeros, values, right-hand side, solution) with its JSON description.
#[test]
fn matrix_market_round_trip_is_exact() {
    let (_, _, mut k) = elastic_system(6, 5);
    // awkward values: an explicit zero, a subnormal, a long mantissa, a huge one
    let v = k.values_mut();
    v[3] = 0.0;
    v[5] = 1e-310;
    v[7] = std::f64::consts::PI * 1e17;
    v[9] = -1.0 / 3.0;
    let b = random_rhs(k.n(), 1);
    let x = lu_reference(&k, &b);
    let dir = std::env::temp_dir().join(format!("mpm-solvers-mm-{}", std::process::id()));
    let json = crate::mm::write_system(
        &dir,
        "sys",
        &k,
        &b,
        Some(&x),
        serde_json::json!({"symmetric": false, "step": 3}),
    )
    .unwrap();
    let back = crate::mm::read_system(&json).unwrap();
    assert_eq!(back.k.col_ptr(), k.col_ptr());
    assert_eq!(back.k.row_idx(), k.row_idx());
    let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(back.k.values()), bits(k.values()));
    assert_eq!(bits(&back.rhs), bits(&b));
    assert_eq!(bits(back.x.as_deref().unwrap()), bits(&x));
    assert_eq!(back.meta["step"], 3);
    assert_eq!(crate::mm::list_systems(&dir).unwrap(), vec![json]);
    #[cfg(feature = "study")]
    bench_reads_the_system(&dir);
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The bench harness (feature `study`) runs every LU variant on the system written by
/// [`matrix_market_round_trip_is_exact`], all in agreement with faer's LU.
#[cfg(feature = "study")]
fn bench_reads_the_system(dir: &std::path::Path) {
    let rows = crate::bench::run_bench(
        dir,
        &BenchOptions {
            repeats: 1,
            ..Default::default()
        },
        |_| {},
    )
    .unwrap();
    assert!(
        rows.iter().all(|r| !r.symmetric && r.status == "ok"),
        "{rows:?}"
    );
    assert!(rows.iter().all(|r| r.diff_to_lu <= 1e-8), "{rows:?}");
}

/// `lu_reuse`: the LU of one tangent solves the next (same pattern, values changed a
/// little) by GMRES to the tolerance; a tangent far from the factored one is factorised
/// anew after GMRES gives up; a new pattern is factorised at once.
#[test]
fn lu_reuse_solves_nearby_tangents_with_earlier_factors() {
    let (asm, blocks, _) = elastic_system(30, 20);
    let scaled = |factor: f64| {
        let blocks: Vec<Vec<f64>> = blocks
            .iter()
            .map(|blk| blk.iter().map(|v| v * factor).collect())
            .collect();
        asm.assemble(&blocks).unwrap()
    };
    // a stiffness change of 2 % in every other cell: near the factored K
    let nearby = {
        let blocks: Vec<Vec<f64>> = blocks
            .iter()
            .enumerate()
            .map(|(e, blk)| {
                blk.iter()
                    .map(|v| v * (1.0 + 0.02 * (e % 2) as f64))
                    .collect()
            })
            .collect();
        asm.assemble(&blocks).unwrap()
    };
    let mut s = LinearSolver::new(LinearOptions {
        method: Method::LuReuse,
        ..Default::default()
    })
    .unwrap();
    let solve = |s: &mut LinearSolver, k: &SparseMatrix, seed: u64| {
        let b = random_rhs(k.n(), seed);
        let used = s.factorize(k, false).unwrap();
        let mut x = b.clone();
        let solved = s.solve_in_place(&mut x).unwrap();
        (used, solved, rel_residual(k, &x, &b))
    };
    let (used, solved, r) = solve(&mut s, &scaled(1.0), 1);
    assert_eq!((used, solved), (Used::Lu, Used::Lu));
    assert!(r <= 1e-12, "fresh LU: residual {r:e}");
    let (used, solved, r) = solve(&mut s, &nearby, 2);
    assert_eq!((used, solved), (Used::LuReused, Used::LuReused));
    // GMRES stops at 1e-10 (checked on the true residual)
    assert!(r <= 1e-10, "reused LU: residual {r:e}");
    let stats = s.stats();
    assert_eq!((stats.numeric_lu, stats.reused_factors), (1, 1));
    println!(
        "GMRES steps with the factors of the nearby K: {}",
        stats.gmres_iterations
    );
    assert!(stats.gmres_iterations <= 6, "{stats:?}");
    // an unsymmetric perturbation as large as the stiffness itself: GMRES gives up, K is
    // factorised
    let far = {
        let mut rng = Rng(5);
        let scale = blocks[0][0];
        let blocks: Vec<[f64; 64]> = blocks
            .iter()
            .map(|blk| {
                let mut blk = *blk;
                for a in 0..8 {
                    for b in (a + 1)..8 {
                        blk[8 * a + b] += scale * rng.uniform();
                    }
                }
                blk
            })
            .collect();
        asm.assemble(&blocks).unwrap()
    };
    let (used, solved, r) = solve(&mut s, &far, 3);
    assert_eq!((used, solved), (Used::LuReused, Used::Lu));
    assert!(r <= 1e-12, "refactorised: residual {r:e}");
    assert_eq!(s.stats().gmres_refactorisations, 1);
    assert_eq!(s.stats().numeric_lu, 2);
    // another pattern: factorised without trying the old factors
    let other = elastic_system(20, 30).2;
    let (used, _, r) = solve(&mut s, &other, 4);
    assert_eq!(used, Used::Lu);
    assert!(r <= 1e-12);
    assert_eq!(s.stats().reused_factors, 1);
}

/// The multifrontal LU through [`LinearSolver`]: the same solution as faer's LU to round-off on
/// an unsymmetric system, the symbolic analysis made once for new values of the same
/// pattern, and a singular system handed to faer's LU (recorded), which reports it.
#[test]
fn multifrontal_agrees_with_faer_lu_and_hands_singular_systems_to_it() {
    let k = unsymmetric_system(30, 20);
    let b = random_rhs(k.n(), 9);
    let x_lu = lu_reference(&k, &b);
    let mut s = LinearSolver::new(LinearOptions {
        method: Method::Multifrontal,
        ..Default::default()
    })
    .unwrap();
    for scale in [1.0, 1.5] {
        let mut scaled = k.clone();
        scaled.values_mut().iter_mut().for_each(|v| *v *= scale);
        assert_eq!(s.factorize(&scaled, false).unwrap(), Used::Multifrontal);
        let mut x = b.clone();
        assert_eq!(s.solve_in_place(&mut x).unwrap(), Used::Multifrontal);
        x.iter_mut().for_each(|v| *v *= scale);
        let d = rel_diff(&x, &x_lu);
        assert!(d <= 5e-14, "difference to faer LU {d:e}");
    }
    let stats = s.stats();
    assert_eq!((stats.symbolic, stats.numeric, stats.fallbacks), (1, 2, 0));
    assert!(s.warnings().is_empty());

    // column 3 zeroed: structurally present, numerically singular
    let mut singular = k.clone();
    for j in 0..singular.n() {
        if let Some(p) = singular.position(3, j) {
            singular.values_mut()[p] = 0.0;
        }
    }
    let err = s.factorize(&singular, false).unwrap_err();
    assert!(
        matches!(
            err,
            SolverError::Singular {
                factor: FactorKind::Lu,
                ..
            }
        ),
        "{err}"
    );
    assert_eq!(s.stats().fallbacks, 1);
    assert!(
        s.warnings()[0].contains("multifrontal"),
        "{:?}",
        s.warnings()
    );
}

/// `Method::Auto` takes the multifrontal factorisation, Cholesky fronts for a symmetric K and LU
/// fronts for an unsymmetric one, and faer's Cholesky or LU when the options ask for one of
/// faer's orderings or factorisations. Each answer solves its system to round-off.
#[test]
fn auto_routes_systems_to_the_multifrontal_factorisation() {
    let (_, _, k_spd) = elastic_system(20, 12);
    let k_unsym = unsymmetric_system(20, 12);
    let b = random_rhs(k_spd.n(), 11);
    let faer_amd = SolverOptions {
        factorization: Factorization::Simplicial,
        ordering: Ordering::Amd,
        ..Default::default()
    };
    let default = SolverOptions::default();
    // (K, symmetric, options, solver used, factorisation counted as Cholesky)
    let cases = [
        (&k_spd, true, default, Used::Multifrontal, true),
        (&k_unsym, false, default, Used::Multifrontal, false),
        (&k_spd, true, faer_amd, Used::Cholesky, true),
        (&k_unsym, false, faer_amd, Used::Lu, false),
    ];
    for (k, symmetric, direct, expected, cholesky) in cases {
        let mut s = LinearSolver::new(LinearOptions {
            method: Method::Auto,
            direct,
            ..Default::default()
        })
        .unwrap();
        assert_eq!(s.factorize(k, symmetric).unwrap(), expected);
        let mut x = b.clone();
        assert_eq!(s.solve_in_place(&mut x).unwrap(), expected);
        let r = rel_residual(k, &x, &b);
        // measured: 3.0e-15 (Cholesky, multifrontal) and 6.5e-15 (LU)
        assert!(r <= 3e-14, "{expected:?}: residual {r:e}");
        let stats = s.stats();
        assert_eq!(stats.fallbacks, 0, "{expected:?}");
        // every factorisation is counted by its kind, the multifrontal ones too
        let counts = (stats.numeric_cholesky, stats.numeric_lu);
        let one = if cholesky { (1, 0) } else { (0, 1) };
        assert_eq!(counts, one, "{expected:?}, Cholesky {cholesky}");
    }
}

/// Measurement (ignored; feature `study`): faer's conjugate gradient ([`Pcg::solve_faer`])
/// against the hand-written [`Pcg::solve`], medians of 7 solves, on the elastic grid systems and
/// the indefinite one of `inapplicable_methods_fall_back_with_a_warning`:
/// `cargo test --release -p mpm-solvers --features study --lib measure_pcg -- --ignored
/// --nocapture --test-threads=1`.
#[cfg(feature = "study")]
#[test]
#[ignore]
fn measure_pcg_faer_against_hand_written() {
    let median = |mut v: Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let mut cases: Vec<(String, SparseMatrix)> = [(40, 40), (100, 100), (200, 150)]
        .iter()
        .map(|&(nx, ny)| (format!("grid {nx}x{ny}"), elastic_system(nx, ny).2))
        .collect();
    let (asm, blocks, k0) = elastic_system(20, 12);
    let sigma = 0.37 * k0.get(0, 0);
    cases.push((
        "indefinite 20x12".into(),
        asm.assemble_with_diagonal(&blocks, Some(&vec![-sigma; asm.n_dofs()]))
            .unwrap(),
    ));
    for (name, k) in &cases {
        let b = random_rhs(k.n(), 5);
        for preconditioner in [Preconditioner::Jacobi, Preconditioner::IncompleteCholesky] {
            let options = PcgOptions {
                preconditioner,
                tolerance: 1e-10,
                max_iterations: 10_000,
            };
            let Ok(pcg) = Pcg::new(k, options) else {
                println!("{name} {preconditioner:?}: preconditioner refused");
                continue;
            };
            for (label, faer) in [("hand", false), ("faer", true)] {
                let mut times = Vec::new();
                let mut what = String::new();
                for _ in 0..7 {
                    let t = std::time::Instant::now();
                    let r = if faer {
                        pcg.solve_faer(k, &b)
                    } else {
                        pcg.solve(k, &b)
                    };
                    times.push(t.elapsed().as_secs_f64());
                    what = match r {
                        Ok(o) => format!("{} it, residual {:.2e}", o.iterations, o.residual),
                        Err(e) => format!("{e}"),
                    };
                }
                println!(
                    "{name} n={} {preconditioner:?} {label}: {:.2} ms, {what}",
                    k.n(),
                    1e3 * median(times)
                );
            }
        }
    }
}

/// Feature `study`: faer's conjugate gradient ([`Pcg::solve_faer`]) takes the iterations of
/// the hand-written one (±1) to the same true residual, and reports an indefinite K.
#[cfg(feature = "study")]
#[test]
fn faer_conjugate_gradient_matches_the_hand_written_one() {
    let (asm, blocks, k) = elastic_system(30, 20);
    let b = random_rhs(k.n(), 5);
    for preconditioner in [Preconditioner::Jacobi, Preconditioner::IncompleteCholesky] {
        let options = PcgOptions {
            preconditioner,
            tolerance: 1e-10,
            max_iterations: 5000,
        };
        let pcg = Pcg::new(&k, options).unwrap();
        let (hand, faer) = (pcg.solve(&k, &b).unwrap(), pcg.solve_faer(&k, &b).unwrap());
        assert!(
            hand.iterations.abs_diff(faer.iterations) <= 1,
            "{preconditioner:?}: {} against {}",
            hand.iterations,
            faer.iterations
        );
        assert!(faer.residual <= 1e-10 && hand.residual <= 1e-10);
        assert!(rel_diff(&faer.x, &hand.x) <= 1e-6);
    }
    let sigma = 0.37 * k.get(0, 0);
    let k_indef = asm
        .assemble_with_diagonal(&blocks, Some(&vec![-sigma; asm.n_dofs()]))
        .unwrap();
    let pcg = Pcg::new(&k_indef, PcgOptions::default()).unwrap();
    let err = pcg.solve_faer(&k_indef, &b).unwrap_err();
    assert!(
        matches!(err, SolverError::NotPositiveDefinite { .. }),
        "{err:?}"
    );
}
