//! Nonlocal averaging over material points (DESIGN §6, \[D33\]–\[D36\]; paper eq. 6).
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
//!   stored without a dense grid: MPs are sorted by the key `(group, bin_y, bin_x)`, so that the
//!   three bins `bin_x − 1 ..= bin_x + 1` of one bin row of one group form a single contiguous
//!   slice, found by binary search. Memory is `O(N)` whatever the spread of the points.
//! * The denominators `Σ_s w V_s` are computed once per operator, at the first call with a
//!   nonzero field (so never in an elastic step), over all pairs (no pair list of all MPs is
//!   stored: neighbour counts reach ~7000 per MP, DESIGN §6), by a symmetric pass that evaluates the kernel once per unordered pair: the key-ordered MPs are
//!   cut into tiles of ≤ 128 MPs of one bin row, every pair of nearby tiles is a parallel task
//!   with private partial sums for both tiles, and the partials are added per MP in a fixed
//!   tile-pair order. The same pass gives the numerators of a mostly nonzero field without
//!   cache.
//! * Weight cache for \[D36\]: the weights are fixed within a step while `average` runs once
//!   per Newton iteration, and only the plastic MPs (`Δκ_q ≠ 0`) are sources.
//!   [`NonlocalAverager::cache_sources`] stores `w(|x_p − x_q|) V_q` for a source set (the
//!   engine passes the increments of the first iteration of the step, later iterations add
//!   further blocks for sources that became plastic), for all receivers within `R_c`, in
//!   *gather* CSR form: per receiver `p` the list `(slot(q), w V_q)`. An iteration then costs
//!   one multiply-add per cached pair (12 bytes streamed, no `sqrt`/`exp`) instead of a
//!   distance, a square root and an exponential. Gather rather than scatter (per source a
//!   receiver list) because every output entry is then summed by one task in a fixed order
//!   (deterministic, no atomics or per-thread buffers) and a source that stopped yielding costs
//!   one multiply by zero. The pair count is bounded by a budget (default
//!   [`DEFAULT_PAIR_BUDGET`]); sources beyond it, and uncached sources with `field_q ≠ 0`, are
//!   evaluated on the fly.
//! * [`NonlocalAverager::average`] compacts the nonzero uncached entries of the field (in the
//!   sorted order) and *gathers* for every output MP first the cached rows, then the on-the-fly
//!   sources. Every output entry is summed by one task in a fixed order (cache blocks, four
//!   interleaved partial sums per row; on-the-fly rows `dy = −1, 0, 1`, then sorted order): the
//!   result is bit-identical for any number of rayon threads, and equals the uncached
//!   evaluation up to summation order (tested to 1e−12 relative to `max|field|`).
//! * Without a cache and for a field nonzero at more than half of the MPs, the numerator is
//!   computed by the symmetric pass of the denominators, in exactly their order, with the term
//!   `w · (V_q f_q)` against `w · V_q`; a field equal to 1 is thus reproduced bit-exactly and
//!   any uniform field to a few ulps.

use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::sync::OnceLock;

/// Default cutoff factor: `R_c = 3 l_s` (DESIGN §6 / decision log item 12). Beyond `3 l_s` the
/// area-weighted tail of [`weight`] holds 4.4e−4 of its integral.
pub const DEFAULT_CUTOFF_FACTOR: f64 = 3.0;

/// Relative enlargement of the bin size over `R_c`, so that two points at a distance `≤ R_c`
/// always lie in the same or adjacent bins despite rounding in `floor((x − x0) / bin)`.
const BIN_SAFETY: f64 = 1.0 + 1e-9;

/// Minimum number of output MPs per rayon task.
const MIN_CHUNK: usize = 64;

/// Default budget of cached weight pairs of [`NonlocalAverager::cache_sources`]: 64 Mi pairs,
/// 12 bytes each (768 MiB). Sources beyond it are evaluated on the fly (DESIGN §6 warns that
/// a full pair list of the footing at h = 0.1 would hold ~350M pairs).
pub const DEFAULT_PAIR_BUDGET: usize = 64 << 20;

/// Maximum number of CSR blocks of the cache; later new sources are evaluated on the fly.
const MAX_BLOCKS: usize = 8;

/// Receivers per chunk of a cache block (unit of parallel work of the cached average).
const CACHE_CHUNK: usize = 128;

/// MPs per tile of the symmetric pair pass ([`SymmetricPlan`]).
const TILE: usize = 128;

/// Slot marker of an MP that is not cached.
const NO_SLOT: u32 = u32::MAX;

/// Parameters of the nonlocal averaging (DESIGN §6, \[D33\]–\[D34\]; paper eq. 6).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct NonlocalParameters {
    /// Material length scale `l_s` (m) of the weight \[D33\]; must be finite and `> 0`.
    pub length_scale: f64,
    /// Cutoff radius in units of `l_s`: `R_c = cutoff_factor · l_s` (default 3, DESIGN §6);
    /// must be finite and `> 0`.
    pub cutoff_factor: f64,
}

impl NonlocalParameters {
    /// Parameters with the given length scale `l_s` and the default cutoff `R_c = 3 l_s`
    /// ([`DEFAULT_CUTOFF_FACTOR`], DESIGN §6).
    pub fn new(length_scale: f64) -> Self {
        Self {
            length_scale,
            cutoff_factor: DEFAULT_CUTOFF_FACTOR,
        }
    }

