//! Running a scene to an output directory: the directory is locked and
//! checked ([`crate::output_dir`]), `run.json` says `running` before the first
//! step, and the observer writes `curve.csv`, snapshots and their `.pvd`
//! collection and drives the progress bar; at the end `run.json` says
//! `completed`, `failed` or `interrupted`. `run.json` lists the files the run
//! writes before it writes them ([`crate::manifest`]), which is what
//! `--overwrite` and `resume` remove.

use std::path::{Path, PathBuf};
use std::time::Instant;

use indicatif::{ProgressBar, ProgressStyle};

use crate::progress_lines::ProgressLines;
use serde_json::json;

use crate::checkpoint::Checkpointer;
use crate::error::RunError;
use crate::integrators::StepReport;
use crate::interrupt::{self, Interruption};
use crate::manifest::{self, Manifest, SNAPSHOTS_AHEAD};
use crate::output::{write_json, write_pvd, write_vtu, CurveWriter, OutputError};
use crate::output_dir;
use crate::profile::Stage;
use crate::provenance::{monitor_summaries, Provenance};
use crate::scene::{AnalysisKind, Scene};
use crate::simulation::{Observer, RunEnd, Simulation};

pub use crate::output::{FieldSnapshot, OutputCursor, PVD_FILE};

/// The run error of an output failure at `sim`'s current step and time.
fn at(sim: &Simulation) -> impl Fn(OutputError) -> RunError + '_ {
    |e| e.at(sim.model.state.step, sim.model.state.time)
}

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
    /// The snapshots written so far, (time, file name), for the `.pvd`.
    snapshots: Vec<(f64, String)>,
    /// Writes a checkpoint every N steps (`--checkpoint-every`) and on an interruption.
    checkpoints: Option<Checkpointer>,
    /// Continuing a run from a checkpoint: the start is already written.
    resumed: bool,
    /// Test hook: end the run after this step as a kill would (no last
    /// row, `run.json` left `running`, no checkpoint at that step).
    stop_after: Option<usize>,
    /// Set once the step `stop_after` is done.
    stop: bool,
    /// Plain progress lines (stderr not a terminal).
    lines: Option<ProgressLines>,
    /// The files of the run, recorded in `run.json` before they are written.
    manifest: Manifest,
    /// Where the run comes from, for the `run.json` it rewrites (set by
    /// [`drive`]).
    provenance: Option<Provenance>,
}

impl OutputObserver {
    /// Create `dir` and `curve.csv` in it; `manifest` is the run's record
    /// of its files (already in `run.json`), extended before each new snapshot.
    pub fn new(
        dir: &Path,
        sim: &Simulation,
        show_progress: bool,
        manifest: Manifest,
    ) -> Result<Self, RunError> {
        std::fs::create_dir_all(dir).map_err(|e| {
            OutputError {
                path: dir.to_path_buf(),
                source: e,
            }
            .at(sim.model.state.step, sim.model.state.time)
        })?;
        let mut columns = sim.step_column_names();
        columns.extend(sim.monitor_columns().into_iter().map(|(_, column)| column));
        let curve = CurveWriter::create(&dir.join("curve.csv"), &columns).map_err(at(sim))?;
        let progress = progress_bar(sim, show_progress);
        let mut pending_times = sim.scene.output.snapshot_times.clone();
        pending_times.sort_by(|a, b| b.total_cmp(a));
        Ok(Self {
            dir: dir.to_path_buf(),
            curve,
            progress,
            last_row_step: usize::MAX,
            pending_times,
            fields: Vec::new(),
            snapshots: Vec::new(),
            checkpoints: None,
            resumed: false,
            stop_after: None,
            stop: false,
            lines: None,
            manifest,
            provenance: None,
        })
    }

    /// Continue the outputs of `dir` from `cursor` (`sim` restored from the
    /// same checkpoint): `curve.csv` cut back to the cursor's length, the
    /// snapshots of later steps that `manifest` records removed (the run
    /// writes them again) and the `.pvd` rewritten with the earlier ones.
    pub fn resume(
        dir: &Path,
        sim: &Simulation,
        cursor: OutputCursor,
        show_progress: bool,
        manifest: Manifest,
    ) -> Result<Self, RunError> {
        let curve =
            CurveWriter::reopen(&dir.join("curve.csv"), cursor.curve_bytes).map_err(at(sim))?;
        remove_snapshots_after(dir, sim.model.state.step, &manifest).map_err(at(sim))?;
        if !cursor.snapshots.is_empty() {
            write_pvd(&dir.join(PVD_FILE), &cursor.snapshots).map_err(at(sim))?;
        }
        let progress = progress_bar(sim, show_progress);
        progress.set_position(progress_position(sim));
        Ok(Self {
            dir: dir.to_path_buf(),
            curve,
            progress,
            last_row_step: cursor.last_row_step.unwrap_or(usize::MAX),
            pending_times: cursor.pending_times,
            fields: cursor.fields,
            snapshots: cursor.snapshots,
            checkpoints: None,
            resumed: true,
            stop_after: None,
            stop: false,
            lines: None,
            manifest,
            provenance: None,
        })
    }

