//! The commit stage, shared by both integrators: the converged step becomes
//! the state of the material points (theory D14: F, V, accumulated strain;
//! stresses and states), points carried through a wall are put back on it
//! (theory eq. W1, [`crate::walls`]), the boundary points follow the grid
//! motion, and points that left the grid stop the run or are removed.

use rayon::prelude::*;

use super::converged_stresses::ConvergedStresses;
use super::{StepSetup, TrialStresses};
use crate::constitutive::Voigt;
use crate::error::StepError;
use crate::grid::Grid;
use crate::model::{Model, PointRemap};
use crate::particles::Particles;
use crate::scene::LostPointPolicy;
use crate::transfer::strain_and_spin;

/// The nodal results of the step the model keeps.
pub struct NodalResults<'a> {
    /// Support reactions per grid node, kN/m.
    pub reaction: &'a [[f64; 2]],
    /// Displacement increment Δu per grid node (moves the traction points).
    pub increment: &'a [[f64; 2]],
    /// Nodal motion that moves the rigid bodies' surface contact points: the
    /// one that moved the material points.
    pub contact_motion: &'a [[f64; 2]],
    /// Gravity of the step's external force (theory D10), m/s² along −y.
    pub gravity: f64,
    /// Time at the end of the step, s (the model's time is the start): a rigid
    /// body's surface point over no soil moves with the body over the step.
    pub end_time: f64,
    /// The only nodes where `reaction` and `increment` can be other than
    /// zero (increasing), when the integrator knows them; `None`: any node.
    pub nonzero_at: Option<&'a [u32]>,
    /// Kinetic energy the fixed dofs removed in the step, kJ/m
    /// ([`super::boundary_work`] B1).
    pub boundary_work: f64,
}

/// Commit the step: points held on the soil's side of the walls (W1, their
/// kinetic energy lost into it booked in B, B2), deformation and stresses at
/// the points, the step's energies, boundary points advected, lost points
/// checked. Returns the
/// index remap when points were removed.
pub fn commit(
    model: &mut Model,
    setup: &StepSetup,
    trial: &TrialStresses,
    converged: ConvergedStresses,
    nodal: NodalResults,
) -> Result<Option<PointRemap>, StepError> {
    let mut converged = converged;
    commit_swapping(model, setup, trial, &mut converged, nodal)
}

/// [`commit`] that swaps the converged stresses and states into the points:
/// `converged` is left with the arrays of the previous step (to be reused,
/// so that a step allocates none), and the model's nodal results are
/// copied into its arrays.
pub fn commit_swapping(
    model: &mut Model,
    setup: &StepSetup,
    trial: &TrialStresses,
    converged: &mut ConvergedStresses,
    nodal: NodalResults,
) -> Result<Option<PointRemap>, StepError> {
    model.state.internal_work += converged.internal_work;
    model.state.dissipated_energy += converged.dissipation;
    model.state.boundary_work += model.walls.hold_points(&mut model.state.particles);
    let p = &mut model.state.particles;
    std::mem::swap(&mut p.stress, &mut converged.stress);
    std::mem::swap(&mut p.state, &mut converged.state);
    let volume_cap = model
        .settings
        .grid
        .max_point_volume
        .map_or(f64::INFINITY, |cells| cells * model.grid.cell_size.powi(2));
    let first = deform_and_check(p, &trial.gradient, &model.grid, volume_cap);
    if let Some(i) = first.non_finite {
        return Err(non_finite_point(p, i));
    }
    check_finite_nodes(&model.grid, &nodal)?;
    if model.settings.grid.lost_points == LostPointPolicy::Stop {
        if let Some(i) = first.outside {
            return Err(StepError::ParticleLeftGrid {
                particle: i,
                position: p.position[i],
            });
        }
    }

    model.account_gravity_work(nodal.gravity);
    model.state.boundary_work += nodal.boundary_work;
    model.state.external_work += model
        .state
        .traction
        .advect(&setup.traction_shapes, nodal.increment);
    model.state.driven.advect(
        &setup.driven_shapes,
        &setup.bins,
        nodal.contact_motion,
        (model.state.time, nodal.end_time),
    );
    keep_nodal_results(model, &nodal);
    let remap = model.drop_lost_points();
    model.state.mass_height = model.current_mass_height();
    remap
}

/// The step's reactions and increments into the model's arrays, written at
/// the nodes where they or the last step's can be nonzero when both are
/// known (a grid much larger than the body costs nothing), else copied
/// whole.
fn keep_nodal_results(model: &mut Model, nodal: &NodalResults) {
    let before = model.state.nodal_results_at.take();
    let (now, before_nodes) = (nodal.nonzero_at, before.as_deref());
    copy_nodal(&mut model.state.reaction, nodal.reaction, before_nodes, now);
    copy_nodal(
        &mut model.state.last_increment,
        nodal.increment,
        before_nodes,
        now,
    );
    model.state.nodal_results_at = now.map(|now| {
        let mut nodes = before.unwrap_or_default();
        nodes.clear();
        nodes.extend_from_slice(now);
        nodes
    });
}

