//! Running a campaign: finding the scenes, running them `jobs` at a time into
//! `out/<scene>/`, and the time-step refinement of each scene.

use crate::progress_lines::BatchProgress;
use crate::provenance::Provenance;
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::time::Instant;

use super::footing::FootingGeometry;
use super::history::{write_history_outputs, History, HistoryColumns};
use super::record::{fingerprint, Part, RunRecord};
use super::report::{
    first_monitor_of, last_value, read_curve, write_outputs, write_step_convergence,
};
use super::spec::{Benchmark, CampaignSpec, SPEC_FILE};
use super::{CampaignError, CampaignRun, CurveColumns, Effort, EnergyBalance};
use crate::checkpoint::{Resumable, ResumeOptions, SceneSource};
use crate::output::deviatoric_hencky_strain;
use crate::run::{run_scene_with, RunOptions};
use crate::scene::{Formulation, MonitorKind, Scene};

/// How a campaign is run.
#[derive(Clone, Debug, Default)]
pub struct CampaignOptions {
    /// Runs at a time.
    pub jobs: usize,
    /// `--set key=value` edits applied to every scene.
    pub overrides: Vec<String>,
    /// Also run every scene with K times the steps (time-step convergence).
    pub step_refinement: Option<usize>,
    /// The scenes as written or the paper's literal formulation.
    pub formulation: Formulation,
    /// The whole campaign, one shard of it, or the report from the shards.
    pub part: Part,
    /// Checkpoint every run every N steps, and resume a run stopped earlier
    /// from its checkpoint.
    pub checkpoint_every: Option<usize>,
}

fn scenes_in(dir: &Path) -> Result<Vec<PathBuf>, CampaignError> {
    let entries = std::fs::read_dir(dir)
        .map_err(|e| CampaignError::Directory(dir.display().to_string(), e.to_string()))?;
    let mut paths: Vec<PathBuf> = entries
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .filter(|p| p.file_name().is_some_and(|n| n != SPEC_FILE))
        .collect();
    paths.sort();
    if paths.is_empty() {
        return Err(CampaignError::Directory(
            dir.display().to_string(),
            "no .toml scene in it".into(),
        ));
    }
    Ok(paths)
}

/// Run every scene of `dir` (validated first, all of them, before anything
/// runs) with every integrator of the directory's `campaign.toml`,
/// `options.jobs` at a time, into `out/<scene>[_explicit]/`, then write the
/// combined outputs of its benchmark. With `step_refinement = Some(K)` every
/// scene is also run with K times the steps at Δt / K (into
/// `out/<scene>_dtK/`) and the time-step discrepancy of each curve is reported
/// (`step_convergence.csv`, report section). Returns the runs in scene order,
/// refinements after the scenes; a run's unreadable `curve.csv` is an error
/// once every run has finished. A run whose directory another process holds
/// (a second campaign into the same `out`) is not run and nothing is
/// recorded for it ([`CampaignError::Locked`]); after SIGINT/SIGTERM (with
/// [`crate::interrupt`] installed) the runs in progress stop after a whole
/// step, no other starts, and no report is written
/// ([`CampaignError::Interrupted`]).
pub fn run_campaign(
    dir: &Path,
    out: &Path,
    options: &CampaignOptions,
) -> Result<Vec<CampaignRun>, CampaignError> {
    let mut plans = [plan_campaign(dir, out, options, "campaign")?];
    run_queued(&mut plans, options);
    let [plan] = plans;
    finish_campaign(plan, options)
}

/// A campaign's runs, planned before any of them runs: its scenes, which of
/// them this part selects, the records of the runs finished earlier, and
/// (filled by [`run_queued`]) what became of the others.
pub struct CampaignPlan {
    /// What its progress lines start with.
    label: String,
    spec: CampaignSpec,
    out: PathBuf,
    all: Vec<Planned>,
    costs: Vec<f64>,
    selected: Vec<bool>,
    records: Vec<Option<RunRecord>>,
    window: Option<crate::plot::Bounds>,
    /// What each run done in this process ended in, by its index in `all`.
    executed: Vec<(usize, Result<Executed, CampaignError>)>,
    /// When the last of them ended.
    last_ended: Option<Instant>,
}

