//! `mpm-geo` command line: run, check and inspect scenes.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use clap::{Parser, Subcommand};

use mpm_geo::campaign::{CampaignOptions, Part};
use mpm_geo::checkpoint::{Resumable, ResumeOptions, SceneSource};
use mpm_geo::cli_values;
use mpm_geo::error_id::{ErrorId, Identified};
use mpm_geo::provenance::{monitor_summaries, Provenance};
use mpm_geo::run::{run_scene_with, RunOptions, RunOutcome};
use mpm_geo::scene::{Formulation, Scene};

/// 2D plane-strain material point method for brittle geomaterials.
#[derive(Parser)]
#[command(name = "mpm-geo", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run a scene and write curve.csv, its plot curve.png/.svg, snapshots
    /// and run.json.
    Run {
        /// Scene file (TOML).
        scene: PathBuf,
        /// Output directory (default: out/<scene file stem>).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Override a scene value, e.g. `--set grid.cell_size=0.002`; an empty value removes the key (`--set solver.newmark_gamma=`) so its default applies (repeatable).
        #[arg(long = "set", value_name = "KEY=VALUE")]
        overrides: Vec<String>,
        /// No run-time estimate at the start, no progress bar (and no progress
        /// lines); warnings are still printed.
        #[arg(long)]
        quiet: bool,
        /// Print the stage profile and work counters at the end (they are in
        /// run.json in any case), also with `--quiet`.
        #[arg(long)]
        profile: bool,
        /// Seconds between the plain progress lines printed when stderr is
        /// not a terminal (a pipe, a log file; default 10).
        #[arg(long, value_name = "SECONDS", value_parser = parse_positive_seconds)]
        progress_every: Option<f64>,
        /// Remove the earlier run's files from the output directory instead
        /// of refusing it: exactly the files that run listed in its run.json
        /// (curve.csv, its plots, snapshots, particles.pvd, checkpoints,
        /// exported systems, its temporary files); nothing else there is touched,
        /// whatever its name.
        #[arg(long)]
        overwrite: bool,
        /// Memory limit for the run's estimate, e.g. `8G`, `512M` (default:
        /// half the available memory; scene key `limits.max_memory_gb`).
        #[arg(long, value_name = "SIZE", value_parser = parse_memory_arg)]
        max_memory: Option<f64>,
        /// Step-count limit (default 1e7; scene key `limits.max_steps`).
        #[arg(long, value_name = "N", value_parser = cli_values::positive_u64)]
        max_steps: Option<u64>,
        /// Write the whole state to OUT/checkpoint.bin every N steps (and on
        /// SIGINT/SIGTERM), so `mpm-geo resume OUT` can continue the run.
        #[arg(long, value_name = "N", value_parser = cli_values::positive_u64)]
        checkpoint_every: Option<u64>,
        /// Test hook: end the run after step M as a kill would (no last
        /// row, run.json left `running`), leaving the last periodic checkpoint.
        #[arg(long, value_name = "M", hide = true, value_parser = cli_values::whole_number)]
        stop_after_step: Option<usize>,
    },
    /// Continue a run started with `--checkpoint-every` from its last
    /// checkpoint; the outputs end as those of an uninterrupted run.
    Resume {
        /// The run's output directory.
        dir: PathBuf,
        /// No progress bar (and no progress lines).
        #[arg(long)]
        quiet: bool,
        /// Print the stage profile and work counters at the end (they are in
        /// run.json in any case), also with `--quiet`.
        #[arg(long)]
        profile: bool,
        /// Seconds between the plain progress lines printed when stderr is
        /// not a terminal (default 10).
        #[arg(long, value_name = "SECONDS", value_parser = parse_positive_seconds)]
        progress_every: Option<f64>,
        /// Checkpoint interval instead of the run's own.
        #[arg(long, value_name = "N", value_parser = cli_values::positive_u64)]
        checkpoint_every: Option<u64>,
        /// Test hook: end the run after step M as a kill would.
        #[arg(long, value_name = "M", hide = true, value_parser = cli_values::whole_number)]
        stop_after_step: Option<usize>,
    },
    /// Run every scene of a directory (in parallel) and write curves.csv,
    /// metrics.csv, report.md and plots (mesh-objectivity campaign).
    Campaign {
        /// Directory of scene files (e.g. validation/biaxial).
        dir: PathBuf,
        /// Output directory (default: out/campaign-<dir name>).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Also run every scene with K times the steps at Δt / K and report
        /// the time-step discrepancy of each curve (step_convergence.csv).
        #[arg(long, value_name = "K", value_parser = cli_values::factor)]
        step_refinement: Option<usize>,
        #[command(flatten)]
        campaign: CampaignArgs,
    },
    /// The whole paper: the biaxial, footing and vertical-cut campaigns (the
    /// cut in both readings of its failure time), their runs from one queue
    /// (--jobs at a time, a campaign's runs starting while the one before
    /// finishes), into OUT/campaign-<name>/, and OUT/README.md putting
    /// each report beside the paper's figures and claim. Resumes like a
    /// campaign (finished runs are not run again). Measured at full size on
    /// 2 cores: hours (2026-11-28, a 2-core AMD EPYC VM: the biaxial campaign
    /// 29 min, the cut's 16 runs ~2 h); `--set` or `--from`
    /// with coarse copies for a quick look.
    Paper {
        /// Output directory (default: out/paper).
        #[arg(long)]
        out: Option<PathBuf>,
        /// The folder holding biaxial/, footing/ and vertical_cut/.
        #[arg(long = "from", value_name = "DIR", default_value = "validation")]
        root: PathBuf,
        #[command(flatten)]
        campaign: CampaignArgs,
    },
    /// Error against run time: run a study spec's sweep (each run a whole
    /// process, timed `repeats` times) and write study.csv,
    /// work_precision.png and report.md.
    Study {
        /// Study spec (TOML), e.g. validation/studies/elastic_bar.toml.
        spec: PathBuf,
        /// Output directory (default: out/study-<spec file stem>).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Repeats per run instead of the spec's `study.repeats`.
        #[arg(long, value_parser = cli_values::count)]
        repeats: Option<usize>,
        /// Override a value in every run's scene, after the spec's own
        /// overrides (repeatable), e.g. `--set scene.steps=2` for a quick look.
        #[arg(long = "set", value_name = "KEY=VALUE")]
        overrides: Vec<String>,
        /// Run only the K-th of N disjoint parts of the study's runs (e.g.
        /// `--shard 2/3`), for a cluster job array; no report (see `--collect`).
        #[arg(long, value_name = "K/N", conflicts_with = "collect")]
        shard: Option<String>,
        /// Run nothing: build the report from the runs every shard measured.
        #[arg(long)]
        collect: bool,
    },
    /// Draw a run's plot again: DIR/curve.png and DIR/curve.svg, each
    /// monitor of DIR/curve.csv against time (`run` and `resume` draw it
    /// when the run ends).
    Plot {
        /// The run's output directory.
        dir: PathBuf,
    },
    /// Homogeneous test on one material point (biaxial, triaxial, simple shear) → CSV.
    Point(mpm_geo::point_command::PointArgs),
    /// Print the table of error identifiers (docs/guide.md §11).
    Errors,
    /// Validate a scene without running it (exit 0 when valid) and print its
    /// estimated memory, step count and run time.
    Check {
        /// Scene file (TOML).
        scene: PathBuf,
        /// Override a scene value; an empty value removes the key (repeatable).
        #[arg(long = "set", value_name = "KEY=VALUE")]
        overrides: Vec<String>,
        /// Memory limit for the run's estimate, e.g. `8G`, `512M` (default:
        /// half the available memory; scene key `limits.max_memory_gb`).
        #[arg(long, value_name = "SIZE", value_parser = parse_memory_arg)]
        max_memory: Option<f64>,
        /// Step-count limit (default 1e7; scene key `limits.max_steps`).
        #[arg(long, value_name = "N", value_parser = cli_values::positive_u64)]
        max_steps: Option<u64>,
    },
}

