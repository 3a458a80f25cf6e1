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

use crate::shape::floor_int;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::sync::{Mutex, OnceLock};

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

/// MPs per tile of the symmetric pair pass ([`SymmetricPlan`]).
const TILE: usize = 128;

/// MPs per column chunk of a tile: the pair passes skip a chunk whose bounding box lies
/// beyond `R_c` of the row's MP ([`weight_row_culled`]).
const CHUNK: usize = 16;

/// Parameters of the nonlocal averaging (theory §6, \[D33\]–\[D34\]; paper eq. 6).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct NonlocalParameters {
    /// Material length scale `l_s` (m) of the weight \[D33\]; must be finite and `> 0`.
    pub length_scale: f64,
    /// Cutoff radius in units of `l_s`: `R_c = cutoff_factor · l_s` (default 3, theory §6);
    /// must be finite and `> 0`.
    pub cutoff_factor: f64,
}

impl NonlocalParameters {
    /// Parameters with the given length scale `l_s` and the default cutoff `R_c = 3 l_s`
    /// ([`DEFAULT_CUTOFF_FACTOR`], theory §6).
    pub fn new(length_scale: f64) -> Self {
        Self {
            length_scale,
            cutoff_factor: DEFAULT_CUTOFF_FACTOR,
        }
    }

    /// Cutoff radius `R_c = cutoff_factor · l_s` (m), theory §6.
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
    /// The cutoff factor is not finite or not strictly positive (theory §6).
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

/// Galavi–Schweiger weight \[D33\]: `w(r) = (r / l_s²) · exp(−(r/l_s)²)` (paper eq. 6, theory §6).
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
    r2.sqrt() * inv_l2 * exp_nonpositive(-(r2 * inv_l2))
}

/// `exp(x)` for `x ≤ 0`, within 2 ulp of the exact value for `x ≥ −708` (below, `exp(−708)`
/// ≈ 3e−308: a weight beyond 26 `l_s`), written without branches or calls so that the loops of
/// kernel evaluations vectorise (std's `exp` is a library call per pair).
///
/// Cody–Waite reduction `x = k ln2 + r`, `|r| ≤ ln2/2`, with `k` rounded by the `1.5·2⁵²`
/// shift, the Taylor polynomial of degree 13 of `exp(r)` (truncation `< 5e−18`), and `2^k`
/// assembled from its exponent bits.
#[inline(always)]
fn exp_nonpositive(x: f64) -> f64 {
    // adding 1.5 · 2^52 rounds to an integer, held in the low bits
    const SHIFT: f64 = 6_755_399_441_055_744.0;
    // ln 2 = LN2_HI + LN2_LO, LN2_HI with 11 trailing zero bits (exact times any |k| < 2^11)
    const LN2_HI: f64 = f64::from_bits(0x3fe6_2e42_fee0_0000);
    const LN2_LO: f64 = f64::from_bits(0x3dea_39ef_3579_3c76);
    // 1/n!, n = 13 … 2
    const INV_FACTORIALS: [f64; 12] = [
        1.0 / 6_227_020_800.0,
        1.0 / 479_001_600.0,
        1.0 / 39_916_800.0,
        1.0 / 3_628_800.0,
        1.0 / 362_880.0,
        1.0 / 40_320.0,
        1.0 / 5_040.0,
        1.0 / 720.0,
        1.0 / 120.0,
        1.0 / 24.0,
        1.0 / 6.0,
        0.5,
    ];
    let x = x.max(-708.0);
    let shifted = x * std::f64::consts::LOG2_E + SHIFT;
    let k = shifted - SHIFT;
    let r = (x - k * LN2_HI) - k * LN2_LO;
    let mut poly = INV_FACTORIALS[0];
    for c in &INV_FACTORIALS[1..] {
        poly = poly * r + c;
    }
    poly = poly * r + 1.0;
    poly = poly * r + 1.0;
    // the low bits of `shifted` hold k (two's complement); 2^k has the biased exponent k + 1023
    let k_bits = shifted.to_bits().wrapping_sub(SHIFT.to_bits());
    poly * f64::from_bits(k_bits.wrapping_add(1023) << 52)
}

/// One row of the kernel ([`kernel`]): `w_q = kernel(|x_p − x_q|²)` where `|x_p − x_q| ≤ R_c`,
/// else 0, for the MPs `q` at `(xs, ys)`; `r2_out` gets the squared distances. Branch-free,
/// so the compiler vectorises it. Returns the number of MPs within `R_c`.
///
/// On x86-64 CPUs with AVX2 the same code is compiled a second time for AVX2 (4 lanes instead
/// of SSE2's 2) and chosen at run time; both perform the same IEEE operations in the same
/// order (no fused multiply-add), so the weights are bit-identical either way.
#[inline]
fn weight_row(
    p: [f64; 2],
    xs: &[f64],
    ys: &[f64],
    rc2: f64,
    inv_l2: f64,
    r2_out: &mut [f64],
    w_out: &mut [f64],
) -> u32 {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU supports AVX2 (checked just above).
        return unsafe { weight_row_avx2(p, xs, ys, rc2, inv_l2, r2_out, w_out) };
    }
    weight_row_portable(p, xs, ys, rc2, inv_l2, r2_out, w_out)
}

