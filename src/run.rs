//! Running a scene to an output directory: the observer that writes
//! `curve.csv`, snapshots and `run.json`, and drives the progress bar.

use std::path::{Path, PathBuf};
use std::time::Instant;

use indicatif::{ProgressBar, ProgressStyle};
use serde_json::json;

use crate::checkpoint::Checkpointer;
use crate::error::RunError;
use crate::integrators::StepReport;
use crate::output::{deviatoric_hencky_strain, write_json, write_vtu, CurveWriter};
use crate::profile::Stage;
use crate::scene::{AnalysisKind, Scene};
use crate::simulation::{Observer, Simulation};

/// Writes a run's outputs as it goes.
pub struct OutputObserver {
    dir: PathBuf,
    curve: CurveWriter,
    progress: ProgressBar,
    last_row_step: usize,
    /// `[output] snapshot_times` not reached yet, latest first.
    pending_times: Vec<f64>,
    /// The fields at the snapshot times reached so far.
    fields: Vec<FieldSnapshot>,
    /// Writes a checkpoint every N steps (`--checkpoint-every`).
    checkpoints: Option<Checkpointer>,
    /// Continuing a run from a checkpoint: the start is already written.
    resumed: bool,
    /// Test hook: end the run after this step as a kill would (no last
    /// row, no `run.json`, no checkpoint at that step).
    stop_after: Option<usize>,
    /// Set once the step `stop_after` is done.
    stop: bool,
}

/// Where a run's outputs stood after a step: what a checkpoint stores so a
/// resumed run writes on exactly as the uninterrupted one would.
#[derive(Clone, Debug, Default)]
pub struct OutputCursor {
    /// Step of the last `curve.csv` row (`None` before the first).
    pub last_row_step: Option<usize>,
    /// `[output] snapshot_times` not reached yet, latest first.
    pub pending_times: Vec<f64>,
    /// The fields at the snapshot times reached so far.
    pub fields: Vec<FieldSnapshot>,
    /// Length of `curve.csv` then, bytes.
    pub curve_bytes: u64,
    /// CRC-32 of those bytes.
    pub curve_checksum: u32,
}

/// The material points' positions and strains at one snapshot time (what the
/// campaigns plot as the paper's Fig. 10).
#[derive(Clone, Debug)]
pub struct FieldSnapshot {
    /// The snapshot time asked for in `[output] snapshot_times`, s.
    pub requested_time: f64,
    /// The time of the step written, s (the first step reaching it).
    pub time: f64,
    /// Positions x_p, m.
    pub positions: Vec<[f64; 2]>,
    /// Deviatoric Hencky strain εq per point (DESIGN D8).
    pub eps_q: Vec<f64>,
    /// Current volume V_p, m³ per m.
    pub volumes: Vec<f64>,
}

impl FieldSnapshot {
    /// The fields of `sim` now, for the requested time `requested_time`.
    pub fn of(sim: &Simulation, requested_time: f64) -> Self {
        let p = &sim.model.particles;
        Self {
            requested_time,
            time: sim.model.time,
            positions: p.position.clone(),
            eps_q: p.def_grad.iter().map(deviatoric_hencky_strain).collect(),
            volumes: p.volume.clone(),
        }
    }
}

impl OutputObserver {
    /// Create `dir` and `curve.csv` in it.
    pub fn new(dir: &Path, sim: &Simulation, show_progress: bool) -> Result<Self, RunError> {
        std::fs::create_dir_all(dir).map_err(|e| RunError::Output {
            path: dir.display().to_string(),
            message: e.to_string(),
        })?;
        let names: Vec<String> = sim.monitors.iter().map(|m| m.name.clone()).collect();
        let curve = CurveWriter::create(&dir.join("curve.csv"), &names)?;
        let mut pending_times = sim.model.scene.output.snapshot_times.clone();
        pending_times.sort_by(|a, b| b.total_cmp(a));
        Ok(Self {
            dir: dir.to_path_buf(),
            curve,
            progress: progress_bar(sim, show_progress),
            last_row_step: usize::MAX,
            pending_times,
            fields: Vec::new(),
            checkpoints: None,
            resumed: false,
            stop_after: None,
            stop: false,
        })
    }

