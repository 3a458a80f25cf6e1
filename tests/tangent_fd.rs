//! Tangent check (issue 3, check 4): the assembled stiffness, including the
//! driven-point penalty (theory D41) and the Newmark mass term (D17), equals
//! a central finite-difference derivative of the residual, −∂R/∂Δu, to 1e−6
//! relative (max entry error over max |K|). The background term of D19 is
//! switched off here: by design it is in the tangent only, not in the residual.
//! Initial stress is zero: the geometric (initial-stress) stiffness is
//! neglected by design (theory §2), so a prestressed state would differ by it.

mod common;

fn fd_check(path: &str, overrides: &[&str]) {
    let mut sim = common::simulation(path, overrides);
    let n = sim.unknowns().unwrap();
    // a deterministic, non-trivial increment of size ~1e-5 m
    let u: Vec<f64> = (0..n)
        .map(|i| 1e-5 * ((i as f64 * 0.7).sin() + 0.3))
        .collect();
    let (_, k) = sim.linearize(&u).unwrap();
    let eta = 1e-7;
    let mut worst = 0.0f64;
    let mut scale = 0.0f64;
    for j in 0..n {
        let mut up = u.clone();
        up[j] += eta;
        let mut um = u.clone();
        um[j] -= eta;
        let (rp, _) = sim.linearize(&up).unwrap();
        let (rm, _) = sim.linearize(&um).unwrap();
        for i in 0..n {
            let fd = -(rp[i] - rm[i]) / (2.0 * eta);
            worst = worst.max((fd - k.get(i, j)).abs());
            scale = scale.max(k.get(i, j).abs());
        }
    }
    println!(
        "{path}: {n} unknowns, max |K - K_fd| / max |K| = {:.3e}",
        worst / scale
    );
    assert!(
        worst <= 1e-6 * scale,
        "tangent mismatch {:.3e}",
        worst / scale
    );
}

#[test]
fn quasi_static_tangent_with_penalty_matches_finite_differences() {
    fd_check("elastic/platen.toml", &["solver.background_stiffness=0"]);
}

#[test]
fn dynamic_tangent_with_mass_term_matches_finite_differences() {
    fd_check(
        "elastic/bar_implicit.toml",
        &["solver.background_stiffness=0"],
    );
}

/// B-bar ([`mpm_physics::volumetric`] B3): the tangent Σ_p V_p B̄_pᵀ D B̄_p with
/// the penalty, against the residual of the averaged-mean-stress force (B4),
/// nearly incompressible (ν = 0.49), bilinear and GIMP (where B̄ couples the
/// whole 4 × 4 node patch).
#[test]
fn b_bar_tangent_matches_finite_differences() {
    for shapes in [
        vec!["grid.shape_functions=\"bilinear\""],
        vec![
            "grid.shape_functions=\"gimp\"",
            "grid.point_layout=\"uniform\"",
        ],
    ] {
        let mut overrides = vec![
            "solver.background_stiffness=0",
            "grid.volumetric=\"b_bar\"",
            "materials.soil.nu=0.49",
        ];
        overrides.extend(shapes);
        fd_check("elastic/platen.toml", &overrides);
    }
}

/// Softening plasticity with prestress and rotation: the biaxial specimen
/// (h = 1/300 m, local) after 150 steps, past the peak with a band forming. The
/// tangent — consistent algorithmic D_alg (theory D32), the spin term of the
/// Jaumann rotation, the penalty and the Newmark mass term — times a direction
/// d equals the central difference of the residual along d to 1e−4 relative
/// (measured 4–6e−5; without the spin term 1e−1; not exact because return mappings switch between elastic
/// and plastic branches within ±η at a few points).
#[test]
fn softening_tangent_with_rotation_matches_directional_differences() {
    let mut sim = common::simulation("biaxial/local_h300.toml", &["scene.steps=150"]);
    while !sim.finished() {
        sim.step_once().unwrap_or_else(|e| panic!("{e}"));
    }
    assert!(
        sim.model
            .state
            .particles
            .state
            .iter()
            .any(|s| s.plastic_strain_eq > 1e-3),
        "state must be plastic"
    );
    let n = sim.unknowns().unwrap();
    let u: Vec<f64> = (0..n)
        .map(|i| 2e-6 * ((i as f64 * 0.37).sin() - 0.2))
        .collect();
    let (_, k) = sim.linearize(&u).unwrap();
    for seed in 0..3 {
        let d: Vec<f64> = (0..n)
            .map(|i| ((i * 7 + seed * 13) as f64 * 0.91).cos())
            .collect();
        let eta = 1e-6;
        let plus: Vec<f64> = u.iter().zip(&d).map(|(a, b)| a + eta * b).collect();
        let minus: Vec<f64> = u.iter().zip(&d).map(|(a, b)| a - eta * b).collect();
        let (rp, _) = sim.linearize(&plus).unwrap();
        let (rm, _) = sim.linearize(&minus).unwrap();
        let mut kd = vec![0.0; n];
        k.mul_vec(&d, &mut kd);
        let err: f64 = rp
            .iter()
            .zip(&rm)
            .zip(&kd)
            .map(|((p, m), k)| (-(p - m) / (2.0 * eta) - k).powi(2))
            .sum::<f64>()
            .sqrt();
        let scale: f64 = kd.iter().map(|v| v * v).sum::<f64>().sqrt();
        println!("direction {seed}: |FD − K d| / |K d| = {:.3e}", err / scale);
        assert!(err <= 1e-4 * scale);
    }
}

