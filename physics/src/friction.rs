//! Coulomb friction on the edges of the grid (`[[bc.friction]]`, theory
//! "Frictional boundary"). The soil cannot cross the edge; along it the
//! tangential reaction T is bounded by μ times the compressive normal
//! reaction N (|T| ≤ μ N: stick below the bound, slip at it), and no
//! reaction acts where the soil pulls away (N ≤ 0). One law,
//! [`coulomb_resistance`], serves both integrators:
//! - FR1 (implicit, force form): the normal dof is held (the edge's reaction
//!   is N), and the tangential dof carries a stick spring continuing from the
//!   last step's friction force T_n, T = T_n − k_t Δu_t while |T| ≤ μ N̂,
//!   else μ N̂ with its sign, k_t = 10 E; N̂ of the last step (FR4), fixed
//!   within the step. (A spring restarted every step lets a sticking node
//!   creep at T/(k_t Δt).)
//! - FR2 (explicit, velocity form): a node whose velocity after the step's
//!   forces, v*, moves into the edge is stopped (normal impulse per mass
//!   v*_n) and its tangential velocity reduced by at most μ v*_n.
//! - FR3 (explicit re-map): the normal increment is the update's, Δt v_n
//!   (zero where FR2 stopped the approach, the free velocity where the node
//!   leaves), as for a prescribed dof, so the strains follow the points'
//!   G2P motion. Zeroing it as a fixed dof moved the points without
//!   straining them: the sliding block rang, lifted off, and slid 0.92 m
//!   (exact 0.5) at h = 0.125. Deciding stop or leave again from the
//!   re-mapped velocity let a node the update released move the points up
//!   while the re-map held it: the block crept 12 mm up off the base, and
//!   on the cut that lift fed the energy budget (R = −27 % of W at h =
//!   0.25 m, CFL 0.5, −6.7 % at CFL 0.125).
//! - FR4 (implicit normal force): on each contact patch (neighbouring active
//!   nodes of a line) the bound uses the net normal force
//!   N_P = max(Σ N_i, 0), shared in proportion to the reactions filtered
//!   over three nodes (see [`FrictionEdges::patch_normals`]).
//! - FR7 (implicit separation): a frictional node whose normal dof is
//!   released in a step is *open*: free to leave the edge, with no reaction
//!   and no friction. A step starts with open the nodes whose last filtered
//!   reaction was not compressive and whose soil moves away
//!   ([`FrictionEdges::open_at_start`]); after the solve a closed patch in
//!   net tension opens, and an open node that the step moved into the edge
//!   closes, and the step is solved again with the new set
//!   ([`FrictionEdges::contact_changes`]).
//!
//! Sliding block (`validation/friction/sliding_block.toml`, exact 0.5 m,
//! stop 0.5 s): implicit 0.5060 / 0.5006 m at h = 0.125 / 0.0625 (dt = 2e-3),
//! explicit 0.4994 / 0.4998 m (`tests/friction_base.rs`).

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

