//! Coulomb friction on the edges of the grid (`[[bc.friction]]`, theory
//! "Frictional boundary"). The soil cannot cross the edge; along it the
//! tangential reaction T is bounded by μ times the compressive normal
//! reaction N (|T| ≤ μ N: stick below the bound, slip at it), and no
//! reaction acts where the soil pulls away (N ≤ 0). One law,
//! [`coulomb_resistance`], serves both integrators:
//! - FR1 (implicit, force form): the normal dof is held (the edge's reaction
//!   is N), and the tangential dof carries T = −k_t Δu_t while
//!   k_t |Δu_t| ≤ μ N̂, else −μ N̂ sign(Δu_t), k_t = 10 E; N̂ of the last step
//!   (FR4), fixed within the step.
//! - FR2 (explicit, velocity form): a node whose velocity after the step's
//!   forces, v*, moves into the edge is stopped (normal impulse per mass
//!   v*_n) and its tangential velocity reduced by at most μ v*_n.
//! - FR3 (explicit re-map): the edge holds the normal increment against the
//!   approach only; a node leaving the edge moves (and strains the soil) as a
//!   free one. Zeroing it as a fixed dof moved the points without straining
//!   them: the sliding block rang, lifted off, and slid 0.92 m (exact 0.5) at
//!   h = 0.125.
//! - FR4 (implicit normal force): on each contact patch (neighbouring active
//!   nodes of a line) the bound uses the net normal force
//!   N_P = max(Σ N_i, 0), shared by nodal mass, N̂_i = N_P m_i / Σ m_j. The
//!   bilateral edge's nodal reactions swing node by node (tension at some);
//!   a bound on max(N_i, 0) overestimated the capacity (slide 0.395 m at
//!   h = 0.0625), and one shared in proportion to max(N_i, 0), lagged,
//!   fed the swing (0.42 m and a Newton failure at dt = 1e-3).
//!
//! Sliding block (`validation/friction/sliding_block.toml`, exact 0.5 m,
//! stop 0.5 s): implicit 0.5059 m at h = 0.125, 0.0625, 0.03125 (dt = 2e-3,
//! deceleration fit 4.000 m/s², exact 4), 0.5030 m at dt = 1e-3; explicit
//! 0.4962 / 0.4975 m at h = 0.125 / 0.0625 (deceleration fit 4.045 / 4.048).

use crate::bc::nodes_on_line;
use crate::grid::Grid;
use crate::scene::{GridLine, Scene};
use crate::transfer::NONE;

/// k_t / E of the implicit stick spring. On the sliding block
/// (`validation/friction/sliding_block.toml`) 10, 100 and 1,000 give the same
/// slide to 1e-4, with 0, 3 and 784 step halvings: a stiffer spring makes
/// Newton chatter between stick and slip where the block comes to rest.
pub const STICK_STIFFNESS_FACTOR: f64 = 10.0;

/// The resistance of a Coulomb contact to a tangential `demand` (the force,
/// or impulse, that would hold the contact still) under the compressive
/// normal force (or impulse) `normal`: the demand itself while it is below
/// μ N (stick), else μ N with its sign (slip); zero when `normal` ≤ 0.
/// Returns (resistance, stick).
pub fn coulomb_resistance(demand: f64, mu: f64, normal: f64) -> (f64, bool) {
    let bound = mu * normal.max(0.0);
    if demand.abs() <= bound {
        (demand, true)
    } else {
        (bound * demand.signum(), false)
    }
}

/// A grid node on a frictional edge.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FrictionNode {
    /// Grid node index.
    pub node: usize,
    /// The component normal to the edge (0: x, 1: y).
    pub normal: usize,
    /// +1 when the soil lies on the side of increasing coordinate, else −1.
    pub inward: f64,
    /// Friction coefficient μ.
    pub mu: f64,
    /// The `[[bc.friction]]` line the node belongs to (its place in the list).
    pub line: usize,
}

