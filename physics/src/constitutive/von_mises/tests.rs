use super::*;
use crate::constitutive::j2;

/// E = 20 000 kPa, c = 50 kPa: G/c ≈ 170, a typical soft clay.
fn model(poisson_ratio: f64) -> VonMises {
    VonMises::new(VonMisesParameters {
        youngs_modulus: 20_000.0,
        poisson_ratio,
        density: 1.8,
        undrained_strength: 50.0,
    })
    .expect("valid parameters")
}

fn max_abs(values: impl IntoIterator<Item = f64>) -> f64 {
    values.into_iter().fold(0.0, |acc, x| acc.max(x.abs()))
}

fn update(model: &VonMises, stress: &Voigt, increment: &Voigt) -> StressUpdate {
    model
        .update(
            stress,
            increment,
            &PointState::default(),
            StrengthVariable::Local,
        )
        .expect("update")
}

/// Deterministic pseudo-random numbers in [−1, 1) (64-bit LCG, Knuth's MMIX constants).
struct Lcg(u64);

impl Lcg {
    fn next(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        (self.0 >> 11) as f64 / (1u64 << 52) as f64 - 1.0
    }

    fn voigt(&mut self, scale: f64) -> Voigt {
        std::array::from_fn(|_| scale * self.next())
    }
}

/// A stress inside the surface: mean −100 … 100 kPa, random deviator at √J₂ = 0 … 0.9 c.
fn stress_inside(rng: &mut Lcg, c: f64) -> Voigt {
    let mean = 100.0 * rng.next();
    let (_, s) = split(&rng.voigt(1.0));
    let radius = deviator_radius(&s);
    let target = 0.45 * (rng.next() + 1.0) * c;
    std::array::from_fn(|i| {
        let deviatoric = s[i] * target / radius;
        if i < 3 {
            mean + deviatoric
        } else {
            deviatoric
        }
    })
}

/// The plastic trial states of the tangent checks: (label, σ_n, Δε), each with √J₂(σ_tr) > c.
fn plastic_cases(model: &VonMises) -> Vec<(String, Voigt, Voigt)> {
    let c = model.undrained_strength();
    let strain = c / model.elastic.shear_modulus(); // strain at which the deviator reaches c
    let mut rng = Lcg(20_240_611);
    let mut cases = Vec::new();
    for k in 0..8 {
        let stress = stress_inside(&mut rng, c);
        // general increment, all four components
        cases.push((format!("general {k}"), stress, rng.voigt(4.0 * strain)));
        // shear-dominated, plane strain (Δεzz = 0)
        let mut shear = rng.voigt(0.3 * strain);
        shear[2] = 0.0;
        shear[3] = 5.0 * strain * if k % 2 == 0 { 1.0 } else { -1.0 };
        cases.push((format!("shear {k}"), stress, shear));
        // zz-dominated (out-of-plane) increment
        let mut zz = rng.voigt(0.3 * strain);
        zz[2] = 4.0 * strain * if k % 2 == 0 { 1.0 } else { -1.0 };
        cases.push((format!("zz {k}"), stress, zz));
    }
    // A plane-strain pure-shear trial exactly along xx − yy with a large zz deviator.
    cases.push((
        "pure shear".into(),
        [-80.0, -120.0, -40.0, 10.0],
        [3.0 * strain, -3.0 * strain, 0.0, 0.0],
    ));
    cases.retain(|(_, stress, increment)| {
        let trial = add(stress, &mat4_mul_vec(&model.stiffness, increment));
        j2(&trial).sqrt() > 1.05 * c
    });
    assert!(cases.len() >= 20, "too few plastic cases: {}", cases.len());
    cases
}

fn add(a: &Voigt, b: &Voigt) -> Voigt {
    std::array::from_fn(|i| a[i] + b[i])
}

/// TOML keys; deny_unknown_fields rejects typos; validation names every bad key.
#[test]
fn toml_keys_and_parameter_checks() {
    let text = "E = 20000.0\nnu = 0.3\ndensity = 1.8\nc = 50.0\n";
    let parsed: VonMisesParameters = toml::from_str(text).expect("parse");
    assert_eq!(parsed.undrained_strength, 50.0);
    assert!(parsed.validate().is_empty());
    assert!(toml::from_str::<VonMisesParameters>(&format!("{text}phi = 3.0\n")).is_err());
    let bad = VonMisesParameters {
        youngs_modulus: 0.0,
        poisson_ratio: 0.5,
        density: f64::NAN,
        undrained_strength: -1.0,
    };
    let keys: Vec<&str> = bad.validate().iter().map(|p| p.key).collect();
    assert_eq!(keys, ["E", "nu", "density", "c"]);
    let infinite = VonMisesParameters {
        undrained_strength: f64::INFINITY,
        ..parsed
    };
    let problems = VonMises::new(infinite).unwrap_err();
    assert_eq!(problems.len(), 1);
    assert!(
        problems[0]
            .to_string()
            .starts_with("c = inf must be a finite"),
        "{}",
        problems[0]
    );
}