impl CampaignPlan {
    /// The runs to do: selected and not finished earlier, the longest
    /// (finest meshes, refinements) first.
    fn queue(&self) -> Vec<usize> {
        let mut queue: Vec<usize> = (0..self.all.len())
            .filter(|&i| self.selected[i] && self.records[i].is_none())
            .collect();
        queue.sort_by(|&a, &b| self.costs[a].total_cmp(&self.costs[b]));
        queue.reverse();
        queue
    }

    /// Runs selected and finished earlier.
    fn earlier(&self) -> usize {
        (0..self.all.len())
            .filter(|&i| self.selected[i] && self.records[i].is_some())
            .count()
    }

    /// When the last run this process did of the campaign ended (`None`:
    /// it did none).
    pub fn last_ended(&self) -> Option<Instant> {
        self.last_ended
    }
}

/// Plan the campaign of `dir` into `out` ([`run_campaign`]): load and
/// validate every scene, and find the runs finished earlier. Its progress
/// lines start with `label`.
pub fn plan_campaign(
    dir: &Path,
    out: &Path,
    options: &CampaignOptions,
    label: &str,
) -> Result<CampaignPlan, CampaignError> {
    let spec = CampaignSpec::load(dir)?;
    let paths = scenes_in(dir)?;
    let mut scenes: Vec<(String, String, Scene)> = Vec::new();
    for path in &paths {
        let stem = path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        let scene = Scene::load(path, &options.overrides)
            .and_then(|s| s.with_formulation(options.formulation))
            .map_err(|e| CampaignError::Scene(e.to_string()))?;
        for integrator in &spec.integrators {
            let name = format!("{stem}{}", integrator.suffix());
            scenes.push((name, stem.clone(), integrator.apply(&scene)?));
        }
    }
    let mut variants: Vec<Planned> = Vec::new();
    if let Some(k) = options.step_refinement {
        for (name, stem, scene) in &scenes {
            variants.push(Planned::new(
                format!("{name}_dt{k}"),
                stem.clone(),
                refine_steps(name, scene, k)?,
                k,
            ));
        }
    }
    let window = scenes
        .first()
        .map(|(_, _, scene)| spec.benchmark.field_window(scene));
    let all: Vec<Planned> = scenes
        .into_iter()
        .map(|(name, scene_file, scene)| Planned::new(name, scene_file, scene, 1))
        .chain(variants)
        .collect();
    let costs: Vec<f64> = all.iter().map(Planned::cost).collect();
    let selected = options.part.selects(&costs);
    // runs finished earlier (same scene, their record matching their
    // run.json and curve.csv) are not run again
    let mut records: Vec<Option<RunRecord>> = Vec::with_capacity(all.len());
    for (planned, selected) in all.iter().zip(&selected) {
        let record = match RunRecord::verify(&out.join(&planned.name), &planned.fingerprint) {
            Ok(record) => record,
            Err(why) => {
                if *selected {
                    eprintln!("{label}: {} is run again: {why}", planned.name);
                }
                None
            }
        };
        if record.is_some() && *selected {
            eprintln!("{label}: {} finished earlier, not run again", planned.name);
        }
        records.push(record);
    }
    Ok(CampaignPlan {
        label: label.to_string(),
        spec,
        out: out.to_path_buf(),
        all,
        costs,
        selected,
        records,
        window,
        executed: Vec::new(),
        last_ended: None,
    })
}