    /// Cutoff radius `R_c = cutoff_factor · l_s` (m), DESIGN §6.
    pub fn cutoff_radius(&self) -> f64 {
        self.cutoff_factor * self.length_scale
    }

    /// Checks `l_s` and the cutoff factor (finite and strictly positive).
    pub fn validate(&self) -> Result<(), NonlocalError> {
        if !(self.length_scale.is_finite() && self.length_scale > 0.0) {
            return Err(NonlocalError::InvalidLengthScale(self.length_scale));
        }
        if !(self.cutoff_factor.is_finite() && self.cutoff_factor > 0.0) {
            return Err(NonlocalError::InvalidCutoffFactor(self.cutoff_factor));
        }
        if !(self.cutoff_radius().is_finite() && self.cutoff_radius() > 0.0) {
            return Err(NonlocalError::InvalidCutoffFactor(self.cutoff_factor));
        }
        Ok(())
    }
}

/// Errors of the nonlocal averaging (invalid parameters or inconsistent inputs).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum NonlocalError {
    /// `l_s` is not finite or not strictly positive (\[D33\]).
    #[error("nonlocal length scale must be finite and > 0, got {0}")]
    InvalidLengthScale(f64),
    /// The cutoff factor is not finite or not strictly positive (DESIGN §6).
    #[error("nonlocal cutoff factor must be finite and > 0, got {0}")]
    InvalidCutoffFactor(f64),
    /// Positions, volumes and groups of the MPs have different lengths.
    #[error(
        "nonlocal input lengths differ: {positions} positions, {volumes} volumes, {groups} groups"
    )]
    InputLengthMismatch {
        /// Number of positions.
        positions: usize,
        /// Number of volumes.
        volumes: usize,
        /// Number of group ids.
        groups: usize,
    },
    /// A field or output slice does not have one entry per MP.
    #[error(
        "nonlocal field length mismatch: {expected} material points, field {field}, output {out}"
    )]
    FieldLengthMismatch {
        /// Number of MPs of the averager.
        expected: usize,
        /// Length of the field slice.
        field: usize,
        /// Length of the output slice.
        out: usize,
    },
    /// A position coordinate is NaN or infinite.
    #[error("material point {index}: non-finite position {position:?}")]
    NonFinitePosition {
        /// Index of the offending MP.
        index: usize,
        /// Its position.
        position: [f64; 2],
    },
    /// A volume is negative, NaN or infinite.
    #[error("material point {index}: volume must be finite and >= 0, got {volume}")]
    InvalidVolume {
        /// Index of the offending MP.
        index: usize,
        /// Its volume.
        volume: f64,
    },
}

/// Galavi–Schweiger weight \[D33\]: `w(r) = (r / l_s²) · exp(−(r/l_s)²)` (paper eq. 6, DESIGN §6).
///
/// Zero at `r = 0` (an MP never weights itself), maximal at `r = l_s/√2`; no cutoff is applied
/// here (the cutoff belongs to [`NonlocalAverager`]).
pub fn weight(r: f64, length_scale: f64) -> f64 {
    let u = r / length_scale;
    (r / (length_scale * length_scale)) * (-(u * u)).exp()
}

/// The kernel used by every sum of this module: \[D33\] evaluated from `r²` and `1/l_s²`.
/// One shared definition keeps denominators, numerators and cached weights bit-consistent.
#[inline(always)]
fn kernel(r2: f64, inv_l2: f64) -> f64 {
    r2.sqrt() * inv_l2 * (-(r2 * inv_l2)).exp()
}

/// Sort key of an MP: group first, then bin row, then bin column.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
struct BinKey {
    group: u16,
    by: i64,
    bx: i64,
}

/// A list of sources in `BinKey` order (structure of arrays).
#[derive(Debug, Clone, Default)]
struct SourceList {
    keys: Vec<BinKey>,
    x: Vec<f64>,
    y: Vec<f64>,
    /// `V_q` (full list) or `V_q f_q` (compacted field).
    s: Vec<f64>,
}

impl SourceList {
    fn with_capacity(n: usize) -> Self {
        Self {
            keys: Vec::with_capacity(n),
            x: Vec::with_capacity(n),
            y: Vec::with_capacity(n),
            s: Vec::with_capacity(n),
        }
    }

    fn push(&mut self, key: BinKey, x: f64, y: f64, s: f64) {
        self.keys.push(key);
        self.x.push(x);
        self.y.push(y);
        self.s.push(s);
    }

    /// Calls `visit(j, r², s_j)` for every source `j` (index in this list) of `key.group` in
    /// the 3×3 bins around `key` with `r² ≤ rc2`, in a fixed order (rows `by − 1, by, by + 1`,
    /// then list order).
    #[inline]
    fn for_each_neighbour(
        &self,
        key: BinKey,
        px: f64,
        py: f64,
        rc2: f64,
        mut visit: impl FnMut(usize, f64, f64),
    ) {
        for dy in -1..=1 {
            let lo_key = BinKey {
                group: key.group,
                by: key.by + dy,
                bx: key.bx - 1,
            };
            let hi_key = BinKey {
                bx: key.bx + 1,
                ..lo_key
            };
            let lo = self.keys.partition_point(|k| *k < lo_key);
            let hi = lo + self.keys[lo..].partition_point(|k| *k <= hi_key);
            let (xs, ys, ss) = (&self.x[lo..hi], &self.y[lo..hi], &self.s[lo..hi]);
            for j in 0..xs.len() {
                let dx = px - xs[j];
                let dyv = py - ys[j];
                let r2 = dx * dx + dyv * dyv;
                if r2 <= rc2 {
                    visit(lo + j, r2, ss[j]);
                }
            }
        }
    }
}

