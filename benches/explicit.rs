//! The explicit step (issue 15): one MUSL step of the elastic block
//! `validation/elastic/block_40k.toml`'s explicit twin,
//! `validation/elastic/block_40k_explicit.toml` (bilinear, 2 × 2 points per
//! cell, Δt from the CFL rule), at four sizes set by the cell size:
//! 10,000 (h = 0.02 m), 40,000 (0.01), 160,000 (0.005) and 640,000 points
//! (0.0025).
//!
//! Each benchmark advances one model step after step (the integrator and
//! its buffers reused, as in a run; the end time moved out of reach), after
//! ten warm-up steps that size the buffers; criterion's throughput is the
//! point-steps per second. The time per step from 10k to 640k points gives
//! the scaling exponent (target: no faster than N^1.05). Rayon uses every
//! thread (2 here); `RAYON_NUM_THREADS=1` gives the single-thread figures.
//! Run: `cargo bench --bench explicit`.

use std::path::PathBuf;
use std::time::Duration;

use criterion::{
    criterion_group, criterion_main, BenchmarkId, Criterion, SamplingMode, Throughput,
};
use mpm_physics::integrators::Integrator;
use mpm_physics::model::Model;
use mpm_physics::profile::Profile;
use mpm_physics::scene::Scene;

/// Cell sizes and the points they give.
const SIZES: [(f64, &str); 4] = [
    (0.02, "10k"),
    (0.01, "40k"),
    (0.005, "160k"),
    (0.0025, "640k"),
];

/// Steps taken before timing.
const WARM_UP_STEPS: usize = 10;

/// The block with cell size `h`, its end time out of reach of the bench.
fn block(h: f64) -> Scene {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("validation/elastic/block_40k_explicit.toml");
    let overrides = [format!("grid.cell_size={h}"), "scene.end_time=1e3".into()];
    Scene::load(&path, &overrides).expect("scene")
}

fn bench_explicit(c: &mut Criterion) {
    // the loops run on this thread, as in `mpm-geo` (mpm_physics::parallel)
    mpm_physics::parallel::join_global_pool();
    let mut group = c.benchmark_group("explicit_step");
    group.sample_size(10);
    group.sampling_mode(SamplingMode::Flat);
    group.warm_up_time(Duration::from_secs(1));
    group.measurement_time(Duration::from_secs(5));
    for (h, name) in SIZES {
        let mut model = Model::new(&block(h)).expect("model");
        let mut integrator = Integrator::for_model(&model).expect("integrator");
        let profile = Profile::default();
        for _ in 0..WARM_UP_STEPS {
            integrator.step(&mut model, &profile).expect("step");
        }
        let points = model.state.particles.len();
        println!("explicit_step/{name}: {points} points, h = {h} m");
        group.throughput(Throughput::Elements(points as u64));
        group.bench_function(BenchmarkId::new("block", name), |b| {
            b.iter(|| integrator.step(&mut model, &profile).expect("step"))
        });
    }
    group.finish();
}

criterion_group!(benches, bench_explicit);
criterion_main!(benches);
