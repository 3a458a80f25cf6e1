//! LU factorisation with partial pivoting of a small dense `N × N` matrix, for the Newton
//! systems of the return mappings (the 6 × 6 Jacobian of theory D30 and its sensitivity solve
//! of D32).
//!
//! Fixed-size arrays and plain loops, so the compiler unrolls them: the return mapping of the
//! softening model spends a quarter of its time in a generic library LU otherwise. The
//! operations are those of nalgebra 0.35's `LU` (pivot: the first row of largest `|a|`;
//! multipliers `a_rk · (1/a_kk)`; updates `a_rj − a_kj · l_rk`; forward and back substitution
//! by columns), in the same order, so every factor and solution keeps nalgebra's bits (tested
//! against it).

/// `P A = L U` of a square matrix: `L` unit lower triangular below the diagonal of `lu`, `U`
/// on and above it; `swaps[k]` is the row exchanged with row `k` at elimination step `k` (`k`
/// itself when none was, or when the column had no nonzero pivot).
#[derive(Clone, Copy, Debug)]
pub struct DenseLu<const N: usize> {
    lu: [[f64; N]; N],
    swaps: [usize; N],
}

impl<const N: usize> DenseLu<N> {
    /// Factorise `a` (row-major `a[row][col]`). A column without a nonzero pivot is left
    /// uneliminated; [`Self::is_invertible`] then reports `false` and the solves `None`.
    #[inline]
    pub fn new(mut a: [[f64; N]; N]) -> Self {
        let mut swaps: [usize; N] = std::array::from_fn(|k| k);
        for k in 0..N {
            let mut pivot = k;
            let mut largest = a[k][k].abs();
            for (r, row) in a.iter().enumerate().skip(k + 1) {
                if row[k].abs() > largest {
                    largest = row[k].abs();
                    pivot = r;
                }
            }
            let diagonal = a[pivot][k];
            if diagonal == 0.0 {
                continue;
            }
            swaps[k] = pivot;
            if pivot != k {
                a.swap(k, pivot);
            }
            let inverse = 1.0 / diagonal;
            let (upper, lower) = a.split_at_mut(k + 1);
            let pivot_row = &upper[k];
            for row in lower.iter_mut() {
                let multiplier = row[k] * inverse;
                row[k] = multiplier;
                for j in k + 1..N {
                    row[j] -= pivot_row[j] * multiplier;
                }
            }
        }
        Self { lu: a, swaps }
    }

    /// True when every pivot of `U` is nonzero.
    #[inline]
    pub fn is_invertible(&self) -> bool {
        (0..N).all(|k| self.lu[k][k] != 0.0)
    }

    /// Solve `A x = b`; `None` when `A` is singular (a zero pivot).
    #[inline]
    pub fn solve(&self, mut b: [f64; N]) -> Option<[f64; N]> {
        for (k, &pivot) in self.swaps.iter().enumerate() {
            b.swap(k, pivot);
        }
        for k in 0..N {
            let coefficient = b[k];
            for r in k + 1..N {
                b[r] -= coefficient * self.lu[r][k];
            }
        }
        for k in (0..N).rev() {
            let diagonal = self.lu[k][k];
            if diagonal == 0.0 {
                return None;
            }
            let coefficient = b[k] / diagonal;
            b[k] = coefficient;
            for r in 0..k {
                b[r] -= coefficient * self.lu[r][k];
            }
        }
        Some(b)
    }