    /// The run's record of its files so far.
    pub fn manifest(&self) -> &Manifest {
        &self.manifest
    }

    /// Print plain progress lines every `every` seconds (`None`: none).
    pub fn with_progress_lines(mut self, sim: &Simulation, every: Option<f64>) -> Self {
        self.lines = every.map(|every| ProgressLines::new(sim, every));
        self
    }

    /// Write a checkpoint with `checkpoints` (every N steps and on an
    /// interruption, see [`Checkpointer`]) and end the run after step
    /// `stop_after` (test hook).
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
            snapshots: self.snapshots.clone(),
            curve_bytes: 0,
            curve_checksum: 0,
        }
    }

    /// Write a checkpoint of `sim` now, if the run writes checkpoints (the
    /// step's outputs must be written already). On an interruption it is
    /// written before the extra last row, which an uninterrupted run would
    /// not have (the resume cuts it off).
    pub fn write_checkpoint(&mut self, sim: &Simulation) -> Result<(), RunError> {
        let cursor = self.cursor();
        match self.checkpoints.as_mut() {
            Some(checkpoints) => checkpoints
                .write(sim, cursor)
                .map_err(|e| e.at(sim.model.state.step, sim.model.state.time)),
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
        let time = sim.model.state.time;
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
        let o = &sim.scene.output;
        let step = sim.model.state.step;
        o.snapshots.contains(&step)
            || (o.snapshot_every > 0 && step.is_multiple_of(o.snapshot_every))
    }

    /// Write `particles_<step>.vtu` and rewrite the `.pvd` collection; a
    /// name `run.json` does not list yet is recorded there first, with the
    /// next ones that can be foreseen.
    fn write_snapshot(&mut self, sim: &Simulation) -> Result<(), RunError> {
        let name = manifest::snapshot_name(sim.model.state.step);
        if !self.manifest.contains(&name) {
            foresee_snapshots(&mut self.manifest, sim, sim.model.state.step);
            self.manifest.add(&name);
            self.manifest.add(PVD_FILE);
            write_run_json(
                &self.dir.join("run.json"),
                sim,
                0.0,
                RunStatus::Running,
                &self.manifest,
                self.provenance.as_ref(),
            )
            .map_err(at(sim))?;
        }
        write_vtu(&self.dir.join(&name), &sim.model.state.particles).map_err(at(sim))?;
        self.snapshots.push((sim.model.state.time, name));
        write_pvd(&self.dir.join(PVD_FILE), &self.snapshots).map_err(at(sim))
    }

    /// The snapshots written so far: (time, file name), as in the `.pvd`.
    pub fn snapshots(&self) -> &[(f64, String)] {
        &self.snapshots
    }

    fn write_row(&mut self, sim: &Simulation) -> Result<(), RunError> {
        let model = &sim.model;
        let mut values = sim.step_column_values();
        values.extend(sim.monitor_values());
        self.curve
            .row(model.state.step, model.state.time, &values)
            .map_err(at(sim))?;
        self.last_row_step = model.state.step;
        Ok(())
    }

    /// Write the last row if it was skipped by `curve_every` (call at the end or on failure).
    pub fn finish(&mut self, sim: &Simulation) -> Result<(), RunError> {
        sim.profile.time(Stage::Output, || {
            self.progress.finish_and_clear();
            if self.last_row_step != sim.model.state.step {
                self.write_row(sim)?;
            }
            Ok(())
        })
    }

    fn show_progress(&self, sim: &Simulation, report: &StepReport) {
        let adaptive = sim.scene.solver.adaptive();
        match sim.model.analysis() {
            AnalysisKind::ImplicitDynamic if adaptive => {
                let end = sim.scene.scene.end_time_or_steps();
                self.progress
                    .set_position((1000.0 * sim.model.state.time / end) as u64);
                self.progress.set_message(format!(
                    "step {} t={:.4e} s dt={:.2e} s Newton {} it",
                    report.step, report.time, report.dt, report.iterations
                ));
            }
            AnalysisKind::Explicit => {
                let end = sim.scene.scene.end_time.unwrap_or(1.0);
                self.progress
                    .set_position((1000.0 * sim.model.state.time / end) as u64);
                self.progress.set_message(format!(
                    "step {} t={:.4e} s dt={:.2e} s",
                    report.step, report.time, report.dt
                ));
            }
            _ => {
                self.progress.set_position(sim.model.state.step as u64);
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

/// The interval of plain progress lines: `every` (default
/// [`crate::progress_lines::DEFAULT_INTERVAL`]) when progress is shown and
/// stderr is not a terminal (where the bar draws nothing), else none.
pub fn progress_lines_every(show: bool, every: Option<f64>) -> Option<f64> {
    use std::io::IsTerminal;
    (show && !std::io::stderr().is_terminal())
        .then(|| every.unwrap_or(crate::progress_lines::DEFAULT_INTERVAL))
}

/// A progress bar over the steps (implicit) or over 1000ths of the end time (explicit).
fn progress_bar(sim: &Simulation, show: bool) -> ProgressBar {
    if !show {
        return ProgressBar::hidden();
    }
    let total = match sim.model.analysis() {
        AnalysisKind::Explicit => 1000,
        AnalysisKind::ImplicitDynamic if sim.scene.solver.adaptive() => 1000,
        _ => sim.scene.scene.steps.unwrap_or(0) as u64,
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
            let end = sim.scene.scene.end_time.unwrap_or(1.0);
            (1000.0 * sim.model.state.time / end) as u64
        }
        _ => sim.model.state.step as u64,
    }
}

/// Remove the snapshots `particles_NNNNNN.vtu` of steps after `step` that
/// `manifest` records (a user's file of such a name stays).
fn remove_snapshots_after(dir: &Path, step: usize, manifest: &Manifest) -> Result<(), OutputError> {
    let later = manifest
        .files
        .iter()
        .filter(|name| manifest::snapshot_step(name).is_some_and(|n| n > step));
    for name in later {
        let path = dir.join(name);
        match std::fs::remove_file(&path) {
            Err(e) if e.kind() != std::io::ErrorKind::NotFound => {
                return Err(OutputError { path, source: e })
            }
            _ => {}
        }
    }
    Ok(())
}

/// Record in `manifest` the snapshot names of steps from `from` on that the
/// run can foresee: the steps of `[output] snapshots`, and the next
/// [`SNAPSHOTS_AHEAD`] multiples of `snapshot_every` (not past the last
/// step when the step count is fixed). Snapshots at `snapshot_times` fall
/// on steps known only when reached: they are recorded then.
pub fn foresee_snapshots(manifest: &mut Manifest, sim: &Simulation, from: usize) {
    let output = &sim.scene.output;
    for &step in output.snapshots.iter().filter(|&&s| s >= from) {
        manifest.add(&manifest::snapshot_name(step));
    }
    let every = output.snapshot_every;
    if every == 0 {
        return;
    }
    let fixed_steps = match sim.model.analysis() {
        AnalysisKind::Explicit => None,
        AnalysisKind::ImplicitDynamic if sim.scene.solver.adaptive() => None,
        _ => sim.scene.scene.steps,
    };
    let first = from.next_multiple_of(every);
    let mut last = first + (SNAPSHOTS_AHEAD - 1) * every;
    if let Some(steps) = fixed_steps {
        last = last.min(steps);
    }
    for step in (first..=last).step_by(every) {
        manifest.add(&manifest::snapshot_name(step));
    }
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
            let every = sim.scene.output.curve_every.max(1);
            if sim.model.state.step.is_multiple_of(every) || sim.finished() {
                self.write_row(sim)?;
            }
            let at_time = self.capture_due_times(sim);
            if Self::snapshot_due(sim) || at_time {
                self.write_snapshot(sim)?;
            }
            self.show_progress(sim, report);
            if let Some(lines) = &mut self.lines {
                lines.after_step(sim, report);
            }
            Ok::<_, RunError>(())
        })?;
        self.stop = self.stop_after == Some(sim.model.state.step);
        if !self.stop && self.checkpoints.as_ref().is_some_and(|c| c.due(sim)) {
            sim.profile
                .time(Stage::Output, || self.write_checkpoint(sim))?;
        }
        Ok(())
    }

    fn stop_requested(&self) -> bool {
        self.stop
    }

    fn interruption(&self) -> Option<Interruption> {
        interrupt::requested()
    }

    fn on_interrupt(
        &mut self,
        sim: &Simulation,
        _interruption: Interruption,
    ) -> Result<(), RunError> {
        sim.profile.time(Stage::Output, || {
            // a checkpoint of this step to resume from, taken before the
            // row below (which an uninterrupted run would not have)
            self.write_checkpoint(sim)?;
            // the interrupted step's row, even if `curve_every` skips it
            if self.last_row_step != sim.model.state.step {
                self.write_row(sim)?;
            }
            Ok(())
        })
    }
}

