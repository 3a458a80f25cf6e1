//! # mpm-geo
//!
//! A 2D plane-strain material point method (MPM) for brittle geomaterials,
//! after "Objective modelling of failure processes in brittle materials: mesh
//! dependence and regularisation in the MPM". Equations are cited as *paper
//! eq. N* and as *DESIGN DN* (the physics reference `shared/DESIGN.md`).

pub mod constitutive;
pub mod grid;
pub mod particles;
pub mod point_driver;
pub mod shape;