/// [`weight_row`] compiled with AVX2 enabled.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn weight_row_avx2(
    p: [f64; 2],
    xs: &[f64],
    ys: &[f64],
    rc2: f64,
    inv_l2: f64,
    r2_out: &mut [f64],
    w_out: &mut [f64],
) -> u32 {
    weight_row_portable(p, xs, ys, rc2, inv_l2, r2_out, w_out)
}

/// The body of [`weight_row`], inlined into each instruction-set variant.
#[inline(always)]
fn weight_row_portable(
    p: [f64; 2],
    xs: &[f64],
    ys: &[f64],
    rc2: f64,
    inv_l2: f64,
    r2_out: &mut [f64],
    w_out: &mut [f64],
) -> u32 {
    let mut count = 0u32;
    for (((w, r2_slot), &xq), &yq) in w_out.iter_mut().zip(r2_out.iter_mut()).zip(xs).zip(ys) {
        let (dx, dy) = (p[0] - xq, p[1] - yq);
        let r2 = dx * dx + dy * dy;
        let inside = r2 <= rc2;
        let k = kernel(r2, inv_l2);
        *w = if inside { k } else { 0.0 };
        *r2_slot = r2;
        count += u32::from(inside);
    }
    count
}

/// [`weight_row`] of `p` against every MP of tile `b` (`xs`, `ys`, `r2_out`, `w_out` cover
/// the whole tile), skipping each column chunk whose box lies beyond `R_c` of `p`: there
/// `w = 0` and `r² = +∞`, where [`weight_row`] gives `w = 0` and some `r² > R_c²`, so every
/// weight and count is the same. Returns the number of MPs within `R_c`.
fn weight_row_culled(
    p: [f64; 2],
    b: &Tile,
    (xs, ys): (&[f64], &[f64]),
    (rc2, inv_l2): (f64, f64),
    r2_out: &mut [f64],
    w_out: &mut [f64],
) -> u32 {
    let chunks = xs.len().div_ceil(CHUNK);
    let mut count = 0;
    let mut c = 0;
    while c < chunks {
        let beyond = b.chunk_gap2(c, p) > rc2;
        // the run of chunks on the same side of the test
        let mut end = c + 1;
        while end < chunks && (b.chunk_gap2(end, p) > rc2) == beyond {
            end += 1;
        }
        let cols = c * CHUNK..(end * CHUNK).min(xs.len());
        if beyond {
            w_out[cols.clone()].fill(0.0);
            r2_out[cols].fill(f64::INFINITY);
        } else {
            count += weight_row(
                p,
                &xs[cols.clone()],
                &ys[cols.clone()],
                rc2,
                inv_l2,
                &mut r2_out[cols.clone()],
                &mut w_out[cols],
            );
        }
        c = end;
    }
    count
}

/// Sort key of an MP: group first, then bin row, bin column, and the sub-bin within the bin
/// (row-major), so that consecutive MPs of a bin, and hence the tiles of the
/// [`SymmetricPlan`], are compact patches rather than strips across the bin.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
struct BinKey {
    group: u16,
    by: i64,
    bx: i64,
    sub: u32,
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
    /// Neighbour count statistics (min, mean, max) over all MPs.
    stats: (usize, f64, usize),
}

impl Weights {
    /// Denominators, counts and their statistics from the symmetric pass whose first source
    /// is `s = V`.
    fn from_sums<const K: usize>(plan: SymmetricPlan, results: &[([f64; K], usize)]) -> Self {
        let n = results.len();
        let den: Vec<f64> = results.iter().map(|r| r.0[0]).collect();
        let stats = if n == 0 {
            (0, 0.0, 0)
        } else {
            let min = results.iter().map(|r| r.1).min().unwrap_or(0);
            let max = results.iter().map(|r| r.1).max().unwrap_or(0);
            let mean = results.iter().map(|r| r.1 as f64).sum::<f64>() / n as f64;
            (min, mean, max)
        };
        Weights { plan, den, stats }
    }
}