/// Outcome of a run started by [`run_scene`].
pub struct RunOutcome {
    /// The finished (or stopped) simulation.
    pub simulation: Simulation,
    /// Wall time, s.
    pub wall_seconds: f64,
    /// The first error that stopped the run, if any: a failed step or an
    /// output that could not be written (outputs up to it are kept, whole).
    pub error: Option<RunError>,
    /// The signal that stopped the run after a completed step, if any.
    pub interrupted: Option<Interruption>,
    /// The fields at the `[output] snapshot_times` the run reached.
    pub fields: Vec<FieldSnapshot>,
    /// The output directory's lock, held until the outcome is dropped (a
    /// campaign writes its run's record under it).
    pub lock: Option<output_dir::DirLock>,
}

/// How a run writes its output directory.
#[derive(Clone, Debug, Default)]
pub struct RunOptions {
    /// Draw a progress bar on stderr, or, when stderr is not a terminal,
    /// print plain progress lines ([`ProgressLines`]).
    pub show_progress: bool,
    /// Seconds between the plain progress lines (default
    /// [`crate::progress_lines::DEFAULT_INTERVAL`]).
    pub progress_every: Option<f64>,
    /// Remove an earlier run's files from the directory instead of refusing
    /// it ([`output_dir::prepare`]).
    pub overwrite: bool,
    /// Write a checkpoint every `every` steps and on an interruption, with
    /// the scene source `mpm-geo resume` rebuilds the run from
    /// ([`crate::checkpoint`]); `every = 0`: only on an interruption or
    /// when asked ([`OutputObserver::write_checkpoint`]).
    pub checkpoint: Option<(crate::checkpoint::SceneSource, usize)>,
    /// Test hook: end the run after this step as a kill would (no last row,
    /// `run.json` left `running`); the simulation in the outcome is then
    /// not finished.
    pub stop_after: Option<usize>,
    /// Files the caller writes into the directory after the run (a
    /// campaign's record), recorded in `run.json` with the run's own.
    pub extra_files: Vec<String>,
    /// Where the run comes from (`run.json` → `provenance`); `None`: this
    /// process, no scene file named.
    pub provenance: Option<Provenance>,
}

