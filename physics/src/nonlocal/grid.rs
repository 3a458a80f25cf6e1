//! The nonlocal average on an auxiliary grid (theory §6.1, NG1–NG3): an
//! approximation of \[D34\] whose cost grows with the area the points cover, not with
//! their number of neighbours.
//!
//! Per group (material), the volumes `V_q` and the sources `V_q f_q` are spread to the
//! nodes of a square grid of spacing Δ by bilinear weights (NG1), convolved there with the
//! kernel \[D33\] sampled at the node offsets within `R_c` (NG2, by FFT), and read back at
//! the points by the same bilinear weights, the numerator divided by the denominator (NG3).
//! A uniform field is reproduced exactly (to round-off), as by \[D34\]; the spreading and
//! the reading-back widen the kernel by O(Δ²) (its second moment by about 0.44 (Δ/l_s)²).

use std::sync::{Arc, Mutex};

use rayon::prelude::*;
use rustfft::num_complex::Complex64;
use rustfft::{Fft, FftPlanner};

use super::kernel::kernel;
use super::parameters::{NonlocalError, NonlocalSpec};
use super::plan::{check_field_lengths, validate_inputs};
use crate::shape::floor_int;

/// Most nodes of one group's auxiliary grid (three arrays of 16 bytes a node): a run whose points
/// spread so far that the grid would pass it is refused rather than swapping.
const MAX_NODES: usize = 1 << 26;

/// A denominator at most this fraction of the group's largest is round-off: the MP has no
/// neighbour within `R_c` (one at `R_c` weighs ~1e−4 of the kernel's peak, a group's
/// largest denominator holds thousands of neighbours).
const ISOLATED: f64 = 1e-12;

/// Grid rows (or columns) per rayon task of the transforms.
const LINES_PER_TASK: usize = 8;

/// Nonlocal averaging operator on an auxiliary grid (NG1–NG3), built per step from the
/// start-of-step positions and volumes like [`super::NonlocalAverager`], whose operator
/// \[D34\] it approximates. Deterministic: every sum has a fixed order whatever the number
/// of rayon threads.
#[derive(Debug, Clone)]
pub struct GridAverager {
    /// One grid per group of MPs that average together.
    groups: Vec<GroupGrid>,
    /// Number of MPs.
    n: usize,
}

/// The auxiliary grid of one group.
#[derive(Clone)]
struct GroupGrid {
    /// Original indices of the group's MPs.
    members: Vec<usize>,
    /// Per member: its four nodes (row-major index `iy · nx + ix`) and bilinear weights.
    stencils: Vec<[(usize, f64); 4]>,
    /// Per member: `V_q`.
    volumes: Vec<f64>,
    /// Per member: the weight its own spreading gives it back, `Σ_ab N_a N_b w(|x_a − x_b|)`
    /// (NG3 takes it out: an MP never weights itself, as in \[D34\]).
    self_weights: Vec<f64>,
    /// Rows `0..rows_used` hold every node a member touches.
    rows_used: usize,
    /// The transforms and the kernel's spectrum for the grid's size.
    spectrum: Arc<Spectrum>,
}

impl std::fmt::Debug for GroupGrid {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GroupGrid")
            .field("members", &self.members.len())
            .field("nx", &self.spectrum.nx)
            .field("ny", &self.spectrum.ny)
            .finish()
    }
}

/// The kernel \[D33\] sampled on an `nx × ny` periodic grid of spacing Δ (NG2), its
/// discrete Fourier transform (real, as the sampled kernel is even) scaled by
/// `1 / (nx ny)`, and the planned transforms of that size.
struct Spectrum {
    key: SpectrumKey,
    nx: usize,
    ny: usize,
    /// Real spectrum in column-major order (`ix · ny + iy`), the transposed layout.
    values: Vec<f64>,
    row_forward: Arc<dyn Fft<f64>>,
    row_inverse: Arc<dyn Fft<f64>>,
    column_forward: Arc<dyn Fft<f64>>,
    column_inverse: Arc<dyn Fft<f64>>,
}

/// What a [`Spectrum`] depends on: the grid's size, its spacing and the kernel's scales.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
struct SpectrumKey {
    nx: usize,
    ny: usize,
    spacing: u64,
    inv_l2: u64,
    rc2: u64,
}

