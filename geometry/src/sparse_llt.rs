//! Sparse symmetric positive-definite solves with faer, split as faer splits them: the
//! symbolic factorisation of a sparsity pattern is computed once ([`SpdPattern::new`]) and
//! reused for every numeric factorisation with new values ([`SpdPattern::factor`]).
//! [`CachedPattern`] keeps the last pattern and its symbolic factorisation across solves
//! whose pattern does not change (the same network, the same mesh, a new pass of weights).
//!
//! ```
//! use sfs_geometry::sparse_llt::SpdPattern;
//! // [[4, 1], [1, 3]] x = [1, 2]: lower-triangle entries, in any order, duplicates summed.
//! let pat = SpdPattern::new(2, &[(0, 0), (1, 0), (1, 1)]).unwrap();
//! let f = pat.factor(&[4.0, 1.0, 3.0]).unwrap();
//! let mut b = vec![[1.0], [2.0]];
//! f.solve(&mut b);
//! assert!((b[0][0] - 1.0 / 11.0).abs() < 1e-12 && (b[1][0] - 7.0 / 11.0).abs() < 1e-12);
//! ```

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::sparse::linalg::cholesky::{
    factorize_symbolic_cholesky, CholeskySymbolicParams, LltRef, SymbolicCholesky,
    SymbolicCholeskyRaw, SymmetricOrdering,
};
use faer::sparse::{Argsort, Pair, SparseColMat, SymbolicSparseColMat};
use faer::{Conj, MatMut, Side};
use std::sync::Arc;

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
    chol: Arc<SymbolicCholesky<usize>>,
    /// The largest factor's values given back (one buffer, shared with the [`CachedPattern`]
    /// that made the pattern): the next numeric factorisation writes into it instead of
    /// asking the system for fresh pages.
    spare: Spare,
}

/// A buffer of a factor's values, given back when the factor is dropped (a factor of a
/// network of 100 curves holds 60 MB; mapping fresh pages for each factorisation took a
/// tenth of its time).
#[derive(Clone, Default)]
struct Spare(Arc<std::sync::Mutex<Option<Vec<f64>>>>);

impl Spare {
    fn lock(&self) -> std::sync::LockResult<std::sync::MutexGuard<'_, Option<Vec<f64>>>> {
        self.0.lock()
    }
}

impl std::fmt::Debug for Spare {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let held = self.lock().ok().and_then(|s| s.as_ref().map(Vec::capacity));
        write!(f, "Spare {{ values: {held:?} }}")
    }
}

impl std::fmt::Debug for SpdPattern {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "SpdPattern {{ n: {}, entries: {}, fill: {} }}",
            self.n,
            self.entries,
            self.fill()
        )
    }
}

/// A column of `L⁻¹ P` ([`SpdFactor::inverse_column`]): its nonzero entries, `(row, value)`
/// in increasing row order.
#[derive(Debug, Clone, Default)]
pub struct InverseColumn(Vec<(usize, f64)>);

/// A numeric factorisation, ready to solve.
pub struct SpdFactor {
    n: usize,
    chol: Arc<SymbolicCholesky<usize>>,
    values: Vec<f64>,
    spare: Spare,
}

impl Drop for SpdFactor {
    fn drop(&mut self) {
        if let Ok(mut spare) = self.spare.lock() {
            // The largest kept: a network's whole regression after its local ones.
            if spare
                .as_ref()
                .is_none_or(|s| s.capacity() < self.values.capacity())
            {
                *spare = Some(std::mem::take(&mut self.values));
            }
        }
    }
}

impl SpdPattern {
    /// `entries` are `(row, col)` with `row ≥ col` (the lower triangle of an n×n matrix);
    /// repeated entries are summed when the values are given. Ordered by approximate minimum
    /// degree (a level-structure nested dissection measured 30 % more fill on the surfacer's
    /// systems).
    pub fn new(n: usize, entries: &[(usize, usize)]) -> Result<Self, SolveError> {
        Self::ordered(n, entries, None)
    }

    /// As [`new`](Self::new), eliminated in `order` (`order[k]`: the row eliminated `k`-th,
    /// e.g. from [`block_order`]); an order that is no permutation of `0..n` is not trusted
    /// (approximate minimum degree instead).
    pub fn with_order(
        n: usize,
        entries: &[(usize, usize)],
        order: &[usize],
    ) -> Result<Self, SolveError> {
        Self::ordered(n, entries, Some(order))
    }

