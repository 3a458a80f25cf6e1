//! Nodal fields that are written at the active nodes only ([`NodalField`]).

use rayon::prelude::*;

/// Nodes handed to one rayon task at least, in the passes over nodes.
pub const NODES_PER_TASK: usize = 512;

/// The zero of a nodal value (the value of a node no point reaches).
pub trait NodalValue: Copy + Send + Sync {
    /// Zero.
    const ZERO: Self;
}

impl NodalValue for f64 {
    const ZERO: Self = 0.0;
}

impl<const K: usize> NodalValue for [f64; K] {
    const ZERO: Self = [0.0; K];
}

/// One value per grid node, zero ([`NodalValue::ZERO`]) except at the nodes of its
/// last refill. A refill over the active nodes touches only those and the
/// ones of the refill before (set back to zero), so that a pass costs the
/// active nodes, not the grid: the explicit step on a grid much larger than
/// the body (the vertical cut's run-out room) no longer pays for the empty
/// nodes. Read it as a slice indexed by grid node.
#[derive(Clone, Debug)]
pub struct NodalField<T> {
    values: Vec<T>,
    /// The nodes of the last refill (increasing).
    written: Vec<u32>,
    /// The values of the nodes being refilled, in their order.
    staging: Vec<T>,
}

impl<T: NodalValue> NodalField<T> {
    /// `value(node)` at the nodes `nodes` (increasing; computed in parallel)
    /// and zero at the other nodes of a grid of `node_count` nodes.
    pub fn refill(
        &mut self,
        node_count: usize,
        nodes: &[u32],
        value: impl Fn(usize) -> T + Sync + Send,
    ) {
        self.staging.clear();
        self.staging.par_extend(
            nodes
                .par_iter()
                .with_min_len(NODES_PER_TASK)
                .map(|&node| value(node as usize)),
        );
        self.zero_written(node_count);
        for (&node, &v) in nodes.iter().zip(&self.staging) {
            self.values[node as usize] = v;
        }
        self.written.extend_from_slice(nodes);
    }

    /// Every value zero again (the grid has `node_count` nodes).
    fn zero_written(&mut self, node_count: usize) {
        if self.values.len() != node_count {
            self.values.clear();
            self.values.resize(node_count, T::ZERO);
        } else {
            for &node in &self.written {
                self.values[node as usize] = T::ZERO;
            }
        }
        self.written.clear();
    }

    /// The values, one per grid node, as a vector.
    pub fn into_vec(self) -> Vec<T> {
        self.values
    }

    /// The nodes of the last refill (increasing).
    pub fn written(&self) -> &[u32] {
        &self.written
    }

    /// The values, to be changed at the nodes of the last refill only (the
    /// others must stay zero).
    pub fn values_mut(&mut self) -> &mut [T] {
        &mut self.values
    }
}

impl<T> Default for NodalField<T> {
    fn default() -> Self {
        Self {
            values: Vec::new(),
            written: Vec::new(),
            staging: Vec::new(),
        }
    }
}

/// [`NodalField::refill`] of several fields at once from one evaluation per
/// node: `value(node)[k]` goes to `fields[k]`; `staging` is the buffer of the
/// values in node order.
pub fn refill_fields<T: NodalValue, const N: usize>(
    fields: [&mut NodalField<T>; N],
    node_count: usize,
    nodes: &[u32],
    staging: &mut Vec<[T; N]>,
    value: impl Fn(usize) -> [T; N] + Sync + Send,
) {
    staging.clear();
    staging.par_extend(
        nodes
            .par_iter()
            .with_min_len(NODES_PER_TASK)
            .map(|&node| value(node as usize)),
    );
    for (k, field) in fields.into_iter().enumerate() {
        field.zero_written(node_count);
        for (&node, v) in nodes.iter().zip(staging.iter()) {
            field.values[node as usize] = v[k];
        }
        field.written.extend_from_slice(nodes);
    }
}

impl<T> std::ops::Deref for NodalField<T> {
    type Target = [T];

    fn deref(&self) -> &[T] {
        &self.values
    }
}
