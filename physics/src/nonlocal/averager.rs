//! The operator `field ↦ W · field` ([`NonlocalAverager`]): the key-sorted
//! MPs, the denominators, the weight cache and the averages (theory D34–D36).

use std::sync::{Mutex, OnceLock};

use rayon::prelude::*;

use super::kernel::kernel;
use super::parameters::{NonlocalError, NonlocalSpec};
use super::plan::{
    block_times, check_field_lengths, sub_bins_per_side, validate_inputs, SymmetricPlan, Tile,
};
use super::{BIN_SAFETY, DEFAULT_PAIR_BUDGET, MIN_CHUNK};
use crate::shape::floor_int;

/// Sort key of an MP: group first, then bin row, bin column, and the sub-bin within the bin
/// (row-major), so that consecutive MPs of a bin, and hence the tiles of the
/// [`SymmetricPlan`], are compact patches rather than strips across the bin.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub(super) struct BinKey {
    pub(super) group: u16,
    pub(super) by: i64,
    pub(super) bx: i64,
    pub(super) sub: u32,
}

/// A list of sources in `BinKey` order (structure of arrays).
#[derive(Debug, Clone, Default)]
pub(super) struct SourceList {
    pub(super) keys: Vec<BinKey>,
    pub(super) x: Vec<f64>,
    pub(super) y: Vec<f64>,
    /// `V_q` (full list) or `V_q f_q` (compacted field).
    s: Vec<f64>,
}

impl SourceList {
    pub(super) fn with_capacity(n: usize) -> Self {
        Self {
            keys: Vec::with_capacity(n),
            x: Vec::with_capacity(n),
            y: Vec::with_capacity(n),
            s: Vec::with_capacity(n),
        }
    }

    pub(super) fn push(&mut self, key: BinKey, x: f64, y: f64, s: f64) {
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
    params: NonlocalSpec,
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
    pub(super) weights: OnceLock<Weights>,
    /// Cached weights of the step (empty until [`NonlocalAverager::cache_sources`]).
    cache: WeightCache,
}

/// The `O(N · n_nb)` part of [`NonlocalAverager`] (\[D34\] denominators), in key order.
#[derive(Debug, Clone)]
pub(super) struct Weights {
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
pub(super) struct WeightCache {
    /// `blocks[e]`: the weight block of tile pair `e` of the plan (empty if not cached).
    pub(super) blocks: Vec<Vec<f64>>,
    /// Tiles every pair of which is cached.
    tile_cached: Vec<bool>,
    /// Per MP (key order): a candidate of [`NonlocalAverager::cache_sources`] in a cached tile.
    source_cached: Vec<bool>,
    /// Number of `true` entries of `source_cached`.
    pub(super) sources: usize,
    /// Number of cached blocks (nonempty entries of `blocks`).
    block_count: usize,
    /// Stored weights over all blocks.
    pub(super) pairs: usize,
    /// Maximum number of stored weights (memory budget, 8 bytes each).
    pub(super) budget: usize,
}

impl WeightCache {
    pub(super) fn new(budget: usize) -> Self {
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
        params: &NonlocalSpec,
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
    pub(super) fn weights(&self) -> &Weights {
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
    pub fn parameters(&self) -> &NonlocalSpec {
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
        check_field_lengths(self.len(), field, out_len)
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
        params: &NonlocalSpec,
        positions: &[[f64; 2]],
        volumes: &[f64],
        groups: &[u16],
        field: &[f64],
        out: &mut [f64],
    ) -> Result<(), NonlocalError> {
        params.validate()?;
        validate_inputs(positions, volumes, groups)?;
        let n = positions.len();
        check_field_lengths(n, field, out.len())?;
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
