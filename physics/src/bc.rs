//! Boundary conditions and loads on the boundary (theory §3 "Linear system",
//! §8.0): grid-line Dirichlet conditions, prescribed nodal values, follower
//! pressure through traction points, and rigid rough platens/footings through
//! penalty-tied ("driven") material points.

use crate::grid::{Grid, ShapeAt};
use crate::particles::Particles;
use crate::scene::{ContactKind, GridLine, Scene, Side};
use crate::start_ramp::StartRamp;
use crate::transfer::{self, ParticleBins, NONE};

/// How one grid degree of freedom (2·node + component) is constrained.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum DofConstraint {
    /// Unknown of the nodal system.
    Free,
    /// Homogeneous Dirichlet condition (roller / fixity).
    Fixed,
    /// Prescribed displacement u(t, x) = D(t) · (rate + gradient · x), D the
    /// displacement factor of the start ramp ([`StartRamp::displacement`], D = t
    /// without ramp).
    Prescribed {
        /// Rate, m per unit time.
        rate: f64,
        /// Gradient of the rate, 1/time.
        gradient: [f64; 2],
        /// Smooth start of the motion (`ramp_time`).
        ramp: StartRamp,
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
    /// Build from the scene's `[[bc.fixed]]`, `[[bc.prescribed]]` and the
    /// normal dofs of `[[bc.friction]]` (fixed wins where several apply).
    pub fn from_scene(scene: &Scene, grid: &Grid) -> Self {
        let mut dof = vec![DofConstraint::Free; 2 * grid.node_count()];
        for f in &scene.bc.friction {
            if let Ok(line) = GridLine::parse(&f.line) {
                for n in nodes_on_line(grid, line) {
                    dof[2 * n + line.axis] = DofConstraint::Fixed;
                }
            }
        }
        for p in &scene.bc.prescribed {
            if let Ok(line) = GridLine::parse(&p.line) {
                for n in nodes_on_line(grid, line) {
                    dof[2 * n + p.dof.index()] = DofConstraint::Prescribed {
                        rate: p.rate,
                        gradient: p.gradient,
                        ramp: StartRamp::new(p.ramp_time),
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

    /// Prescribed displacement D(t) · (rate + gradient · x) of grid dof `d` at
    /// time `t` (0 for free and fixed dofs), D of [`StartRamp::displacement`].
    pub fn prescribed_value(&self, grid: &Grid, d: usize, t: f64) -> f64 {
        match self.dof[d] {
            DofConstraint::Prescribed {
                rate,
                gradient,
                ramp,
            } => {
                let x = grid.node_position(d / 2);
                ramp.displacement(t) * (rate + gradient[0] * x[0] + gradient[1] * x[1])
            }
            _ => 0.0,
        }
    }
}

/// Bilinear shape functions at a point `x` on a body's surface (outward
/// normal `n`) in the cell of the body it belongs to: the cell containing
/// x − 1e−9·h·n if it is *filled* (holds at least `min_points` material
/// points), else the first filled cell met going inward along −n (up to one
/// cell), else the cell containing x − 1e−9·h·n. `None` outside the grid.
/// See [`TractionPoints::shapes`] for why.
pub fn surface_shape(
    grid: &Grid,
    bins: &ParticleBins,
    x: [f64; 2],
    n: [f64; 2],
    min_points: usize,
) -> Option<ShapeAt> {
    let probe = |depth: f64| {
        [
            x[0] - depth * grid.cell_size * n[0],
            x[1] - depth * grid.cell_size * n[1],
        ]
    };
    let own = grid.locate(probe(1e-9))?;
    let filled =
        |(ci, cj): (usize, usize)| bins.particles_in(cj * grid.cells[0] + ci).len() >= min_points;
    let cell = [1e-9, 0.5, 1.0]
        .iter()
        .filter_map(|&d| grid.locate(probe(d)))
        .find(|&c| filled(c))
        .unwrap_or(own);
    Some(grid.shape_in_cell(cell.0, cell.1, x))
}

/// The edges a pressure loads, each as (start, end) running counter-clockwise
/// round the body (so that the outward normal is the tangent turned
/// clockwise): a side of a `box`, or a range of a polygon's edges.
fn loaded_edges(
    body: &crate::scene::BodySpec,
    spec: &crate::scene::PressureSpec,
) -> Vec<([f64; 2], [f64; 2])> {
    if let (Some(side), Some([lo, hi])) = (spec.side, body.rectangle) {
        let edge = match side {
            Side::Bottom => (lo, [hi[0], lo[1]]),
            Side::Right => ([hi[0], lo[1]], hi),
            Side::Top => (hi, [lo[0], hi[1]]),
            Side::Left => ([lo[0], hi[1]], lo),
        };
        return vec![edge];
    }
    let (Some([first, last]), Some(polygon)) = (spec.edges, &body.polygon) else {
        return Vec::new();
    };
    let n = polygon.len();
    let twice_area: f64 = (0..n)
        .map(|k| {
            let (a, b) = (polygon[k], polygon[(k + 1) % n]);
            a[0] * b[1] - b[0] * a[1]
        })
        .sum();
    (first..=last.min(n - 1))
        .map(|k| {
            let (a, b) = (polygon[k], polygon[(k + 1) % n]);
            if twice_area >= 0.0 {
                (a, b)
            } else {
                (b, a)
            }
        })
        .collect()
}

/// Massless boundary points carrying a follower pressure (theory §8.0).
#[derive(Clone, Debug, Default, serde::Serialize, serde::Deserialize)]
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
        for spec in &scene.bc.pressure {
            let Some(b) = scene.body_index(spec.body.as_deref()) else {
                continue;
            };
            for (start, end) in loaded_edges(&scene.body[b], spec) {
                tp.add_edge(start, end, h, spec.p);
            }
        }
        tp
    }

    /// Two Gauss points per segment of the edge `start` → `end` (counter-clockwise).
    fn add_edge(&mut self, start: [f64; 2], end: [f64; 2], h: f64, pressure: f64) {
        let gauss = 0.5 / 3f64.sqrt();
        let length = ((end[0] - start[0]).powi(2) + (end[1] - start[1]).powi(2)).sqrt();
        let segments = ((length / h) - 1e-9).ceil().max(1.0) as usize;
        let dir = [(end[0] - start[0]) / length, (end[1] - start[1]) / length];
        let seg = length / segments as f64;
        for s in 0..segments {
            for g in [0.5 - gauss, 0.5 + gauss] {
                let d = (s as f64 + g) * seg;
                self.position
                    .push([start[0] + d * dir[0], start[1] + d * dir[1]]);
                self.tangent.push([0.5 * seg * dir[0], 0.5 * seg * dir[1]]);
                self.pressure.push(pressure);
            }
        }
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
                surface_shape(grid, bins, self.position[s], n, min_points).ok_or(
                    transfer::OutsideGrid {
                        particle: s,
                        position: self.position[s],
                    },
                )
            })
            .collect()
    }

    /// Add the nodal forces −P n_s ℓ_s N_i(x_s) into `force` (per grid node), in point order.
    pub fn add_forces(&self, shapes: &[ShapeAt], force: &mut [[f64; 2]]) {
        for (s, shape) in shapes.iter().enumerate() {
            let f = self.force(s);
            for a in shape.support() {
                let node = shape.nodes[a] as usize;
                force[node][0] += f[0] * shape.n[a];
                force[node][1] += f[1] * shape.n[a];
            }
        }
    }

    /// Force −P n_s ℓ_s of point `s` on the body, kN/m.
    fn force(&self, s: usize) -> [f64; 2] {
        let (n, len) = self.normal_and_length(s);
        let magnitude = self.pressure[s] * len;
        [-magnitude * n[0], -magnitude * n[1]]
    }

    /// Move the points with the converged nodal displacement increment and
    /// stretch/rotate their tangents with ΔF(x_s) (follower load). Returns the
    /// work of the pressure on this motion, Σ_s ½ (f_s,before + f_s,after)·Δx_s
    /// (kJ/m; trapezoidal in the follower force).
    pub fn advect(&mut self, shapes: &[ShapeAt], du: &[[f64; 2]]) -> f64 {
        let mut work = 0.0;
        for (s, shape) in shapes.iter().enumerate() {
            let u = transfer::interpolate(shape, du);
            let l = transfer::gradient(shape, du);
            let before = self.force(s);
            let t = self.tangent[s];
            self.position[s][0] += u[0];
            self.position[s][1] += u[1];
            self.tangent[s] = [
                t[0] + l[0] * t[0] + l[1] * t[1],
                t[1] + l[2] * t[0] + l[3] * t[1],
            ];
            let after = self.force(s);
            work += 0.5 * ((before[0] + after[0]) * u[0] + (before[1] + after[1]) * u[1]);
        }
        work
    }
}

/// The points that tie rigid rough bodies (platens, footings) to the soil by
/// penalty springs (theory D40–D41), each anchored to its body. Per
/// `[[bc.rigid]] contact`:
///
/// - `top_points` (theory §8.0): the material points of the body's top point
///   row inside the footprint. The soil between that row and the surface
///   (0.21 h for Gauss points, h/4 for sub-cell centres) moves with the rigid
///   body, which stiffens the response by O(h).
/// - `surface`: massless points on the top surface inside the footprint, two
///   per cell-wide segment at the Gauss positions (like traction points),
///   moving with the surface (x_s += Σ N_i(x_s) Δu_i, with the grid motion
///   that moves the material points), so the tie never jumps from a grid row
///   to the next (theory §8.0's reason for not using nodal rows). Explicit runs
///   are stable up to CFL 0.9 with it (1.0 with `top_points`).
///   The first step then equals a bilinear FE model with the top nodes
///   tied: 12,635 kN/m per m on the biaxial at h = 1/300 m, as an independent
///   FE computation gives (`scripts/rough_top_fe.py`, `tests/rigid_contact.rs`).
#[derive(Clone, Debug, Default, serde::Serialize, serde::Deserialize)]
pub struct DrivenPoints {
    /// The tied material point, or `None` for a surface point.
    pub particle: Vec<Option<usize>>,
    /// Current position of a surface point, m (unused for material points).
    pub position: Vec<[f64; 2]>,
    /// Initial position of the point, m.
    pub position0: Vec<[f64; 2]>,
    /// Rigid body index (order of `[[bc.rigid]]`) of each point.
    pub rigid: Vec<usize>,
    /// Penalty stiffness k_p = β_pen E, kN/m per m.
    pub stiffness: Vec<f64>,
    /// Prescribed rigid velocity of each rigid body, m per unit time (its
    /// full value, after the start ramp).
    pub velocity: Vec<[f64; 2]>,
    /// Smooth start of each rigid body's motion (`ramp_time`): the scene's,
    /// so not checkpointed.
    #[serde(skip)]
    pub ramp: Vec<StartRamp>,
    /// Names of the rigid bodies.
    pub names: Vec<String>,
    /// Whether each point bore on soil in the last committed step
    /// ([`DrivenPoints::bears_on_soil`]); empty before the first step (all
    /// bear). Derived every step, so not checkpointed.
    #[serde(skip)]
    pub bearing: Vec<bool>,
}

/// Derivatives of the driven points' forces with respect to the anchors' time
/// parameter τ and of the driven load F (theory PF3), over a system's unknowns.
#[derive(Clone, Debug, Default)]
pub struct TravelDerivatives {
    /// ∂f_pen/∂τ = Σ_k k N_k v, per unknown, kN/m per unit time.
    pub force_rate: Vec<f64>,
    /// ∂F/∂Δu = −Σ_k k N_k v̂, per unknown, kN/m per m.
    pub load_gradient: Vec<f64>,
    /// ∂F/∂τ = Σ_k k v·v̂, kN/m per unit time.
    pub load_rate: f64,
}

/// Outward normal of the contact surface (the body's top).
const CONTACT_NORMAL: [f64; 2] = [0.0, 1.0];

impl DrivenPoints {
    /// Select or place the tied points of every `[[bc.rigid]]` (see the type).
    /// Returns the index of a rigid entry that ties no point as an error.
    pub fn from_scene(
        scene: &Scene,
        particles: &Particles,
        penalty_factor: f64,
        youngs_modulus: &[f64],
    ) -> Result<Self, usize> {
        let mut d = DrivenPoints::default();
        for (r, spec) in scene.bc.rigid.iter().enumerate() {
            let before = d.len();
            match spec.contact {
                ContactKind::TopPoints => d.tie_top_points(r, scene, particles),
                ContactKind::Surface => d.place_surface_points(r, scene, particles)?,
            }
            if d.len() == before {
                return Err(r);
            }
            d.velocity.push(spec.velocity);
            d.ramp.push(StartRamp::new(spec.ramp_time));
            d.names.push(spec.name.clone());
        }
        d.stiffness = (0..d.len())
            .map(|k| penalty_factor * youngs_modulus[d.material(k, scene, particles)])
            .collect();
        Ok(d)
    }

    /// Material index of the soil under point `k`.
    fn material(&self, k: usize, scene: &Scene, particles: &Particles) -> usize {
        let p = self.particle[k].unwrap_or_else(|| {
            let body = scene
                .body_index(scene.bc.rigid[self.rigid[k]].body.as_deref())
                .unwrap_or(0);
            particles
                .body
                .iter()
                .position(|&b| b as usize == body)
                .unwrap_or(0)
        });
        particles.material.get(p).map_or(0, |&m| m as usize)
    }

    /// theory §8.0: the material points of the top row of the body of rigid
    /// entry `r` whose x lies in its footprint.
    fn tie_top_points(&mut self, r: usize, scene: &Scene, particles: &Particles) {
        let spec = &scene.bc.rigid[r];
        let h = scene.grid.cell_size;
        let body = scene.body_index(spec.body.as_deref()).unwrap_or(0) as u16;
        let in_footprint = |p: usize| {
            let x = particles.position[p][0];
            particles.body[p] == body && x >= spec.footprint[0] && x <= spec.footprint[1]
        };
        let top = (0..particles.len())
            .filter(|&p| in_footprint(p))
            .map(|p| particles.position[p][1])
            .fold(f64::NEG_INFINITY, f64::max);
        for p in 0..particles.len() {
            if in_footprint(p) && particles.position[p][1] >= top - 0.25 * h {
                self.particle.push(Some(p));
                self.position.push(particles.position[p]);
                self.position0.push(particles.position0[p]);
                self.rigid.push(r);
            }
        }
    }

    /// Two surface points per segment (of at most one cell) of the footprint
    /// of rigid entry `r` on the top of its body's outline. Errs when the
    /// footprint is empty, does not lie on the body's top, or the body holds
    /// no material point.
    fn place_surface_points(
        &mut self,
        r: usize,
        scene: &Scene,
        particles: &Particles,
    ) -> Result<(), usize> {
        let spec = &scene.bc.rigid[r];
        let h = scene.grid.cell_size;
        let body_index = scene.body_index(spec.body.as_deref()).unwrap_or(0);
        if !particles.body.iter().any(|&b| b as usize == body_index) {
            return Err(r);
        }
        let outline = scene.body[body_index].outline();
        let top = outline
            .iter()
            .map(|v| v[1])
            .fold(f64::NEG_INFINITY, f64::max);
        let covers = |x: f64| crate::scene::polygon_contains(&outline, [x, top - 1e-9 * h]);
        let [x0, x1] = spec.footprint;
        let width = x1 - x0;
        if width <= 0.0 || !covers(x0 + 1e-9 * h) || !covers(x1 - 1e-9 * h) {
            return Err(r);
        }
        let gauss = 0.5 / 3f64.sqrt();
        let segments = ((width / h) - 1e-9).ceil().max(1.0) as usize;
        let seg = width / segments as f64;
        for k in 0..segments {
            for g in [0.5 - gauss, 0.5 + gauss] {
                let x = [x0 + (k as f64 + g) * seg, top];
                self.particle.push(None);
                self.position.push(x);
                self.position0.push(x);
                self.rigid.push(r);
            }
        }
        Ok(())
    }

    /// Number of tied points.
    pub fn len(&self) -> usize {
        self.particle.len()
    }

    /// True when there are none.
    pub fn is_empty(&self) -> bool {
        self.particle.is_empty()
    }

    /// Shape functions of every tied point: a material point's own
    /// (`particle_shapes`), or for a surface point the bilinear ones in the
    /// filled cell of the body below it ([`surface_shape`]); errs with the
    /// first surface point that left the grid.
    pub fn shapes(
        &self,
        grid: &Grid,
        bins: &ParticleBins,
        min_points: usize,
        particle_shapes: &[ShapeAt],
    ) -> Result<Vec<ShapeAt>, transfer::OutsideGrid> {
        (0..self.len())
            .map(|k| match self.particle[k] {
                Some(p) => Ok(particle_shapes[p]),
                None => {
                    let x = self.position[k];
                    surface_shape(grid, bins, x, CONTACT_NORMAL, min_points).ok_or(
                        transfer::OutsideGrid {
                            particle: k,
                            position: x,
                        },
                    )
                }
            })
            .collect()
    }

    /// Current position of point `k`, m.
    fn current(&self, k: usize, particles: &Particles) -> [f64; 2] {
        self.particle[k].map_or(self.position[k], |p| particles.position[p])
    }

    /// Anchor X̄(t) = x(0) + ū(t) of point `k` (theory D40), ū(t) = D(t) v
    /// with v the body's velocity and D its start ramp's displacement factor
    /// ([`StartRamp::displacement`]; D = t without ramp).
    pub fn anchor(&self, k: usize, t: f64) -> [f64; 2] {
        let x0 = self.position0[k];
        let r = self.rigid[k];
        let (v, d) = (self.velocity[r], self.ramp[r].displacement(t));
        [x0[0] + v[0] * d, x0[1] + v[1] * d]
    }

    /// Distance D(t1) − D(t0) rigid body `r` travels over [t0, t1] per unit of
    /// its velocity: every anchor of the body moves by
    /// X̄(t1) − X̄(t0) = (D(t1) − D(t0)) v.
    pub fn travel(&self, r: usize, t0: f64, t1: f64) -> f64 {
        let ramp = self.ramp[r];
        ramp.displacement(t1) - ramp.displacement(t0)
    }

    /// Whether a point with shape `shape` bears on soil this step: its cell
    /// holds material points. A surface point whose cell the soil has left
    /// (squeezed out at a footing corner) carries neither force nor
    /// stiffness. Its nodes can still carry unknowns through the
    /// neighbouring cells, so a force without its stiffness would leave the
    /// tangent inconsistent: measured on the footing at h = 0.1 m, nonlocal,
    /// where Newton diverged at δ = 0.28 m until such points were left out.
    pub fn bears_on_soil(shape: &ShapeAt, bins: &ParticleBins) -> bool {
        bins.cell_slot[shape.cell as usize] != NONE
    }

    /// Penalty forces f_i^pen = Σ k N_i (X̄(t) − x − Σ_j N_j Δu_j) added into `force`
    /// (theory D40) by the points that bear on soil; `du` is the current
    /// nodal displacement increment (zeros for explicit).
    pub fn add_forces(
        &self,
        particles: &Particles,
        shapes: &[ShapeAt],
        bins: &ParticleBins,
        du: &[[f64; 2]],
        t: f64,
        force: &mut [[f64; 2]],
    ) {
        for (k, s) in shapes.iter().enumerate() {
            if !Self::bears_on_soil(s, bins) {
                continue;
            }
            let gap = self.gap(k, particles, s, du, t);
            for a in s.support() {
                let node = s.nodes[a] as usize;
                force[node][0] += self.stiffness[k] * s.n[a] * gap[0];
                force[node][1] += self.stiffness[k] * s.n[a] * gap[1];
            }
        }
    }

    /// Gap X̄(t) − (x + Σ_j N_j Δu_j) of point `k`.
    pub fn gap(
        &self,
        k: usize,
        particles: &Particles,
        shape: &ShapeAt,
        du: &[[f64; 2]],
        t: f64,
    ) -> [f64; 2] {
        let anchor = self.anchor(k, t);
        let x = self.current(k, particles);
        let u = transfer::interpolate(shape, du);
        [anchor[0] - x[0] - u[0], anchor[1] - x[1] - u[1]]
    }

    /// Add K_pen = Σ k N Nᵀ ⊗ I₂ (theory D41) into the patch blocks of the
    /// active cells (one flat array, block `slot` at `slot · dofs²`, `dofs`
    /// per block row). A point that does not bear on soil
    /// ([`DrivenPoints::bears_on_soil`]) adds nothing, as it adds no force.
    pub fn add_stiffness(
        &self,
        shapes: &[ShapeAt],
        bins: &ParticleBins,
        dofs: usize,
        blocks: &mut [f64],
    ) {
        for (k, s) in shapes.iter().enumerate() {
            if !Self::bears_on_soil(s, bins) {
                continue;
            }
            let slot = bins.cell_slot[s.cell as usize];
            let size = dofs * dofs;
            let block = &mut blocks[slot as usize * size..(slot as usize + 1) * size];
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

    /// Whether point `k` bore on soil in the last committed step (every point
    /// before the first step and after a restore).
    fn bore(&self, k: usize) -> bool {
        self.bearing.get(k).copied().unwrap_or(true)
    }

    /// Move the surface points over the step from `t0` to `t1`: with the soil
    /// surface, x_s += Σ_i N_i(x_s) Δu_i, where they bore on soil, and with their
    /// rigid body, x_s += X̄(t1) − X̄(t0), where they did not (tied material
    /// points move themselves); record which points bore on soil in the step
    /// ([`DrivenPoints::bearing`]).
    ///
    /// A point over soil squeezed out of its cell is pulled by nothing, and the
    /// nodal motion it would follow is that of the soil beside it: at the
    /// footing's corners at h = 0.1 m (nonlocal) such points rose up to 6 cm above
    /// the footing's base. When soil came back under them, the penalty closed
    /// that gap in one step, whatever its length (the run stopped at δ = 0.29 m:
    /// a point moved 6.1 cm in a step of Δt/256). Carried with the body, the
    /// point ties the returning soil where the footing is.
    pub fn advect(
        &mut self,
        shapes: &[ShapeAt],
        bins: &ParticleBins,
        du: &[[f64; 2]],
        (t0, t1): (f64, f64),
    ) {
        self.bearing.clear();
        self.bearing
            .extend(shapes.iter().map(|s| Self::bears_on_soil(s, bins)));
        for (k, shape) in shapes.iter().enumerate() {
            if self.particle[k].is_some() {
                continue;
            }
            let u = if self.bearing[k] {
                transfer::interpolate(shape, du)
            } else {
                let (from, to) = (self.anchor(k, t0), self.anchor(k, t1));
                [to[0] - from[0], to[1] - from[1]]
            };
            self.position[k][0] += u[0];
            self.position[k][1] += u[1];
        }
    }

    /// Force exerted by rigid body `r` on the soil, R = Σ k (X̄ − x) (theory D40), kN/m,
    /// at the committed positions and time `t`.
    pub fn force_on_soil(&self, r: usize, particles: &Particles, t: f64) -> [f64; 2] {
        let mut f = [0.0; 2];
        for k in (0..self.len()).filter(|&k| self.rigid[k] == r && self.bore(k)) {
            let anchor = self.anchor(k, t);
            let x = self.current(k, particles);
            f[0] += self.stiffness[k] * (anchor[0] - x[0]);
            f[1] += self.stiffness[k] * (anchor[1] - x[1]);
        }
        f
    }

    /// The driven load along the motion at the committed positions and time
    /// `t`: Σ_r R_r·v̂_r over the rigid bodies (theory PF1), kN/m.
    pub fn committed_load(&self, particles: &Particles, t: f64) -> f64 {
        (0..self.velocity.len())
            .map(|r| {
                let (f, e) = (self.force_on_soil(r, particles, t), self.direction(r));
                f[0] * e[0] + f[1] * e[1]
            })
            .sum()
    }

    /// Mean displacement x − x(0) of the points tied to rigid body `r` that
    /// bear on soil (all of them if none does), m: a point over an emptied
    /// cell is not pulled along and would lag.
    pub fn mean_displacement(&self, r: usize, particles: &Particles) -> [f64; 2] {
        let mut sum = [0.0; 2];
        let mut count = 0;
        let any_bears = (0..self.len()).any(|k| self.rigid[k] == r && self.bore(k));
        for k in (0..self.len()).filter(|&k| self.rigid[k] == r && (self.bore(k) || !any_bears)) {
            let x = self.current(k, particles);
            sum[0] += x[0] - self.position0[k][0];
            sum[1] += x[1] - self.position0[k][1];
            count += 1;
        }
        let n = count.max(1) as f64;
        [sum[0] / n, sum[1] / n]
    }

    /// Unit vector of rigid body `r`'s motion, v̂ = v/|v| (zero for a body
    /// at rest).
    fn direction(&self, r: usize) -> [f64; 2] {
        let v = self.velocity[r];
        let speed = (v[0] * v[0] + v[1] * v[1]).sqrt();
        if speed > 0.0 {
            [v[0] / speed, v[1] / speed]
        } else {
            [0.0; 2]
        }
    }

    /// The driven load along the motion, F = Σ_k k (X̄_k(t) − x_k − N_k·Δu)·v̂
    /// over the points that bear on soil (theory PF1): the force the rigid
    /// bodies exert on the soil in the direction they move, kN/m, at the
    /// nodal increment `du` and time `t`.
    pub fn load_along_motion(
        &self,
        particles: &Particles,
        shapes: &[ShapeAt],
        bins: &ParticleBins,
        du: &[[f64; 2]],
        t: f64,
    ) -> f64 {
        shapes
            .iter()
            .enumerate()
            .filter(|(_, s)| Self::bears_on_soil(s, bins))
            .map(|(k, s)| {
                let gap = self.gap(k, particles, s, du, t);
                let e = self.direction(self.rigid[k]);
                self.stiffness[k] * (gap[0] * e[0] + gap[1] * e[1])
            })
            .sum()
    }

    /// How the penalty forces and the driven load change with the time
    /// parameter τ of the anchors (theory PF3), over the unknowns numbered by
    /// `index` (grid dof → unknown, [`NONE`] for the others) of a system of
    /// `unknowns` unknowns.
    pub fn travel_derivatives(
        &self,
        shapes: &[ShapeAt],
        bins: &ParticleBins,
        index: &[u32],
        unknowns: usize,
    ) -> TravelDerivatives {
        let mut d = TravelDerivatives {
            force_rate: vec![0.0; unknowns],
            load_gradient: vec![0.0; unknowns],
            load_rate: 0.0,
        };
        for (k, s) in shapes.iter().enumerate() {
            if !Self::bears_on_soil(s, bins) {
                continue;
            }
            let (r, stiffness) = (self.rigid[k], self.stiffness[k]);
            let (v, e) = (self.velocity[r], self.direction(r));
            d.load_rate += stiffness * (v[0] * e[0] + v[1] * e[1]);
            for a in s.support() {
                let node = s.nodes[a] as usize;
                for c in 0..2 {
                    let unknown = index[2 * node + c];
                    if unknown != NONE {
                        d.force_rate[unknown as usize] += stiffness * s.n[a] * v[c];
                        d.load_gradient[unknown as usize] -= stiffness * s.n[a] * e[c];
                    }
                }
            }
        }
        d
    }

    /// Largest gap |X̄ − x| over all tied points at time `t`, m.
    pub fn max_gap(&self, particles: &Particles, t: f64) -> f64 {
        (0..self.len())
            .map(|k| {
                let anchor = self.anchor(k, t);
                let x = self.current(k, particles);
                ((anchor[0] - x[0]).powi(2) + (anchor[1] - x[1]).powi(2)).sqrt()
            })
            .fold(0.0, f64::max)
    }
}