/// B-bar with plasticity: the sharp-cone HMC footing on bilinear cells after
/// 12 steps (δ = 0.03 m, a plastic zone under the footing), linearised at the
/// third iterate of the 13th step's Newton loop (solved here by hand with the
/// assembled tangent): the tangent times a direction matches the residual's
/// central difference to 1e−4 relative, as for the softening case above.
/// Measured 2.9e−5 with B-bar and the same 2.9e−5 with the standard strain,
/// independent of η from 1e−7 to 1e−9 and also with c = 1e7 kPa (no
/// yielding): a floor of this prestressed, rotating footing state, not of
/// B-bar, and the reason Newton converges here at a fast linear rate rather
/// than quadratically (tests/prandtl_footing.rs shows B-bar's quadratic
/// Newton on von Mises).
#[test]
fn b_bar_plastic_tangent_matches_directional_differences() {
    let cot_phi = 1.0 / 20f64.to_radians().tan();
    let pt = format!("materials.soil.pt_ini={}", 0.999 * 100.0 * cot_phi);
    let mut sim = common::simulation(
        "footing_nosoft/footing_nosoft_h250.toml",
        &[
            &pt,
            "grid.volumetric=\"b_bar\"",
            "scene.steps=13",
            "solver.background_stiffness=0",
        ],
    );
    for _ in 0..12 {
        sim.step_once().unwrap_or_else(|e| panic!("{e}"));
    }
    let yielded = sim
        .model
        .state
        .particles
        .state
        .iter()
        .filter(|s| s.plastic_strain_eq > 0.0)
        .count();
    assert!(yielded > 20, "state must be plastic ({yielded} points)");
    let n = sim.unknowns().unwrap();
    let mut u = vec![0.0; n];
    let mut solver = mpm_solvers::DirectSolver::new(mpm_solvers::SolverPolicy::Lu);
    for _ in 0..2 {
        let (r, k) = sim.linearize(&u).unwrap();
        solver.factorize(&k, false).unwrap();
        let mut delta = r;
        solver.solve_in_place(&mut delta).unwrap();
        u.iter_mut().zip(&delta).for_each(|(a, b)| *a += b);
    }
    let (_, k) = sim.linearize(&u).unwrap();
    let d: Vec<f64> = (0..n).map(|i| (i as f64 * 0.91).cos()).collect();
    let eta = 1e-7;
    let shifted = |s: f64| -> Vec<f64> { u.iter().zip(&d).map(|(a, b)| a + s * b).collect() };
    let (rp, _) = sim.linearize(&shifted(eta)).unwrap();
    let (rm, _) = sim.linearize(&shifted(-eta)).unwrap();
    let mut kd = vec![0.0; n];
    k.mul_vec(&d, &mut kd);
    let err: f64 = rp
        .iter()
        .zip(&rm)
        .zip(&kd)
        .map(|((p, m), k)| (-(p - m) / (2.0 * eta) - k).powi(2))
        .sum::<f64>()
        .sqrt();
    let scale: f64 = kd.iter().map(|v| v * v).sum::<f64>().sqrt();
    println!(
        "B-bar plastic footing: |FD − K d| / |K d| = {:.3e}",
        err / scale
    );
    assert!(err <= 1e-4 * scale, "{:.3e}", err / scale);
}