/// Nonlocal averaging operator `W` of \[D34\] over a fixed set of MPs (start-of-step positions
/// and volumes), applied as in \[D35\]/\[D36\] (paper eq. 6).
///
/// Built once per step by [`NonlocalAverager::new`] (bins; denominators at first use). Optionally
/// [`NonlocalAverager::cache_sources`] stores the weights of the step's plastic sources; every
/// [`NonlocalAverager::average`] call then costs one multiply-add per cached pair plus one
/// kernel evaluation per pair `(p, q)` with `q` uncached, `field_q ≠ 0` and
/// `|x_p − x_q| ≤ R_c`. Results do not depend on the number of rayon threads.
#[derive(Debug, Clone)]
pub struct NonlocalAverager {
    params: NonlocalParameters,
    /// Squared cutoff radius.
    rc2: f64,
    /// `1 / l_s²`.
    inv_l2: f64,
    /// Bin size (`R_c` times [`BIN_SAFETY`]).
    bin: f64,
    /// Lower-left corner of the bounding box (bin origin).
    origin: [f64; 2],
    /// All MPs in key order, `s = V_q`.
    sorted: SourceList,
    /// `order[k]` = original index of the `k`-th MP in key order.
    order: Vec<usize>,
    /// Denominators, neighbour counts and the symmetric pass plan, computed at the first call
    /// that needs them (a step whose fields are all zero, e.g. elastic, never does).
    weights: OnceLock<Weights>,
    /// Cached weights of the step (empty until [`NonlocalAverager::cache_sources`]).
    cache: WeightCache,
}

/// The `O(N · n_nb)` part of [`NonlocalAverager`] (\[D34\] denominators), in key order.
#[derive(Debug, Clone)]
struct Weights {
    /// Tiles of the symmetric pair pass (denominators, dense uncached numerators).
    plan: SymmetricPlan,
    /// `Σ_s w(|x_p − x_s|) V_s`; 0 for an isolated MP.
    den: Vec<f64>,
    /// Number of same-group neighbours within `R_c` of every MP (itself excluded): an upper
    /// bound of the cached pairs a source adds (budget check).
    counts: Vec<u32>,
    /// Neighbour count statistics (min, mean, max) over all MPs.
    stats: (usize, f64, usize),
}

/// Weights `w(|x_p − x_q|) V_q` of \[D34\] cached for a set of sources (the MPs plastic in the
/// step), reused by every [`NonlocalAverager::average`] call of the step (\[D36\]).
///
/// Every cached source has a *slot* (0, 1, … in the order of caching). The weights are held
/// in gather form, one CSR block per call of [`NonlocalAverager::cache_sources`] that added
/// sources: for each receiver `p` (key order) the `(slot, w V_q)` of the block's sources within
/// `R_c`, `q ≠ p`, in the fixed visiting order of the cell list.
#[derive(Debug, Clone, Default)]
struct WeightCache {
    /// `slot_of[k]` = slot of the MP with key-order index `k`, or [`NO_SLOT`].
    slot_of: Vec<u32>,
    /// `slot_key[s]` = key-order index of the MP in slot `s`.
    slot_key: Vec<u32>,
    /// CSR blocks, summed in this order.
    blocks: Vec<CacheBlock>,
    /// Total number of cached pairs over all blocks.
    pairs: usize,
    /// Maximum number of cached pairs (memory budget, 12 bytes a pair).
    budget: usize,
}

/// One block of [`WeightCache`]: CSR in gather form, split into chunks of [`CACHE_CHUNK`]
/// consecutive receivers (key order) so that it is built in one parallel pass without a
/// counting pass; chunk `c` holds the rows of receivers `c·CACHE_CHUNK ..`.
#[derive(Debug, Clone, Default)]
struct CacheBlock {
    chunks: Vec<CacheChunk>,
}

/// Rows of [`CACHE_CHUNK`] consecutive receivers of a [`CacheBlock`].
#[derive(Debug, Clone, Default)]
struct CacheChunk {
    /// Local row `i` is `row_ptr[i] .. row_ptr[i + 1]`.
    row_ptr: Vec<u32>,
    /// Slot of the source of each entry.
    slot: Vec<u32>,
    /// `w(|x_p − x_q|) V_q` of each entry.
    wv: Vec<f64>,
}

impl CacheChunk {
    /// `Σ_j wv_j f_slot(j)` over local row `i`, with four interleaved partial sums (fixed
    /// order, independent of the thread count).
    #[inline]
    fn row_dot(&self, i: usize, slot_field: &[f64]) -> f64 {
        let (lo, hi) = (self.row_ptr[i] as usize, self.row_ptr[i + 1] as usize);
        let (slots, wv) = (&self.slot[lo..hi], &self.wv[lo..hi]);
        let mut acc = [0.0f64; 4];
        let mut sc = slots.chunks_exact(4);
        let mut wc = wv.chunks_exact(4);
        for (s4, w4) in (&mut sc).zip(&mut wc) {
            for l in 0..4 {
                acc[l] += w4[l] * slot_field[s4[l] as usize];
            }
        }
        let mut tail = 0.0;
        for (s, w) in sc.remainder().iter().zip(wc.remainder()) {
            tail += w * slot_field[*s as usize];
        }
        ((acc[0] + acc[1]) + (acc[2] + acc[3])) + tail
    }
}

