//! Plain progress lines of a run whose stderr is not a terminal (a pipe, a
//! log file, a batch job), where the progress bar draws nothing: one line
//! every few seconds with the step, the time reached, the first monitor,
//! Newton's work and an estimate of the time left.

use std::time::{Duration, Instant};

use crate::integrators::StepReport;
use crate::scene::AnalysisKind;
use crate::simulation::Simulation;

/// Seconds between two lines by default.
pub const DEFAULT_INTERVAL: f64 = 10.0;

/// Writes a progress line to stderr at most once per interval.
#[derive(Debug)]
pub struct ProgressLines {
    interval: Duration,
    start: Instant,
    last: Instant,
    /// Share of the run done when the lines started (a resumed run).
    done_at_start: f64,
}

impl ProgressLines {
    /// Lines every `interval` seconds for `sim` from now.
    pub fn new(sim: &Simulation, interval: f64) -> Self {
        let now = Instant::now();
        Self {
            interval: Duration::from_secs_f64(interval.max(0.0)),
            start: now,
            last: now,
            done_at_start: share_done(sim),
        }
    }

    /// After a step: the line, when an interval has passed since the last.
    pub fn after_step(&mut self, sim: &Simulation, report: &StepReport) {
        let now = Instant::now();
        if now.duration_since(self.last) < self.interval {
            return;
        }
        self.last = now;
        eprintln!("{}", self.line(sim, report, now.duration_since(self.start)));
    }

    /// The line after `elapsed` of running.
    fn line(&self, sim: &Simulation, report: &StepReport, elapsed: Duration) -> String {
        let done = share_done(sim);
        let mut line = format!(
            "step {}  t = {:.4e} s ({:.1} %)  dt = {:.2e} s",
            report.step,
            report.time,
            100.0 * done,
            report.dt
        );
        if let Some(monitor) = sim.monitors.first() {
            line += &format!("  {} = {:.4e}", monitor.name, monitor.value(&sim.model));
        }
        if report.iterations > 0 {
            line += &format!("  Newton {} it", report.iterations);
        }
        if report.substeps > 1 {
            line += &format!(" ({} substeps)", report.substeps);
        }
        line += &format!("  elapsed {}", clock(elapsed.as_secs_f64()));
        let progress = done - self.done_at_start;
        if progress > 0.0 && done < 1.0 {
            let left = elapsed.as_secs_f64() * (1.0 - done) / progress;
            line += &format!("  left ~{} (estimate)", clock(left));
        }
        line
    }
}

/// The share of the run done: time over end time (explicit and adaptive
/// runs), else steps over steps.
fn share_done(sim: &Simulation) -> f64 {
    let model = &sim.model;
    let scene = &model.scene.scene;
    let by_time = match model.analysis() {
        AnalysisKind::Explicit => true,
        AnalysisKind::ImplicitDynamic => model.scene.solver.adaptive(),
        AnalysisKind::QuasiStatic => false,
    };
    let share = if by_time {
        model.time / scene.end_time_or_steps()
    } else {
        model.step as f64 / scene.steps.unwrap_or(0) as f64
    };
    if share.is_finite() {
        share.clamp(0.0, 1.0)
    } else {
        0.0
    }
}

/// `seconds` as 1h02m, 3m05s or 12s.
fn clock(seconds: f64) -> String {
    let s = seconds.round() as u64;
    match (s / 3600, (s % 3600) / 60, s % 60) {
        (0, 0, s) => format!("{s}s"),
        (0, m, s) => format!("{m}m{s:02}s"),
        (h, m, _) => format!("{h}h{m:02}m"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clock_reads_as_a_person_would() {
        assert_eq!(clock(12.4), "12s");
        assert_eq!(clock(185.0), "3m05s");
        assert_eq!(clock(3725.0), "1h02m");
    }
}