/// Run a validated scene, writing `curve.csv`, snapshots and `run.json` into
/// `out`, which must not hold an earlier run's files (see [`run_scene_with`]).
pub fn run_scene(
    scene: Scene,
    out: &Path,
    show_progress: bool,
) -> Result<RunOutcome, Box<dyn std::error::Error + Send + Sync>> {
    let options = RunOptions {
        show_progress,
        ..RunOptions::default()
    };
    run_scene_with(scene, out, &options)
}

/// Run a validated scene into `out`: lock the directory (refused if another
/// run holds it, or if it holds an earlier run's files and not
/// `options.overwrite`), write `run.json` with status `running`, run, and
/// rewrite `run.json` with the end status. Setup errors (the scene's
/// geometry, the directory) are returned as `Err` and write nothing; a
/// failure during the run (a step, or the first output that could not be
/// written) is returned in [`RunOutcome::error`], a signal in
/// [`RunOutcome::interrupted`].
pub fn run_scene_with(
    scene: Scene,
    out: &Path,
    options: &RunOptions,
) -> Result<RunOutcome, Box<dyn std::error::Error + Send + Sync>> {
    let start = Instant::now();
    let mut sim = Simulation::new(scene)?;
    let manifest = planned_manifest(&sim, options);
    let lock = output_dir::prepare(out, options.overwrite, &manifest)?;
    let systems = sim.scene.output.systems.clone();
    let max_mb = sim.scene.output.systems_max_mb;
    if let Some(implicit) = sim.integrator.implicit_mut() {
        implicit.export_systems(out.join(manifest::SYSTEMS_FOLDER), systems, max_mb);
    }
    let (show, stop_after) = (options.show_progress, options.stop_after);
    let lines = progress_lines_every(show, options.progress_every);
    let drive_options = Drive {
        start,
        lock,
        manifest,
        earlier: None,
        written_later: options.extra_files.clone(),
        provenance: options
            .provenance
            .clone()
            .unwrap_or_else(|| Provenance::now(None, &[])),
    };
    drive(sim, out, drive_options, move |sim, manifest| {
        let checkpoints = match &options.checkpoint {
            Some((source, every)) => Some(
                Checkpointer::start(out, source, *every, start)
                    .map_err(|e| e.at(sim.model.state.step, sim.model.state.time))?,
            ),
            None => None,
        };
        let observer = sim.profile.time(Stage::Output, || {
            OutputObserver::new(out, sim, show, manifest)
        })?;
        Ok(observer
            .with_checkpoints(checkpoints, stop_after)
            .with_progress_lines(sim, lines))
    })
}