    /// In `order` when it is a permutation of `0..n`, else by approximate minimum degree.
    fn ordered(
        n: usize,
        entries: &[(usize, usize)],
        order: Option<&[usize]>,
    ) -> Result<Self, SolveError> {
        if let Some(&(row, col)) = entries.iter().find(|&&(r, c)| r >= n || c > r) {
            return Err(SolveError::BadEntry { row, col, n });
        }
        let pairs: Vec<Pair<usize, usize>> =
            entries.iter().map(|&(r, c)| Pair::new(r, c)).collect();
        let (symbolic, argsort) = SymbolicSparseColMat::try_new_from_indices(n, n, &pairs)
            .map_err(|e| SolveError::Faer(format!("{e:?}")))?;
        let symbolic_with =
            |ordering: SymmetricOrdering<'_, usize>| symbolic_cholesky(&symbolic, ordering);
        let chol = match order.and_then(|o| Some((o, inverse_of(o, n)?))) {
            Some((order, inverse)) => symbolic_with(SymmetricOrdering::Custom(
                faer::perm::PermRef::new_checked(order, &inverse, n),
            ))?,
            None => symbolic_with(SymmetricOrdering::Amd)?,
        };
        Ok(SpdPattern {
            n,
            entries: entries.len(),
            symbolic,
            argsort,
            chol: Arc::new(chol),
            spare: Spare::default(),
        })
    }

    /// Dimension.
    pub fn n(&self) -> usize {
        self.n
    }

    /// Stored values of the Cholesky factor (its fill, for the logs and benchmarks).
    pub fn fill(&self) -> usize {
        self.chol.len_val()
    }

    /// Numeric factorisation with `values[k]` for `entries[k]` (reusing the symbolic one).
    pub fn factor(&self, values: &[f64]) -> Result<SpdFactor, SolveError> {
        assert_eq!(values.len(), self.entries, "one value per pattern entry");
        let a = SparseColMat::new_from_argsort(self.symbolic.clone(), &self.argsort, values)
            .map_err(|e| SolveError::Faer(format!("{e:?}")))?;
        let par = faer::get_global_parallelism();
        let len = self.chol.len_val();
        // faer sets every value (a reused buffer needs no clearing).
        let mut l = match self.spare.lock() {
            Ok(mut spare) => match spare.take() {
                Some(mut v) if v.capacity() >= len => {
                    v.resize(len, 0.0);
                    v
                }
                other => {
                    *spare = other;
                    // A quarter more: the next network, a curve larger, fits in it.
                    let mut v = Vec::with_capacity(len + len / 4);
                    v.resize(len, 0.0);
                    v
                }
            },
            Err(_) => vec![0.0; len],
        };
        let mut mem = MemBuffer::try_new(
            self.chol
                .factorize_numeric_llt_scratch::<f64>(par, Default::default()),
        )
        .map_err(|e| SolveError::Faer(format!("{e:?}")))?;
        let done = self
            .chol
            .factorize_numeric_llt::<f64>(
                &mut l,
                a.as_ref(),
                Side::Lower,
                Default::default(),
                par,
                MemStack::new(&mut mem),
                Default::default(),
            )
            .map(|_| ())
            .map_err(|e| {
                let faer::linalg::cholesky::llt::factor::LltError::NonPositivePivot { index } = e;
                SolveError::NonPositivePivot { index }
            });
        let factor = SpdFactor {
            n: self.n,
            chol: self.chol.clone(),
            values: l,
            spare: self.spare.clone(),
        };
        done.map(|()| factor)
    }
}