/// The spectra of the last few grid sizes: a run's grids keep their size for many steps
/// (sizes are rounded up to [`padded_size`]), and a spectrum costs a transform.
static SPECTRA: Mutex<Vec<Arc<Spectrum>>> = Mutex::new(Vec::new());

/// Spectra kept in [`SPECTRA`].
const SPECTRA_KEPT: usize = 4;

impl GridAverager {
    /// Builds the operator from positions `x_q`, volumes `V_q` and a group id per MP (MPs
    /// of different groups never average together), with the grid spacing
    /// `grid_spacing_factor · l_s` of `params`.
    ///
    /// # Errors
    /// As [`super::NonlocalAverager::new`], and [`NonlocalError::GridTooLarge`] when a
    /// group's points spread over more than `2^26` grid nodes.
    pub fn new(
        params: &NonlocalSpec,
        positions: &[[f64; 2]],
        volumes: &[f64],
        groups: &[u16],
    ) -> Result<Self, NonlocalError> {
        params.validate()?;
        validate_inputs(positions, volumes, groups)?;
        let mut ids: Vec<u16> = groups.to_vec();
        ids.sort_unstable();
        ids.dedup();
        let grids = ids
            .into_iter()
            .map(|g| {
                let members: Vec<usize> =
                    (0..positions.len()).filter(|&i| groups[i] == g).collect();
                GroupGrid::new(params, members, positions, volumes)
            })
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Self {
            groups: grids,
            n: positions.len(),
        })
    }

    /// Number of MPs of the operator.
    pub fn len(&self) -> usize {
        self.n
    }

    /// True if the operator has no MPs.
    pub fn is_empty(&self) -> bool {
        self.n == 0
    }

    /// `out_p ≈ Σ_q W_pq field_q` (NG1–NG3 for \[D34\]), for a field given at every MP.
    /// An MP whose denominator vanishes (no neighbour within `R_c` on the grid) keeps its
    /// own value. `out` is overwritten.
    ///
    /// # Errors
    /// [`NonlocalError::FieldLengthMismatch`] if `field` or `out` does not have
    /// [`Self::len`] entries.
    pub fn average(&self, field: &[f64], out: &mut [f64]) -> Result<(), NonlocalError> {
        check_field_lengths(self.n, field, out.len())?;
        if field.iter().all(|&f| f == 0.0) {
            out.fill(0.0);
            return Ok(());
        }
        for grid in &self.groups {
            grid.average(field, out);
        }
        Ok(())
    }
}

impl GroupGrid {
    fn new(
        params: &NonlocalSpec,
        members: Vec<usize>,
        positions: &[[f64; 2]],
        volumes: &[f64],
    ) -> Result<Self, NonlocalError> {
        let spacing = params.grid_spacing();
        let rc = params.cutoff_radius();
        let mut lo = [f64::INFINITY; 2];
        let mut hi = [f64::NEG_INFINITY; 2];
        for &i in &members {
            for a in 0..2 {
                lo[a] = lo[a].min(positions[i][a]);
                hi[a] = hi[a].max(positions[i][a]);
            }
        }
        // nodes a point touches, per axis: floor((x − lo)/Δ) and the next one
        let used = |a: usize| floor_int((hi[a] - lo[a]) / spacing).max(0) as usize + 2;
        // offsets within R_c, per axis
        let reach = (rc / spacing).floor() as usize;
        // no wrap-around between used nodes within reach (NG2): n ≥ used + reach
        let (nx, ny) = (padded_size(used(0) + reach), padded_size(used(1) + reach));
        if nx.saturating_mul(ny) > MAX_NODES {
            return Err(NonlocalError::GridTooLarge {
                nodes: nx.saturating_mul(ny),
                spacing,
            });
        }
        let stencils: Vec<[(usize, f64); 4]> = members
            .iter()
            .map(|&i| {
                let (fx, fy) = (
                    (positions[i][0] - lo[0]) / spacing,
                    (positions[i][1] - lo[1]) / spacing,
                );
                let (ix, iy) = (
                    (floor_int(fx).max(0) as usize).min(nx - 2),
                    (floor_int(fy).max(0) as usize).min(ny - 2),
                );
                let (tx, ty) = (fx - ix as f64, fy - iy as f64);
                let node = |dx: usize, dy: usize| (iy + dy) * nx + ix + dx;
                [
                    (node(0, 0), (1.0 - tx) * (1.0 - ty)),
                    (node(1, 0), tx * (1.0 - ty)),
                    (node(0, 1), (1.0 - tx) * ty),
                    (node(1, 1), tx * ty),
                ]
            })
            .collect();
        let volumes = members.iter().map(|&i| volumes[i]).collect();
        let inv_l2 = 1.0 / (params.length_scale * params.length_scale);
        // the four nodes of a stencil lie 0, Δ or √2 Δ apart
        let apart = [
            0.0,
            kernel(spacing * spacing, inv_l2),
            kernel(2.0 * spacing * spacing, inv_l2),
        ];
        let self_weights = stencils
            .iter()
            .map(|stencil| {
                let mut sum = 0.0;
                for (a, &(_, wa)) in stencil.iter().enumerate() {
                    for (b, &(_, wb)) in stencil.iter().enumerate() {
                        // stencil k = 2 dy + dx: the offsets differ in (a ^ b).count_ones() axes
                        sum += wa * wb * apart[(a ^ b).count_ones() as usize];
                    }
                }
                sum
            })
            .collect();
        let key = SpectrumKey {
            nx,
            ny,
            spacing: spacing.to_bits(),
            inv_l2: inv_l2.to_bits(),
            rc2: (rc * rc).to_bits(),
        };
        Ok(Self {
            members,
            stencils,
            volumes,
            self_weights,
            rows_used: used(1).min(ny),
            spectrum: Spectrum::get(key),
        })
    }