/// `to = from` for a nodal array, where `from` is zero outside the nodes
/// `now` and `to` outside the nodes `before` (each when given): with both
/// known, `to` is zeroed at `before` and written at `now` only; otherwise
/// the whole array is copied (reusing the array of `to`).
fn copy_nodal(
    to: &mut Vec<[f64; 2]>,
    from: &[[f64; 2]],
    before: Option<&[u32]>,
    now: Option<&[u32]>,
) {
    match (before, now) {
        (Some(before), Some(now)) if to.len() == from.len() => {
            for &node in before {
                to[node as usize] = [0.0; 2];
            }
            for &node in now {
                to[node as usize] = from[node as usize];
            }
        }
        _ => {
            to.clear();
            to.extend_from_slice(from);
        }
    }
}

/// The lowest-index points that fail the checks of the committed state.
#[derive(Clone, Copy, Default)]
struct FirstFailures {
    /// The first point with a NaN or infinite variable (or a volume that is
    /// not positive).
    non_finite: Option<usize>,
    /// The first point outside the grid.
    outside: Option<usize>,
}

impl FirstFailures {
    /// The lower indices of two sets of points.
    fn merge(self, other: Self) -> Self {
        let lower = |a: Option<usize>, b: Option<usize>| match (a, b) {
            (Some(a), Some(b)) => Some(a.min(b)),
            _ => a.or(b),
        };
        Self {
            non_finite: lower(self.non_finite, other.non_finite),
            outside: lower(self.outside, other.outside),
        }
    }
}

/// The one pass over the committed point state, in parallel: F, V and ε of
/// every point from its increment gradient (theory D14, V bounded by
/// `volume_cap`, m², see `grid.max_point_volume`), then the point checked;
/// returns the lowest-index points with a non-finite variable and outside
/// the grid (the same whatever the number of threads).
fn deform_and_check(
    p: &mut Particles,
    gradient: &[[f64; 4]],
    grid: &Grid,
    volume_cap: f64,
) -> FirstFailures {
    let Particles {
        position,
        velocity,
        acceleration,
        volume,
        def_grad,
        stress,
        strain,
        state,
        ..
    } = p;
    let (position, velocity, acceleration) = (&*position, &*velocity, &*acceleration);
    let (stress, state) = (&*stress, &*state);
    def_grad
        .par_iter_mut()
        .zip(volume.par_iter_mut())
        .zip(strain.par_iter_mut())
        .zip(gradient.par_iter())
        .enumerate()
        .with_min_len(1024)
        .fold(
            FirstFailures::default,
            |mut first, (i, (((f, v), e), l))| {
                deform(f, v, e, l, volume_cap);
                let finite = |x: &[f64]| x.iter().all(|c| c.is_finite());
                let point_finite = finite(&stress[i])
                    && finite(&position[i])
                    && finite(&velocity[i])
                    && finite(&acceleration[i])
                    && volume_is_valid(*v)
                    && finite(f)
                    && finite(e)
                    && state[i].plastic_strain_eq.is_finite()
                    && state[i].plastic_strain_eq_nonlocal.is_finite()
                    && finite(&state[i].plastic_strain);
                if !point_finite && first.non_finite.is_none() {
                    first.non_finite = Some(i);
                }
                if first.outside.is_none() && !grid.contains(position[i]) {
                    first.outside = Some(i);
                }
                first
            },
        )
        .reduce(FirstFailures::default, FirstFailures::merge)
}

/// The error of point `i`, the first with a non-finite variable: its
/// stress, or the first non-finite quantity in the order of the checks.
fn non_finite_point(p: &Particles, i: usize) -> StepError {
    let finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
    if !finite(&p.stress[i]) {
        return StepError::NonFiniteStress { particle: i };
    }
    let quantity = if !finite(&p.position[i]) {
        "position"
    } else if !finite(&p.velocity[i]) {
        "velocity"
    } else if !finite(&p.acceleration[i]) {
        "acceleration"
    } else if !volume_is_valid(p.volume[i]) {
        "volume (non-finite or not positive)"
    } else if !finite(&p.def_grad[i]) {
        "deformation gradient"
    } else if !finite(&p.strain[i]) {
        "strain"
    } else {
        "plastic strain"
    };
    let position = if finite(&p.position[i]) {
        p.position[i]
    } else {
        p.position0[i]
    };
    StepError::NonFinitePoint {
        particle: i,
        quantity,
        position,
    }
}

/// A committed volume must be finite and positive.
fn volume_is_valid(volume: f64) -> bool {
    volume.is_finite() && volume > 0.0
}