/// Run the queued runs of every plan, `options.jobs` at a time, into the
/// plans' folders: the first plan's runs first (the longest first), and
/// each next plan's as soon as a job is free, so that no core waits for
/// the last run of a campaign while another campaign has runs to do. What
/// each run ended in goes to its plan.
pub fn run_queued(plans: &mut [CampaignPlan], options: &CampaignOptions) {
    let jobs = options.jobs.max(1);
    let mut queue: Vec<(usize, usize)> = Vec::new();
    let mut progress = Vec::with_capacity(plans.len());
    for (p, plan) in plans.iter().enumerate() {
        let runs = plan.queue();
        let costs: Vec<f64> = runs.iter().map(|&i| plan.costs[i]).collect();
        let at_a_time = jobs.min(runs.len().max(1));
        progress.push(Mutex::new(BatchProgress::start(
            &plan.label,
            &costs,
            plan.earlier(),
            at_a_time,
        )));
        queue.extend(runs.into_iter().map(|i| (p, i)));
    }
    // popped from the back
    queue.reverse();
    let queue = Mutex::new(queue);
    let results = Mutex::new(Vec::new());
    let plans_read: &[CampaignPlan] = plans;
    let run_next = || loop {
        // after SIGINT/SIGTERM no further run starts
        if crate::interrupt::requested().is_some() {
            break;
        }
        let next = queue.lock().map(|mut q| q.pop()).unwrap_or(None);
        let Some((p, index)) = next else {
            break;
        };
        let plan = &plans_read[p];
        let planned = &plan.all[index];
        if let Ok(mut progress) = progress[p].lock() {
            progress.started(&planned.name);
        }
        let out = plan.out.join(&planned.name);
        let executed = execute(planned, &out, options.checkpoint_every, &plan.label);
        say(&plan.label, &planned.name, &executed);
        if let Ok(mut progress) = progress[p].lock() {
            eprintln!("{}", progress.finished(plan.costs[index]));
        }
        if let Ok(mut r) = results.lock() {
            r.push((p, index, executed, Instant::now()));
        }
    };
    // Every job's pool has all the threads, so a run left alone at the end
    // (the longest starts first, so it often is) keeps every core busy;
    // while jobs run side by side their pools share the cores (more threads
    // than cores then, the OS time-slicing them). Before, each pool had
    // threads / jobs workers: the biaxial campaign (2 jobs, 2 cores) spent
    // 38 % of its wall time on one thread with a core idle.
    let threads_per_job = rayon::current_num_threads();
    std::thread::scope(|scope| {
        for _ in 0..jobs {
            scope.spawn(|| {
                // each job's parallel loops in a pool of its own, this thread one of its workers
                match crate::parallel::job_pool(threads_per_job) {
                    Some(pool) => pool.install(run_next),
                    None => run_next(),
                }
            });
        }
    });
    for (p, index, executed, ended) in results.into_inner().unwrap_or_default() {
        let plan = &mut plans[p];
        plan.executed.push((index, executed));
        plan.last_ended = plan.last_ended.max(Some(ended));
    }
}

/// The campaign's runs once [`run_queued`] has run them: every run's
/// record, and (not for a shard) the combined outputs of its benchmark.
/// Returns the runs in scene order, refinements after the scenes.
pub fn finish_campaign(
    plan: CampaignPlan,
    options: &CampaignOptions,
) -> Result<Vec<CampaignRun>, CampaignError> {
    let CampaignPlan {
        spec,
        out,
        all,
        selected,
        mut records,
        window,
        executed,
        ..
    } = plan;
    let (mut locked, mut stopped) = (Vec::new(), Vec::new());
    for (index, executed) in executed {
        match executed? {
            Executed::Finished(record) | Executed::NotSetUp(record) => {
                records[index] = Some(record)
            }
            Executed::Locked(why) => locked.push(format!("{} ({why})", all[index].name)),
            Executed::Interrupted(_) => stopped.push(all[index].name.clone()),
        }
    }
    if let Some(signal) = crate::interrupt::requested() {
        stopped.sort();
        return Err(CampaignError::Interrupted { signal, stopped });
    }
    if !locked.is_empty() {
        locked.sort();
        return Err(CampaignError::Locked(locked.join("; ")));
    }
    let in_scope: Vec<usize> = match options.part {
        Part::Shard { .. } => (0..all.len()).filter(|&i| selected[i]).collect(),
        Part::Whole | Part::Collect => (0..all.len()).collect(),
    };
    let missing: Vec<&str> = in_scope
        .iter()
        .filter(|&&i| records[i].is_none())
        .map(|&i| all[i].name.as_str())
        .collect();
    if !missing.is_empty() {
        return Err(CampaignError::Unfinished(missing.join(", ")));
    }
    let mut runs = Vec::with_capacity(in_scope.len());
    for i in in_scope {
        let record = records[i]
            .take()
            .unwrap_or_else(|| RunRecord::new(String::new()));
        runs.push(gather(
            &all[i],
            record,
            &out.join(&all[i].name),
            spec.benchmark,
        )?);
    }
    if let Part::Shard { .. } = options.part {
        return Ok(runs);
    }
    let scenes_as_written: Vec<CampaignRun> = runs
        .iter()
        .filter(|r| r.step_factor == 1)
        .cloned()
        .collect();
    let window = window.unwrap_or(crate::plot::Bounds::new(0.0, 1.0, 0.0, 1.0));
    match spec.benchmark {
        Benchmark::VerticalCut => write_history_outputs(&out, &scenes_as_written, window)?,
        benchmark => write_outputs(&out, &scenes_as_written, benchmark, window)?,
    }
    if options.step_refinement.is_some() {
        write_step_convergence(&out, &runs)?;
    }
    Ok(runs)
}

