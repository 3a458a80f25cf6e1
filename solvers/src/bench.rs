//! `mpm-solvers bench DIR`: every applicable solver on every exported system of a directory
//! ([`crate::mm`]), the median of `repeats` fresh solves (symbolic step included), written as
//! a CSV and a markdown table: seconds per phase, fill, PCG iterations, relative residual and
//! the relative difference to faer's LU (the reference).

use std::io::Write;
use std::path::Path;

use crate::mm::{list_systems, read_system, System};
pub use crate::norms::{relative_difference, relative_residual};
use crate::{
    Factorization, LinearOptions, LinearSolver, Method, Ordering, PcgOptions, Preconditioner,
    SolverError, SolverOptions, SparseMatrix,
};

/// Settings of [`run_bench`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BenchOptions {
    /// Solves per solver and system (the median of each phase is reported).
    pub repeats: usize,
    /// Relative-residual tolerance of the PCG runs.
    pub pcg_tolerance: f64,
    /// The identity (no) ordering is run only on systems with at most this many unknowns.
    pub identity_max_n: usize,
}

impl Default for BenchOptions {
    fn default() -> Self {
        Self {
            repeats: 3,
            pcg_tolerance: 1e-10,
            identity_max_n: 20_000,
        }
    }
}

/// One solver on one system.
#[derive(Debug, Clone, PartialEq)]
pub struct BenchRow {
    /// The system's name.
    pub system: String,
    /// Unknowns.
    pub n: usize,
    /// Stored entries of K.
    pub nnz: usize,
    /// Whether K is symmetric (the export's flag and a numerical check, 1e-12).
    pub symmetric: bool,
    /// The solver's label.
    pub solver: String,
    /// Median seconds of ordering + symbolic factorisation.
    pub symbolic_seconds: f64,
    /// Median seconds of the numeric factorisation (PCG: preconditioner set-up).
    pub numeric_seconds: f64,
    /// Median seconds of the solve (PCG: the iterations).
    pub solve_seconds: f64,
    /// Median seconds of faer LU's singularity probe (0 for the others).
    pub probe_seconds: f64,
    /// Stored entries of the factor (L, or L + U; PCG: its preconditioner), if known.
    pub fill: Option<usize>,
    /// PCG iterations.
    pub iterations: Option<usize>,
    /// ‖b − Kx‖ / ‖b‖.
    pub residual: f64,
    /// ‖x − x_LU‖ / ‖x_LU‖ against faer's LU (COLAMD, automatic variant).
    pub diff_to_lu: f64,
    /// `ok`, or what happened (a fallback to LU, an error).
    pub status: String,
}