/// The files a new run of `sim` with `options` will write, as far as they
/// can be foreseen: `run.json`, `curve.csv`, `particles.pvd` and the first
/// snapshots, the checkpoint files, the caller's files and the exported
/// systems.
fn planned_manifest(sim: &Simulation, options: &RunOptions) -> Manifest {
    let mut manifest = Manifest::new();
    for name in ["run.json", "curve.csv", PVD_FILE] {
        manifest.add(name);
    }
    if options.checkpoint.is_some() {
        manifest.add(crate::checkpoint::CHECKPOINT_FILE);
        manifest.add(crate::checkpoint::SOURCE_FILE);
    }
    for name in &options.extra_files {
        manifest.add(name);
    }
    let systems = &sim.scene.output.systems;
    if sim.integrator.implicit().is_some() && !systems.is_empty() {
        manifest.systems = Some(manifest::SystemsRecord {
            folder: manifest::SYSTEMS_FOLDER.into(),
            steps: systems.clone(),
        });
    }
    foresee_snapshots(&mut manifest, sim, sim.model.state.step);
    manifest
}

/// What [`drive`] needs besides the simulation and the directory.
pub(crate) struct Drive {
    /// When the command started (for the wall time).
    pub start: Instant,
    /// The directory's lock, handed on to the outcome.
    pub lock: output_dir::DirLock,
    /// The run's files as recorded so far.
    pub manifest: Manifest,
    /// A resumed run: the `run.json` it continues, put back if the resume
    /// fails before its time loop starts (it then changed nothing the
    /// checkpoint does not restore, and the run stays as it was).
    pub earlier: Option<Vec<u8>>,
    /// Files the caller writes after the run (a campaign's record): kept
    /// in the manifest though they do not exist yet when it is written.
    pub written_later: Vec<String>,
    /// Where the run comes from.
    pub provenance: Provenance,
}

/// Run `sim` in `out` (locked by the caller) with the observer `make`
/// gives (a new run's or a resumed one's, holding the manifest it is
/// given): `run.json` says `running`, the time loop, the last row,
/// `run.json` with the end status and the files that exist.
pub(crate) fn drive(
    mut sim: Simulation,
    out: &Path,
    options: Drive,
    make: impl FnOnce(&Simulation, Manifest) -> Result<OutputObserver, RunError>,
) -> Result<RunOutcome, Box<dyn std::error::Error + Send + Sync>> {
    let Drive {
        start,
        lock,
        manifest,
        earlier,
        written_later,
        provenance,
    } = options;
    let mut observer = None;
    let result = start_and_run(&mut sim, out, &manifest, &provenance, make, &mut observer);
    if let (Ok(_), Some(o)) = (&result, observer.as_mut()) {
        if o.stopped() {
            // the stop hook leaves what a kill leaves
            o.progress.finish_and_clear();
            return Ok(RunOutcome {
                wall_seconds: start.elapsed().as_secs_f64(),
                simulation: sim,
                error: None,
                interrupted: None,
                fields: observer.map(|o| o.fields).unwrap_or_default(),
                lock: Some(lock),
            });
        }
    }
    let (mut error, interrupted) = match result {
        Ok(RunEnd::Completed) => (None, None),
        Ok(RunEnd::Interrupted(signal)) => (None, Some(signal)),
        Err(e) => (Some(e), None),
    };
    if let Some(observer) = observer.as_mut() {
        if let Err(e) = observer.finish(&sim) {
            error.get_or_insert(e);
        }
    }
    let wall_seconds = start.elapsed().as_secs_f64();
    let status = match (&error, interrupted) {
        (Some(e), _) => RunStatus::Failed(e),
        (None, Some(signal)) => RunStatus::Interrupted(signal),
        (None, None) => RunStatus::Completed,
    };
    let path = out.join("run.json");
    let written = match earlier.filter(|_| observer.is_none()) {
        // a resume that never reached its time loop leaves the run as it was
        Some(bytes) => {
            crate::atomic_file::write_atomic(&path, bytes).map_err(|source| OutputError {
                path: path.clone(),
                source,
            })
        }
        None => {
            let mut manifest = observer.as_ref().map_or(manifest, |o| o.manifest.clone());
            manifest.retain_existing(out);
            for name in &written_later {
                manifest.add(name);
            }
            write_run_json(
                &path,
                &sim,
                wall_seconds,
                status,
                &manifest,
                Some(&provenance),
            )
        }
    };
    if let Err(e) = written {
        // the first error is the one reported; run.json keeps its last
        // whole version (`running`) if even this fails
        error.get_or_insert(e.at(sim.model.state.step, sim.model.state.time));
    }
    Ok(RunOutcome {
        simulation: sim,
        wall_seconds,
        interrupted: interrupted.filter(|_| error.is_none()),
        error,
        fields: observer.map(|o| o.fields).unwrap_or_default(),
        lock: Some(lock),
    })
}

