//! One whole step of the finest nonlocal biaxial mesh (issue 13 bench
//! `step`): `validation/biaxial/nonlocal_h1000.toml` (h = 1 mm, GIMP, 2 × 2
//! points per cell, l_s = 0.01 m), as written (implicit dynamic, Newmark
//! γ = 0.6, Δt = 1 ms) and as its explicit twin (`Scene::explicit_twin`: MUSL,
//! CFL 0.5, no damping, same end time), each from two states:
//!
//! * `step0`: the initial state (the first step is elastic);
//! * `step150`: after 150 implicit steps (platen at δ = 1.5 mm, on the
//!   softening branch, with the shear band formed).
//!
//! Every iteration takes the same step from a clone of the same `Model`
//! (`iter_batched`, one clone per iteration, cloned outside the timing), with
//! one integrator per benchmark that is reused between iterations: its sparse
//! pattern and symbolic factorisation stay cached as in a run whose active
//! cells do not change. The explicit step from `step150` starts from the
//! implicit run's state (the twin's integrator on a clone of that `Model`).
//! Rayon uses every thread (as a run does); the sparse factorisation is
//! sequential. The printed lines give points, unknowns, nnz, Newton
//! iterations and Δt of each benchmarked step.
//! Run: `cargo bench --bench step`.

use std::path::PathBuf;
use std::time::Duration;

use criterion::{
    criterion_group, criterion_main, BatchSize, BenchmarkId, Criterion, SamplingMode, Throughput,
};
use mpm_physics::integrators::Integrator;
use mpm_physics::model::Model;
use mpm_physics::nonlocal::NonlocalAverager;
use mpm_physics::profile::Profile;
use mpm_physics::scene::Scene;
use mpm_physics::settings::Settings;
use mpm_physics::simulation::Simulation;

/// Implicit steps taken before the second benchmarked state.
const ADVANCED: usize = 150;

fn load() -> Scene {
    let path =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("validation/biaxial/nonlocal_h1000.toml");
    Scene::load(&path, &["output.snapshots=[]".into()]).expect("scene")
}

/// `model` as a simulation with a fresh integrator for `scene` (no monitors).
fn simulation(model: &Model, scene: &Scene) -> Simulation {
    let mut model = model.clone();
    model.settings = Settings::of(scene);
    let integrator = Integrator::for_model(&model).expect("integrator");
    Simulation {
        scene: scene.clone(),
        model,
        integrator,
        monitors: Vec::new(),
        profile: Profile::default(),
        last_step: None,
    }
}

/// Times one step of `sim` from its current state, after printing what that
/// step does.
fn bench_one(c: &mut Criterion, sim: Simulation, kind: &str, state: &str) {
    let Simulation {
        model,
        mut integrator,
        profile,
        ..
    } = sim;
    let points = model.state.particles.len();
    let mut probe = model.clone();
    let report = integrator.step(&mut probe, &profile).expect("step");
    println!(
        "step/{kind}/{state}: step {} → {}, {points} points, Δt {:.4e} s, {} Newton iterations, {} sub-steps",
        model.state.step,
        probe.state.step,
        report.dt,
        report.iterations,
        report.substeps
    );
    if let Some(limit) = integrator.usage().time_step_limited_by {
        let p = &model.state.particles;
        let wave = (0..p.len())
            .map(|i| {
                let c = model.materials[p.material[i] as usize].p_wave_modulus() * p.volume[i]
                    / p.mass[i];
                model.grid.cell_size / c.sqrt()
            })
            .fold(f64::INFINITY, f64::min);
        println!(
            "step/{kind}/{state}: Δt limited by {limit}; the wave-speed limit alone (material at rest) \
             would give CFL × h/c = {:.4e} s",
            model.settings.solver.cfl * wave
        );
    }
    drop(probe);
    let mut steps = 1u64; // the probe step
    let mut group = c.benchmark_group("step");
    group.sample_size(10);
    group.sampling_mode(SamplingMode::Flat);
    group.warm_up_time(Duration::from_secs(1));
    group.measurement_time(Duration::from_secs(4));
    group.throughput(Throughput::Elements(points as u64));
    group.bench_function(BenchmarkId::new(kind, state), |b| {
        b.iter_batched(
            || model.clone(),
            |mut m| {
                integrator.step(&mut m, &profile).expect("step");
                steps += 1;
                m
            },
            BatchSize::PerIteration,
        )
    });
    group.finish();
    print_profile(&profile, steps, kind, state);
}

/// Exclusive time per step of every stage that took at least 1 % of the
/// benchmarked steps (the probe step, warm-up and samples together).
fn print_profile(profile: &Profile, steps: u64, kind: &str, state: &str) {
    let rows = profile.totals(0.0);
    let steps = steps as f64;
    let total: f64 = rows.iter().map(|r| r.seconds).sum();
    let stages: Vec<String> = rows
        .iter()
        .filter(|r| r.seconds >= 0.01 * total)
        .map(|r| {
            format!(
                "{} {:.3} ms ({:.0} %)",
                r.stage,
                1e3 * r.seconds / steps,
                100.0 * r.seconds / total
            )
        })
        .collect();
    println!(
        "step/{kind}/{state}: per step, over {steps} steps: {}",
        stages.join(", ")
    );
    println!("step/{kind}/{state}: {}", profile.work_line());
}

fn bench_step(c: &mut Criterion) {
    // the loops run on this thread, as in `mpm-geo` (mpm_physics::parallel)
    mpm_physics::parallel::join_global_pool();
    let scene = load();
    let twin = scene.explicit_twin().expect("explicit twin");
    let mut sim = Simulation::new(scene.clone()).expect("setup");
    let mut states = vec![("step0", sim.model.clone())];
    for _ in 0..ADVANCED {
        sim.step_once().expect("advance");
    }
    states.push(("step150", sim.model.clone()));
    drop(sim);
    for (state, model) in &states {
        let mut implicit = simulation(model, &scene);
        let n = implicit.unknowns().expect("unknowns");
        let (_, k) = implicit.linearize(&vec![0.0; n]).expect("linearize");
        let spec = model.settings.nonlocal.as_ref().expect("a nonlocal scene");
        let params = *spec;
        let p = &model.state.particles;
        let averager =
            NonlocalAverager::new(&params, &p.position, &p.volume, &p.material).expect("averager");
        let (min, mean, max) = averager.neighbour_count_stats();
        println!(
            "step/{state}: t = {:.4} s, {} points, {n} unknowns, nnz {}; nonlocal neighbours \
             (R_c = {} l_s = {} m) min {min} mean {mean:.0} max {max}",
            model.state.time,
            p.len(),
            k.nnz(),
            spec.cutoff_factor,
            spec.cutoff_factor * spec.length_scale
        );
        bench_one(c, implicit, "implicit", state);
        bench_one(c, simulation(model, &twin), "explicit", state);
    }
}

criterion_group!(benches, bench_step);
criterion_main!(benches);
