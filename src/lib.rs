//! # mpm-geo
//!
//! A 2D plane-strain material point method (MPM) for brittle geomaterials,
//! after "Objective modelling of failure processes in brittle materials: mesh
//! dependence and regularisation in the MPM". Equations are cited as *paper
//! eq. N* and as *theory DN* (the physics reference `docs/theory.md`).
//!
//! Two crates (and the solvers' `mpm-solvers`):
//! - `mpm-physics` (directory `physics/`): everything a run computes, the
//!   grid, material points, constitutive models, kernels, integrators, the
//!   time loop and its observer, the scene schema and its validation, the
//!   exact solutions, and the errors with their identifiers. It knows
//!   nothing of files a run leaves, signals or the command line. Its modules
//!   are re-exported here under their own names ([`grid`], [`scene`],
//!   [`simulation`], ...), so `mpm_geo::scene` is `mpm_physics::scene`.
//! - `mpm-geo` (this crate, `src/`): the application that drives runs.
//!
//! The application, one module per concept:
//! - the run: [`run`] (a run's outputs and its observer of the time loop),
//!   [`output`] (the CSV and VTK writers), [`csv_columns`] (units and
//!   fields of every CSV column, a physics module: the monitors' columns
//!   are named there), [`provenance`] (where a run came from,
//!   what it found), [`progress_lines`], [`checkpoint`] (saving a run's
//!   state and checking it can resume), [`resume`] (continuing it);
//! - many runs: [`campaign`] (mesh studies), [`paper`] (the three
//!   campaigns in one command), [`study`] (error against run time),
//!   [`plot`];
//! - runs that survive: [`atomic_file`] (outputs whole or absent),
//!   [`output_dir`] (the output directory's lock and reuse), [`manifest`]
//!   (the files a run records it wrote), [`interrupt`]
//!   (SIGINT/SIGTERM end a run after its step, through the run's observer);
//! - the command line: [`cli_values`], [`point_command`] (the
//!   material-point driver's options), [`error_id`] (the identifier of any
//!   error, as printed).
//!
//! The physics crate never depends on this one (Cargo enforces that), and
//! neither crate's top-level modules import each other in a circle
//! (`tests/layering.rs`).

// Index loops over nodes, components and Voigt entries mirror the equations
// (B_a, D_ij, N_a) more readably than iterator chains.
#![allow(clippy::needless_range_loop)]

pub mod atomic_file;
pub mod campaign;
pub mod checkpoint;
pub mod cli_values;
pub mod error_id;
pub mod interrupt;
pub mod manifest;
pub mod output;
pub mod output_dir;
pub mod paper;
pub mod plot;
pub mod point_command;
pub mod progress_lines;
pub mod provenance;
pub mod resume;
pub mod run;
pub mod study;

pub use mpm_physics::{
    bc, closed_form, constitutive, csv_columns, dofs, energy, error, friction, grid, integrators,
    metrics, model, monitor, nonlocal, parallel, particles, point_driver, profile, scene, seeding,
    settings, shape, simulation, smoothing, start_ramp, stiffness, transfer, volumetric, walls,
};
