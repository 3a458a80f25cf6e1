//! An estimate of a run's time from the scene's keys, before anything big is
//! allocated (`mpm-geo check` prints it; `mpm-geo run` prints it at the start
//! and warns when it passes [`LONG_RUN_SECONDS`]): the step count of
//! [`Scene::estimate_resources`] times the cost of one step.
//!
//! The cost of a step comes from the size (material points, grid nodes,
//! unknowns of the implicit tangent, nonlocal neighbour pairs) and from how
//! plastic each step is: the *load-step ratio* r, the elastic stress that one
//! step's prescribed strain increment would add (E · Δε, Δε from the rigid
//! bodies' and prescribed lines' rates) over the material's strength (HMC
//! `c_ini`, von Mises `c`). A scene with r ≫ 1 drives every point far past
//! its yield surface in one step: the return mapping sub-steps (up to 64
//! sub-steps, theory §5.6) and Newton needs many iterations and halvings.
//! That is why the biaxial test with E = 10¹² kPa (r ≈ 10⁶) takes tens of
//! seconds a step on 540 points. Load-controlled scenes (gravity, pressures)
//! have r = 0: their plasticity is not counted beyond the typical Newton
//! iterations.
//!
//! The cost of one step, with the constants below:
//!
//! ```text
//! implicit: newton_iterations(r) · (points · STRESS_UPDATE · stress_update_slowdown(r)
//!                                   + LINEAR_SOLVE · n^LINEAR_EXPONENT
//!                                   + pairs · NONLOCAL_PAIR)
//!           + points · STEP_PER_POINT + STEP_OVERHEAD
//! explicit: points · EXPLICIT_PER_POINT · stress_update_slowdown(r)
//!           + nodes · STEP_PER_NODE + pairs · NONLOCAL_PAIR + STEP_OVERHEAD
//! ```
//!
//! The point costs are those of points that yield when a material in use
//! can yield, so a run that stays elastic (the first steps of most scenes:
//! one Newton iteration a step) takes less; an explicit run whose stable
//! step shrinks as it goes (the cut's slide) takes more steps.
//!
//! Calibration (2026-11-28, on this 2-core machine while other builds ran,
//! load average 2–14): each run timed with
//! `/usr/bin/time -f "%e %U %S" mpm-geo run validation/SCENE --set … --quiet`,
//! the constants fitted to its CPU time (user + system, which the load
//! stretches less than the wall time), the stage shares from the profile in
//! its `run.json`:
//! - linear algebra per Newton iteration (assembly, factorisation, solve):
//!   0.43 ms at n = 318 unknowns (biaxial h = 1/300), 1.3 ms at 830, 5.4 ms
//!   at 1,922 (cut h = 0.1), 11–13 ms at 3,157–3,755 (biaxial h = 1/1000,
//!   footing h = 0.25), 18.6 ms at 4,802 (cut h = 1/16), 137 ms at 22,990
//!   (footing h = 0.1): 1.8e-7 s · n^1.35 within 20 %;
//! - stress update per point and Newton iteration: 2.0–2.2 µs on the
//!   biaxial test once every point yields, 0.3 µs while elastic (the
//!   footing's first steps); with E raised on `biaxial/nonlocal_h300.toml`
//!   (r = 2, 200, 2·10⁴, 10⁶) 4, 20, 58 and 222 µs: `1 + r^0.35` times
//!   2 µs, at most 128 times; the footing's (only the zone under it yields)
//!   4, 13 and 34 µs at r = 16, 1,600 and 1.6·10⁵;
//! - Newton iterations per step: 2.6–7.7 over the scenes as written
//!   (r ≤ 0.2); 8, 12, 22 and 132 (with 8 halvings in 4 steps) on the
//!   biaxial test at r = 2, 200, 2·10⁴ and 10⁶; 14 and 35 on the footing at
//!   r = 16 and 1,600, whose first step at r = 1.6·10⁵ failed after 4
//!   halvings of 60 iterations: `5 · (1 + 0.45 r^0.3)`, at most the
//!   `max_iterations` × (1 + `max_halvings`) of a step that fails;
//! - nonlocal averaging: 0.3–0.6 ns per neighbour pair and Newton
//!   iteration once points yield (cut, footing, biaxial), 0.7 ns per pair
//!   and explicit step (cut to 0.3 s);
//! - explicit steps: 0.2 ms on the biaxial test's 540 points, 2.0–2.3 ms
//!   on its 6,000 points (h = 1/1000), 3.8 ms on the cut's 9,216 points and
//!   83k nodes, 13 ms on the cut's 3,600 points at h = 0.1 in its slide,
//!   4.3 ms on the elastic 40k block: 600 ns a point (100 ns elastic), 30 ns
//!   a node.
//!
//! Estimate against CPU time (`docs/guide.md` §7 has the table): whole or
//! plastic runs 0.27–2.5 times (the biaxial test as written 1.2, the footing
//! at h = 0.25 m 1.3, the cut 300 steps 1.2, its explicit slide to 0.3 s
//! 0.27, the issue's E = 10¹² kPa 1.3); runs cut short while still elastic
//! up to 17 times. With two idle cores the wall time is 0.6–0.8 of the CPU
//! time; on a shared machine it is longer.