/// Test 1 — below yield the update is the elastic trial σ + DΔε (1e−12 relative), the tangent is
/// D exactly and the state does not change.
#[test]
fn elastic_below_yield() {
    let model = model(0.3);
    let c = model.undrained_strength();
    let d = model.elastic_stiffness();
    let mut rng = Lcg(7);
    let mut worst: f64 = 0.0;
    for _ in 0..50 {
        let stress = stress_inside(&mut rng, 0.5 * c);
        let increment = rng.voigt(0.2 * c / model.elastic.shear_modulus());
        let expected = add(&stress, &mat4_mul_vec(&d, &increment));
        assert!(j2(&expected).sqrt() < c);
        let u = update(&model, &stress, &increment);
        let error = max_abs((0..4).map(|i| u.stress[i] - expected[i])) / max_abs(expected);
        worst = worst.max(error);
        assert!(error <= 1e-12, "relative stress error {error:e}");
        assert_eq!(u.tangent, d);
        assert!(!u.yielded);
        assert_eq!(u.state, PointState::default());
    }
    println!("elastic branch: worst relative stress error {worst:e}");
}

/// Test 2 — a plastic update lands on the surface (√J₂ = c to 1e−10 relative), keeps the mean
/// stress (1e−12 relative to max(|σm|, c)), and its plastic strain increment is isochoric
/// (|tr Δε^p| ≤ 1e−12 ‖Δε^p‖ε); κ grows by ‖Δε^p‖ε (theory D27).
#[test]
fn plastic_return_is_radial_and_isochoric() {
    let model = model(0.3);
    let c = model.undrained_strength();
    let (mut worst_surface, mut worst_mean, mut worst_trace): (f64, f64, f64) = (0.0, 0.0, 0.0);
    for (label, stress, increment) in plastic_cases(&model) {
        let trial = add(&stress, &mat4_mul_vec(&model.stiffness, &increment));
        let state_n = PointState {
            plastic_strain_eq: 0.25,
            plastic_strain_eq_nonlocal: 0.25,
            plastic_strain: [0.1, -0.05, -0.05, 0.2],
        };
        let u = model
            .update(&stress, &increment, &state_n, StrengthVariable::Local)
            .expect("update");
        assert!(u.yielded, "{label}");
        let surface = (j2(&u.stress).sqrt() / c - 1.0).abs();
        let mean_trial = (trial[0] + trial[1] + trial[2]) / 3.0;
        let mean = (u.stress[0] + u.stress[1] + u.stress[2]) / 3.0;
        let mean_error = (mean - mean_trial).abs() / mean_trial.abs().max(c);
        let plastic: Voigt =
            std::array::from_fn(|i| u.state.plastic_strain[i] - state_n.plastic_strain[i]);
        let norm = strain_norm_f64(&plastic);
        let trace = (plastic[0] + plastic[1] + plastic[2]).abs() / norm;
        assert!(surface <= 1e-10, "{label}: |√J2/c − 1| = {surface:e}");
        assert!(
            mean_error <= 1e-12,
            "{label}: mean stress error {mean_error:e}"
        );
        assert!(trace <= 1e-12, "{label}: |tr Δε^p|/‖Δε^p‖ = {trace:e}");
        // Δε^p = C (σ_tr − σ) and Δκ = ‖Δε^p‖ε
        let expected = mat4_mul_vec(
            &model.compliance,
            &std::array::from_fn(|i| trial[i] - u.stress[i]),
        );
        assert!(
            max_abs((0..4).map(|i| plastic[i] - expected[i])) <= 1e-9 * norm,
            "{label}"
        );
        assert!(
            (u.state.plastic_strain_eq - 0.25 - norm).abs() <= 1e-15,
            "{label}"
        );
        assert_eq!(
            u.state.plastic_strain_eq_nonlocal,
            u.state.plastic_strain_eq
        );
        worst_surface = worst_surface.max(surface);
        worst_mean = worst_mean.max(mean_error);
        worst_trace = worst_trace.max(trace);
    }
    println!(
        "plastic branch: |√J2/c − 1| ≤ {worst_surface:e}, mean-stress error ≤ {worst_mean:e}, \
         |tr Δε^p|/‖Δε^p‖ ≤ {worst_trace:e}"
    );
}