/// The solvers run on a system: label and options.
pub fn solver_configs(
    symmetric: bool,
    n: usize,
    bench: &BenchOptions,
) -> Vec<(String, LinearOptions)> {
    let direct = |method, factorization, ordering| LinearOptions {
        method,
        direct: SolverOptions {
            factorization,
            ordering,
            ..Default::default()
        },
        pcg: PcgOptions::default(),
    };
    use Factorization::{Auto, Simplicial, Supernodal};
    let mut out = vec![
        (
            "faer LU (COLAMD)".to_string(),
            direct(Method::Lu, Auto, Ordering::Default),
        ),
        (
            "faer LU supernodal (COLAMD)".into(),
            direct(Method::Lu, Supernodal, Ordering::Default),
        ),
        (
            "faer LU simplicial (COLAMD)".into(),
            direct(Method::Lu, Simplicial, Ordering::Default),
        ),
        (
            "faer LU simplicial (AMD)".into(),
            direct(Method::Lu, Simplicial, Ordering::Amd),
        ),
    ];
    out.push((
        "multifrontal (AMD of K + Kᵀ)".into(),
        direct(Method::Multifrontal, Auto, Ordering::Default),
    ));
    if n <= bench.identity_max_n {
        out.push((
            "faer LU simplicial (identity)".into(),
            direct(Method::Lu, Simplicial, Ordering::Identity),
        ));
    }
    if symmetric {
        out.extend([
            (
                "faer Cholesky (AMD)".to_string(),
                direct(Method::Cholesky, Auto, Ordering::Amd),
            ),
            (
                "faer Cholesky supernodal (AMD)".into(),
                direct(Method::Cholesky, Supernodal, Ordering::Amd),
            ),
            (
                "faer Cholesky simplicial (AMD)".into(),
                direct(Method::Cholesky, Simplicial, Ordering::Amd),
            ),
            (
                "faer Cholesky (COLAMD)".into(),
                direct(Method::Cholesky, Auto, Ordering::Colamd),
            ),
        ]);
        if n <= bench.identity_max_n {
            out.push((
                "faer Cholesky (identity)".into(),
                direct(Method::Cholesky, Auto, Ordering::Identity),
            ));
        }
        for (label, preconditioner) in [
            ("PCG Jacobi", Preconditioner::Jacobi),
            ("PCG IC(0)", Preconditioner::IncompleteCholesky),
        ] {
            out.push((
                label.to_string(),
                LinearOptions {
                    method: Method::Pcg,
                    direct: SolverOptions::default(),
                    pcg: PcgOptions {
                        preconditioner,
                        tolerance: bench.pcg_tolerance,
                        max_iterations: 20_000,
                    },
                },
            ));
        }
        if Method::Ldl.available() {
            out.push((
                "sprs_ldl LDLᵀ (AMD)".into(),
                direct(Method::Ldl, Auto, Ordering::Default),
            ));
        }
    }
    out
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    let m = v.len() / 2;
    if v.len() % 2 == 1 {
        v[m]
    } else {
        0.5 * (v[m - 1] + v[m])
    }
}

/// One solve from scratch: (solution, stats, what solved it).
pub fn solve_once(
    options: LinearOptions,
    k: &SparseMatrix,
    symmetric: bool,
    rhs: &[f64],
) -> Result<(Vec<f64>, crate::SolverStats, crate::Used, Vec<String>), SolverError> {
    let mut solver = LinearSolver::new(options)?;
    solver.factorize(k, symmetric)?;
    let mut x = rhs.to_vec();
    let used = solver.solve_in_place(&mut x)?;
    Ok((x, solver.stats(), used, solver.warnings()))
}

/// Runs every applicable solver on `system`.
pub fn bench_system(system: &System, bench: &BenchOptions) -> Vec<BenchRow> {
    let k = &system.k;
    let flag = system
        .meta
        .get("symmetric")
        .and_then(|v| v.as_bool())
        .unwrap_or(true);
    let symmetric = flag && k.is_symmetric(1e-12);
    let reference = solve_once(
        LinearOptions {
            method: Method::Lu,
            ..Default::default()
        },
        k,
        false,
        &system.rhs,
    )
    .map(|r| r.0)
    .ok();
    let mut rows = Vec::new();
    for (label, options) in solver_configs(symmetric, k.n(), bench) {
        let mut times = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        let mut last = None;
        let mut status = String::from("ok");
        for _ in 0..bench.repeats.max(1) {
            match solve_once(options, k, symmetric, &system.rhs) {
                Ok(r) => {
                    times.0.push(r.1.symbolic_seconds);
                    times.1.push(r.1.numeric_seconds);
                    times.2.push(r.1.solve_seconds);
                    times.3.push(r.1.probe_seconds);
                    if !r.3.is_empty() {
                        status = r.3.join("; ");
                    }
                    last = Some(r);
                }
                Err(e) => {
                    status = format!("error: {e}");
                    break;
                }
            }
        }
        let Some((x, stats, _, _)) = last else {
            rows.push(BenchRow {
                system: system.name.clone(),
                n: k.n(),
                nnz: k.nnz(),
                symmetric,
                solver: label,
                symbolic_seconds: f64::NAN,
                numeric_seconds: f64::NAN,
                solve_seconds: f64::NAN,
                probe_seconds: f64::NAN,
                fill: None,
                iterations: None,
                residual: f64::NAN,
                diff_to_lu: f64::NAN,
                status,
            });
            continue;
        };
        rows.push(BenchRow {
            system: system.name.clone(),
            n: k.n(),
            nnz: k.nnz(),
            symmetric,
            solver: label,
            symbolic_seconds: median(times.0),
            numeric_seconds: median(times.1),
            solve_seconds: median(times.2),
            probe_seconds: median(times.3),
            fill: stats.factor_nnz,
            iterations: (options.method == Method::Pcg).then_some(stats.pcg_iterations),
            residual: relative_residual(k, &x, &system.rhs),
            diff_to_lu: reference
                .as_ref()
                .map_or(f64::NAN, |r| relative_difference(&x, r)),
            status,
        });
    }
    rows
}