    /// Continue the outputs of `dir` from `cursor` (`sim` restored from the
    /// same checkpoint): `curve.csv` cut back to the cursor's length, the
    /// snapshots of later steps removed (the run writes them again).
    pub fn resume(
        dir: &Path,
        sim: &Simulation,
        cursor: OutputCursor,
        show_progress: bool,
    ) -> Result<Self, RunError> {
        let curve = CurveWriter::reopen(&dir.join("curve.csv"), cursor.curve_bytes)?;
        remove_snapshots_after(dir, sim.model.step)?;
        let progress = progress_bar(sim, show_progress);
        progress.set_position(progress_position(sim));
        Ok(Self {
            dir: dir.to_path_buf(),
            curve,
            progress,
            last_row_step: cursor.last_row_step.unwrap_or(usize::MAX),
            pending_times: cursor.pending_times,
            fields: cursor.fields,
            checkpoints: None,
            resumed: true,
            stop_after: None,
            stop: false,
        })
    }

    /// Write a checkpoint with `checkpoints` (every N steps, see
    /// [`Checkpointer`]) and end the run after step `stop_after` (test hook).
    pub fn with_checkpoints(
        mut self,
        checkpoints: Option<Checkpointer>,
        stop_after: Option<usize>,
    ) -> Self {
        self.checkpoints = checkpoints;
        self.stop_after = stop_after;
        self
    }

    /// The output cursors now (the `curve.csv` length and checksum are the
    /// checkpoint writer's to fill in).
    pub fn cursor(&self) -> OutputCursor {
        OutputCursor {
            last_row_step: (self.last_row_step != usize::MAX).then_some(self.last_row_step),
            pending_times: self.pending_times.clone(),
            fields: self.fields.clone(),
            curve_bytes: 0,
            curve_checksum: 0,
        }
    }

    /// Write a checkpoint of `sim` now, if the run writes checkpoints (the
    /// step's outputs must be written already). On an interruption call it
    /// before [`Self::finish`]: the checkpoint must not see the extra last
    /// row `finish` writes, which an uninterrupted run would not have.
    pub fn write_checkpoint(&mut self, sim: &Simulation) -> Result<(), RunError> {
        let cursor = self.cursor();
        match self.checkpoints.as_mut() {
            Some(checkpoints) => checkpoints.write(sim, cursor).map_err(RunError::from),
            None => Ok(()),
        }
    }

    /// True when the run ended early at the `stop_after` test hook.
    pub fn stopped(&self) -> bool {
        self.stop
    }

    /// Capture the fields for every snapshot time the run has now reached
    /// (within a relative 1e-9 of the time); true if any.
    fn capture_due_times(&mut self, sim: &Simulation) -> bool {
        let time = sim.model.time;
        let mut any = false;
        while let Some(&t) = self.pending_times.last() {
            if time < t - 1e-9 * t.abs().max(1.0) {
                break;
            }
            self.pending_times.pop();
            self.fields.push(FieldSnapshot::of(sim, t));
            any = true;
        }
        any
    }

    fn snapshot_due(sim: &Simulation) -> bool {
        let o = &sim.model.scene.output;
        let step = sim.model.step;
        o.snapshots.contains(&step)
            || (o.snapshot_every > 0 && step.is_multiple_of(o.snapshot_every))
    }

    fn write_snapshot(&self, sim: &Simulation) -> Result<(), RunError> {
        write_vtu(
            &self
                .dir
                .join(format!("particles_{:06}.vtu", sim.model.step)),
            &sim.model.particles,
        )
    }

    fn write_row(&mut self, sim: &Simulation) -> Result<(), RunError> {
        let model = &sim.model;
        self.curve
            .row(model.step, model.time, &sim.monitor_values())?;
        self.last_row_step = model.step;
        Ok(())
    }

    /// Write the last row if it was skipped by `curve_every` (call at the end or on failure).
    pub fn finish(&mut self, sim: &Simulation) -> Result<(), RunError> {
        sim.profile.time(Stage::Output, || {
            self.progress.finish_and_clear();
            if self.last_row_step != sim.model.step {
                self.write_row(sim)?;
            }
            Ok(())
        })
    }

    fn show_progress(&self, sim: &Simulation, report: &StepReport) {
        self.progress.set_position(progress_position(sim));
        match sim.model.analysis() {
            AnalysisKind::Explicit => {
                self.progress.set_message(format!(
                    "step {} t={:.4e} s dt={:.2e} s",
                    report.step, report.time, report.dt
                ));
            }
            _ => {
                self.progress.set_message(format!(
                    "t={:.4e} Newton {} it{}",
                    report.time,
                    report.iterations,
                    if report.substeps > 1 {
                        format!(" ({} substeps)", report.substeps)
                    } else {
                        String::new()
                    }
                ));
            }
        }
    }
}