/// Cache statistics of a [`NonlocalAverager`] (see [`NonlocalAverager::cache_stats`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct CacheStats {
    /// Number of cached sources.
    pub sources: usize,
    /// Number of cached pairs `(p, q)`.
    pub pairs: usize,
    /// Number of CSR blocks (one per [`NonlocalAverager::cache_sources`] call that added
    /// sources).
    pub blocks: usize,
    /// Pair budget ([`NonlocalAverager::set_pair_budget`]).
    pub budget: usize,
}

impl NonlocalAverager {
    /// Builds the operator \[D34\] from start-of-step positions `x_q`, volumes `V_q` and a group
    /// (material) id per MP; only MPs of the same group average together (DESIGN §6).
    ///
    /// Sorts the MPs into a cell-linked list with bins of size `R_c`. The weight denominators
    /// `Σ_s w(|x_p − x_s|) V_s` (sum over same-group MPs within `R_c`) are computed once, at
    /// the first call that needs them (an all-zero field, e.g. Δκ of an elastic step, does
    /// not). An MP whose denominator is 0 (isolated, or only zero-volume/coincident
    /// neighbours) gets `W_pp = 1`, i.e. keeps its own value.
    ///
    /// # Errors
    /// [`NonlocalError`] if `l_s` or the cutoff factor is not finite and positive, if the
    /// slices have different lengths, if a position is not finite, or if a volume is negative
    /// or not finite.
    pub fn new(
        params: &NonlocalParameters,
        positions: &[[f64; 2]],
        volumes: &[f64],
        groups: &[u16],
    ) -> Result<Self, NonlocalError> {
        params.validate()?;
        validate_inputs(positions, volumes, groups)?;
        let n = positions.len();
        let rc = params.cutoff_radius();
        let bin = rc * BIN_SAFETY;
        let inv_l2 = 1.0 / (params.length_scale * params.length_scale);
        let rc2 = rc * rc;

        let mut origin = [f64::INFINITY; 2];
        for p in positions {
            origin[0] = origin[0].min(p[0]);
            origin[1] = origin[1].min(p[1]);
        }
        let key_of = |i: usize| BinKey {
            group: groups[i],
            by: ((positions[i][1] - origin[1]) / bin).floor() as i64,
            bx: ((positions[i][0] - origin[0]) / bin).floor() as i64,
        };
        let mut order: Vec<usize> = (0..n).collect();
        // Stable sort: ties (same bin) keep the original index order -> deterministic.
        order.sort_by_key(|&i| key_of(i));
        let mut sorted = SourceList::with_capacity(n);
        for &i in &order {
            sorted.push(key_of(i), positions[i][0], positions[i][1], volumes[i]);
        }

        Ok(Self {
            params: *params,
            rc2,
            inv_l2,
            bin,
            origin,
            sorted,
            order,
            weights: OnceLock::new(),
            cache: WeightCache {
                slot_of: vec![NO_SLOT; n],
                budget: DEFAULT_PAIR_BUDGET,
                ..WeightCache::default()
            },
        })
    }

    /// Denominators and neighbour counts (symmetric pass, [`SymmetricPlan`]), computed once.
    fn weights(&self) -> &Weights {
        self.weights.get_or_init(|| {
            let n = self.len();
            let plan = SymmetricPlan::new(&self.sorted, self.rc2);
            let results = plan.sums(&self.sorted, &self.sorted.s, self.rc2, self.inv_l2);
            let den: Vec<f64> = results.iter().map(|r| r.0).collect();
            let counts: Vec<u32> = results
                .iter()
                .map(|r| u32::try_from(r.1).unwrap_or(u32::MAX))
                .collect();
            let stats = if n == 0 {
                (0, 0.0, 0)
            } else {
                let min = results.iter().map(|r| r.1).min().unwrap_or(0);
                let max = results.iter().map(|r| r.1).max().unwrap_or(0);
                let mean = results.iter().map(|r| r.1 as f64).sum::<f64>() / n as f64;
                (min, mean, max)
            };
            Weights {
                plan,
                den,
                counts,
                stats,
            }
        })
    }

    /// Whether the denominators (\[D34\], the `O(N · n_nb)` pass) have been
    /// computed: by the first call that needed them.
    pub fn has_weights(&self) -> bool {
        self.weights.get().is_some()
    }

    /// Number of MPs of the operator.
    pub fn len(&self) -> usize {
        self.order.len()
    }

    /// True if the operator has no MPs.
    pub fn is_empty(&self) -> bool {
        self.order.is_empty()
    }

    /// The parameters the operator was built with.
    pub fn parameters(&self) -> &NonlocalParameters {
        &self.params
    }