/// Weights `w(|x_p − x_q|)` of \[D34\] cached for the tile pairs around the step's plastic
/// sources, reused by every [`NonlocalAverager::average`] call of the step (\[D36\]).
///
/// One dense block per cached pair `(I, J)` of tiles of the [`SymmetricPlan`]: row `p` holds
/// the weights from the `p`-th MP of tile `I` to every MP of tile `J` (zero beyond `R_c` and
/// between coincident MPs). `w` is symmetric, so one block serves both directions: receivers
/// in `I` gather `W_IJ (V f)_J` (row dot products) and receivers in `J` gather `W_IJᵀ (V f)_I`
/// (row-wise axpy). A diagonal pair (`I = J`) holds the full square. Per cached pair of MPs
/// this is 8 bytes, read in contiguous rows (no index), once per unordered pair and call.
#[derive(Debug, Clone, Default)]
struct WeightCache {
    /// `blocks[e]`: the weight block of tile pair `e` of the plan (empty if not cached).
    blocks: Vec<Vec<f64>>,
    /// Tiles every pair of which is cached.
    tile_cached: Vec<bool>,
    /// Per MP (key order): a candidate of [`NonlocalAverager::cache_sources`] in a cached tile.
    source_cached: Vec<bool>,
    /// Number of `true` entries of `source_cached`.
    sources: usize,
    /// Number of cached blocks (nonempty entries of `blocks`).
    block_count: usize,
    /// Stored weights over all blocks.
    pairs: usize,
    /// Maximum number of stored weights (memory budget, 8 bytes each).
    budget: usize,
}

impl WeightCache {
    fn new(budget: usize) -> Self {
        Self {
            blocks: Vec::new(),
            tile_cached: Vec::new(),
            source_cached: Vec::new(),
            sources: 0,
            block_count: 0,
            pairs: 0,
            budget,
        }
    }

    /// The block of tile pair `e`, if cached.
    fn block(&self, e: usize) -> Option<&[f64]> {
        self.blocks
            .get(e)
            .filter(|b| !b.is_empty())
            .map(Vec::as_slice)
    }
}

/// Blocks of dropped caches, reused by the next step's cache ([`recycled_block`]): every
/// step builds a new operator, and its blocks (hundreds of MB at the paper's resolutions) would
/// otherwise be fresh memory, mapped and zeroed page by page by the kernel each step. Holds
/// at most the blocks of one cache.
static BLOCK_POOL: Mutex<Vec<Vec<f64>>> = Mutex::new(Vec::new());

impl Drop for WeightCache {
    fn drop(&mut self) {
        let blocks: Vec<Vec<f64>> = self.blocks.drain(..).filter(|b| !b.is_empty()).collect();
        if let Ok(mut pool) = BLOCK_POOL.lock() {
            if blocks.len() >= pool.len() {
                *pool = blocks;
            }
        }
    }
}

/// A block of `len` weights for [`WeightCache`], taken from [`BLOCK_POOL`] where one is free.
/// Its contents are unspecified: the passes that fill a block write every entry.
fn recycled_block(len: usize) -> Vec<f64> {
    let reused = BLOCK_POOL.lock().ok().and_then(|mut pool| pool.pop());
    match reused {
        Some(mut block) => {
            block.resize(len, 0.0);
            block
        }
        None => vec![0.0; len],
    }
}

/// Cache statistics of a [`NonlocalAverager`] (see [`NonlocalAverager::cache_stats`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct CacheStats {
    /// Number of cached sources (candidates of [`NonlocalAverager::cache_sources`] whose
    /// weights to every receiver are stored).
    pub sources: usize,
    /// Number of stored weights (pairs `(p, q)` of MPs of cached tile pairs, within `R_c` or
    /// not; an unordered pair is stored once).
    pub pairs: usize,
    /// Number of cached tile-pair blocks.
    pub blocks: usize,
    /// Budget of stored weights ([`NonlocalAverager::set_pair_budget`]).
    pub budget: usize,
}

