//! Least-squares data gathered chunk by chunk: the rows of a design [A | Y] (library columns, then
//! target columns) are pushed one sample at a time and never held together. What the fits need of
//! them is kept instead: the Gram matrix [A Y]ᵀ[A Y] (STLSQ's and SR3's normal equations) and the
//! triangular factor R of [A Y] = Q R (every least-squares solve, and the residual sums of squares,
//! without squaring the condition number).
//!
//! R is updated by a QR factorisation of R stacked on each chunk of rows ("TSQR"): [R; B] = Q' R'
//! gives [A; B] = diag(Q, I) Q' R', so R' is the factor of all rows so far. Mathematically R (up
//! to the signs of its rows) and the Gram matrix do not depend on the chunk size; in floating point
//! they differ from a one-shot factorisation by round-off only (the tests of this module: chunks of
//! 1, 7 and more rows than the data).
//!
//! With R = [[R_A, C], [0, R_Y]] (C = Q_Aᵀ Y):
//! - the least squares of target t on the columns S of A is the small problem ‖R_A[:, S] w − C_t‖
//!   (the rest of ‖A_S w − y_t‖² does not depend on w);
//! - the residual sum of squares of any coefficients ξ is ‖R_A ξ − C_t‖² + Σ_{i ≤ t} R_Y[i, t]².
//!
//! Memory: O(m²) for m columns plus one chunk of rows, whatever the number of samples.

use nalgebra::DMatrix;

/// Rows per chunk of the fits' accumulators: a chunk of 2048 rows of the physics library's 74
/// columns is 1.2 MB, and the stacked factorisation's extra work over a one-shot QR is m / 2048
/// (4 %). A count of samples, not of seconds: it changes nothing but round-off.
pub const CHUNK_ROWS: usize = 2048;

/// The Gram matrix and R factor of the rows pushed so far (see the module documentation).
#[derive(Clone, Debug)]
pub struct Accumulator {
    m: usize,
    chunk: usize,
    rows: usize,
    gram: DMatrix<f64>,
    r: DMatrix<f64>,
    block: DMatrix<f64>,
    filled: usize,
    nonzero: Vec<bool>,
    finite: bool,
}

/// What an [`Accumulator`] gathered: the Gram matrix and the R factor (m × m, upper triangular)
/// of the n rows of [A | Y], and which columns had a non-zero entry.
#[derive(Clone, Debug)]
pub struct LsData {
    pub n: usize,
    pub gram: DMatrix<f64>,
    pub r: DMatrix<f64>,
    pub nonzero: Vec<bool>,
    /// Every entry pushed was finite.
    pub finite: bool,
}

impl Accumulator {
    /// Rows of `m` columns, factorised every `chunk` rows (at least 1).
    pub fn new(m: usize, chunk: usize) -> Self {
        let chunk = chunk.max(1);
        Self {
            m,
            chunk,
            rows: 0,
            gram: DMatrix::zeros(m, m),
            r: DMatrix::zeros(m, m),
            block: DMatrix::zeros(0, m),
            filled: 0,
            nonzero: vec![false; m],
            finite: true,
        }
    }

    /// Append one row (`m` values).
    pub fn push(&mut self, row: &[f64]) {
        debug_assert_eq!(row.len(), self.m);
        if self.block.nrows() == 0 {
            self.block = DMatrix::zeros(self.chunk, self.m);
        }
        for (j, &v) in row.iter().enumerate() {
            self.block[(self.filled, j)] = v;
            self.nonzero[j] |= v != 0.0;
            self.finite &= v.is_finite();
        }
        self.filled += 1;
        self.rows += 1;
        if self.filled == self.chunk {
            self.flush();
        }
    }

    fn flush(&mut self) {
        if self.filled == 0 {
            return;
        }
        let (m, c) = (self.m, self.filled);
        self.filled = 0;
        if !self.finite {
            // The caller refuses non-finite data; a factorisation of it would be meaningless.
            return;
        }
        let b = self.block.rows(0, c);
        self.gram.gemm_tr(1.0, &b, &b, 1.0);
        let mut stacked = DMatrix::zeros(m + c, m);
        stacked.rows_mut(0, m).copy_from(&self.r);
        stacked.rows_mut(m, c).copy_from(&b);
        self.r = stacked.qr().r();
    }

    /// Everything pushed, gathered.
    pub fn finish(mut self) -> LsData {
        self.flush();
        LsData {
            n: self.rows,
            gram: self.gram,
            r: self.r,
            nonzero: self.nonzero,
            finite: self.finite,
        }
    }
}

impl LsData {
    /// The same data restricted to the columns `cols` (in that order): the Gram sub-matrix and the
    /// R factor of those columns (a QR of R's columns `cols`: [A Y][:, cols] = Q R[:, cols]).
    pub fn select(&self, cols: &[usize]) -> LsData {
        let m = self.gram.nrows();
        if cols.len() == m && cols.iter().enumerate().all(|(i, &c)| i == c) {
            return self.clone();
        }
        let k = cols.len();
        let gram = DMatrix::from_fn(k, k, |i, j| self.gram[(cols[i], cols[j])]);
        let r = if k == 0 {
            DMatrix::zeros(0, 0)
        } else {
            let sub = self.r.select_columns(cols);
            let mut r = DMatrix::zeros(k, k);
            let f = sub.qr().r();
            r.view_mut((0, 0), (f.nrows(), k)).copy_from(&f);
            r
        };
        LsData {
            n: self.n,
            gram,
            r,
            nonzero: cols.iter().map(|&c| self.nonzero[c]).collect(),
            finite: self.finite,
        }
    }

