//! Mesh-objectivity metrics of theory §9 (M1–M5), on plain data.
//!
//! Every function here takes slices (load curves as `(δ, F)` pairs, material
//! point positions and values, Voigt 4-vectors) and none of the engine's
//! types, so the metrics can be computed from CSV output as well as in a run.
//!
//! * M1 – post-peak curve discrepancy \[D42\]: [`post_peak_discrepancy`],
//!   [`curve_discrepancy`], [`family_discrepancy`].
//! * M2 – peak spread: [`peak`], [`peak_spread`].
//! * M3 – brittleness: [`brittleness`].
//! * M4 – shear-band width: [`shear_band_width`], [`shear_band_width_in`].
//! * M5 – dissipated energy \[D43\]: [`Dissipation`], [`dissipation_increment`],
//!   [`external_work`], [`elastic_energy`], [`energy_balance`].
//!
//! Curves must have non-decreasing abscissae (δ or t); they are interpolated
//! linearly and never extrapolated beyond a relative tolerance of
//! [`RANGE_TOL`] of their abscissa range.

use thiserror::Error;

mod time_history;
pub use time_history::{fall_roughness, first_exceedance, reversals};

/// Number of sample points of the M1 discrepancy \[D42\].
pub const M1_SAMPLES: usize = 101;

/// Relative tolerance (of a curve's abscissa range) within which a sample
/// abscissa just outside the curve is clamped to the curve's end instead of
/// being rejected (accumulated round-off of δ = n·Δδ).
pub const RANGE_TOL: f64 = 1e-6;

