//! Stress-update throughput of the HMC model (theory §5.6): elastic branch and plastic
//! (softening) branch, reported by criterion as updates per second (throughput in elements).
//! The `*_no_tangent` rows are the explicit integrator's update ([`ConstitutiveModel::update_stress`]);
//! `over_nonlocal` solves for the point's own κ with the weight 1 − m = −0.1 of the scenes' m = 1.1.
//!
//! Run: `cargo bench --bench constitutive`.

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use mpm_physics::constitutive::hmc::{Hmc, HmcParameters};
use mpm_physics::constitutive::{ConstitutiveModel, PointState, StrengthVariable, Voigt};
use mpm_physics::point_driver::run_biaxial;

/// (stress σ_n, strain increment Δε, state_n) triples.
type Cases = Vec<(Voigt, Voigt, PointState)>;

/// Plastic cases from the softening branch of the homogeneous biaxial test (Table 1),
/// δ from 1.35 to 2.25 mm in 1 µm steps: each step yields and softens.
fn softening_cases(model: &Hmc) -> Cases {
    let targets: Vec<f64> = (1..=2260).map(|k| -(k as f64) * 1e-6 / 0.05).collect();
    let records = run_biaxial(model, 100.0, &targets).expect("biaxial path");
    records
        .windows(2)
        .skip(1350)
        .map(|w| {
            let increment = std::array::from_fn(|i| w[1].strain[i] - w[0].strain[i]);
            let state = PointState {
                plastic_strain_eq: w[0].plastic_strain_eq,
                plastic_strain_eq_nonlocal: w[0].plastic_strain_eq,
                plastic_strain: [0.0; 4],
            };
            (w[0].stress, increment, state)
        })
        .collect()
}

/// Elastic cases: small increments from isotropic states well inside the surface.
fn elastic_cases(n: usize) -> Cases {
    (0..n)
        .map(|k| {
            let p = 100.0 + (k % 50) as f64;
            let s = 1e-6 * (1.0 + (k % 7) as f64);
            (
                [-p, -p, -p, 0.0],
                [s, -2.0 * s, 0.0, s],
                PointState::default(),
            )
        })
        .collect()
}

fn bench(c: &mut Criterion) {
    // the loops run on this thread, as in `mpm-geo` (mpm_physics::parallel)
    mpm_physics::parallel::join_global_pool();
    let model = Hmc::new(HmcParameters::table1()).expect("Table 1");
    let plastic = softening_cases(&model);
    assert!(plastic.iter().all(|(s, e, st)| model
        .update(s, e, st, StrengthVariable::Local)
        .expect("update")
        .yielded));
    let elastic = elastic_cases(plastic.len());
    let mut group = c.benchmark_group("hmc_update");
    for (name, cases, frozen) in [
        ("elastic", &elastic, false),
        ("plastic_softening_local", &plastic, false),
        ("plastic_softening_nonlocal", &plastic, true),
    ] {
        group.throughput(Throughput::Elements(cases.len() as u64));
        group.bench_function(name, |b| {
            b.iter(|| {
                let mut acc = 0.0;
                for (stress, increment, state) in cases.iter() {
                    let kbar = StrengthVariable::from(frozen.then_some(state.plastic_strain_eq));
                    let u = model
                        .update(black_box(stress), black_box(increment), state, kbar)
                        .expect("update");
                    acc += u.stress[1] + u.tangent[1][1];
                }
                black_box(acc)
            })
        });
    }
    for (name, strength) in [
        ("plastic_softening_local_no_tangent", None),
        ("plastic_softening_over_nonlocal_no_tangent", Some(-0.1)),
    ] {
        group.throughput(Throughput::Elements(plastic.len() as u64));
        group.bench_function(name, |b| {
            b.iter(|| {
                let mut acc = 0.0;
                for (stress, increment, state) in plastic.iter() {
                    let strength = strength.map_or(StrengthVariable::Local, |own_weight| {
                        StrengthVariable::Nonlocal {
                            neighbours: state.plastic_strain_eq,
                            own_weight,
                        }
                    });
                    let (mut s, mut st) = (*stress, *state);
                    model
                        .update_stress(
                            black_box(stress),
                            black_box(increment),
                            state,
                            strength,
                            (&mut s, &mut st),
                        )
                        .expect("update");
                    acc += s[1];
                }
                black_box(acc)
            })
        });
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
