//! A run: the [`Model`], the [`Integrator`] the scene asks for, the
//! monitors (curve columns) and the stage profile, and the time loop that
//! calls the integrator's `step` until the end and reports every step to an
//! [`Observer`] (the output writer).

use mpm_solvers::SparseMatrix;

use crate::error::{RunError, StepError};
use crate::integrators::{ImplicitIntegrator, Integrator, StepReport};
use crate::model::Model;
use crate::monitor::Monitor;
use crate::profile::{Profile, Stage};
use crate::scene::{ResourceLimits, Scene, SceneError};

/// Receives the run's progress; the CLI writes outputs and a progress bar here.
pub trait Observer {
    /// Called once before the first step (state at step 0).
    fn on_start(&mut self, sim: &Simulation) -> Result<(), RunError>;
    /// Called after every completed step.
    fn on_step(&mut self, sim: &Simulation, report: &StepReport) -> Result<(), RunError>;
    /// True when the run should end after the step just reported, before its
    /// end (checked after every step; a test hook that stops as a kill would).
    fn stop_requested(&self) -> bool {
        false
    }
    /// A request to stop the run after the step just reported (a signal the
    /// application caught), checked after every step that did not end the
    /// run; `Some` ends it as [`RunEnd::Interrupted`] after
    /// [`Observer::on_interrupt`]. The default never asks.
    fn interruption(&self) -> Option<Interruption> {
        None
    }
    /// Called once when a signal stops the run, after the `on_step` of the
    /// last completed step: the place to finish that step's outputs and to
    /// leave a checkpoint to resume from. The default does nothing.
    fn on_interrupt(
        &mut self,
        _sim: &Simulation,
        _interruption: Interruption,
    ) -> Result<(), RunError> {
        Ok(())
    }
}

/// A signal that asked the run to stop.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Interruption {
    /// The signal number (2 = SIGINT, 15 = SIGTERM).
    pub signal: i32,
}

impl Interruption {
    /// `SIGINT`, `SIGTERM` or `signal N`.
    pub fn name(&self) -> String {
        match self.signal {
            2 => "SIGINT".into(),
            15 => "SIGTERM".into(),
            n => format!("signal {n}"),
        }
    }

    /// The process exit code of an interrupted run: 128 + the signal number,
    /// the shells' convention (130 for SIGINT, 143 for SIGTERM).
    pub fn exit_code(&self) -> u8 {
        u8::try_from(128 + self.signal).unwrap_or(255)
    }
}

/// How [`Simulation::run`] ended without an error.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RunEnd {
    /// The last step / end time was reached.
    Completed,
    /// A signal stopped the run after a completed step
    /// ([`Observer::interruption`]).
    Interrupted(Interruption),
}

/// An observer that does nothing (library use, tests).
pub struct NullObserver;

impl Observer for NullObserver {
    fn on_start(&mut self, _: &Simulation) -> Result<(), RunError> {
        Ok(())
    }
    fn on_step(&mut self, _: &Simulation, _: &StepReport) -> Result<(), RunError> {
        Ok(())
    }
}

pub use crate::scene::{STEP_COLUMN, STEP_COLUMNS, TIME_COLUMN};

/// A run in progress.
pub struct Simulation {
    /// The validated scene the run was built from (its outputs record it;
    /// the physics reads the model's [`crate::settings::Settings`]).
    pub scene: Scene,
    /// The model and its state.
    pub model: Model,
    /// The time integrator.
    pub integrator: Integrator,
    /// Monitors (curve columns).
    pub monitors: Vec<Monitor>,
    /// Stage timings.
    pub profile: Profile,
    /// What the last step reported (`None` before the first step of this process).
    pub last_step: Option<StepReport>,
}

impl Simulation {
    /// Build a run from a validated scene: the model (seeded points, boundary
    /// devices), its integrator and the monitors. The scene's estimated
    /// memory and step count are checked first against its `[limits]`
    /// ([`Scene::check_resources`]); problems that only show once points are
    /// seeded are reported as field errors.
    pub fn new(scene: Scene) -> Result<Self, SceneError> {
        scene.check_resources(&ResourceLimits::for_scene(&scene))?;
        let profile = Profile::default();
        let (model, integrator, monitors) = profile.time(Stage::Build, || {
            let mut model = Model::new(&scene)?;
            let integrator = Integrator::for_model(&model)?;
            let monitors: Vec<Monitor> = scene
                .monitor
                .iter()
                .map(|m| Monitor::resolve(m, &model))
                .collect();
            model.state.pinned_points = monitors.iter().filter_map(Monitor::particle).collect();
            Ok::<_, SceneError>((model, integrator, monitors))
        })?;
        Ok(Self {
            scene,
            model,
            integrator,
            monitors,
            profile,
            last_step: None,
        })
    }

