//! Boundary conditions and loads on the boundary (DESIGN §3 "Linear system",
//! §8.0): grid-line Dirichlet conditions, prescribed nodal values, follower
//! pressure through traction points, and rigid rough platens/footings through
//! penalty-tied ("driven") material points.

use crate::grid::{Grid, ShapeAt};
use crate::particles::Particles;
use crate::scene::{GridLine, Scene, Side};
use crate::transfer::{self, ParticleBins, NONE};

/// How one grid degree of freedom (2·node + component) is constrained.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum DofConstraint {
    /// Unknown of the nodal system.
    Free,
    /// Homogeneous Dirichlet condition (roller / fixity).
    Fixed,
    /// Prescribed displacement u(t, x) = t · (rate + gradient · x).
    Prescribed {
        /// Rate, m per unit time.
        rate: f64,
        /// Gradient of the rate, 1/time.
        gradient: [f64; 2],
    },
}

/// Nodes of the grid lying on `line`.
pub fn nodes_on_line(grid: &Grid, line: GridLine) -> Vec<usize> {
    let index = ((line.value - grid.origin[line.axis]) / grid.cell_size).round() as usize;
    let (nx, ny) = (grid.cells[0] + 1, grid.cells[1] + 1);
    if line.axis == 0 {
        (0..ny).map(|j| j * nx + index).collect()
    } else {
        (0..nx).map(|i| index * nx + i).collect()
    }
}

/// Dirichlet constraints of every grid dof, built once per run.
#[derive(Clone, Debug)]
pub struct Constraints {
    /// One entry per grid dof `2·node + component`.
    pub dof: Vec<DofConstraint>,
}

impl Constraints {
    /// Build from the scene's `[[bc.fixed]]` and `[[bc.prescribed]]` (fixed wins where both apply).
    pub fn from_scene(scene: &Scene, grid: &Grid) -> Self {
        let mut dof = vec![DofConstraint::Free; 2 * grid.node_count()];
        for p in &scene.bc.prescribed {
            if let Ok(line) = GridLine::parse(&p.line) {
                for n in nodes_on_line(grid, line) {
                    dof[2 * n + p.dof.index()] = DofConstraint::Prescribed {
                        rate: p.rate,
                        gradient: p.gradient,
                    };
                }
            }
        }
        for f in &scene.bc.fixed {
            if let Ok(line) = GridLine::parse(&f.line) {
                for n in nodes_on_line(grid, line) {
                    for c in &f.dofs {
                        dof[2 * n + c.index()] = DofConstraint::Fixed;
                    }
                }
            }
        }
        Self { dof }
    }

    /// Prescribed displacement of grid dof `d` at time `t` (0 for free and fixed dofs).
    pub fn prescribed_value(&self, grid: &Grid, d: usize, t: f64) -> f64 {
        match self.dof[d] {
            DofConstraint::Prescribed { rate, gradient } => {
                let x = grid.node_position(d / 2);
                t * (rate + gradient[0] * x[0] + gradient[1] * x[1])
            }
            _ => 0.0,
        }
    }
}

/// Numbering of the free dofs of the active nodes for one step.
#[derive(Clone, Debug)]
pub struct DofMap {
    /// For every grid dof, its index in the system, or [`NONE`].
    pub index: Vec<u32>,
    /// Number of unknowns.
    pub n_free: usize,
}

impl DofMap {
    /// Number the free dofs of active nodes in grid-dof order (deterministic).
    pub fn new(bins: &ParticleBins, constraints: &Constraints) -> Self {
        let mut index = vec![NONE; constraints.dof.len()];
        let mut n_free = 0;
        for (node, &active) in bins.node_active.iter().enumerate() {
            if !active {
                continue;
            }
            for c in 0..2 {
                let d = 2 * node + c;
                if constraints.dof[d] == DofConstraint::Free {
                    index[d] = n_free as u32;
                    n_free += 1;
                }
            }
        }
        Self { index, n_free }
    }