    /// The data of the rows of `self` and then of `other` (the same columns).
    pub fn stack(&self, other: &LsData) -> LsData {
        let m = self.gram.nrows();
        let mut stacked = DMatrix::zeros(2 * m, m);
        stacked.rows_mut(0, m).copy_from(&self.r);
        stacked.rows_mut(m, m).copy_from(&other.r);
        LsData {
            n: self.n + other.n,
            gram: &self.gram + &other.gram,
            r: if m == 0 { DMatrix::zeros(0, 0) } else { stacked.qr().r() },
            nonzero: self.nonzero.iter().zip(&other.nonzero).map(|(a, b)| *a || *b).collect(),
            finite: self.finite && other.finite,
        }
    }

    /// The residual sum of squares ‖A ξ − y_t‖² of target `t` (column p + t, p = the columns of
    /// A = `xi.len()`), from R (see the module documentation).
    pub fn rss(&self, t: usize, xi: &[f64]) -> f64 {
        let p = xi.len();
        let col = p + t;
        let mut s = 0.0;
        for i in 0..p {
            let mut v = -self.r[(i, col)];
            for (j, x) in xi.iter().enumerate().skip(i) {
                v += self.r[(i, j)] * x;
            }
            s += v * v;
        }
        for i in p..=col.min(self.r.nrows() - 1) {
            s += self.r[(i, col)] * self.r[(i, col)];
        }
        s
    }
}

/// [`Accumulator`] over the rows of `m` (one push per row), chunks of `chunk` rows.
pub fn of_matrix(m: &DMatrix<f64>, chunk: usize) -> LsData {
    let mut acc = Accumulator::new(m.ncols(), chunk);
    let mut row = vec![0.0; m.ncols()];
    for i in 0..m.nrows() {
        for (j, v) in row.iter_mut().enumerate() {
            *v = m[(i, j)];
        }
        acc.push(&row);
    }
    acc.finish()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn design(n: usize) -> DMatrix<f64> {
        DMatrix::from_fn(n, 6, |k, j| {
            let t = k as f64 * 0.07;
            match j {
                0 => 1.0,
                1 => t.sin(),
                2 => (1.3 * t).cos() * 1e3,
                3 => t.sin() * (0.4 * t).cos() * 1e-3,
                4 => (0.9 * t).sin() + 0.5 * t.cos() + 0.01 * ((k * 7919) % 13) as f64,
                _ => 2.0 * t.sin() - 0.3 * (1.3 * t).cos() + 0.001 * ((k * 31) % 7) as f64,
            }
        })
    }

    /// The chunked Gram matrix and R are the one-shot ones (XᵀX, the R of one Householder QR up
    /// to the signs of its rows) to round-off, for chunks of 1, 7 and more rows than the data;
    /// residual sums of squares from R are the direct sums.
    #[test]
    fn chunked_gram_and_r_are_the_one_shot_ones() {
        let n = 40;
        let x = design(n);
        let gram = x.transpose() * &x;
        let r = x.clone().qr().r();
        for chunk in [1, 7, n + 1] {
            let d = of_matrix(&x, chunk);
            assert_eq!(d.n, n);
            for (a, b) in d.gram.iter().zip(gram.iter()) {
                assert!((a - b).abs() <= 1e-12 * b.abs().max(1.0), "{chunk}: {a} {b}");
            }
            for i in 0..6 {
                let s = if (d.r[(i, i)] > 0.0) == (r[(i, i)] > 0.0) {
                    1.0
                } else {
                    -1.0
                };
                for j in 0..6 {
                    let (a, b) = (s * d.r[(i, j)], r[(i, j)]);
                    assert!(
                        (a - b).abs() <= 1e-10 * r[(j, j)].abs().max(1.0),
                        "{chunk} ({i},{j}): {a} {b}"
                    );
                }
            }
            // Targets: columns 4 and 5 on the library 0..4.
            let xi = [0.3, -1.0, 2e-3, 5.0];
            for t in 0..2 {
                let direct: f64 = (0..n)
                    .map(|k| {
                        let fit: f64 = (0..4).map(|j| x[(k, j)] * xi[j]).sum();
                        (x[(k, 4 + t)] - fit).powi(2)
                    })
                    .sum();
                let got = d.rss(t, &xi);
                assert!((got - direct).abs() <= 1e-9 * direct, "{chunk} {t}: {got} {direct}");
            }
            assert!(d.nonzero.iter().all(|&z| z) && d.finite);
        }
    }

    /// A column subset's R (a QR of R's columns) gives that subset's least squares.
    #[test]
    fn a_selection_is_the_subsets_factor() {
        let n = 30;
        let x = design(n);
        let d = of_matrix(&x, 7);
        let cols = [1, 3, 5];
        let s = d.select(&cols);
        let direct = x.select_columns(&cols);
        let g = direct.transpose() * &direct;
        for (a, b) in s.gram.iter().zip(g.iter()) {
            assert!((a - b).abs() <= 1e-12 * b.abs().max(1.0));
        }
        let rtr = s.r.transpose() * &s.r;
        for (a, b) in rtr.iter().zip(g.iter()) {
            assert!((a - b).abs() <= 1e-9 * b.abs().max(1.0), "{a} {b}");
        }
        // Fewer rows than columns: R keeps the zero rows, RᵀR is still the Gram matrix.
        let few = of_matrix(&x.rows(0, 3).into_owned(), 2);
        let g = x.rows(0, 3).transpose() * x.rows(0, 3);
        let rtr = few.r.transpose() * &few.r;
        for (a, b) in rtr.iter().zip(g.iter()) {
            assert!((a - b).abs() <= 1e-9 * b.abs().max(1.0), "{a} {b}");
        }
    }
}