/// The options `campaign` and `paper` share.
#[derive(clap::Args)]
struct CampaignArgs {
    /// Scenes run at the same time (each may use every thread, so a run
    /// left alone at the end keeps all cores busy).
    #[arg(long, default_value_t = 2, value_parser = cli_values::count)]
    jobs: usize,
    /// Override a value in every scene; an empty value removes the key (repeatable).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    overrides: Vec<String>,
    /// `ours` (the scenes as written: GIMP, m as written, no double
    /// mapping) or `paper` (bilinear cells, Gauss points, m = 1, double
    /// mapping of the stress increment, no B-bar); a campaign's paper runs
    /// go to out/campaign-<dir name>-paper by default.
    #[arg(long, value_enum, default_value_t = FormulationArg::Ours)]
    formulation: FormulationArg,
    /// Run only the K-th of N disjoint parts (e.g. `--shard 2/3`), for a
    /// cluster job array; no report (see `--collect`).
    #[arg(long, value_name = "K/N", conflicts_with = "collect")]
    shard: Option<String>,
    /// Run nothing: build the report from the runs every shard left in
    /// the output directory.
    #[arg(long)]
    collect: bool,
    /// Checkpoint every run every N steps; a run stopped earlier (a
    /// killed campaign) is then resumed from its checkpoint.
    #[arg(long, value_name = "N", value_parser = cli_values::positive_u64)]
    checkpoint_every: Option<u64>,
}

