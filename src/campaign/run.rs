//! Running a campaign: finding the scenes, running them `jobs` at a time into
//! `out/<scene>/`, and the time-step refinement of each scene.

use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::time::Instant;

use super::footing::FootingGeometry;
use super::history::{write_history_outputs, History, HistoryColumns};
use super::report::{last_value, read_curve, write_outputs, write_step_convergence};
use super::spec::{Benchmark, CampaignSpec, SPEC_FILE};
use super::{CampaignError, CampaignRun, CurveColumns, Effort, EnergyBalance};
use crate::output::deviatoric_hencky_strain;
use crate::run::{run_scene_with, RunOptions};
use crate::scene::{Formulation, Scene};

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
/// once every run has finished.
pub fn run_campaign(
    dir: &Path,
    out: &Path,
    options: &CampaignOptions,
) -> Result<Vec<CampaignRun>, CampaignError> {
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
            variants.push(Planned {
                name: format!("{name}_dt{k}"),
                scene_file: stem.clone(),
                scene: refine_steps(name, scene, k)?,
                step_factor: k,
            });
        }
    }
    let window = scenes
        .first()
        .map(|(_, _, scene)| spec.benchmark.field_window(scene));
    let all: Vec<Planned> = scenes
        .into_iter()
        .map(|(name, scene_file, scene)| Planned {
            name,
            scene_file,
            scene,
            step_factor: 1,
        })
        .chain(variants)
        .collect();
    // popped from the back: the longest runs (finest meshes, refinements) start
    // first, estimated as step factor / h²
    let mut queue: Vec<(usize, Planned)> = all.into_iter().enumerate().collect();
    let cost = |p: &Planned| p.step_factor as f64 / p.scene.grid.cell_size.powi(2);
    queue.sort_by(|a, b| cost(&a.1).total_cmp(&cost(&b.1)));
    let queue = Mutex::new(queue);
    let results = Mutex::new(Vec::new());
    std::thread::scope(|scope| {
        for _ in 0..options.jobs.max(1) {
            scope.spawn(|| loop {
                let next = queue.lock().map(|mut q| q.pop()).unwrap_or(None);
                let Some((index, planned)) = next else {
                    break;
                };
                let name = planned.name.clone();
                let run = run_one(planned, &out.join(&name));
                match &run {
                    Ok(run) => eprintln!(
                        "campaign: {name} finished in {:.1} s{}",
                        run.wall_seconds,
                        run.error
                            .as_ref()
                            .map(|e| format!(" (stopped: {e})"))
                            .unwrap_or_default()
                    ),
                    Err(e) => eprintln!("campaign: {name}: {e}"),
                }
                if let Ok(mut r) = results.lock() {
                    r.push((index, run));
                }
            });
        }
    });
    let mut runs: Vec<(usize, Result<CampaignRun, CampaignError>)> =
        results.into_inner().unwrap_or_default();
    runs.sort_by_key(|(i, _)| *i);
    let runs: Vec<CampaignRun> = runs.into_iter().map(|(_, r)| r).collect::<Result<_, _>>()?;
    let scenes_as_written: Vec<CampaignRun> = runs
        .iter()
        .filter(|r| r.step_factor == 1)
        .cloned()
        .collect();
    let window = window.unwrap_or(crate::plot::Bounds::new(0.0, 1.0, 0.0, 1.0));
    match spec.benchmark {
        Benchmark::VerticalCut => write_history_outputs(out, &scenes_as_written, window)?,
        benchmark => write_outputs(out, &scenes_as_written, benchmark, window)?,
    }
    if options.step_refinement.is_some() {
        write_step_convergence(out, &runs)?;
    }
    Ok(runs)
}

/// A run waiting in the campaign's queue.
struct Planned {
    name: String,
    scene_file: String,
    scene: Scene,
    step_factor: usize,
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

/// Run one scene into `out` and gather what the report needs; an unreadable
/// curve is an error.
fn run_one(planned: Planned, out: &Path) -> Result<CampaignRun, CampaignError> {
    let Planned {
        name,
        scene_file,
        scene,
        step_factor,
    } = planned;
    let cell_size = scene.grid.cell_size;
    let length_scale = scene.nonlocal.as_ref().map(|n| n.length_scale);
    let curve_columns = CurveColumns::of_scene(&scene);
    let history_columns = HistoryColumns::of_scene(&scene);
    let start = Instant::now();
    let mut run = CampaignRun {
        scene: scene_file,
        analysis: scene.scene.analysis,
        history: None,
        fields: Vec::new(),
        volumes: Vec::new(),
        footing: FootingGeometry::of_scene(&scene),
        effort: Effort::default(),
        name,
        cell_size,
        length_scale,
        curve: Vec::new(),
        curve_columns,
        positions: Vec::new(),
        eps_q: Vec::new(),
        kappa_bar: Vec::new(),
        error: None,
        lost_points: (0, 0.0),
        dissipation: None,
        energy: None,
        wall_seconds: 0.0,
        profile: String::new(),
        step_factor,
    };
    // the campaign owns its runs' directories: an earlier campaign's files
    // there are replaced
    let options = RunOptions {
        show_progress: false,
        overwrite: true,
    };
    let set_up = match run_scene_with(scene, out, &options) {
        Err(e) => {
            run.error = Some(e.to_string());
            false
        }
        Ok(outcome) => {
            let p = &outcome.simulation.model.particles;
            run.positions = p.position.clone();
            run.volumes = p.volume.clone();
            let usage = outcome.simulation.integrator.usage();
            run.effort = Effort {
                steps: outcome.simulation.model.step,
                newton_iterations: usage.newton_iterations,
                halvings: usage.halvings,
            };
            run.fields = outcome.fields;
            run.eps_q = p.def_grad.iter().map(deviatoric_hencky_strain).collect();
            if run.length_scale.is_some() {
                run.kappa_bar = p
                    .state
                    .iter()
                    .map(|s| s.plastic_strain_eq_nonlocal)
                    .collect();
            }
            run.error = outcome.error.map(|e| e.to_string());
            let sim = &outcome.simulation.model;
            let lost_mass: f64 = sim.lost_points.iter().map(|l| l.mass).sum();
            let total_mass = sim.particles.mass.iter().sum::<f64>() + lost_mass;
            run.lost_points = (sim.lost_points.len(), lost_mass / total_mass);
            run.profile = outcome.simulation.profile.table(outcome.wall_seconds);
            true
        }
    };
    let curve = out.join("curve.csv");
    // a run whose setup failed may have written no curve: it then has none
    let curve_written = set_up || curve.exists();
    if curve_written {
        if let Some(columns) = &run.curve_columns {
            run.curve = read_curve(&curve, columns)?;
        }
        if let Some(columns) = &history_columns {
            run.history = Some(History::read(&curve, columns)?);
        }
    }
    run.dissipation = last_value(&curve, "dissipation");
    run.energy = match (
        last_value(&curve, "external_work"),
        last_value(&curve, "internal_work"),
        last_value(&curve, "kinetic_energy"),
    ) {
        (Some(external), Some(internal), Some(kinetic)) => Some(EnergyBalance {
            external,
            internal,
            kinetic,
        }),
        _ => None,
    };
    run.wall_seconds = start.elapsed().as_secs_f64();
    Ok(run)
}
