//! The stresses stage, shared by both integrators: what a converged step's
//! trial stresses become at the material points — the step's energies (M5),
//! the nonlocal variable κ̄(n+1) (theory D35) and the double-mapped stresses
//! (D37–D39).

use rayon::prelude::*;

use super::{NonlocalStep, StepSetup, TrialStresses};
use crate::constitutive::{PointState, Voigt};
use crate::dofs::DofMap;
use crate::error::StepError;
use crate::metrics::work_and_dissipation_density;
use crate::model::Model;
use crate::profile::{Profile, Stage, Work};
use crate::scene::DoubleMapping;
use crate::smoothing::{double_map, Equilibrium, MappingFrame};

/// Stresses, states and energies of a converged step, ready to commit.
#[derive(Default)]
pub struct ConvergedStresses {
    /// σ(n+1) after double mapping, kPa.
    pub stress: Vec<Voigt>,
    /// State with κ̄(n+1).
    pub state: Vec<PointState>,
    /// Work of the stresses on the step's strain increments, kJ/m.
    pub internal_work: f64,
    /// Plastic dissipation of the step (theory D43), kJ/m.
    pub dissipation: f64,
    /// Internal work of each point, kJ/m (buffer of [`step_energies`]).
    point_work: Vec<f64>,
    /// Dissipation of each point, kJ/m (buffer of [`step_energies`]).
    point_dissipation: Vec<f64>,
}

/// The converged step's stresses and states to commit (times its nonlocal
/// and double-mapping parts under their own stages, and counts the
/// double-mapping passes).
pub fn converged_stresses(
    model: &Model,
    setup: &StepSetup,
    trial: &TrialStresses,
    nonlocal: Option<&mut NonlocalStep>,
    profile: &Profile,
) -> Result<ConvergedStresses, StepError> {
    let mut converged = ConvergedStresses {
        stress: trial.stress.clone(),
        state: trial.state.clone(),
        ..ConvergedStresses::default()
    };
    converge(model, setup, trial, nonlocal, profile, &mut converged)?;
    Ok(converged)
}

/// [`converged_stresses`] that takes the trial stresses and states over
/// instead of copying them: `trial.stress` and `trial.state` are swapped
/// with the arrays of `converged` (a step that reuses its arrays allocates
/// none; the trial's other fields are kept).
pub fn converged_stresses_taking(
    model: &Model,
    setup: &StepSetup,
    trial: &mut TrialStresses,
    nonlocal: Option<&mut NonlocalStep>,
    profile: &Profile,
    converged: &mut ConvergedStresses,
) -> Result<(), StepError> {
    std::mem::swap(&mut trial.stress, &mut converged.stress);
    std::mem::swap(&mut trial.state, &mut converged.state);
    converge(model, setup, trial, nonlocal, profile, converged)
}

/// The converged step from `converged`'s stresses and states, which hold
/// the trial ones (the trial's own may not): the energies, κ̄(n+1) and the
/// double mapping.
fn converge(
    model: &Model,
    setup: &StepSetup,
    trial: &TrialStresses,
    nonlocal: Option<&mut NonlocalStep>,
    profile: &Profile,
    converged: &mut ConvergedStresses,
) -> Result<(), StepError> {
    let ConvergedStresses {
        stress,
        state,
        internal_work,
        dissipation,
        point_work,
        point_dissipation,
    } = converged;
    (*internal_work, *dissipation) =
        step_energies(model, trial, stress, (point_work, point_dissipation));
    let kappa_bar = match nonlocal {
        Some(nl) => Some(profile.time(Stage::Nonlocal, || {
            nl.committed(
                &model.state.particles,
                |p| state[p].plastic_strain_eq,
                profile,
            )
        })?),
        None => None,
    };
    if let Some(kappa_bar) = &kappa_bar {
        for (s, k) in state.iter_mut().zip(kappa_bar) {
            s.plastic_strain_eq_nonlocal = *k;
        }
    }
    let mode = model.double_mapping();
    if mode != DoubleMapping::Off {
        let restored = profile.time(Stage::DoubleMapping, || {
            smooth(
                model,
                setup,
                trial,
                mode,
                state,
                kappa_bar.as_deref(),
                stress,
            )
        })?;
        profile.count(Work::SmoothingPasses, 1);
        profile.count(Work::ForceRestorations, u64::from(restored));
    }
    Ok(())
}

