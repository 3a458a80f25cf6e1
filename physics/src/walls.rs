//! Walls: the grid edges whose normal dof is held at every node, by a
//! `[[bc.fixed]]` line (the paper's no-slip base, rollers) or a
//! `[[bc.friction]]` line (theory §10.4). The soil cannot cross a wall, and
//! the commit stage of both integrators keeps every material point on the
//! soil's side of it (theory eq. W1), booking the kinetic energy that takes
//! as boundary work (theory B2).
//!
//! The nodes of a wall never move into it, but a point moves by
//! Σ_i N_ip Δu_i (D14), which also weighs the nodes one cell in. With uGIMP
//! the point's domain is clipped at the edge, and that weight stays at least
//! l_p/(2h) (1/8 with 2 × 2 points per cell) however close the point comes:
//! soil squeezed against the wall carries the point through it at an eighth
//! of the speed one cell in. Measured on the friction cut at h = 0.0833 m
//! (explicit, nonlocal): the point that stopped the run sat 6 µm above the
//! base with weight 0.125 on nodes moving down at 4.9 and 8.6 m/s while the
//! base nodes were held, and left by 0.18 mm in one step.

use crate::bc::{Constraints, DofConstraint};
use crate::grid::Grid;
use crate::particles::Particles;

/// The walls of a run: the grid edges the soil cannot cross.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Walls {
    /// `edges[d][side]`: the coordinate of the grid edge normal to axis d
    /// (0: x, 1: y), the lower one (side 0) or the upper one (side 1), when
    /// that edge is a wall.
    pub edges: [[Option<f64>; 2]; 2],
}

impl Walls {
    /// The grid edges whose every node has its normal dof fixed in
    /// `constraints` (the normal dofs of frictional edges are held there
    /// too). A prescribed edge moves and is not a wall.
    pub fn of(grid: &Grid, constraints: &Constraints) -> Self {
        let nodes = [grid.cells[0] + 1, grid.cells[1] + 1];
        let node = |d: usize, index: usize, k: usize| match d {
            0 => k * nodes[0] + index,
            _ => index * nodes[0] + k,
        };
        let max = grid.extent_max();
        let mut walls = Self::default();
        for d in 0..2 {
            let sides = [(0, grid.origin[d]), (grid.cells[d], max[d])];
            for (side, (index, value)) in sides.into_iter().enumerate() {
                let held = (0..nodes[1 - d])
                    .all(|k| constraints.dof[2 * node(d, index, k) + d] == DofConstraint::Fixed);
                walls.edges[d][side] = held.then_some(value);
            }
        }
        walls
    }

    /// Whether the run has a wall.
    pub fn any(&self) -> bool {
        self.edges.iter().flatten().any(Option::is_some)
    }

    /// W1 for one point of mass `mass`: a point beyond a wall is put back on
    /// it, and the velocity component it still has into the wall is
    /// removed. Returns the kinetic energy removed, ½ m v_n² (B2), kJ/m.
    pub fn hold(&self, position: &mut [f64; 2], velocity: &mut [f64; 2], mass: f64) -> f64 {
        let mut removed = 0.0;
        for d in 0..2 {
            for (side, edge) in self.edges[d].iter().enumerate() {
                let Some(edge) = *edge else { continue };
                let inward = if side == 0 { 1.0 } else { -1.0 };
                if inward * (position[d] - edge) >= 0.0 || position[d].is_nan() {
                    continue;
                }
                position[d] = edge;
                if inward * velocity[d] < 0.0 {
                    removed += 0.5 * mass * velocity[d] * velocity[d];
                    velocity[d] = 0.0;
                }
            }
        }
        removed
    }