use std::fmt;

use super::schema::*;
use super::ResourceEstimate;

/// Runs estimated to take longer than this, s, are warned about.
pub const LONG_RUN_SECONDS: f64 = 3600.0;
/// Stress update of one point in one Newton iteration, s: a material that
/// yields (once the point yields), an elastic one.
const STRESS_UPDATE: [f64; 2] = [2e-6, 3e-7];
/// Linear algebra of one Newton iteration: this × n^[`LINEAR_EXPONENT`], s.
const LINEAR_SOLVE: f64 = 1.8e-7;
/// Exponent of the linear algebra's cost in the unknowns.
const LINEAR_EXPONENT: f64 = 1.35;
/// Nonlocal averaging per neighbour pair, Newton iteration or explicit step, s.
const NONLOCAL_PAIR: f64 = 5e-10;
/// The per-point work of an implicit step outside Newton (transfers, commit), s.
const STEP_PER_POINT: f64 = 3e-7;
/// The per-point work of an explicit step, s: a material that yields, an
/// elastic one.
const EXPLICIT_PER_POINT: [f64; 2] = [6e-7, 1e-7];
/// The per-node work of an explicit step, s.
const STEP_PER_NODE: f64 = 3e-8;
/// Fixed cost of a step, s.
const STEP_OVERHEAD: f64 = 1e-5;
/// Newton iterations of a step at r = 0.
const BASE_ITERATIONS: f64 = 5.0;
/// Largest slowdown of the stress update: the 1 + 2 + … + 64 sub-steps of
/// the finest sub-stepping level.
const MAX_SLOWDOWN: f64 = 128.0;

/// A run-time estimate.
#[derive(Clone, Debug, PartialEq)]
pub struct RunTimeEstimate {
    /// Estimated run time, s.
    pub seconds: f64,
    /// Steps the run will take (as [`ResourceEstimate::steps`]).
    pub steps: f64,
    /// Estimated time of one step, s.
    pub seconds_per_step: f64,
    /// Newton iterations per step (implicit runs).
    pub newton_iterations: Option<f64>,
    /// The load-step ratio r: one step's elastic stress increment over the
    /// strength (0 without prescribed motion or a yielding material).
    pub load_step_ratio: f64,
}

impl RunTimeEstimate {
    /// Whether the run is estimated to take longer than [`LONG_RUN_SECONDS`].
    pub fn is_long(&self) -> bool {
        self.seconds > LONG_RUN_SECONDS
    }
}

impl RunTimeEstimate {
    /// The warning of a run estimated to take longer than
    /// [`LONG_RUN_SECONDS`], naming what drives it; `None` for a shorter one.
    pub fn long_run_warning(&self) -> Option<String> {
        if !self.is_long() {
            return None;
        }
        let why = if self.load_step_ratio > 100.0 {
            format!(
                "one step's prescribed strain adds {:.1e} times the material's strength elastically (E against c_ini or c, with the rigid bodies' speed and the step), so every step is far into the plastic range; check E, the strength and the step",
                self.load_step_ratio
            )
        } else {
            "check the step count (scene.steps, or end_time over the explicit step) and the mesh (grid.cell_size)".to_string()
        };
        Some(format!(
            "the run is estimated to take {}, more than {}: {why}",
            human_duration(self.seconds),
            human_duration(LONG_RUN_SECONDS)
        ))
    }
}

