//! Time integrators. Both use the same transfer kernels (`crate::transfer`),
//! the same constitutive interface and the same boundary-condition devices;
//! they differ only in how the nodal displacement increment of a step is found:
//!
//! * [`implicit`]: Newton–Raphson on the nodal equilibrium, quasi-static or
//!   Newmark trapezoidal (paper eq. 2, DESIGN D15–D19), sparse direct solves;
//! * [`explicit`]: MUSL central difference, matrix-free (DESIGN §4).

pub mod explicit;
mod finalize;
pub mod implicit;
mod regularisation;
mod stress;

pub(crate) use regularisation::NonlocalStep;
pub(crate) use stress::{evaluate_stresses, TrialStresses};
