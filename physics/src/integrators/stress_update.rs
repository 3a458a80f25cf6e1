//! The stress-update stage shared by both integrators: for each material
//! point, Δε and ω from the nodal displacement increment (theory D12), Jaumann
//! rotation of the stored stress (D13), and the constitutive update (§5).

use std::sync::atomic::{AtomicUsize, Ordering};

use rayon::prelude::*;

use super::regularisation::NonlocalStrength;
use super::{StepSetup, POINTS_PER_TASK};
use crate::constitutive::{
    mat4_mul_vec, ConstitutiveError, Mat4, PointState, StrengthVariable, Voigt,
};
use crate::grid::Support;
use crate::model::Model;
use crate::profile::{Profile, Work};
use crate::transfer;
use crate::volumetric;

/// Trial stresses, states and tangents of all material points for a given
/// displacement increment (not yet committed).
#[derive(Clone, Debug, Default)]
pub struct TrialStresses {
    /// σ_{n+1}, kPa.
    pub stress: Vec<Voigt>,
    /// State after the update.
    pub state: Vec<PointState>,
    /// Algorithmic tangents dσ/dΔε.
    pub tangent: Vec<Mat4>,
    /// Displacement-increment gradient L per point (row-major 2×2).
    pub gradient: Vec<[f64; 4]>,
    /// σ^R(n): the committed stress rotated by the step's spin (D13).
    pub rotated: Vec<Voigt>,
    /// dσ_{n+1}/dω = D_alg C g (see `stiffness::add_spin_stiffness`); filled only
    /// when compliances are passed (unsymmetric tangents).
    pub spin_sensitivity: Vec<Voigt>,
    /// B-bar: ⅓ (θ̄_c − θ_p) per point, added to the normal strain components
    /// ([`volumetric`] B2); empty for the standard treatment.
    pub volumetric_correction: Vec<f64>,
    /// Implicit frictional edges: dT/dΔu_t of each frictional node at this
    /// iterate (k_t sticking, 0 slipping), in the order of
    /// [`crate::friction::FrictionEdges::nodes`].
    pub friction_stiffness: Vec<f64>,
}

impl TrialStresses {
    /// The strain increment Δε the stress update of point `p` was given:
    /// from its gradient, with the B-bar correction when there is one.
    pub fn strain_increment(&self, p: usize) -> Voigt {
        let strain = transfer::strain_and_spin(&self.gradient[p]).0;
        match self.volumetric_correction.get(p) {
            Some(&c) => volumetric::corrected_strain(&strain, c),
            None => strain,
        }
    }
}

/// Evaluate the stress update at every material point of `model` for the
/// nodal increment `du`, with the shape functions and bins of `setup`.
/// `strength` (nonlocal runs) gives the variable each point's strength is
/// evaluated at (D36); local runs pass `None`. With `spin_term`, dσ/dω is
/// kept for the tangent's spin term. With B-bar (`[grid] volumetric`), each
/// point's dilatation is its cell's average ([`volumetric`] B1–B2). Returns what the
/// updates did: [`UpdateTally::counted`] records it in the profile and gives
/// the lowest-index failing point, if any (deterministic whatever the thread
/// count). After a failure the trial arrays are incomplete: points above
/// the failing one may be left as they were ([`FirstFailure`]).
pub fn evaluate_stresses(
    model: &Model,
    setup: &StepSetup,
    du: &[[f64; 2]],
    strength: Option<NonlocalStrength<'_>>,
    spin_term: bool,
    trial: &mut TrialStresses,
) -> UpdateTally {
    let tangents = if spin_term {
        Tangents::WithSpinTerm
    } else {
        Tangents::Kept
    };
    evaluate(model, setup, &setup.shapes, du, strength, tangents, trial)
}

/// [`evaluate_stresses`] for a step that builds no tangent (explicit), with
/// the points' shape functions `shapes` (those of `setup`, or their compact
/// form): the same stresses, states, gradients and rotated stresses, with
/// `trial.tangent` and `trial.spin_sensitivity` left empty.
pub fn evaluate_stresses_without_tangent<S: Support>(
    model: &Model,
    setup: &StepSetup,
    shapes: &[S],
    du: &[[f64; 2]],
    strength: Option<NonlocalStrength<'_>>,
    trial: &mut TrialStresses,
) -> UpdateTally {
    evaluate(model, setup, shapes, du, strength, Tangents::None, trial)
}

