//! `mpm-geo paper`: the paper's three benchmarks in one command. The
//! biaxial, footing and vertical-cut campaigns, and the cut again in the
//! late reading of its failure time (theory decision 36), from the
//! directories of those names under the root (`validation/` by default), run one after the other, each
//! into its own folder of the output (`campaign-<name>/`, as `mpm-geo
//! campaign` writes it), and `README.md` there puts every campaign's report
//! beside the paper's figures and the claim they test. The campaigns share
//! one queue of runs, `--jobs` at a time, in the paper's order and the
//! longest of each campaign first: a campaign's runs start as soon as a job
//! is free, without waiting for the last run of the one before. Like a
//! campaign it resumes (a finished run is not run again) and shards
//! (`--shard K/N` shards every campaign; `--collect` then builds the reports
//! and the index).

use std::path::Path;
use std::time::Instant;

use crate::campaign::{
    finish_campaign, plan_campaign, run_queued, CampaignError, CampaignOptions, CampaignPlan, Part,
};

/// One benchmark of the paper: its campaign directory and what it tests.
#[derive(Clone, Copy, Debug)]
pub struct PaperBenchmark {
    /// Directory under the root, and the campaign's folder `campaign-<name>`.
    pub name: &'static str,
    /// The paper's figures the campaign draws.
    pub figures: &'static str,
    /// The claim of the paper they test.
    pub claim: &'static str,
}

/// The paper's benchmarks, in its order (paper §3).
pub const BENCHMARKS: [PaperBenchmark; 4] = [
    PaperBenchmark {
        name: "biaxial",
        figures: "Figs. 3–5",
        claim: "local runs grow more brittle and their band narrower as the mesh is refined; nonlocal runs keep one curve and a band of width ≈ l_s",
    },
    PaperBenchmark {
        name: "footing",
        figures: "Figs. 7–8",
        claim: "similar peak loads on every mesh; after the peak the local runs soften more, and more with finer meshes, with a secondary band under the corner; nonlocal runs do not",
    },
    PaperBenchmark {
        name: "vertical_cut",
        figures: "Figs. 10–12",
        claim: "the nonlocal column fails alike on every mesh (q at B, u_A); local final displacements depend strongly on the mesh",
    },
    PaperBenchmark {
        name: "vertical_cut_late",
        figures: "Figs. 10–12, late reading",
        claim: "the same claims with the onset near the end of the gravity ramp (ρ = 0.22 t/m³, theory decision 36), as the paper's snapshots at 0.6 and 0.7 s suggest: the nonlocal q at B falls smoothly, the local one does not",
    },
];

/// What one benchmark's campaign did.
#[derive(Clone, Debug)]
pub struct PaperOutcome {
    /// The benchmark.
    pub benchmark: PaperBenchmark,
    /// Runs of the campaign (this shard's with `--shard`).
    pub runs: usize,
    /// Runs that stopped early.
    pub stopped: usize,
    /// Time from the command's start until the campaign's last run in it
    /// ended (or until it was planned, if it ran none), s.
    pub seconds: f64,
    /// Why the campaign could not run or report (`None`: it did).
    pub error: Option<String>,
}

