//! Criterion benchmark of the nonlocal averaging operator (theory §6, [D33]–[D36]; paper
//! eq. 6) at 10k and 50k MPs on a regular 2×2-Gauss-point lattice with l_s = 3 h (≈ 10³
//! neighbours within R_c = 3 l_s), and on the 6,000 points of the finest biaxial mesh
//! (≈ 4,700 neighbours, the case where nearly every point neighbours every other):
//!
//! * `new`: constructor (bins) plus the denominators [D34] (computed at first use), once per
//!   step;
//! * `new_cache_sparse` / `new_cache_dense`: constructor plus the weight cache of the field's
//!   sources (`cache_sources`), i.e. the per-step build cost with caching;
//! * `new_average_sparse` / `new_average_dense`: constructor plus one `average`, the
//!   explicit step's cost (one pass evaluates each kernel once for denominators and
//!   numerators; before, `new` plus `uncached_*`);
//! * `average_sparse` / `average_dense`: one `average` with the cache of that field (the
//!   per-Newton-iteration cost, [D36]), sparse = 10 % band, dense = nonzero everywhere;
//! * `uncached_sparse` / `uncached_dense`: `average_uncached` (every nonzero source evaluated
//!   on the fly, the evaluation before caching);
//! * `grid_new_average_sparse` / `grid_new_average_dense`: the grid averaging (theory §6.1,
//!   NG1–NG3, spacing 0.1 l_s): a fresh operator and one average, the explicit step's cost
//!   with `averaging = "grid"` (the kernel's spectrum is kept between calls, as in a run);
//! * `grid_average_sparse`: one grid average with a built operator (a Newton iteration's);
//! * `brute_force`: the O(N²) reference pass (sparse field).

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use mpm_physics::nonlocal::{GridAverager, NonlocalAverager, NonlocalSpec};
use std::hint::black_box;
use std::time::Duration;

struct Scene {
    pos: Vec<[f64; 2]>,
    vol: Vec<f64>,
    grp: Vec<u16>,
    sparse: Vec<f64>,
    dense: Vec<f64>,
    params: NonlocalSpec,
}

/// `n_cells × n_cells` cells of side h = 1 with 4 Gauss-point MPs each.
fn scene(n_cells: usize) -> Scene {
    let h = 1.0;
    let d = h / (2.0 * 3f64.sqrt());
    let mut pos = Vec::with_capacity(4 * n_cells * n_cells);
    for j in 0..n_cells {
        for i in 0..n_cells {
            let c = [(i as f64 + 0.5) * h, (j as f64 + 0.5) * h];
            for (sx, sy) in [(-1.0, -1.0), (1.0, -1.0), (-1.0, 1.0), (1.0, 1.0)] {
                pos.push([c[0] + sx * d, c[1] + sy * d]);
            }
        }
    }
    let n = pos.len();
    let l = n_cells as f64 * h;
    // A diagonal shear band holding ~10 % of the MPs (linear profile across the band).
    let half_width = 0.0355 * l;
    let sparse: Vec<f64> = pos
        .iter()
        .map(|p| {
            let dist = (p[0] - p[1]).abs() / 2f64.sqrt();
            if dist < half_width {
                1e-3 * (1.0 - dist / half_width)
            } else {
                0.0
            }
        })
        .collect();
    let dense: Vec<f64> = pos
        .iter()
        .map(|p| 1e-3 * (1.0 + 0.01 * p[0] - 0.02 * p[1]))
        .collect();
    Scene {
        vol: vec![h * h / 4.0; n],
        grp: vec![0; n],
        pos,
        sparse,
        dense,
        params: NonlocalSpec::new(3.0 * h),
    }
}

/// The points of the finest biaxial mesh (`validation/biaxial/nonlocal_h1000.toml`: 60 × 100
/// points 0.5 mm apart on the 30 mm × 50 mm quarter specimen, l_s = 10 mm, so R_c = 30 mm
/// and ~4,700 neighbours a point): dense = every point plastic (before the peak), sparse =
/// a band of width ~l_s across the specimen (after localisation, ~25 % of the points).
fn biaxial_lattice() -> Scene {
    let h = 0.0005;
    let pos: Vec<[f64; 2]> = (0..100)
        .flat_map(|j| (0..60).map(move |i| [(i as f64 + 0.5) * h, (j as f64 + 0.5) * h]))
        .collect();
    let n = pos.len();
    let sparse = pos
        .iter()
        .map(|p| {
            let dist = (p[1] - 0.01 - 1.2 * p[0]).abs() / 1.2f64.hypot(1.0);
            if dist < 0.004 {
                1e-3 * (1.0 - dist / 0.004)
            } else {
                0.0
            }
        })
        .collect();
    let dense = pos.iter().map(|p| 1e-3 * (1.0 + 10.0 * p[0])).collect();
    Scene {
        vol: vec![h * h; n],
        grp: vec![0; n],
        pos,
        sparse,
        dense,
        params: NonlocalSpec::new(0.01),
    }
}

