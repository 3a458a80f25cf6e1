//! Plain progress lines of a run whose stderr is not a terminal (a pipe, a
//! log file, a batch job), where the progress bar draws nothing: one line
//! every few seconds with the step, the time reached, the first monitor,
//! Newton's work and an estimate of the time left. And the lines of a batch
//! of runs (`campaign`, `study`): a start line, one line per run started and
//! finished, with an estimate of the time left ([`BatchProgress`]).

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
    let run = &model.settings.run;
    let by_time = match model.analysis() {
        AnalysisKind::Explicit => true,
        AnalysisKind::ImplicitDynamic => model.settings.solver.adaptive(),
        AnalysisKind::QuasiStatic => false,
    };
    let share = if by_time {
        model.state.time / run.end_time_or_steps()
    } else {
        model.state.step as f64 / run.steps.unwrap_or(0) as f64
    };
    if share.is_finite() {
        share.clamp(0.0, 1.0)
    } else {
        0.0
    }
}

/// The progress of a batch of runs (a campaign's, a study's), printed to
/// stderr whatever stderr is: the runs take minutes to hours, so a line per
/// run is never too many. The time left is estimated from the relative cost
/// of the runs (points × steps, or the caller's measure): the wall time
/// since the first run started times the cost left over the cost done.
#[derive(Debug)]
pub struct BatchProgress {
    label: String,
    total: usize,
    total_cost: f64,
    done: usize,
    done_cost: f64,
    /// When the first run started (`None` before): the batches of
    /// `mpm-geo paper` share one queue, and a later one's runs wait.
    start: Option<Instant>,
}

impl BatchProgress {
    /// Announce a batch of runs whose relative costs are `costs` (the runs
    /// to do; `earlier` more were done before and are not run again), with
    /// `jobs` at a time.
    pub fn start(label: &str, costs: &[f64], earlier: usize, jobs: usize) -> Self {
        let again = if earlier > 0 {
            format!(" ({earlier} finished earlier)")
        } else {
            String::new()
        };
        eprintln!(
            "{label}: {} runs to do{again}, {jobs} at a time",
            costs.len()
        );
        Self {
            label: label.to_string(),
            total: costs.len(),
            total_cost: costs.iter().sum(),
            done: 0,
            done_cost: 0.0,
            start: None,
        }
    }

    /// A run starts (the first one starts the clock of the estimate).
    pub fn started(&mut self, name: &str) {
        self.start.get_or_insert_with(Instant::now);
        eprintln!("{}: {name} started", self.label);
    }

    /// A run of relative cost `cost` ended: the count and the estimate, to
    /// follow the line that says how it ended.
    pub fn finished(&mut self, cost: f64) -> String {
        self.done += 1;
        self.done_cost += cost;
        let elapsed = self.start.map_or(0.0, |t| t.elapsed().as_secs_f64());
        let left = match self.estimate_left(elapsed) {
            Some(seconds) if self.done < self.total => {
                format!(", about {} left (estimate)", clock(seconds))
            }
            _ => String::new(),
        };
        format!(
            "{}: {} of {} runs done{left}",
            self.label, self.done, self.total
        )
    }

    /// The time left after `elapsed` seconds, s (`None` before any cost is
    /// done).
    fn estimate_left(&self, elapsed: f64) -> Option<f64> {
        (self.done_cost > 0.0)
            .then(|| elapsed * (self.total_cost - self.done_cost).max(0.0) / self.done_cost)
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

    /// A quarter of the cost done in 60 s leaves 180 s; nothing is
    /// estimated before any cost is done, and the clock starts with the
    /// first run, not with the batch (a later batch of `mpm-geo paper`'s
    /// queue waits for the runs before it).
    #[test]
    fn batch_estimate_scales_the_time_by_the_cost_left() {
        let mut batch = BatchProgress::start("test", &[1.0, 3.0], 0, 1);
        assert!(batch.start.is_none());
        batch.started("first");
        let first = batch.start;
        batch.started("second");
        assert!(first.is_some() && batch.start == first);
        assert_eq!(batch.estimate_left(60.0), None);
        let line = batch.finished(1.0);
        assert!(line.starts_with("test: 1 of 2 runs done"), "{line}");
        assert_eq!(batch.estimate_left(60.0), Some(180.0));
        assert!(!batch.finished(3.0).contains("left"));
    }
}