    /// The system indices of every element's dofs ([`NONE`] where constrained
    /// or outside the grid), in the order of `transfer::system_blocks`: each
    /// active cell's node patch (row-major), then each GIMP-reached cell's four
    /// nodes (row-major).
    pub fn element_dofs(&self, grid: &Grid, bins: &ParticleBins) -> Vec<Vec<u32>> {
        let dofs_of = |nodes: &[Option<u32>]| -> Vec<u32> {
            nodes
                .iter()
                .flat_map(|node| {
                    (0..2).map(move |k| node.map_or(NONE, |n| self.index[2 * n as usize + k]))
                })
                .collect()
        };
        let patches = bins.active_cells.iter().map(|&c| {
            let (ci, cj) = grid.cell_ij(c as usize);
            dofs_of(&grid.patch_nodes(ci, cj))
        });
        let reached = bins.reached_cells.iter().map(|&c| {
            let (ci, cj) = grid.cell_ij(c as usize);
            let [ll, lr, ur, ul] = grid.cell_nodes(ci, cj);
            dofs_of(&[Some(ll), Some(lr), Some(ul), Some(ur)])
        });
        patches.chain(reached).collect()
    }
}

/// Massless boundary points carrying a follower pressure (DESIGN §8.0).
#[derive(Clone, Debug, Default)]
pub struct TractionPoints {
    /// Current position x_s, m.
    pub position: Vec<[f64; 2]>,
    /// Current edge tangent t_s (length = tributary length ℓ_s), m.
    pub tangent: Vec<[f64; 2]>,
    /// Pressure P, kPa (positive pushes into the body).
    pub pressure: Vec<f64>,
}

impl TractionPoints {
    /// Place two Gauss points per edge segment on every loaded body side. A side
    /// of length L is split into ⌈L/h⌉ equal segments; each Gauss point carries
    /// half a segment (ℓ_s = L/(2n)). Tangents run counter-clockwise, so the
    /// outward normal is (t_y, −t_x)/|t|.
    pub fn from_scene(scene: &Scene) -> Self {
        let mut tp = TractionPoints::default();
        let h = scene.grid.cell_size;
        let gauss = 0.5 / 3f64.sqrt();
        for spec in &scene.bc.pressure {
            let Some(b) = scene.body_index(spec.body.as_deref()) else {
                continue;
            };
            let Some([lo, hi]) = scene.body[b].rectangle else {
                continue;
            };
            // start and end of the side, counter-clockwise
            let (start, end) = match spec.side {
                Side::Bottom => (lo, [hi[0], lo[1]]),
                Side::Right => ([hi[0], lo[1]], hi),
                Side::Top => (hi, [lo[0], hi[1]]),
                Side::Left => ([lo[0], hi[1]], lo),
            };
            let length = ((end[0] - start[0]).powi(2) + (end[1] - start[1]).powi(2)).sqrt();
            let segments = ((length / h) - 1e-9).ceil().max(1.0) as usize;
            let dir = [(end[0] - start[0]) / length, (end[1] - start[1]) / length];
            let seg = length / segments as f64;
            for s in 0..segments {
                for g in [0.5 - gauss, 0.5 + gauss] {
                    let d = (s as f64 + g) * seg;
                    tp.position
                        .push([start[0] + d * dir[0], start[1] + d * dir[1]]);
                    tp.tangent.push([0.5 * seg * dir[0], 0.5 * seg * dir[1]]);
                    tp.pressure.push(spec.p);
                }
            }
        }
        tp
    }

    /// Number of traction points.
    pub fn len(&self) -> usize {
        self.position.len()
    }

    /// True when there are none.
    pub fn is_empty(&self) -> bool {
        self.position.is_empty()
    }

    /// Outward unit normal and tributary length of point `s`.
    fn normal_and_length(&self, s: usize) -> ([f64; 2], f64) {
        let t = self.tangent[s];
        let len = (t[0] * t[0] + t[1] * t[1]).sqrt();
        ([t[1] / len, -t[0] / len], len)
    }

