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
//!   slice, found by binary search. Memory is `O(N)` whatever the spread of the points, and no
//!   pair list is stored (neighbour counts reach ~7000 per MP): distances are recomputed.
//! * The denominators `Σ_s w V_s` are computed once in [`NonlocalAverager::new`].
//! * [`NonlocalAverager::average`] first compacts the nonzero entries of the field (in the
//!   sorted order), then *gathers* for every output MP from the compacted list only. The pair
//!   count is therefore the same as for a scatter from the nonzero sources, but every output
//!   entry is summed by one task in a fixed order (rows `dy = −1, 0, 1`, then sorted order):
//!   the result is bit-identical for any number of rayon threads.
//! * For a field that is nonzero everywhere, the numerator visits the sources in exactly the
//!   order used for the denominator, with the term `w · (V_q f_q)` against `w · V_q`; a field
//!   equal to 1 is thus reproduced bit-exactly and any uniform field to a few ulps.

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Default cutoff factor: `R_c = 3 l_s` (DESIGN §6 / decision log item 12). Beyond `3 l_s` the
/// area-weighted tail of [`weight`] holds 4.4e−4 of its integral.
pub const DEFAULT_CUTOFF_FACTOR: f64 = 3.0;

/// Relative enlargement of the bin size over `R_c`, so that two points at a distance `≤ R_c`
/// always lie in the same or adjacent bins despite rounding in `floor((x − x0) / bin)`.
const BIN_SAFETY: f64 = 1.0 + 1e-9;

/// Minimum number of output MPs per rayon task.
const MIN_CHUNK: usize = 64;

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
/// One shared definition keeps denominators and numerators bit-consistent.
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

    /// Calls `visit(r², s_q)` for every source of `key.group` in the 3×3 bins around `key`
    /// with `r² ≤ rc2`, in a fixed order (rows `by − 1, by, by + 1`, then list order).
    #[inline]
    fn for_each_neighbour(
        &self,
        key: BinKey,
        px: f64,
        py: f64,
        rc2: f64,
        mut visit: impl FnMut(f64, f64),
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
                    visit(r2, ss[j]);
                }
            }
        }
    }
}

/// Nonlocal averaging operator `W` of \[D34\] over a fixed set of MPs (start-of-step positions
/// and volumes), applied as in \[D35\]/\[D36\] (paper eq. 6).
///
/// Built once per step by [`NonlocalAverager::new`] (bins and denominators); every
/// [`NonlocalAverager::average`] call then costs one pass over the pairs `(p, q)` with
/// `field_q ≠ 0` and `|x_p − x_q| ≤ R_c`. Results do not depend on the number of rayon threads.
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
    /// Original-indexed field values are read in key order through `order`; the denominators
    /// below are in key order as well.
    denominators_sorted: Vec<f64>,
    /// Neighbour count statistics (min, mean, max) over all MPs.
    stats: (usize, f64, usize),
}

impl NonlocalAverager {
    /// Builds the operator \[D34\] from start-of-step positions `x_q`, volumes `V_q` and a group
    /// (material) id per MP; only MPs of the same group average together (DESIGN §6).
    ///
    /// Sorts the MPs into a cell-linked list with bins of size `R_c` and computes the weight
    /// denominators `Σ_s w(|x_p − x_s|) V_s` (sum over same-group MPs within `R_c`). An MP
    /// whose denominator is 0 (isolated, or only zero-volume/coincident neighbours) gets
    /// `W_pp = 1`, i.e. keeps its own value.
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

        let results: Vec<(f64, usize)> = (0..n)
            .into_par_iter()
            .with_min_len(MIN_CHUNK)
            .map(|k| {
                let (px, py) = (sorted.x[k], sorted.y[k]);
                let mut den = 0.0;
                let mut count = 0usize;
                sorted.for_each_neighbour(sorted.keys[k], px, py, rc2, |r2, v| {
                    den += kernel(r2, inv_l2) * v;
                    count += 1;
                });
                // The MP itself is always found (r = 0) and is not its own neighbour.
                (den, count - 1)
            })
            .collect();
        let denominators_sorted: Vec<f64> = results.iter().map(|r| r.0).collect();
        let stats = if n == 0 {
            (0, 0.0, 0)
        } else {
            let min = results.iter().map(|r| r.1).min().unwrap_or(0);
            let max = results.iter().map(|r| r.1).max().unwrap_or(0);
            let mean = results.iter().map(|r| r.1 as f64).sum::<f64>() / n as f64;
            (min, mean, max)
        };
        Ok(Self {
            params: *params,
            rc2,
            inv_l2,
            bin,
            origin,
            sorted,
            order,
            denominators_sorted,
            stats,
        })
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
            d[i] = self.denominators_sorted[k];
        }
        d
    }

    /// Applies the operator of \[D34\]: `out_p = Σ_q W_pq field_q` for a field given at every MP
    /// (original order), as used by \[D35\]/\[D36\] with `field = Δκ` (paper eq. 6).
    ///
    /// Only sources with `field_q ≠ 0` are visited (they are compacted first, then every
    /// output entry gathers from them), so the cost scales with the number of nonzero sources'
    /// neighbours. Each `out_p` is summed in a fixed order by a single task: the result is
    /// bit-identical for any number of rayon threads. Isolated MPs (zero denominator) copy
    /// their own value (`W_pp = 1`). `out` is overwritten.
    ///
    /// # Errors
    /// [`NonlocalError::FieldLengthMismatch`] if `field` or `out` does not have [`Self::len`]
    /// entries.
    pub fn average(&self, field: &[f64], out: &mut [f64]) -> Result<(), NonlocalError> {
        let n = self.len();
        if field.len() != n || out.len() != n {
            return Err(NonlocalError::FieldLengthMismatch {
                expected: n,
                field: field.len(),
                out: out.len(),
            });
        }
        // Compact the nonzero sources, keeping the key order of the full list.
        let mut sources = SourceList::with_capacity(n / 4);
        for (k, &i) in self.order.iter().enumerate() {
            let f = field[i];
            if f != 0.0 {
                sources.push(
                    self.sorted.keys[k],
                    self.sorted.x[k],
                    self.sorted.y[k],
                    self.sorted.s[k] * f,
                );
            }
        }
        let (rc2, inv_l2) = (self.rc2, self.inv_l2);
        let mut out_sorted = vec![0.0; n];
        if !sources.keys.is_empty() {
            out_sorted
                .par_iter_mut()
                .with_min_len(MIN_CHUNK)
                .enumerate()
                .for_each(|(k, o)| {
                    let den = self.denominators_sorted[k];
                    if den == 0.0 {
                        *o = field[self.order[k]];
                        return;
                    }
                    let mut num = 0.0;
                    sources.for_each_neighbour(
                        self.sorted.keys[k],
                        self.sorted.x[k],
                        self.sorted.y[k],
                        rc2,
                        |r2, s| num += kernel(r2, inv_l2) * s,
                    );
                    *o = num / den;
                });
        }
        for (k, &i) in self.order.iter().enumerate() {
            out[i] = out_sorted[k];
        }
        Ok(())
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
        self.stats
    }

    /// Bin size of the cell-linked list (`R_c` enlarged by a relative 1e−9) and the bin origin.
    pub fn bin_geometry(&self) -> (f64, [f64; 2]) {
        (self.bin, self.origin)
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