/// The last sparsity pattern solved and its symbolic factorisation: a new pattern is
/// factorised symbolically, the same one again is reused (only the numeric factorisation is
/// redone).
///
/// ```
/// use sfs_geometry::sparse_llt::CachedPattern;
/// let mut cache = CachedPattern::default();
/// let entries = vec![(0, 0), (1, 0), (1, 1)];
/// for scale in [1.0, 2.0] {
///     let f = cache.factor(2, entries.clone(), &[4.0 * scale, scale, 3.0 * scale]).unwrap();
///     let mut b = vec![[1.0], [2.0]];
///     f.solve(&mut b);
/// }
/// assert_eq!(cache.symbolic_count(), 1);
/// ```
#[derive(Debug, Default)]
pub struct CachedPattern {
    cached: Option<SpdPattern>,
    /// The entries of the cached pattern.
    entries: Vec<(usize, usize)>,
    symbolic_count: usize,
    /// The last numeric factorisation and its values, when asked to keep it
    /// ([`factor_kept`](Self::factor_kept)).
    last: Option<(Vec<f64>, Arc<SpdFactor>)>,
    numeric_count: usize,
    /// The largest factor's values, kept across patterns (see [`SpdPattern`]).
    spare: Spare,
}

impl std::fmt::Debug for SpdFactor {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "SpdFactor {{ n: {}, fill: {} }}",
            self.n,
            self.values.len()
        )
    }
}

impl CachedPattern {
    /// The pattern of an `n`×`n` matrix's lower-triangle `entries` (see [`SpdPattern::new`]):
    /// the cached one when `n` and the entries are the same, else a new one, which is kept;
    /// and whether it is new.
    pub fn pattern(
        &mut self,
        n: usize,
        entries: Vec<(usize, usize)>,
    ) -> Result<(&SpdPattern, bool), SolveError> {
        self.pattern_ordered(n, entries, || None)
    }

    /// As [`pattern`](Self::pattern), with the elimination order of a new pattern (see
    /// [`SpdPattern::with_order`]; `None`: approximate minimum degree), made only when the
    /// pattern is new.
    pub fn pattern_ordered(
        &mut self,
        n: usize,
        entries: Vec<(usize, usize)>,
        order: impl FnOnce() -> Option<Vec<usize>>,
    ) -> Result<(&SpdPattern, bool), SolveError> {
        let same = matches!(&self.cached, Some(p) if p.n == n && self.entries == entries);
        if !same {
            self.cached = None;
            self.last = None;
            let order = order();
            let mut pattern = SpdPattern::ordered(n, &entries, order.as_deref())?;
            pattern.spare = self.spare.clone();
            self.symbolic_count += 1;
            self.entries = entries;
            self.cached = Some(pattern);
        }
        Ok((self.cached.as_ref().expect("set above"), !same))
    }

    /// The numeric factorisation of `values` on the pattern of `entries` (reusing the
    /// symbolic factorisation when the pattern is the cached one).
    pub fn factor(
        &mut self,
        n: usize,
        entries: Vec<(usize, usize)>,
        values: &[f64],
    ) -> Result<SpdFactor, SolveError> {
        self.numeric_count += 1;
        self.pattern(n, entries)?.0.factor(values)
    }

    /// As [`factor`](Self::factor), but the numeric factorisation is kept, and when the
    /// pattern and the values are those of the kept one it is returned as it is (the same
    /// system again: only back-substitutions to do). `keep = false` drops the kept one.
    ///
    /// ```
    /// use sfs_geometry::sparse_llt::CachedPattern;
    /// let mut cache = CachedPattern::default();
    /// let entries = vec![(0, 0), (1, 0), (1, 1)];
    /// let a = cache.factor_kept(2, entries.clone(), &[4.0, 1.0, 3.0], true).unwrap();
    /// let b = cache.factor_kept(2, entries.clone(), &[4.0, 1.0, 3.0], true).unwrap();
    /// assert!(std::sync::Arc::ptr_eq(&a, &b));
    /// assert_eq!(cache.numeric_count(), 1);
    /// cache.factor_kept(2, entries, &[4.0, 1.0, 5.0], true).unwrap();
    /// assert_eq!(cache.numeric_count(), 2);
    /// ```
    pub fn factor_kept(
        &mut self,
        n: usize,
        entries: Vec<(usize, usize)>,
        values: &[f64],
        keep: bool,
    ) -> Result<Arc<SpdFactor>, SolveError> {
        self.pattern(n, entries)?;
        if let Some((v, f)) = &self.last {
            if keep && v.as_slice() == values {
                return Ok(f.clone());
            }
        }
        self.last = None;
        let pattern = self.cached.as_ref().expect("set by pattern()");
        let f = Arc::new(pattern.factor(values)?);
        self.numeric_count += 1;
        if keep {
            self.last = Some((values.to_vec(), f.clone()));
        }
        Ok(f)
    }