    /// Denominators `Σ_s w(|x_p − x_s|) V_s` of \[D34\], in the original MP order (0 for an
    /// isolated MP, whose `W_pp = 1`).
    pub fn denominators(&self) -> Vec<f64> {
        let mut d = vec![0.0; self.len()];
        for (k, &i) in self.order.iter().enumerate() {
            d[i] = self.weights().den[k];
        }
        d
    }

    /// Applies the operator of \[D34\]: `out_p = Σ_q W_pq field_q` for a field given at every MP
    /// (original order), as used by \[D35\]/\[D36\] with `field = Δκ` (paper eq. 6).
    ///
    /// Sources cached by [`Self::cache_sources`] use their stored weights (one multiply-add
    /// per pair, also when `field_q = 0`); the other sources with `field_q ≠ 0` are evaluated on
    /// the fly (compacted first, then every output entry gathers from them), sources with
    /// `field_q = 0` outside the cache are skipped. Each `out_p` is summed in a fixed order by a
    /// single task (cache blocks in order, then the on-the-fly sources): the result is
    /// bit-identical for any number of rayon threads, and equals the uncached evaluation
    /// ([`Self::average_uncached`]) up to summation order. Isolated MPs (zero denominator) copy
    /// their own value (`W_pp = 1`). `out` is overwritten.
    ///
    /// # Errors
    /// [`NonlocalError::FieldLengthMismatch`] if `field` or `out` does not have [`Self::len`]
    /// entries.
    pub fn average(&self, field: &[f64], out: &mut [f64]) -> Result<(), NonlocalError> {
        self.average_impl(field, out, true)
    }

    /// The same operator as [`Self::average`] with every nonzero source evaluated on the fly,
    /// ignoring the cache (reference for tests and benchmarks; the behaviour before caching).
    ///
    /// # Errors
    /// As [`Self::average`].
    pub fn average_uncached(&self, field: &[f64], out: &mut [f64]) -> Result<(), NonlocalError> {
        self.average_impl(field, out, false)
    }

    fn check_field(&self, field: &[f64], out_len: usize) -> Result<(), NonlocalError> {
        let n = self.len();
        if field.len() != n || out_len != n {
            return Err(NonlocalError::FieldLengthMismatch {
                expected: n,
                field: field.len(),
                out: out_len,
            });
        }
        Ok(())
    }

    fn average_impl(
        &self,
        field: &[f64],
        out: &mut [f64],
        use_cache: bool,
    ) -> Result<(), NonlocalError> {
        self.check_field(field, out.len())?;
        if field.iter().all(|&f| f == 0.0) {
            // W · 0 = 0 (isolated MPs keep their own value, 0): no weights needed.
            out.fill(0.0);
            return Ok(());
        }
        let n = self.len();
        let cache = &self.cache;
        let weights = self.weights();
        let cached = use_cache && !cache.blocks.is_empty();
        // Field values of the cached sources, by slot.
        let slot_field: Vec<f64> = if cached {
            cache
                .slot_key
                .iter()
                .map(|&k| field[self.order[k as usize]])
                .collect()
        } else {
            Vec::new()
        };
        // Compact the nonzero sources outside the cache, keeping the key order of the list.
        let mut sources = SourceList::with_capacity(n / 4);
        for (k, &i) in self.order.iter().enumerate() {
            let f = field[i];
            if f != 0.0 && !(cached && cache.slot_of[k] != NO_SLOT) {
                sources.push(
                    self.sorted.keys[k],
                    self.sorted.x[k],
                    self.sorted.y[k],
                    self.sorted.s[k] * f,
                );
            }
        }
        let (rc2, inv_l2) = (self.rc2, self.inv_l2);
        // One output entry: cached blocks in order, then the on-the-fly sources.
        let entry = |k: usize, cached_num: f64| -> f64 {
            let den = weights.den[k];
            if den == 0.0 {
                return field[self.order[k]];
            }
            let mut num = cached_num;
            sources.for_each_neighbour(
                self.sorted.keys[k],
                self.sorted.x[k],
                self.sorted.y[k],
                rc2,
                |_, r2, s| num += kernel(r2, inv_l2) * s,
            );
            num / den
        };
        let mut out_sorted = vec![0.0; n];
        if !cached && 2 * sources.keys.len() > n {
            // Mostly nonzero field: the symmetric pass (each kernel once per unordered pair)
            // is cheaper than gathering every source per receiver. Its summation order is that
            // of the denominators, so a field of ones is reproduced bit-exactly.
            let s: Vec<f64> = self
                .order
                .iter()
                .zip(&self.sorted.s)
                .map(|(&i, &v)| v * field[i])
                .collect();
            let sums = weights.plan.sums(&self.sorted, &s, rc2, inv_l2);
            for (k, (o, (num, _))) in out_sorted.iter_mut().zip(sums).enumerate() {
                let den = weights.den[k];
                *o = if den == 0.0 {
                    field[self.order[k]]
                } else {
                    num / den
                };
            }
        } else if cached {
            out_sorted
                .par_chunks_mut(CACHE_CHUNK)
                .enumerate()
                .for_each(|(c, o)| {
                    for (i, oi) in o.iter_mut().enumerate() {
                        let mut num = 0.0;
                        for block in &cache.blocks {
                            num += block.chunks[c].row_dot(i, &slot_field);
                        }
                        *oi = entry(c * CACHE_CHUNK + i, num);
                    }
                });
        } else if !sources.keys.is_empty() {
            out_sorted
                .par_iter_mut()
                .with_min_len(MIN_CHUNK)
                .enumerate()
                .for_each(|(k, o)| *o = entry(k, 0.0));
        }
        for (k, &i) in self.order.iter().enumerate() {
            out[i] = out_sorted[k];
        }
        Ok(())
    }