/// Which tangents a stress evaluation keeps.
#[derive(Clone, Copy, PartialEq)]
enum Tangents {
    /// None (explicit steps).
    None,
    /// The algorithmic tangents dσ/dΔε.
    Kept,
    /// The tangents and dσ/dω (unsymmetric tangents with the spin term).
    WithSpinTerm,
}

/// The stress update of every point for the increment `du` (interpolated
/// with `shapes`), with the tangents `tangents` asks for
/// ([`evaluate_stresses`]). Without B-bar each point's gradient is formed in
/// the same run of [`POINTS_PER_RUN`] points as its update.
fn evaluate<S: Support>(
    model: &Model,
    setup: &StepSetup,
    shapes: &[S],
    du: &[[f64; 2]],
    strength: Option<NonlocalStrength<'_>>,
    tangents: Tangents,
    trial: &mut TrialStresses,
) -> UpdateTally {
    let (particles, materials) = (&model.state.particles, &model.materials);
    let compliances = (tangents == Tangents::WithSpinTerm).then_some(model.compliances.as_slice());
    let n = particles.len();
    let gradient_known = prepare_trial(model, setup, shapes, du, trial);
    let correction = &trial.volumetric_correction;
    let first_failure = FirstFailure::default();
    // Each task takes a run of points in two passes: the gradients and the
    // rotated stresses first (a loop without calls, so the divisions of
    // consecutive points' rotations overlap), then the constitutive updates.
    let kinematics = |p0: usize, rotated: &mut [Voigt], gradient: &mut [[f64; 4]]| {
        for (k, (rotated, l)) in rotated.iter_mut().zip(gradient.iter_mut()).enumerate() {
            if !gradient_known {
                *l = transfer::gradient(&shapes[p0 + k], du);
            }
            let spin = transfer::strain_and_spin(l).1;
            *rotated = transfer::rotate_stress(&particles.stress[p0 + k], spin);
        }
    };
    // the update of point p: trial stress, state and (when asked for)
    // tangent stored in place, from its rotated stress and gradient
    let update_point = |tally: &mut UpdateTally,
                        p: usize,
                        (stress, state): (&mut Voigt, &mut PointState),
                        (rotated, l): (&Voigt, &[f64; 4]),
                        tangent: Option<&mut Mat4>| {
        if first_failure.decided_before(p) {
            return;
        }
        let strain = transfer::strain_and_spin(l).0;
        let strain_increment = match correction.get(p) {
            Some(&c) => volumetric::corrected_strain(&strain, c),
            None => strain,
        };
        let material = &materials[particles.material[p] as usize];
        let strength = strength.map_or(StrengthVariable::Local, |s| s.at(p));
        tally.updates += 1;
        tally.yield_checks += u64::from(!material.is_elastic());
        let (state_n, strain) = (&particles.state[p], &strain_increment);
        let updated = match tangent {
            None => material.update_stress(rotated, strain, state_n, strength, (stress, state)),
            Some(tangent) => {
                material.update_into(rotated, strain, state_n, strength, (stress, state, tangent))
            }
        };
        match updated {
            Ok(yielded) => tally.return_mappings += u64::from(yielded),
            Err(e) => {
                first_failure.record(p);
                tally.fail(p, e);
            }
        }
    };
    let runs = trial
        .stress
        .par_chunks_mut(POINTS_PER_RUN)
        .zip(trial.state.par_chunks_mut(POINTS_PER_RUN))
        .zip(trial.rotated.par_chunks_mut(POINTS_PER_RUN))
        .zip(trial.gradient.par_chunks_mut(POINTS_PER_RUN))
        .enumerate()
        .with_min_len(POINTS_PER_TASK / POINTS_PER_RUN);
    let tally = if tangents == Tangents::None {
        trial.tangent.clear();
        runs.fold(
            UpdateTally::default,
            |mut tally, (run, (((stress, state), rotated), gradient))| {
                let p0 = run * POINTS_PER_RUN;
                kinematics(p0, rotated, gradient);
                let points = stress.iter_mut().zip(state.iter_mut());
                let formed = rotated.iter().zip(gradient.iter());
                for (k, (point, kinematic)) in points.zip(formed).enumerate() {
                    update_point(&mut tally, p0 + k, point, kinematic, None);
                }
                tally
            },
        )
        .reduce(UpdateTally::default, UpdateTally::merge)
    } else {
        trial.tangent.resize(n, [[0.0; 4]; 4]);
        runs.zip(trial.tangent.par_chunks_mut(POINTS_PER_RUN))
            .fold(
                UpdateTally::default,
                |mut tally, ((run, (((stress, state), rotated), gradient)), tangent)| {
                    let p0 = run * POINTS_PER_RUN;
                    kinematics(p0, rotated, gradient);
                    let points = stress.iter_mut().zip(state.iter_mut());
                    let formed = rotated.iter().zip(gradient.iter());
                    for (k, ((point, kinematic), tangent)) in
                        points.zip(formed).zip(tangent.iter_mut()).enumerate()
                    {
                        update_point(&mut tally, p0 + k, point, kinematic, Some(tangent));
                    }
                    tally
                },
            )
            .reduce(UpdateTally::default, UpdateTally::merge)
    };
    spin_sensitivities(model, compliances, trial);
    tally
}