/// Why a metric could not be evaluated.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum MetricsError {
    /// A curve or point set has too few (finite) entries.
    #[error("empty or too short input: {0}")]
    Empty(&'static str),
    /// Slices that must match in length do not.
    #[error("length mismatch: {0}")]
    LengthMismatch(&'static str),
    /// A NaN/inf where a finite number is needed.
    #[error("non-finite input: {0}")]
    NonFinite(&'static str),
    /// Abscissae decrease somewhere.
    #[error("abscissae of a curve must be non-decreasing")]
    NotMonotone,
    /// A sample abscissa lies outside a curve's range.
    #[error("abscissa {x} outside curve range [{lo}, {hi}]")]
    OutOfRange {
        /// requested abscissa
        x: f64,
        /// first abscissa of the curve
        lo: f64,
        /// last abscissa of the curve
        hi: f64,
    },
    /// The input is valid but the metric is undefined (zero peak, no band…).
    #[error("degenerate input: {0}")]
    Degenerate(&'static str),
}

/// Result type of this module.
pub type Result<T> = std::result::Result<T, MetricsError>;

// ---------------------------------------------------------------------------
// Curves: validation, interpolation, peak (M1–M3)
// ---------------------------------------------------------------------------

fn check_curve(curve: &[(f64, f64)], what: &'static str) -> Result<()> {
    if curve.len() < 2 {
        return Err(MetricsError::Empty(what));
    }
    if curve.iter().any(|&(x, y)| !x.is_finite() || !y.is_finite()) {
        return Err(MetricsError::NonFinite(what));
    }
    if curve.windows(2).any(|w| w[1].0 < w[0].0) {
        return Err(MetricsError::NotMonotone);
    }
    if curve[curve.len() - 1].0 <= curve[0].0 {
        return Err(MetricsError::Degenerate("curve has zero abscissa range"));
    }
    Ok(())
}

/// Linear interpolation of a curve (non-decreasing abscissae) at `x`.
///
/// `x` within [`RANGE_TOL`]·range outside the curve is clamped to the end
/// value; farther out is [`MetricsError::OutOfRange`]. At a vertical step
/// (repeated abscissa) the value right of the step (its last point) is used.
pub fn interpolate(curve: &[(f64, f64)], x: f64) -> Result<f64> {
    check_curve(curve, "curve")?;
    interp_unchecked(curve, x)
}

fn interp_unchecked(curve: &[(f64, f64)], x: f64) -> Result<f64> {
    let (lo, hi) = (curve[0].0, curve[curve.len() - 1].0);
    let tol = RANGE_TOL * (hi - lo);
    if !x.is_finite() || x < lo - tol || x > hi + tol {
        return Err(MetricsError::OutOfRange { x, lo, hi });
    }
    if x <= lo {
        return Ok(curve[0].1);
    }
    if x >= hi {
        return Ok(curve[curve.len() - 1].1);
    }
    // first index with abscissa > x (exists because x < hi)
    let k = curve.partition_point(|p| p.0 <= x);
    // curve[k - 1].0 <= x < curve[k].0: the interval has positive length
    let (x0, y0) = curve[k - 1];
    let (x1, y1) = curve[k];
    Ok(y0 + (y1 - y0) * (x - x0) / (x1 - x0))
}

/// Peak of a load curve: `(δ_peak, F_peak)` = the point of maximum F (first
/// one if several are equal).
pub fn peak(curve: &[(f64, f64)]) -> Result<(f64, f64)> {
    if curve.is_empty() {
        return Err(MetricsError::Empty("curve"));
    }
    if curve.iter().any(|&(x, y)| !x.is_finite() || !y.is_finite()) {
        return Err(MetricsError::NonFinite("curve"));
    }
    let mut best = curve[0];
    for &p in &curve[1..] {
        if p.1 > best.1 {
            best = p;
        }
    }
    Ok(best)
}

/// Relative L2 discrepancy of `curve` against `reference` on
/// [`M1_SAMPLES`] equally spaced abscissae in `[x_start, x_end]` \[D42\]:
///
/// e = sqrt(Σ_j (F(x_j) − F_ref(x_j))²) / sqrt(Σ_j F_ref(x_j)²)
///
/// This is the general form used for the cut (u_A(t) on [0, t_end]); for the
/// load curves use [`post_peak_discrepancy`].
pub fn curve_discrepancy(
    curve: &[(f64, f64)],
    reference: &[(f64, f64)],
    x_start: f64,
    x_end: f64,
) -> Result<f64> {
    check_curve(curve, "curve")?;
    check_curve(reference, "reference")?;
    if !x_start.is_finite() || !x_end.is_finite() {
        return Err(MetricsError::NonFinite("sample interval"));
    }
    if x_end <= x_start {
        return Err(MetricsError::Degenerate("empty sample interval"));
    }
    let n = M1_SAMPLES - 1;
    let (mut num, mut den) = (0.0, 0.0);
    for j in 0..=n {
        let x = x_start + (x_end - x_start) * j as f64 / n as f64;
        let f = interp_unchecked(curve, x)?;
        let r = interp_unchecked(reference, x)?;
        num += (f - r) * (f - r);
        den += r * r;
    }
    if den == 0.0 {
        return Err(MetricsError::Degenerate(
            "reference is zero on the interval",
        ));
    }
    Ok((num / den).sqrt())
}

/// M1 post-peak discrepancy e_h \[D42\]: [`curve_discrepancy`] on
/// `[δ_peak,ref, delta_end]`, δ_peak,ref being the abscissa of the
/// reference curve's peak ([`peak`]).
pub fn post_peak_discrepancy(
    curve: &[(f64, f64)],
    reference: &[(f64, f64)],
    delta_end: f64,
) -> Result<f64> {
    let (d_peak, _) = peak(reference)?;
    curve_discrepancy(curve, reference, d_peak, delta_end)
}

/// M1 family value S = max_h e_h \[D42\] over `curves` (the reference itself
/// may be among them; it contributes 0).
pub fn family_discrepancy(
    curves: &[&[(f64, f64)]],
    reference: &[(f64, f64)],
    delta_end: f64,
) -> Result<f64> {
    if curves.is_empty() {
        return Err(MetricsError::Empty("family of curves"));
    }
    let mut s = 0.0f64;
    for c in curves {
        s = s.max(post_peak_discrepancy(c, reference, delta_end)?);
    }
    Ok(s)
}

/// M2 peak spread |F_peak,h / F_peak,ref − 1|.
pub fn peak_spread(curve: &[(f64, f64)], reference: &[(f64, f64)]) -> Result<f64> {
    let (_, f) = peak(curve)?;
    let (_, r) = peak(reference)?;
    if r == 0.0 {
        return Err(MetricsError::Degenerate("reference peak is zero"));
    }
    Ok((f / r - 1.0).abs())
}

/// M3 brittleness β = (F_peak − F(δ_end)) / F_peak, F(δ_end) interpolated.
pub fn brittleness(curve: &[(f64, f64)], delta_end: f64) -> Result<f64> {
    check_curve(curve, "curve")?;
    let (_, fp) = peak(curve)?;
    if fp <= 0.0 {
        return Err(MetricsError::Degenerate("peak load is not positive"));
    }
    let fe = interp_unchecked(curve, delta_end)?;
    Ok((fp - fe) / fp)
}

/// M3 drop length Δδ_½ = δ_½ − δ_peak: the travel from the peak to where the
/// load first falls to half the peak after it, interpolated linearly between
/// the bracketing points (theory §9, M3). `None` where the load stays above
/// half the peak; negative where the curve snaps back (path following).
pub fn half_peak_drop(curve: &[(f64, f64)]) -> Result<Option<f64>> {
    if curve.len() < 2 {
        return Err(MetricsError::Empty("curve"));
    }
    let (delta_peak, load_peak) = peak(curve)?;
    if load_peak <= 0.0 {
        return Err(MetricsError::Degenerate("peak load is not positive"));
    }
    let half = 0.5 * load_peak;
    let start = curve.iter().position(|p| p.1 == load_peak).unwrap_or(0);
    Ok(curve[start..].windows(2).find_map(|pair| {
        let ((d0, f0), (d1, f1)) = (pair[0], pair[1]);
        (f1 <= half).then(|| d0 + (d1 - d0) * (f0 - half) / (f0 - f1) - delta_peak)
    }))
}

// ---------------------------------------------------------------------------
// M4: shear-band width
// ---------------------------------------------------------------------------

/// One bin of the M4 cross-band profile.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProfileBin {
    /// Mean signed normal distance of the bin's points (the profile abscissa).
    pub d: f64,
    /// Mean εq of the bin's points (background not subtracted).
    pub eps_q: f64,
    /// Number of points in the bin.
    pub count: usize,
}

/// M4 result: band width, geometry and diagnostics.
#[derive(Debug, Clone, PartialEq)]
pub struct BandWidth {
    /// w_b: full width at half maximum of the background-corrected profile.
    pub width: f64,
    /// Point on the band centreline at the FWHM centre (midpoint of the two
    /// half-maximum crossings), in the plane.
    pub centre: [f64; 2],
    /// Unit direction of the band (principal axis; sign: x ≥ 0, or +y if
    /// vertical).
    pub direction: [f64; 2],
    /// Unit normal of the band, `[-direction[1], direction[0]]`; the sign of
    /// the profile abscissa d.
    pub normal: [f64; 2],
    /// Band midpoint on the fitted line (middle of the thresholded points'
    /// extent along the band), the slab's centre.
    pub midpoint: [f64; 2],
    /// max εq over the considered points.
    pub max_eps_q: f64,
    /// Number of points with εq ≥ ½ max εq (used for the line fit).
    pub n_band: usize,
    /// Ratio of the smaller to the larger principal variance of the band
    /// points (≪ 1 for a well-defined straight band).
    pub aspect: f64,
    /// Half length along the band of the slab, 2·max(h, l_s/4).
    pub slab_half_length: f64,
    /// Number of points in the slab.
    pub n_slab: usize,
    /// Background εq subtracted from the profile.
    pub background: f64,
    /// Number of bins with |d| > 1.5·w_guess used for the background; 0 means
    /// none existed and the profile minimum was used instead.
    pub n_background_bins: usize,
    /// Peak of the background-corrected profile.
    pub peak: f64,
    /// Signed normal distances of the left and right half-maximum crossings.
    pub crossings: (f64, f64),
    /// The binned profile (non-empty bins, increasing d).
    pub profile: Vec<ProfileBin>,
    /// Points skipped because their εq or position was not finite.
    pub n_skipped: usize,
}

/// `values` with everything above their `quantile` (e.g. 0.99) clipped to it
/// (NaN kept). Used before M4: a few material points squeezed at a platen
/// corner reach strains far above the band's, and "½ max εq" would then select
/// them instead of the band.
pub fn clip_outliers(values: &[f64], quantile: f64) -> Vec<f64> {
    let mut finite: Vec<f64> = values.iter().copied().filter(|v| v.is_finite()).collect();
    if finite.is_empty() {
        return values.to_vec();
    }
    finite.sort_by(f64::total_cmp);
    let index = ((finite.len() - 1) as f64 * quantile.clamp(0.0, 1.0)).round() as usize;
    let cap = finite[index];
    values
        .iter()
        .map(|&v| if v.is_finite() { v.min(cap) } else { v })
        .collect()
}

/// M4 shear-band width (theory §9) over all material points.
///
/// `positions` and `eps_q` (εq of \[D8\]) per MP, `h` the cell size, `l_s`
/// the nonlocal length (0 for local runs). See [`shear_band_width_in`].
pub fn shear_band_width(
    positions: &[[f64; 2]],
    eps_q: &[f64],
    h: f64,
    l_s: f64,
) -> Result<BandWidth> {
    shear_band_width_in(positions, eps_q, h, l_s, |_| true)
}

/// M4 shear-band width restricted to the MPs for which `region(x)` is true
/// (e.g. the main Prandtl branch of the footing).
///
/// Steps (theory §9, M4):
/// 1. band points: εq ≥ ½ max εq; principal-component line fit (centroid and
///    major axis of their covariance) gives the direction t and normal n;
/// 2. midpoint m: the middle of the band points' extent along t;
/// 3. slab: MPs with |(x − m)·t| ≤ 2·max(h, l_s/4);
/// 4. bins of width h/2 in d = (x − m)·n, centred on d = k·h/2; each bin
///    holds the mean εq and the mean d of its points (the profile abscissa,
///    which removes the up-to-half-bin offset of a bin's points);
/// 5. background = median of the bins with |d_bin| > 1.5·w_guess,
///    w_guess = max(l_s, 4h) (profile minimum if there are none);
/// 6. width = distance between the half-maximum crossings on either side of
///    the profile maximum, linearly interpolated between adjacent bins.
///
/// Errors (never panics) on empty or mismatched input, non-positive h, no
/// positive strain, coincident band points, or a profile that does not fall
/// below half maximum on both sides.
pub fn shear_band_width_in(
    positions: &[[f64; 2]],
    eps_q: &[f64],
    h: f64,
    l_s: f64,
    region: impl Fn([f64; 2]) -> bool,
) -> Result<BandWidth> {
    check_band_inputs(positions, eps_q, h, l_s)?;
    let (pts, n_skipped) = selected_points(positions, eps_q, region)?;
    let max_eps = pts.iter().map(|p| p.1).fold(f64::NEG_INFINITY, f64::max);
    if max_eps <= 0.0 {
        return Err(MetricsError::Degenerate("max εq is not positive"));
    }
    let line = band_line(&pts, max_eps, h)?;
    let m = band_midpoint(&line);
    let half_len = 2.0 * h.max(0.25 * l_s);
    let (bins, n_slab) = slab_bins(&pts, &line, m, half_len, h);
    let profile: Vec<ProfileBin> = bins
        .values()
        .map(|&(sd, se, cnt)| ProfileBin {
            d: sd / cnt as f64,
            eps_q: se / cnt as f64,
            count: cnt,
        })
        .collect();
    if profile.len() < 3 {
        return Err(MetricsError::Degenerate("fewer than 3 profile bins"));
    }
    let (background, n_background_bins) = background_level(&bins, &profile, h, l_s);
    let (peak, (left, right)) = half_maximum_crossings(&profile, background)?;
    let (t, n) = (line.direction, line.normal);
    let dc = 0.5 * (left + right);
    Ok(BandWidth {
        width: right - left,
        centre: [m[0] + dc * n[0], m[1] + dc * n[1]],
        direction: t,
        normal: n,
        midpoint: m,
        max_eps_q: max_eps,
        n_band: line.band.len(),
        aspect: line.aspect,
        slab_half_length: half_len,
        n_slab,
        background,
        n_background_bins,
        peak,
        crossings: (left, right),
        profile,
        n_skipped,
    })
}

/// The inputs of [`shear_band_width_in`]: as many strains as points, h
/// positive and finite, l_s non-negative and finite.
fn check_band_inputs(positions: &[[f64; 2]], eps_q: &[f64], h: f64, l_s: f64) -> Result<()> {
    if positions.len() != eps_q.len() {
        return Err(MetricsError::LengthMismatch("positions vs eps_q"));
    }
    if !(h.is_finite() && h > 0.0) {
        return Err(MetricsError::Degenerate("h must be positive and finite"));
    }
    if !(l_s.is_finite() && l_s >= 0.0) {
        return Err(MetricsError::Degenerate(
            "l_s must be non-negative and finite",
        ));
    }
    Ok(())
}

/// A material point's position and εq.
type PointStrain = ([f64; 2], f64);

/// The finite points (position, εq) inside `region`, and how many points
/// were skipped as not finite.
fn selected_points(
    positions: &[[f64; 2]],
    eps_q: &[f64],
    region: impl Fn([f64; 2]) -> bool,
) -> Result<(Vec<PointStrain>, usize)> {
    let mut n_skipped = 0usize;
    let mut pts: Vec<PointStrain> = Vec::with_capacity(positions.len());
    for (&x, &e) in positions.iter().zip(eps_q) {
        if !(x[0].is_finite() && x[1].is_finite() && e.is_finite()) {
            n_skipped += 1;
            continue;
        }
        if region(x) {
            pts.push((x, e));
        }
    }
    if pts.is_empty() {
        return Err(MetricsError::Empty("material points"));
    }
    Ok((pts, n_skipped))
}

/// The band points of M4 step 1 and their principal-component line.
struct BandLine {
    /// Points with εq ≥ ½ max εq.
    band: Vec<[f64; 2]>,
    /// Their centroid.
    centroid: [f64; 2],
    /// The major axis t (t_x > 0, or t_y > 0 when t_x = 0).
    direction: [f64; 2],
    /// The normal n = t rotated by +90°.
    normal: [f64; 2],
    /// Minor over major eigenvalue of the band points' covariance.
    aspect: f64,
}

/// M4 step 1: the band points (εq ≥ ½ max εq) and the centroid and major
/// axis of their covariance.
fn band_line(pts: &[PointStrain], max_eps: f64, h: f64) -> Result<BandLine> {
    let band: Vec<[f64; 2]> = pts
        .iter()
        .filter(|p| p.1 >= 0.5 * max_eps)
        .map(|p| p.0)
        .collect();
    if band.len() < 2 {
        return Err(MetricsError::Degenerate("fewer than 2 band points"));
    }
    let nb = band.len() as f64;
    let c = [
        band.iter().map(|x| x[0]).sum::<f64>() / nb,
        band.iter().map(|x| x[1]).sum::<f64>() / nb,
    ];
    let (mut sxx, mut syy, mut sxy) = (0.0, 0.0, 0.0);
    for x in &band {
        let (dx, dy) = (x[0] - c[0], x[1] - c[1]);
        sxx += dx * dx;
        syy += dy * dy;
        sxy += dx * dy;
    }
    sxx /= nb;
    syy /= nb;
    sxy /= nb;
    // eigenvalues of [[sxx, sxy], [sxy, syy]]
    let half_tr = 0.5 * (sxx + syy);
    let disc = (0.25 * (sxx - syy) * (sxx - syy) + sxy * sxy).sqrt();
    let (l1, l2) = (half_tr + disc, half_tr - disc);
    if l1 <= f64::EPSILON * h * h {
        return Err(MetricsError::Degenerate("band points coincide"));
    }
    // major axis angle: tan 2α = 2 sxy / (sxx − syy)
    let alpha = 0.5 * (2.0 * sxy).atan2(sxx - syy);
    let mut t = [alpha.cos(), alpha.sin()];
    if t[0] < 0.0 || (t[0] == 0.0 && t[1] < 0.0) {
        t = [-t[0], -t[1]];
    }
    let n = [-t[1], t[0]];
    let aspect = (l2.max(0.0)) / l1;
    Ok(BandLine {
        band,
        centroid: c,
        direction: t,
        normal: n,
        aspect,
    })
}

/// M4 step 2: the midpoint m, the middle of the band points' extent along t.
fn band_midpoint(line: &BandLine) -> [f64; 2] {
    let (band, c, t) = (&line.band, line.centroid, line.direction);
    let (mut smin, mut smax) = (f64::INFINITY, f64::NEG_INFINITY);
    for x in band {
        let s = (x[0] - c[0]) * t[0] + (x[1] - c[1]) * t[1];
        smin = smin.min(s);
        smax = smax.max(s);
    }
    let sm = 0.5 * (smin + smax);
    [c[0] + sm * t[0], c[1] + sm * t[1]]
}

/// Per bin k of the profile: Σ d, Σ εq and the count of its points.
type ProfileSums = std::collections::BTreeMap<i64, (f64, f64, usize)>;

/// M4 steps 3–4: the MPs of the slab |(x − m)·t| ≤ `half_len`, summed into
/// bins of width h/2 in d = (x − m)·n centred on d = k·h/2; and how many
/// MPs the slab holds.
fn slab_bins(
    pts: &[PointStrain],
    line: &BandLine,
    m: [f64; 2],
    half_len: f64,
    h: f64,
) -> (ProfileSums, usize) {
    let (t, n) = (line.direction, line.normal);
    let bw = 0.5 * h;
    let mut bins: ProfileSums = Default::default();
    let mut n_slab = 0usize;
    for &(x, e) in pts {
        let (dx, dy) = (x[0] - m[0], x[1] - m[1]);
        let s = dx * t[0] + dy * t[1];
        if s.abs() > half_len {
            continue;
        }
        let d = dx * n[0] + dy * n[1];
        let k = (d / bw).round();
        if !k.is_finite() || k.abs() > 1e15 {
            continue;
        }
        n_slab += 1;
        let b = bins.entry(k as i64).or_insert((0.0, 0.0, 0));
        b.0 += d;
        b.1 += e;
        b.2 += 1;
    }
    (bins, n_slab)
}

/// M4 step 5: the background εq, the median of the bins with
/// |d_bin| > 1.5·w_guess, w_guess = max(l_s, 4h) (the profile minimum if
/// there are none); and how many bins it is the median of.
fn background_level(bins: &ProfileSums, profile: &[ProfileBin], h: f64, l_s: f64) -> (f64, usize) {
    let bw = 0.5 * h;
    let w_guess = l_s.max(4.0 * h);
    let mut tail: Vec<f64> = bins
        .iter()
        .filter(|(&k, _)| (k as f64 * bw).abs() > 1.5 * w_guess)
        .map(|(_, &(_, se, cnt))| se / cnt as f64)
        .collect();
    let n_background_bins = tail.len();
    let background = if tail.is_empty() {
        profile
            .iter()
            .map(|b| b.eps_q)
            .fold(f64::INFINITY, f64::min)
    } else {
        median(&mut tail)
    };
    (background, n_background_bins)
}

/// M4 step 6: the profile's peak above `background` and its half-maximum
/// crossings on either side, linearly interpolated between adjacent bins.
fn half_maximum_crossings(profile: &[ProfileBin], background: f64) -> Result<(f64, (f64, f64))> {
    let v: Vec<f64> = profile.iter().map(|b| b.eps_q - background).collect();
    let (kmax, &peak) = v
        .iter()
        .enumerate()
        .max_by(|a, b| a.1.total_cmp(b.1))
        .ok_or(MetricsError::Empty("profile"))?;
    if peak <= 0.0 {
        return Err(MetricsError::Degenerate(
            "profile peak not above background",
        ));
    }
    let half = 0.5 * peak;
    let cross = |i_in: usize, i_out: usize| -> f64 {
        let (d0, v0) = (profile[i_in].d, v[i_in]);
        let (d1, v1) = (profile[i_out].d, v[i_out]);
        d0 + (d1 - d0) * (v0 - half) / (v0 - v1)
    };
    let left = (0..kmax)
        .rev()
        .find(|&i| v[i] < half)
        .map(|i| cross(i + 1, i))
        .ok_or(MetricsError::Degenerate(
            "profile does not fall below half maximum on the negative side",
        ))?;
    let right = (kmax + 1..v.len())
        .find(|&i| v[i] < half)
        .map(|i| cross(i - 1, i))
        .ok_or(MetricsError::Degenerate(
            "profile does not fall below half maximum on the positive side",
        ))?;
    Ok((peak, (left, right)))
}

/// Median of finite values (the slice is reordered). Empty → NaN.
fn median(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

// ---------------------------------------------------------------------------
// M5: energies
// ---------------------------------------------------------------------------

/// A 4×4 compliance matrix in the Voigt order of \[D2\] (engineering shear).
pub type Compliance = [[f64; 4]; 4];

/// Isotropic compliance C = D⁻¹ for the 4-component plane-strain Voigt
/// storage \[D2\] (σzz tracked, engineering shear γxy): C = (1/E)·
/// [[1, −ν, −ν, 0], [−ν, 1, −ν, 0], [−ν, −ν, 1, 0], [0, 0, 0, 2(1+ν)]].
pub fn isotropic_compliance(e: f64, nu: f64) -> Compliance {
    let a = 1.0 / e;
    let b = -nu / e;
    let g = 2.0 * (1.0 + nu) / e;
    [
        [a, b, b, 0.0],
        [b, a, b, 0.0],
        [b, b, a, 0.0],
        [0.0, 0.0, 0.0, g],
    ]
}

/// Compliance per material point or one for all (a single material).
#[derive(Debug, Clone, Copy)]
pub enum ComplianceSource<'a> {
    /// The same C for every point.
    Uniform(&'a Compliance),
    /// C_p per point (length = number of points).
    PerPoint(&'a [Compliance]),
}

fn mat_vec(c: &Compliance, v: &[f64; 4]) -> [f64; 4] {
    let mut r = [0.0; 4];
    for i in 0..4 {
        for j in 0..4 {
            r[i] += c[i][j] * v[j];
        }
    }
    r
}

fn dot4(a: &[f64; 4], b: &[f64; 4]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3]
}

/// One point's term of [`dissipation_increment`] per unit volume,
/// σ(n+1) · (Δε − C(σ(n+1) − σ^R(n))), with compliance `c`, `stress_new` =
/// σ(n+1), `stress_rot_old` = σ^R(n) and `dstrain` = Δε.
pub fn dissipation_density(
    c: &Compliance,
    stress_new: &[f64; 4],
    stress_rot_old: &[f64; 4],
    dstrain: &[f64; 4],
) -> f64 {
    let (s1, s0, de) = (stress_new, stress_rot_old, dstrain);
    let ds = [s1[0] - s0[0], s1[1] - s0[1], s1[2] - s0[2], s1[3] - s0[3]];
    let de_el = mat_vec(c, &ds);
    let dep = [
        de[0] - de_el[0],
        de[1] - de_el[1],
        de[2] - de_el[2],
        de[3] - de_el[3],
    ];
    dot4(s1, &dep)
}

/// One point's work of the stress on its strain increment per unit volume,
/// integrated the way the backward-Euler return of the stress update
/// integrates it: the elastic part Δε^e = C(σ(n+1) − σ^R(n)) by the
/// trapezoidal rule (exact for linear elasticity: the change of ½ σ·Cσ), the
/// plastic part Δε^p = Δε − Δε^e at σ(n+1) (the dissipation of
/// [`dissipation_density`]):
///
/// w = ½ (σ(n+1) + σ^R(n)) · Δε^e + σ(n+1) · Δε^p
///   = ½ (σ(n+1) + σ^R(n)) · Δε + ½ (σ(n+1) − σ^R(n)) · Δε^p.
///
/// The plain trapezoid ½ (σ(n+1) + σ^R(n)) · Δε assumes the stress linear
/// in the strain across the step; a point torn from compression to the apex
/// in one step flows dilatantly at σ(n+1) ≈ 0, and the trapezoid charges that
/// flow with ½ σ^R(n), a negative work without bound (the vertical cut's
/// internal work fell below zero). Returns (w, σ(n+1) · Δε^p); same
/// arguments as [`dissipation_density`].
pub fn work_and_dissipation_density(
    c: &Compliance,
    stress_new: &[f64; 4],
    stress_rot_old: &[f64; 4],
    dstrain: &[f64; 4],
) -> (f64, f64) {
    let (s1, s0, de) = (stress_new, stress_rot_old, dstrain);
    let ds = [s1[0] - s0[0], s1[1] - s0[1], s1[2] - s0[2], s1[3] - s0[3]];
    let de_el = mat_vec(c, &ds);
    let sum = [s1[0] + s0[0], s1[1] + s0[1], s1[2] + s0[2], s1[3] + s0[3]];
    let dep = [
        de[0] - de_el[0],
        de[1] - de_el[1],
        de[2] - de_el[2],
        de[3] - de_el[3],
    ];
    let dissipation = dot4(s1, &dep);
    (0.5 * dot4(&sum, &de_el) + dissipation, dissipation)
}

/// One step's dissipation increment \[D43, with σ(n+1) for the trapezoid\]:
///
/// ΔD = Σ_p V_p(n) · σ_p(n+1) · Δε^p_p,
/// Δε^p = Δε − C(σ(n+1) − σ^R(n)),
///
/// with Voigt dot products (engineering shear, \[D2\]). D43 as first
/// written weighted Δε^p with ½(σ(n+1) + σ^R(n)), which can be negative: a point
/// torn from compression to the apex in one step flows dilatantly under
/// the compressive σ^R(n) (measured on the vertical cut: D fell to
/// −7·10⁵ kJ/m). σ(n+1) · Δε^p is the dissipation of the backward-Euler
/// return, Δλ σ:∂g/∂σ ≥ 0 for the HMC surfaces; the two agree to
/// O(Δσ · Δε^p) per step. `volumes` = V_p(n),
/// `stress_new` = σ(n+1) (constitutive stress, before double mapping \[D38\]),
/// `stress_rot_old` = σ^R(n) (the rotated start-of-step stress), `dstrain`
/// = the step's strain increment Δε.
pub fn dissipation_increment(
    volumes: &[f64],
    stress_new: &[[f64; 4]],
    stress_rot_old: &[[f64; 4]],
    dstrain: &[[f64; 4]],
    compliance: ComplianceSource<'_>,
) -> Result<f64> {
    let n = volumes.len();
    if stress_new.len() != n || stress_rot_old.len() != n || dstrain.len() != n {
        return Err(MetricsError::LengthMismatch("per-point arrays of D43"));
    }
    if let ComplianceSource::PerPoint(c) = compliance {
        if c.len() != n {
            return Err(MetricsError::LengthMismatch("per-point compliance"));
        }
    }
    let mut d = 0.0;
    for p in 0..n {
        let c = match compliance {
            ComplianceSource::Uniform(c) => c,
            ComplianceSource::PerPoint(c) => &c[p],
        };
        d += volumes[p] * dissipation_density(c, &stress_new[p], &stress_rot_old[p], &dstrain[p]);
    }
    if !d.is_finite() {
        return Err(MetricsError::NonFinite("dissipation increment"));
    }
    Ok(d)
}

/// M5 accumulator of the dissipated energy D(δ) \[D43\]: the engine calls
/// [`Dissipation::add_step`] once per converged step; the history of
/// `(load parameter, D)` pairs is kept for output.
#[derive(Debug, Clone, Default)]
pub struct Dissipation {
    total: f64,
    history: Vec<(f64, f64)>,
}

impl Dissipation {
    /// D = 0, empty history.
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds the step's increment ([`dissipation_increment`]) and records
    /// `(at, D)`; `at` is the step's load parameter (δ or t). Returns the
    /// increment. On error nothing is added.
    pub fn add_step(
        &mut self,
        at: f64,
        volumes: &[f64],
        stress_new: &[[f64; 4]],
        stress_rot_old: &[[f64; 4]],
        dstrain: &[[f64; 4]],
        compliance: ComplianceSource<'_>,
    ) -> Result<f64> {
        let inc = dissipation_increment(volumes, stress_new, stress_rot_old, dstrain, compliance)?;
        self.total += inc;
        self.history.push((at, self.total));
        Ok(inc)
    }

    /// Accumulated D.
    pub fn total(&self) -> f64 {
        self.total
    }

    /// `(load parameter, D)` after each step.
    pub fn history(&self) -> &[(f64, f64)] {
        &self.history
    }
}

/// External work W = ∫F dδ of a load curve by the trapezoidal rule (M5).
/// Returns the cumulative work at every curve point, starting at 0.
pub fn external_work_history(curve: &[(f64, f64)]) -> Result<Vec<(f64, f64)>> {
    if curve.is_empty() {
        return Err(MetricsError::Empty("curve"));
    }
    if curve.iter().any(|&(x, y)| !x.is_finite() || !y.is_finite()) {
        return Err(MetricsError::NonFinite("curve"));
    }
    let mut w = 0.0;
    let mut out = Vec::with_capacity(curve.len());
    out.push((curve[0].0, 0.0));
    for s in curve.windows(2) {
        w += 0.5 * (s[0].1 + s[1].1) * (s[1].0 - s[0].0);
        out.push((s[1].0, w));
    }
    Ok(out)
}

/// Total external work W = ∫F dδ (trapezoidal rule) of a load curve (M5).
pub fn external_work(curve: &[(f64, f64)]) -> Result<f64> {
    Ok(external_work_history(curve)?
        .last()
        .map(|p| p.1)
        .unwrap_or(0.0))
}

/// Complementary elastic energy U = Σ_p V_p · ½ σ_p·C σ_p (M5).
///
/// For the balance use the change U(now) − U(initial) (the initial state may
/// be prestressed, e.g. the biaxial −100 kPa).
pub fn elastic_energy(
    volumes: &[f64],
    stress: &[[f64; 4]],
    compliance: ComplianceSource<'_>,
) -> Result<f64> {
    let n = volumes.len();
    if stress.len() != n {
        return Err(MetricsError::LengthMismatch("volumes vs stress"));
    }
    if let ComplianceSource::PerPoint(c) = compliance {
        if c.len() != n {
            return Err(MetricsError::LengthMismatch("per-point compliance"));
        }
    }
    let mut u = 0.0;
    for p in 0..n {
        let c = match compliance {
            ComplianceSource::Uniform(c) => c,
            ComplianceSource::PerPoint(c) => &c[p],
        };
        u += volumes[p] * 0.5 * dot4(&stress[p], &mat_vec(c, &stress[p]));
    }
    Ok(u)
}

/// M5 energy balance W − D − (U − U₀): zero (to discretisation error) when
/// `external_work` contains the work of *all* external loads (platen and
/// confining pressure), `dissipated` is [`Dissipation::total`] and
/// `elastic_now`/`elastic_initial` are [`elastic_energy`] at the end and the
/// start.
pub fn energy_balance(
    external_work: f64,
    dissipated: f64,
    elastic_now: f64,
    elastic_initial: f64,
) -> f64 {
    external_work - dissipated - (elastic_now - elastic_initial)
}

#[cfg(test)]
mod tests;