/// A run waiting in the campaign's queue.
struct Planned {
    name: String,
    scene_file: String,
    scene: Scene,
    step_factor: usize,
    /// [`fingerprint`] of the scene and step factor.
    fingerprint: String,
}

impl Planned {
    fn new(name: String, scene_file: String, scene: Scene, step_factor: usize) -> Self {
        let fingerprint = fingerprint(&scene, step_factor);
        Self {
            name,
            scene_file,
            scene,
            step_factor,
            fingerprint,
        }
    }

    /// Estimated cost: step factor / h².
    fn cost(&self) -> f64 {
        self.step_factor as f64 / self.scene.grid.cell_size.powi(2)
    }
}

/// The scene with K times the steps at Δt / K (loads are functions of time, so
/// the loading path is the same); snapshot steps are scaled too.
fn refine_steps(name: &str, scene: &Scene, k: usize) -> Result<Scene, CampaignError> {
    if k < 2 {
        return Err(CampaignError::Scene(format!(
            "--step-refinement must be at least 2 (got {k})"
        )));
    }
    let mut refined = scene.clone();
    let analysis = &mut refined.scene;
    let Some(steps) = analysis.steps else {
        return Err(CampaignError::Scene(format!(
            "{name}: --step-refinement needs implicit scenes with `scene.steps` (explicit runs choose their own step)"
        )));
    };
    analysis.steps = Some(steps * k);
    analysis.dt = Some(analysis.dt.unwrap_or(1.0) / k as f64);
    refined.output.snapshots = scene.output.snapshots.iter().map(|s| s * k).collect();
    Ok(refined)
}

/// How one planned run of a campaign ended in this process.
enum Executed {
    /// It ran to its end (completed, or stopped by a failed step); its
    /// record is saved in its directory.
    Finished(RunRecord),
    /// It could not be set up (the message is in the record, which is not
    /// saved: the run is tried again by the next campaign).
    NotSetUp(RunRecord),
    /// Another live process holds its directory (why, with the process id).
    Locked(String),
    /// A signal stopped it after a whole step; its `run.json` says
    /// `interrupted` and no record is saved.
    Interrupted(crate::interrupt::Interruption),
}

/// Print how a run ended, after `label`.
fn say(label: &str, name: &str, executed: &Result<Executed, CampaignError>) {
    match executed {
        Ok(Executed::Finished(record)) | Ok(Executed::NotSetUp(record)) => eprintln!(
            "{label}: {name} finished in {:.1} s{}",
            record.wall_seconds,
            record
                .error
                .as_ref()
                .map(|e| format!(" (stopped: {e})"))
                .unwrap_or_default()
        ),
        Ok(Executed::Locked(why)) => eprintln!("{label}: {name} not run here: {why}"),
        Ok(Executed::Interrupted(signal)) => eprintln!(
            "{label}: {name} interrupted by {} after a whole step",
            signal.name()
        ),
        Err(e) => eprintln!("{label}: {name}: {e}"),
    }
}