    /// Numeric factorisations computed so far.
    pub fn numeric_count(&self) -> usize {
        self.numeric_count
    }

    /// Symbolic factorisations computed so far (1 while the pattern never changed).
    pub fn symbolic_count(&self) -> usize {
        self.symbolic_count
    }
}

impl SpdFactor {
    /// Dimension.
    pub fn n(&self) -> usize {
        self.n
    }

    /// Stored values of the Cholesky factor.
    pub fn fill(&self) -> usize {
        self.values.len()
    }

    /// Factorised by supernodes (faer's choice for the larger systems), not column by column.
    pub fn supernodal(&self) -> bool {
        matches!(self.chol.raw(), SymbolicCholeskyRaw::Supernodal(_))
    }

    /// Column `i` of `L⁻¹ P` (the factorisation `P A Pᵀ = L Lᵀ`), from which any entry of
    /// `A⁻¹ = (L⁻¹ P)ᵀ (L⁻¹ P)` follows ([`inverse_entry`](Self::inverse_entry)): a forward
    /// solve that visits only the path from `i`'s column up the elimination tree (a
    /// column's parent is its first row below the diagonal; of a supernodal factor, faer's
    /// choice for the larger systems, a supernode's is the supernode of its first row below
    /// its own), where the column's entries are. A few entries of the inverse among a few
    /// rows (a live update's loop test at its new curve's nodes, issue 51) then cost those
    /// paths, not a solve over every row each. `None` for a row out of range.
    pub fn inverse_column(&self, i: usize) -> Option<InverseColumn> {
        let mut j = match self.chol.perm() {
            Some(p) => *p.arrays().1.get(i)?,
            None => i,
        };
        if j >= self.n {
            return None;
        }
        let mut y = vec![0.0; self.n];
        y[j] = 1.0;
        let mut out = Vec::new();
        match self.chol.raw() {
            SymbolicCholeskyRaw::Simplicial(s) => {
                let (col_ptr, rows) = (s.col_ptr(), s.row_idx());
                // Faer's simplicial columns hold the diagonal first, then their rows in order.
                loop {
                    let (lo, hi) = (col_ptr[j], col_ptr[j + 1]);
                    let yj = std::mem::take(&mut y[j]) / self.values[lo];
                    out.push((j, yj));
                    if lo + 1 >= hi {
                        break;
                    }
                    for p in lo + 1..hi {
                        y[rows[p]] -= self.values[p] * yj;
                    }
                    j = rows[lo + 1];
                }
            }
            SymbolicCholeskyRaw::Supernodal(s) => {
                // Each supernode's columns `begin..end` are one column-major block: its
                // diagonal block's rows, then its rows below (`pattern`, in order).
                let (begin, end, at) =
                    (s.supernode_begin(), s.supernode_end(), s.col_ptr_for_val());
                let of = |col: usize| begin.partition_point(|&b| b <= col) - 1;
                let mut sn = of(j);
                let mut first = j - begin[sn];
                loop {
                    let (start, size) = (begin[sn], end[sn] - begin[sn]);
                    let pattern = s.supernode(sn).pattern();
                    let rows = size + pattern.len();
                    let block = &self.values[at[sn]..at[sn + 1]];
                    for c in first..size {
                        let col = &block[c * rows..(c + 1) * rows];
                        let yc = std::mem::take(&mut y[start + c]) / col[c];
                        out.push((start + c, yc));
                        for (r, l) in (c + 1..size).zip(&col[c + 1..size]) {
                            y[start + r] -= l * yc;
                        }
                        for (&row, l) in pattern.iter().zip(&col[size..]) {
                            y[row] -= l * yc;
                        }
                    }
                    // The rest of the path: every row reached is in the first one's
                    // supernode or above it.
                    let Some(&next) = pattern.first() else { break };
                    sn = of(next);
                    first = next - begin[sn];
                }
            }
        }
        Some(InverseColumn(out))
    }