/// `run.json` saying `running`, the observer (its `curve.csv`), the time loop.
fn start_and_run(
    sim: &mut Simulation,
    out: &Path,
    manifest: &Manifest,
    provenance: &Provenance,
    make: impl FnOnce(&Simulation, Manifest) -> Result<OutputObserver, RunError>,
    observer: &mut Option<OutputObserver>,
) -> Result<RunEnd, RunError> {
    write_run_json(
        &out.join("run.json"),
        sim,
        0.0,
        RunStatus::Running,
        manifest,
        Some(provenance),
    )
    .map_err(at(sim))?;
    let mut new = make(sim, manifest.clone())?;
    new.provenance = Some(provenance.clone());
    sim.run(observer.insert(new))
}

/// The status a `run.json` records.
#[derive(Clone, Copy, Debug)]
pub enum RunStatus<'a> {
    /// Written before the first step; a `run.json` that still says so after
    /// the process ended belongs to a run that was killed.
    Running,
    /// The run reached its end.
    Completed,
    /// A step failed or an output could not be written.
    Failed(&'a RunError),
    /// A signal stopped the run after a completed step.
    Interrupted(Interruption),
}

impl RunStatus<'_> {
    /// Whether `mpm-geo resume` can continue the run from its checkpoint: an
    /// interrupted run, or one whose write failed ([`RunError::resumable`]).
    pub fn resumable(&self) -> bool {
        match self {
            RunStatus::Interrupted(_) => true,
            RunStatus::Failed(e) => e.resumable(),
            RunStatus::Running | RunStatus::Completed => false,
        }
    }

    /// `running`, `completed`, `failed` or `interrupted`.
    pub fn name(&self) -> &'static str {
        match self {
            RunStatus::Running => "running",
            RunStatus::Completed => "completed",
            RunStatus::Failed(_) => "failed",
            RunStatus::Interrupted(_) => "interrupted",
        }
    }
}