impl CampaignArgs {
    /// The campaign options, with `step_refinement`, or the message of a
    /// bad `--shard`.
    fn options(self, step_refinement: Option<usize>) -> Result<CampaignOptions, String> {
        Ok(CampaignOptions {
            jobs: self.jobs,
            overrides: self.overrides,
            step_refinement,
            formulation: match self.formulation {
                FormulationArg::Ours => Formulation::AsWritten,
                FormulationArg::Paper => Formulation::Paper,
            },
            part: parse_part(self.shard, self.collect)?,
            checkpoint_every: self.checkpoint_every.map(|n| n as usize),
        })
    }
}

/// The exit of `campaign` and `paper`: 0 when every run completed (`whole`),
/// 1 when some stopped early, the signal's code after an interrupt, 2 on
/// an error.
fn campaign_exit(result: Result<bool, mpm_geo::campaign::CampaignError>) -> ExitCode {
    match result {
        Ok(true) => ExitCode::SUCCESS,
        Ok(false) => ExitCode::from(1),
        Err(e @ mpm_geo::campaign::CampaignError::Interrupted { signal, .. }) => {
            eprintln!("{e}");
            ExitCode::from(signal.exit_code())
        }
        Err(e) => fail_with(2, &e),
    }
}

/// `--formulation`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
enum FormulationArg {
    /// The scenes as written.
    Ours,
    /// The paper's literal formulation.
    Paper,
}

/// `--shard K/N` / `--collect` of `campaign` and `study`.
fn parse_part(shard: Option<String>, collect: bool) -> Result<Part, String> {
    match (shard, collect) {
        (Some(text), _) => Part::shard(&text),
        (None, true) => Ok(Part::Collect),
        (None, false) => Ok(Part::Whole),
    }
}

