//! Entries of the inverse of a sparse symmetric positive-definite matrix on the pattern of its
//! Cholesky factor (a *selected inversion*, Takahashi's equations), for the cost of about one
//! factorisation: what the loop-closure test needs of a node Laplacian's inverse (effective
//! resistances across segments and between a tag's neighbours), where one solve per tag made
//! the test O(tags × fill).
//!
//! `A = L D Lᵀ` (unit lower `L`, in a fill-reducing order), then, from the last column back,
//! `Z_ij = −Σ_k Z_ik L_kj` and `Z_jj = 1/d_j − Σ_k L_kj Z_kj` over the rows `k > j` of column
//! `j` of `L`: every `Z_ik` needed lies on the factor's pattern. Entries of `A` given as
//! explicit zeros are on the pattern too, so their `Z` can be asked for.
//!
//! The same on dual numbers `a + ε b` gives, besides, the entries of `A⁻¹ B A⁻¹` on the
//! pattern ([`SelectedPattern::sandwich`]): a covariance propagated through a least squares.
//!
//! ```
//! use sfs_geometry::selected_inverse::SelectedInverse;
//! // [[4, 1], [1, 3]]⁻¹ = [[3, −1], [−1, 4]] / 11.
//! let z = SelectedInverse::new(2, &[(0, 0), (1, 0), (1, 1)], &[4.0, 1.0, 3.0]).unwrap();
//! assert!((z.get(0, 0).unwrap() - 3.0 / 11.0).abs() < 1e-15);
//! assert!((z.get(0, 1).unwrap() + 1.0 / 11.0).abs() < 1e-15);
//! assert!((z.get(1, 1).unwrap() - 4.0 / 11.0).abs() < 1e-15);
//! ```

use crate::sparse_llt::SolveError;

/// The entries of `A⁻¹` on the pattern of `A`'s Cholesky factor.
#[derive(Debug, Clone)]
pub struct SelectedInverse {
    /// `new_of[i]`: the position of row `i` in the elimination order.
    new_of: Vec<usize>,
    /// Column `j` of the factor (new indices): its rows `col_ptr[j]..col_ptr[j + 1]` in
    /// `rows`, sorted, the diagonal first; `z` the inverse's entries there.
    col_ptr: Vec<usize>,
    rows: Vec<usize>,
    z: Vec<f64>,
}

impl SelectedInverse {
    /// Of the `n`×`n` matrix whose lower-triangle `entries` (`row ≥ col`, duplicates summed)
    /// have `values`. Errors when it is not positive definite.
    pub fn new(n: usize, entries: &[(usize, usize)], values: &[f64]) -> Result<Self, SolveError> {
        SelectedPattern::new(n, entries)?.inverse(values)
    }

    /// `(A⁻¹)_ij`, when `(i, j)` is on the factor's pattern (an entry of `A`, explicit zeros
    /// included, or a fill-in).
    pub fn get(&self, i: usize, j: usize) -> Option<f64> {
        let (a, b) = (*self.new_of.get(i)?, *self.new_of.get(j)?);
        let (r, c) = (a.max(b), a.min(b));
        let span = &self.rows[self.col_ptr[c]..self.col_ptr[c + 1]];
        span.binary_search(&r)
            .ok()
            .map(|k| self.z[self.col_ptr[c] + k])
    }

    /// Stored entries (the factor's fill).
    pub fn fill(&self) -> usize {
        self.z.len()
    }
}

/// The symbolic part of a selected inversion (the order and the factor's pattern), for
/// several matrices on the same `entries`.
#[derive(Debug, Clone)]
pub struct SelectedPattern {
    entries: Vec<(usize, usize)>,
    new_of: Vec<usize>,
    col_ptr: Vec<usize>,
    rows: Vec<usize>,
}

impl SelectedPattern {
    /// The pattern of the `n`×`n` matrices with lower-triangle `entries` (`row ≥ col`).
    pub fn new(n: usize, entries: &[(usize, usize)]) -> Result<Self, SolveError> {
        if let Some(&(row, col)) = entries.iter().find(|&&(r, c)| r >= n || c > r) {
            return Err(SolveError::BadEntry { row, col, n });
        }
        let (new_of, col_ptr, rows) = symbolic(n, entries);
        Ok(SelectedPattern {
            entries: entries.to_vec(),
            new_of,
            col_ptr,
            rows,
        })
    }