impl FrictionNode {
    /// The tangential component.
    pub fn tangent(&self) -> usize {
        1 - self.normal
    }

    /// Explicit update of the node's trial velocity `v` (after the step's
    /// forces, mass `m`): a node moving into the edge is stopped and its
    /// tangential velocity reduced by the Coulomb law on the impulses per
    /// mass (theory eq. FR2). Returns the new velocity.
    pub fn stop_and_slide(&self, v: [f64; 2]) -> [f64; 2] {
        let (n, t) = (self.normal, self.tangent());
        let approach = -self.inward * v[n];
        if approach <= 0.0 {
            return v;
        }
        let (resisted, _) = coulomb_resistance(v[t], self.mu, approach);
        let mut out = [0.0; 2];
        out[n] = 0.0;
        out[t] = v[t] - resisted;
        out
    }
}

/// The frictional edges of a run, node by node.
#[derive(Clone, Debug, Default)]
pub struct FrictionEdges {
    /// The nodes of every `[[bc.friction]]` line.
    pub nodes: Vec<FrictionNode>,
    /// Per grid node: its index in `nodes`, or [`NONE`].
    pub at_node: Vec<u32>,
    /// Implicit: the tangential spring k_t that holds a sticking node,
    /// [`STICK_STIFFNESS_FACTOR`] E of the stiffest material, kN/m per m.
    pub stiffness: f64,
}

impl FrictionEdges {
    /// The nodes of the scene's `[[bc.friction]]` lines (validated: each on an
    /// edge of the grid).
    pub fn from_scene(scene: &Scene, grid: &Grid) -> Self {
        let stiffest = scene
            .materials
            .values()
            .map(|m| m.youngs_modulus())
            .fold(0.0, f64::max);
        let mut edges = Self {
            nodes: Vec::new(),
            at_node: vec![NONE; grid.node_count()],
            stiffness: STICK_STIFFNESS_FACTOR * stiffest,
        };
        for (index, spec) in scene.bc.friction.iter().enumerate() {
            let Ok(line) = GridLine::parse(&spec.line) else {
                continue;
            };
            let lower_edge = (line.value - grid.origin[line.axis]).abs() < 0.5 * grid.cell_size;
            let inward = if lower_edge { 1.0 } else { -1.0 };
            for node in nodes_on_line(grid, line) {
                if edges.at_node[node] == NONE {
                    edges.at_node[node] = edges.nodes.len() as u32;
                    edges.nodes.push(FrictionNode {
                        node,
                        normal: line.axis,
                        inward,
                        mu: spec.mu,
                        line: index,
                    });
                }
            }
        }
        edges
    }

    /// Implicit: the tangential force at frictional node `contact` whose
    /// step has moved it by `du` along the edge, under the compressive
    /// normal force `normal` (from the last step, [`Self::patch_normals`]),
    /// theory eq. FR1: T = −k_t Δu_t while |k_t Δu_t| ≤ μ N, else
    /// −μ N sign(Δu_t). Returns (T, dT/dΔu_t).
    pub fn tangential_force(&self, contact: &FrictionNode, du: f64, normal: f64) -> (f64, f64) {
        let (resistance, stick) = coulomb_resistance(self.stiffness * du, contact.mu, normal);
        (-resistance, if stick { self.stiffness } else { 0.0 })
    }

