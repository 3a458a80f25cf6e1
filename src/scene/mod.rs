//! Scene files (TOML): plain serde structures, `--set` overrides, and the one
//! place where every value is validated before a run.
//!
//! Every key is documented in `docs/scene.md`. Unknown keys are refused by
//! `deny_unknown_fields`; [`Scene::validate`] returns every semantic problem
//! with the path of the offending field and the allowed range.
//!
//! The module is split by concern: `schema.rs` holds the serde structures and
//! configuration enums, `validation.rs` the checks of [`Scene::validate`] and
//! [`Scene::warnings`], `overrides.rs` the `--set key=value` edits of the TOML
//! table. Every public item is re-exported here (`crate::scene::X`).

use std::path::Path;

mod overrides;
mod schema;
mod validation;
mod variants;

mod linear_solver;
pub use overrides::apply_override;
pub use schema::*;
pub use validation::{polygon_contains, FieldError};
pub use variants::Formulation;

use validation::whole_cells;

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
    /// TOML syntax error, unknown key, or a value of the wrong type.
    #[error("scene {path}: {message}")]
    Parse {
        /// The scene path.
        path: String,
        /// The parser's message (names the key and its location).
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
}

fn list(errors: &[FieldError]) -> String {
    errors
        .iter()
        .map(|e| format!("  - {e}"))
        .collect::<Vec<_>>()
        .join("\n")
}

impl Scene {
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
        let mut table: toml::Table =
            text.parse()
                .map_err(|e: toml::de::Error| SceneError::Parse {
                    path: origin.to_string(),
                    message: e.to_string(),
                })?;
        for assignment in overrides {
            apply_override(&mut table, assignment)?;
        }
        let scene: Scene = toml::Value::Table(table)
            .try_into()
            .map_err(|e: toml::de::Error| SceneError::Parse {
                path: origin.to_string(),
                message: e.to_string(),
            })?;
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

#[cfg(test)]
mod tests;