/// The nodal results the model keeps must be finite (checked at the nodes
/// where they can be other than zero).
fn check_finite_nodes(grid: &Grid, nodal: &NodalResults) -> Result<(), StepError> {
    let finite = |v: &[f64; 2]| v[0].is_finite() && v[1].is_finite();
    for (quantity, values) in [
        ("reaction", nodal.reaction),
        ("displacement increment", nodal.increment),
    ] {
        let first_bad = match nodal.nonzero_at {
            Some(nodes) => nodes
                .iter()
                .map(|&node| node as usize)
                .find(|&node| !finite(&values[node])),
            None => values.iter().position(|v| !finite(v)),
        };
        if let Some(node) = first_bad {
            return Err(StepError::NonFiniteNode {
                node,
                quantity,
                position: grid.node_position(node),
            });
        }
    }
    Ok(())
}

/// F ← (I + L) F; V ← min(det(I + L) V, `volume_cap`); ε += Δε of one
/// point (theory D14; the bound is `grid.max_point_volume`, infinite when
/// unset). F keeps the whole motion: only the volume that weights the
/// point's force, stiffness, density and nonlocal weight is bounded.
fn deform(
    def_grad: &mut [f64; 4],
    volume: &mut f64,
    strain: &mut Voigt,
    l: &[f64; 4],
    volume_cap: f64,
) {
    let df = [1.0 + l[0], l[1], l[2], 1.0 + l[3]];
    let f = *def_grad;
    *def_grad = [
        df[0] * f[0] + df[1] * f[2],
        df[0] * f[1] + df[1] * f[3],
        df[2] * f[0] + df[3] * f[2],
        df[2] * f[1] + df[3] * f[3],
    ];
    let deformed = *volume * (df[0] * df[3] - df[1] * df[2]);
    // not `f64::min`, which would turn a NaN volume into the cap and hide it
    *volume = if deformed > volume_cap {
        volume_cap
    } else {
        deformed
    };
    let (de, _) = strain_and_spin(l);
    for k in 0..4 {
        strain[k] += de[k];
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A uniform stretch grows V by det(I + L) until the bound, then V stays
    /// at the bound while F keeps the whole motion; a NaN volume stays NaN
    /// (the check after it must see it).
    #[test]
    fn volume_follows_the_motion_up_to_its_bound() {
        let (mut f, mut v, mut e) = ([1.0, 0.0, 0.0, 1.0], 0.25, [0.0; 4]);
        let stretch = [0.5, 0.0, 0.0, 0.0]; // det(I + L) = 1.5 per step
        deform(&mut f, &mut v, &mut e, &stretch, 1.0);
        assert!((v - 0.375).abs() < 1e-15, "unbounded step: V = {v}");
        for _ in 0..4 {
            deform(&mut f, &mut v, &mut e, &stretch, 1.0);
        }
        assert_eq!(v, 1.0, "V must stop at the bound");
        let det = f[0] * f[3] - f[1] * f[2];
        assert!((det - 1.5f64.powi(5)).abs() < 1e-12, "det F = {det}");
        let mut nan = f64::NAN;
        deform(&mut f, &mut nan, &mut e, &stretch, 1.0);
        assert!(nan.is_nan(), "a NaN volume became {nan}");
    }

    /// The nodal results kept over a run of steps whose nonzero nodes move
    /// (and one whose nodes are unknown) are the step's arrays, bit for bit,
    /// whichever way they are written.
    #[test]
    fn kept_nodal_results_are_the_steps() {
        let node_count = 50;
        // a field zero outside `nodes`, its values from the step number
        let field = |step: usize, nodes: &[u32]| {
            let mut values = vec![[0.0; 2]; node_count];
            for &n in nodes {
                let x = (step * 100 + n as usize) as f64;
                values[n as usize] = [x.sin(), -x.cos()];
            }
            values
        };
        let steps: [Option<Vec<u32>>; 5] = [
            Some((10..20).collect()),
            Some((15..30).collect()),
            None,
            Some((0..5).collect()),
            Some(vec![]),
        ];
        let mut kept = vec![[0.0; 2]; node_count];
        let mut before: Option<Vec<u32>> = Some(vec![]);
        for (step, nonzero_at) in steps.iter().enumerate() {
            let all: Vec<u32> = (0..node_count as u32).collect();
            let values = field(step, nonzero_at.as_deref().unwrap_or(&all));
            copy_nodal(&mut kept, &values, before.as_deref(), nonzero_at.as_deref());
            let same = kept
                .iter()
                .zip(&values)
                .all(|(a, b)| a[0].to_bits() == b[0].to_bits() && a[1].to_bits() == b[1].to_bits());
            assert!(same, "step {step}: the kept array differs from the step's");
            before = nonzero_at.clone();
        }
    }
}
