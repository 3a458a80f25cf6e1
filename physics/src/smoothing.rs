//! Double mapping of stresses (theory §7, paper §2.1: González Acosta et al.
//! 2020): the converged stress increment of a step is mapped mass-weighted to
//! the nodes and interpolated back, which reduces the cell-crossing stress
//! oscillations of the MPM (on `validation/elastic/soft_column.toml` it halves
//! their RMS). Applied once per converged step, after the constitutive update
//! and before the points move; state variables (κ, κ̄) are not smoothed.
//! The smoothed state is no longer in equilibrium; [`restore_internal_forces`]
//! (optional) gives the internal forces back.

use std::sync::Arc;

use mpm_solvers::{Assembler, DirectSolver, SolverError, SolverOptions, SolverPolicy};

use crate::constitutive::{ConstitutiveModel, Mat4, PointState, Voigt};
use crate::dofs::DofMap;
use crate::grid::{Grid, ShapeAt, MAX_SUPPORT};
use crate::scene::DoubleMapping;
use crate::stiffness;
use crate::transfer::{self, ParticleBins, NONE};

/// What restores equilibrium after smoothing: the point volumes V_p(n) and the
/// free dofs of the step (see [`restore_internal_forces`]).
pub struct Equilibrium<'a> {
    /// V_p(n), m² per metre run.
    pub volume: &'a [f64],
    /// Free dofs of the active nodes.
    pub dofs: &'a DofMap,
}

/// The points and grid a double mapping runs on: the shape functions of the
/// step (at the start-of-step positions) and the point masses.
pub struct MappingFrame<'a> {
    /// The background grid.
    pub grid: &'a Grid,
    /// Points sorted by cell.
    pub bins: &'a ParticleBins,
    /// Shape functions of every point.
    pub shapes: &'a [ShapeAt],
    /// Point masses, t per metre run.
    pub mass: &'a [f64],
}

/// First mapping of D37: the lumped mass-weighted nodal average
/// v̂_i = Σ_p N_ip m_p v_p / Σ_p N_ip m_p of a point field of Voigt vectors
/// (zero at inactive nodes).
pub fn project_to_nodes(frame: &MappingFrame, value: impl Fn(usize) -> Voigt + Sync) -> Vec<Voigt> {
    let weighted = transfer::scatter::<5, _>(frame.grid, frame.bins, frame.shapes, |p| {
        let s = &frame.shapes[p];
        let v = value(p);
        let mut c = [[0.0; 5]; MAX_SUPPORT];
        for a in s.support() {
            let w = s.n[a] * frame.mass[p];
            for k in 0..4 {
                c[a][k] = w * v[k];
            }
            c[a][4] = w;
        }
        c
    });
    weighted
        .iter()
        .map(|m| {
            if m[4] > 0.0 {
                [m[0] / m[4], m[1] / m[4], m[2] / m[4], m[3] / m[4]]
            } else {
                [0.0; 4]
            }
        })
        .collect()
}