/// A progress bar over the steps (implicit) or over 1000ths of the end time (explicit).
fn progress_bar(sim: &Simulation, show: bool) -> ProgressBar {
    if !show {
        return ProgressBar::hidden();
    }
    let total = match sim.model.analysis() {
        AnalysisKind::Explicit => 1000,
        _ => sim.model.scene.scene.steps.unwrap_or(0) as u64,
    };
    let bar = ProgressBar::new(total);
    let template = "{bar:30} {pos}/{len} [{elapsed_precise} < {eta_precise}] {msg}";
    bar.set_style(
        ProgressStyle::with_template(template).unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    bar
}

/// The progress bar's position for `sim`'s step and time.
fn progress_position(sim: &Simulation) -> u64 {
    match sim.model.analysis() {
        AnalysisKind::Explicit => {
            let end = sim.model.scene.scene.end_time.unwrap_or(1.0);
            (1000.0 * sim.model.time / end) as u64
        }
        _ => sim.model.step as u64,
    }
}

/// Remove the snapshots `particles_NNNNNN.vtu` of steps after `step`.
fn remove_snapshots_after(dir: &Path, step: usize) -> Result<(), RunError> {
    let io = |path: &Path, e: std::io::Error| RunError::Output {
        path: path.display().to_string(),
        message: e.to_string(),
    };
    for entry in std::fs::read_dir(dir).map_err(|e| io(dir, e))? {
        let path = entry.map_err(|e| io(dir, e))?.path();
        let later = path
            .file_name()
            .and_then(|n| n.to_str())
            .and_then(|n| n.strip_prefix("particles_")?.strip_suffix(".vtu"))
            .and_then(|n| n.parse::<usize>().ok())
            .is_some_and(|n| n > step);
        if later {
            std::fs::remove_file(&path).map_err(|e| io(&path, e))?;
        }
    }
    Ok(())
}

impl Observer for OutputObserver {
    fn on_start(&mut self, sim: &Simulation) -> Result<(), RunError> {
        if self.resumed {
            return Ok(());
        }
        sim.profile.time(Stage::Output, || {
            self.write_row(sim)?;
            let at_time = self.capture_due_times(sim);
            if Self::snapshot_due(sim) || at_time {
                self.write_snapshot(sim)?;
            }
            Ok(())
        })
    }

    fn on_step(&mut self, sim: &Simulation, report: &StepReport) -> Result<(), RunError> {
        sim.profile.time(Stage::Output, || {
            let every = sim.model.scene.output.curve_every.max(1);
            if sim.model.step.is_multiple_of(every) || sim.finished() {
                self.write_row(sim)?;
            }
            let at_time = self.capture_due_times(sim);
            if Self::snapshot_due(sim) || at_time {
                self.write_snapshot(sim)?;
            }
            self.show_progress(sim, report);
            Ok::<_, RunError>(())
        })?;
        self.stop = self.stop_after == Some(sim.model.step);
        if !self.stop && self.checkpoints.as_ref().is_some_and(|c| c.due(sim)) {
            sim.profile
                .time(Stage::Output, || self.write_checkpoint(sim))?;
        }
        Ok(())
    }

    fn stop_requested(&self) -> bool {
        self.stop
    }
}

/// Outcome of a run started by [`run_scene`].
pub struct RunOutcome {
    /// The finished (or stopped) simulation.
    pub simulation: Simulation,
    /// Wall time, s.
    pub wall_seconds: f64,
    /// The error that stopped the run, if any (outputs up to it are kept).
    pub error: Option<RunError>,
    /// The fields at the `[output] snapshot_times` the run reached.
    pub fields: Vec<FieldSnapshot>,
}

/// Run a validated scene, writing `curve.csv`, snapshots and `run.json` into `out`.
/// Setup errors (the scene's geometry) are returned as `Err`; a failure during
/// the run is returned in [`RunOutcome::error`] after `run.json` is written.
pub fn run_scene(
    scene: Scene,
    out: &Path,
    show_progress: bool,
) -> Result<RunOutcome, Box<dyn std::error::Error + Send + Sync>> {
    run_scene_with(scene, out, show_progress, RunOptions::default())
}

/// What a run does besides its outputs.
#[derive(Default)]
pub struct RunOptions {
    /// Write a checkpoint every `every` steps, with the scene source
    /// `mpm-geo resume` rebuilds the run from ([`crate::checkpoint`]);
    /// `every = 0` writes one only when asked
    /// ([`OutputObserver::write_checkpoint`], e.g. on an interruption).
    pub checkpoint: Option<(crate::checkpoint::SceneSource, usize)>,
    /// Test hook: end the run after this step as a kill would (no last row,
    /// no `run.json`); the simulation in the outcome is then not finished.
    pub stop_after: Option<usize>,
}

/// [`run_scene`] with checkpoints and the stop hook of `options`.
pub fn run_scene_with(
    scene: Scene,
    out: &Path,
    show_progress: bool,
    options: RunOptions,
) -> Result<RunOutcome, Box<dyn std::error::Error + Send + Sync>> {
    let start = Instant::now();
    let sim = Simulation::new(scene)?;
    let observer = sim.profile.time(Stage::Output, || {
        OutputObserver::new(out, &sim, show_progress)
    })?;
    let checkpoints = match options.checkpoint {
        Some((source, every)) => Some(Checkpointer::start(out, &source, every)?),
        None => None,
    };
    let observer = observer.with_checkpoints(checkpoints, options.stop_after);
    drive(sim, observer, out, start)
}

/// Run `sim` to its end with `observer` (a new run or one resumed from a
/// checkpoint), then write the last row and `run.json`.
pub(crate) fn drive(
    mut sim: Simulation,
    mut observer: OutputObserver,
    out: &Path,
    start: Instant,
) -> Result<RunOutcome, Box<dyn std::error::Error + Send + Sync>> {
    let result = sim.run(&mut observer);
    if observer.stopped() && result.is_ok() {
        observer.progress.finish_and_clear();
    } else {
        observer.finish(&sim)?;
    }
    let wall_seconds = start.elapsed().as_secs_f64();
    let error = result.err();
    if !observer.stopped() || error.is_some() {
        write_run_json(&out.join("run.json"), &sim, wall_seconds, error.as_ref())?;
    }
    Ok(RunOutcome {
        simulation: sim,
        wall_seconds,
        error,
        fields: observer.fields,
    })
}

/// `run.json`: resolved scene, crate version, solver choices and the tangent
/// solver's factorisation counts, per-stage profile, work counters
/// ([`crate::profile::Work`], every counter, zeros too), status.
pub fn write_run_json(
    path: &Path,
    sim: &Simulation,
    wall_seconds: f64,
    error: Option<&RunError>,
) -> Result<(), RunError> {
    let model = &sim.model;
    let materials: Vec<_> = model
        .material_names
        .iter()
        .zip(&model.materials)
        .map(|(name, m)| json!({"name": name, "model": m.name(), "symmetric_tangent": m.has_symmetric_tangent()}))
        .collect();
    let factorisation = sim.integrator.factorisation_stats();
    let work: serde_json::Map<String, serde_json::Value> = sim
        .profile
        .work()
        .into_iter()
        .map(|(name, n)| (name.to_string(), n.into()))
        .collect();
    let value = json!({
        "mpm_geo_version": env!("CARGO_PKG_VERSION"),
        "status": if error.is_some() { "failed" } else { "completed" },
        "warnings": model.scene.warnings(),
        "error": error.map(|e| e.to_string()),
        "steps_completed": model.step,
        "time": model.time,
        "particles": model.particles.len(),
        "lost_points": model.lost_points,
        "grid_cells": model.grid.cells,
        "wall_seconds": wall_seconds,
        "rayon_threads": rayon::current_num_threads(),
        "materials": materials,
        "solver": {
            "analysis": model.analysis(),
            "linear_solver_policy": model.scene.solver.linear_solver,
            "usage": sim.integrator.usage(),
            "factorisation": {
                "symbolic": factorisation.symbolic,
                "numeric": factorisation.numeric,
                "numeric_cholesky": factorisation.numeric_cholesky,
                "numeric_lu": factorisation.numeric_lu,
                "symbolic_reuses": factorisation.numeric.saturating_sub(factorisation.symbolic),
                "cholesky_fallbacks": factorisation.cholesky_fallbacks,
                "solves": factorisation.solves,
                "symbolic_seconds": factorisation.symbolic_seconds,
                "numeric_seconds": factorisation.numeric_seconds,
                "solve_seconds": factorisation.solve_seconds,
                "probe_seconds": factorisation.probe_seconds,
            },
        },
        "profile": sim.profile.totals(wall_seconds),
        "work": work,
        "scene": model.scene,
    });
    write_json(path, &value)
}