    /// [`SelectedInverse::new`] of the matrix with `values` on the entries.
    pub fn inverse(&self, values: &[f64]) -> Result<SelectedInverse, SolveError> {
        let z = numeric(
            &self.col_ptr,
            &self.rows,
            self.columns(values),
            &self.new_of,
        )?;
        Ok(self.with(z))
    }

    /// The entries of `A⁻¹` (`values`) and of `A⁻¹ B A⁻¹` (`B` the symmetric matrix with
    /// `b_values` on the same entries) on the factor's pattern, for about two selected
    /// inversions: `A⁻¹ B A⁻¹ = −d/dt (A + tB)⁻¹` at `t = 0`, so the same elimination and
    /// Takahashi's equations run on numbers `a + ε b` (ε² = 0) give both. A covariance
    /// propagated through a least squares, `K M K` with `K` the inverse of its normal matrix,
    /// is read so on the pattern, not a solve per column. The first is bit for bit
    /// [`inverse`](Self::inverse)'s.
    ///
    /// ```
    /// use sfs_geometry::selected_inverse::SelectedPattern;
    /// // A = [[4, 1], [1, 3]], B = [[1, 0], [0, 0]]: A⁻¹ B A⁻¹ = [[9, −3], [−3, 1]] / 121.
    /// let p = SelectedPattern::new(2, &[(0, 0), (1, 0), (1, 1)]).unwrap();
    /// let (z, s) = p.sandwich(&[4.0, 1.0, 3.0], &[1.0, 0.0, 0.0]).unwrap();
    /// assert!((z.get(0, 0).unwrap() - 3.0 / 11.0).abs() < 1e-15);
    /// assert!((s.get(0, 0).unwrap() - 9.0 / 121.0).abs() < 1e-15);
    /// assert!((s.get(1, 0).unwrap() + 3.0 / 121.0).abs() < 1e-15);
    /// assert!((s.get(1, 1).unwrap() - 1.0 / 121.0).abs() < 1e-15);
    /// ```
    pub fn sandwich(
        &self,
        values: &[f64],
        b_values: &[f64],
    ) -> Result<(SelectedInverse, SelectedInverse), SolveError> {
        let duals: Vec<Dual> = values
            .iter()
            .zip(b_values)
            .map(|(&v, &d)| Dual { v, d })
            .collect();
        let z = numeric(
            &self.col_ptr,
            &self.rows,
            self.columns(&duals),
            &self.new_of,
        )?;
        let (v, d): (Vec<f64>, Vec<f64>) = z.into_iter().map(|x| (x.v, -x.d)).unzip();
        Ok((self.with(v), self.with(d)))
    }

    fn with(&self, z: Vec<f64>) -> SelectedInverse {
        SelectedInverse {
            new_of: self.new_of.clone(),
            col_ptr: self.col_ptr.clone(),
            rows: self.rows.clone(),
            z,
        }
    }

    /// The matrix's lower triangle by column, in the new order (duplicates summed).
    fn columns<T: Scalar>(&self, values: &[T]) -> Vec<Vec<(usize, T)>> {
        assert_eq!(values.len(), self.entries.len(), "one value per entry");
        let mut a_cols: Vec<Vec<(usize, T)>> = vec![Vec::new(); self.new_of.len()];
        for (&(r, c), &v) in self.entries.iter().zip(values) {
            let (r, c) = (self.new_of[r], self.new_of[c]);
            let (r, c) = (r.max(c), r.min(c));
            a_cols[c].push((r, v));
        }
        for col in &mut a_cols {
            col.sort_unstable_by_key(|e| e.0);
            col.dedup_by(|b, a| {
                if a.0 == b.0 {
                    a.1 = a.1 + b.1;
                    true
                } else {
                    false
                }
            });
        }
        a_cols
    }
}

