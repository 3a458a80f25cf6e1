//! Nonlocal averaging over material points (theory §6, \[D33\]–\[D36\]; paper eq. 6).
//!
//! The paper replaces the local equivalent plastic strain by its nonlocal counterpart
//! (paper eq. 6), `ε̄(x) = ∫ w(x, ξ) ε(ξ) dξ`, with the Galavi–Schweiger radial weight
//! [`weight`] (\[D33\]). Discretised with the material-point (MP) volumes as quadrature weights
//! and renormalised so that a uniform field is reproduced also near free surfaces (\[D34\]):
//!
//! ```text
//!     W_pq = w(|x_p − x_q|) V_q / Σ_s w(|x_p − x_s|) V_s,    |x_p − x_q| ≤ R_c = cutoff · l_s
//! ```
//!
//! where the sums run over MPs of the same group (material) only. The engine applies the
//! operator to the increment of the local equivalent plastic strain, `κ̄_p = κ̄_p(n) +
//! Σ_q W_pq Δκ_q` (\[D35\]), once per Newton iteration with the lagged increments (\[D36\]); this
//! module only provides the linear operator `field ↦ W · field` ([`NonlocalAverager::average`]).
//!
//! # Implementation
//!
//! * A cell-linked list of bin size `R_c` (enlarged by a relative 1e-9 so that floating-point
//!   rounding in the bin index can never hide a neighbour at distance exactly `R_c`). It is
//!   stored without a dense grid: MPs are sorted by the key `(group, bin_y, bin_x, sub-bin)`,
//!   the sub-bins splitting a bin into patches of about 128 MPs. Memory is `O(N)` whatever the
//!   spread of the points.
//! * Tiles: the key-ordered MPs are cut into runs of ≤ 128 MPs of one bin row (compact
//!   patches, thanks to the sub-bins), and every pair of tiles whose bounding boxes come
//!   within `R_c` is listed once (`SymmetricPlan`). All sums run over tile pairs: one task per
//!   pair, private partial sums for both tiles, then per MP the partials in a fixed pair
//!   order, so every result is bit-identical for any number of rayon threads.
//! * The denominators `Σ_s w V_s` are computed once per operator, at the first call with a
//!   nonzero field (so never in an elastic step), evaluating the kernel once per unordered
//!   pair. The same pass gives the numerators of a mostly nonzero field without cache, in the
//!   denominators' order: a field equal to 1 is reproduced bit-exactly and any uniform field
//!   to a few ulps. The first average of an operator (an explicit step's only one) forms
//!   denominators and numerators in one such pass, each kernel evaluated once for both
//!   (measured on the explicit vertical cut, h = 0.1 m, to t = 0.25 s, one thread: nonlocal
//!   stage 16.4 → 9.3 s, wall 20.3 → 13.1 s).
//! * Weight cache for \[D36\]: the weights are fixed within a step while `average` runs once
//!   per Newton iteration, and only the plastic MPs (`Δκ_q ≠ 0`) are sources.
//!   [`NonlocalAverager::cache_sources`] stores, for every tile pair around a source tile, the
//!   dense block of `w(|x_p − x_q|)` (8 bytes a pair of MPs, no index; at the first call filled
//!   by the denominators' pass itself). `w` is symmetric, so one block read serves both tiles:
//!   row dot products for the receivers of one, row-wise axpys from the sources of the other.
//!   Measured on the biaxial lattice (6,000 MPs, ~4,700 neighbours each, every MP a source):
//!   7 ms per average against 34 ms with the gather lists of (receiver, source, `w V`) it
//!   replaces, and 92 ms against 404 ms for denominators plus cache. The stored weights are
//!   bounded by a budget (default [`DEFAULT_PAIR_BUDGET`]); tile pairs beyond it, and
//!   uncached pairs with a source, are evaluated on the fly.
//! * [`NonlocalAverager::average`] skips every tile pair whose source tile has no nonzero
//!   entry; the result equals the uncached evaluation up to summation order (tested to
//!   1e−12 relative to `max|field|`).
//! * Culling within a tile pair: a row whose MP lies farther than `R_c` from the other
//!   tile's bounding box is skipped, and so is every chunk of 16 columns whose own box
//!   lies beyond `R_c` of the row's MP (`weight_row_culled`): their weights are all 0, so
//!   the sums keep their bits. Tile boxes are coarse (a tile may span several sub-bins): on
//!   the explicit nonlocal vertical cut (h = 0.1 m, to t = 0.2 s) only 48 % of the pairs
//!   evaluated without culling lie within `R_c`; skipped rows held 19 % of the
//!   evaluations and skipped chunks a further 21 %. Nonlocal stage, one thread, the same
//!   outputs: 6.40 → 5.47 s (rows) → 5.3 s (chunks); at h = 0.0625 m to t = 0.12 s,
//!   22.1 → 18.3–19.0 s → 18.1 s.

mod averager;
mod grid;
mod kernel;
mod parameters;
mod plan;
#[cfg(test)]
mod tests;

pub use averager::{CacheStats, NonlocalAverager};
pub use grid::GridAverager;
pub use kernel::weight;
pub use parameters::{NonlocalAveraging, NonlocalError, NonlocalSpec, NonlocalUpdate};

// the private items the tests reach through `use super::*`
#[cfg(test)]
use averager::{BinKey, SourceList};
#[cfg(test)]
use kernel::exp_nonpositive;
#[cfg(test)]
use plan::Tile;

/// Default cutoff factor: `R_c = 3 l_s` (theory §6 / decision log item 12). Beyond `3 l_s` the
/// area-weighted tail of [`weight`] holds 4.4e−4 of its integral.
pub const DEFAULT_CUTOFF_FACTOR: f64 = 3.0;

/// Relative enlargement of the bin size over `R_c`, so that two points at a distance `≤ R_c`
/// always lie in the same or adjacent bins despite rounding in `floor((x − x0) / bin)`.
const BIN_SAFETY: f64 = 1.0 + 1e-9;

/// Minimum number of output MPs per rayon task.
const MIN_CHUNK: usize = 64;

/// Default budget of stored weights of [`NonlocalAverager::cache_sources`]: 64 Mi weights,
/// 8 bytes each (512 MiB). Tiles beyond it are evaluated on the fly (theory §6 warns that a
/// full pair list of the footing at h = 0.1 would hold ~350M pairs).
pub const DEFAULT_PAIR_BUDGET: usize = 64 << 20;

/// MPs per tile of the symmetric pair pass ([`plan::SymmetricPlan`]).
const TILE: usize = 128;

/// MPs per column chunk of a tile: the pair passes skip a chunk whose bounding box lies
/// beyond `R_c` of the row's MP ([`kernel::weight_row_culled`]).
const CHUNK: usize = 16;
