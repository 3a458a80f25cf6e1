//! Stable identifiers of the errors that end a run or refuse an input.
//!
//! The command line prints every error as `error[ID]: message`, `run.json`
//! records the identifier of the error that stopped a run (`error_id`), and
//! the user guide (`docs/guide.md` §11) lists every identifier with what it
//! means and what to do about it. The list is defined once, here, by
//! `error_ids!`; `mpm-geo errors` prints it as the guide's table, and
//! `tests/guide.rs` checks that the guide holds exactly that table.
//!
//! The list is kept low, in the physics crate, so that every error type,
//! of this crate or of the application, implements [`Identified`] where it
//! is defined; the application's `error_id::identify` finds the identifier
//! of any error through those implementations.

/// Defines [`ErrorId`]: variant, identifier, meaning and remedy, in the
/// order of the guide's table.
macro_rules! error_ids {
    ($($variant:ident => $name:literal: $meaning:literal; $remedy:literal;)*) => {
        /// A stable error identifier (docs/guide.md §11).
        #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
        pub enum ErrorId {
            $(
                #[doc = $meaning]
                $variant,
            )*
        }

        impl ErrorId {
            /// Every identifier, in the guide's order.
            pub const ALL: &'static [ErrorId] = &[$(ErrorId::$variant,)*];

            /// The identifier as printed, e.g. `SCENE_INVALID`.
            pub fn name(self) -> &'static str {
                match self {
                    $(ErrorId::$variant => $name,)*
                }
            }

            /// What the error means.
            pub fn meaning(self) -> &'static str {
                match self {
                    $(ErrorId::$variant => $meaning,)*
                }
            }

            /// What to do about it.
            pub fn remedy(self) -> &'static str {
                match self {
                    $(ErrorId::$variant => $remedy,)*
                }
            }
        }
    };
}