fn main() -> ExitCode {
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) => return usage_error(&e),
    };
    // this thread runs the parallel loops itself (`mpm_geo::parallel`)
    mpm_geo::parallel::join_global_pool();
    match cli.command {
        Command::Campaign {
            dir,
            out,
            step_refinement,
            campaign,
        } => {
            let options = match campaign.options(step_refinement) {
                Ok(options) => options,
                Err(e) => return fail(2, ErrorId::CliArgument, &e),
            };
            let part = options.part;
            let name = dir
                .file_name()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_else(|| "campaign".into());
            let suffix = match options.formulation {
                Formulation::Paper => "-paper",
                _ => "",
            };
            let out = out
                .unwrap_or_else(|| PathBuf::from("out").join(format!("campaign-{name}{suffix}")));
            install_interrupt();
            campaign_exit(
                mpm_geo::campaign::run_campaign(&dir, &out, &options).map(|runs| {
                    let stopped = runs.iter().filter(|r| r.error.is_some()).count();
                    if let Part::Shard { index, count } = part {
                        eprintln!(
                            "campaign: shard {index}/{count}: {} runs ({stopped} stopped early) in {}; build the report with --collect",
                            runs.len(),
                            out.display()
                        );
                    } else {
                        eprintln!(
                            "campaign: {} runs ({} stopped early); report in {}",
                            runs.len(),
                            stopped,
                            out.join("report.md").display()
                        );
                    }
                    stopped == 0
                }),
            )
        }
        Command::Paper {
            out,
            root,
            campaign,
        } => {
            let options = match campaign.options(None) {
                Ok(options) => options,
                Err(e) => return fail(2, ErrorId::CliArgument, &e),
            };
            let part = options.part;
            let out = out.unwrap_or_else(|| PathBuf::from("out").join("paper"));
            install_interrupt();
            campaign_exit(
                mpm_geo::paper::run_paper(&root, &out, &options).map(|outcomes| {
                    for o in &outcomes {
                        let what = match &o.error {
                            Some(e) => format!("not reported: {e}"),
                            None => format!("{} runs ({} stopped early)", o.runs, o.stopped),
                        };
                        eprintln!("paper: {}: {what} in {:.0} s", o.benchmark.name, o.seconds);
                    }
                    if !matches!(part, Part::Shard { .. }) {
                        eprintln!("paper: index in {}", out.join("README.md").display());
                    }
                    outcomes.iter().all(|o| o.error.is_none() && o.stopped == 0)
                }),
            )
        }
        Command::Study {
            spec,
            out,
            repeats,
            overrides,
            shard,
            collect,
        } => {
            let part = match parse_part(shard, collect) {
                Ok(part) => part,
                Err(e) => return fail(2, ErrorId::CliArgument, &e),
            };
            let stem = spec
                .file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_else(|| "study".into());
            let out = out.unwrap_or_else(|| PathBuf::from("out").join(format!("study-{stem}")));
            let executable = match std::env::current_exe() {
                Ok(exe) => exe,
                Err(e) => {
                    return fail(
                        2,
                        ErrorId::StudyIo,
                        &format!("cannot find the mpm-geo executable: {e}"),
                    )
                }
            };
            let options = mpm_geo::study::StudyOptions {
                executable,
                repeats,
                verbose: true,
                overrides,
                part,
            };
            install_interrupt();
            match mpm_geo::study::run_study(&spec, &out, &options) {
                Ok(rows) => {
                    let stopped = rows.iter().filter(|r| !r.measured.completed()).count();
                    let report = match part {
                        Part::Shard { index, count } => format!(
                            "shard {index}/{count} in {}; build the report with --collect",
                            out.display()
                        ),
                        _ => format!("report in {}", out.join("report.md").display()),
                    };
                    eprintln!(
                        "study: {} runs ({stopped} did not complete); {report}",
                        rows.len()
                    );
                    // a stopped or refused run is an outcome; a panic, a
                    // time-out or a signal is a fault of the engine
                    let faults: Vec<&str> = rows
                        .iter()
                        .filter(|r| !r.measured.stated())
                        .map(|r| r.planned.name.as_str())
                        .collect();
                    if faults.is_empty() {
                        ExitCode::SUCCESS
                    } else {
                        fail(
                            1,
                            ErrorId::StudyFaults,
                            &format!(
                                "{} run(s) ended without a stated outcome (panic, time-out or signal): {}",
                                faults.len(),
                                faults.join(", ")
                            ),
                        )
                    }
                }
                Err(e @ mpm_geo::study::StudyError::Interrupted { signal, .. }) => {
                    eprintln!("{e}");
                    ExitCode::from(signal.exit_code())
                }
                Err(e) => fail_with(2, &e),
            }
        }
        Command::Plot { dir } => plot_command(&dir),
        Command::Errors => {
            print!("{}", mpm_geo::error_id::markdown_table());
            ExitCode::SUCCESS
        }
        Command::Point(args) => match mpm_geo::point_command::run(&args) {
            Ok(()) => ExitCode::SUCCESS,
            Err(e) => fail_with(1, &e),
        },
        Command::Check {
            scene,
            overrides,
            max_memory,
            max_steps,
        } => match Scene::load(&scene, &overrides) {
            Ok(mut s) => {
                set_limits(&mut s, max_memory, max_steps);
                let estimate = s.estimate_resources();
                let run_time = s.run_time_of(&estimate);
                match mpm_geo::simulation::Simulation::new(s) {
                    Ok(run) => {
                        let sim = &run.model;
                        for w in run.scene.warnings() {
                            eprintln!("warning: {w}");
                        }
                        println!(
                            "{}: valid ({} material points, {}×{} cells; {})\n{run_time}",
                            scene.display(),
                            sim.state.particles.len(),
                            sim.grid.cells[0],
                            sim.grid.cells[1],
                            estimate
                        );
                        if let Some(warning) = run_time.long_run_warning() {
                            eprintln!("warning: {warning}");
                        }
                        ExitCode::SUCCESS
                    }
                    Err(e) => fail_with(2, &e),
                }
            }
            Err(e) => fail_with(2, &e),
        },
        Command::Run {
            scene,
            out,
            overrides,
            quiet,
            profile,
            progress_every,
            overwrite,
            max_memory,
            max_steps,
            checkpoint_every,
            stop_after_step,
        } => {
            let source = match SceneSource::read(&scene, &overrides) {
                Ok(s) => s,
                Err(e) => return fail_with(2, &e),
            };
            let mut loaded = match source.scene() {
                Ok(s) => s,
                Err(e) => return fail_with(2, &e),
            };
            set_limits(&mut loaded, max_memory, max_steps);
            for w in loaded.warnings() {
                eprintln!("warning: {w}");
            }
            announce_run_time(&loaded, quiet);
            let stem = scene
                .file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_else(|| "run".into());
            let out = out.unwrap_or_else(|| PathBuf::from("out").join(stem));
            install_interrupt();
            let options = RunOptions {
                show_progress: !quiet,
                progress_every,
                overwrite,
                checkpoint: checkpoint_every.map(|n| (source, n as usize)),
                stop_after: stop_after_step,
                extra_files: run_plot_files(),
                provenance: Some(Provenance::now(Some(&scene), &overrides)),
            };
            let outcome = run_scene_with(loaded, &out, &options);
            draw_run_plot(&outcome, &out);
            report(outcome, &out, quiet, profile)
        }
        Command::Resume {
            dir,
            quiet,
            profile,
            progress_every,
            checkpoint_every,
            stop_after_step,
        } => {
            let resumable = match Resumable::open(&dir) {
                Ok(r) => r,
                Err(e) => return fail_with(2, e.as_ref()),
            };
            for w in resumable.scene().warnings() {
                eprintln!("warning: {w}");
            }
            eprintln!(
                "resuming {} from the checkpoint of step {}",
                resumable.source().origin,
                resumable.step()
            );
            install_interrupt();
            let options = ResumeOptions {
                checkpoint_every: checkpoint_every.map(|n| n as usize),
                stop_after: stop_after_step,
                progress_every,
                extra_files: run_plot_files(),
            };
            let outcome = resumable.run(!quiet, &options);
            draw_run_plot(&outcome, &dir);
            report(outcome, &dir, quiet, profile)
        }
    }
}

