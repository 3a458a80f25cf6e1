//! Running a campaign: finding the scenes, running them `jobs` at a time into
//! `out/<scene>/`, and the time-step refinement of each scene.

use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::time::Instant;

use super::report::{last_value, read_curve, write_outputs, write_step_convergence};
use super::{CampaignError, CampaignRun, CurveColumns, EnergyBalance};
use crate::output::deviatoric_hencky_strain;
use crate::run::run_scene;
use crate::scene::Scene;

fn scenes_in(dir: &Path) -> Result<Vec<PathBuf>, CampaignError> {
    let entries = std::fs::read_dir(dir)
        .map_err(|e| CampaignError::Directory(dir.display().to_string(), e.to_string()))?;
    let mut paths: Vec<PathBuf> = entries
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
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
/// runs), `jobs` at a time, into `out/<scene>/`, then write the combined
/// outputs. With `step_refinement = Some(K)` every scene is also run with K
/// times the steps at Δt / K (into `out/<scene>_dtK/`) and the time-step
/// discrepancy of each curve is reported (`step_convergence.csv`, report
/// section). Returns the runs in scene order, refinements after the scenes; a
/// run's unreadable `curve.csv` is an error once every run has finished.
pub fn run_campaign(
    dir: &Path,
    out: &Path,
    jobs: usize,
    overrides: &[String],
    step_refinement: Option<usize>,
) -> Result<Vec<CampaignRun>, CampaignError> {
    let paths = scenes_in(dir)?;
    let scenes: Vec<(String, Scene)> = paths
        .iter()
        .map(|p| {
            let name = p
                .file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_default();
            Scene::load(p, overrides)
                .map(|s| (name, s))
                .map_err(|e| CampaignError::Scene(e.to_string()))
        })
        .collect::<Result<_, _>>()?;
    let mut variants: Vec<(String, Scene, usize)> = Vec::new();
    if let Some(k) = step_refinement {
        for (name, scene) in &scenes {
            variants.push((format!("{name}_dt{k}"), refine_steps(name, scene, k)?, k));
        }
    }
    let all: Vec<(String, Scene, usize)> = scenes
        .into_iter()
        .map(|(name, scene)| (name, scene, 1))
        .chain(variants)
        .collect();
    // popped from the back: queue the longest runs (finest meshes, refinements) first
    let queue = Mutex::new(all.into_iter().enumerate().collect::<Vec<_>>());
    let results = Mutex::new(Vec::new());
    std::thread::scope(|scope| {
        for _ in 0..jobs.max(1) {
            scope.spawn(|| loop {
                let next = queue.lock().map(|mut q| q.pop()).unwrap_or(None);
                let Some((index, (name, scene, factor))) = next else {
                    break;
                };
                let run = run_one(&name, scene, &out.join(&name), factor);
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
    write_outputs(out, &scenes_as_written)?;
    if step_refinement.is_some() {
        write_step_convergence(out, &runs)?;
    }
    Ok(runs)
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
fn run_one(
    name: &str,
    scene: Scene,
    out: &Path,
    step_factor: usize,
) -> Result<CampaignRun, CampaignError> {
    let cell_size = scene.grid.cell_size;
    let length_scale = scene.nonlocal.as_ref().map(|n| n.length_scale);
    let curve_columns = CurveColumns::of_scene(&scene);
    let start = Instant::now();
    let mut run = CampaignRun {
        name: name.to_string(),
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
    let set_up = match run_scene(scene, out, false) {
        Err(e) => {
            run.error = Some(e.to_string());
            false
        }
        Ok(outcome) => {
            let p = &outcome.simulation.model.particles;
            run.positions = p.position.clone();
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