/// Run the campaign of every benchmark found under `root` into
/// `out/campaign-<name>`, their runs in one queue ([`run_queued`]), then
/// write each campaign's report and `out/README.md` (not for a shard). A
/// campaign that cannot be planned, run or reported is recorded in its
/// outcome and the others go on; an interrupt stops the command at once.
pub fn run_paper(
    root: &Path,
    out: &Path,
    options: &CampaignOptions,
) -> Result<Vec<PaperOutcome>, CampaignError> {
    let start = Instant::now();
    let mut plans: Vec<CampaignPlan> = Vec::new();
    let mut planned: Vec<(PaperBenchmark, Result<(), String>, Instant)> = Vec::new();
    for (k, benchmark) in BENCHMARKS.into_iter().enumerate() {
        eprintln!(
            "paper: {} ({} of {}, the paper's {})",
            benchmark.name,
            k + 1,
            BENCHMARKS.len(),
            benchmark.figures
        );
        let (dir, out) = (root.join(benchmark.name), campaign_dir(out, benchmark));
        // the campaigns' runs share the queue, and two have runs of one name
        let label = out.file_name().map(|n| n.to_string_lossy().into_owned());
        let label = label.unwrap_or_else(|| benchmark.name.to_string());
        let plan = plan_campaign(&dir, &out, options, &label);
        let result = plan.map(|plan| plans.push(plan)).map_err(|e| e.to_string());
        planned.push((benchmark, result, Instant::now()));
    }
    run_queued(&mut plans, options);
    let mut plans = plans.into_iter();
    let mut outcomes = Vec::new();
    for (benchmark, result, planned_at) in planned {
        let (mut runs, mut stopped, mut ended) = (0, 0, planned_at);
        let error = match result.map(|()| plans.next()) {
            Err(e) => Some(e),
            Ok(None) => Some("no plan: an internal error, please report it".into()),
            Ok(Some(plan)) => {
                ended = plan.last_ended().unwrap_or(planned_at);
                match finish_campaign(plan, options) {
                    Err(e @ CampaignError::Interrupted { .. }) => return Err(e),
                    Err(e) => Some(e.to_string()),
                    Ok(finished) => {
                        runs = finished.len();
                        stopped = finished.iter().filter(|r| r.error.is_some()).count();
                        None
                    }
                }
            }
        };
        let seconds = ended.duration_since(start).as_secs_f64();
        eprintln!(
            "paper: {} {} in {seconds:.0} s",
            benchmark.name,
            if error.is_some() { "stopped" } else { "done" }
        );
        outcomes.push(PaperOutcome {
            benchmark,
            runs,
            stopped,
            seconds,
            error,
        });
    }
    if !matches!(options.part, Part::Shard { .. }) {
        crate::atomic_file::write_atomic(&out.join("README.md"), index(&outcomes)).map_err(
            |e| CampaignError::Output(out.join("README.md").display().to_string(), e.to_string()),
        )?;
    }
    Ok(outcomes)
}

/// The folder of `benchmark`'s campaign under `out`.
pub fn campaign_dir(out: &Path, benchmark: PaperBenchmark) -> std::path::PathBuf {
    out.join(format!("campaign-{}", benchmark.name))
}

/// The index page: one row per benchmark, its report beside the claim.
fn index(outcomes: &[PaperOutcome]) -> String {
    let mut text = String::from(
        "# The paper's benchmarks\n\nWritten by `mpm-geo paper`. Each campaign's `report.md` holds its curves, metrics and figures. The campaigns share the jobs: \"done after\" is the time from the command's start until the campaign's last run ended.\n\n| benchmark | paper | claim tested | runs | stopped early | done after, s | report |\n|---|---|---|---|---|---|---|\n",
    );
    for o in outcomes {
        let b = o.benchmark;
        let report = match &o.error {
            None => format!("[report](campaign-{}/report.md)", b.name),
            Some(e) => format!("not written: {}", e.replace('|', "\\|").replace('\n', " ")),
        };
        text.push_str(&format!(
            "| {} | {} | {} | {} | {} | {:.0} | {} |\n",
            b.name, b.figures, b.claim, o.runs, o.stopped, o.seconds, report
        ));
    }
    text
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The index links each report that was written and says why another was
    /// not, one row per benchmark, with a table cell that stays one cell.
    #[test]
    fn index_links_reports_and_names_failures() {
        let outcome = |i: usize, error: Option<&str>| PaperOutcome {
            benchmark: BENCHMARKS[i],
            runs: 4,
            stopped: 1,
            seconds: 12.0,
            error: error.map(String::from),
        };
        let text = index(&[
            outcome(0, None),
            outcome(1, Some("campaign directory x: no scene | none")),
            outcome(2, None),
        ]);
        assert!(text.contains("[report](campaign-biaxial/report.md)"));
        assert!(text.contains("not written: campaign directory x: no scene \\| none"));
        assert_eq!(text.lines().filter(|l| l.starts_with("| ")).count(), 4);
    }
}