    /// `(A⁻¹)_ij` from the columns of `i` and `j` ([`inverse_column`](Self::inverse_column)):
    /// the dot product over the rows both paths share.
    pub fn inverse_entry(a: &InverseColumn, b: &InverseColumn) -> f64 {
        let (a, b) = (&a.0, &b.0);
        let (mut p, mut q, mut sum) = (0, 0, 0.0);
        while p < a.len() && q < b.len() {
            match a[p].0.cmp(&b[q].0) {
                std::cmp::Ordering::Less => p += 1,
                std::cmp::Ordering::Greater => q += 1,
                std::cmp::Ordering::Equal => {
                    sum += a[p].1 * b[q].1;
                    p += 1;
                    q += 1;
                }
            }
        }
        sum
    }

    /// Solves in place for `K` right-hand sides given row by row (`b[i][k]`).
    pub fn solve<const K: usize>(&self, b: &mut [[f64; K]]) {
        assert_eq!(b.len(), self.n);
        // Rows of K values are a row-major n×K matrix: its transpose view is column-major
        // K×n, so the n×K view has row stride K.
        let flat: &mut [f64] = b.as_flattened_mut();
        let rhs = MatMut::from_row_major_slice_mut(flat, self.n, K);
        let par = faer::get_global_parallelism();
        let llt = LltRef::new(&self.chol, &self.values);
        let mut mem = MemBuffer::new(self.chol.solve_in_place_scratch::<f64>(K, par));
        llt.solve_in_place_with_conj(Conj::No, rhs, par, MemStack::new(&mut mem));
    }
}

impl SpdFactor {
    /// Solves two sets of right-hand sides at once, `b` on a second thread when the system is
    /// large enough for it to pay (the back-substitutions read the factor from memory; two
    /// cores read it twice as fast). The results are those of two [`solve`](Self::solve)s.
    pub fn solve_two<const K: usize>(&self, a: &mut [[f64; K]], b: &mut [[f64; K]]) {
        if self.values.len() < PARALLEL_SOLVE_FILL {
            self.solve(a);
            self.solve(b);
            return;
        }
        std::thread::scope(|s| {
            s.spawn(|| self.solve(b));
            self.solve(a);
        });
    }
}

/// Factors with fewer stored values are solved on one thread ([`SpdFactor::solve_two`]).
/// Measured on a 2-D grid Laplacian, 3 + 3 right-hand sides against 6 on one thread: 4.6 ms
/// against 5.5 ms at 22 500 unknowns (738 k stored values), 28 ms against 49 ms at 102 400.
const PARALLEL_SOLVE_FILL: usize = 200_000;

/// Uses one thread for sparse solves: on 2 cores faer's default pool made them ~20× slower
/// (see the crate notes). Called once at start-up by the binary and by the benches.
pub fn single_threaded() {
    faer::set_global_parallelism(faer::Par::Seq);
}

/// The symbolic Cholesky factorisation of the lower triangle `symbolic` in `ordering`.
fn symbolic_cholesky(
    symbolic: &SymbolicSparseColMat<usize>,
    ordering: SymmetricOrdering<'_, usize>,
) -> Result<SymbolicCholesky<usize>, SolveError> {
    factorize_symbolic_cholesky(
        symbolic.as_ref(),
        Side::Lower,
        ordering,
        CholeskySymbolicParams::default(),
    )
    .map_err(|e| SolveError::Faer(format!("{e:?}")))
}

/// `inverse[v]`: where `v` is in `order`, when `order` is a permutation of `0..n`.
fn inverse_of(order: &[usize], n: usize) -> Option<Vec<usize>> {
    if order.len() != n {
        return None;
    }
    let mut inverse = vec![usize::MAX; n];
    for (k, &v) in order.iter().enumerate() {
        if v >= n || inverse[v] != usize::MAX {
            return None;
        }
        inverse[v] = k;
    }
    Some(inverse)
}