/// `run.json`: resolved scene, crate version, solver choices and the tangent
/// solver's factorisation counts, per-stage profile, work counters
/// ([`crate::profile::Work`], every counter, zeros too), status (with the
/// error, or the signal of an interrupted run), the files of the run
/// (`manifest`), written whole.
pub fn write_run_json(
    path: &Path,
    sim: &Simulation,
    wall_seconds: f64,
    status: RunStatus<'_>,
    manifest: &Manifest,
    provenance: Option<&Provenance>,
) -> Result<(), OutputError> {
    let (error, error_id) = match status {
        RunStatus::Failed(e) => (
            Some(e.to_string()),
            Some(mpm_physics::error_id::Identified::error_id(e).name()),
        ),
        _ => (None, None),
    };
    let interrupted = match status {
        RunStatus::Interrupted(i) => Some(json!({"signal": i.name(), "exit_code": i.exit_code()})),
        _ => None,
    };
    let model = &sim.model;
    let materials: Vec<_> = model
        .material_names
        .iter()
        .zip(&model.materials)
        .map(|(name, m)| json!({"name": name, "model": m.name(), "symmetric_tangent": m.has_symmetric_tangent()}))
        .collect();
    let factorisation = sim.integrator.factorisation_stats();
    let implicit = sim.integrator.implicit();
    let solver_warnings = implicit.map_or_else(Vec::new, |i| i.solver_warnings());
    let energy = crate::energy::EnergyBudget::of(model);
    let energy_warning = energy.warning(sim.scene.output.energy_remainder_warning);
    let all_warnings = [
        sim.scene.warnings(),
        solver_warnings.clone(),
        energy_warning.into_iter().collect(),
        volume_warning(sim).into_iter().collect(),
    ]
    .concat();
    let newton_iterations = sim.integrator.usage().newton_iterations;
    let linear_seconds = factorisation.symbolic_seconds
        + factorisation.numeric_seconds
        + factorisation.solve_seconds
        + factorisation.probe_seconds;
    let work: serde_json::Map<String, serde_json::Value> = sim
        .profile
        .work()
        .into_iter()
        .map(|(name, n)| (name.to_string(), n.into()))
        .collect();
    let value = json!({
        "mpm_geo_version": env!("CARGO_PKG_VERSION"),
        "status": status.name(),
        "warnings": all_warnings,
        "error": error,
        "error_id": error_id,
        "interrupted": interrupted,
        "steps_completed": model.state.step,
        "time": model.state.time,
        "particles": model.state.particles.len(),
        "lost_points": model.state.lost_points,
        "point_volumes": point_volume_summary(sim),
        "energy": energy,
        "grid_cells": model.grid.cells,
        "wall_seconds": wall_seconds,
        "rayon_threads": rayon::current_num_threads(),
        "materials": materials,
        "solver": {
            "analysis": model.analysis(),
            "linear_solver_policy": sim.scene.solver.linear_solver,
            "usage": sim.integrator.usage(),
            "factorisation": {
                "symbolic": factorisation.symbolic,
                "numeric": factorisation.numeric,
                "numeric_cholesky": factorisation.numeric_cholesky,
                "numeric_lu": factorisation.numeric_lu,
                "symbolic_reuses": factorisation.numeric.saturating_sub(factorisation.symbolic),
                "reused_factors": factorisation.reused_factors,
                "gmres_iterations": factorisation.gmres_iterations,
                "gmres_refactorisations": factorisation.gmres_refactorisations,
                "cholesky_fallbacks": factorisation.cholesky_fallbacks,
                "solves": factorisation.solves,
                "symbolic_seconds": factorisation.symbolic_seconds,
                "numeric_seconds": factorisation.numeric_seconds,
                "solve_seconds": factorisation.solve_seconds,
                "probe_seconds": factorisation.probe_seconds,
            },
            "linear": {
                "options": {
                    "linear_solver": sim.scene.solver.linear_solver,
                    "factorization": sim.scene.solver.factorization,
                    "ordering": sim.scene.solver.ordering,
                    "pcg_preconditioner": sim.scene.solver.pcg_preconditioner,
                    "pcg_tolerance": sim.scene.solver.pcg_tolerance,
                },
                "symbolic_seconds": factorisation.symbolic_seconds,
                "numeric_seconds": factorisation.numeric_seconds,
                "solve_seconds": factorisation.solve_seconds,
                "probe_seconds": factorisation.probe_seconds,
                "seconds_per_newton_iteration": if newton_iterations > 0 { linear_seconds / newton_iterations as f64 } else { 0.0 },
                "factor_nnz": factorisation.factor_nnz,
                "factor_variant": factorisation.last_variant,
                "pcg_iterations": factorisation.pcg_iterations,
                "pcg_last_iterations": factorisation.last_pcg_iterations,
                "pcg_final_residual": factorisation.last_pcg_residual,
                "pcg_max_final_residual": factorisation.max_pcg_residual,
                "fallbacks_to_lu": factorisation.fallbacks,
                "warnings": solver_warnings,
                "systems_exported": implicit.map_or(0, |i| i.systems_written()),
            },
        },
        "profile": sim.profile.totals(wall_seconds),
        "work": work,
        "manifest": manifest,
        "provenance": provenance_record(provenance, sim, status),
        "summary": run_summary(path, sim, status),
        "scene": sim.scene,
    });
    write_json(path, &value)
}

/// `run.json` → `provenance`: where the run came from, the scene's
/// fingerprint (FNV-1a of its resolved form, as campaign records keep it)
/// and, once it ended, when.
fn provenance_record(
    provenance: Option<&Provenance>,
    sim: &Simulation,
    status: RunStatus<'_>,
) -> serde_json::Value {
    let mut record = match provenance {
        Some(p) => serde_json::to_value(p).unwrap_or_default(),
        None => serde_json::to_value(Provenance::now(None, &[])).unwrap_or_default(),
    };
    let scene = serde_json::to_string(&sim.scene).unwrap_or_default();
    record["scene_fingerprint"] = crate::provenance::fingerprint_text(&scene).into();
    record["ended_at"] = match status {
        RunStatus::Running => serde_json::Value::Null,
        _ => crate::provenance::timestamp().into(),
    };
    record
}

