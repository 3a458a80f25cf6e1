//! Continuing a checkpointed run ([`crate::checkpoint`]) through the run's
//! own output machinery ([`crate::run`]): this module sits above both, so
//! that the run writes checkpoints without the checkpoint module driving
//! runs.

use std::path::Path;
use std::time::Duration;

use crate::checkpoint::{io_error, Checkpointer, Resumable, ResumeOptions};
use crate::run::{OutputObserver, RunOutcome};

impl Resumable {
    /// Continue the run to its end: `run.json` says `running` (its manifest
    /// naming this process's temporary files too), the temporary files the
    /// earlier processes left are removed, `curve.csv` is cut back to the
    /// checkpoint's rows, later snapshots are removed and written again,
    /// checkpoints go on, and `run.json` is written at the end. A resume
    /// that fails before its time loop puts the earlier `run.json` back.
    pub fn run(
        self,
        show_progress: bool,
        options: &ResumeOptions,
    ) -> Result<RunOutcome, Box<dyn std::error::Error + Send + Sync>> {
        let Self {
            _lock,
            dir,
            source,
            every,
            mut simulation,
            state,
            curve,
            earlier,
            mut manifest,
            opened,
        } = self;
        let left_behind = manifest.temporary_prefixes.clone();
        manifest.add_own_temporary_prefix();
        for name in &options.extra_files {
            manifest.add(name);
        }
        // the run's wall time goes on from the checkpoint's
        let before = Duration::try_from_secs_f64(state.wall_seconds).unwrap_or_default();
        let start = opened.checked_sub(before).unwrap_or(opened);
        let cursor = state.restore(&mut simulation);
        let checkpoints = Checkpointer {
            dir: dir.clone(),
            every: options.checkpoint_every.unwrap_or(every),
            fingerprint: source.fingerprint(),
            curve,
            run_start: start,
        };
        let stop_after = options.stop_after;
        let lines = crate::run::progress_lines_every(show_progress, options.progress_every);
        let drive = crate::run::Drive {
            start,
            lock: _lock,
            manifest,
            earlier,
            written_later: options.extra_files.clone(),
            provenance: crate::provenance::Provenance::now(
                Some(Path::new(&source.origin)),
                &source.overrides,
            ),
        };
        crate::run::drive(simulation, &dir, drive, |sim, mut manifest| {
            manifest
                .remove_temporaries(&dir, &left_behind)
                .map_err(|(path, e)| {
                    io_error(&path, e).at(sim.model.state.step, sim.model.state.time)
                })?;
            manifest
                .temporary_prefixes
                .retain(|p| !left_behind.contains(p));
            manifest.add_own_temporary_prefix();
            let observer = OutputObserver::resume(&dir, sim, cursor, show_progress, manifest)?;
            Ok(observer
                .with_checkpoints(Some(checkpoints), stop_after)
                .with_progress_lines(sim, lines))
        })
    }
}

/// `mpm-geo resume DIR`: check `dir`'s checkpoint and continue the run.
pub fn resume_run(
    dir: &Path,
    show_progress: bool,
    options: &ResumeOptions,
) -> Result<RunOutcome, Box<dyn std::error::Error + Send + Sync>> {
    Resumable::open(dir)?.run(show_progress, options)
}