/// The elimination order of a matrix of `nb`×`nb` dense blocks whose pattern has the
/// lower-triangle blocks `blocks` (`(row, col)`, `row ≥ col`; the diagonal implied): of
/// approximate minimum degree on the blocks and `candidate` (`candidate[k]`: the block
/// eliminated `k`-th, e.g. [`crate::nested_dissection::order_interiors_first`]), the one
/// whose factor of blocks fills less; `order[k]` the block eliminated `k`-th. Expanded to
/// each block's rows it is an order for [`SpdPattern::with_order`]: both orders are judged
/// on the graph of blocks, a ninth of the entries of 3×3 blocks, instead of ordering the
/// scalar matrix twice.
pub fn block_order(
    nb: usize,
    blocks: &[(usize, usize)],
    candidate: Option<&[usize]>,
) -> Result<Vec<usize>, SolveError> {
    let mut pairs: Vec<Pair<usize, usize>> = (0..nb).map(|i| Pair::new(i, i)).collect();
    for &(row, col) in blocks {
        if row >= nb || col > row {
            return Err(SolveError::BadEntry { row, col, n: nb });
        }
        pairs.push(Pair::new(row, col));
    }
    let (symbolic, _) = SymbolicSparseColMat::try_new_from_indices(nb, nb, &pairs)
        .map_err(|e| SolveError::Faer(format!("{e:?}")))?;
    let symbolic_with =
        |ordering: SymmetricOrdering<'_, usize>| symbolic_cholesky(&symbolic, ordering);
    let amd = symbolic_with(SymmetricOrdering::Amd)?;
    let amd_order: Vec<usize> = match amd.perm() {
        Some(p) => p.arrays().0.to_vec(),
        None => (0..nb).collect(),
    };
    if let Some(order) = candidate {
        if let Some(inverse) = inverse_of(order, nb) {
            let perm = faer::perm::PermRef::new_checked(order, &inverse, nb);
            let custom = symbolic_with(SymmetricOrdering::Custom(perm))?;
            if custom.len_val() < amd.len_val() {
                return Ok(order.to_vec());
            }
        }
    }
    Ok(amd_order)
}

