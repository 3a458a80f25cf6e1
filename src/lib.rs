//! # mpm-geo
//!
//! A 2D plane-strain material point method (MPM) for brittle geomaterials,
//! after "Objective modelling of failure processes in brittle materials: mesh
//! dependence and regularisation in the MPM". Equations are cited as *paper
//! eq. N* and as *theory DN* (the physics reference `docs/theory.md`).
//!
//! Layout, one module per concept:
//! - the model: [`grid`] and [`shape`] (background grid, bilinear and GIMP
//!   shape functions), [`particles`] and [`seeding`] (material points),
//!   [`constitutive`] (stress updates), [`bc`] (Dirichlet lines, traction
//!   points, driven points), [`start_ramp`] (smooth start of their
//!   prescribed motion), [`model`] (all of it and its state in time);
//! - the kernels: [`transfer`] (the P2G/G2P kernels both integrators share),
//!   [`stiffness`] (tangent blocks), [`dofs`] (numbering of the unknowns),
//!   [`nonlocal`] (averaging of the equivalent plastic strain), [`smoothing`]
//!   (double mapping);
//! - the step: [`integrators`] (implicit Newton/Newmark and explicit MUSL,
//!   each a list of named stages in the order of paper Fig. 1);
//! - the answers: [`closed_form`] (the exact solutions the validation tests
//!   and the studies compare runs against);
//! - the run: [`simulation`] (time loop, monitors), [`monitor`], [`output`],
//!   [`run`] and [`profile`] (what a run writes and measures),
//!   [`csv_columns`] (units and fields of every CSV column),
//!   [`provenance`] (where a run came from, what it found),
//!   [`checkpoint`] (saving and resuming a run), [`scene`]
//!   (TOML input and its validation), [`campaign`] and [`metrics`] (mesh
//!   studies), [`paper`] (the three campaigns in one command), [`study`]
//!   (error against run time), [`error`];
//! - runs that survive: [`atomic_file`] (outputs whole or absent),
//!   [`output_dir`] (the output directory's lock and reuse), [`manifest`]
//!   (the files a run records it wrote), [`interrupt`]
//!   (SIGINT/SIGTERM end a run after its step).

// Index loops over nodes, components and Voigt entries mirror the equations
// (B_a, D_ij, N_a) more readably than iterator chains.
#![allow(clippy::needless_range_loop)]

pub mod atomic_file;
pub mod bc;
pub mod campaign;
pub mod checkpoint;
pub mod cli_values;
pub mod closed_form;
pub mod constitutive;
pub mod csv_columns;
pub mod dofs;
pub mod energy;
pub mod error;
pub mod error_id;
pub mod friction;
pub mod grid;
pub mod integrators;
pub mod interrupt;
pub mod manifest;
pub mod metrics;
pub mod model;
pub mod monitor;
pub mod nonlocal;
pub mod output;
pub mod output_dir;
pub mod paper;
pub mod parallel;
pub mod particles;
pub mod plot;
pub mod point_driver;
pub mod profile;
pub mod progress_lines;
pub mod provenance;
pub mod run;
pub mod scene;
pub mod seeding;
pub mod shape;
pub mod simulation;
pub mod smoothing;
pub mod start_ramp;
pub mod stiffness;
pub mod study;
pub mod transfer;
pub mod volumetric;
pub mod walls;