error_ids! {
    CliArgument => "CLI_ARGUMENT":
        "a command-line argument is unknown, missing or malformed (e.g. `--jobs two`, `--shard 4/3`); clap's usage line follows";
        "see `mpm-geo help COMMAND`";
    SceneRead => "SCENE_READ":
        "the scene file cannot be read";
        "check the path and the file's permissions";
    SceneSyntax => "SCENE_SYNTAX":
        "the scene is not valid TOML, has an unknown key or a value of the wrong type: the message gives file, line and column, the key, and the key or value probably meant";
        "fix the named key; docs/scene.md lists every key and type";
    SceneOverride => "SCENE_OVERRIDE":
        "a `--set key=value` does not apply (no such key, or a value of the wrong type); the message names the override and the key probably meant";
        "write it as `--set table.key=value`, arrays by index (`body.0.box`)";
    SceneInvalid => "SCENE_INVALID":
        "values out of range or inconsistent: every field is listed (also contradictory conditions on one dof, a line held where a rigid body drives, pressures that would add up, self-intersecting polygons, initial stresses far outside the yield surface)";
        "fix each listed field; `mpm-geo check` shows them without running";
    SceneNonFinite => "SCENE_NON_FINITE":
        "a number in the scene is `nan` or `inf` (the keys are named)";
        "give a finite value";
    SceneMemoryLimit => "SCENE_MEMORY_LIMIT":
        "the estimated memory of the run is over the limit; each part is listed with the keys that drive it";
        "coarsen the grid (`grid.cell_size`), shrink the body or the nonlocal cutoff, or raise `--max-memory` / `limits.max_memory_gb` if the machine has the memory";
    SceneStepLimit => "SCENE_STEP_LIMIT":
        "the run would take more steps than the limit (explicit: end time over the stable step)";
        "check E, density, `cfl` and `dt`; raise `--max-steps` / `limits.max_steps` if the count is meant";
    OutputLocked => "OUTPUT_LOCKED":
        "another run is writing into the output directory (the message names its process); a lock left by a killed run does not count";
        "wait for it, or choose another `--out`";
    OutputReused => "OUTPUT_REUSED":
        "the output directory holds an earlier run's files";
        "choose another `--out`, or add `--overwrite` to remove the files that run lists in its `run.json` (other files are kept)";
    OutputUnlisted => "OUTPUT_UNLISTED":
        "`--overwrite` cannot tell the earlier run's files from yours: its `run.json` lists none (an older mpm-geo) or is damaged";
        "remove that run's files yourself, or choose another `--out`";
    OutputForeign => "OUTPUT_FOREIGN":
        "the output directory holds files the run would write over (e.g. a `curve.csv`) that no earlier run recorded writing";
        "move them, or choose another `--out`";
    OutputDirectory => "OUTPUT_DIRECTORY":
        "the output directory cannot be created or listed";
        "check the path, the permissions and the free space";
    OutputWrite => "OUTPUT_WRITE":
        "an output file could not be written (full disk, permissions); the message names the step, time and path";
        "free space or fix the permissions, then run again (every file written so far is whole)";
    RunPointLeftGrid => "RUN_POINT_LEFT_GRID":
        "a material point left the background grid";
        "enlarge `grid.size` (room for heave or run-out), or set `grid.lost_points = \"remove\"` for fragments";
    RunBoundaryPointLeftGrid => "RUN_BOUNDARY_POINT_LEFT_GRID":
        "a traction or contact point left the background grid";
        "enlarge `grid.size` around the loaded boundary";
    RunNewtonFailed => "RUN_NEWTON_FAILED":
        "Newton did not converge after every allowed step halving (the residual history and the node of the largest residual are given)";
        "use smaller steps (`scene.steps`, `scene.dt`), more halvings (`solver.max_halvings`), or check the boundary conditions";
    RunPathBudget => "RUN_PATH_BUDGET":
        "a path-following run used its `solver.path_max_steps` before its rigid bodies reached the end travel (where it stood is given)";
        "raise `solver.path_max_steps`, or take larger nominal steps (`scene.dt`); a path that keeps turning back shows in `curve.csv`";
    RunPathLost => "RUN_PATH_LOST":
        "a path-following step jumped off its path (far longer than predicted) at every allowed halving";
        "more halvings (`solver.max_halvings`) or smaller nominal steps (`scene.dt`)";
    RunStressUpdate => "RUN_STRESS_UPDATE":
        "the stress update (return mapping) failed at a material point (\"after N step halvings\" where the halved steps failed too)";
        "use smaller steps; check the material parameters near the named point";
    RunNonFinite => "RUN_NON_FINITE":
        "a NaN or infinite value appeared in a point, node or monitor (named, with the step)";
        "usually an unstable step: reduce `dt` or `cfl`, or check the materials and loads";
    RunTimeStep => "RUN_TIME_STEP":
        "the explicit time step is not finite or is above the stability limit";
        "lower `solver.cfl` or `scene.dt`";
    RunLinearSolver => "RUN_LINEAR_SOLVER":
        "the linear solver failed (a singular tangent: a body not held, a mechanism; the node where it is most singular is named, and \"after N step halvings\" where the halved steps failed too)";
        "fix the boundary conditions so that every body is held; see `solver.linear_solver`; `--set 'output.systems=[N]'` writes the systems of step N, the failing one included. Past the peak of a quasi-static or path-following run the softened and heaved soil can make it singular (a cell of heaved soil held by one node turns freely, docs/theory.md §3.7): run the scene implicit dynamic";
    RunNonlocal => "RUN_NONLOCAL":
        "the nonlocal averaging failed (a non-finite position or volume)";
        "as RUN_NON_FINITE: reduce the step";
    RunInternal => "RUN_INTERNAL":
        "an internal request the integrator cannot serve (a tangent of an explicit run, inputs of the wrong length)";
        "report it with the scene: this is a bug";
    CheckpointMissing => "CHECKPOINT_MISSING":
        "the directory has no checkpoint";
        "run the scene with `--checkpoint-every N` past a checkpointed step";
    CheckpointNotACheckpoint => "CHECKPOINT_NOT_A_CHECKPOINT":
        "the checkpoint file is not an mpm-geo checkpoint";
        "run the scene again";
    CheckpointVersion => "CHECKPOINT_VERSION":
        "the checkpoint was written by another version of its format";
        "resume with the mpm-geo that wrote it, or run the scene again";
    CheckpointTruncated => "CHECKPOINT_TRUNCATED":
        "the checkpoint file is cut off";
        "run the scene again";
    CheckpointCorrupt => "CHECKPOINT_CORRUPT":
        "the checkpoint's checksum does not match (damaged file)";
        "run the scene again";
    CheckpointForeign => "CHECKPOINT_FOREIGN":
        "the checkpoint belongs to a run of another scene";
        "resume each run in its own directory";
    CheckpointOutputs => "CHECKPOINT_OUTPUTS":
        "the outputs in the directory were changed after the checkpoint";
        "run the scene again";
    CheckpointScene => "CHECKPOINT_SCENE":
        "the scene stored with the checkpoint cannot be rebuilt";
        "run the scene again";
    CheckpointCompleted => "CHECKPOINT_COMPLETED":
        "the run in the directory completed: there is nothing to resume";
        "to repeat it, run the scene again with `--overwrite`";
    CheckpointIo => "CHECKPOINT_IO":
        "the checkpoint could not be read or written";
        "check the free space and the permissions";
    CampaignDirectory => "CAMPAIGN_DIRECTORY":
        "the campaign directory cannot be read or holds no scene";
        "give a directory of scene files (and an optional campaign.toml)";
    CampaignScene => "CAMPAIGN_SCENE":
        "a scene or option of the campaign is refused (nothing was run)";
        "fix the named scene; `mpm-geo check` each scene";
    CampaignOutput => "CAMPAIGN_OUTPUT":
        "a campaign output could not be written";
        "check the free space and the permissions";
    CampaignUnfinished => "CAMPAIGN_UNFINISHED":
        "`--collect` found runs without a finished record";
        "run the missing shards (their runs are listed), then collect again";
    CampaignCurve => "CAMPAIGN_CURVE":
        "a run's `curve.csv` cannot be read as its curve";
        "run that scene again (its directory is named)";
    Interrupted => "INTERRUPTED":
        "SIGINT or SIGTERM stopped a campaign or study: the runs in progress ended after a whole step, their `run.json` says `interrupted` (exit code 130 or 143)";
        "run the same command again: finished runs are not run again, and with `--checkpoint-every` a campaign resumes the stopped ones";
    StudySpec => "STUDY_SPEC":
        "the study spec is refused (the key is named)";
        "fix it; docs/study.md lists the keys";
    StudyScene => "STUDY_SCENE":
        "a scene of the study is refused";
        "fix the base scene or the overrides named";
    StudyIo => "STUDY_IO":
        "a study file could not be written or a run process not started";
        "check the path, the free space and the permissions";
    StudyUnfinished => "STUDY_UNFINISHED":
        "`--collect` found runs not measured yet";
        "run the missing shards, then collect again";
    StudyReference => "STUDY_REFERENCE":
        "the study's reference run did not complete, so no error can be measured";
        "make the reference run complete (its status is given), e.g. with a smaller step";
    StudyFaults => "STUDY_FAULTS":
        "runs of a study ended without a stated outcome (a panic, a time-out, a signal)";
        "read the runs' `stderr.txt`; a panic is a bug, a time-out may need `study.timeout`";
    PointInput => "POINT_INPUT":
        "the material-point driver's material file or options are refused";
        "fix the named parameter";
    PointFailed => "POINT_FAILED":
        "the material-point driver's stress update or mixed control did not converge";
        "use more steps (`--steps`)";
    PointWrite => "POINT_WRITE":
        "the material-point driver's CSV could not be written";
        "check the path and the free space";
}

/// An error type whose values each have an [`ErrorId`].
pub trait Identified {
    /// The identifier of this error.
    fn error_id(&self) -> ErrorId;
}

/// The guide's error table (markdown): identifier, meaning, what to do.
pub fn markdown_table() -> String {
    let mut table = String::from("| identifier | meaning | what to do |\n|---|---|---|\n");
    for id in ErrorId::ALL {
        table.push_str(&format!(
            "| `{}` | {} | {} |\n",
            id.name(),
            id.meaning().replace('|', "\\|"),
            id.remedy().replace('|', "\\|")
        ));
    }
    table
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn identifiers_are_unique_upper_snake_case() {
        let mut seen = std::collections::HashSet::new();
        for id in ErrorId::ALL {
            let name = id.name();
            assert!(seen.insert(name), "{name} twice");
            assert!(
                name.chars().all(|c| c.is_ascii_uppercase() || c == '_'),
                "{name}"
            );
            assert!(!id.meaning().is_empty() && !id.remedy().is_empty());
        }
    }
}