/// The files of the run's curve plot, recorded in its `run.json` so that
/// `--overwrite` removes them.
fn run_plot_files() -> Vec<String> {
    mpm_geo::plot::run_curve::FILES
        .iter()
        .map(|f| f.to_string())
        .collect()
}

/// Draw the curve plot of a run that ended (completed, failed or
/// interrupted: of its rows so far) while the directory is still locked; a
/// run stopped as a kill would be (the test hook) draws nothing. A plot that
/// cannot be drawn is a warning, never the run's failure.
fn draw_run_plot(
    outcome: &Result<RunOutcome, Box<dyn std::error::Error + Send + Sync>>,
    out: &Path,
) {
    let Ok(outcome) = outcome else { return };
    let ended =
        outcome.error.is_some() || outcome.interrupted.is_some() || outcome.simulation.finished();
    if !ended {
        return;
    }
    match mpm_geo::plot::run_curve::plot_run(out) {
        Ok(_) | Err(mpm_geo::plot::PlotError::Empty(_)) => {}
        Err(e) => eprintln!("warning: the run's curve plot was not drawn: {e}"),
    }
}

/// `mpm-geo plot DIR`: draw the run's curve plot again.
fn plot_command(dir: &Path) -> ExitCode {
    match mpm_geo::plot::run_curve::plot_run(dir) {
        Ok(files) => {
            for f in files {
                println!("{}", f.display());
            }
            ExitCode::SUCCESS
        }
        Err(e @ mpm_geo::plot::PlotError::Input(_)) => {
            fail(2, ErrorId::OutputDirectory, &e.to_string())
        }
        Err(e @ mpm_geo::plot::PlotError::Empty(_)) => fail(
            2,
            ErrorId::OutputDirectory,
            &format!("{}: {e}", dir.display()),
        ),
        Err(e) => fail(2, ErrorId::OutputWrite, &e.to_string()),
    }
}