    /// Shape functions at each point, in the cell of the body it loads: the cell
    /// containing x_s − 1e−9·h·n_s if it is *filled* (holds at least
    /// `min_points` material points, half the seeding count), else the first
    /// filled cell met going inward along −n_s (up to one cell). When the body's
    /// edge has moved into an empty or nearly empty cell, the shape functions of
    /// the body's cell are thereby extrapolated to x_s: this keeps the traction
    /// in balance with the internal force of the material points (a homogeneous
    /// stress equal to the pressure stays in equilibrium), whereas the far
    /// nodes of a nearly empty cell have almost no stiffness and would be
    /// thrown away by the load. Errs with the first point that left the grid.
    pub fn shapes(
        &self,
        grid: &Grid,
        bins: &ParticleBins,
        min_points: usize,
    ) -> Result<Vec<ShapeAt>, transfer::OutsideGrid> {
        (0..self.len())
            .map(|s| {
                let (n, _) = self.normal_and_length(s);
                let x = self.position[s];
                let outside = transfer::OutsideGrid {
                    particle: s,
                    position: x,
                };
                let probe = |depth: f64| {
                    [
                        x[0] - depth * grid.cell_size * n[0],
                        x[1] - depth * grid.cell_size * n[1],
                    ]
                };
                let own = grid.locate(probe(1e-9)).ok_or(outside)?;
                let filled = |(ci, cj): (usize, usize)| {
                    bins.particles_in(cj * grid.cells[0] + ci).len() >= min_points
                };
                let cell = [1e-9, 0.5, 1.0]
                    .iter()
                    .filter_map(|&d| grid.locate(probe(d)))
                    .find(|&c| filled(c))
                    .unwrap_or(own);
                Ok(grid.shape_in_cell(cell.0, cell.1, x))
            })
            .collect()
    }

    /// Add the nodal forces −P n_s ℓ_s N_i(x_s) into `force` (per grid node), in point order.
    pub fn add_forces(&self, shapes: &[ShapeAt], force: &mut [[f64; 2]]) {
        for (s, shape) in shapes.iter().enumerate() {
            let (n, len) = self.normal_and_length(s);
            let magnitude = self.pressure[s] * len;
            for a in shape.support() {
                let node = shape.nodes[a] as usize;
                force[node][0] -= magnitude * n[0] * shape.n[a];
                force[node][1] -= magnitude * n[1] * shape.n[a];
            }
        }
    }

    /// Move the points with the converged nodal displacement increment and
    /// stretch/rotate their tangents with ΔF(x_s) (follower load).
    pub fn advect(&mut self, shapes: &[ShapeAt], du: &[[f64; 2]]) {
        for (s, shape) in shapes.iter().enumerate() {
            let u = transfer::interpolate(shape, du);
            let l = transfer::gradient(shape, du);
            let t = self.tangent[s];
            self.position[s][0] += u[0];
            self.position[s][1] += u[1];
            self.tangent[s] = [
                t[0] + l[0] * t[0] + l[1] * t[1],
                t[1] + l[2] * t[0] + l[3] * t[1],
            ];
        }
    }
}

/// Material points tied by penalty springs to rigid bodies (DESIGN D40–D41).
#[derive(Clone, Debug, Default)]
pub struct DrivenPoints {
    /// Driven particle indices.
    pub particle: Vec<usize>,
    /// Rigid body index (order of `[[bc.rigid]]`) of each driven particle.
    pub rigid: Vec<usize>,
    /// Penalty stiffness k_p = β_pen E, kN/m per m.
    pub stiffness: Vec<f64>,
    /// Prescribed rigid velocity of each rigid body, m per unit time.
    pub velocity: Vec<[f64; 2]>,
    /// Names of the rigid bodies.
    pub names: Vec<String>,
}

impl DrivenPoints {
    /// Select, for every `[[bc.rigid]]`, the material points of the top row of its
    /// body whose x lies in the footprint (DESIGN §8.0). Returns the index of the
    /// rigid entry that selects no point as an error.
    pub fn from_scene(
        scene: &Scene,
        particles: &Particles,
        penalty_factor: f64,
        youngs_modulus: &[f64],
    ) -> Result<Self, usize> {
        let mut d = DrivenPoints::default();
        let h = scene.grid.cell_size;
        for (r, spec) in scene.bc.rigid.iter().enumerate() {
            let body = scene.body_index(spec.body.as_deref()).unwrap_or(0) as u16;
            let in_footprint = |p: usize| {
                let x = particles.position[p][0];
                particles.body[p] == body && x >= spec.footprint[0] && x <= spec.footprint[1]
            };
            let top = (0..particles.len())
                .filter(|&p| in_footprint(p))
                .map(|p| particles.position[p][1])
                .fold(f64::NEG_INFINITY, f64::max);
            let before = d.particle.len();
            for p in 0..particles.len() {
                if in_footprint(p) && particles.position[p][1] >= top - 0.25 * h {
                    d.particle.push(p);
                    d.rigid.push(r);
                    d.stiffness
                        .push(penalty_factor * youngs_modulus[particles.material[p] as usize]);
                }
            }
            if d.particle.len() == before {
                return Err(r);
            }
            d.velocity.push(spec.velocity);
            d.names.push(spec.name.clone());
        }
        Ok(d)
    }

