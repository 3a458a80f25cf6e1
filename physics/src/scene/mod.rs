//! Scene files (TOML): plain serde structures, `--set` overrides, and the one
//! place where every value is validated before a run.
//!
//! Every key is documented in `docs/scene.md`. Unknown keys are refused by
//! `deny_unknown_fields`; [`Scene::validate`] returns every semantic problem
//! with the path of the offending field and the allowed range.
//!
//! The module is split by concern: `schema.rs` holds the serde structures and
//! configuration enums, `validation.rs` the checks of [`Scene::validate`] and
//! [`Scene::warnings`] (`conflicts.rs` those of entries that contradict each
//! other), `overrides.rs` the `--set key=value` edits of the TOML table,
//! `diagnostics.rs` the explanation of a file or override that cannot be
//! read (file, line and column, plain words, "did you mean"), `budget.rs`
//! and `run_time.rs` what a run will need (memory, steps, time). Every public
//! item is re-exported here (`crate::scene::X`).

use std::path::Path;

mod budget;
mod conflicts;
mod diagnostics;
mod overrides;
mod run_time;
mod schema;
mod validation;
mod variants;

mod linear_solver;
pub use budget::{
    available_memory, human_bytes, parse_memory, MemoryPart, ResourceEstimate, ResourceLimits,
    DEFAULT_MAX_STEPS, DEFAULT_MEMORY_SHARE,
};
pub use diagnostics::{plain_toml_error, Location};
pub use overrides::apply_override;
pub use run_time::{human_duration, RunTimeEstimate, LONG_RUN_SECONDS};
pub use schema::*;
pub use validation::{polygon_contains, FieldError};
pub use variants::Formulation;

use validation::whole_cells;

/// The step column of `curve.csv` (the step number); monitors may not take
/// its name.
pub const STEP_COLUMN: &str = "step_1";
/// The time column of `curve.csv`, s (with path following, the travel per
/// unit velocity); monitors may not take its name.
pub const TIME_COLUMN: &str = "time_s";
/// The step's columns of `curve.csv` ([`crate::simulation::Simulation::step_column_names`]):
/// the step `dt_s`, then, with adaptive steps, its relative error estimate
/// and the attempts redone for their error and for Newton failures.
pub const STEP_COLUMNS: [&str; 4] = [
    "dt_s",
    "error_estimate_1",
    "rejected_error_1",
    "rejected_newton_1",
];

/// Why a scene could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    /// The file could not be read.
    #[error("cannot read scene file {path}: {source}")]
    Io {
        /// The scene path.
        path: String,
        /// The I/O error.
        source: std::io::Error,
    },
    /// TOML syntax error, unknown key, or a value of the wrong type, where
    /// its position in the file is not known.
    #[error("scene {path}: {message}")]
    Parse {
        /// The scene path.
        path: String,
        /// What is wrong (names the key).
        message: String,
    },
    /// TOML syntax error, unknown key, or a value of the wrong type, at a
    /// position in the file: `path:line:column: message` and the line.
    #[error("{path}:{}:{}: {message}\n{location}", location.line, location.column)]
    Located {
        /// The scene path.
        path: String,
        /// Where in the file.
        location: Location,
        /// What is wrong, in plain words, naming the key.
        message: String,
    },
    /// A `--set key=value` override that cannot be applied.
    #[error("override `{assignment}`: {message}")]
    Override {
        /// The override as given.
        assignment: String,
        /// What is wrong with it.
        message: String,
    },
    /// Values out of range or impossible geometry.
    #[error("scene {path} is invalid:\n{}", list(.errors))]
    Invalid {
        /// The scene path.
        path: String,
        /// Every problem found.
        errors: Vec<FieldError>,
    },
    /// Non-finite numbers (`nan`, `inf`) in the scene file or its overrides.
    #[error("scene {path}: non-finite value (nan or inf) at {}", keys.join(", "))]
    NonFinite {
        /// The scene path.
        path: String,
        /// Dotted paths of the non-finite values.
        keys: Vec<String>,
    },
    /// The estimated memory of the run exceeds the limit.
    #[error("scene {path} is too large: {estimate}\nthe limit is {} ({source_of_limit}); reduce the keys named above", human_bytes(*limit))]
    MemoryLimit {
        /// The scene path.
        path: String,
        /// The estimate, with the keys that drive each part.
        estimate: Box<ResourceEstimate>,
        /// The limit, bytes.
        limit: f64,
        /// Where the limit comes from.
        source_of_limit: String,
    },
    /// The run would take more steps than the limit.
    #[error("scene {path} would take {steps:.3e} steps ({reason}), more than the limit {limit} (limits.max_steps, --max-steps); check {}", fields.join(", "))]
    StepLimit {
        /// The scene path.
        path: String,
        /// Estimated steps.
        steps: f64,
        /// The limit.
        limit: u64,
        /// How the step count was found.
        reason: String,
        /// Keys that drive it.
        fields: Vec<String>,
    },
}

