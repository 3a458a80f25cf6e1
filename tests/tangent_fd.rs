//! Tangent check (issue 3, check 4): the assembled stiffness, including the
//! driven-point penalty (DESIGN D41) and the Newmark mass term (D17), equals
//! a central finite-difference derivative of the residual, −∂R/∂Δu, to 1e−6
//! relative (max entry error over max |K|). The background term of D19 is
//! switched off here: by design it is in the tangent only, not in the residual.
//! Initial stress is zero: the geometric (initial-stress) stiffness is
//! neglected by design (DESIGN §2), so a prestressed state would differ by it.

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