    /// Solve `A X = B` for `M` right-hand sides, the columns of `b` (row-major `b[row][col]`),
    /// each column with the operations of [`Self::solve`] (the same bits), the columns side by
    /// side so that their divisions overlap; `None` when `A` is singular.
    #[inline]
    pub fn solve_columns<const M: usize>(&self, b: &[[f64; M]; N]) -> Option<[[f64; M]; N]> {
        if !self.is_invertible() {
            return None;
        }
        let mut x = *b;
        for (k, &pivot) in self.swaps.iter().enumerate() {
            x.swap(k, pivot);
        }
        for k in 0..N {
            let (upper, lower) = x.split_at_mut(k + 1);
            let coefficients = &upper[k];
            for (r, row) in lower.iter_mut().enumerate() {
                let factor = self.lu[k + 1 + r][k];
                for (value, &coefficient) in row.iter_mut().zip(coefficients) {
                    *value -= coefficient * factor;
                }
            }
        }
        for k in (0..N).rev() {
            let diagonal = self.lu[k][k];
            let (upper, lower) = x.split_at_mut(k);
            let coefficients = &mut lower[0];
            for value in coefficients.iter_mut() {
                *value /= diagonal;
            }
            for (r, row) in upper.iter_mut().enumerate() {
                let factor = self.lu[r][k];
                for (value, &coefficient) in row.iter_mut().zip(coefficients.iter()) {
                    *value -= coefficient * factor;
                }
            }
        }
        Some(x)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::SMatrix;

    /// A deterministic pseudo-random value in [−1, 1) (64-bit LCG).
    fn draw(seed: &mut u64) -> f64 {
        *seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((*seed >> 11) as f64) / ((1u64 << 53) as f64) * 2.0 - 1.0
    }

    fn bits<const R: usize, const C: usize>(m: &[[f64; C]; R]) -> Vec<u64> {
        m.iter().flatten().map(|x| x.to_bits()).collect()
    }

    /// Factors, solutions and the singular verdict equal nalgebra's bit for bit: random
    /// matrices of mixed scales, rows that tie for the pivot, an exactly zero column and a
    /// matrix whose elimination meets a zero pivot.
    #[test]
    fn same_bits_as_nalgebra() {
        let mut seed = 7;
        let mut cases: Vec<[[f64; 6]; 6]> = Vec::new();
        for case in 0..400 {
            let mut a: [[f64; 6]; 6] = std::array::from_fn(|_| {
                std::array::from_fn(|_| draw(&mut seed) * 10f64.powi(case % 7 - 3))
            });
            match case % 5 {
                1 => a[3] = a[1].map(|x| -x),            // tie of |a| in every column
                2 => (0..6).for_each(|r| a[r][2] = 0.0), // a zero column
                3 => a[4] = a[0],                        // singular: a zero pivot appears late
                _ => {}
            }
            cases.push(a);
        }
        for a in cases {
            let b: [f64; 6] = std::array::from_fn(|_| draw(&mut seed));
            let rhs: [[f64; 4]; 6] =
                std::array::from_fn(|_| std::array::from_fn(|_| draw(&mut seed)));
            let ours = DenseLu::new(a);
            let theirs = SMatrix::<f64, 6, 6>::from_fn(|r, c| a[r][c]).lu();
            let their_lu: [[f64; 6]; 6] =
                std::array::from_fn(|r| std::array::from_fn(|c| theirs.lu_internal()[(r, c)]));
            assert_eq!(bits(&ours.lu), bits(&their_lu));
            assert_eq!(ours.is_invertible(), theirs.is_invertible());
            let x = ours.solve(b);
            let y = theirs.solve(&SMatrix::<f64, 6, 1>::from_fn(|r, _| b[r]));
            assert_eq!(x.is_some(), y.is_some());
            if let (Some(x), Some(y)) = (x, y) {
                let y: [[f64; 1]; 6] = std::array::from_fn(|r| [y[r]]);
                assert_eq!(bits(&x.map(|v| [v])), bits(&y));
            }
            let xs = ours.solve_columns(&rhs);
            let ys = theirs.solve(&SMatrix::<f64, 6, 4>::from_fn(|r, c| rhs[r][c]));
            assert_eq!(xs.is_some(), ys.is_some());
            if let (Some(xs), Some(ys)) = (xs, ys) {
                let ys: [[f64; 4]; 6] =
                    std::array::from_fn(|r| std::array::from_fn(|c| ys[(r, c)]));
                assert_eq!(bits(&xs), bits(&ys));
            }
        }
    }

    /// The solution satisfies `A x = b` to round-off on a well-conditioned system.
    #[test]
    fn solves_a_diagonally_dominant_system() {
        let mut seed = 11;
        let mut a: [[f64; 6]; 6] =
            std::array::from_fn(|_| std::array::from_fn(|_| draw(&mut seed)));
        (0..6).for_each(|k| a[k][k] += 8.0);
        let b: [f64; 6] = std::array::from_fn(|_| draw(&mut seed));
        let x = DenseLu::new(a).solve(b).expect("invertible");
        for r in 0..6 {
            let ax: f64 = (0..6).map(|c| a[r][c] * x[c]).sum();
            assert!(
                (ax - b[r]).abs() < 40.0 * f64::EPSILON,
                "row {r}: {ax} vs {}",
                b[r]
            );
        }
    }
}