/// Dotted paths (`body[0].velocity0[1]`) of every `nan` or `±inf` in `value`.
fn non_finite_keys(value: &toml::Value, path: &str, keys: &mut Vec<String>) {
    match value {
        toml::Value::Float(v) if !v.is_finite() => keys.push(path.to_string()),
        toml::Value::Table(t) => {
            for (k, v) in t {
                let child = if path.is_empty() {
                    k.clone()
                } else {
                    format!("{path}.{k}")
                };
                non_finite_keys(v, &child, keys);
            }
        }
        toml::Value::Array(a) => {
            for (i, v) in a.iter().enumerate() {
                non_finite_keys(v, &format!("{path}[{i}]"), keys);
            }
        }
        _ => {}
    }
}

/// A TOML syntax error of the scene `text`, at its position.
fn syntax_error(origin: &str, text: &str, error: &toml::de::Error) -> SceneError {
    let location = error.span().map(|span| Location::of(text, span));
    parse_error(origin, location, error.message().trim().to_string())
}

/// A [`SceneError::Located`] error, or [`SceneError::Parse`] without a location.
fn parse_error(origin: &str, location: Option<Location>, message: String) -> SceneError {
    let path = origin.to_string();
    match location {
        Some(location) => SceneError::Located {
            path,
            location,
            message,
        },
        None => SceneError::Parse { path, message },
    }
}

/// The scene of a TOML table (serde's checks: keys, types, required keys).
fn deserialize(table: &toml::Table) -> Result<Scene, toml::de::Error> {
    toml::Value::Table(table.clone()).try_into()
}

/// Explain `error`, the failure to read the scene `text` with `overrides`
/// applied: in plain words, and from the input it comes from. An error of
/// the file itself (`base`, its table) gives its line and column; one that
/// first appears with the k-th override is that override's error.
fn explain_failure(
    origin: &str,
    text: &str,
    base: &toml::Table,
    overrides: &[String],
    error: &toml::de::Error,
) -> SceneError {
    let (raw, keys) = diagnostics::message_and_keys(error);
    let (message, keys) = diagnostics::explain(&raw, keys.as_deref());
    let shown = error.to_string();
    let same = |table: &toml::Table| deserialize(table).is_err_and(|e| e.to_string() == shown);
    if overrides.is_empty() || same(base) {
        let location = diagnostics::locate(text, error, &raw, keys.as_deref());
        return parse_error(origin, location, message);
    }
    let mut table = base.clone();
    for assignment in overrides {
        if apply_override(&mut table, assignment).is_err() {
            break;
        }
        if same(&table) {
            return SceneError::Override {
                assignment: assignment.clone(),
                message,
            };
        }
    }
    parse_error(origin, None, message)
}

fn list(errors: &[FieldError]) -> String {
    errors
        .iter()
        .map(|e| format!("  - {e}"))
        .collect::<Vec<_>>()
        .join("\n")
}