    /// [`Self::hold`] for every point of `points`; returns the kinetic
    /// energy removed, summed in point order (kJ/m).
    pub fn hold_points(&self, points: &mut Particles) -> f64 {
        if !self.any() {
            return 0.0;
        }
        let Particles {
            position,
            velocity,
            mass,
            ..
        } = points;
        position
            .iter_mut()
            .zip(velocity.iter_mut())
            .zip(mass.iter())
            .map(|((x, v), &m)| self.hold(x, v, m))
            .sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A frictional base (y = 0) and rollers on x = 0 are walls; the top and
    /// the right edge, free, are not.
    fn base_and_left_wall() -> Walls {
        Walls {
            edges: [[Some(0.0), None], [Some(0.0), None]],
        }
    }

    /// On a 4 × 2 grid from (1, 2), h = 0.5: the edge y = 2 held in y at
    /// every node and x = 3 held in x at every node are walls; x = 1, held
    /// in y only (the wrong component), and y = 3, held at all nodes but
    /// one, are not.
    #[test]
    fn an_edge_is_a_wall_when_every_node_holds_its_normal_dof() {
        let grid = Grid::bilinear([1.0, 2.0], 0.5, [4, 2]);
        let mut constraints = Constraints {
            dof: vec![DofConstraint::Free; 2 * grid.node_count()],
        };
        let mut hold = |i: usize, j: usize, d: usize| {
            constraints.dof[2 * (j * 5 + i) + d] = DofConstraint::Fixed
        };
        for i in 0..5 {
            hold(i, 0, 1);
        }
        for i in 0..4 {
            hold(i, 2, 1);
        }
        for j in 0..3 {
            hold(4, j, 0);
            hold(0, j, 1);
        }
        let walls = Walls::of(&grid, &constraints);
        assert_eq!(walls.edges, [[None, Some(3.0)], [Some(2.0), None]]);
    }

    /// A point carried 0.2 mm through the base while moving down at 1 m/s is
    /// put back on it, its downward velocity (and ½ m v_y² of kinetic
    /// energy) removed and its slide kept; a point above the base, or one
    /// beyond it but already moving away, keeps its velocity.
    #[test]
    fn a_point_through_the_base_is_put_back_and_stops_entering_it() {
        let walls = base_and_left_wall();
        let (mut x, mut v) = ([8.07, -1.8e-4], [9.0, -1.0]);
        let removed = walls.hold(&mut x, &mut v, 0.5);
        assert_eq!(x, [8.07, 0.0]);
        assert_eq!(v, [9.0, 0.0]);
        assert!((removed - 0.25).abs() < 1e-15, "{removed}");

        let (mut x, mut v) = ([8.07, 1e-6], [9.0, -1.0]);
        assert_eq!(walls.hold(&mut x, &mut v, 0.5), 0.0);
        assert_eq!((x, v), ([8.07, 1e-6], [9.0, -1.0]));

        let (mut x, mut v) = ([-1e-5, -1e-5], [0.5, 0.1]);
        assert_eq!(walls.hold(&mut x, &mut v, 0.5), 0.0);
        assert_eq!((x, v), ([0.0, 0.0], [0.5, 0.1]));
    }

    /// Over a set of points, the energy removed is the drop of their kinetic
    /// energy Σ ½ m v² (what the budget E1 books in B).
    #[test]
    fn the_energy_removed_is_the_drop_of_kinetic_energy() {
        let walls = base_and_left_wall();
        let mut points = Particles {
            position: vec![[1.0, -1e-4], [-2e-4, 0.3], [2.0, 0.5], [-1e-4, -1e-4]],
            velocity: vec![[3.0, -2.0], [-0.5, 4.0], [1.0, -7.0], [-1.5, -0.25]],
            mass: vec![0.2, 0.3, 0.4, 0.1],
            ..Particles::default()
        };
        let kinetic = |p: &Particles| -> f64 {
            (0..4)
                .map(|i| 0.5 * p.mass[i] * (p.velocity[i][0].powi(2) + p.velocity[i][1].powi(2)))
                .sum()
        };
        let before = kinetic(&points);
        let removed = walls.hold_points(&mut points);
        let after = kinetic(&points);
        assert!(
            (before - after - removed).abs() < 1e-14,
            "{before} {after} {removed}"
        );
        let expected = 0.5 * (0.2 * 4.0 + 0.3 * 0.25 + 0.1 * (2.25 + 0.0625));
        assert!(
            (removed - expected).abs() < 1e-14,
            "{removed} vs {expected}"
        );
        assert!(points.position.iter().all(|x| x[0] >= 0.0 && x[1] >= 0.0));
    }
}