/// Catch SIGINT and SIGTERM: the runs in progress end after a whole step
/// with `run.json` saying `interrupted` (`run`, `resume`, `campaign`, `study`).
fn install_interrupt() {
    if let Err(e) = mpm_geo::interrupt::install() {
        eprintln!("warning: SIGINT/SIGTERM will end the run without run.json: {e}");
    }
}

/// Print a run's summary (with `profile` its stage profile and work
/// counters) and turn its outcome into the exit code.
fn report(
    outcome: Result<RunOutcome, Box<dyn std::error::Error + Send + Sync>>,
    out: &Path,
    quiet: bool,
    profile: bool,
) -> ExitCode {
    let outcome = match outcome {
        Err(e) => return fail_with(2, e.as_ref()),
        Ok(outcome) => outcome,
    };
    let sim = &outcome.simulation.model;
    let succeeded = outcome.error.is_none() && outcome.interrupted.is_none();
    // asked for by name, so `--quiet` keeps it
    if profile {
        eprintln!("{}", outcome.simulation.profile.table(outcome.wall_seconds));
        eprintln!("{}", outcome.simulation.profile.work_line());
    }
    if quiet && succeeded && outcome.simulation.finished() {
        // warnings only
        print_warnings(&outcome.simulation);
        return ExitCode::SUCCESS;
    }
    print_run_summary(&outcome, out);
    print_warnings(&outcome.simulation);
    let checkpoint = out.join("checkpoint.bin").exists();
    let resume = || match checkpoint {
        true => format!("; continue with `mpm-geo resume {}`", out.display()),
        false => String::new(),
    };
    match (outcome.error, outcome.interrupted) {
        (Some(e), _) => {
            let next = match (e.resumable(), checkpoint) {
                (true, _) => resume(),
                // the same step from the same checkpoint fails the same way
                (false, true) => "; resuming from the checkpoint would repeat this step: change the scene and run again".to_string(),
                (false, false) => String::new(),
            };
            fail(
                1,
                e.error_id(),
                &format!(
                    "run stopped: {e}\noutputs up to the last completed step are in {}{next}",
                    out.display(),
                ),
            )
        }
        (None, Some(signal)) => {
            eprintln!(
                "interrupted by {} after step {} (t = {:.6e} s); outputs up to it are in {}{}",
                signal.name(),
                sim.state.step,
                sim.state.time,
                out.display(),
                resume()
            );
            ExitCode::from(signal.exit_code())
        }
        (None, None) if !outcome.simulation.finished() => {
            eprintln!(
                "stopped after step {} (--stop-after-step); continue with `mpm-geo resume {}`",
                sim.state.step,
                out.display()
            );
            ExitCode::SUCCESS
        }
        (None, None) => {
            let pvd = out.join(mpm_geo::run::PVD_FILE);
            let view = if pvd.exists() {
                format!(" (open {} in ParaView)", pvd.display())
            } else {
                String::new()
            };
            eprintln!("outputs in {}{view}", out.display());
            ExitCode::SUCCESS
        }
    }
}

/// The physics summary of a run: steps, time and effort, then each
/// monitor's last value and its peak (largest magnitude) with its time, as
/// `run.json` → `summary` records them.
fn print_run_summary(outcome: &RunOutcome, out: &Path) {
    let (sim, usage) = (
        &outcome.simulation.model,
        outcome.simulation.integrator.usage(),
    );
    let mut effort = format!(
        "{} steps to t = {:.4e} s in {:.2} s",
        sim.state.step, sim.state.time, outcome.wall_seconds
    );
    if usage.newton_iterations > 0 {
        effort += &format!(
            "; {} Newton iterations, {} halvings",
            usage.newton_iterations, usage.halvings
        );
    }
    if let (Some((lo, hi)), Some(by)) = (usage.explicit_time_step, &usage.time_step_limited_by) {
        effort += &format!("; time step {lo:.3e} to {hi:.3e} s (limited by {by})");
    }
    eprintln!("{effort}");
    let columns = outcome.simulation.monitor_columns();
    let Some(monitors) = monitor_summaries(&out.join("curve.csv"), &columns) else {
        return;
    };
    let width = monitors.iter().map(|m| m.column.len()).max().unwrap_or(0);
    for m in monitors {
        eprintln!(
            "  {:width$}  last {:>11.4e}  peak {:>11.4e} at t = {:.4e} s",
            m.column, m.last, m.peak, m.peak_time
        );
    }
}