/// Run one planned scene into `out` and, if it ran to its end, leave its
/// [`RunRecord`] there, written while the run's lock is still held. With
/// `checkpoint_every`, the run writes checkpoints, and a run of the same
/// scene stopped earlier in `out` (a killed campaign) is resumed from its
/// checkpoint instead of started again. `label` starts its progress line.
fn execute(
    planned: &Planned,
    out: &Path,
    checkpoint_every: Option<usize>,
    label: &str,
) -> Result<Executed, CampaignError> {
    let mut record = RunRecord::new(planned.fingerprint.clone());
    let start = Instant::now();
    let extra_files = vec![super::RECORD_FILE.to_string()];
    let outcome = match checkpoint_every.and_then(|_| resumable(planned, out)) {
        Some(resumable) => {
            eprintln!(
                "{label}: {} resumed from the checkpoint of step {}",
                planned.name,
                resumable.step()
            );
            let options = ResumeOptions {
                extra_files,
                ..ResumeOptions::default()
            };
            resumable.run(false, &options)
        }
        None => {
            // the campaign owns its runs' directories: an earlier campaign's
            // files there (of another scene: a finished run of this one is
            // not run again) are replaced
            let source = |every| {
                let text = toml::to_string(&planned.scene).unwrap_or_default();
                let source = SceneSource {
                    origin: planned.name.clone(),
                    text,
                    overrides: Vec::new(),
                };
                (source, every)
            };
            let options = RunOptions {
                show_progress: false,
                overwrite: true,
                checkpoint: checkpoint_every.map(source),
                extra_files,
                provenance: Some(Provenance::now(Some(Path::new(&planned.scene_file)), &[])),
                ..Default::default()
            };
            run_scene_with(planned.scene.clone(), out, &options)
        }
    };
    let outcome = match outcome {
        Ok(outcome) => outcome,
        Err(e) => {
            if let Some(lock) = e.downcast_ref::<crate::output_dir::OutputDirError>() {
                if matches!(lock, crate::output_dir::OutputDirError::Locked { .. }) {
                    return Ok(Executed::Locked(lock.to_string()));
                }
            }
            record.error = Some(e.to_string());
            record.wall_seconds = start.elapsed().as_secs_f64();
            return Ok(Executed::NotSetUp(record));
        }
    };
    if let Some(signal) = outcome.interrupted {
        return Ok(Executed::Interrupted(signal));
    }
    let model = &outcome.simulation.model;
    let p = &model.state.particles;
    record.positions = p.position.clone();
    record.volumes = p.volume.clone();
    record.initial_volumes = initial_volumes(p, &model.material_names, &planned.scene);
    let usage = outcome.simulation.integrator.usage();
    record.effort = Effort {
        steps: model.state.step,
        newton_iterations: usage.newton_iterations,
        halvings: usage.halvings,
    };
    record.eps_q = p.def_grad.iter().map(deviatoric_hencky_strain).collect();
    if planned.scene.nonlocal.is_some() {
        record.kappa_bar = p
            .state
            .iter()
            .map(|s| s.plastic_strain_eq_nonlocal)
            .collect();
    }
    record.error = outcome.error.as_ref().map(|e| e.to_string());
    let lost_mass: f64 = model.state.lost_points.iter().map(|l| l.mass).sum();
    let total_mass = p.mass.iter().sum::<f64>() + lost_mass;
    record.lost_points = (model.state.lost_points.len(), lost_mass / total_mass);
    record.profile = outcome.simulation.profile.table(outcome.wall_seconds);
    record.wall_seconds = start.elapsed().as_secs_f64();
    record.fields = outcome.fields;
    // still under the run's lock (`outcome.lock`, released below)
    record.seal(out)?;
    record.save(out)?;
    drop(outcome.lock);
    Ok(Executed::Finished(record))
}