    /// Caches the weights `w(|x_p − x_q|) V_q` (\[D34\]) of every source `q` with
    /// `candidates_q ≠ 0` that is not cached yet, for all receivers `p` within `R_c`, so that
    /// the following [`Self::average`] calls of the step (\[D36\]: one per Newton iteration)
    /// reuse them instead of re-evaluating the kernel. Typically `candidates = Δκ`.
    ///
    /// The new sources form one CSR block (gather form, built in parallel, deterministic).
    /// Sources are admitted in key order while the pair budget ([`Self::set_pair_budget`],
    /// bounded by each source's neighbour count) allows; the excess, and all new sources once
    /// the block limit (8) is reached or when fewer than `max(16, cached/16)` sources are new,
    /// stay uncached and are evaluated on the fly by [`Self::average`]. Returns the number of
    /// sources added.
    ///
    /// # Errors
    /// [`NonlocalError::FieldLengthMismatch`] if `candidates` does not have [`Self::len`]
    /// entries.
    pub fn cache_sources(&mut self, candidates: &[f64]) -> Result<usize, NonlocalError> {
        self.check_field(candidates, self.len())?;
        let n = self.len();
        if self.cache.blocks.len() >= MAX_BLOCKS {
            return Ok(0);
        }
        let new: Vec<usize> = (0..n)
            .filter(|&k| candidates[self.order[k]] != 0.0 && self.cache.slot_of[k] == NO_SLOT)
            .collect();
        if new.len() < (self.cache.slot_key.len() / 16).max(16) {
            return Ok(0);
        }
        // Budget: admit in key order while the (upper bound of the) pair count fits.
        let mut room = self.cache.budget.saturating_sub(self.cache.pairs);
        let mut admitted = SourceList::with_capacity(new.len());
        let mut admitted_slots = Vec::with_capacity(new.len());
        for &k in &new {
            let c = self.weights().counts[k] as usize;
            if c <= room {
                room -= c;
                let slot = self.cache.slot_key.len() as u32;
                self.cache.slot_of[k] = slot;
                self.cache.slot_key.push(k as u32);
                admitted_slots.push(slot);
                admitted.push(
                    self.sorted.keys[k],
                    self.sorted.x[k],
                    self.sorted.y[k],
                    self.sorted.s[k],
                );
            }
        }
        if admitted_slots.is_empty() {
            return Ok(0);
        }
        let block = self.build_block(&admitted, &admitted_slots);
        self.cache.pairs += block.chunks.iter().map(|c| c.wv.len()).sum::<usize>();
        self.cache.blocks.push(block);
        Ok(admitted_slots.len())
    }

    /// CSR block (gather form) of the sources `list` (slots `slots`) for all receivers, built
    /// in one parallel pass over chunks of [`CACHE_CHUNK`] receivers.
    fn build_block(&self, list: &SourceList, slots: &[u32]) -> CacheBlock {
        let n = self.len();
        let inv_l2 = self.inv_l2;
        let counts = &self.weights().counts;
        let chunks = (0..n.div_ceil(CACHE_CHUNK))
            .into_par_iter()
            .map(|c| {
                let rows = c * CACHE_CHUNK..((c + 1) * CACHE_CHUNK).min(n);
                // Expected entries: the receivers' neighbour counts times the share of
                // sources in `list` (+25 %), to avoid most reallocations.
                let expect = rows
                    .clone()
                    .map(|k| counts[k] as usize)
                    .sum::<usize>()
                    .saturating_mul(list.keys.len())
                    / n.max(1);
                let expect = expect + expect / 4 + 16;
                let mut chunk = CacheChunk {
                    row_ptr: Vec::with_capacity(rows.len() + 1),
                    slot: Vec::with_capacity(expect),
                    wv: Vec::with_capacity(expect),
                };
                chunk.row_ptr.push(0);
                for k in rows {
                    self.visit_block_row(list, k, |j, r2, v| {
                        chunk.slot.push(slots[j]);
                        chunk.wv.push(kernel(r2, inv_l2) * v);
                    });
                    // Row lengths are bounded by the pair budget (< 2^32 per chunk).
                    chunk.row_ptr.push(chunk.slot.len() as u32);
                }
                chunk.slot.shrink_to_fit();
                chunk.wv.shrink_to_fit();
                chunk
            })
            .collect();
        CacheBlock { chunks }
    }

    /// Visits the sources of `list` cached for receiver `k` (key order): same group, within
    /// `R_c`, `r > 0` (`w(0) = 0`); none for an isolated receiver (`W_pp = 1`).
    #[inline]
    fn visit_block_row(&self, list: &SourceList, k: usize, mut f: impl FnMut(usize, f64, f64)) {
        if self.weights().den[k] == 0.0 {
            return;
        }
        list.for_each_neighbour(
            self.sorted.keys[k],
            self.sorted.x[k],
            self.sorted.y[k],
            self.rc2,
            |j, r2, v| {
                if r2 > 0.0 {
                    f(j, r2, v)
                }
            },
        );
    }