/// The trial arrays sized for every point and, with B-bar, the gradients of
/// all points and their cell-averaged dilatations ([B1]–[B2]), which every
/// update needs first. Returns whether the gradients are formed already.
fn prepare_trial<S: Support>(
    model: &Model,
    setup: &StepSetup,
    shapes: &[S],
    du: &[[f64; 2]],
    trial: &mut TrialStresses,
) -> bool {
    let particles = &model.state.particles;
    let b_bar = model.b_bar().then_some(&setup.bins);
    let n = particles.len();
    trial.stress.resize(n, [0.0; 4]);
    trial.state.resize(n, PointState::default());
    trial.rotated.resize(n, [0.0; 4]);
    trial.gradient.resize(n, [0.0; 4]);
    trial.volumetric_correction = match b_bar {
        Some(bins) => {
            trial
                .gradient
                .par_iter_mut()
                .zip(shapes)
                .for_each(|(l, s)| *l = transfer::gradient(s, du));
            volumetric::dilatation_corrections(bins, &particles.volume, &trial.gradient)
        }
        None => Vec::new(),
    };
    b_bar.is_some()
}

/// The spin term's sensitivities dσ/dω = D_alg C (dσ_J/dω) of every point
/// (with `compliances`: unsymmetric tangents with the spin term), else none.
fn spin_sensitivities(model: &Model, compliances: Option<&[Mat4]>, trial: &mut TrialStresses) {
    let particles = &model.state.particles;
    if let Some(compliances) = compliances {
        trial.spin_sensitivity.resize(particles.len(), [0.0; 4]);
        trial
            .spin_sensitivity
            .par_iter_mut()
            .enumerate()
            .for_each(|(p, out)| {
                let spin = transfer::strain_and_spin(&trial.gradient[p]).1;
                let g = transfer::rotate_stress_derivative(&particles.stress[p], spin);
                let cg = mat4_mul_vec(&compliances[particles.material[p] as usize], &g);
                *out = mat4_mul_vec(&trial.tangent[p], &cg);
            });
    } else {
        trial.spin_sensitivity.clear();
    }
}

/// The lowest index of a point whose update has failed so far in one
/// evaluation, shared by its threads. A failed update rejects the whole
/// increment, and only the lowest failing index is reported, so a point above
/// a known failure need not be updated: every point below the final lowest
/// failure is still updated, and the reported failure is the one a full
/// evaluation finds, whatever the thread count. Its cost is one relaxed
/// load per point; it saves the updates of a rejected line-search
/// candidate after its first failure (with one thread, all of them).
struct FirstFailure(AtomicUsize);

impl Default for FirstFailure {
    fn default() -> Self {
        Self(AtomicUsize::new(usize::MAX))
    }
}

impl FirstFailure {
    /// Whether a point with a lower index than `p` has failed already.
    fn decided_before(&self, p: usize) -> bool {
        self.0.load(Ordering::Relaxed) < p
    }

