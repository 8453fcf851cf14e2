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
        if let Some(&(row, col)) = entries.iter().find(|&&(r, c)| r >= n || c > r) {
            return Err(SolveError::BadEntry { row, col, n });
        }
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
        // A's lower triangle by column, in the new order (duplicates summed).
        let mut a_cols: Vec<Vec<(usize, f64)>> = vec![Vec::new(); n];
        for (&(r, c), &v) in entries.iter().zip(values) {
            let (r, c) = (new_of[r], new_of[c]);
            let (r, c) = (r.max(c), r.min(c));
            a_cols[c].push((r, v));
        }
        for col in &mut a_cols {
            col.sort_unstable_by_key(|e| e.0);
            col.dedup_by(|b, a| {
                if a.0 == b.0 {
                    a.1 += b.1;
                    true
                } else {
                    false
                }
            });
        }
        // The factor's pattern: column j is A's column j with the columns of its children in
        // the elimination tree (less their own rows above j).
        let mut children: Vec<Vec<usize>> = vec![Vec::new(); n];
        let mut pattern: Vec<Vec<usize>> = Vec::with_capacity(n);
        for j in 0..n {
            let mut rows: Vec<usize> = a_cols[j].iter().map(|e| e.0).collect();
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
        drop(pattern);
        drop(children);
        // L D Lᵀ, left-looking: column j gathers the updates of the columns k < j whose row j
        // is set (row lists kept as they fill), each column's cursor at its first row ≥ j.
        let mut l = vec![0.0; rows.len()];
        let mut d = vec![0.0; n];
        let mut x = vec![0.0; n];
        let mut row_cols: Vec<Vec<usize>> = vec![Vec::new(); n];
        let mut cursor: Vec<usize> = col_ptr[..n].iter().map(|&p| p + 1).collect();
        for j in 0..n {
            for &(r, v) in &a_cols[j] {
                x[r] += v;
            }
            for &k in &row_cols[j] {
                // Row j of column k, then every row below it.
                let at = cursor[k];
                debug_assert_eq!(rows[at], j);
                let ljk = l[at];
                let f = ljk * d[k];
                for p in at..col_ptr[k + 1] {
                    x[rows[p]] -= l[p] * f;
                }
                cursor[k] = at + 1;
            }
            let dj = x[j];
            x[j] = 0.0;
            if dj.is_nan() || dj <= 0.0 || !dj.is_finite() {
                return Err(SolveError::NonPositivePivot { index: order[j] });
            }
            d[j] = dj;
            for p in col_ptr[j] + 1..col_ptr[j + 1] {
                let r = rows[p];
                l[p] = x[r] / dj;
                x[r] = 0.0;
                row_cols[r].push(j);
            }
        }
        drop(row_cols);
        // Takahashi, from the last column back.
        let mut z = vec![0.0; rows.len()];
        let find = |rows: &[usize], col_ptr: &[usize], i: usize, k: usize| -> usize {
            let (r, c) = (i.max(k), i.min(k));
            let span = &rows[col_ptr[c]..col_ptr[c + 1]];
            col_ptr[c] + span.binary_search(&r).expect("on the factor's pattern")
        };
        for j in (0..n).rev() {
            let (lo, hi) = (col_ptr[j] + 1, col_ptr[j + 1]);
            let mut zjj = 1.0 / d[j];
            for p in lo..hi {
                let i = rows[p];
                let mut s = 0.0;
                for q in lo..hi {
                    s += z[find(&rows, &col_ptr, i, rows[q])] * l[q];
                }
                z[p] = -s;
            }
            for p in lo..hi {
                zjj -= l[p] * z[p];
            }
            z[col_ptr[j]] = zjj;
        }
        Ok(SelectedInverse {
            new_of,
            col_ptr,
            rows,
            z,
        })
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sparse_llt::SpdPattern;

    /// A matrix's size, lower-triangle entries, their values, and its explicit zeros.
    type Matrix = (usize, Vec<(usize, usize)>, Vec<f64>, Vec<(usize, usize)>);

    /// A grid Laplacian with a gauge, and explicit zeros between some far pairs.
    fn grid(k: usize) -> Matrix {
        let n = k * k;
        let mut entries: Vec<(usize, usize)> = (0..n).map(|i| (i, i)).collect();
        let mut values = vec![0.0; n];
        let mut rng = crate::rng::Rng::new(7);
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