    /// NG1–NG3 for this group's MPs: writes `out` at its members.
    fn average(&self, field: &[f64], out: &mut [f64]) {
        let spectrum = &self.spectrum;
        let (nx, ny) = (spectrum.nx, spectrum.ny);
        // NG1: volumes (real part) and sources (imaginary part) spread to the nodes
        let mut nodes = vec![Complex64::new(0.0, 0.0); nx * ny];
        for ((stencil, &volume), &i) in self.stencils.iter().zip(&self.volumes).zip(&self.members) {
            let source = volume * field[i];
            for &(node, weight) in stencil {
                nodes[node] += Complex64::new(weight * volume, weight * source);
            }
        }
        // NG2: both convolved with the kernel at once (its spectrum is real)
        let used = self.rows_used * nx;
        transform_lines(&mut nodes[..used], nx, &spectrum.row_forward);
        let mut columns = transposed(&nodes, nx, ny);
        transform_lines(&mut columns, ny, &spectrum.column_forward);
        columns
            .par_iter_mut()
            .with_min_len(4096)
            .zip(spectrum.values.par_iter().with_min_len(4096))
            .for_each(|(c, &k)| *c *= k);
        transform_lines(&mut columns, ny, &spectrum.column_inverse);
        let mut nodes = transposed(&columns, ny, nx);
        transform_lines(&mut nodes[..used], nx, &spectrum.row_inverse);
        // NG3: read back at the points, numerator over denominator
        let read_back = |k: usize| {
            let (mut den, mut num) = (0.0, 0.0);
            for &(node, weight) in &self.stencils[k] {
                den += weight * nodes[node].re;
                num += weight * nodes[node].im;
            }
            let own = self.self_weights[k] * self.volumes[k];
            (den - own, num - own * field[self.members[k]])
        };
        let sums: Vec<(f64, f64)> = (0..self.members.len())
            .into_par_iter()
            .with_min_len(1024)
            .map(read_back)
            .collect();
        // an MP with no neighbour keeps its own value: its denominator is the round-off
        // of the sums it is taken from
        let largest = sums.iter().map(|s| s.0).fold(0.0, f64::max);
        let values: Vec<f64> = sums
            .iter()
            .zip(&self.members)
            .map(|(&(den, num), &i)| {
                if den > ISOLATED * largest {
                    num / den
                } else {
                    field[i]
                }
            })
            .collect();
        for (&i, value) in self.members.iter().zip(values) {
            out[i] = value;
        }
    }
}