/// Numbers the elimination runs on: `f64`, or [`Dual`] for a derivative.
trait Scalar:
    Copy
    + std::ops::Add<Output = Self>
    + std::ops::Sub<Output = Self>
    + std::ops::Mul<Output = Self>
    + std::ops::Div<Output = Self>
    + std::ops::Neg<Output = Self>
{
    const ZERO: Self;
    const ONE: Self;
    /// The value (a pivot is checked on it).
    fn value(self) -> f64;
}

impl Scalar for f64 {
    const ZERO: f64 = 0.0;
    const ONE: f64 = 1.0;
    fn value(self) -> f64 {
        self
    }
}

/// `v + ε d` with `ε² = 0`: arithmetic on it carries the derivative `d` along; its value
/// takes exactly the operations `f64` would.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Dual {
    v: f64,
    d: f64,
}

impl std::ops::Add for Dual {
    type Output = Dual;
    fn add(self, o: Dual) -> Dual {
        Dual {
            v: self.v + o.v,
            d: self.d + o.d,
        }
    }
}

impl std::ops::Sub for Dual {
    type Output = Dual;
    fn sub(self, o: Dual) -> Dual {
        Dual {
            v: self.v - o.v,
            d: self.d - o.d,
        }
    }
}

impl std::ops::Mul for Dual {
    type Output = Dual;
    fn mul(self, o: Dual) -> Dual {
        Dual {
            v: self.v * o.v,
            d: self.v * o.d + self.d * o.v,
        }
    }
}

impl std::ops::Div for Dual {
    type Output = Dual;
    fn div(self, o: Dual) -> Dual {
        let v = self.v / o.v;
        Dual {
            v,
            d: (self.d - v * o.d) / o.v,
        }
    }
}

impl std::ops::Neg for Dual {
    type Output = Dual;
    fn neg(self) -> Dual {
        Dual {
            v: -self.v,
            d: -self.d,
        }
    }
}

impl Scalar for Dual {
    const ZERO: Dual = Dual { v: 0.0, d: 0.0 };
    const ONE: Dual = Dual { v: 1.0, d: 0.0 };
    fn value(self) -> f64 {
        self.v
    }
}

/// Where each row goes in a fill-reducing order (`new_of`) and the factor's pattern (column
/// `j`'s rows `rows[col_ptr[j]..col_ptr[j + 1]]`, sorted, the diagonal first).
fn symbolic(n: usize, entries: &[(usize, usize)]) -> (Vec<usize>, Vec<usize>, Vec<usize>) {
    // A fill-reducing order of the graph.
    let mut adj = vec![Vec::new(); n];
    for &(r, c) in entries {
        if r != c {
            adj[r].push(c);
            adj[c].push(r);
        }
    }
    let order = crate::nested_dissection::order(&adj);
    let mut new_of = vec![0; n];
    for (k, &v) in order.iter().enumerate() {
        new_of[v] = k;
    }
    // A's rows by column, in the new order.
    let mut a_rows: Vec<Vec<usize>> = vec![Vec::new(); n];
    for &(r, c) in entries {
        let (r, c) = (new_of[r], new_of[c]);
        a_rows[r.min(c)].push(r.max(c));
    }
    // The factor's pattern: column j is A's column j with the columns of its children in
    // the elimination tree (less their own rows above j).
    let mut children: Vec<Vec<usize>> = vec![Vec::new(); n];
    let mut pattern: Vec<Vec<usize>> = Vec::with_capacity(n);
    for j in 0..n {
        let mut rows = std::mem::take(&mut a_rows[j]);
        rows.push(j);
        for &c in &children[j] {
            rows.extend(pattern[c].iter().copied().filter(|&r| r >= j));
        }
        rows.sort_unstable();
        rows.dedup();
        if let Some(&parent) = rows.iter().find(|&&r| r > j) {
            children[parent].push(j);
        }
        pattern.push(rows);
    }
    let mut col_ptr = Vec::with_capacity(n + 1);
    col_ptr.push(0);
    let mut rows = Vec::new();
    for p in &pattern {
        rows.extend_from_slice(p);
        col_ptr.push(rows.len());
    }
    (new_of, col_ptr, rows)
}