/// A k×k grid's Laplacian with random conductances in [0.5, 1.5) (`seed`), no gauge: `(n,
/// lower-triangle entries, values)`, for tests.
#[cfg(test)]
pub(crate) fn grid_laplacian(k: usize, seed: u64) -> (usize, Vec<(usize, usize)>, Vec<f64>) {
    let n = k * k;
    let mut entries: Vec<(usize, usize)> = (0..n).map(|i| (i, i)).collect();
    let mut values = vec![0.0; n];
    let mut rng = crate::rng::Rng::new(seed);
    for i in 0..k {
        for j in 0..k {
            let v = i * k + j;
            for w in [(j + 1 < k).then(|| v + 1), (i + 1 < k).then(|| v + k)]
                .into_iter()
                .flatten()
            {
                let g = 0.5 + rng.uniform();
                values[v] += g;
                values[w] += g;
                entries.push((w, v));
                values.push(-g);
            }
        }
    }
    (n, entries, values)
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

    /// Issue 51: the entries of the inverse from two columns of `L⁻¹ P` are those of solves,
    /// on a grid Laplacian (ordered by minimum degree: the permutation is not the identity),
    /// and a column's path is a part of the rows.
    #[test]
    fn any_entry_of_the_inverse_from_two_paths_is_a_solves() {
        let (n, entries, mut values) = grid_laplacian(12, 3);
        values[5] += 1.0;
        let f = SpdPattern::new(n, &entries)
            .unwrap()
            .factor(&values)
            .unwrap();
        let columns: Vec<InverseColumn> = (0..n)
            .map(|i| f.inverse_column(i).expect("a simplicial factor"))
            .collect();
        for j in (0..n).step_by(5) {
            let mut col = vec![[0.0]; n];
            col[j][0] = 1.0;
            f.solve(&mut col);
            for (i, want) in col.iter().enumerate() {
                let got = SpdFactor::inverse_entry(&columns[i], &columns[j]);
                assert!(
                    (got - want[0]).abs() < 1e-12,
                    "({i}, {j}): {got} vs {}",
                    want[0]
                );
            }
        }
        let mean = columns.iter().map(|c| c.0.len()).sum::<usize>() as f64 / n as f64;
        assert!(mean < n as f64 / 4.0, "{mean}");
    }

    #[test]
    fn two_sets_of_right_hand_sides_solved_on_two_threads_give_two_solves() {
        // A grid Laplacian large enough for the second thread.
        let side = 120;
        let n = side * side;
        let (mut entries, mut vals) = (Vec::new(), Vec::new());
        for k in 0..n {
            entries.push((k, k));
            vals.push(4.01);
            let neighbours = [(k % side > 0, 1), (k >= side, side)];
            for (_, d) in neighbours.into_iter().filter(|(on, _)| *on) {
                entries.push((k, k - d));
                vals.push(-1.0);
            }
        }
        let f = SpdPattern::new(n, &entries).unwrap().factor(&vals).unwrap();
        assert!(f.fill() >= PARALLEL_SOLVE_FILL, "{}", f.fill());
        let rhs = |s: f64| -> Vec<[f64; 3]> {
            (0..n)
                .map(|i| [s * i as f64, 1.0, (i % 7) as f64])
                .collect()
        };
        let (mut a, mut b) = (rhs(1.0), rhs(-2.0));
        f.solve_two(&mut a, &mut b);
        let (mut a1, mut b1) = (rhs(1.0), rhs(-2.0));
        f.solve(&mut a1);
        f.solve(&mut b1);
        assert!(a == a1 && b == b1);
        assert!(a != rhs(1.0));
    }

    #[test]
    fn a_candidate_block_order_is_kept_only_when_it_fills_less_and_solves_the_same() {
        // A cycle of 200 blocks with chords every 10: the Laplacian plus the identity, each
        // entry a 3×3 multiple of the identity.
        let nb = 200;
        let mut edges: Vec<(usize, usize)> = (0..nb).map(|i| (i, (i + 1) % nb)).collect();
        edges.extend((0..nb).step_by(10).map(|i| (i, (i + 100) % nb)));
        let blocks: Vec<(usize, usize)> =
            edges.iter().map(|&(a, b)| (a.max(b), a.min(b))).collect();
        let (mut entries, mut values) = (Vec::new(), Vec::new());
        for i in 0..nb {
            let degree = edges.iter().filter(|&&(a, b)| a == i || b == i).count();
            for d in 0..3 {
                entries.push((3 * i + d, 3 * i + d));
                values.push(1.0 + degree as f64);
            }
        }
        for &(a, b) in &blocks {
            for d in 0..3 {
                entries.push((3 * a + d, 3 * b + d));
                values.push(-1.0);
            }
        }
        let n = 3 * nb;
        let amd = SpdPattern::new(n, &entries).unwrap();
        let scalar = |o: &[usize]| -> Vec<usize> {
            o.iter()
                .flat_map(|&b| [3 * b, 3 * b + 1, 3 * b + 2])
                .collect()
        };
        let amd_blocks = block_order(nb, &blocks, None).unwrap();
        let natural: Vec<usize> = (0..nb).collect();
        let reversed: Vec<usize> = (0..nb).rev().collect();
        for candidate in [&natural, &reversed] {
            let o = block_order(nb, &blocks, Some(candidate)).unwrap();
            assert!(o == *candidate || o == amd_blocks);
            let p = SpdPattern::with_order(n, &entries, &scalar(&o)).unwrap();
            let natural_fill = SpdPattern::with_order(n, &entries, &scalar(candidate))
                .unwrap()
                .fill();
            let amd_fill = SpdPattern::with_order(n, &entries, &scalar(&amd_blocks))
                .unwrap()
                .fill();
            // The one kept fills no more than the other (up to the supernodes' padding).
            assert!(
                p.fill() <= natural_fill.min(amd_fill) * 11 / 10,
                "{} {natural_fill} {amd_fill}",
                p.fill()
            );
            let b: Vec<[f64; 1]> = (0..n).map(|i| [(i as f64).sin()]).collect();
            let (mut x, mut y) = (b.clone(), b.clone());
            amd.factor(&values).unwrap().solve(&mut x);
            p.factor(&values).unwrap().solve(&mut y);
            for (a, b) in x.iter().zip(&y) {
                assert!((a[0] - b[0]).abs() < 1e-12, "{a:?} {b:?}");
            }
        }
        // The natural order of a cycle with chords fills more than minimum degree.
        assert_eq!(
            block_order(nb, &blocks, Some(&natural)).unwrap(),
            amd_blocks
        );
        // An order that is no permutation is ignored, not trusted.
        let bad = vec![0; n];
        assert_eq!(
            block_order(nb, &blocks, Some(&bad[..nb])).unwrap(),
            amd_blocks
        );
        assert_eq!(
            SpdPattern::with_order(n, &entries, &bad).unwrap().fill(),
            amd.fill()
        );
        assert!(matches!(
            block_order(2, &[(0, 1)], None),
            Err(SolveError::BadEntry { .. })
        ));
    }
}