    /// Sets the budget of cached pairs of [`Self::cache_sources`] (default
    /// [`DEFAULT_PAIR_BUDGET`]; 0 disables caching). Already cached blocks are kept.
    pub fn set_pair_budget(&mut self, pairs: usize) {
        self.cache.budget = pairs;
    }

    /// Drops all cached weights ([`Self::average`] then evaluates every source on the fly).
    pub fn clear_cache(&mut self) {
        let budget = self.cache.budget;
        self.cache = WeightCache {
            slot_of: vec![NO_SLOT; self.len()],
            budget,
            ..WeightCache::default()
        };
    }

    /// Number of cached sources, pairs and blocks, and the pair budget.
    pub fn cache_stats(&self) -> CacheStats {
        CacheStats {
            sources: self.cache.slot_key.len(),
            pairs: self.cache.pairs,
            blocks: self.cache.blocks.len(),
            budget: self.cache.budget,
        }
    }

    /// `O(N²)` brute-force reference of the same operator \[D34\] (tests and benchmark): for
    /// every MP `p`, loops over all MPs `q` of the same group within `R_c`, accumulating both
    /// the denominator and the numerator; isolated MPs keep their own value (`W_pp = 1`).
    /// Parallel over `p`, each `out_p` summed in index order (deterministic).
    ///
    /// # Errors
    /// As [`Self::new`], plus [`NonlocalError::FieldLengthMismatch`].
    pub fn average_brute_force(
        params: &NonlocalParameters,
        positions: &[[f64; 2]],
        volumes: &[f64],
        groups: &[u16],
        field: &[f64],
        out: &mut [f64],
    ) -> Result<(), NonlocalError> {
        params.validate()?;
        validate_inputs(positions, volumes, groups)?;
        let n = positions.len();
        if field.len() != n || out.len() != n {
            return Err(NonlocalError::FieldLengthMismatch {
                expected: n,
                field: field.len(),
                out: out.len(),
            });
        }
        let rc = params.cutoff_radius();
        let rc2 = rc * rc;
        let inv_l2 = 1.0 / (params.length_scale * params.length_scale);
        out.par_iter_mut()
            .with_min_len(MIN_CHUNK)
            .enumerate()
            .for_each(|(p, o)| {
                let [px, py] = positions[p];
                let g = groups[p];
                let (mut den, mut num) = (0.0, 0.0);
                for q in 0..n {
                    if groups[q] != g {
                        continue;
                    }
                    let dx = px - positions[q][0];
                    let dy = py - positions[q][1];
                    let r2 = dx * dx + dy * dy;
                    if r2 <= rc2 {
                        let wv = kernel(r2, inv_l2) * volumes[q];
                        den += wv;
                        num += wv * field[q];
                    }
                }
                *o = if den == 0.0 { field[p] } else { num / den };
            });
        Ok(())
    }

    /// Statistics of the number of same-group neighbours within `R_c` (the MP itself
    /// excluded): `(min, mean, max)` over all MPs; `(0, 0.0, 0)` if empty. Useful to check
    /// the resolution rule of DESIGN §6 (`h ≲ 0.2 l_s`) and to predict the cost of \[D36\].
    pub fn neighbour_count_stats(&self) -> (usize, f64, usize) {
        self.weights().stats
    }

    /// Bin size of the cell-linked list (`R_c` enlarged by a relative 1e−9) and the bin origin.
    pub fn bin_geometry(&self) -> (f64, [f64; 2]) {
        (self.bin, self.origin)
    }
}

/// A run of at most [`TILE`] consecutive MPs (key order) of one group and bin row, with its
/// bounding box ([`SymmetricPlan`]).
#[derive(Debug, Clone)]
struct Tile {
    lo: usize,
    hi: usize,
    group: u16,
    by: i64,
    min: [f64; 2],
    max: [f64; 2],
}

/// Partial sums of one tile pair `(I, J)`: `Σ w V` and counts for the MPs of `I` and of `J`.
type TilePartial = (Vec<f64>, Vec<u32>, Vec<f64>, Vec<u32>);

/// Tiles and interacting tile pairs of the symmetric pair pass ([`SymmetricPlan::sums`]).
#[derive(Debug, Clone, Default)]
struct SymmetricPlan {
    tiles: Vec<Tile>,
    /// Tile pairs `(I, J)`, `I ≤ J`, in lexicographic order.
    pairs: Vec<(usize, usize)>,
    /// Per tile, its `(pair, is_second_tile)` entries in pair order.
    touches: Vec<Vec<(usize, bool)>>,
}

