//! # mpm-physics
//!
//! The physics of mpm-geo, a 2D plane-strain material point method (MPM)
//! for brittle geomaterials: everything a run computes, nothing of how a
//! run is driven, interrupted or written (that is the application crate,
//! `mpm-geo`). Equations are cited as *paper eq. N* and as *theory DN*
//! (the physics reference `docs/theory.md`).
//!
//! Layout, one module per concept:
//! - the model: [`grid`] and [`shape`] (background grid, bilinear and GIMP
//!   shape functions), [`particles`] and [`seeding`] (material points),
//!   [`constitutive`] (stress updates), [`bc`] (Dirichlet lines, traction
//!   points, driven points), [`start_ramp`] (smooth start of their
//!   prescribed motion), [`walls`] and [`friction`] (rigid bodies and
//!   frictional contact), [`model`] (all of it and its state in time);
//! - the kernels: [`transfer`] (the P2G/G2P kernels both integrators share),
//!   [`stiffness`] and [`volumetric`] (tangent blocks), [`dofs`] (numbering
//!   of the unknowns), [`nonlocal`] (averaging of the equivalent plastic
//!   strain), [`smoothing`] (double mapping), [`parallel`];
//! - the step: [`integrators`] (implicit Newton/Newmark and explicit MUSL,
//!   each a list of named stages in the order of paper Fig. 1);
//! - the time loop: [`simulation`] (time loop and its observer),
//!   [`monitor`], [`energy`], [`profile`] (what a run measures);
//! - the answers: [`closed_form`] (the exact solutions the validation tests
//!   and the studies compare runs against), [`metrics`] (mesh-study
//!   measures), [`point_driver`] (single material-point tests);
//! - the input: [`scene`] (TOML schema and its validation), [`csv_columns`]
//!   (units and fields of every CSV column a run writes);
//! - the errors: [`error`] and [`error_id`] (their stable identifiers).

// Index loops over nodes, components and Voigt entries mirror the equations
// (B_a, D_ij, N_a) more readably than iterator chains.
#![allow(clippy::needless_range_loop)]

pub mod bc;
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
pub mod metrics;
pub mod model;
pub mod monitor;
pub mod nonlocal;
pub mod parallel;
pub mod particles;
pub mod point_driver;
pub mod profile;
pub mod scene;
pub mod seeding;
pub mod settings;
pub mod shape;
pub mod simulation;
pub mod smoothing;
pub mod start_ramp;
pub mod stiffness;
pub mod transfer;
pub mod volumetric;
pub mod walls;