impl Spectrum {
    /// The spectrum of `key`, from [`SPECTRA`] or computed (and kept there).
    fn get(key: SpectrumKey) -> Arc<Spectrum> {
        if let Ok(kept) = SPECTRA.lock() {
            if let Some(s) = kept.iter().find(|s| s.key == key) {
                return Arc::clone(s);
            }
        }
        let spectrum = Arc::new(Self::compute(key));
        if let Ok(mut kept) = SPECTRA.lock() {
            if kept.len() >= SPECTRA_KEPT {
                kept.remove(0);
            }
            kept.push(Arc::clone(&spectrum));
        }
        spectrum
    }

    /// The kernel sampled at the node offsets `(a Δ, b Δ)`, wrapped periodically, zero
    /// beyond `R_c` (NG2), and transformed.
    fn compute(key: SpectrumKey) -> Self {
        let (nx, ny) = (key.nx, key.ny);
        let spacing = f64::from_bits(key.spacing);
        let (inv_l2, rc2) = (f64::from_bits(key.inv_l2), f64::from_bits(key.rc2));
        let mut planner = FftPlanner::<f64>::new();
        let (row_forward, row_inverse) =
            (planner.plan_fft_forward(nx), planner.plan_fft_inverse(nx));
        let (column_forward, column_inverse) =
            (planner.plan_fft_forward(ny), planner.plan_fft_inverse(ny));
        let offset = |k: usize, n: usize| k.min(n - k) as f64 * spacing;
        let scale = 1.0 / (nx * ny) as f64;
        let mut sampled: Vec<Complex64> = (0..nx * ny)
            .map(|k| {
                let (dx, dy) = (offset(k % nx, nx), offset(k / nx, ny));
                let r2 = dx * dx + dy * dy;
                let w = if r2 <= rc2 { kernel(r2, inv_l2) } else { 0.0 };
                Complex64::new(w * scale, 0.0)
            })
            .collect();
        transform_lines(&mut sampled, nx, &row_forward);
        let mut columns = transposed(&sampled, nx, ny);
        transform_lines(&mut columns, ny, &column_forward);
        Self {
            key,
            nx,
            ny,
            values: columns.iter().map(|c| c.re).collect(),
            row_forward,
            row_inverse,
            column_forward,
            column_inverse,
        }
    }
}

/// Transforms every line of `len` entries of `data` in place, lines split over rayon tasks.
fn transform_lines(data: &mut [Complex64], len: usize, fft: &Arc<dyn Fft<f64>>) {
    data.par_chunks_mut(len * LINES_PER_TASK).for_each(|lines| {
        let mut scratch = vec![Complex64::new(0.0, 0.0); fft.get_inplace_scratch_len()];
        fft.process_with_scratch(lines, &mut scratch);
    });
}

/// The `cols × rows` transpose of a row-major `rows × cols` array (`cols` entries a row).
fn transposed(data: &[Complex64], cols: usize, rows: usize) -> Vec<Complex64> {
    let mut out = vec![Complex64::new(0.0, 0.0); data.len()];
    out.par_chunks_mut(rows * LINES_PER_TASK)
        .enumerate()
        .for_each(|(task, lines)| {
            for (k, line) in lines.chunks_mut(rows).enumerate() {
                let c = task * LINES_PER_TASK + k;
                for (r, value) in line.iter_mut().enumerate() {
                    *value = data[r * cols + c];
                }
            }
        });
    out
}

/// The least size `≥ n` of the form `2^a 3^b` (fast transforms), at least 2.
fn padded_size(n: usize) -> usize {
    let target = n.max(2);
    let mut best = usize::MAX;
    let mut three = 1usize;
    while three < 2 * target {
        let mut size = three;
        while size < target {
            size *= 2;
        }
        best = best.min(size);
        three *= 3;
    }
    best
}

#[cfg(test)]
mod tests {
    use super::super::NonlocalAverager;
    use super::*;

    const L_S: f64 = 0.4;

    /// A 3 l_s × 2 l_s block of points at spacing l_s/8, moved off the lattice by up to
    /// 0.2 of a spacing, with volumes varying by ±30 %.
    fn block() -> (Vec<[f64; 2]>, Vec<f64>) {
        let d = L_S / 8.0;
        let mut x = Vec::new();
        let mut v = Vec::new();
        for j in 0..16 {
            for i in 0..24 {
                let k = (i * 16 + j) as f64;
                let jitter = |phase: f64| 0.2 * d * (1.7 * k + phase).sin();
                x.push([
                    (i as f64 + 0.5) * d + jitter(0.0),
                    (j as f64 + 0.5) * d + jitter(1.3),
                ]);
                v.push(d * d * (1.0 + 0.3 * (0.9 * k).cos()));
            }
        }
        (x, v)
    }