fn bench_nonlocal(c: &mut Criterion) {
    // the loops run on this thread, as in `mpm-geo` (mpm_physics::parallel)
    mpm_physics::parallel::join_global_pool();
    let mut group = c.benchmark_group("nonlocal");
    group.sample_size(10);
    group.warm_up_time(Duration::from_millis(500));
    group.measurement_time(Duration::from_secs(3));
    for s in [scene(50), scene(112), biaxial_lattice()] {
        let n = s.pos.len();
        let nl = NonlocalAverager::new(&s.params, &s.pos, &s.vol, &s.grp).unwrap();
        let (min, mean, max) = nl.neighbour_count_stats();
        let nonzero = s.sparse.iter().filter(|&&v| v != 0.0).count();
        eprintln!(
            "N = {n}: neighbours min {min} mean {mean:.0} max {max}; sparse field {:.1} % nonzero",
            100.0 * nonzero as f64 / n as f64
        );
        let mut out = vec![0.0; n];
        group.bench_function(BenchmarkId::new("new", n), |b| {
            b.iter(|| {
                let nl =
                    NonlocalAverager::new(&s.params, black_box(&s.pos), &s.vol, &s.grp).unwrap();
                nl.neighbour_count_stats(); // forces the denominators
                nl
            })
        });
        for (name, field) in [("sparse", &s.sparse), ("dense", &s.dense)] {
            // an explicit step: a fresh operator and one average (denominators and
            // numerators in one pass); before, the cost of `new` + `uncached_{name}`
            group.bench_function(BenchmarkId::new(format!("new_average_{name}"), n), |b| {
                b.iter(|| {
                    let nl = NonlocalAverager::new(&s.params, black_box(&s.pos), &s.vol, &s.grp)
                        .unwrap();
                    nl.average(field, &mut out).unwrap();
                    nl
                })
            });
            group.bench_function(BenchmarkId::new(format!("new_cache_{name}"), n), |b| {
                b.iter(|| {
                    let mut nl =
                        NonlocalAverager::new(&s.params, black_box(&s.pos), &s.vol, &s.grp)
                            .unwrap();
                    nl.cache_sources(field).unwrap();
                    nl
                })
            });
            let mut cached = nl.clone();
            cached.cache_sources(field).unwrap();
            let stats = cached.cache_stats();
            eprintln!(
                "N = {n}, {name} field: {} cached sources, {} stored weights ({:.0} MiB)",
                stats.sources,
                stats.pairs,
                stats.pairs as f64 * 8.0 / (1024.0 * 1024.0)
            );
            group.bench_function(BenchmarkId::new(format!("average_{name}"), n), |b| {
                b.iter(|| cached.average(black_box(field), &mut out).unwrap())
            });
            drop(cached);
            group.bench_function(BenchmarkId::new(format!("uncached_{name}"), n), |b| {
                b.iter(|| nl.average_uncached(black_box(field), &mut out).unwrap())
            });
            group.bench_function(
                BenchmarkId::new(format!("grid_new_average_{name}"), n),
                |b| {
                    b.iter(|| {
                        let grid = GridAverager::new(&s.params, black_box(&s.pos), &s.vol, &s.grp)
                            .unwrap();
                        grid.average(field, &mut out).unwrap();
                        grid
                    })
                },
            );
        }
        let grid = GridAverager::new(&s.params, &s.pos, &s.vol, &s.grp).unwrap();
        group.bench_function(BenchmarkId::new("grid_average_sparse", n), |b| {
            b.iter(|| grid.average(black_box(&s.sparse), &mut out).unwrap())
        });
        group.bench_function(BenchmarkId::new("brute_force", n), |b| {
            b.iter(|| {
                NonlocalAverager::average_brute_force(
                    &s.params,
                    black_box(&s.pos),
                    &s.vol,
                    &s.grp,
                    &s.sparse,
                    &mut out,
                )
                .unwrap()
            })
        });
    }
    group.finish();
}

criterion_group!(benches, bench_nonlocal);
criterion_main!(benches);
