//! The Galavi–Schweiger weight (theory D33) and its rows over a tile pair:
//! vectorised, portable, and culled by chunk boxes.

use super::plan::Tile;
use super::CHUNK;

/// Galavi–Schweiger weight \[D33\]: `w(r) = (r / l_s²) · exp(−(r/l_s)²)` (paper eq. 6, theory §6).
///
/// Zero at `r = 0` (an MP never weights itself), maximal at `r = l_s/√2`; no cutoff is applied
/// here (the cutoff belongs to [`super::NonlocalAverager`]).
pub fn weight(r: f64, length_scale: f64) -> f64 {
    let u = r / length_scale;
    (r / (length_scale * length_scale)) * (-(u * u)).exp()
}

/// The kernel used by every sum of this module: \[D33\] evaluated from `r²` and `1/l_s²`.
/// One shared definition keeps denominators, numerators and cached weights bit-consistent.
#[inline(always)]
pub(super) fn kernel(r2: f64, inv_l2: f64) -> f64 {
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
pub(super) fn exp_nonpositive(x: f64) -> f64 {
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
pub(super) fn weight_row(
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
pub(super) fn weight_row_culled(
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