    /// Point `p`'s update failed.
    fn record(&self, p: usize) {
        self.0.fetch_min(p, Ordering::Relaxed);
    }
}

/// Points of one run of [`evaluate`]: their gradients and rotated stresses
/// are formed in one pass, then their constitutive updates.
const POINTS_PER_RUN: usize = 32;

/// What the parallel stress-update loop of [`evaluate_stresses`] did, summed
/// over the points, and its first failure.
#[derive(Default)]
#[must_use = "the stress update may have failed: call `counted`"]
pub struct UpdateTally {
    /// Stress updates (every material).
    updates: u64,
    /// Updates of a material that can yield.
    yield_checks: u64,
    /// Updates that returned to the yield surface.
    return_mappings: u64,
    /// The lowest-index point whose update failed.
    failure: Option<(usize, ConstitutiveError)>,
}

impl UpdateTally {
    /// Count the updates, yield checks and return mappings in `profile`
    /// (those of a failed evaluation too: the work was done), then the
    /// lowest-index failing point, if any.
    pub fn counted(self, profile: &Profile) -> Result<(), (usize, ConstitutiveError)> {
        profile.count(Work::StressUpdates, self.updates);
        profile.count(Work::YieldChecks, self.yield_checks);
        profile.count(Work::ReturnMappings, self.return_mappings);
        match self.failure {
            Some(first) => Err(first),
            None => Ok(()),
        }
    }

    /// Record a failure at point `p`, keeping the lowest index.
    fn fail(&mut self, p: usize, error: ConstitutiveError) {
        if self.failure.as_ref().is_none_or(|(q, _)| p < *q) {
            self.failure = Some((p, error));
        }
    }

    /// The tally of two disjoint sets of points.
    fn merge(mut self, other: Self) -> Self {
        self.updates += other.updates;
        self.yield_checks += other.yield_checks;
        self.return_mappings += other.return_mappings;
        if let Some((p, error)) = other.failure {
            self.fail(p, error);
        }
        self
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Scene;

    const BIAXIAL: &str = include_str!("../../../validation/biaxial/local_h300.toml");

    /// A nodal increment with non-finite values at two nodes, one low and one
    /// high in the node order, fails the updates of the points they reach.
    /// The evaluation reports the lowest such point (found here from the
    /// points' gradients alone) on one thread and on two; on one thread it
    /// updates no point after it ([`FirstFailure`]).
    #[test]
    fn the_lowest_failing_point_is_reported_and_later_points_are_skipped() {
        let scene = Scene::from_str_with_overrides(BIAXIAL, "biaxial", &[]).unwrap();
        let model = Model::new(&scene).unwrap();
        let setup = StepSetup::new(&model).unwrap();
        let nodes = model.grid.node_count();
        let mut du: Vec<[f64; 2]> = (0..nodes).map(|i| [1e-7 * (i % 7) as f64, -1e-6]).collect();
        let active = &setup.bins.active_nodes;
        let (low, high) = (
            active[active.len() / 3] as usize,
            active[2 * active.len() / 3] as usize,
        );
        du[low] = [f64::NAN, 0.0];
        du[high] = [0.0, f64::INFINITY];
        let reached: Vec<usize> = (0..model.state.particles.len())
            .filter(|&p| {
                let l = transfer::gradient(&setup.shapes[p], &du);
                l.iter().any(|x| !x.is_finite())
            })
            .collect();
        assert!(reached.len() >= 2, "both nodes reach points: {reached:?}");
        for threads in [1, 2] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            let profile = Profile::default();
            let mut trial = TrialStresses::default();
            let tally =
                pool.install(|| evaluate_stresses(&model, &setup, &du, None, false, &mut trial));
            let outcome = tally.counted(&profile);
            let (p, _) = outcome.expect_err("non-finite increments fail");
            assert_eq!(p, reached[0], "{threads} threads");
            let updates = profile.work_count(Work::StressUpdates);
            if threads == 1 {
                assert_eq!(updates, reached[0] as u64 + 1);
            } else {
                assert!(updates > reached[0] as u64, "{threads} threads: {updates}");
            }
        }
    }
}