impl NonlocalAverager {
    /// Builds the operator \[D34\] from start-of-step positions `x_q`, volumes `V_q` and a group
    /// (material) id per MP; only MPs of the same group average together (theory §6).
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
        let bin_of = |i: usize| {
            [
                floor_int((positions[i][0] - origin[0]) / bin),
                floor_int((positions[i][1] - origin[1]) / bin),
            ]
        };
        let subdivisions = sub_bins_per_side(n, (0..n).map(|i| (groups[i], bin_of(i))));
        let key_of = |i: usize| {
            let [bx, by] = bin_of(i);
            let sub_bin = bin / subdivisions as f64;
            let sub_index = |x: f64, b: i64, o: f64| {
                floor_int((x - o - b as f64 * bin) / sub_bin).clamp(0, subdivisions - 1)
            };
            let sx = sub_index(positions[i][0], bx, origin[0]);
            let sy = sub_index(positions[i][1], by, origin[1]);
            BinKey {
                group: groups[i],
                by,
                bx,
                sub: (sy * subdivisions + sx) as u32,
            }
        };
        // each key formed once (in the comparisons they cost more than the sort itself)
        let keys: Vec<BinKey> = (0..n).map(key_of).collect();
        let mut order: Vec<usize> = (0..n).collect();
        // Stable sort: ties (same bin) keep the original index order -> deterministic.
        order.sort_by_key(|&i| keys[i]);
        let mut sorted = SourceList::with_capacity(n);
        for &i in &order {
            sorted.push(keys[i], positions[i][0], positions[i][1], volumes[i]);
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
            cache: WeightCache::new(DEFAULT_PAIR_BUDGET),
        })
    }

    /// Denominators and neighbour counts (symmetric pass, [`SymmetricPlan`]), computed once.
    fn weights(&self) -> &Weights {
        self.weights.get_or_init(|| {
            let plan = SymmetricPlan::new(&self.sorted, self.rc2);
            let results = plan.sums(
                &self.sorted,
                [&self.sorted.s],
                self.rc2,
                self.inv_l2,
                &mut [],
            );
            Weights::from_sums(plan, &results)
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
    /// Every output tile gathers, over the tile pairs it belongs to (in plan order), the
    /// contributions of the other tile's nonzero sources: from the stored block where the pair
    /// is cached ([`Self::cache_sources`]), else by evaluating the kernel on the fly; tiles
    /// without a nonzero source are skipped. Each `out_p` is summed in a fixed order by a single
    /// task: the result is bit-identical for any number of rayon threads, and equals the
    /// uncached evaluation ([`Self::average_uncached`]) up to summation order. Isolated MPs
    /// (zero denominator) copy their own value (`W_pp = 1`). `out` is overwritten.
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
        // `s_q = V_q f_q` in key order.
        let s: Vec<f64> = self
            .order
            .iter()
            .zip(&self.sorted.s)
            .map(|(&i, &v)| v * field[i])
            .collect();
        let cached = use_cache && self.cache.block_count > 0;
        let numerators: Vec<f64> = if !cached && !self.has_weights() {
            // The denominators are still to be computed (an explicit step averages once):
            // one symmetric pass evaluates each kernel once for both sums.
            let plan = SymmetricPlan::new(&self.sorted, self.rc2);
            let sums = plan.sums(
                &self.sorted,
                [&self.sorted.s, &s],
                self.rc2,
                self.inv_l2,
                &mut [],
            );
            let _ = self.weights.set(Weights::from_sums(plan, &sums));
            sums.into_iter().map(|(sum, _)| sum[1]).collect()
        } else {
            let weights = self.weights();
            let nonzero = self.order.iter().filter(|&&i| field[i] != 0.0).count();
            if !cached && 2 * nonzero > n {
                // Mostly nonzero field: the symmetric pass (each kernel once per unordered
                // pair) is cheaper than gathering every source per receiver.
                let sums = weights
                    .plan
                    .sums(&self.sorted, [&s], self.rc2, self.inv_l2, &mut []);
                sums.into_iter().map(|(sum, _)| sum[0]).collect()
            } else {
                self.gather_numerators(&weights.plan, &s, cached)
            }
        };
        let weights = self.weights();
        for (k, (&i, num)) in self.order.iter().zip(numerators).enumerate() {
            let den = weights.den[k];
            out[i] = if den == 0.0 { field[i] } else { num / den };
        }
        Ok(())
    }

    /// `Σ_q w(|x_p − x_q|) s_q` for every MP `p` (key order), over the tile pairs of the plan:
    /// one parallel task per tile pair with a nonzero source forms the partial sums of both
    /// tiles (`W_IJ s_J` and `W_IJᵀ s_I`, reading a cached block once, or evaluating each
    /// kernel once), then every MP sums its partials in plan order. The order is fixed, so
    /// the result is bit-identical for any number of threads.
    fn gather_numerators(&self, plan: &SymmetricPlan, s: &[f64], use_cache: bool) -> Vec<f64> {
        let has_source: Vec<bool> = plan
            .tiles
            .iter()
            .map(|t| s[t.lo..t.hi].iter().any(|&v| v != 0.0))
            .collect();
        let partials: Vec<(Vec<f64>, Vec<f64>)> = plan
            .pairs
            .par_iter()
            .enumerate()
            .map(|(e, &(i, j))| {
                let (a, b) = (&plan.tiles[i], &plan.tiles[j]);
                // rows gather from J's sources; columns (not for a diagonal pair, whose
                // rows cover the full square) from I's
                let rows = has_source[j];
                let columns = i != j && has_source[i];
                let mut from_j = vec![0.0; if rows { a.hi - a.lo } else { 0 }];
                let mut from_i = vec![0.0; if columns { b.hi - b.lo } else { 0 }];
                if rows || columns {
                    let (s_i, s_j) = (&s[a.lo..a.hi], &s[b.lo..b.hi]);
                    match self.cache.block(e).filter(|_| use_cache) {
                        Some(w) => block_times(w, s_i, s_j, &mut from_j, &mut from_i),
                        None => self.pair_on_the_fly(a, b, s, &mut from_j, &mut from_i),
                    }
                }
                (from_j, from_i)
            })
            .collect();
        let mut numerators = vec![0.0; self.len()];
        for (t, tile) in plan.tiles.iter().enumerate() {
            let out = &mut numerators[tile.lo..tile.hi];
            for &(e, second) in &plan.touches[t] {
                let part = if second {
                    &partials[e].1
                } else {
                    &partials[e].0
                };
                for (o, v) in out.iter_mut().zip(part) {
                    *o += v;
                }
            }
        }
        numerators
    }

    /// The partial sums of tile pair `(a, b)` with the kernel evaluated on the fly:
    /// `from_b_p += Σ_{q ∈ b} w_pq s_q` for `p ∈ a` (if `from_b` is not empty; for a diagonal
    /// pair over the full square) and `from_a_q += Σ_{p ∈ a} w_pq s_p` for `q ∈ b` (if `from_a`
    /// is not empty).
    fn pair_on_the_fly(
        &self,
        a: &Tile,
        b: &Tile,
        s: &[f64],
        from_b: &mut [f64],
        from_a: &mut [f64],
    ) {
        let (x, y) = (&self.sorted.x, &self.sorted.y);
        let (rows, columns) = (!from_b.is_empty(), !from_a.is_empty());
        for p in a.lo..a.hi {
            if (!rows && s[p] == 0.0) || b.gap2([x[p], y[p]]) > self.rc2 {
                continue;
            }
            let mut acc = 0.0;
            for q in b.lo..b.hi {
                if s[q] == 0.0 && s[p] == 0.0 {
                    continue;
                }
                let (dx, dy) = (x[p] - x[q], y[p] - y[q]);
                let r2 = dx * dx + dy * dy;
                if r2 <= self.rc2 {
                    let w = kernel(r2, self.inv_l2);
                    acc += w * s[q];
                    if columns {
                        from_a[q - b.lo] += w * s[p];
                    }
                }
            }
            if rows {
                from_b[p - a.lo] += acc;
            }
        }
    }

    /// Caches the weights `w(|x_p − x_q|)` (\[D34\]) of the tile pairs around every MP with
    /// `candidates_q ≠ 0` not cached yet, so that the following [`Self::average`] calls of the
    /// step (\[D36\]: one per Newton iteration) read them instead of re-evaluating the kernel.
    /// Typically `candidates = Δκ`.
    ///
    /// The tiles holding a candidate are admitted in key order while the budget of stored
    /// weights ([`Self::set_pair_budget`]) allows all their missing tile pairs; the others are
    /// evaluated on the fly by [`Self::average`]. At the first call with a nonzero candidate
    /// the blocks are filled by the same symmetric pass that computes the denominators (one
    /// kernel evaluation per unordered pair for both); later blocks by a pass of their own.
    /// Returns the number of candidates newly cached.
    ///
    /// # Errors
    /// [`NonlocalError::FieldLengthMismatch`] if `candidates` does not have [`Self::len`]
    /// entries.
    pub fn cache_sources(&mut self, candidates: &[f64]) -> Result<usize, NonlocalError> {
        self.check_field(candidates, self.len())?;
        let is_candidate: Vec<bool> = self.order.iter().map(|&i| candidates[i] != 0.0).collect();
        if !is_candidate.contains(&true) {
            return Ok(0);
        }
        // the plan of the denominators, or a new one if they are still to be computed
        let fresh_plan = match self.weights.get() {
            Some(_) => None,
            None => Some(SymmetricPlan::new(&self.sorted, self.rc2)),
        };
        let plan = match (&fresh_plan, self.weights.get()) {
            (Some(plan), _) => plan,
            (None, Some(w)) => &w.plan,
            (None, None) => unreachable!("a plan exists in one of the two"),
        };
        let cache = &mut self.cache;
        if cache.blocks.len() != plan.pairs.len() {
            cache.blocks = vec![Vec::new(); plan.pairs.len()];
            cache.tile_cached = vec![false; plan.tiles.len()];
            cache.source_cached = vec![false; self.order.len()];
        }
        let mut is_new = vec![false; plan.pairs.len()];
        let mut new_pairs = Vec::new();
        for (t, tile) in plan.tiles.iter().enumerate() {
            if cache.tile_cached[t] || !is_candidate[tile.lo..tile.hi].contains(&true) {
                continue;
            }
            let missing: Vec<usize> = plan.touches[t]
                .iter()
                .map(|&(e, _)| e)
                .filter(|&e| cache.blocks[e].is_empty() && !is_new[e])
                .collect();
            let size: usize = missing.iter().map(|&e| plan.block_len(e)).sum();
            if cache.pairs + size > cache.budget {
                continue;
            }
            cache.pairs += size;
            cache.tile_cached[t] = true;
            for &e in &missing {
                is_new[e] = true;
            }
            new_pairs.extend(missing);
        }
        for &e in &new_pairs {
            cache.blocks[e] = recycled_block(plan.block_len(e));
        }
        cache.block_count += new_pairs.len();
        let mut added = 0;
        for (t, tile) in plan.tiles.iter().enumerate() {
            if !cache.tile_cached[t] {
                continue;
            }
            for k in tile.lo..tile.hi {
                if is_candidate[k] && !cache.source_cached[k] {
                    cache.source_cached[k] = true;
                    added += 1;
                }
            }
        }
        cache.sources += added;
        if fresh_plan.is_some() {
            let results = plan.sums(
                &self.sorted,
                [&self.sorted.s],
                self.rc2,
                self.inv_l2,
                &mut cache.blocks,
            );
            if let Some(plan) = fresh_plan {
                // the cell was empty above, so this cannot fail
                let _ = self.weights.set(Weights::from_sums(plan, &results));
            }
        } else {
            let (sorted, rc2, inv_l2) = (&self.sorted, self.rc2, self.inv_l2);
            cache
                .blocks
                .par_iter_mut()
                .enumerate()
                .filter(|(e, _)| is_new[*e])
                .for_each(|(e, block)| plan.fill_block(e, sorted, rc2, inv_l2, block));
        }
        Ok(added)
    }

    /// Sets the budget of stored weights of [`Self::cache_sources`] (default
    /// [`DEFAULT_PAIR_BUDGET`]; 0 disables caching). Already cached blocks are kept.
    pub fn set_pair_budget(&mut self, pairs: usize) {
        self.cache.budget = pairs;
    }

    /// Drops all cached weights ([`Self::average`] then evaluates every source on the fly).
    pub fn clear_cache(&mut self) {
        self.cache = WeightCache::new(self.cache.budget);
    }

    /// Number of cached sources, stored weights and blocks, and the budget.
    pub fn cache_stats(&self) -> CacheStats {
        CacheStats {
            sources: self.cache.sources,
            pairs: self.cache.pairs,
            blocks: self.cache.block_count,
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
    /// the resolution rule of theory §6 (`h ≲ 0.2 l_s`) and to predict the cost of \[D36\].
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
    /// Bounding boxes `[min x, min y, max x, max y]` of the MPs `lo + c·CHUNK ..` in chunks
    /// of [`CHUNK`].
    chunks: [[f64; 4]; TILE / CHUNK],
}

impl Tile {
    /// The tile of the key-ordered MPs `lo..hi` (at most [`TILE`]) with their boxes.
    fn new(sorted: &SourceList, lo: usize, hi: usize) -> Self {
        let key = sorted.keys[lo];
        let mut chunks = [[
            f64::INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NEG_INFINITY,
        ]; TILE / CHUNK];
        for (k, chunk) in (lo..hi).zip((0..).map(|k| k / CHUNK)) {
            let b = &mut chunks[chunk];
            *b = [
                b[0].min(sorted.x[k]),
                b[1].min(sorted.y[k]),
                b[2].max(sorted.x[k]),
                b[3].max(sorted.y[k]),
            ];
        }
        let used = &chunks[..(hi - lo).div_ceil(CHUNK)];
        let min = used
            .iter()
            .fold([f64::INFINITY; 2], |m, b| [m[0].min(b[0]), m[1].min(b[1])]);
        let max = used.iter().fold([f64::NEG_INFINITY; 2], |m, b| {
            [m[0].max(b[2]), m[1].max(b[3])]
        });
        Self {
            lo,
            hi,
            group: key.group,
            by: key.by,
            min,
            max,
            chunks,
        }
    }

    /// Squared gap between the point `x` and the box of column chunk `c` (0 inside), a
    /// lower bound of the computed `r²` as [`Self::gap2`].
    fn chunk_gap2(&self, c: usize, x: [f64; 2]) -> f64 {
        let b = &self.chunks[c];
        box_gap2([b[0], b[1]], [b[2], b[3]], x, x)
    }

    /// Squared gap between the bounding boxes of `self` and `other` (0 if they
    /// overlap), a lower bound of the computed `r²` of every pair of their MPs.
    fn gap2_to(&self, other: &Tile) -> f64 {
        box_gap2(self.min, self.max, other.min, other.max)
    }

    /// Squared gap between the point `x` and the bounding box (0 inside), a lower
    /// bound of the computed `r²` from `x` to every MP of the tile.
    fn gap2(&self, x: [f64; 2]) -> f64 {
        box_gap2(self.min, self.max, x, x)
    }
}

/// Squared gap between the boxes `[min, max]` and `[other_min, other_max]` (0 if they
/// overlap). Rounding is monotone, so for points `p` in the one box and `q` in the other
/// it never exceeds the `r² = (p_x − q_x)² + (p_y − q_y)²` the kernel rows compute.
fn box_gap2(min: [f64; 2], max: [f64; 2], other_min: [f64; 2], other_max: [f64; 2]) -> f64 {
    let gap = |d: usize| (other_min[d] - max[d]).max(min[d] - other_max[d]).max(0.0);
    let (gx, gy) = (gap(0), gap(1));
    gx * gx + gy * gy
}

/// Partial sums of one tile pair `(I, J)` ([`SymmetricPlan::sums`]): `Σ w s_k` for each of the
/// `K` sources and the neighbour counts, for the MPs of `I` and of `J`.
type TilePartial<const K: usize> = ([Vec<f64>; K], Vec<u32>, [Vec<f64>; K], Vec<u32>);

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
            tiles.push(Tile::new(sorted, lo, hi));
            lo = hi;
        }
        let near = |a: &Tile, b: &Tile| a.gap2_to(b) <= rc2;
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

    /// Number of weights of the block of tile pair `e` (rows × columns).
    fn block_len(&self, e: usize) -> usize {
        let (i, j) = self.pairs[e];
        (self.tiles[i].hi - self.tiles[i].lo) * (self.tiles[j].hi - self.tiles[j].lo)
    }

    /// Fills the weight block of tile pair `e` ([`WeightCache`]): `w(|x_p − x_q|)` for every MP
    /// `p` of the first tile (rows) and `q` of the second (columns) within `R_c`, the same
    /// bits as the symmetric pass ([`Self::sums`]) writes.
    fn fill_block(&self, e: usize, sorted: &SourceList, rc2: f64, inv_l2: f64, block: &mut [f64]) {
        let (a, b) = (&self.tiles[self.pairs[e].0], &self.tiles[self.pairs[e].1]);
        let width = b.hi - b.lo;
        let mut r2 = [0.0; TILE];
        for (p, row) in (a.lo..a.hi).zip(block.chunks_exact_mut(width)) {
            let xp = [sorted.x[p], sorted.y[p]];
            if b.gap2(xp) > rc2 {
                row.fill(0.0); // beyond R_c of the whole tile (see `sums`)
                continue;
            }
            let columns = (&sorted.x[b.lo..b.hi], &sorted.y[b.lo..b.hi]);
            weight_row_culled(xp, b, columns, (rc2, inv_l2), &mut r2[..width], row);
        }
    }

    /// `(Σ_q kernel(r_pq²) s_k,q for each source k, count)` over all same-group `q ≠ p` within
    /// `R_c`, for every MP `p` (key order), evaluating the kernel once per unordered pair:
    /// `s = [V]` gives the denominators of \[D34\] and the neighbour counts, `s = [V f]` the
    /// numerators, `s = [V, V f]` both from one evaluation of the kernel.
    ///
    /// Every tile pair is one parallel task that adds `w s_q` to `p` and `w s_p` to `q` in
    /// private partial arrays; the partials are then summed per MP in tile-pair order. The
    /// summation order is fixed (independent of the number of rayon threads) and the same for
    /// every source and every `K`, so `s = V · 1` reproduces the denominators bit-exactly.
    ///
    /// `blocks` is empty, or holds one entry per tile pair: the pass also writes the weights
    /// into every nonempty (zeroed) entry, laid out as [`WeightCache`] describes.
    fn sums<const K: usize>(
        &self,
        sorted: &SourceList,
        s: [&[f64]; K],
        rc2: f64,
        inv_l2: f64,
        blocks: &mut [Vec<f64>],
    ) -> Vec<([f64; K], usize)> {
        let tiles = &self.tiles;
        let pair_pass = |(i, j): (usize, usize), mut block: Option<&mut [f64]>| {
            let (a, b) = (&tiles[i], &tiles[j]);
            let width = b.hi - b.lo;
            let mut da: [Vec<f64>; K] = std::array::from_fn(|_| vec![0.0; a.hi - a.lo]);
            let mut ca = vec![0u32; a.hi - a.lo];
            let mut db: [Vec<f64>; K] = std::array::from_fn(|_| vec![0.0; width]);
            let mut cb = vec![0u32; width];
            let (mut r2, mut scratch) = ([0.0; TILE], [0.0; TILE]);
            for p in a.lo..a.hi {
                // a diagonal pair visits q > p only (each unordered pair once)
                let start = if i == j { p + 1 } else { b.lo };
                let (r2, cols) = (&mut r2[..b.hi - start], start - b.lo..width);
                let w = match block.as_deref_mut() {
                    Some(block) => &mut block[(p - a.lo) * width..][cols.clone()],
                    None => &mut scratch[..b.hi - start],
                };
                let xp = [sorted.x[p], sorted.y[p]];
                if b.gap2(xp) > rc2 {
                    // every weight of the row is 0 (the box gap is a rounding-monotone lower
                    // bound of every computed r²): its sums and counts stay as they are
                    w.fill(0.0);
                    continue;
                }
                let (xs, ys) = (&sorted.x[start..b.hi], &sorted.y[start..b.hi]);
                ca[p - a.lo] = if i == j {
                    weight_row(xp, xs, ys, rc2, inv_l2, r2, w)
                } else {
                    weight_row_culled(xp, b, (xs, ys), (rc2, inv_l2), r2, w)
                };
                for (k, source) in s.iter().enumerate() {
                    da[k][p - a.lo] = dot(w, &source[start..b.hi]);
                    let sp = source[p];
                    for (d, &wq) in db[k][cols.clone()].iter_mut().zip(w.iter()) {
                        *d += wq * sp;
                    }
                }
                for (c, &r2q) in cb[cols].iter_mut().zip(r2.iter()) {
                    *c += u32::from(r2q <= rc2);
                }
            }
            if let (Some(block), true) = (block, i == j) {
                // the lower triangle of a diagonal block mirrors the upper one (every entry
                // is written: a recycled block holds the weights of an earlier step)
                for p in 0..width {
                    for q in 0..p {
                        block[p * width + q] = block[q * width + p];
                    }
                    block[p * width + p] = 0.0;
                }
            }
            (da, ca, db, cb)
        };
        let partials: Vec<TilePartial<K>> = if blocks.is_empty() {
            self.pairs.par_iter().map(|&e| pair_pass(e, None)).collect()
        } else {
            self.pairs
                .par_iter()
                .zip(blocks.par_iter_mut())
                .map(|(&e, block)| {
                    pair_pass(e, (!block.is_empty()).then_some(block.as_mut_slice()))
                })
                .collect()
        };
        let per_tile: Vec<Vec<([f64; K], usize)>> = tiles
            .par_iter()
            .zip(&self.touches)
            .map(|(t, list)| {
                let mut out = vec![([0.0; K], 0usize); t.hi - t.lo];
                for &(e, second) in list {
                    let (d, c) = if second {
                        (&partials[e].2, &partials[e].3)
                    } else {
                        (&partials[e].0, &partials[e].1)
                    };
                    for (m, (o, cv)) in out.iter_mut().zip(c).enumerate() {
                        for k in 0..K {
                            o.0[k] += d[k][m];
                        }
                        o.1 += *cv as usize;
                    }
                }
                out
            })
            .collect();
        per_tile.into_iter().flatten().collect()
    }
}

/// The partial sums of a cached block ([`WeightCache`]), read once: `from_j_p = Σ_q w_pq s_j,q`
/// per row `p` (if `from_j` is not empty) and `from_i_q = Σ_p w_pq s_i,p` per column `q` (if
/// `from_i` is not empty; one axpy per row with `s_i,p ≠ 0`).
fn block_times(block: &[f64], s_i: &[f64], s_j: &[f64], from_j: &mut [f64], from_i: &mut [f64]) {
    if s_j.is_empty() {
        return;
    }
    let (rows, columns) = (!from_j.is_empty(), !from_i.is_empty());
    for (p, row) in block.chunks_exact(s_j.len()).enumerate() {
        if rows {
            from_j[p] = dot(row, s_j);
        }
        let sp = s_i[p];
        if columns && sp != 0.0 {
            for (o, &w) in from_i.iter_mut().zip(row) {
                *o += w * sp;
            }
        }
    }
}

/// `Σ a_i b_i` with eight interleaved partial sums (a fixed order the compiler vectorises).
#[inline]
fn dot(a: &[f64], b: &[f64]) -> f64 {
    let mut acc = [0.0f64; 8];
    let (ac, bc) = (a.chunks_exact(8), b.chunks_exact(8));
    let tail: f64 = ac
        .remainder()
        .iter()
        .zip(bc.remainder())
        .map(|(x, y)| x * y)
        .sum();
    for (a8, b8) in ac.zip(bc) {
        for l in 0..8 {
            acc[l] += a8[l] * b8[l];
        }
    }
    ((acc[0] + acc[1]) + (acc[2] + acc[3])) + ((acc[4] + acc[5]) + (acc[6] + acc[7])) + tail
}

/// Sub-bins per bin side: about [`TILE`] MPs per sub-bin on average over the occupied bins
/// (1 when a bin holds fewer), so that a tile of the [`SymmetricPlan`] is about one sub-bin.
fn sub_bins_per_side(n: usize, bins: impl Iterator<Item = (u16, [i64; 2])>) -> i64 {
    let mut occupied: Vec<(u16, [i64; 2])> = bins.collect();
    occupied.sort_unstable();
    occupied.dedup();
    let per_bin = n as f64 / occupied.len().max(1) as f64;
    ((per_bin / TILE as f64).sqrt().ceil() as i64).clamp(1, 64)
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