/// Test 3 — the algorithmic tangent equals the central finite difference of the update,
/// max|D_fd − D_alg| ≤ 1e−6 max|D_alg|, on random plastic trial states (general, shear-dominated,
/// zz-dominated, pure shear), for three Poisson's ratios. Step η = 1e−5 c/G in strain
/// (truncation ~ (η G/c)² ≈ 1e−10, round-off ~ 1e−16 |σ|/(η G) ≈ 1e−11; measured ≈ 1e−10).
#[test]
fn tangent_matches_finite_differences() {
    let mut worst: f64 = 0.0;
    for nu in [0.0, 0.3, 0.49] {
        let model = model(nu);
        let eta = 1e-5 * model.undrained_strength() / model.elastic.shear_modulus();
        for (label, stress, increment) in plastic_cases(&model) {
            let u = update(&model, &stress, &increment);
            let scale = max_abs(u.tangent.iter().flatten().copied());
            let mut error: f64 = 0.0;
            for j in 0..4 {
                let mut plus = increment;
                let mut minus = increment;
                plus[j] += eta;
                minus[j] -= eta;
                let (sp, sm) = (
                    update(&model, &stress, &plus),
                    update(&model, &stress, &minus),
                );
                assert!(sp.yielded && sm.yielded, "{label}");
                for i in 0..4 {
                    let fd = (sp.stress[i] - sm.stress[i]) / (2.0 * eta);
                    error = error.max((fd - u.tangent[i][j]).abs() / scale);
                }
            }
            assert!(
                error <= 1e-6,
                "nu = {nu}, {label}: relative FD error {error:e}"
            );
            worst = worst.max(error);
        }
    }
    println!("tangent FD check: worst relative error {worst:e}");
}

/// Test 4 — the plastic tangent is symmetric (to 1e−14 of its largest entry) and the model says
/// so (sparse Cholesky); it is positive semi-definite with the zero eigenvalue along n (perfect
/// plasticity: D_alg n = K tr(n) 1 + 2Gβ (n_dev − n) = 0 for deviatoric n).
#[test]
fn tangent_is_symmetric() {
    let model = model(0.3);
    assert!(model.has_symmetric_tangent() && !model.is_elastic() && !model.can_soften());
    let mut worst: f64 = 0.0;
    for (label, stress, increment) in plastic_cases(&model) {
        let u = update(&model, &stress, &increment);
        let t = u.tangent;
        let scale = max_abs(t.iter().flatten().copied());
        for i in 0..4 {
            for j in 0..4 {
                let asym = (t[i][j] - t[j][i]).abs() / scale;
                worst = worst.max(asym);
                assert!(
                    asym <= 1e-14,
                    "{label}: D[{i}][{j}] − D[{j}][{i}] = {asym:e}"
                );
            }
        }
        // The flow direction as an engineering strain, m = (nx, ny, nz, 2 nxy), is a null vector.
        let (_, s) = split(&u.stress);
        let m = [s[0], s[1], s[2], 2.0 * s[3]];
        let tm = mat4_mul_vec(&t, &m);
        assert!(
            max_abs(tm) <= 1e-12 * scale * max_abs(m),
            "{label}: D_alg m = {tm:?}"
        );
    }
    println!("tangent symmetry: worst |D_ij − D_ji|/max|D| = {worst:e}");
}