    /// Whether the run has reached its last step / end time.
    pub fn finished(&self) -> bool {
        self.model.finished()
    }

    /// Advance one step with the scene's integrator; a failure carries the
    /// step and the time reached.
    pub fn step_once(&mut self) -> Result<StepReport, RunError> {
        let start = self.model.state.time;
        let report = self
            .integrator
            .step(&mut self.model, &self.profile)
            .map_err(|cause| RunError::Step {
                step: self.model.state.step + 1,
                time: self.model.state.time,
                cause,
            })?;
        self.model.account_rigid_work(start);
        // the points are already removed: the monitors follow their new
        // indices before anything reads them
        for remap in &report.removed_points {
            for monitor in &mut self.monitors {
                monitor.remap_particle(remap);
            }
        }
        self.check_monitors()?;
        self.last_step = Some(StepReport {
            removed_points: Vec::new(),
            ..report.clone()
        });
        Ok(report)
    }

    /// The columns of `curve.csv` between `time_s` and the monitors: the
    /// first of [`STEP_COLUMNS`], all four with adaptive steps.
    pub fn step_column_names(&self) -> Vec<String> {
        let used = if self.adaptive() { 4 } else { 1 };
        STEP_COLUMNS[..used].iter().map(|c| c.to_string()).collect()
    }

    /// `(name, column)` of each monitor, in column order: the columns of
    /// `curve.csv` after [`Self::step_column_names`].
    pub fn monitor_columns(&self) -> Vec<(String, String)> {
        self.monitors
            .iter()
            .map(|m| (m.name.clone(), m.spec.column()))
            .collect()
    }

    /// The values of [`Self::step_column_names`] after the last step (zero
    /// before the first).
    pub fn step_column_values(&self) -> Vec<f64> {
        let last = self.last_step.clone().unwrap_or_default();
        let mut values = vec![last.dt];
        if self.adaptive() {
            values.extend([
                last.error_estimate.unwrap_or(0.0),
                last.rejected_error as f64,
                last.rejected_newton as f64,
            ]);
        }
        values
    }

    /// Whether the run's steps are error-controlled.
    fn adaptive(&self) -> bool {
        self.model.analysis() == crate::scene::AnalysisKind::ImplicitDynamic
            && self.model.settings.solver.adaptive()
    }

    /// Run to the end, reporting every step to `observer`. On a failure the
    /// error names step, time and cause; everything the observer wrote stays.
    /// A stop the observer requests ([`Observer::interruption`]) ends the
    /// run after the step in progress and its outputs
    /// ([`Observer::on_interrupt`]).
    pub fn run(&mut self, observer: &mut dyn Observer) -> Result<RunEnd, RunError> {
        observer.on_start(self)?;
        while !self.finished() && !observer.stop_requested() {
            let report = self.step_once()?;
            observer.on_step(self, &report)?;
            if let Some(interruption) = observer.interruption().filter(|_| !self.finished()) {
                observer.on_interrupt(self, interruption)?;
                return Ok(RunEnd::Interrupted(interruption));
            }
        }
        Ok(RunEnd::Completed)
    }

    /// A NaN or infinite monitor stops the run after the step that made it
    /// so, naming the monitor (no row of `curve.csv` is written for it).
    fn check_monitors(&self) -> Result<(), RunError> {
        for m in &self.monitors {
            let value = m.value(&self.model);
            if !value.is_finite() {
                return Err(RunError::Step {
                    step: self.model.state.step,
                    time: self.model.state.time,
                    cause: StepError::NonFiniteMonitor {
                        name: m.name.clone(),
                        value,
                    },
                });
            }
        }
        Ok(())
    }

    /// Current monitor values, in column order.
    pub fn monitor_values(&self) -> Vec<f64> {
        self.monitors.iter().map(|m| m.value(&self.model)).collect()
    }

    /// The next implicit step's residual and tangent at a free-dof increment
    /// (see [`ImplicitIntegrator::linearize`]).
    pub fn linearize(
        &mut self,
        free_increment: &[f64],
    ) -> Result<(Vec<f64>, SparseMatrix), RunError> {
        let step_error = |model: &Model, cause| RunError::Step {
            step: model.state.step + 1,
            time: model.state.time,
            cause,
        };
        match self.integrator.implicit_mut() {
            Some(implicit) => implicit
                .linearize(&self.model, free_increment)
                .map_err(|cause| step_error(&self.model, cause)),
            None => Err(step_error(
                &self.model,
                StepError::NotAvailable("an explicit run has no tangent"),
            )),
        }
    }

    /// Number of unknowns of the next implicit step.
    pub fn unknowns(&self) -> Result<usize, RunError> {
        ImplicitIntegrator::unknowns(&self.model).map_err(|cause| RunError::Step {
            step: self.model.state.step + 1,
            time: self.model.state.time,
            cause,
        })
    }
}