/// Print the run's time estimate (unless `quiet`) and warn of a run
/// estimated to take more than an hour (even when `quiet`, as every warning).
fn announce_run_time(scene: &Scene, quiet: bool) {
    let run_time = scene.estimate_run_time();
    if !quiet {
        eprintln!("{run_time}");
    }
    if let Some(warning) = run_time.long_run_warning() {
        eprintln!("warning: {warning}");
    }
}

/// [`fail`] with the error's own identifier.
fn fail_with(code: u8, error: &(dyn std::error::Error + 'static)) -> ExitCode {
    let id = mpm_geo::error_id::identify(error).unwrap_or(ErrorId::RunInternal);
    fail(code, id, &error.to_string())
}

/// `--max-memory` (bytes) and `--max-steps` replace the scene's `[limits]`.
fn set_limits(scene: &mut Scene, max_memory: Option<f64>, max_steps: Option<u64>) {
    if let Some(bytes) = max_memory {
        scene.limits.max_memory_gb = Some(bytes / 1e9);
    }
    if let Some(n) = max_steps {
        scene.limits.max_steps = Some(n);
    }
}

fn parse_memory_arg(text: &str) -> Result<f64, String> {
    mpm_geo::scene::parse_memory(text)
}

/// The warnings of a finished or stopped run: points removed, an energy
/// budget that does not close.
fn print_warnings(run: &mpm_geo::simulation::Simulation) {
    let sim = &run.model;
    if let Some(first) = sim.state.lost_points.first() {
        let mass: f64 = sim.state.lost_points.iter().map(|l| l.mass).sum();
        let total: f64 = sim.state.particles.mass.iter().sum::<f64>() + mass;
        eprintln!(
            "warning: {} material point(s) left the grid and were removed (first at step {}, {:.2e} of the mass; listed in run.json)",
            sim.state.lost_points.len(),
            first.step,
            mass / total
        );
    }
    let energy = mpm_geo::energy::EnergyBudget::of(sim);
    if let Some(w) = energy.warning(run.scene.output.energy_remainder_warning) {
        eprintln!("warning: {w}");
    }
    if let Some(w) = mpm_geo::run::volume_warning(run) {
        eprintln!("warning: {w}");
    }
}

/// A number of seconds > 0 (`--progress-every`).
fn parse_positive_seconds(text: &str) -> Result<f64, String> {
    match text.trim().parse::<f64>() {
        Ok(s) if s.is_finite() && s > 0.0 => Ok(s),
        _ => Err(format!("`{text}` is not a number of seconds > 0")),
    }
}

/// A command-line usage error (clap's: an unknown argument, a missing or
/// malformed value) printed as `error[CLI_ARGUMENT]: …` with clap's usage
/// lines; `--help` and `--version` print as usual, and a missing command
/// prints the help before its error line.
fn usage_error(error: &clap::Error) -> ExitCode {
    use clap::error::ErrorKind;
    match error.kind() {
        ErrorKind::DisplayHelp | ErrorKind::DisplayVersion => {
            let _ = error.print();
            ExitCode::SUCCESS
        }
        ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand => {
            let _ = error.print();
            fail(
                2,
                ErrorId::CliArgument,
                "a command is needed (listed above)",
            )
        }
        _ => {
            let rendered = error.render().to_string();
            let text = rendered.trim_end();
            fail(
                2,
                ErrorId::CliArgument,
                text.strip_prefix("error: ").unwrap_or(text),
            )
        }
    }
}

/// Print `error[ID]: message` and return the exit code.
fn fail(code: u8, id: ErrorId, message: &str) -> ExitCode {
    eprintln!("error[{}]: {message}", id.name());
    ExitCode::from(code)
}