impl fmt::Display for RunTimeEstimate {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "estimated run time {} (a rough estimate from {:.3e} steps of ~{}",
            human_duration(self.seconds),
            self.steps,
            human_duration(self.seconds_per_step)
        )?;
        if let Some(iterations) = self.newton_iterations {
            write!(f, ", {iterations:.0} Newton iterations a step")?;
        }
        if self.load_step_ratio > 1.0 {
            write!(
                f,
                "; one step's elastic stress increment is {:.1e} times the strength, so the stress updates sub-step",
                self.load_step_ratio
            )?;
        }
        write!(f, ")")
    }
}

/// `1.5 h`, `12 min`, `3.4 s`, `250 µs`-style text of a duration in seconds.
pub fn human_duration(seconds: f64) -> String {
    if !seconds.is_finite() {
        return format!("{seconds} s");
    }
    let units = [(86400.0, "d"), (3600.0, "h"), (60.0, "min"), (1.0, "s")];
    for (scale, unit) in units {
        if seconds >= scale {
            return format!("{:.2} {unit}", seconds / scale);
        }
    }
    if seconds >= 1e-3 {
        format!("{:.2} ms", seconds * 1e3)
    } else {
        format!("{:.0} µs", seconds * 1e6)
    }
}

/// How much slower a point's stress update is at load-step ratio `r` than
/// at a small step: `1 + r^0.35`, at most [`MAX_SLOWDOWN`].
fn stress_update_slowdown(r: f64) -> f64 {
    (1.0 + r.powf(0.35)).min(MAX_SLOWDOWN)
}

/// Newton iterations of a step at load-step ratio `r`: `5 (1 + 0.45 r^0.3)`,
/// at most `most` (the iterations of a step that fails at every halving).
fn newton_iterations(r: f64, most: f64) -> f64 {
    (BASE_ITERATIONS * (1.0 + 0.45 * r.powf(0.3))).min(most)
}

impl Scene {
    /// Estimate the run's time from its keys (a validated scene; nothing is
    /// allocated); see the module notes for the model and its calibration.
    pub fn estimate_run_time(&self) -> RunTimeEstimate {
        self.run_time_of(&self.estimate_resources())
    }

    /// [`Self::estimate_run_time`] from the scene's resource estimate.
    pub fn run_time_of(&self, size: &ResourceEstimate) -> RunTimeEstimate {
        let r = self.load_step_ratio(size.steps);
        let slowdown = stress_update_slowdown(r);
        // the costs of a material that yields, else of an elastic one
        let kind = usize::from(self.yielding_materials().is_empty());
        let nonlocal = size.neighbour_pairs.unwrap_or(0.0) * NONLOCAL_PAIR;
        let (seconds_per_step, newton) = match size.unknowns {
            Some(unknowns) => {
                let most = (self.max_iterations() * (1 + self.solver.max_halvings)) as f64;
                let iterations = newton_iterations(r, most);
                let iteration = size.points * STRESS_UPDATE[kind] * slowdown
                    + LINEAR_SOLVE * unknowns.powf(LINEAR_EXPONENT)
                    + nonlocal;
                let step = iterations * iteration + size.points * STEP_PER_POINT + STEP_OVERHEAD;
                (step, Some(iterations))
            }
            None => (
                size.points * EXPLICIT_PER_POINT[kind] * slowdown
                    + size.nodes * STEP_PER_NODE
                    + nonlocal
                    + STEP_OVERHEAD,
                None,
            ),
        };
        RunTimeEstimate {
            seconds: size.steps * seconds_per_step,
            steps: size.steps,
            seconds_per_step,
            newton_iterations: newton,
            load_step_ratio: r,
        }
    }