impl SymmetricPlan {
    /// Cuts the key-ordered MPs into tiles ([`Tile`]) and lists every pair of tiles `I ≤ J` of
    /// the same group in the same or the next bin row whose bounding boxes are within `R_c`.
    /// The box test is a rounding-monotone lower bound of every computed `r²`, and bins are
    /// `≥ R_c`, so the pairs cover exactly the pairs of the cell list.
    fn new(sorted: &SourceList, rc2: f64) -> Self {
        let n = sorted.keys.len();
        let mut tiles: Vec<Tile> = Vec::with_capacity(n / TILE + 1);
        let mut lo = 0;
        while lo < n {
            let (group, by) = (sorted.keys[lo].group, sorted.keys[lo].by);
            let mut hi = lo + 1;
            while hi < n
                && hi - lo < TILE
                && sorted.keys[hi].group == group
                && sorted.keys[hi].by == by
            {
                hi += 1;
            }
            let mut min = [f64::INFINITY; 2];
            let mut max = [f64::NEG_INFINITY; 2];
            for k in lo..hi {
                min = [min[0].min(sorted.x[k]), min[1].min(sorted.y[k])];
                max = [max[0].max(sorted.x[k]), max[1].max(sorted.y[k])];
            }
            tiles.push(Tile {
                lo,
                hi,
                group,
                by,
                min,
                max,
            });
            lo = hi;
        }
        let near = |a: &Tile, b: &Tile| {
            let gx = (b.min[0] - a.max[0]).max(a.min[0] - b.max[0]).max(0.0);
            let gy = (b.min[1] - a.max[1]).max(a.min[1] - b.max[1]).max(0.0);
            gx * gx + gy * gy <= rc2
        };
        let tiles_ref = &tiles;
        let pairs: Vec<(usize, usize)> = (0..tiles.len())
            .into_par_iter()
            .flat_map_iter(|i| {
                let a = &tiles_ref[i];
                tiles_ref[i..]
                    .iter()
                    .enumerate()
                    .take_while(move |(_, b)| b.group == a.group && b.by <= a.by + 1)
                    .filter(move |(_, b)| near(a, b))
                    .map(move |(d, _)| (i, i + d))
            })
            .collect();
        let mut touches: Vec<Vec<(usize, bool)>> = vec![Vec::new(); tiles.len()];
        for (e, &(i, j)) in pairs.iter().enumerate() {
            touches[i].push((e, false));
            touches[j].push((e, true));
        }
        Self {
            tiles,
            pairs,
            touches,
        }
    }

    /// `(Σ_q kernel(r_pq²) s_q, count)` over all same-group `q ≠ p` within `R_c`, for every MP
    /// `p` (key order), evaluating the kernel once per unordered pair: `s = V` gives the
    /// denominators of \[D34\] and the neighbour counts, `s = V f` the numerators.
    ///
    /// Every tile pair is one parallel task that adds `w s_q` to `p` and `w s_p` to `q` in
    /// private partial arrays; the partials are then summed per MP in tile-pair order. The
    /// summation order is fixed (independent of the number of rayon threads) and the same for
    /// every `s`, so `s = V · 1` reproduces the denominators bit-exactly.
    fn sums(&self, sorted: &SourceList, s: &[f64], rc2: f64, inv_l2: f64) -> Vec<(f64, usize)> {
        let tiles = &self.tiles;
        let partials: Vec<TilePartial> = self
            .pairs
            .par_iter()
            .map(|&(i, j)| {
                let (a, b) = (&tiles[i], &tiles[j]);
                let mut da = vec![0.0; a.hi - a.lo];
                let mut ca = vec![0u32; a.hi - a.lo];
                let mut db = vec![0.0; b.hi - b.lo];
                let mut cb = vec![0u32; b.hi - b.lo];
                for p in a.lo..a.hi {
                    let (px, py, sp) = (sorted.x[p], sorted.y[p], s[p]);
                    let start = if i == j { p + 1 } else { b.lo };
                    let (mut acc, mut count) = (0.0, 0u32);
                    for q in start..b.hi {
                        let dx = px - sorted.x[q];
                        let dy = py - sorted.y[q];
                        let r2 = dx * dx + dy * dy;
                        if r2 <= rc2 {
                            let w = kernel(r2, inv_l2);
                            acc += w * s[q];
                            count += 1;
                            db[q - b.lo] += w * sp;
                            cb[q - b.lo] += 1;
                        }
                    }
                    da[p - a.lo] = acc;
                    ca[p - a.lo] = count;
                }
                (da, ca, db, cb)
            })
            .collect();
        let per_tile: Vec<Vec<(f64, usize)>> = tiles
            .par_iter()
            .zip(&self.touches)
            .map(|(t, list)| {
                let mut out = vec![(0.0, 0usize); t.hi - t.lo];
                for &(e, second) in list {
                    let (d, c) = if second {
                        (&partials[e].2, &partials[e].3)
                    } else {
                        (&partials[e].0, &partials[e].1)
                    };
                    for (o, (dv, cv)) in out.iter_mut().zip(d.iter().zip(c)) {
                        o.0 += dv;
                        o.1 += *cv as usize;
                    }
                }
                out
            })
            .collect();
        per_tile.into_iter().flatten().collect()
    }
}

fn validate_inputs(
    positions: &[[f64; 2]],
    volumes: &[f64],
    groups: &[u16],
) -> Result<(), NonlocalError> {
    if positions.len() != volumes.len() || positions.len() != groups.len() {
        return Err(NonlocalError::InputLengthMismatch {
            positions: positions.len(),
            volumes: volumes.len(),
            groups: groups.len(),
        });
    }
    for (index, p) in positions.iter().enumerate() {
        if !(p[0].is_finite() && p[1].is_finite()) {
            return Err(NonlocalError::NonFinitePosition {
                index,
                position: *p,
            });
        }
    }
    for (index, &v) in volumes.iter().enumerate() {
        if !(v.is_finite() && v >= 0.0) {
            return Err(NonlocalError::InvalidVolume { index, volume: v });
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests;
