//! Tiles of the key-ordered MPs and the list of tile pairs within `R_c`
//! ([`SymmetricPlan`]), with the block products that the pair passes share.

use rayon::prelude::*;

use super::averager::SourceList;
use super::kernel::{weight_row, weight_row_culled};
use super::parameters::NonlocalError;
use super::{CHUNK, TILE};

/// A run of at most [`TILE`] consecutive MPs (key order) of one group and bin row, with its
/// bounding box ([`SymmetricPlan`]).
#[derive(Debug, Clone)]
pub(super) struct Tile {
    pub(super) lo: usize,
    pub(super) hi: usize,
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
    pub(super) fn new(sorted: &SourceList, lo: usize, hi: usize) -> Self {
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
    pub(super) fn chunk_gap2(&self, c: usize, x: [f64; 2]) -> f64 {
        let b = &self.chunks[c];
        box_gap2([b[0], b[1]], [b[2], b[3]], x, x)
    }

    /// Squared gap between the bounding boxes of `self` and `other` (0 if they
    /// overlap), a lower bound of the computed `r²` of every pair of their MPs.
    pub(super) fn gap2_to(&self, other: &Tile) -> f64 {
        box_gap2(self.min, self.max, other.min, other.max)
    }

    /// Squared gap between the point `x` and the bounding box (0 inside), a lower
    /// bound of the computed `r²` from `x` to every MP of the tile.
    pub(super) fn gap2(&self, x: [f64; 2]) -> f64 {
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
pub(super) struct SymmetricPlan {
    pub(super) tiles: Vec<Tile>,
    /// Tile pairs `(I, J)`, `I ≤ J`, in lexicographic order.
    pub(super) pairs: Vec<(usize, usize)>,
    /// Per tile, its `(pair, is_second_tile)` entries in pair order.
    pub(super) touches: Vec<Vec<(usize, bool)>>,
}

impl SymmetricPlan {
    /// Cuts the key-ordered MPs into tiles ([`Tile`]) and lists every pair of tiles `I ≤ J` of
    /// the same group in the same or the next bin row whose bounding boxes are within `R_c`.
    /// The box test is a rounding-monotone lower bound of every computed `r²`, and bins are
    /// `≥ R_c`, so the pairs cover exactly the pairs of the cell list.
    pub(super) fn new(sorted: &SourceList, rc2: f64) -> Self {
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
    pub(super) fn block_len(&self, e: usize) -> usize {
        let (i, j) = self.pairs[e];
        (self.tiles[i].hi - self.tiles[i].lo) * (self.tiles[j].hi - self.tiles[j].lo)
    }

    /// Fills the weight block of tile pair `e` ([`super::averager::WeightCache`]): `w(|x_p − x_q|)` for every MP
    /// `p` of the first tile (rows) and `q` of the second (columns) within `R_c`, the same
    /// bits as the symmetric pass ([`Self::sums`]) writes.
    pub(super) fn fill_block(
        &self,
        e: usize,
        sorted: &SourceList,
        rc2: f64,
        inv_l2: f64,
        block: &mut [f64],
    ) {
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
    /// into every nonempty (zeroed) entry, laid out as [`super::averager::WeightCache`] describes.
    pub(super) fn sums<const K: usize>(
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

/// The partial sums of a cached block ([`super::averager::WeightCache`]), read once: `from_j_p = Σ_q w_pq s_j,q`
/// per row `p` (if `from_j` is not empty) and `from_i_q = Σ_p w_pq s_i,p` per column `q` (if
/// `from_i` is not empty; one axpy per row with `s_i,p ≠ 0`).
pub(super) fn block_times(
    block: &[f64],
    s_i: &[f64],
    s_j: &[f64],
    from_j: &mut [f64],
    from_i: &mut [f64],
) {
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
pub(super) fn sub_bins_per_side(n: usize, bins: impl Iterator<Item = (u16, [i64; 2])>) -> i64 {
    let mut occupied: Vec<(u16, [i64; 2])> = bins.collect();
    occupied.sort_unstable();
    occupied.dedup();
    let per_bin = n as f64 / occupied.len().max(1) as f64;
    ((per_bin / TILE as f64).sqrt().ceil() as i64).clamp(1, 64)
}

/// A field and an output of one entry per MP each (`n` MPs).
pub(super) fn check_field_lengths(
    n: usize,
    field: &[f64],
    out_len: usize,
) -> Result<(), NonlocalError> {
    if field.len() != n || out_len != n {
        return Err(NonlocalError::FieldLengthMismatch {
            expected: n,
            field: field.len(),
            out: out_len,
        });
    }
    Ok(())
}

pub(super) fn validate_inputs(
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
