//! The implicit linear system (issue 3 bench `solve`, issue 13): assembly of
//! the tangent and faer's sparse factorisations, on the oedometer column's
//! tangent at ~10k and ~100k unknowns (bilinear), at ~10k with GIMP shape
//! functions (`10k_gimp`: each point reaches up to 3 × 3 nodes, so the tangent
//! couples nodes up to two apart and the factors are denser), and on the
//! first-step tangent of the finest nonlocal biaxial mesh
//! (`biaxial_h1000`: `validation/biaxial/nonlocal_h1000.toml`, GIMP, Newmark
//! mass term). faer's factorisations are single-threaded (`Par::Seq`, as in a run); the
//! multifrontal LU factorises independent subtrees on the rayon pool.
//!
//! Group `assembly`, each stage of building K on its own:
//! * `blocks`: the per-cell tangent blocks Σ V_p B_pᵀ D B_p (rayon, elastic D
//!   at every point) plus the background-stiffness elements;
//! * `pattern`: the CSC pattern and scatter map from the element dof lists
//!   (`Assembler::with_couplings`, once per step when the active cells change);
//! * `scatter`: blocks → sparse matrix (`Assembler::assemble`, every Newton
//!   iteration);
//! * `linearize`: the whole `Simulation::linearize` (stress update at a zero
//!   increment, blocks, assembly, residual).
//!
//! Group `solve`, for `cholesky` and `lu` (`DirectSolver` with a fixed
//! policy):
//! * `{f}_symbolic`: the symbolic factorisation alone (AMD / COLAMD ordering,
//!   elimination tree, scratch), read from the solver's own timer
//!   (`SolverStats::symbolic_seconds`) around a fresh solver's `factorize`;
//! * `{f}_symbolic_numeric`: a fresh solver's `factorize`, i.e. symbolic +
//!   numeric (no reuse);
//! * `{f}_numeric`: `factorize` again on the same pattern: numeric only (the
//!   symbolic factorisation, factor storage and workspace reused, as every
//!   Newton iteration does while the pattern holds);
//! * `{f}_solve`: one forward/back substitution;
//! * `multifrontal_{lu,cholesky}_{numeric,solve}`: the same for the multifrontal
//!   factorisation on the pattern of K + Kᵀ (`mpm_solvers::MultifrontalLu`, LU or Cholesky
//!   fronts; its solve includes one step of iterative refinement, i.e. two substitutions and
//!   a product with K).
//!
//! Both groups sample flat (10 samples of equal iteration counts), so that the
//! 100k factorisations finish in seconds; `{f}_symbolic` pays a whole
//! factorisation per iteration but reports only its symbolic part.
//! The LU numeric rows include `DirectSolver`'s singularity probe (one
//! mat-vec and one solve), which the engine always pays.
//! Run: `cargo bench --bench solve`.

use std::path::PathBuf;
use std::time::Duration;

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, SamplingMode};
use mpm_physics::dofs::DofMap;
use mpm_physics::integrators::tangent::background_block;
use mpm_physics::integrators::StepSetup;
use mpm_physics::scene::Scene;
use mpm_physics::simulation::Simulation;
use mpm_physics::stiffness;
use mpm_solvers::{Assembler, DirectSolver, MultifrontalLu, SolverPolicy};

fn manifest(path: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(path)
}

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
    let path = manifest("validation/elastic/oedometer.toml");
    Simulation::new(Scene::load(&path, &overrides).expect("scene")).expect("setup")
}

/// The finest nonlocal biaxial mesh (h = 1 mm) at its initial state.
fn biaxial_h1000() -> Simulation {
    let path = manifest("validation/biaxial/nonlocal_h1000.toml");
    Simulation::new(Scene::load(&path, &[]).expect("scene")).expect("setup")
}

/// The matrices: label and simulation at its first step.
fn cases() -> Vec<(&'static str, Simulation)> {
    vec![
        ("10k", column(50, 100, false)),
        ("10k_gimp", column(50, 100, true)),
        ("100k", column(158, 316, false)),
        ("biaxial_h1000", biaxial_h1000()),
    ]
}

