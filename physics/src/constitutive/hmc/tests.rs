use super::*;
use crate::constitutive::flow_rule::strain_norm_f64;
use crate::constitutive::yield_surface::stress_from_invariants;

/// (label, model, σ_n, Δε, κ_n, strength variable) of the tangent check.
type TangentCase<'a> = (String, &'a Hmc, Voigt, Voigt, f64, StrengthVariable);

fn model(edit: impl FnOnce(&mut HmcParameters)) -> Hmc {
    let mut p = HmcParameters::table1();
    edit(&mut p);
    Hmc::new(p).expect("valid parameters")
}

/// Table 1 without any softening (c_post = c_ini, φ_res = φ_peak).
fn perfectly_plastic(omega: f64) -> Hmc {
    model(|p| {
        p.cohesion_post = p.cohesion_ini;
        p.friction_angle_res = p.friction_angle_peak;
        p.softening_rate_post = 0.0;
        p.softening_rate_res = 0.0;
        p.omega = omega;
    })
}

fn isotropic(p: f64) -> Voigt {
    [-p, -p, -p, 0.0]
}

fn add(a: &Voigt, b: &Voigt) -> Voigt {
    std::array::from_fn(|i| a[i] + b[i])
}

fn scale(a: &Voigt, k: f64) -> Voigt {
    a.map(|x| x * k)
}

