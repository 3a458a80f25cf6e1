//! Material points as a structure of arrays (theory §2).
//!
//! Every array has one entry per material point (MP). Quantities not needed
//! by a scene (velocity and acceleration in a quasi-static run) stay zero.

use crate::constitutive::{PointState, Voigt};

/// All material points of a run.
#[derive(Clone, Debug, Default, serde::Serialize, serde::Deserialize)]
pub struct Particles {
    /// Current position x_p, m.
    pub position: Vec<[f64; 2]>,
    /// Initial position x_p(0), m (displacement output).
    pub position0: Vec<[f64; 2]>,
    /// Mass m_p, t per metre run.
    pub mass: Vec<f64>,
    /// Current volume V_p (area × 1 m), m³.
    pub volume: Vec<f64>,
    /// Deformation gradient F_p (in-plane, row-major `[Fxx, Fxy, Fyx, Fyy]`, F_zz = 1).
    pub def_grad: Vec<[f64; 4]>,
    /// Cauchy stress σ_p (tension-positive Voigt), kPa.
    pub stress: Vec<Voigt>,
    /// Accumulated small-strain increments Σ Δε (Voigt, engineering shear).
    pub strain: Vec<Voigt>,
    /// Velocity v_p, m/s (dynamic runs).
    pub velocity: Vec<[f64; 2]>,
    /// Acceleration a_p, m/s² (implicit dynamic runs).
    pub acceleration: Vec<[f64; 2]>,
    /// Force per mass q_p = Σ_i N_ip [M⁻¹(f_ext − f_int)]_i of the last
    /// step's end, m/s² (generalised-α runs; zero at the start, i.e. the
    /// body starts in balance, as a_p = 0 assumes).
    pub force_per_mass: Vec<[f64; 2]>,
    /// Constitutive state variables.
    pub state: Vec<PointState>,
    /// Index of the material in the run's material table.
    pub material: Vec<u16>,
    /// Index of the body (scene `[[body]]` entry) the point was seeded from.
    pub body: Vec<u16>,
}

impl Particles {
    /// Number of material points.
    pub fn len(&self) -> usize {
        self.position.len()
    }

    /// True when there are no material points.
    pub fn is_empty(&self) -> bool {
        self.position.is_empty()
    }

    /// Append one material point at rest with the given mass, volume, initial stress and material.
    pub fn push(
        &mut self,
        position: [f64; 2],
        mass: f64,
        volume: f64,
        stress: Voigt,
        material: u16,
        body: u16,
    ) {
        self.position.push(position);
        self.position0.push(position);
        self.mass.push(mass);
        self.volume.push(volume);
        self.def_grad.push([1.0, 0.0, 0.0, 1.0]);
        self.stress.push(stress);
        self.strain.push([0.0; 4]);
        self.velocity.push([0.0; 2]);
        self.acceleration.push([0.0; 2]);
        self.force_per_mass.push([0.0; 2]);
        self.state.push(PointState::default());
        self.material.push(material);
        self.body.push(body);
    }

    /// Keep the points with `keep[p]` true (all per-point arrays, order preserved).
    pub fn retain(&mut self, keep: &[bool]) {
        fn filter<T: Copy>(values: &mut Vec<T>, keep: &[bool]) {
            let mut flags = keep.iter();
            values.retain(|_| *flags.next().unwrap_or(&true));
        }
        filter(&mut self.position, keep);
        filter(&mut self.position0, keep);
        filter(&mut self.mass, keep);
        filter(&mut self.volume, keep);
        filter(&mut self.def_grad, keep);
        filter(&mut self.stress, keep);
        filter(&mut self.strain, keep);
        filter(&mut self.velocity, keep);
        filter(&mut self.acceleration, keep);
        filter(&mut self.force_per_mass, keep);
        filter(&mut self.state, keep);
        filter(&mut self.material, keep);
        filter(&mut self.body, keep);
    }

    /// Displacement x_p − x_p(0) of point `p`, m.
    pub fn displacement(&self, p: usize) -> [f64; 2] {
        [
            self.position[p][0] - self.position0[p][0],
            self.position[p][1] - self.position0[p][1],
        ]
    }

    /// Total mass Σ m_p.
    pub fn total_mass(&self) -> f64 {
        self.mass.iter().sum()
    }
}
