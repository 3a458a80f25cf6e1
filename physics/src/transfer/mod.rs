//! Particle ↔ grid transfer kernels (theory D10–D14), shared by the implicit
//! and the explicit integrator.
//!
//! All nodal sums are formed in a fixed order (particles binned by cell with a
//! stable counting sort, cell sums in particle order, node sums over the four
//! neighbouring cells in a fixed order), so results are bit-identical whatever
//! the number of rayon threads.

mod bins;
mod nodal_field;
mod nodal_forces;
mod point_kinematics;
mod scatter;
mod shapes;
#[cfg(test)]
pub(crate) mod tests;

pub use bins::{ParticleBins, MAX_PATCH};
pub use nodal_field::{refill_fields, NodalField, NodalValue, NODES_PER_TASK};
pub use nodal_forces::{
    body_force, internal_force, internal_force_into, nodal_mass, nodal_mass_weighted,
};
pub use point_kinematics::{
    gradient, interpolate, rotate_stress, rotate_stress_derivative, strain_and_spin,
};
pub use scatter::{scatter, scatter_into_field, Contribution};
pub use shapes::{bilinear_shapes_into, shapes_at, shapes_into, OutsideGrid, ShapeScratch};

/// Sentinel for "no slot" in index maps.
pub const NONE: u32 = u32::MAX;