/// Volume of every point before it deformed, m_p / ρ of its material
/// (NaN for a material the scene does not name, which a built model never
/// has).
fn initial_volumes(
    p: &crate::particles::Particles,
    material_names: &[String],
    scene: &Scene,
) -> Vec<f64> {
    let density: Vec<f64> = material_names
        .iter()
        .map(|name| scene.materials.get(name).map_or(f64::NAN, |m| m.density()))
        .collect();
    p.mass
        .iter()
        .zip(&p.material)
        .map(|(m, &k)| m / density[k as usize])
        .collect()
}

/// The checkpointed run of `planned`'s scene in `out`, if there is one.
fn resumable(planned: &Planned, out: &Path) -> Option<Resumable> {
    if !out.join(crate::checkpoint::CHECKPOINT_FILE).is_file() {
        return None;
    }
    let resumable = Resumable::open(out).ok()?;
    (fingerprint(resumable.scene(), planned.step_factor) == planned.fingerprint)
        .then_some(resumable)
}

/// The campaign run of `planned` from its record and the `curve.csv` in
/// `out`; an unreadable curve is an error.
fn gather(
    planned: &Planned,
    record: RunRecord,
    out: &Path,
    benchmark: Benchmark,
) -> Result<CampaignRun, CampaignError> {
    let scene = &planned.scene;
    let mut run = CampaignRun {
        scene: planned.scene_file.clone(),
        analysis: scene.scene.analysis,
        scheme: scene.scheme(),
        history: None,
        fields: record.fields,
        volumes: record.volumes,
        initial_volumes: record.initial_volumes,
        // the footing's numbers belong to the footing benchmark only (a biaxial
        // platen is a rigid body too)
        footing: (benchmark == Benchmark::Footing)
            .then(|| FootingGeometry::of_scene(scene))
            .flatten(),
        effort: record.effort,
        name: planned.name.clone(),
        cell_size: scene.grid.cell_size,
        length_scale: scene.nonlocal.as_ref().map(|n| n.length_scale),
        curve: Vec::new(),
        curve_columns: CurveColumns::of_scene(scene),
        positions: record.positions,
        eps_q: record.eps_q,
        kappa_bar: record.kappa_bar,
        error: record.error,
        lost_points: record.lost_points,
        dissipation: None,
        energy: None,
        wall_seconds: record.wall_seconds,
        profile: record.profile,
        step_factor: planned.step_factor,
    };
    let curve = out.join("curve.csv");
    // a run whose setup failed may have written no curve: it then has none
    if curve.exists() {
        if let Some(columns) = &run.curve_columns {
            run.curve = read_curve(&curve, columns)?;
        }
        if let Some(columns) = &HistoryColumns::of_scene(scene) {
            run.history = Some(History::read(&curve, columns)?);
        }
    }
    // the last value of the scene's first monitor of `kind`
    let last = |kind| first_monitor_of(scene, &[kind]).and_then(|c| last_value(&curve, &c));
    run.dissipation = last(MonitorKind::DissipatedEnergy);
    run.energy = match (
        last(MonitorKind::ExternalWork),
        last(MonitorKind::InternalWork),
        last(MonitorKind::KineticEnergy),
    ) {
        (Some(external), Some(internal), Some(kinetic)) => Some(EnergyBalance {
            external,
            internal,
            kinetic,
            boundary: last(MonitorKind::BoundaryWork).unwrap_or(0.0),
        }),
        _ => None,
    };
    Ok(run)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::Model;

    /// m_p/ρ, with the material's own (overridden) density, is the seeded
    /// volume h²/n² of every point, whatever the point's current volume.
    #[test]
    fn initial_volumes_are_the_seeded_volumes() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("validation/footing/local_h250.toml");
        let overrides = ["materials.soil.density=1.7".to_string()];
        let scene = Scene::load(&path, &overrides).expect("footing scene");
        let model = Model::new(&scene).expect("model");
        let seeded = (scene.grid.cell_size / scene.grid.points_per_cell as f64).powi(2);
        let p = &model.state.particles;
        let v0 = initial_volumes(p, &model.material_names, &scene);
        assert_eq!(v0.len(), p.len());
        for v in v0 {
            assert!((v / seeded - 1.0).abs() < 1e-12, "{v} against {seeded}");
        }
    }
}