/// `L D Lᵀ` on the pattern, then Takahashi's equations: the inverse's entries there.
fn numeric<T: Scalar>(
    col_ptr: &[usize],
    rows: &[usize],
    a_cols: Vec<Vec<(usize, T)>>,
    new_of: &[usize],
) -> Result<Vec<T>, SolveError> {
    let n = a_cols.len();
    // L D Lᵀ, left-looking: column j gathers the updates of the columns k < j whose row j
    // is set (row lists kept as they fill), each column's cursor at its first row ≥ j.
    let mut l = vec![T::ZERO; rows.len()];
    let mut d = vec![T::ZERO; n];
    let mut x = vec![T::ZERO; n];
    let mut row_cols: Vec<Vec<usize>> = vec![Vec::new(); n];
    let mut cursor: Vec<usize> = col_ptr[..n].iter().map(|&p| p + 1).collect();
    for j in 0..n {
        for &(r, v) in &a_cols[j] {
            x[r] = x[r] + v;
        }
        for &k in &row_cols[j] {
            // Row j of column k, then every row below it.
            let at = cursor[k];
            debug_assert_eq!(rows[at], j);
            let ljk = l[at];
            let f = ljk * d[k];
            for p in at..col_ptr[k + 1] {
                x[rows[p]] = x[rows[p]] - l[p] * f;
            }
            cursor[k] = at + 1;
        }
        let dj = x[j];
        x[j] = T::ZERO;
        let pivot = dj.value();
        if pivot.is_nan() || pivot <= 0.0 || !pivot.is_finite() {
            let index = new_of.iter().position(|&k| k == j).unwrap_or(j);
            return Err(SolveError::NonPositivePivot { index });
        }
        d[j] = dj;
        for p in col_ptr[j] + 1..col_ptr[j + 1] {
            let r = rows[p];
            l[p] = x[r] / dj;
            x[r] = T::ZERO;
            row_cols[r].push(j);
        }
    }
    drop(row_cols);
    // Takahashi, from the last column back.
    let mut z = vec![T::ZERO; rows.len()];
    // Column j's rows below the diagonal (R) marked with their place in it; for each k of
    // R, column k (already inverted) walked once: its rows in R give Z_ik (and, below the
    // diagonal, Z_ki) without a search. Every Z_ik needed is there: R's rows past k are
    // on column k's pattern (the elimination tree). Each sum takes its terms in the
    // order of R, as the equations read.
    //
    // s_k is summed in a register (no other term of it comes while column k is walked: its
    // rows lie below k), and the walk stops past R's last row (column k's rows are sorted):
    // the same terms in the same order as the equations read, so the same bits.
    let mut place = vec![usize::MAX; n];
    let mut s = Vec::new();
    for j in (0..n).rev() {
        let (lo, hi) = (col_ptr[j] + 1, col_ptr[j + 1]);
        for p in lo..hi {
            place[rows[p]] = p - lo;
        }
        s.clear();
        s.resize(hi - lo, T::ZERO);
        let last = if hi > lo { rows[hi - 1] } else { 0 };
        for q in lo..hi {
            let (k, lk) = (rows[q], l[q]);
            let qk = q - lo;
            // The diagonal first, then the rows below it in R.
            let mut sk = s[qk] + z[col_ptr[k]] * lk;
            for e in col_ptr[k] + 1..col_ptr[k + 1] {
                let r = rows[e];
                if r > last {
                    break;
                }
                let at = place[r];
                if at != usize::MAX {
                    // Z_rk: a term of s_r (with l_k) and of s_k (with l_r).
                    s[at] = s[at] + z[e] * lk;
                    sk = sk + z[e] * l[lo + at];
                }
            }
            s[qk] = sk;
        }
        let mut zjj = T::ONE / d[j];
        for p in lo..hi {
            z[p] = -s[p - lo];
            place[rows[p]] = usize::MAX;
        }
        for p in lo..hi {
            zjj = zjj - l[p] * z[p];
        }
        z[col_ptr[j]] = zjj;
    }
    Ok(z)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sparse_llt::SpdPattern;

    /// A matrix's size, lower-triangle entries, their values, and its explicit zeros.
    type Matrix = (usize, Vec<(usize, usize)>, Vec<f64>, Vec<(usize, usize)>);

    /// A grid Laplacian with a gauge, and explicit zeros between some far pairs.
    fn grid(k: usize) -> Matrix {
        let (n, mut entries, mut values) = crate::sparse_llt::grid_laplacian(k, 7);
        values[0] += 1.0;
        let zeros = vec![(n - 1, 0), (k + 3, 2)];
        for &(r, c) in &zeros {
            entries.push((r, c));
            values.push(0.0);
        }
        (n, entries, values, zeros)
    }

    #[test]
    fn its_entries_are_those_of_the_inverse() {
        let (n, entries, values, zeros) = grid(9);
        let z = SelectedInverse::new(n, &entries, &values).unwrap();
        let f = SpdPattern::new(n, &entries)
            .unwrap()
            .factor(&values)
            .unwrap();
        let mut cols: Vec<[f64; 1]>;
        let mut checked = 0;
        for j in 0..n {
            cols = vec![[0.0]; n];
            cols[j][0] = 1.0;
            f.solve(&mut cols);
            for i in 0..n {
                if let Some(v) = z.get(i, j) {
                    assert!(
                        (v - cols[i][0]).abs() < 1e-12 * cols[j][0].abs().max(1.0),
                        "({i}, {j}): {v} vs {}",
                        cols[i][0]
                    );
                    assert_eq!(z.get(j, i), Some(v));
                    checked += 1;
                }
            }
        }
        // Every entry of A is there: the diagonal, the edges, the explicit zeros.
        for &(r, c) in entries.iter().chain(&zeros) {
            assert!(z.get(r, c).is_some(), "({r}, {c})");
        }
        assert!(checked >= entries.len());
        assert!(z.fill() < n * n / 4, "fill {}", z.fill());
    }

    #[test]
    fn the_sandwich_is_k_b_k_and_the_inverse_is_the_same_bits() {
        // B: another Laplacian on the same edges (weights of their own), the explicit zeros
        // with values too.
        let (n, entries, values, _) = grid(7);
        let mut rng = crate::rng::Rng::new(11);
        let mut b = vec![0.0; entries.len()];
        for (k, &(r, c)) in entries.iter().enumerate() {
            if r != c {
                let w = rng.uniform();
                b[k] = -w;
                b[r] += w;
                b[c] += w;
            }
        }
        let (z, s) = SelectedPattern::new(n, &entries)
            .unwrap()
            .sandwich(&values, &b)
            .unwrap();
        let plain = SelectedInverse::new(n, &entries, &values).unwrap();
        assert_eq!(z.z, plain.z, "the inverse is new()'s, bit for bit");
        // K B K column by column: K e_j, B, K again.
        let f = SpdPattern::new(n, &entries)
            .unwrap()
            .factor(&values)
            .unwrap();
        let mut checked = 0;
        for j in 0..n {
            let mut col = vec![[0.0]; n];
            col[j][0] = 1.0;
            f.solve(&mut col);
            let mut bk = vec![[0.0]; n];
            for (&(r, c), &w) in entries.iter().zip(&b) {
                bk[r][0] += w * col[c][0];
                if r != c {
                    bk[c][0] += w * col[r][0];
                }
            }
            f.solve(&mut bk);
            for i in 0..n {
                if let Some(v) = s.get(i, j) {
                    assert!(
                        (v - bk[i][0]).abs() < 1e-11 * bk[j][0].abs().max(1e-3),
                        "({i}, {j}): {v} vs {}",
                        bk[i][0]
                    );
                    checked += 1;
                }
            }
        }
        assert!(checked >= entries.len());
    }

    #[test]
    fn a_matrix_that_is_not_positive_definite_is_refused() {
        let e = [(0, 0), (1, 0), (1, 1)];
        assert!(matches!(
            SelectedInverse::new(2, &e, &[1.0, 2.0, 1.0]),
            Err(SolveError::NonPositivePivot { .. })
        ));
        assert!(matches!(
            SelectedInverse::new(2, &[(0, 1)], &[1.0]),
            Err(SolveError::BadEntry { .. })
        ));
    }
}