/// `run.json` → `summary` of a run that ended (null while it runs): its
/// status, steps and time, each monitor's last and peak value over
/// `curve.csv` (beside `run_json`), and where to look.
fn run_summary(run_json: &Path, sim: &Simulation, status: RunStatus<'_>) -> serde_json::Value {
    if matches!(status, RunStatus::Running) {
        return serde_json::Value::Null;
    }
    let dir = run_json.parent().unwrap_or(Path::new("."));
    let monitors =
        monitor_summaries(&dir.join("curve.csv"), &sim.monitor_columns()).unwrap_or_default();
    let pvd = dir.join(PVD_FILE);
    json!({
        "status": status.name(),
        "steps": sim.model.state.step,
        "time": sim.model.state.time,
        "monitors": monitors,
        "outputs": dir.display().to_string(),
        "paraview": pvd.exists().then(|| pvd.display().to_string()),
        "resume": status
            .resumable()
            .then(|| dir.join("checkpoint.bin"))
            .filter(|c| c.exists())
            .map(|_| format!("mpm-geo resume {}", dir.display())),
    })
}

/// The largest point volume at the end of the run, in cell areas h², and
/// how many points sit at the `grid.max_point_volume` bound (null when
/// unset): how far the motion stretched the points (a 2 × 2 layout starts
/// at 0.25).
fn point_volume_summary(sim: &Simulation) -> serde_json::Value {
    let model = &sim.model;
    let cell_area = model.grid.cell_size.powi(2);
    let largest = model
        .state
        .particles
        .volume
        .iter()
        .copied()
        .fold(0.0, f64::max)
        / cell_area;
    let at_bound = model.settings.grid.max_point_volume.map(|cells| {
        let bound = cells * cell_area;
        model
            .state
            .particles
            .volume
            .iter()
            .filter(|&&v| v >= bound * (1.0 - 1e-12))
            .count()
    });
    let range = jacobian_range(sim);
    json!({
        "largest_cells": largest,
        "bound_cells": model.settings.grid.max_point_volume,
        "at_bound": at_bound,
        "jacobian_range": range.map(|r| [r.smallest, r.largest]),
        "jacobian_out_of_range": range.map(|r| r.outside),
    })
}

/// The range of the points' volume ratio J = V/V0 a run is trusted over
/// without a word: a point squeezed below 1 % of its volume or stretched
/// beyond 100 times it stands for a domain the transfers no longer resolve.
pub const JACOBIAN_RANGE: [f64; 2] = [1e-2, 1e2];

/// The points' volume ratios J = V/V0 (V0 = m / ρ0 of the point's
/// material) at the end of a run.
#[derive(Clone, Copy, Debug)]
pub struct JacobianRange {
    /// Smallest J.
    pub smallest: f64,
    /// Largest J.
    pub largest: f64,
    /// Points outside [`JACOBIAN_RANGE`], those held at the scene's
    /// `grid.max_point_volume` bound left out (that stretch is the scene's
    /// choice).
    pub outside: usize,
}

/// J = V/V0 over the points of the run `sim` (`None` without points).
pub fn jacobian_range(sim: &Simulation) -> Option<JacobianRange> {
    let model = &sim.model;
    let p = &model.state.particles;
    let density: Vec<f64> = model
        .material_names
        .iter()
        .map(|name| sim.scene.materials.get(name).map_or(0.0, |m| m.density()))
        .collect();
    let bound = model
        .settings
        .grid
        .max_point_volume
        .map(|cells| cells * model.grid.cell_size.powi(2) * (1.0 - 1e-12));
    let mut range: Option<JacobianRange> = None;
    for i in 0..p.len() {
        let rho0 = density.get(p.material[i] as usize).copied().unwrap_or(0.0);
        if p.mass[i] <= 0.0 || rho0 <= 0.0 {
            continue;
        }
        let j = p.volume[i] * rho0 / p.mass[i];
        let at_bound = bound.is_some_and(|b| p.volume[i] >= b);
        let outside =
            usize::from(!at_bound && !(JACOBIAN_RANGE[0]..=JACOBIAN_RANGE[1]).contains(&j));
        range = Some(match range {
            None => JacobianRange {
                smallest: j,
                largest: j,
                outside,
            },
            Some(r) => JacobianRange {
                smallest: r.smallest.min(j),
                largest: r.largest.max(j),
                outside: r.outside + outside,
            },
        });
    }
    range
}

/// The warning of a run whose points left [`JACOBIAN_RANGE`].
pub fn volume_warning(sim: &Simulation) -> Option<String> {
    let r = jacobian_range(sim)?;
    (r.outside > 0).then(|| {
        format!(
            "{} material point(s) end with a volume ratio V/V0 outside [{:e}, {:e}] (from {:.2e} to {:.2e}): the body was crushed or torn beyond what the grid resolves; check the loads, the time step and `grid.max_point_volume`",
            r.outside, JACOBIAN_RANGE[0], JACOBIAN_RANGE[1], r.smallest, r.largest
        )
    })
}