/// Apply double mapping to `stress` (the converged σ(n+1) of every point, in
/// place), given the rotated start-of-step stresses `rotated` (σ^R(n)): the
/// smoothed quantity (increment or total) is projected onto the nodes (D37)
/// and interpolated back (D38); every smoothed stress that lies outside the
/// yield surface is then returned to it at fixed p and θ (theory D39) through
/// [`ConstitutiveModel::project_to_surface`]. With `equilibrium`, the internal
/// forces of the unsmoothed stresses are restored before D39
/// ([`restore_internal_forces`]).
///
/// # Errors
/// The solver error if the equilibrium system cannot be factorised.
#[allow(clippy::too_many_arguments)]
pub fn double_map(
    mode: DoubleMapping,
    frame: &MappingFrame,
    equilibrium: Option<Equilibrium>,
    rotated: &[Voigt],
    stress: &mut [Voigt],
    materials: &[Arc<dyn ConstitutiveModel>],
    material: &[u16],
    state: &[PointState],
    strength_kappa: Option<&[f64]>,
) -> Result<(), SolverError> {
    // `Auto` is resolved by the caller (`Model::double_mapping`).
    if matches!(mode, DoubleMapping::Off | DoubleMapping::Auto) {
        return Ok(());
    }
    let base = |p: usize| -> Voigt {
        match mode {
            DoubleMapping::Increment => rotated[p],
            _ => [0.0; 4],
        }
    };
    // D37: nodal values of Δσ (or σ)
    let nodal = {
        let stress: &[Voigt] = stress;
        project_to_nodes(frame, |p| {
            let b = base(p);
            std::array::from_fn(|k| stress[p][k] - b[k])
        })
    };
    // D38: σ_p ← σ^R_p + Σ_i N_ip Δσ̂_i
    let mut smoothed: Vec<Voigt> = (0..stress.len())
        .map(|p| {
            let s = &frame.shapes[p];
            let mut smoothed = base(p);
            for a in s.support() {
                let v = &nodal[s.nodes[a] as usize];
                for k in 0..4 {
                    smoothed[k] += s.n[a] * v[k];
                }
            }
            smoothed
        })
        .collect();
    if let Some(eq) = equilibrium {
        restore_internal_forces(frame, eq.volume, eq.dofs, stress, &mut smoothed)?;
    }
    // D39
    for (p, smoothed) in smoothed.into_iter().enumerate() {
        let model = &materials[material[p] as usize];
        stress[p] = if model.is_elastic() {
            smoothed
        } else {
            model.project_to_surface(&smoothed, &state[p], strength_kappa.map(|k| k[p]))
        };
    }
    Ok(())
}

/// Regularisation of GGᵀ relative to its largest diagonal entry: GGᵀ is only
/// semi-definite where a cell's points do not control all its displacement
/// modes, and the right-hand side has no component along those modes.
const EQUILIBRIUM_REGULARISATION: f64 = 1e-10;