/// Smallest factor t such that σ0 + D (t·dir) reaches f = 0 (bisection on the elastic trial).
fn elastic_limit(model: &Hmc, stress0: &Voigt, direction: &Voigt) -> f64 {
    let d = model.elastic_stiffness();
    let f =
        |t: f64| model.yield_function(&add(stress0, &mat4_mul_vec(&d, &scale(direction, t))), 0.0);
    let (mut lo, mut hi) = (0.0, 1.0);
    while f(hi) < 0.0 {
        hi *= 2.0;
    }
    for _ in 0..100 {
        let mid = 0.5 * (lo + hi);
        if f(mid) < 0.0 {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    hi
}

/// Run a proportional strain path in `n` equal increments (local mode).
fn proportional_path(model: &Hmc, stress0: &Voigt, total: &Voigt, n: usize) -> (Voigt, PointState) {
    let mut stress = *stress0;
    let mut state = PointState::default();
    let inc = scale(total, 1.0 / n as f64);
    for _ in 0..n {
        let u = model
            .update(&stress, &inc, &state, StrengthVariable::Local)
            .expect("update converges");
        stress = u.stress;
        state = u.state;
    }
    (stress, state)
}

/// Table 1 values (paper) and TOML keys; deny_unknown_fields rejects typos.
#[test]
fn table1_and_toml_keys() {
    let text = "E = 20000.0\nnu = 0.2\nphi_ini = 20.0\nphi_peak = 20.0\nphi_res = 15.0\nc_ini = 200.0\n\
                c_post = 0.0\npt_ini = 0.0\npt_post = 0.0\nb_post = 10.0\nb_res = 2.0\nomega = 1.0\n";
    let parsed: HmcParameters = toml::from_str(text).expect("parse");
    assert_eq!(parsed, HmcParameters::table1());
    assert!(toml::from_str::<HmcParameters>(&format!("{text}phi_post = 3.0\n")).is_err());
    assert!(HmcParameters::table1().validate().is_empty());
}

/// validate() names each bad field by its TOML key.
#[test]
fn validation_messages_name_fields() {
    let mut p = HmcParameters::table1();
    p.youngs_modulus = -1.0;
    p.poisson_ratio = 0.5;
    p.friction_angle_ini = 25.0;
    p.friction_angle_res = 21.0;
    p.cohesion_post = 300.0;
    p.tensile_strength_ini = 1e4;
    p.omega = 1.5;
    let problems = p.validate();
    for key in ["E", "nu", "phi_ini", "phi_res", "c_post", "pt_ini", "omega"] {
        assert!(
            problems.iter().any(|problem| problem.key == key),
            "no message for {key}: {problems:?}"
        );
    }
    assert_eq!(problems.len(), 7, "{problems:?}");
    p = HmcParameters::table1();
    p.density = f64::NAN;
    assert_eq!(p.validate().len(), 1);
    assert!(Hmc::new(p).is_err());
}

/// D28 for Table 1: c = 200 e^{−10κ} (floored at 0.2 kPa), φ = 15° + 5° e^{−2κ}, p_t = 0, at three κ
/// (tolerance 1e-12 relative), and with p_t > 0 the three-level law of D28 for p_t.
#[test]
fn strength_follows_d28() {
    let m = model(|_| {});
    for kappa in [0.0, 0.1, 0.5, 2.0] {
        let s = m.strength_at(kappa);
        let c = (200.0 * (-10.0 * kappa).exp()).max(0.2);
        let phi = 15.0 + 5.0 * (-2.0 * kappa).exp();
        assert!(
            (s.cohesion - c).abs() <= 1e-12 * c,
            "κ = {kappa}: c = {}",
            s.cohesion
        );
        assert!(
            (s.friction_angle_deg - phi).abs() <= 1e-12 * phi,
            "κ = {kappa}: φ = {}",
            s.friction_angle_deg
        );
        assert_eq!(s.tensile_strength, 0.0);
    }
    let m = model(|p| {
        p.cohesion_post = 50.0;
        p.tensile_strength_ini = 100.0;
        p.tensile_strength_post = 40.0;
    });
    for kappa in [0.0, 0.1, 0.5] {
        let s = m.strength_at(kappa);
        let c = 50.0 * (-2.0 * kappa).exp() + 150.0 * (-10.0 * kappa).exp();
        let pt = 40.0 * (-2.0 * kappa).exp() + 60.0 * (-10.0 * kappa).exp();
        let phi = (15.0 + 5.0 * (-2.0 * kappa).exp()).to_radians();
        let pt = pt.min((c - 0.2) / phi.tan());
        assert!((s.cohesion - c).abs() <= 1e-12 * c);
        assert!(
            (s.tensile_strength - pt).abs() <= 1e-12 * pt,
            "κ = {kappa}: p_t = {} vs {pt}",
            s.tensile_strength
        );
    }
}

/// Symmetric tangent only for ω = 1 without softening; never elastic.
#[test]
fn tangent_symmetry_flag() {
    assert!(perfectly_plastic(1.0).has_symmetric_tangent());
    assert!(!perfectly_plastic(0.5).has_symmetric_tangent());
    assert!(!model(|_| {}).has_symmetric_tangent());
    // Softening possible only through p_t:
    let pt_only = model(|p| {
        p.cohesion_post = p.cohesion_ini;
        p.friction_angle_res = p.friction_angle_peak;
        p.tensile_strength_ini = 10.0;
    });
    assert!(!pt_only.has_symmetric_tangent());
    assert!(!model(|_| {}).is_elastic());
    // and the returned tangent is then symmetric (1e-10 relative), with and without sub-steps.
    let m = perfectly_plastic(1.0);
    for factor in [3.0, 300.0] {
        let dir = [0.2, -1.0, 0.0, 0.3];
        let inc = scale(&dir, factor * elastic_limit(&m, &isotropic(100.0), &dir));
        let u = m
            .update(
                &isotropic(100.0),
                &inc,
                &PointState::default(),
                StrengthVariable::Local,
            )
            .unwrap();
        assert!(u.yielded);
        let big = u
            .tangent
            .iter()
            .flatten()
            .fold(0.0f64, |a, x| a.max(x.abs()));
        for i in 0..4 {
            for j in 0..4 {
                assert!((u.tangent[i][j] - u.tangent[j][i]).abs() <= 1e-10 * big);
            }
        }
    }
}

/// After a plastic update |f| ≤ 1e-8 c_ref, Δε^p = Δε − C Δσ is parallel to m(σ_{n+1}, κ_{n+1})
/// (|cos − 1| ≤ 1e-10), Δκ = ‖Δε^p‖ε (1e-12), for several models, directions and both modes.
#[test]
fn return_is_on_surface_and_flow_is_normal() {
    let models = [
        model(|_| {}),
        perfectly_plastic(1.0),
        model(|p| p.omega = 0.3),
        model(|p| {
            p.cohesion_post = 50.0;
            p.tensile_strength_ini = 50.0;
            p.tensile_strength_post = 20.0;
        }),
    ];
    let directions = [
        [0.002, -0.01, 0.0, 0.0],
        [0.0, 0.0, 0.0, 0.02],
        [0.004, 0.003, 0.0, 0.001],
        [-0.003, 0.004, 0.0, 0.003],
    ];
    for m in &models {
        for dir in &directions {
            for frozen in [None, Some(0.05)] {
                let stress0 = isotropic(100.0);
                let state0 = PointState {
                    plastic_strain_eq: 0.02,
                    plastic_strain_eq_nonlocal: 0.02,
                    ..Default::default()
                };
                let dir = &scale(dir, 3.0 * elastic_limit(m, &stress0, dir));
                let u = m
                    .update(&stress0, dir, &state0, frozen.into())
                    .expect("converges");
                assert!(u.yielded, "direction {dir:?} should yield");
                let kappa_strength = frozen.unwrap_or(u.state.plastic_strain_eq);
                let f = m.yield_function(&u.stress, kappa_strength);
                assert!(f.abs() <= 1e-8 * m.strength_scale(), "f = {f}");
                let dsig: Voigt = std::array::from_fn(|i| u.stress[i] - stress0[i]);
                let c_dsig = mat4_mul_vec(&m.compliance, &dsig);
                let dep: Voigt = std::array::from_fn(|i| dir[i] - c_dsig[i]);
                let recorded: Voigt = std::array::from_fn(|i| u.state.plastic_strain[i]);
                for i in 0..4 {
                    assert!((dep[i] - recorded[i]).abs() <= 1e-10 * strain_norm_f64(&dep));
                }
                if u.state.plastic_strain_eq == state0.plastic_strain_eq {
                    continue;
                }
                let flow = m.flow_direction(&u.stress, kappa_strength);
                let dot: f64 = (0..4).map(|i| dep[i] * flow[i]).sum();
                let cos = dot
                    / (dep.iter().map(|x| x * x).sum::<f64>().sqrt()
                        * flow.iter().map(|x| x * x).sum::<f64>().sqrt());
                assert!((cos - 1.0).abs() <= 1e-10, "cos = {cos} for {dir:?}");
                let dk = u.state.plastic_strain_eq - state0.plastic_strain_eq;
                assert!((dk - strain_norm_f64(&dep)).abs() <= 1e-12, "Δκ = {dk}");
                match frozen {
                    None => assert_eq!(
                        u.state.plastic_strain_eq_nonlocal,
                        u.state.plastic_strain_eq
                    ),
                    Some(_) => assert_eq!(
                        u.state.plastic_strain_eq_nonlocal,
                        state0.plastic_strain_eq_nonlocal
                    ),
                }
            }
        }
    }
}

/// A strain increment 100× the elastic limit converges (through sub-stepping if needed) with
/// |f| ≤ 1e-8 c_ref, for compression, shear and extension directions, Table 1 softening.
#[test]
fn huge_increment_converges() {
    let m = model(|_| {});
    let stress0 = isotropic(100.0);
    for dir in [
        [0.0, -1.0, 0.0, 0.0],
        [0.0, 0.0, 0.0, 1.0],
        [0.5, -1.0, 0.0, 0.3],
        [1.0, 0.0, 0.0, 0.0],
    ] {
        let t = elastic_limit(&m, &stress0, &dir);
        let inc = scale(&dir, 100.0 * t);
        let (u, substeps) = m
            .update_with_substeps(
                &stress0,
                &inc,
                &PointState::default(),
                StrengthVariable::Local,
            )
            .expect("converges");
        let f = m.yield_function(&u.stress, u.state.plastic_strain_eq);
        assert!(f.abs() <= 1e-8 * m.strength_scale(), "f = {f}");
        assert!(u.stress.iter().all(|x| x.is_finite()));
        eprintln!(
            "direction {dir:?}: 100× elastic limit used {substeps} sub-step(s), κ = {}",
            u.state.plastic_strain_eq
        );
    }
}

/// Isotropic tension beyond the tip returns to the tip σ = p_t(1,1,1,0) with D_alg = 0.
#[test]
fn tip_return_in_tension() {
    let m = model(|p| {
        p.cohesion_post = 50.0;
        p.tensile_strength_ini = 30.0;
        p.tensile_strength_post = 30.0;
    });
    let u = m
        .update(
            &isotropic(10.0),
            &[0.01, 0.01, 0.01, 0.0],
            &PointState::default(),
            StrengthVariable::frozen(0.0),
        )
        .expect("tip");
    let pt = m.strength_at(0.0).tensile_strength;
    for i in 0..3 {
        assert!(
            (u.stress[i] - pt).abs() <= 1e-8 * m.strength_scale(),
            "{:?}",
            u.stress
        );
    }
    assert!(u.stress[3].abs() <= 1e-8 * m.strength_scale());
    assert!(u.tangent.iter().flatten().all(|&x| x == 0.0));
}

/// Without softening, one increment and 100 increments of the same proportional strain (10× the
/// elastic limit) agree within 1 % (relative to ‖σ‖∞). Paths: isochoric triaxial compression and
/// extension strain (θ = ±30° throughout) from σ0 = −1000(1,1,1,0) kPa, where the surface is close to
/// its straight asymptotic cone and backward Euler is exact for a straight cone (constant normal).
/// On strongly curved parts of the hyperbola the one-step closest-point projection differs more
/// (it is only first-order accurate in the path); see the softening test for the order.
#[test]
fn one_versus_many_increments_without_softening() {
    for omega in [1.0, 0.3] {
        let m = perfectly_plastic(omega);
        let stress0 = isotropic(1000.0);
        for dir in [[0.5, -1.0, 0.5, 0.0], [-0.5, 1.0, -0.5, 0.0]] {
            let total = scale(&dir, 10.0 * elastic_limit(&m, &stress0, &dir));
            let (one, _) = proportional_path(&m, &stress0, &total, 1);
            let (many, _) = proportional_path(&m, &stress0, &total, 100);
            let norm = many.iter().fold(0.0f64, |a, x| a.max(x.abs()));
            let diff = (0..4).fold(0.0f64, |a, i| a.max((one[i] - many[i]).abs()));
            eprintln!(
                "ω = {omega}, direction {dir:?}: relative difference {:.3e}",
                diff / norm
            );
            assert!(
                diff <= 0.01 * norm,
                "ω = {omega}, {dir:?}: one {one:?} vs many {many:?}"
            );
        }
    }
}

/// With softening (Table 1, local) the path error shrinks at first order (backward Euler):
/// e_N = ‖σ_N − σ_2N‖∞ for N = 8 … 128; the observed orders log2(e_N/e_2N) of the finest
/// three refinements lie in [0.8, 1.2].
#[test]
fn softening_path_converges_at_first_order() {
    let m = model(|_| {});
    let stress0 = isotropic(100.0);
    let total = [0.004, -0.08, 0.0, 0.0];
    let ns = [8usize, 16, 32, 64, 128];
    let results: Vec<Voigt> = ns
        .iter()
        .map(|&n| proportional_path(&m, &stress0, &total, n).0)
        .collect();
    let errors: Vec<f64> = results
        .windows(2)
        .map(|w| (0..4).fold(0.0f64, |a, i| a.max((w[0][i] - w[1][i]).abs())))
        .collect();
    let orders: Vec<f64> = errors.windows(2).map(|w| (w[0] / w[1]).log2()).collect();
    eprintln!("softening path: differences {errors:?}, observed orders {orders:?}");
    for order in &orders[orders.len() - 3..] {
        assert!((0.8..=1.2).contains(order), "orders {orders:?}");
    }
}

/// Consistent tangent (D32, chained through sub-steps) equals central differences of the full
/// update (η = 1e-6 ‖Δε‖-scaled) to 1e-5 relative (max-norm over the matrix) at ≥ 20 states:
/// elastic, plastic without softening, softening, near the tip, θ near ±30°, ω ∈ {1, 0.3},
/// local and nonlocal.
#[test]
fn consistent_tangent_matches_finite_differences() {
    let softening = model(|_| {});
    let soft_omega = model(|p| p.omega = 0.3);
    let ideal = perfectly_plastic(1.0);
    let ideal_omega = perfectly_plastic(0.3);
    let tensile = model(|p| {
        p.cohesion_post = 50.0;
        p.tensile_strength_ini = 40.0;
        p.tensile_strength_post = 20.0;
    });
    let models: [(&str, &Hmc); 5] = [
        ("table1", &softening),
        ("ω=0.3 soft", &soft_omega),
        ("ideal", &ideal),
        ("ideal ω=0.3", &ideal_omega),
        ("p_t", &tensile),
    ];
    let mut cases: Vec<TangentCase> = Vec::new();
    for (name, m) in models {
        for theta_deg in [29.9f64, -29.9, 0.0, 12.0] {
            let over_nonlocal = StrengthVariable::Nonlocal {
                neighbours: 0.03,
                own_weight: -0.3,
            };
            for strength in [
                StrengthVariable::Local,
                StrengthVariable::frozen(0.03),
                over_nonlocal,
            ] {
                // Start on (just inside) the surface at p = 150 kPa and push along the flow direction + shear.
                let theta = theta_deg.to_radians();
                let kappa0 = 0.01;
                let strength_k = match strength {
                    StrengthVariable::Local => kappa0,
                    StrengthVariable::Nonlocal { neighbours, .. } => neighbours,
                };
                let p = 150.0;
                let (mut lo, mut hi) = (0.0, 2000.0);
                for _ in 0..100 {
                    let mid = 0.5 * (lo + hi);
                    if m.yield_function(&stress_from_invariants(p, mid, theta), strength_k) > 0.0 {
                        hi = mid;
                    } else {
                        lo = mid;
                    }
                }
                let stress0 = stress_from_invariants(p, 0.98 * lo, theta);
                let flow = m.flow_direction(&stress0, strength_k);
                let inc: Voigt = std::array::from_fn(|i| {
                    2e-3 * flow[i] / strain_norm_f64(&flow) + [1e-4, -2e-4, 0.0, 3e-4][i]
                });
                cases.push((
                    format!("{name} θ={theta_deg} {strength:?}"),
                    m,
                    stress0,
                    inc,
                    kappa0,
                    strength,
                ));
            }
        }
        // Near the tip: small stress, expansion with some shear.
        let pt = m.strength_at(0.0).tensile_strength;
        cases.push((
            format!("{name} near tip"),
            m,
            [pt - 1.0, pt - 1.5, pt - 1.2, 0.2],
            [2e-4, 1.5e-4, 0.0, 1e-4],
            0.0,
            StrengthVariable::Local,
        ));
        // Elastic unloading.
        cases.push((
            format!("{name} elastic"),
            m,
            isotropic(100.0),
            [1e-4, -2e-4, 0.0, 1e-4],
            0.0,
            StrengthVariable::Local,
        ));
    }
    // A large increment that needs sub-stepping (the tangent is chained through the sub-steps).
    let big: Voigt = [0.0, -3.0, 0.0, 0.0];
    let t = elastic_limit(&softening, &isotropic(100.0), &big);
    cases.push((
        "sub-stepped".into(),
        &softening,
        isotropic(100.0),
        scale(&big, 100.0 * t),
        0.0,
        StrengthVariable::Local,
    ));
    assert!(cases.len() >= 20);
    let mut plastic_cases = 0;
    let mut worst_overall: f64 = 0.0;
    for (label, m, stress0, inc, kappa0, strength) in &cases {
        let state0 = PointState {
            plastic_strain_eq: *kappa0,
            plastic_strain_eq_nonlocal: *kappa0,
            ..Default::default()
        };
        let u = m.update(stress0, inc, &state0, *strength).expect("update");
        if u.yielded {
            plastic_cases += 1;
        }
        let eta = 1e-6 * strain_norm_f64(inc).max(1e-4);
        let mut worst: f64 = 0.0;
        let dmax = u
            .tangent
            .iter()
            .flatten()
            .fold(0.0f64, |a, x| a.max(x.abs()));
        for j in 0..4 {
            let (mut ip, mut im) = (*inc, *inc);
            ip[j] += eta;
            im[j] -= eta;
            let up = m
                .update(stress0, &ip, &state0, *strength)
                .expect("update +");
            let um = m
                .update(stress0, &im, &state0, *strength)
                .expect("update −");
            for i in 0..4 {
                let fd = (up.stress[i] - um.stress[i]) / (2.0 * eta);
                worst = worst.max((fd - u.tangent[i][j]).abs());
            }
        }
        let rel = worst / dmax;
        worst_overall = worst_overall.max(rel);
        assert!(
            rel <= 1e-5,
            "{label}: tangent error {rel:e} (yielded {})",
            u.yielded
        );
    }
    let (_, substeps) = softening
        .update_with_substeps(
            &isotropic(100.0),
            &scale(&big, 100.0 * t),
            &PointState::default(),
            StrengthVariable::Local,
        )
        .unwrap();
    eprintln!("tangent check: {} cases, worst relative error {worst_overall:.2e}; large case used {substeps} sub-steps", cases.len());
    assert!(substeps > 1);
    assert!(plastic_cases >= 20, "only {plastic_cases} plastic cases");
}

/// The theory's first proposal (§5.6): second derivatives by central differences of the analytic m
/// (η = 1e−6 max(‖σ‖∞, c_ref)) and of f, m, h in κ (η_κ = 1e−7 max(κ, 1e−4)).
fn linearise_fd(m: &Hmc, stress: &Voigt, kappa: f64) -> ([[f64; 4]; 4], Voigt, f64) {
    let eta = 1e-6
        * stress
            .iter()
            .fold(m.strength_scale(), |a, x| a.max(x.abs()));
    let mut m_sigma = [[0.0; 4]; 4];
    for j in 0..4 {
        let (mut sp, mut sm) = (*stress, *stress);
        sp[j] += eta;
        sm[j] -= eta;
        let (mp, mm) = (m.flow_direction(&sp, kappa), m.flow_direction(&sm, kappa));
        for i in 0..4 {
            m_sigma[i][j] = (mp[i] - mm[i]) / (2.0 * eta);
        }
    }
    let eta_k = 1e-7 * kappa.max(1e-4);
    let (mp, mm) = (
        m.flow_direction(stress, kappa + eta_k),
        m.flow_direction(stress, kappa - eta_k),
    );
    let m_kappa = std::array::from_fn(|i| (mp[i] - mm[i]) / (2.0 * eta_k));
    let f_kappa = (m.yield_function(stress, kappa + eta_k)
        - m.yield_function(stress, kappa - eta_k))
        / (2.0 * eta_k);
    (m_sigma, m_kappa, f_kappa)
}

/// The exact dual-number second derivatives agree with the central differences of theory §5.6 to 1e-5
/// (relative to the largest entry) at several states; also prints the cost of both.
#[test]
fn dual_second_derivatives_match_central_differences() {
    let models = [model(|_| {}), model(|p| p.omega = 0.3)];
    let states = [
        ([-100.0, -650.0, -210.0, 0.0], 0.05),
        ([-80.0, -300.0, -150.0, 60.0], 0.2),
        (
            stress_from_invariants(200.0, 150.0, 29.5f64.to_radians()),
            0.01,
        ),
        (
            stress_from_invariants(200.0, 150.0, -29.5f64.to_radians()),
            0.3,
        ),
    ];
    for m in &models {
        for (stress, kappa) in &states {
            let lin = m.linearise(stress, *kappa, StrengthArg::LOCAL);
            let (m_sigma, m_kappa, f_kappa) = linearise_fd(m, stress, *kappa);
            let big = lin
                .m_sigma
                .iter()
                .flatten()
                .fold(0.0f64, |a, x| a.max(x.abs()));
            for (dual_row, fd_row) in lin.m_sigma.iter().zip(&m_sigma) {
                for (exact, fd) in dual_row.iter().zip(fd_row) {
                    assert!((exact - fd).abs() <= 1e-5 * big);
                }
            }
            let big_k = lin.m_kappa.iter().fold(1e-12f64, |a, x| a.max(x.abs()));
            for (exact, fd) in lin.m_kappa.iter().zip(&m_kappa) {
                assert!((exact - fd).abs() <= 1e-5 * big_k);
            }
            assert!((lin.f_kappa - f_kappa).abs() <= 1e-5 * f_kappa.abs().max(1e-9));
        }
    }
    let m = &models[0];
    let (stress, kappa) = states[1];
    let n = 20_000;
    let start = std::time::Instant::now();
    let mut acc = 0.0;
    for k in 0..n {
        acc += m
            .linearise(&stress, kappa + 1e-9 * k as f64, StrengthArg::LOCAL)
            .m_sigma[1][1];
    }
    let dual = start.elapsed().as_secs_f64() / n as f64;
    let start = std::time::Instant::now();
    for k in 0..n {
        let (ms, mk, fk) = linearise_fd(m, &stress, kappa + 1e-9 * k as f64);
        acc += ms[1][1] + mk[0] + fk + m.flow_direction(&stress, kappa)[0];
    }
    let fd = start.elapsed().as_secs_f64() / n as f64;
    eprintln!(
        "second derivatives: dual {:.0} ns, central differences {:.0} ns per evaluation ({acc:e})",
        dual * 1e9,
        fd * 1e9
    );
}

/// Robustness sweep: 4000 pseudo-random admissible start states and increments (up to 20× the
/// elastic strain scale, tension and compression, local and nonlocal, four models) all return a
/// finite stress with f ≤ 1e-8 c_ref (or, in the allowed cases, a ReturnMappingFailed error; the
/// count of those must be 0 here). The tangent-free update of explicit steps
/// ([`ConstitutiveModel::update_stress`]) returns the same bits as the full one, local,
/// frozen and over-nonlocal (m = 1.1).
#[test]
fn robustness_sweep() {
    let models = [
        model(|_| {}),
        model(|p| p.omega = 0.0),
        model(|p| {
            p.cohesion_post = 50.0;
            p.tensile_strength_ini = 100.0;
            p.tensile_strength_post = 40.0;
        }),
        perfectly_plastic(0.5),
    ];
    let mut seed: u64 = 12345;
    let mut uniform = || {
        seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((seed >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
    };
    let mut failures = Vec::new();
    for k in 0..4000 {
        let m = &models[k % models.len()];
        let kappa0 = 0.5 * (uniform() + 1.0) * if k % 3 == 0 { 0.0 } else { 0.4 };
        let frozen = if k % 2 == 0 {
            None
        } else {
            Some(kappa0 + 0.1 * (uniform() + 1.0))
        };
        // Start: a random stress scaled back onto or inside the surface at κ̄ (or κ).
        let p0 = 300.0 * (uniform() + 1.0);
        let mut stress0 = [
            -p0 + 150.0 * uniform(),
            -p0 + 150.0 * uniform(),
            -p0 + 150.0 * uniform(),
            100.0 * uniform(),
        ];
        let kappa_strength = frozen.unwrap_or(kappa0);
        let tip = m.strength_at(kappa_strength).tensile_strength;
        let mut shrink = 1.0;
        while m.yield_function(&stress0, kappa_strength) > 0.0 && shrink > 1e-6 {
            shrink *= 0.8;
            stress0 = std::array::from_fn(|i| {
                (stress0[i] - if i < 3 { tip } else { 0.0 }) * 0.8 + if i < 3 { tip } else { 0.0 }
            });
        }
        let size = 0.02 * (uniform() + 1.0);
        let inc = [
            size * uniform(),
            size * uniform(),
            0.5 * size * uniform(),
            size * uniform(),
        ];
        let state0 = PointState {
            plastic_strain_eq: kappa0,
            plastic_strain_eq_nonlocal: kappa0,
            ..Default::default()
        };
        match m.update(&stress0, &inc, &state0, frozen.into()) {
            Ok(u) => {
                // the explicit steps' update, without the tangent, gives the same bits
                let (mut stress, mut state) = ([f64::NAN; 4], PointState::default());
                let yielded = m
                    .update_stress(
                        &stress0,
                        &inc,
                        &state0,
                        frozen.into(),
                        (&mut stress, &mut state),
                    )
                    .expect("the update with the tangent succeeded");
                assert_eq!(yielded, u.yielded, "case {k}");
                assert_eq!(
                    stress.map(f64::to_bits),
                    u.stress.map(f64::to_bits),
                    "case {k}"
                );
                assert_eq!(state, u.state, "case {k}");
                // and so does the over-nonlocal update (m = 1.1), which solves for κ
                let over = StrengthVariable::Nonlocal {
                    neighbours: frozen.unwrap_or(kappa0),
                    own_weight: -0.1,
                };
                if let Ok(full) = m.update(&stress0, &inc, &state0, over) {
                    let mut no_tangent = (stress, state);
                    m.update_stress(
                        &stress0,
                        &inc,
                        &state0,
                        over,
                        (&mut no_tangent.0, &mut no_tangent.1),
                    )
                    .expect("the update with the tangent succeeded");
                    assert_eq!(
                        no_tangent.0.map(f64::to_bits),
                        full.stress.map(f64::to_bits),
                        "case {k}, m = 1.1"
                    );
                    assert_eq!(no_tangent.1, full.state, "case {k}, m = 1.1");
                }
                let f = m.yield_function(&u.stress, frozen.unwrap_or(u.state.plastic_strain_eq));
                assert!(f <= 1e-8 * m.strength_scale(), "case {k}: f = {f}");
                assert!(u
                    .stress
                    .iter()
                    .chain(u.tangent.iter().flatten())
                    .all(|x| x.is_finite()));
                assert!(u.state.plastic_strain_eq >= kappa0);
            }
            Err(e) => failures.push((k, e)),
        }
    }
    assert!(
        failures.is_empty(),
        "{} failures, first: {:?}",
        failures.len(),
        failures.first()
    );
}

/// D22 elastic branch: tangent = D, stress = σ + DΔε, state unchanged.
#[test]
fn elastic_branch_is_exact() {
    let m = model(|_| {});
    let inc = [1e-5, -2e-5, 0.0, 1e-5];
    let u = m
        .update(
            &isotropic(100.0),
            &inc,
            &PointState::default(),
            StrengthVariable::Local,
        )
        .unwrap();
    assert!(!u.yielded);
    assert_eq!(u.tangent, m.elastic_stiffness());
    let expected = add(
        &isotropic(100.0),
        &mat4_mul_vec(&m.elastic_stiffness(), &inc),
    );
    assert_eq!(u.stress, expected);
    assert_eq!(u.state, PointState::default());
    assert!(matches!(
        m.update(
            &[f64::NAN, 0.0, 0.0, 0.0],
            &inc,
            &PointState::default(),
            StrengthVariable::Local
        ),
        Err(ConstitutiveError::NonFinite(_))
    ));
}

/// theory D39: a stress outside the surface is returned onto it (|f| ≤ 1e−9 of
/// the strength scale) with its mean stress and Lode angle unchanged; a stress
/// inside is untouched; beyond the apex it goes to the tip.
#[test]
fn projection_after_double_mapping_keeps_p_and_theta() {
    let hmc = Hmc::new(HmcParameters::table1()).unwrap();
    let state = PointState {
        plastic_strain_eq: 0.05,
        ..Default::default()
    };
    let outside = [-900.0, -150.0, -300.0, 120.0];
    let projected = hmc.project_to_surface(&outside, &state, None);
    let f = hmc.yield_function(&projected, 0.05);
    assert!(f.abs() <= 1e-9 * hmc.strength_scale(), "f = {f}");
    let (a, b) = (
        Invariants::of(&outside, 1e-10),
        Invariants::of(&projected, 1e-10),
    );
    assert!((a.mean_stress - b.mean_stress).abs() < 1e-9 * a.mean_stress.abs());
    assert!((a.sin_3theta - b.sin_3theta).abs() < 1e-9);
    assert!(b.j < a.j);
    let inside = [-200.0, -210.0, -205.0, 1.0];
    assert_eq!(hmc.project_to_surface(&inside, &state, None), inside);
    let tension = [50.0, 40.0, 45.0, 3.0];
    let pt = hmc.strength_at(0.05).tensile_strength;
    assert_eq!(
        hmc.project_to_surface(&tension, &state, None),
        [pt, pt, pt, 0.0]
    );
}

/// A large tensile increment in a softened local point (a state met in the fragmenting band of
/// `validation/biaxial/local_h500.toml`): from the trial state the Newton iteration creeps
/// towards the apex and exhausts its iterations (theory §5.6 then sub-steps); with the
/// `apex_start` option, started at the apex ([`Hmc::apex_start`]), it converges in the one
/// step, to a closest-point projection (D29 holds at the result) whose consistent tangent
/// matches finite differences.
#[test]
fn apex_start_rescues_a_creeping_return() {
    let as_written = model(|_| {});
    let m = model(|p| p.apex_start = true);
    let stress_n: Voigt = [-150.0, -400.0, -120.0, 50.0];
    let trial: Voigt = [13038.956, 4305.750, 3382.195, 4490.950];
    let diff: Voigt = std::array::from_fn(|i| trial[i] - stress_n[i]);
    let increment = mat4_mul_vec(&m.compliance, &diff);
    let kappa_n = 5.9048e-3;
    let state_n = PointState {
        plastic_strain_eq: kappa_n,
        plastic_strain_eq_nonlocal: kappa_n,
        ..Default::default()
    };
    let arg = StrengthArg::LOCAL;
    let trial = add(&stress_n, &mat4_mul_vec(&m.stiffness, &increment));
    let tolerance = (NEWTON_TOLERANCE * m.strength_scale()).max(1e-13 * 13039.0);
    let from_trial = NewtonStart {
        stress: trial,
        kappa: kappa_n,
        multiplier: 0.0,
    };
    assert!(
        m.plastic_step((&trial, kappa_n), arg, tolerance, from_trial, true)
            .is_err(),
        "the case no longer exercises the apex start"
    );
    let start = m
        .apex_start((&stress_n, &increment, &trial), kappa_n, arg)
        .expect("beyond the apex");
    assert!(m
        .plastic_step((&trial, kappa_n), arg, tolerance, start, true)
        .is_ok());

    // theory §5.6 as written sub-steps this update; with the option it takes one step
    let (_, substeps) = as_written
        .update_with_substeps(&stress_n, &increment, &state_n, StrengthVariable::Local)
        .expect("converges");
    assert!(substeps > 1, "{substeps} sub-steps without the option");
    let (u, substeps) = m
        .update_with_substeps(&stress_n, &increment, &state_n, StrengthVariable::Local)
        .expect("converges");
    assert_eq!(substeps, 1, "one step, no sub-stepping and no tip return");
    let kappa = u.state.plastic_strain_eq;
    // D29 at the result, within the return mapping's own tolerances (|f| ≤ 1e-11 c_ref,
    // |r_κ| ≤ 1e-12, ‖r_σ‖ E ≤ 1e-11 c_ref, i.e. 1e-13 in strain here): f = 0,
    // Δκ = ‖Δε^p‖ε and Δε^p = Δλ m (normality)
    let elastic = mat4_mul_vec(
        &m.compliance,
        &std::array::from_fn(|i| u.stress[i] - stress_n[i]),
    );
    let plastic: Voigt = std::array::from_fn(|i| increment[i] - elastic[i]);
    let f = m.yield_function(&u.stress, kappa);
    assert!(
        f.abs() <= NEWTON_TOLERANCE * m.strength_scale(),
        "f = {f} kPa"
    );
    let plastic_norm = strain_norm_f64(&plastic);
    assert!(
        (kappa - kappa_n - plastic_norm).abs() <= KAPPA_TOLERANCE,
        "Δκ = {} against ‖Δε^p‖ = {plastic_norm}",
        kappa - kappa_n
    );
    let flow = m.flow_direction(&u.stress, kappa);
    let multiplier = plastic_norm / strain_norm_f64(&flow);
    for i in 0..4 {
        assert!(
            (plastic[i] - multiplier * flow[i]).abs() <= 1e-12 * plastic_norm,
            "Δε^p {plastic:?} against Δλ m {:?}",
            flow.map(|x| multiplier * x)
        );
    }
    // the consistent tangent of the one-step return, by central differences
    let eta = 1e-6 * strain_norm_f64(&increment);
    let dmax = u
        .tangent
        .iter()
        .flatten()
        .fold(0.0f64, |a, x| a.max(x.abs()));
    let mut worst: f64 = 0.0;
    for j in 0..4 {
        let (mut ip, mut im) = (increment, increment);
        ip[j] += eta;
        im[j] -= eta;
        let up = m
            .update(&stress_n, &ip, &state_n, StrengthVariable::Local)
            .unwrap();
        let um = m
            .update(&stress_n, &im, &state_n, StrengthVariable::Local)
            .unwrap();
        for i in 0..4 {
            let fd = (up.stress[i] - um.stress[i]) / (2.0 * eta);
            worst = worst.max((fd - u.tangent[i][j]).abs());
        }
    }
    let normality = (0..4).fold(0.0f64, |a, i| {
        a.max((plastic[i] - multiplier * flow[i]).abs())
    });
    eprintln!(
        "apex start: κ {kappa_n} → {kappa}, σ = {:?}, f = {f:.1e}, Δκ error {:.1e}, normality {:.1e}, tangent error {:.2e}",
        u.stress,
        (kappa - kappa_n - plastic_norm).abs() / plastic_norm,
        normality / plastic_norm,
        worst / dmax
    );
    assert!(worst / dmax <= 1e-8, "tangent error {:e}", worst / dmax);
}
