//! # mpm-geo
//!
//! A 2D plane-strain material point method (MPM) for brittle geomaterials,
//! after "Objective modelling of failure processes in brittle materials: mesh
//! dependence and regularisation in the MPM". Equations are cited as *paper
//! eq. N* and as *DESIGN DN* (the physics reference `shared/DESIGN.md`).
//!
//! Layout, one module per concept: [`grid`] and [`shape`] (background grid,
//! bilinear shape functions), [`particles`] (material points), [`transfer`]
//! (the P2G/G2P kernels both integrators share), [`constitutive`] (stress
//! updates), [`nonlocal`] (averaging of the equivalent plastic strain),
//! [`integrators`] (implicit Newton/Newmark and explicit MUSL), [`bc`]
//! (Dirichlet lines, traction points, driven points), [`scene`] (TOML input
//! and its validation), [`simulation`] (the time loop), [`monitor`],
//! [`output`], [`run`] and [`profile`] (what a run writes and measures).

// Index loops over nodes, components and Voigt entries mirror the equations
// (B_a, D_ij, N_a) more readably than iterator chains.
#![allow(clippy::needless_range_loop)]

pub mod bc;
pub mod campaign;
pub mod constitutive;
pub mod dofs;
pub mod error;
pub mod grid;
pub mod integrators;
pub mod metrics;
pub mod model;
pub mod monitor;
pub mod nonlocal;
pub mod output;
pub mod particles;
pub mod plot;
pub mod point_driver;
pub mod profile;
pub mod run;
pub mod scene;
pub mod seeding;
pub mod shape;
pub mod simulation;
pub mod smoothing;
pub mod stiffness;
pub mod transfer;