    /// Number of driven points.
    pub fn len(&self) -> usize {
        self.particle.len()
    }

    /// True when there are none.
    pub fn is_empty(&self) -> bool {
        self.particle.is_empty()
    }

    /// Anchor X̄_p(t) = x_p(0) + ū(t) of driven point `k` (DESIGN D40).
    pub fn anchor(&self, k: usize, particles: &Particles, t: f64) -> [f64; 2] {
        let x0 = particles.position0[self.particle[k]];
        let v = self.velocity[self.rigid[k]];
        [x0[0] + v[0] * t, x0[1] + v[1] * t]
    }

    /// Penalty forces f_i^pen = Σ k_p N_ip (X̄_p(t) − x_p − Σ_j N_jp Δu_j) added into `force`
    /// (DESIGN D40); `du` is the current nodal displacement increment (zeros for explicit).
    pub fn add_forces(
        &self,
        particles: &Particles,
        shapes: &[ShapeAt],
        du: &[[f64; 2]],
        t: f64,
        force: &mut [[f64; 2]],
    ) {
        for k in 0..self.len() {
            let p = self.particle[k];
            let gap = self.gap(k, particles, &shapes[p], du, t);
            let s = &shapes[p];
            for a in s.support() {
                let node = s.nodes[a] as usize;
                force[node][0] += self.stiffness[k] * s.n[a] * gap[0];
                force[node][1] += self.stiffness[k] * s.n[a] * gap[1];
            }
        }
    }

    /// Gap X̄_p(t) − (x_p + Σ_j N_jp Δu_j) of driven point `k`.
    pub fn gap(
        &self,
        k: usize,
        particles: &Particles,
        shape: &ShapeAt,
        du: &[[f64; 2]],
        t: f64,
    ) -> [f64; 2] {
        let p = self.particle[k];
        let anchor = self.anchor(k, particles, t);
        let u = transfer::interpolate(shape, du);
        [
            anchor[0] - particles.position[p][0] - u[0],
            anchor[1] - particles.position[p][1] - u[1],
        ]
    }

    /// Add K_pen = Σ k_p N_p N_pᵀ ⊗ I₂ (DESIGN D41) into the patch blocks of
    /// the active cells (indexed by cell slot, `dofs` per block row).
    pub fn add_stiffness(
        &self,
        shapes: &[ShapeAt],
        bins: &ParticleBins,
        dofs: usize,
        blocks: &mut [Vec<f64>],
    ) {
        for k in 0..self.len() {
            let s = &shapes[self.particle[k]];
            let block = &mut blocks[bins.cell_slot[s.cell as usize] as usize];
            for a in s.support() {
                let row = 2 * s.local[a] as usize;
                for b in s.support() {
                    let col = 2 * s.local[b] as usize;
                    let kab = self.stiffness[k] * s.n[a] * s.n[b];
                    block[row * dofs + col] += kab;
                    block[(row + 1) * dofs + col + 1] += kab;
                }
            }
        }
    }

    /// Force exerted by rigid body `r` on the soil, R = Σ k_p (X̄_p − x_p) (DESIGN D40), kN/m,
    /// at the committed positions and time `t`.
    pub fn force_on_soil(&self, r: usize, particles: &Particles, t: f64) -> [f64; 2] {
        let mut f = [0.0; 2];
        for k in (0..self.len()).filter(|&k| self.rigid[k] == r) {
            let anchor = self.anchor(k, particles, t);
            let x = particles.position[self.particle[k]];
            f[0] += self.stiffness[k] * (anchor[0] - x[0]);
            f[1] += self.stiffness[k] * (anchor[1] - x[1]);
        }
        f
    }

    /// Largest gap |X̄_p − x_p| over all driven points at time `t`, m.
    pub fn max_gap(&self, particles: &Particles, t: f64) -> f64 {
        (0..self.len())
            .map(|k| {
                let anchor = self.anchor(k, particles, t);
                let x = particles.position[self.particle[k]];
                ((anchor[0] - x[0]).powi(2) + (anchor[1] - x[1]).powi(2)).sqrt()
            })
            .fold(0.0, f64::max)
    }
}
