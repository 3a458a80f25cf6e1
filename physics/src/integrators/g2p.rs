//! The grid-to-particle kernel both integrators use (theory D14, §3, §4):
//! positions, velocities and accelerations of the material points from the
//! step's nodal solution. Deformation gradients, volumes and stresses follow
//! in the commit stage.

use rayon::prelude::*;

use super::POINTS_PER_TASK;
use crate::grid::Support;
use crate::particles::Particles;
use crate::transfer::interpolate;

/// How a point's velocity follows its new acceleration a_p(n+1) = Σ_i N_ip a_i.
#[derive(Clone, Copy, Debug)]
pub enum VelocityUpdate {
    /// Explicit (symplectic Euler, theory §4 step 3): v += Δt a(n+1).
    Forward,
    /// Newmark (theory §3): v += Δt ((1 − γ) a(n) + γ a(n+1)).
    Newmark {
        /// γ of the scheme.
        gamma: f64,
    },
}

/// The nodal fields one step maps back to its points.
pub struct GridMotion<'a> {
    /// Time step Δt, s.
    pub dt: f64,
    /// The nodal field whose interpolation, times `scale`, moves the points:
    /// Δu_i with scale 1 (implicit) or v_i with scale Δt (explicit).
    pub displacement: &'a [[f64; 2]],
    /// Scale of `displacement`.
    pub scale: f64,
    /// New nodal accelerations a_i(n+1) and how velocities follow them;
    /// `None` in quasi-static runs (no velocities or accelerations).
    pub acceleration: Option<(&'a [[f64; 2]], VelocityUpdate)>,
    /// The nodal force per mass M⁻¹(f_ext − f_int) at the step's end, which
    /// the points carry to the next step (generalised-α only).
    pub force_per_mass: Option<&'a [[f64; 2]]>,
    /// Implicit: the mapped nodal velocity the fixed dofs zeroed, which the
    /// points lose (the explicit integrator's a_i = −v_i/Δt there does the
    /// same through `acceleration`).
    pub velocity_removed: Option<&'a [[f64; 2]]>,
}

/// x_p += scale Σ_i N_ip u_i; with accelerations, a_p = Σ_i N_ip a_i and v_p
/// by the velocity rule; with a force per mass, q_p = Σ_i N_ip q_i (in
/// parallel over the points: each point's update reads only its own state
/// and the nodal fields).
pub fn g2p<S: Support>(particles: &mut Particles, shapes: &[S], motion: &GridMotion) {
    if let Some(nodal) = motion.force_per_mass {
        particles
            .force_per_mass
            .par_iter_mut()
            .zip(shapes.par_iter())
            .with_min_len(POINTS_PER_TASK)
            .for_each(|(q, shape)| *q = interpolate(shape, nodal));
    }
    let Particles {
        position,
        velocity,
        acceleration,
        ..
    } = particles;
    position
        .par_iter_mut()
        .zip(velocity.par_iter_mut())
        .zip(acceleration.par_iter_mut())
        .zip(shapes.par_iter())
        .with_min_len(POINTS_PER_TASK)
        .for_each(|(((x, v), a), shape)| move_point(shape, motion, x, v, a));
}

/// The G2P update of one point with shape functions `shape`.
#[inline]
fn move_point<S: Support>(
    shape: &S,
    motion: &GridMotion,
    position: &mut [f64; 2],
    velocity: &mut [f64; 2],
    acceleration: &mut [f64; 2],
) {
    let dt = motion.dt;
    if let Some((nodal_acceleration, rule)) = motion.acceleration {
        let a = interpolate(shape, nodal_acceleration);
        let v = velocity;
        match rule {
            VelocityUpdate::Forward => {
                v[0] += dt * a[0];
                v[1] += dt * a[1];
            }
            VelocityUpdate::Newmark { gamma } => {
                let before = *acceleration;
                let removed = motion
                    .velocity_removed
                    .map_or([0.0; 2], |r| interpolate(shape, r));
                for c in 0..2 {
                    v[c] += dt * ((1.0 - gamma) * before[c] + gamma * a[c]) - removed[c];
                }
            }
        }
        *acceleration = a;
    }
    let u = interpolate(shape, motion.displacement);
    position[0] += motion.scale * u[0];
    position[1] += motion.scale * u[1];
}
