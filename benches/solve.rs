//! Assembly, symbolic + numeric factorisation and solve of the oedometer
//! column's tangent (issue 3 bench `solve`) at ~10k and ~100k unknowns,
//! Cholesky vs LU (faer, single-threaded factorisation); at ~10k also with GIMP
//! shape functions (`10k_gimp`: each point reaches up to 3 × 3 nodes, so the
//! tangent couples nodes up to two apart and the factors are denser).
//! Run: `cargo bench --bench solve`.

use std::path::PathBuf;

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use mpm_geo::scene::Scene;
use mpm_geo::simulation::Simulation;
use mpm_solvers::{DirectSolver, SolverPolicy};

/// The oedometer scene widened to `nx` × `ny` cells of 0.01 m, with GIMP
/// shape functions when `gimp`.
fn column(nx: usize, ny: usize, gimp: bool) -> Simulation {
    let h = 0.01;
    let (w, height) = (nx as f64 * h, ny as f64 * h);
    let mut overrides = vec![
        format!("grid.cell_size={h}"),
        format!("grid.size=[{w}, {height}]"),
        format!("body.0.box=[[0.0, 0.0], [{w}, {height}]]"),
        format!("bc.fixed.1.line=\"x={w}\""),
    ];
    if gimp {
        overrides.push("grid.shape_functions=\"gimp\"".into());
        overrides.push("grid.point_layout=\"uniform\"".into());
    }
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("validation/elastic/oedometer.toml");
    Simulation::new(Scene::load(&path, &overrides).expect("scene")).expect("setup")
}

fn bench_solve(c: &mut Criterion) {
    let mut group = c.benchmark_group("solve");
    group.sample_size(10);
    for (label, nx, ny, gimp) in [
        ("10k", 50usize, 100usize, false),
        ("10k_gimp", 50, 100, true),
        ("100k", 158, 316, false),
    ] {
        let mut sim = column(nx, ny, gimp);
        let n = sim.unknowns().expect("unknowns");
        let zeros = vec![0.0; n];
        group.bench_function(BenchmarkId::new("linearize_and_assemble", label), |b| {
            b.iter(|| sim.linearize(&zeros).expect("linearize"))
        });
        let (rhs, k) = sim.linearize(&zeros).expect("linearize");
        for (name, policy) in [
            ("cholesky", SolverPolicy::Cholesky),
            ("lu", SolverPolicy::Lu),
        ] {
            group.bench_function(
                BenchmarkId::new(format!("{name}_symbolic_numeric"), label),
                |b| {
                    b.iter(|| {
                        let mut solver = DirectSolver::new(policy);
                        solver.factorize(&k, true).expect("factorize")
                    })
                },
            );
            let mut solver = DirectSolver::new(policy);
            solver.factorize(&k, true).expect("factorize");
            group.bench_function(BenchmarkId::new(format!("{name}_numeric"), label), |b| {
                b.iter(|| solver.factorize(&k, true).expect("refactorize"))
            });
            group.bench_function(BenchmarkId::new(format!("{name}_solve"), label), |b| {
                b.iter(|| {
                    let mut x = rhs.clone();
                    solver.solve_in_place(&mut x).expect("solve");
                    x
                })
            });
        }
        println!("solve/{label}: {n} unknowns, nnz {}", k.nnz());
    }
    group.finish();
}

criterion_group!(benches, bench_solve);
criterion_main!(benches);
