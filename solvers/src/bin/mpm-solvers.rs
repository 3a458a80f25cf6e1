//! `mpm-solvers bench DIR [--repeats N] [--out DIR] [--pcg-tolerance T] [--identity-max-n N]`:
//! every applicable linear solver on every system exported by `mpm-geo run` with
//! `[output] systems = [...]` (see `mpm_solvers::bench`); writes `bench.csv` and `bench.md`.

use std::path::PathBuf;
use std::process::ExitCode;

use mpm_solvers::bench::{markdown, run_bench, write_csv, BenchOptions};

const USAGE: &str = "usage: mpm-solvers bench DIR [--repeats N] [--out DIR] [--pcg-tolerance T] [--identity-max-n N]";

fn parse() -> Result<(PathBuf, PathBuf, BenchOptions), String> {
    let mut args = std::env::args().skip(1);
    match args.next().as_deref() {
        Some("bench") => {}
        Some("--help" | "-h") | None => return Err(USAGE.into()),
        Some(other) => return Err(format!("unknown command `{other}`\n{USAGE}")),
    }
    let mut dir = None;
    let mut out = None;
    let mut options = BenchOptions::default();
    while let Some(a) = args.next() {
        let mut value = |name: &str| args.next().ok_or(format!("{name} needs a value\n{USAGE}"));
        match a.as_str() {
            "--repeats" => {
                options.repeats = value("--repeats")?
                    .parse()
                    .ok()
                    .filter(|&n: &usize| n >= 1)
                    .ok_or("--repeats: a whole number >= 1")?
            }
            "--pcg-tolerance" => {
                options.pcg_tolerance = value("--pcg-tolerance")?
                    .parse()
                    .ok()
                    .filter(|&t: &f64| t > 0.0 && t < 1.0)
                    .ok_or("--pcg-tolerance: a number in (0, 1)")?
            }
            "--identity-max-n" => {
                options.identity_max_n = value("--identity-max-n")?
                    .parse()
                    .map_err(|_| "--identity-max-n: a whole number")?
            }
            "--out" => out = Some(PathBuf::from(value("--out")?)),
            _ if dir.is_none() && !a.starts_with("--") => dir = Some(PathBuf::from(a)),
            _ => return Err(format!("unexpected argument `{a}`\n{USAGE}")),
        }
    }
    let dir = dir.ok_or(USAGE)?;
    let out = out.unwrap_or_else(|| dir.clone());
    Ok((dir, out, options))
}

fn main() -> ExitCode {
    let (dir, out, options) = match parse() {
        Ok(p) => p,
        Err(e) => {
            eprintln!("{e}");
            return ExitCode::from(2);
        }
    };
    let rows = match run_bench(&dir, &options, |name| eprintln!("bench: {name}")) {
        Ok(rows) => rows,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::from(1);
        }
    };
    if rows.is_empty() {
        eprintln!(
            "error: no exported systems (*.json with a `matrix` key) in {}",
            dir.display()
        );
        return ExitCode::from(1);
    }
    if let Err(e) = std::fs::create_dir_all(&out) {
        eprintln!("error: {}: {e}", out.display());
        return ExitCode::from(1);
    }
    if let Err(e) = write_csv(&rows, &out.join("bench.csv")) {
        eprintln!("error: {e}");
        return ExitCode::from(1);
    }
    let table = markdown(&rows);
    if let Err(e) = std::fs::write(out.join("bench.md"), &table) {
        eprintln!("error: {}: {e}", out.join("bench.md").display());
        return ExitCode::from(1);
    }
    print!("{table}");
    ExitCode::SUCCESS
}