/// The state of an implicit frictional node in a Newton iterate (FR1).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ContactState {
    /// The stick spring holds it.
    Stick,
    /// It slides; the edge resists with μ N against `direction` (±1, the
    /// sign of the demand k_t Δu_t − T_n).
    Slip {
        /// Sign of the demand.
        direction: f64,
    },
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
    /// with `previous` the tangential force of the last step, theory eq.
    /// FR1: the stick spring continues from it, T = T_n − k_t Δu_t, while
    /// |T| ≤ μ N, else μ N with its sign. With `held_stick` the node sticks
    /// whatever `du` (FR6). Returns (T, dT/dΔu_t) and the state.
    pub fn tangential_force(
        &self,
        contact: &FrictionNode,
        du: f64,
        normal: f64,
        previous: f64,
        held_stick: bool,
    ) -> (f64, f64, ContactState) {
        let demand = self.stiffness * du - previous;
        match coulomb_resistance(demand, contact.mu, normal) {
            (_, stick) if stick || held_stick => (-demand, self.stiffness, ContactState::Stick),
            (resisted, _) => (
                -resisted,
                0.0,
                ContactState::Slip {
                    direction: resisted.signum(),
                },
            ),
        }
    }

    /// The normal forces that bound the friction, per node of `nodes`
    /// (theory eq. FR4): on each contact patch (a run of neighbouring
    /// `active` nodes of one line), the patch's net compressive force
    /// N_P = max(Σ N_i, 0), N_i = `normal(node)` (compressive positive),
    /// shared among its nodes in proportion to the reactions filtered over
    /// three nodes, w_i = max((N_{i−1} + 2 N_i + N_{i+1}) / 4, 0) (at a
    /// patch's end (2 N_i + N_{i±1}) / 3): N̂_i = N_P w_i / Σ_j w_j. The
    /// bilateral edge's nodal reactions swing node by node (tension at
    /// some), and a bound following them (max(N_i, 0)) both overestimates the
    /// capacity and, lagged, feeds the swing (the sliding block stopped 21 %
    /// short at h = 0.0625); the filter removes that node-to-node mode and
    /// keeps the distribution along the edge, which sharing by nodal mass
    /// lost (the thin front of the cut's debris then carried the pile's
    /// mean pressure and stopped ~1 m short).
    pub fn patch_normals(
        &self,
        active: impl Fn(usize) -> bool,
        normal: impl Fn(&FrictionNode) -> f64,
        out: &mut Vec<f64>,
    ) {
        out.clear();
        out.resize(self.nodes.len(), 0.0);
        for patch in self.patches(|k| active(self.nodes[k].node)) {
            let reactions: Vec<f64> = self.nodes[patch.clone()].iter().map(&normal).collect();
            let net = reactions.iter().sum::<f64>().max(0.0);
            let weights = &mut out[patch];
            for (i, w) in weights.iter_mut().enumerate() {
                *w = filtered(&reactions, i).max(0.0);
            }
            let total: f64 = weights.iter().sum();
            let scale = if total > 0.0 { net / total } else { 0.0 };
            for n in weights.iter_mut() {
                *n *= scale;
            }
        }
    }

    /// The contact patches: runs of neighbouring frictional nodes k of one
    /// line for which `member(k)` holds, as ranges of `nodes`.
    fn patches(&self, member: impl Fn(usize) -> bool) -> Vec<std::ops::Range<usize>> {
        let mut patches = Vec::new();
        let mut start = 0;
        while start < self.nodes.len() {
            if !member(start) {
                start += 1;
                continue;
            }
            let line = self.nodes[start].line;
            let mut end = start + 1;
            while end < self.nodes.len() && self.nodes[end].line == line && member(end) {
                end += 1;
            }
            patches.push(start..end);
            start = end;
        }
        patches
    }

    /// Implicit separation, start of a step (FR7): per frictional node,
    /// whether it starts the step open: at an `active` node whose reaction
    /// in the last step (`last_normal`, compressive positive), filtered over
    /// three nodes as in FR4, was not compressive, and whose soil moves away
    /// from the edge (`leaving` > 0).
    pub fn open_at_start(
        &self,
        active: impl Fn(usize) -> bool,
        last_normal: impl Fn(&FrictionNode) -> f64,
        leaving: impl Fn(&FrictionNode) -> f64,
    ) -> Vec<bool> {
        let mut open = vec![false; self.nodes.len()];
        for patch in self.patches(|k| active(self.nodes[k].node)) {
            let reactions: Vec<f64> = self.nodes[patch.clone()].iter().map(&last_normal).collect();
            for (i, k) in patch.enumerate() {
                open[k] = filtered(&reactions, i) <= 0.0 && leaving(&self.nodes[k]) > 0.0;
            }
        }
        open
    }

    /// Implicit separation after a solve (FR7): the frictional nodes k whose
    /// contact changes, with `open[k]` the set the step was solved with. A
    /// patch of `active` closed nodes whose net reaction `normal`
    /// (compressive positive) is tensile opens as a whole: the edge pulls
    /// the soil there. (Opening single nodes on the filtered reaction let a
    /// bending wave of the sliding block peel the base open and shut, and
    /// the nodes reclosed found no normal force of the last step to bound
    /// their friction: at h = 0.0625 m the slide grew by 8 %.) An open node
    /// whose normal increment `inward_motion` (along the inward normal) is
    /// below −`tolerance` closes: the step moved it into the edge.
    pub fn contact_changes(
        &self,
        active: impl Fn(usize) -> bool,
        open: &[bool],
        normal: impl Fn(&FrictionNode) -> f64,
        inward_motion: impl Fn(&FrictionNode) -> f64,
        tolerance: f64,
    ) -> Vec<usize> {
        let mut changes: Vec<usize> = (0..self.nodes.len())
            .filter(|&k| open[k] && inward_motion(&self.nodes[k]) < -tolerance)
            .collect();
        let closed = |k: usize| !open[k] && active(self.nodes[k].node);
        for patch in self.patches(closed) {
            if self.nodes[patch.clone()].iter().map(&normal).sum::<f64>() < 0.0 {
                changes.extend(patch);
            }
        }
        changes.sort_unstable();
        changes
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

/// The reaction at place `i` of a patch's `reactions` filtered over its
/// neighbours, (N_{i−1} + 2 N_i + N_{i+1}) / 4, one-sided (2 N_i + N_{i±1}) / 3
/// at an end (eq. FR4).
fn filtered(reactions: &[f64], i: usize) -> f64 {
    let before = i.checked_sub(1).map(|j| reactions[j]);
    let after = reactions.get(i + 1).copied();
    let (sum, weight) = [before, after]
        .into_iter()
        .flatten()
        .fold((2.0 * reactions[i], 2.0), |(s, w), n| (s + n, w + 1.0));
    sum / weight
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

    /// A patch's capacity is its net normal force, shared by the filtered
    /// reactions; an inactive node splits the edge into two patches, and a
    /// patch in net tension carries nothing.
    #[test]
    fn patch_normals_share_the_net_force_by_the_filtered_reactions() {
        let edges = edge(6);
        let reaction = [3.0, -1.0, 2.0, 9.0, -4.0, 1.0];
        let mut out = Vec::new();
        edges.patch_normals(|n| n != 3, |c| reaction[c.node], &mut out);
        // filtered 5/3, 3/4, 1 (sum 41/12) share the net 4
        let expected = [80.0 / 41.0, 36.0 / 41.0, 48.0 / 41.0, 0.0, 0.0, 0.0];
        for (o, e) in out.iter().zip(expected) {
            assert!((o - e).abs() < 1e-14, "{out:?}");
        }
    }

    /// A node-to-node swing of ±3 on a load rising along the edge: the
    /// interior bounds follow the load (in proportion 2 : 3 : 4 : 5), not
    /// the swing, and their sum with the ends' is the net force.
    #[test]
    fn patch_normals_remove_the_node_to_node_swing() {
        let edges = edge(6);
        let reaction: Vec<f64> = (0..6)
            .map(|i| (i + 1) as f64 + if i % 2 == 0 { 3.0 } else { -3.0 })
            .collect();
        let mut out = Vec::new();
        edges.patch_normals(|_| true, |c| reaction[c.node], &mut out);
        let unit = out[1] / 2.0;
        for (i, n) in out.iter().enumerate().take(5).skip(1) {
            assert!((n - unit * (i + 1) as f64).abs() < 1e-12, "{out:?}");
        }
        assert!((out.iter().sum::<f64>() - 21.0).abs() < 1e-12);
    }

    /// The stick spring continues from the last step's force; past the
    /// bound the node slips at μ N; a node held in stick keeps its spring
    /// past the bound (FR1, FR6).
    #[test]
    fn tangential_force_continues_the_spring_and_holds_a_stick() {
        let edges = FrictionEdges {
            stiffness: 100.0,
            ..edge(1)
        };
        let node = edges.nodes[0];
        // T_n = −3 on a bound μ N = 0.5 × 10 = 5: Δu = 0.01 gives −4 (stick)
        let (t, k, state) = edges.tangential_force(&node, 0.01, 10.0, -3.0, false);
        assert_eq!((t, k, state), (-4.0, 100.0, ContactState::Stick));
        // Δu = 0.03 would give −6: slip at −5
        let (t, k, state) = edges.tangential_force(&node, 0.03, 10.0, -3.0, false);
        let slip = ContactState::Slip { direction: 1.0 };
        assert_eq!((t, k, state), (-5.0, 0.0, slip));
        // held in stick: the spring past the bound
        let (t, k, state) = edges.tangential_force(&node, 0.03, 10.0, -3.0, true);
        assert_eq!((t, k, state), (-6.0, 100.0, ContactState::Stick));
    }

    /// A step starts open only where the last step's filtered reaction was
    /// not compressive and the soil moves away; after the solve, a closed
    /// patch in net tension opens as a whole (not a compressed one with a
    /// tensile node), and open nodes moved into the edge close.
    #[test]
    fn contacts_open_under_tension_and_close_on_approach() {
        let edges = edge(7);
        let last = [0.0, 0.0, 2.0, -3.0, -1.0, 0.0, 0.0];
        let leaving = [1.0, -1.0, 1.0, 1.0, 1.0, 1.0, 1.0];
        let open = edges.open_at_start(|n| n != 6, |c| last[c.node], |c| leaving[c.node]);
        // filtered: 0, 1/2, 1/4, −5/4, −5/4, −1/3
        assert_eq!(open, [true, false, false, true, true, true, false]);
        // closed patch 1..=2 in net tension opens; node 0 moved into the
        // edge closes, nodes 3..=5 moved away or stayed
        let open = [true, false, false, true, true, true, false];
        let reaction = [0.0, 1.0, -2.0, 0.0, 0.0, 0.0, 0.0];
        let motion = [-1e-3, 0.0, 0.0, 1e-3, 0.0, -1e-10, 0.0];
        let changes = edges.contact_changes(
            |n| n != 6,
            &open,
            |c| reaction[c.node],
            |c| motion[c.node],
            1e-9,
        );
        assert_eq!(changes, [0, 1, 2]);
        // a compressed patch with a tensile node stays closed
        let reaction = [0.0, 3.0, -1.0, 0.0, 0.0, 0.0, 0.0];
        let none = edges.contact_changes(|n| n != 6, &open, |c| reaction[c.node], |_| 0.0, 1e-9);
        assert!(none.is_empty(), "{none:?}");
    }

    /// `n` nodes of one frictional base line.
    fn edge(n: usize) -> FrictionEdges {
        FrictionEdges {
            nodes: (0..n)
                .map(|node| FrictionNode {
                    node,
                    normal: 1,
                    inward: 1.0,
                    mu: 0.5,
                    line: 0,
                })
                .collect(),
            ..Default::default()
        }
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