/// Runs [`bench_system`] on every system of `dir` (see [`list_systems`]), calling `progress`
/// with each system's name before it is run.
pub fn run_bench(
    dir: &Path,
    bench: &BenchOptions,
    mut progress: impl FnMut(&str),
) -> Result<Vec<BenchRow>, SolverError> {
    let mut rows = Vec::new();
    for json in list_systems(dir)? {
        let system = read_system(&json)?;
        progress(&system.name);
        rows.extend(bench_system(&system, bench));
    }
    Ok(rows)
}

fn opt<T: std::fmt::Display>(v: Option<T>) -> String {
    v.map_or_else(String::new, |v| v.to_string())
}

/// A number field of `bench.csv`: `v` in full precision, empty when it is
/// not finite (a difference to an LU that did not run); the rule of
/// `mpm_geo::csv_columns::number`, which this crate cannot depend on.
fn number(v: f64) -> String {
    if v.is_finite() {
        format!("{v:e}")
    } else {
        String::new()
    }
}

/// Header of `bench.csv`: the identifiers `system`, `solver` and `status`,
/// and number columns named with their unit (`_s` seconds, `_1` counts and
/// ratios; `symmetric_1` is 1 or 0), as in the CSV files of `mpm-geo`.
const CSV_HEADER: &str = "system,n_1,nnz_1,symmetric_1,solver,symbolic_s,numeric_s,solve_s,probe_s,total_s,fill_1,iterations_1,residual_1,diff_to_lu_1,status";

/// Writes the rows as CSV (one line per solver and system).
pub fn write_csv(rows: &[BenchRow], path: &Path) -> Result<(), SolverError> {
    let err = |e: std::io::Error| SolverError::Io {
        path: path.display().to_string(),
        message: e.to_string(),
    };
    let mut f = std::io::BufWriter::new(std::fs::File::create(path).map_err(err)?);
    writeln!(f, "{CSV_HEADER}").map_err(err)?;
    for r in rows {
        writeln!(
            f,
            "{},{},{},{},\"{}\",{},{},{},{},{},{},{},{},{},\"{}\"",
            r.system,
            r.n,
            r.nnz,
            u8::from(r.symmetric),
            r.solver,
            number(r.symbolic_seconds),
            number(r.numeric_seconds),
            number(r.solve_seconds),
            number(r.probe_seconds),
            number(r.symbolic_seconds + r.numeric_seconds + r.solve_seconds),
            opt(r.fill),
            opt(r.iterations),
            number(r.residual),
            number(r.diff_to_lu),
            r.status.replace('"', "'"),
        )
        .map_err(err)?;
    }
    f.flush().map_err(err)
}

/// The rows as a markdown table (milliseconds).
pub fn markdown(rows: &[BenchRow]) -> String {
    let mut s = String::from(
        "| system | n | nnz(K) | solver | symbolic ms | numeric ms | solve ms | total ms | fill nnz | iterations | residual | diff to LU | status |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    for r in rows {
        let ms = |x: f64| format!("{:.1}", 1e3 * x);
        s.push_str(&format!(
            "| {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {:.1e} | {:.1e} | {} |\n",
            r.system,
            r.n,
            r.nnz,
            r.solver,
            ms(r.symbolic_seconds),
            ms(r.numeric_seconds),
            ms(r.solve_seconds),
            ms(r.symbolic_seconds + r.numeric_seconds + r.solve_seconds),
            opt(r.fill),
            opt(r.iterations),
            r.residual,
            r.diff_to_lu,
            r.status,
        ));
    }
    s
}
