//! Sparse symmetric positive-definite solves with faer, split as faer splits them: the
//! symbolic factorisation of a sparsity pattern is computed once ([`SpdPattern::new`]) and
//! reused for every numeric factorisation with new values ([`SpdPattern::factor`]).
//!
//! ```
//! use sfs::sparse_llt::SpdPattern;
//! // [[4, 1], [1, 3]] x = [1, 2]: lower-triangle entries, in any order, duplicates summed.
//! let pat = SpdPattern::new(2, &[(0, 0), (1, 0), (1, 1)]).unwrap();
//! let f = pat.factor(&[4.0, 1.0, 3.0]).unwrap();
//! let mut b = vec![[1.0], [2.0]];
//! f.solve(&mut b);
//! assert!((b[0][0] - 1.0 / 11.0).abs() < 1e-12 && (b[1][0] - 7.0 / 11.0).abs() < 1e-12);
//! ```

use faer::linalg::solvers::Solve;
use faer::sparse::linalg::solvers::{Llt, SymbolicLlt};
use faer::sparse::{Argsort, Pair, SparseColMat, SymbolicSparseColMat};
use faer::{Mat, Side};

/// Why a system cannot be solved.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SolveError {
    #[error("entry ({row}, {col}) is outside the {n}×{n} matrix or above the diagonal")]
    BadEntry { row: usize, col: usize, n: usize },
    #[error("the matrix is not positive definite (pivot {index})")]
    NonPositivePivot { index: usize },
    #[error("{0}")]
    Faer(String),
}

/// A sparsity pattern (lower triangle) with its symbolic Cholesky factorisation.
pub struct SpdPattern {
    n: usize,
    entries: usize,
    symbolic: SymbolicSparseColMat<usize>,
    argsort: Argsort<usize>,
    llt: SymbolicLlt<usize>,
}

impl std::fmt::Debug for SpdPattern {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "SpdPattern {{ n: {}, entries: {} }}",
            self.n, self.entries
        )
    }
}

/// A numeric factorisation, ready to solve.
pub struct SpdFactor {
    n: usize,
    llt: Llt<usize, f64>,
}

impl SpdPattern {
    /// `entries` are `(row, col)` with `row ≥ col` (the lower triangle of an n×n matrix);
    /// repeated entries are summed when the values are given.
    pub fn new(n: usize, entries: &[(usize, usize)]) -> Result<Self, SolveError> {
        if let Some(&(row, col)) = entries.iter().find(|&&(r, c)| r >= n || c > r) {
            return Err(SolveError::BadEntry { row, col, n });
        }
        let pairs: Vec<Pair<usize, usize>> =
            entries.iter().map(|&(r, c)| Pair::new(r, c)).collect();
        let (symbolic, argsort) = SymbolicSparseColMat::try_new_from_indices(n, n, &pairs)
            .map_err(|e| SolveError::Faer(format!("{e:?}")))?;
        let llt = SymbolicLlt::try_new(symbolic.as_ref(), Side::Lower)
            .map_err(|e| SolveError::Faer(format!("{e:?}")))?;
        Ok(SpdPattern {
            n,
            entries: entries.len(),
            symbolic,
            argsort,
            llt,
        })
    }

    /// Dimension.
    pub fn n(&self) -> usize {
        self.n
    }

    /// Numeric factorisation with `values[k]` for `entries[k]` (reusing the symbolic one).
    pub fn factor(&self, values: &[f64]) -> Result<SpdFactor, SolveError> {
        assert_eq!(values.len(), self.entries, "one value per pattern entry");
        let a = SparseColMat::new_from_argsort(self.symbolic.clone(), &self.argsort, values)
            .map_err(|e| SolveError::Faer(format!("{e:?}")))?;
        let llt =
            Llt::try_new_with_symbolic(self.llt.clone(), a.as_ref(), Side::Lower).map_err(|e| {
                match e {
                    faer::sparse::linalg::LltError::Numeric(
                        faer::linalg::cholesky::llt::factor::LltError::NonPositivePivot { index },
                    ) => SolveError::NonPositivePivot { index },
                    other => SolveError::Faer(format!("{other:?}")),
                }
            })?;
        Ok(SpdFactor { n: self.n, llt })
    }
}

impl SpdFactor {
    /// Solves in place for `K` right-hand sides given row by row (`b[i][k]`).
    pub fn solve<const K: usize>(&self, b: &mut [[f64; K]]) {
        assert_eq!(b.len(), self.n);
        let mut m = Mat::<f64>::from_fn(self.n, K, |i, k| b[i][k]);
        self.llt.solve_in_place(m.as_mut());
        for (i, row) in b.iter_mut().enumerate() {
            for (k, x) in row.iter_mut().enumerate() {
                *x = m[(i, k)];
            }
        }
    }
}

/// Uses one thread for sparse solves: on 2 cores faer's default pool made them ~20× slower
/// (see the crate notes). Called once at start-up by the binary and by the benches.
pub fn single_threaded() {
    faer::set_global_parallelism(faer::Par::Seq);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn path_laplacian_with_a_gauge_solves_and_reuses_the_pattern() {
        // 1D Poisson: x0 fixed (penalty), (x_{i+1} − x_i) = 1.
        let n = 50;
        let mut entries = Vec::new();
        for i in 0..n {
            entries.push((i, i));
            if i > 0 {
                entries.push((i, i - 1));
            }
        }
        let pat = SpdPattern::new(n, &entries).unwrap();
        for scale in [1.0, 3.0] {
            let mut vals = Vec::new();
            for i in 0..n {
                let deg = if i == 0 || i == n - 1 { 1.0 } else { 2.0 };
                vals.push(scale * (deg + if i == 0 { 1.0 } else { 0.0 }));
                if i > 0 {
                    vals.push(-scale);
                }
            }
            let f = pat.factor(&vals).unwrap();
            // rhs = Dᵀ 1: node i gets (+1 from edge i−1) − (1 from edge i).
            let mut b: Vec<[f64; 1]> = (0..n)
                .map(|i| [scale * ((i > 0) as i32 as f64 - (i + 1 < n) as i32 as f64)])
                .collect();
            f.solve(&mut b);
            for (i, x) in b.iter().enumerate() {
                assert!((x[0] - i as f64).abs() < 1e-9, "x{i} = {}", x[0]);
            }
        }
        assert!(matches!(
            pat.factor(&vec![-1.0; entries.len()]),
            Err(SolveError::NonPositivePivot { .. })
        ));
        assert!(matches!(
            SpdPattern::new(2, &[(0, 1)]),
            Err(SolveError::BadEntry { .. })
        ));
    }
}