fn bench_assembly(c: &mut Criterion) {
    // the loops run on this thread, as in `mpm-geo` (mpm_physics::parallel)
    mpm_physics::parallel::join_global_pool();
    let mut group = c.benchmark_group("assembly");
    group.sample_size(10);
    group.sampling_mode(SamplingMode::Flat);
    group.warm_up_time(Duration::from_secs(1));
    group.measurement_time(Duration::from_secs(2));
    for (label, mut sim) in cases() {
        let model = &sim.model;
        let grid = &model.grid;
        let setup = StepSetup::new(model).expect("setup");
        let dofs = DofMap::new(&setup.bins, &model.constraints);
        let element_dofs = dofs.element_dofs(grid, &setup.bins);
        let tangent: Vec<_> = model
            .state
            .particles
            .material
            .iter()
            .map(|&m| model.materials[m as usize].elastic_stiffness())
            .collect();
        let background = background_block(&model.settings, grid);
        let blocks = || {
            let cells = stiffness::cell_stiffness_blocks(
                grid,
                &setup.bins,
                &setup.shapes,
                &model.state.particles.volume,
                &tangent,
                None,
                None,
            );
            stiffness::system_blocks(grid, &setup.bins, cells, Some(&background))
        };
        let pattern = || {
            Assembler::with_couplings(
                dofs.n_free,
                &element_dofs,
                stiffness::patch_coupling(grid, false),
            )
            .expect("pattern")
        };
        group.bench_function(BenchmarkId::new("blocks", label), |b| b.iter(blocks));
        group.bench_function(BenchmarkId::new("pattern", label), |b| b.iter(pattern));
        let (element_blocks, assembler) = (blocks(), pattern());
        group.bench_function(BenchmarkId::new("scatter", label), |b| {
            b.iter(|| assembler.assemble(&element_blocks).expect("assemble"))
        });
        println!(
            "assembly/{label}: {} points, {} active + {} reached cells, {} elements, {} unknowns, nnz {}",
            model.state.particles.len(),
            setup.bins.active_cells.len(),
            setup.bins.reached_cells.len(),
            element_dofs.len(),
            dofs.n_free,
            assembler.nnz()
        );
        let zeros = vec![0.0; dofs.n_free];
        group.bench_function(BenchmarkId::new("linearize", label), |b| {
            b.iter(|| sim.linearize(&zeros).expect("linearize"))
        });
    }
    group.finish();
}

fn bench_solve(c: &mut Criterion) {
    let mut group = c.benchmark_group("solve");
    group.sample_size(10);
    group.sampling_mode(SamplingMode::Flat);
    group.warm_up_time(Duration::from_secs(1));
    group.measurement_time(Duration::from_secs(2));
    for (label, mut sim) in cases() {
        let n = sim.unknowns().expect("unknowns");
        let zeros = vec![0.0; n];
        let (rhs, k) = sim.linearize(&zeros).expect("linearize");
        for (name, policy) in [
            ("cholesky", SolverPolicy::Cholesky),
            ("lu", SolverPolicy::Lu),
        ] {
            group.bench_function(BenchmarkId::new(format!("{name}_symbolic"), label), |b| {
                b.iter_custom(|iters| {
                    let mut total = Duration::ZERO;
                    for _ in 0..iters {
                        let mut solver = DirectSolver::new(policy);
                        solver.factorize(&k, true).expect("factorize");
                        total += Duration::from_secs_f64(solver.stats().symbolic_seconds);
                    }
                    total
                })
            });
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
            let kind = solver.factorize(&k, true).expect("factorize");
            assert_eq!(
                solver.stats().cholesky_fallbacks,
                0,
                "{label}: K is not positive definite"
            );
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
            let stats = solver.stats();
            println!(
                "solve/{label}/{name}: {kind:?}; {} symbolic, {} numeric in the solver's timers: \
                 symbolic {:.3} s, numeric {:.3} s, LU probe {:.3} s in total",
                stats.symbolic,
                stats.numeric,
                stats.symbolic_seconds,
                stats.numeric_seconds,
                stats.probe_seconds
            );
        }
        // the multifrontal factorisation on the pattern of K + Kᵀ (issue 15), with LU fronts
        // (as for an unsymmetric K) and Cholesky fronts: numeric factorisation on the same
        // pattern, and the solve with its one step of iterative refinement
        for (name, symmetric) in [("multifrontal_lu", false), ("multifrontal_cholesky", true)] {
            let mut multifrontal = MultifrontalLu::new();
            multifrontal.factorize(&k, symmetric).expect("multifrontal");
            group.bench_function(BenchmarkId::new(format!("{name}_numeric"), label), |b| {
                b.iter(|| multifrontal.factorize(&k, symmetric).expect("refactorize"))
            });
            group.bench_function(BenchmarkId::new(format!("{name}_solve"), label), |b| {
                b.iter(|| {
                    let mut x = rhs.clone();
                    multifrontal.solve(&k, &mut x).expect("solve");
                    x
                })
            });
            println!(
                "solve/{label}/{name}: factors {} entries, last refinement correction {:.1e}",
                multifrontal.factor_nnz,
                multifrontal.last_correction.unwrap_or(f64::NAN)
            );
        }
        println!("solve/{label}: {n} unknowns, nnz {}", k.nnz());
    }
    group.finish();
}

criterion_group!(benches, bench_assembly, bench_solve);
criterion_main!(benches);