/// Restore the internal forces of the unsmoothed stresses after smoothing, with
/// the smallest change of the smoothed field (an option beyond theory §7,
/// `[smoothing] restore_forces`; measured effects in `docs/scene.md`).
///
/// The internal force at the free dofs is f = G σ with G σ = Σ_p V_p B_pᵀ σ_p
/// (theory D11). Smoothing σ → σ̂ changes f, so the converged step would no
/// longer be in equilibrium and the next step's Newton iterations would add the
/// strain that restores it — a ratchet that accumulates with the number of steps.
/// The correction σ̃ = σ̂ + Gᵀλ, with (G Gᵀ) λ = G(σ − σ̂), is the least-squares
/// smallest change of σ̂ that gives back G σ̃ = G σ exactly; Gᵀλ at point p is
/// V_p B_p λ (σzz is not touched: it does not enter f).
///
/// `dofs` numbers the free dofs of the active nodes; constrained dofs carry
/// reactions and need no correction.
pub fn restore_internal_forces(
    frame: &MappingFrame,
    volume: &[f64],
    dofs: &DofMap,
    original: &[Voigt],
    smoothed: &mut [Voigt],
) -> Result<(), SolverError> {
    let n = dofs.n_free;
    if n == 0 {
        return Ok(());
    }
    let difference: Vec<Voigt> = original
        .iter()
        .zip(smoothed.iter())
        .map(|(o, s)| std::array::from_fn(|k| o[k] - s[k]))
        .collect();
    let nodal = transfer::internal_force(frame.grid, frame.bins, frame.shapes, volume, &difference);
    let mut rhs = vec![0.0; n];
    for (d, &index) in dofs.index.iter().enumerate() {
        if index != NONE {
            rhs[index as usize] = nodal[d / 2][d % 2];
        }
    }
    // G Gᵀ = Σ_p V_p² B_pᵀ B_p: the stiffness kernel with V² and D = diag(1, 1, 0, 1)
    let volume_squared: Vec<f64> = volume.iter().map(|v| v * v).collect();
    let identity: Mat4 = [
        [1.0, 0.0, 0.0, 0.0],
        [0.0, 1.0, 0.0, 0.0],
        [0.0, 0.0, 0.0, 0.0],
        [0.0, 0.0, 0.0, 1.0],
    ];
    let identities = vec![identity; volume.len()];
    let blocks = stiffness::cell_stiffness_blocks(
        frame.grid,
        frame.bins,
        frame.shapes,
        &volume_squared,
        &identities,
        None,
        None,
    );
    let blocks = stiffness::system_blocks(frame.grid, frame.bins, blocks, None);
    let element_dofs = dofs.element_dofs(frame.grid, frame.bins);
    let coupling = stiffness::patch_coupling(frame.grid, false);
    let assembler = Assembler::with_couplings(n, &element_dofs, coupling)?;
    let mut gram = assembler.assemble(&blocks)?;
    let max_diagonal = (0..n).map(|i| gram.get(i, i)).fold(0.0, f64::max);
    let shift = EQUILIBRIUM_REGULARISATION * max_diagonal.max(f64::MIN_POSITIVE);
    for i in 0..n {
        if let Some(k) = gram.position(i, i) {
            gram.values_mut()[k] += shift;
        }
    }
    let mut solver = DirectSolver::with_options(
        SolverPolicy::Cholesky,
        SolverOptions {
            pivot_ratio_tol: 0.0,
            ..SolverOptions::default()
        },
    );
    solver.factorize(&gram, true)?;
    solver.solve_in_place(&mut rhs)?;
    let mut lambda = vec![[0.0; 2]; frame.grid.node_count()];
    for (d, &index) in dofs.index.iter().enumerate() {
        if index != NONE {
            lambda[d / 2][d % 2] = rhs[index as usize];
        }
    }
    for (p, s) in smoothed.iter_mut().enumerate() {
        let g = transfer::gradient(&frame.shapes[p], &lambda);
        // V_p B_p λ: [∂x λx, ∂y λy, 0, ∂y λx + ∂x λy]
        s[0] += volume[p] * g[0];
        s[1] += volume[p] * g[3];
        s[3] += volume[p] * (g[1] + g[2]);
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bc::Constraints;
    use crate::constitutive::LinearElastic;

    /// 36 points scattered over a 3×3-cell grid, with masses and volumes.
    struct Cloud {
        grid: Grid,
        shapes: Vec<ShapeAt>,
        bins: ParticleBins,
        mass: Vec<f64>,
        volume: Vec<f64>,
    }

    fn cloud() -> Cloud {
        let grid = Grid::bilinear([0.0, 0.0], 0.5, [3, 3]);
        let positions: Vec<[f64; 2]> = (0..36)
            .map(|i| {
                let (a, b) = ((i % 6) as f64, (i / 6) as f64);
                [0.1 + 0.25 * a + 0.01 * b, 0.12 + 0.24 * b + 0.02 * a]
            })
            .collect();
        let shapes = transfer::shapes_at(&grid, &positions).unwrap();
        let bins = ParticleBins::new(&grid, &shapes);
        Cloud {
            mass: (0..36).map(|i| 1.0 + 0.1 * i as f64).collect(),
            volume: (0..36).map(|i| 0.06 + 0.001 * i as f64).collect(),
            grid,
            shapes,
            bins,
        }
    }

    fn frame(c: &Cloud) -> MappingFrame<'_> {
        MappingFrame {
            grid: &c.grid,
            bins: &c.bins,
            shapes: &c.shapes,
            mass: &c.mass,
        }
    }

    /// A uniform stress increment on top of a varying start stress is left
    /// unchanged to round-off (1e−12): the mass-weighted nodal projection
    /// reproduces uniform fields exactly.
    #[test]
    fn uniform_increment_is_unchanged_and_mass_weighting_is_exact() {
        let c = cloud();
        let rotated: Vec<Voigt> = (0..36)
            .map(|i| [-100.0 - i as f64, -50.0, -70.0, 3.0 * i as f64])
            .collect();
        let increment = [-5.0, 2.0, 1.0, -0.5];
        let mut stress: Vec<Voigt> = rotated
            .iter()
            .map(|r| std::array::from_fn(|k| r[k] + increment[k]))
            .collect();
        let expected = stress.clone();
        let materials: Vec<Arc<dyn ConstitutiveModel>> =
            vec![Arc::new(LinearElastic::new(1000.0, 0.3))];
        let state = vec![PointState::default(); 36];
        double_map(
            DoubleMapping::Increment,
            &frame(&c),
            None,
            &rotated,
            &mut stress,
            &materials,
            &[0; 36],
            &state,
            None,
        )
        .unwrap();
        for (s, e) in stress.iter().zip(&expected) {
            for k in 0..4 {
                assert!((s[k] - e[k]).abs() < 1e-12 * e[k].abs().max(1.0));
            }
        }
    }

    /// After smoothing an oscillating field, [`restore_internal_forces`] gives
    /// back the internal force Σ_p V_p B_pᵀ σ_p of the unsmoothed field at every
    /// free dof (relative 1e−8 of the force scale; the left and bottom edges are
    /// constrained and keep their changed reactions), and leaves σzz alone.
    #[test]
    fn restoring_forces_recovers_the_internal_force_at_free_dofs() {
        let c = cloud();
        let original: Vec<Voigt> = (0..36)
            .map(|i| {
                let wiggle = if i % 2 == 0 { 30.0 } else { -30.0 };
                [
                    -100.0 + wiggle,
                    -60.0 - 0.5 * wiggle,
                    -80.0,
                    10.0 + 0.3 * wiggle,
                ]
            })
            .collect();
        let nodal = project_to_nodes(&frame(&c), |p| original[p]);
        let mut smoothed: Vec<Voigt> = c
            .shapes
            .iter()
            .map(|s| {
                let mut v = [0.0; 4];
                for a in s.support() {
                    for k in 0..4 {
                        v[k] += s.n[a] * nodal[s.nodes[a] as usize][k];
                    }
                }
                v
            })
            .collect();
        let before = smoothed.clone();
        let mut constraints = Constraints {
            dof: vec![crate::bc::DofConstraint::Free; 2 * c.grid.node_count()],
        };
        for node in 0..c.grid.node_count() {
            let (i, j) = c.grid.node_ij(node);
            if i == 0 {
                constraints.dof[2 * node] = crate::bc::DofConstraint::Fixed;
            }
            if j == 0 {
                constraints.dof[2 * node + 1] = crate::bc::DofConstraint::Fixed;
            }
        }
        let dofs = DofMap::new(&c.bins, &constraints);
        restore_internal_forces(&frame(&c), &c.volume, &dofs, &original, &mut smoothed).unwrap();
        let f = |s: &[Voigt]| transfer::internal_force(&c.grid, &c.bins, &c.shapes, &c.volume, s);
        let (target, smoothed_force, restored) = (f(&original), f(&before), f(&smoothed));
        let scale = target.iter().flatten().fold(0.0f64, |m, v| m.max(v.abs()));
        let mut changed = 0.0f64;
        for (d, &index) in dofs.index.iter().enumerate() {
            if index == NONE {
                continue;
            }
            let (node, k) = (d / 2, d % 2);
            changed = changed.max((smoothed_force[node][k] - target[node][k]).abs());
            assert!(
                (restored[node][k] - target[node][k]).abs() <= 1e-8 * scale,
                "dof {d}: {} vs {}",
                restored[node][k],
                target[node][k]
            );
        }
        // the smoothing did change the forces, so the check is not empty
        assert!(
            changed > 1e-2 * scale,
            "smoothing changed forces by {changed}"
        );
        for (s, b) in smoothed.iter().zip(&before) {
            assert_eq!(s[2], b[2]);
        }
    }
}