/// Double mapping of the step's stresses (theory D37–D39), with the
/// force-restoring correction when the scene asks for it; returns whether
/// the forces were restored.
fn smooth(
    model: &Model,
    setup: &StepSetup,
    trial: &TrialStresses,
    mode: DoubleMapping,
    state: &[PointState],
    kappa_bar: Option<&[f64]>,
    stress: &mut [Voigt],
) -> Result<bool, StepError> {
    let frame = MappingFrame {
        grid: &model.grid,
        bins: &setup.bins,
        shapes: &setup.shapes,
        mass: &model.state.particles.mass,
    };
    let dofs = model
        .settings
        .smoothing
        .restore_forces
        .then(|| DofMap::new(&setup.bins, &model.constraints));
    let equilibrium = dofs.as_ref().map(|dofs| Equilibrium {
        volume: &model.state.particles.volume,
        dofs,
    });
    let restored = equilibrium.is_some();
    double_map(
        mode,
        &frame,
        equilibrium,
        &trial.rotated,
        stress,
        &model.materials,
        &model.state.particles.material,
        state,
        kappa_bar,
    )
    .map_err(StepError::DoubleMapping)?;
    Ok(restored)
}

/// Energies of the converged step (M5), kJ per metre run, from the
/// constitutive stresses before double mapping (Voigt dot products,
/// engineering shear), with one strain increment Δε per point (the one its
/// stress update was given, B-bar included):
/// - internal work Σ_p V_p(n) · w_p, w_p the work of the stress on Δε_p
///   integrated as the return mapping integrates it
///   ([`crate::metrics::work_and_dissipation_density`]: the elastic part
///   by the trapezoidal rule, the plastic part at σ(n+1)); for a point of
///   an elastic material, ½(σ_p(n+1) + σ_p^R(n)) · Δε_p. Per step it is
///   the change of Σ_p V_p(n) ½ σ_p·Cσ_p plus the dissipation, whence
///   W_int = stored elastic energy + D up to the change of the points'
///   volumes;
/// - plastic dissipation (theory D43 with σ(n+1), see
///   [`crate::metrics::dissipation_increment`]) Σ_p V_p(n) · σ_p(n+1) · Δε^p_p
///   with Δε^p = Δε − C(σ(n+1) − σ^R(n)); elastic materials contribute
///   nothing, and a sum that is not finite is NaN.
///
/// The constitutive stresses are `stress` (the trial's). The points' terms
/// are formed in parallel into `point_work` and `point_dissipation` and
/// summed in point order (the same sums whatever the number of threads).
fn step_energies(
    model: &Model,
    trial: &TrialStresses,
    stress: &[Voigt],
    (point_work, point_dissipation): (&mut Vec<f64>, &mut Vec<f64>),
) -> (f64, f64) {
    let p = &model.state.particles;
    let all_elastic = model.materials.iter().all(|m| m.is_elastic());
    let point_energies = |i: usize| {
        let strain = trial.strain_increment(i);
        let (now, before) = (&stress[i], &trial.rotated[i]);
        let material = p.material[i] as usize;
        if all_elastic || model.materials[material].is_elastic() {
            let work: f64 = (0..4).map(|k| 0.5 * (now[k] + before[k]) * strain[k]).sum();
            return (p.volume[i] * work, 0.0);
        }
        let compliance = &model.compliances[material];
        let (work, dissipation) = work_and_dissipation_density(compliance, now, before, &strain);
        (p.volume[i] * work, p.volume[i] * dissipation)
    };
    (0..p.len())
        .into_par_iter()
        .with_min_len(1024)
        .map(point_energies)
        .unzip_into_vecs(point_work, point_dissipation);
    let internal_work = point_work.iter().sum();
    if all_elastic {
        return (internal_work, 0.0);
    }
    let dissipation = point_dissipation.iter().fold(0.0, |sum, d| sum + d);
    match dissipation.is_finite() {
        true => (internal_work, dissipation),
        false => (internal_work, f64::NAN),
    }
}