/// Test 5 — Tresca equivalence in plane strain. Simple shear (Δε = (0, 0, 0, Δγ)) from zero stress:
/// σxy levels off at c (1e−8 relative) for any ν, the normal stresses stay 0, and κ grows by
/// |Δγ^p|/√2 per plastic step (theory D27). Pure shear (Δε = (δ, −δ, 0, 0), Δεzz = 0) from a
/// stress with σzz away from the in-plane mean: the flow drives σzz to (σxx + σyy)/2, so the
/// in-plane Tresca radius √(((σxx − σyy)/2)² + σxy²) levels off at c (1e−8 relative).
#[test]
fn plane_strain_shear_reaches_tresca_strength() {
    for nu in [-0.3, 0.0, 0.2, 0.45, 0.499] {
        let model = model(nu);
        let c = model.undrained_strength();
        let g = model.elastic.shear_modulus();
        let steps = 400;
        let gamma_total = 10.0 * c / g;
        let increment = [0.0, 0.0, 0.0, gamma_total / steps as f64];
        let mut stress = [0.0; 4];
        let mut state = PointState::default();
        let mut plastic_gamma = 0.0;
        for _ in 0..steps {
            let u = model
                .update(&stress, &increment, &state, StrengthVariable::Local)
                .expect("update");
            if u.yielded {
                plastic_gamma += u.state.plastic_strain[3] - state.plastic_strain[3];
            }
            stress = u.stress;
            state = u.state;
        }
        let error = (stress[3] / c - 1.0).abs();
        println!("simple shear, nu = {nu}: |σxy/c − 1| = {error:e}");
        assert!(error <= 1e-8, "nu = {nu}: σxy = {} kPa", stress[3]);
        assert!(
            max_abs(stress[..3].iter().copied()) <= 1e-8 * c,
            "{stress:?}"
        );
        let kappa_expected = plastic_gamma / std::f64::consts::SQRT_2;
        assert!((state.plastic_strain_eq - kappa_expected).abs() <= 1e-12 * kappa_expected);
        assert!(plastic_gamma > 0.0);

        // Pure shear from an anisotropic stress.
        let mut stress = [-100.0, -100.0, -40.0, 0.0];
        let mut state = PointState::default();
        let delta = 20.0 * c / g / steps as f64;
        let increment = [delta, -delta, 0.0, 0.0];
        for _ in 0..steps {
            let u = model
                .update(&stress, &increment, &state, StrengthVariable::Local)
                .expect("update");
            stress = u.stress;
            state = u.state;
        }
        let tresca = (0.25 * (stress[0] - stress[1]).powi(2) + stress[3] * stress[3]).sqrt();
        let error = (tresca / c - 1.0).abs();
        println!(
            "pure shear, nu = {nu}: |τ_max/c − 1| = {error:e}, σzz − (σxx+σyy)/2 = {:e} kPa",
            stress[2] - 0.5 * (stress[0] + stress[1])
        );
        assert!(
            error <= 1e-8,
            "nu = {nu}: in-plane radius {tresca} kPa, {stress:?}"
        );
    }
}

/// project_to_surface scales the deviator of an outside stress to √J₂ = c at fixed mean stress and
/// leaves an inside stress alone (theory D39).
#[test]
fn projection_scales_the_deviator() {
    let model = model(0.3);
    let c = model.undrained_strength();
    let state = PointState::default();
    let inside = [-100.0, -120.0, -110.0, 20.0];
    assert_eq!(model.project_to_surface(&inside, &state, None), inside);
    let outside = [-50.0, -250.0, -100.0, 60.0];
    let projected = model.project_to_surface(&outside, &state, Some(0.3));
    assert!((j2(&projected).sqrt() / c - 1.0).abs() <= 1e-12);
    let (mean_out, s_out) = split(&outside);
    let (mean_p, s_p) = split(&projected);
    assert!((mean_p - mean_out).abs() <= 1e-12 * mean_out.abs());
    let ratio = s_p[3] / s_out[3];
    for i in 0..4 {
        assert!((s_p[i] - ratio * s_out[i]).abs() <= 1e-12 * c);
    }
}

/// p-wave modulus K + 4G/3 of the shared elasticity, and non-finite input is refused.
#[test]
fn p_wave_modulus_and_non_finite_input() {
    let model = model(0.25);
    let e = 20_000.0;
    let nu = 0.25;
    let expected = e * (1.0 - nu) / ((1.0 + nu) * (1.0 - 2.0 * nu));
    assert!((model.p_wave_modulus() / expected - 1.0).abs() <= 1e-13);
    let stress = [-100.0, -100.0, -100.0, 0.0];
    let state = PointState::default();
    for (s, de) in [
        ([f64::NAN, 0.0, 0.0, 0.0], [0.0; 4]),
        (stress, [0.0, 0.0, 0.0, f64::INFINITY]),
    ] {
        assert!(matches!(
            model.update(&s, &de, &state, StrengthVariable::Local),
            Err(ConstitutiveError::NonFinite(_))
        ));
    }
    let bad_state = PointState {
        plastic_strain_eq: f64::NAN,
        ..state
    };
    assert!(matches!(
        model.update(&stress, &[0.0; 4], &bad_state, StrengthVariable::Local),
        Err(ConstitutiveError::NonFinite(_))
    ));
}