    /// The load-step ratio r of a run of `steps` steps: the largest E · Δε /
    /// strength over the yielding materials in use, Δε the strain one step
    /// prescribes.
    fn load_step_ratio(&self, steps: f64) -> f64 {
        let strain = self.strain_per_step(steps);
        self.yielding_materials()
            .iter()
            .map(|(m, strength)| m.youngs_modulus() * strain / strength)
            .filter(|r| r.is_finite())
            .fold(0.0, f64::max)
    }

    /// The materials in use that yield, with their strengths.
    fn yielding_materials(&self) -> Vec<(&MaterialSpec, f64)> {
        let used: Vec<&String> = self.body.iter().map(|b| &b.material).collect();
        self.materials
            .iter()
            .filter(|(name, _)| used.contains(name))
            .filter_map(|(_, m)| Some((m, strength(m)?)))
            .collect()
    }

    /// The strain one step prescribes: the largest rate of a rigid body or a
    /// prescribed line times the step, over the bodies' extent along it,
    /// plus a prescribed line's rate gradient times the step.
    fn strain_per_step(&self, steps: f64) -> f64 {
        let dt = if steps > 0.0 {
            self.scene.end_time_or_steps() / steps
        } else {
            0.0
        };
        let extent = self.bodies_extent();
        let along = |v: [f64; 2]| {
            let c = usize::from(v[1].abs() > v[0].abs());
            v[c].abs() / extent[c]
        };
        let rigid = self.bc.rigid.iter().map(|r| along(r.velocity));
        let prescribed = self.bc.prescribed.iter().map(|p| {
            let c = match p.dof {
                Component::X => 0,
                Component::Y => 1,
            };
            p.rate.abs() / extent[c] + p.gradient[0].abs().max(p.gradient[1].abs())
        });
        let rate = rigid.chain(prescribed).fold(0.0, f64::max);
        let strain = rate * dt;
        if strain.is_finite() {
            strain
        } else {
            0.0
        }
    }

    /// Width and height of the bounding box of every body, m.
    fn bodies_extent(&self) -> [f64; 2] {
        let mut b = [[f64::INFINITY; 2], [f64::NEG_INFINITY; 2]];
        for body in &self.body {
            let [lo, hi] = body.bounds();
            for c in 0..2 {
                b[0][c] = b[0][c].min(lo[c]);
                b[1][c] = b[1][c].max(hi[c]);
            }
        }
        [b[1][0] - b[0][0], b[1][1] - b[0][1]]
    }
}

/// The strength of a material that yields: HMC `c_ini` (else its tensile
/// strength), von Mises `c`; `None` for an elastic one or no positive strength.
fn strength(m: &MaterialSpec) -> Option<f64> {
    let s = match m {
        MaterialSpec::LinearElastic(_) => return None,
        MaterialSpec::Hmc(h) => {
            if h.cohesion_ini > 0.0 {
                h.cohesion_ini
            } else {
                h.tensile_strength_ini
            }
        }
        MaterialSpec::VonMises(v) => v.undrained_strength,
    };
    (s > 0.0).then_some(s)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Durations read in the unit that fits them.
    #[test]
    fn durations_are_written_in_fitting_units() {
        assert_eq!(human_duration(4572.0), "1.27 h");
        assert_eq!(human_duration(90.0), "1.50 min");
        assert_eq!(human_duration(2.53), "2.53 s");
        assert_eq!(human_duration(0.0112), "11.20 ms");
        assert_eq!(human_duration(2.5e-5), "25 µs");
    }

    /// The stiffness terms are 1 and the base iterations at r = 0, grow
    /// with r and stop at their bounds.
    #[test]
    fn stiffness_terms_grow_to_their_bounds() {
        assert_eq!(stress_update_slowdown(0.0), 1.0);
        assert_eq!(newton_iterations(0.0, 60.0), BASE_ITERATIONS);
        assert!(stress_update_slowdown(200.0) > stress_update_slowdown(2.0));
        assert_eq!(stress_update_slowdown(1e12), MAX_SLOWDOWN);
        assert_eq!(newton_iterations(1e12, 300.0), 300.0);
    }
}