    /// The normal forces that bound the friction, per node of `nodes`
    /// (theory eq. FR4): on each contact patch (a run of neighbouring
    /// `active` nodes of one line), the patch's net compressive force
    /// N_P = max(Σ N_i, 0), N_i = `normal(node)` (compressive positive),
    /// shared among its nodes in proportion to `weight(node)` (the nodal
    /// mass): N̂_i = N_P w_i / Σ_j w_j. The nodal reactions of a bilateral
    /// edge swing node by node (tension at some), and a bound following them
    /// (max(N_i, 0)) both overestimates the capacity and, lagged, feeds the
    /// swing: the sliding block then stopped 21 % short at h = 0.0625.
    pub fn patch_normals(
        &self,
        active: impl Fn(usize) -> bool,
        normal: impl Fn(&FrictionNode) -> f64,
        weight: impl Fn(&FrictionNode) -> f64,
        out: &mut Vec<f64>,
    ) {
        out.clear();
        out.resize(self.nodes.len(), 0.0);
        let mut start = 0;
        while start < self.nodes.len() {
            if !active(self.nodes[start].node) {
                start += 1;
                continue;
            }
            let line = self.nodes[start].line;
            let mut end = start + 1;
            while end < self.nodes.len()
                && self.nodes[end].line == line
                && active(self.nodes[end].node)
            {
                end += 1;
            }
            let (mut net, mut total) = (0.0, 0.0);
            for k in start..end {
                net += normal(&self.nodes[k]);
                out[k] = weight(&self.nodes[k]);
                total += out[k];
            }
            let scale = if total > 0.0 {
                net.max(0.0) / total
            } else {
                0.0
            };
            for n in &mut out[start..end] {
                *n *= scale;
            }
            start = end;
        }
    }

    /// Whether the run has frictional edges.
    pub fn is_empty(&self) -> bool {
        self.nodes.is_empty()
    }

    /// The frictional node at grid node `node`, if any.
    #[inline]
    pub fn at(&self, node: usize) -> Option<&FrictionNode> {
        match self.at_node.get(node) {
            Some(&k) if k != NONE => Some(&self.nodes[k as usize]),
            _ => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn coulomb_law_sticks_below_the_bound_and_slips_at_it() {
        assert_eq!(coulomb_resistance(0.3, 0.5, 1.0), (0.3, true));
        assert_eq!(coulomb_resistance(-0.7, 0.5, 1.0), (-0.5, false));
        assert_eq!(coulomb_resistance(0.7, 0.5, -1.0), (0.0, false));
        assert_eq!(coulomb_resistance(0.0, 0.0, 1.0), (0.0, true));
    }

    /// A patch's capacity is its net normal force, shared by weight; an
    /// inactive node splits the edge into two patches.
    #[test]
    fn patch_normals_share_the_net_force_by_weight() {
        let node = |node, line| FrictionNode {
            node,
            normal: 1,
            inward: 1.0,
            mu: 0.5,
            line,
        };
        let edges = FrictionEdges {
            nodes: (0..6).map(|n| node(n, 0)).collect(),
            ..Default::default()
        };
        let reaction = [3.0, -1.0, 2.0, 9.0, -4.0, 1.0];
        let weight = [1.0, 2.0, 1.0, 1.0, 1.0, 1.0];
        let mut out = Vec::new();
        edges.patch_normals(
            |n| n != 3,
            |c| reaction[c.node],
            |c| weight[c.node],
            &mut out,
        );
        assert_eq!(out, vec![1.0, 2.0, 1.0, 0.0, 0.0, 0.0]);
    }

    /// On a base (normal y, soil above): a node moving down and sideways is
    /// stopped and slowed by μ times its downward speed; one moving up is
    /// left alone; a slow slide sticks.
    #[test]
    fn explicit_contact_stops_the_approach_and_limits_the_slide() {
        let base = FrictionNode {
            node: 0,
            normal: 1,
            inward: 1.0,
            mu: 0.5,
            line: 0,
        };
        assert_eq!(base.stop_and_slide([2.0, -1.0]), [1.5, 0.0]);
        assert_eq!(base.stop_and_slide([-2.0, -1.0]), [-1.5, 0.0]);
        assert_eq!(base.stop_and_slide([0.2, -1.0]), [0.0, 0.0]);
        assert_eq!(base.stop_and_slide([2.0, 1.0]), [2.0, 1.0]);
        // a right wall (normal x, soil to its left)
        let wall = FrictionNode {
            normal: 0,
            inward: -1.0,
            ..base
        };
        assert_eq!(wall.stop_and_slide([1.0, 3.0]), [0.0, 2.5]);
    }
}