impl Scene {
    /// The time scheme in words, for reports: "quasi-static", "quasi-static,
    /// path following (dissipation control)", "implicit dynamic, Newmark γ =
    /// 0.6" or "explicit MUSL, CFL 0.5".
    pub fn scheme(&self) -> String {
        let solver = &self.solver;
        match self.scene.analysis {
            AnalysisKind::QuasiStatic if solver.follows_path() => {
                "quasi-static, path following (dissipation control)".into()
            }
            AnalysisKind::QuasiStatic => "quasi-static".into(),
            AnalysisKind::ImplicitDynamic => {
                let steps = if solver.adaptive() {
                    ", adaptive steps"
                } else {
                    ""
                };
                format!("implicit dynamic, {}{steps}", solver.time_scheme())
            }
            AnalysisKind::Explicit => format!("explicit MUSL, CFL {}", solver.cfl),
        }
    }

    /// Read, apply `overrides` (`key.path=value`), parse and validate a scene file.
    pub fn load(path: &Path, overrides: &[String]) -> Result<Scene, SceneError> {
        let text = std::fs::read_to_string(path).map_err(|source| SceneError::Io {
            path: path.display().to_string(),
            source,
        })?;
        Self::from_str_with_overrides(&text, &path.display().to_string(), overrides)
    }

    /// Parse and validate scene text (`origin` names it in messages).
    pub fn from_str_with_overrides(
        text: &str,
        origin: &str,
        overrides: &[String],
    ) -> Result<Scene, SceneError> {
        let base: toml::Table = text
            .parse()
            .map_err(|e: toml::de::Error| syntax_error(origin, text, &e))?;
        let mut table = base.clone();
        for assignment in overrides {
            apply_override(&mut table, assignment)?;
        }
        let mut keys = Vec::new();
        non_finite_keys(&toml::Value::Table(table.clone()), "", &mut keys);
        if !keys.is_empty() {
            return Err(SceneError::NonFinite {
                path: origin.to_string(),
                keys,
            });
        }
        let scene =
            deserialize(&table).map_err(|e| explain_failure(origin, text, &base, overrides, &e))?;
        let errors = scene.validate();
        if errors.is_empty() {
            Ok(scene)
        } else {
            Err(SceneError::Invalid {
                path: origin.to_string(),
                errors,
            })
        }
    }

    /// Number of cells of the grid along x and y (valid scenes only).
    pub fn grid_cells(&self) -> [usize; 2] {
        [
            whole_cells(self.grid.size[0], self.grid.cell_size).unwrap_or(1),
            whole_cells(self.grid.size[1], self.grid.cell_size).unwrap_or(1),
        ]
    }

    /// Newton iteration limit: the scene's value, else 25 (local) or 60 (nonlocal).
    pub fn max_iterations(&self) -> usize {
        self.solver
            .max_iterations
            .unwrap_or(if self.nonlocal.is_some() { 60 } else { 25 })
    }

    /// Index of the body named `name` (`None` → the first body).
    pub fn body_index(&self, name: Option<&str>) -> Option<usize> {
        match name {
            None => (!self.body.is_empty()).then_some(0),
            Some(n) => self
                .body
                .iter()
                .enumerate()
                .position(|(i, b)| b.name_or_default(i) == n),
        }
    }
}

use crate::error_id::{ErrorId, Identified};

impl Identified for SceneError {
    fn error_id(&self) -> ErrorId {
        match self {
            SceneError::Io { .. } => ErrorId::SceneRead,
            SceneError::Parse { .. } | SceneError::Located { .. } => ErrorId::SceneSyntax,
            SceneError::Override { .. } => ErrorId::SceneOverride,
            SceneError::Invalid { .. } => ErrorId::SceneInvalid,
            SceneError::NonFinite { .. } => ErrorId::SceneNonFinite,
            SceneError::MemoryLimit { .. } => ErrorId::SceneMemoryLimit,
            SceneError::StepLimit { .. } => ErrorId::SceneStepLimit,
        }
    }
}

#[cfg(test)]
mod tests;