    /// A band of plastic strain across the block, as a softening zone leaves it.
    fn band(x: &[[f64; 2]]) -> Vec<f64> {
        x.iter()
            .map(|p| {
                let across = (p[1] - 0.5 * p[0] - 0.1) / (0.5 * L_S);
                0.05 * (-(across * across)).exp()
            })
            .collect()
    }

    fn spec(factor: f64) -> NonlocalSpec {
        NonlocalSpec {
            grid_spacing_factor: factor,
            ..NonlocalSpec::new(L_S)
        }
    }

    fn grid_average(factor: f64, x: &[[f64; 2]], v: &[f64], g: &[u16], f: &[f64]) -> Vec<f64> {
        let mut out = vec![0.0; x.len()];
        GridAverager::new(&spec(factor), x, v, g)
            .unwrap()
            .average(f, &mut out)
            .unwrap();
        out
    }

    #[test]
    fn padded_sizes_are_smooth_and_not_smaller() {
        for (n, expected) in [
            (1, 2),
            (2, 2),
            (5, 6),
            (7, 8),
            (10, 12),
            (13, 16),
            (100, 108),
        ] {
            assert_eq!(padded_size(n), expected, "n = {n}");
        }
    }

    /// NG3 divides two convolutions of the same spreading: a uniform field comes back
    /// to round-off, free surfaces included (as D34's normalisation gives).
    #[test]
    fn uniform_field_is_reproduced() {
        let (x, v) = block();
        let g = vec![0; x.len()];
        let out = grid_average(0.1, &x, &v, &g, &vec![0.37; x.len()]);
        for (p, o) in out.iter().enumerate() {
            assert!((o - 0.37).abs() < 1e-13, "point {p}: {o}");
        }
    }

    /// The grid average approaches the pair average (D34) at second order in the
    /// spacing: the spreading and reading back widen the kernel by O(Δ²).
    #[test]
    fn grid_average_converges_to_the_pair_average_at_second_order() {
        let (x, v) = block();
        let g = vec![0; x.len()];
        let f = band(&x);
        let mut exact = vec![0.0; x.len()];
        NonlocalAverager::average_brute_force(&NonlocalSpec::new(L_S), &x, &v, &g, &f, &mut exact)
            .unwrap();
        let error = |factor: f64| {
            let out = grid_average(factor, &x, &v, &g, &f);
            out.iter()
                .zip(&exact)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max)
                / 0.05
        };
        let errors = [error(0.2), error(0.1), error(0.05)];
        for k in 0..2 {
            let order = (errors[k] / errors[k + 1]).log2();
            assert!((1.7..2.3).contains(&order), "order {order} from {errors:?}");
        }
        assert!(errors[1] < 2e-3, "{errors:?}");
    }

    /// Points of different groups never average together, and a point with no
    /// neighbour within R_c keeps its own value.
    #[test]
    fn groups_stay_apart_and_an_isolated_point_keeps_its_value() {
        let (mut x, mut v) = block();
        let n = x.len();
        let mut g: Vec<u16> = (0..n).map(|p| (p % 2) as u16).collect();
        let mut f: Vec<f64> = g.iter().map(|&k| if k == 0 { 0.2 } else { 0.7 }).collect();
        x.push([10.0, 10.0]);
        v.push(1e-3);
        g.push(0);
        f.push(0.9);
        let out = grid_average(0.1, &x, &v, &g, &f);
        for p in 0..n {
            assert!(
                (out[p] - f[p]).abs() < 1e-13,
                "point {p}: {} against {}",
                out[p],
                f[p]
            );
        }
        assert!((out[n] - 0.9).abs() < 1e-15, "isolated point: {}", out[n]);
    }

    /// Every line of the transforms is one task's: one thread and two give the same bits.
    #[test]
    fn results_do_not_depend_on_the_number_of_threads() {
        let (x, v) = block();
        let g = vec![0; x.len()];
        let f = band(&x);
        let run = |threads: usize| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| grid_average(0.1, &x, &v, &g, &f))
        };
        assert_eq!(run(1), run(2));
    }
}
