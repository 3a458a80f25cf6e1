//! P2G + G2P cost per particle per step (issue 3 bench `transfer`), at 10k and
//! 100k material points (2×2 per cell), serial (1-thread rayon pool) and
//! rayon (all threads); `gimp_*`: the same with GIMP shape functions, points
//! on sub-cell centres moved by up to ±0.05 h so that domains cross cell
//! edges (up to 3 × 3 nodes per point). Group `transfer_stages` times the
//! three parts of that step on their own, with rayon on all threads (as a run
//! does): `shapes` (shape functions and gradients at every point, and the
//! binning of points by cell), `p2g` (nodal mass, momentum and internal
//! force) and `g2p` (velocity and velocity gradient at every point).
//! Run: `cargo bench --bench transfer`.

use std::time::Duration;

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use mpm_physics::grid::ShapeAt;
use mpm_physics::grid::{Grid, ShapeFunctions};
use mpm_physics::transfer::{self, ParticleBins};
use rayon::prelude::*;

struct Cloud {
    grid: Grid,
    position: Vec<[f64; 2]>,
    mass: Vec<f64>,
    volume: Vec<f64>,
    velocity: Vec<[f64; 2]>,
    stress: Vec<[f64; 4]>,
}

fn cloud(particles: usize, gimp: bool) -> Cloud {
    let cells_side = ((particles / 4) as f64).sqrt().ceil() as usize;
    let h = 0.01;
    let mut grid = Grid::bilinear([0.0, 0.0], h, [cells_side + 2, cells_side + 2]);
    let g = if gimp {
        grid.shape_functions = ShapeFunctions::Gimp {
            half_width: 0.25 * h,
        };
        0.25
    } else {
        0.5 / 3f64.sqrt()
    };
    let mut position = Vec::with_capacity(particles);
    'outer: for cj in 1..=cells_side {
        for ci in 1..=cells_side {
            for (dx, dy) in [(-g, -g), (g, -g), (g, g), (-g, g)] {
                if position.len() == particles {
                    break 'outer;
                }
                let k = position.len() as f64;
                let jitter = if gimp { 0.05 * (k * 0.7).sin() } else { 0.0 };
                position.push([
                    (ci as f64 + 0.5 + dx + jitter) * h,
                    (cj as f64 + 0.5 + dy - jitter) * h,
                ]);
            }
        }
    }
    let n = position.len();
    let velocity = (0..n)
        .map(|p| [(p as f64 * 0.1).sin(), (p as f64 * 0.3).cos()])
        .collect();
    let stress = (0..n)
        .map(|p| [-100.0 - p as f64 * 1e-3, -80.0, -90.0, 5.0])
        .collect();
    Cloud {
        grid,
        position,
        mass: vec![2e-4; n],
        volume: vec![1e-4; n],
        velocity,
        stress,
    }
}

/// Shape functions at every point and the points binned by cell.
fn shapes(c: &Cloud) -> (Vec<ShapeAt>, ParticleBins) {
    let shapes = transfer::shapes_at(&c.grid, &c.position).expect("inside");
    let bins = ParticleBins::new(&c.grid, &shapes);
    (shapes, bins)
}

/// P2G of mass, momentum and internal force; returns the nodal velocity and
/// the internal force.
fn p2g(c: &Cloud, shapes: &[ShapeAt], bins: &ParticleBins) -> (Vec<[f64; 2]>, Vec<[f64; 2]>) {
    let mass = transfer::nodal_mass(&c.grid, bins, shapes, &c.mass);
    let momentum = transfer::nodal_mass_weighted(&c.grid, bins, shapes, &c.mass, &c.velocity);
    let force = transfer::internal_force(&c.grid, bins, shapes, &c.volume, &c.stress);
    let v: Vec<[f64; 2]> = momentum
        .iter()
        .zip(&mass)
        .map(|(q, &m)| {
            if m > 0.0 {
                [q[0] / m, q[1] / m]
            } else {
                [0.0; 2]
            }
        })
        .collect();
    (v, force)
}

/// G2P of the velocity and its gradient (summed, so nothing is optimised away).
fn g2p(shapes: &[ShapeAt], v: &[[f64; 2]]) -> f64 {
    shapes
        .par_iter()
        .map(|s| {
            let u = transfer::interpolate(s, v);
            let l = transfer::gradient(s, v);
            u[0] + l[0] + l[3]
        })
        .sum()
}

/// One step's transfers: shapes + binning, P2G of mass, momentum and internal
/// force, G2P of velocity and its gradient.
fn p2g_g2p(c: &Cloud) -> f64 {
    let (shapes, bins) = shapes(c);
    let (v, force) = p2g(c, &shapes, &bins);
    g2p(&shapes, &v) + force[0][0]
}

fn bench_transfer(c: &mut Criterion) {
    let mut group = c.benchmark_group("transfer");
    group.sample_size(20);
    group.warm_up_time(Duration::from_secs(1));
    group.measurement_time(Duration::from_secs(3));
    let serial = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    let parallel = rayon::ThreadPoolBuilder::new().build().unwrap();
    for n in [10_000usize, 100_000] {
        for (prefix, gimp) in [("", false), ("gimp_", true)] {
            let cloud = cloud(n, gimp);
            group.throughput(Throughput::Elements(cloud.position.len() as u64));
            let serial_id = BenchmarkId::new(format!("{prefix}serial"), n);
            group.bench_with_input(serial_id, &cloud, |b, cl| {
                b.iter(|| serial.install(|| p2g_g2p(cl)))
            });
            let rayon_id = BenchmarkId::new(format!("{prefix}rayon"), n);
            group.bench_with_input(rayon_id, &cloud, |b, cl| {
                b.iter(|| parallel.install(|| p2g_g2p(cl)))
            });
        }
    }
    group.finish();
}

fn bench_stages(c: &mut Criterion) {
    let mut group = c.benchmark_group("transfer_stages");
    group.sample_size(20);
    group.warm_up_time(Duration::from_secs(1));
    group.measurement_time(Duration::from_secs(2));
    for n in [10_000usize, 100_000] {
        for (prefix, gimp) in [("", false), ("gimp_", true)] {
            let cloud = cloud(n, gimp);
            group.throughput(Throughput::Elements(cloud.position.len() as u64));
            group.bench_function(BenchmarkId::new(format!("{prefix}shapes"), n), |b| {
                b.iter(|| shapes(&cloud))
            });
            let (sh, bins) = shapes(&cloud);
            group.bench_function(BenchmarkId::new(format!("{prefix}p2g"), n), |b| {
                b.iter(|| p2g(&cloud, &sh, &bins))
            });
            let (v, _) = p2g(&cloud, &sh, &bins);
            group.bench_function(BenchmarkId::new(format!("{prefix}g2p"), n), |b| {
                b.iter(|| g2p(&sh, &v))
            });
        }
    }
    group.finish();
}

criterion_group!(benches, bench_transfer, bench_stages);
criterion_main!(benches);
