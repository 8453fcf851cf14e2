//! A fill-reducing elimination order by nested dissection for graphs made of chains coupled at
//! a few places: a curve network's frames (chains, the curves, tied at the nodes where they
//! cross). Each part of the graph is cut by a level of a breadth-first search from a
//! pseudo-peripheral vertex (a "wavefront" across the chains, one vertex per chain it crosses),
//! its two sides ordered first, recursively, and the separator last; parts of at most
//! [`LEAF`] vertices are ordered by minimum degree. On a grid of crossing chains the fill
//! grows about as `n log n`, where approximate minimum degree let the crossings' fronts
//! grow (BENCHMARKS.md, "Sessions of hundreds of curves"). [`order_interiors_first`] orders
//! the chains' pieces between the ties first and dissects only the graph of the ties, whose
//! separators are then a few vertices at each tie.
//!
//! ```
//! use sfs_geometry::nested_dissection::order;
//! // A path 0 – 1 – 2 – 3 – 4: every vertex once.
//! let adj = vec![vec![1], vec![0, 2], vec![1, 3], vec![2, 4], vec![3]];
//! let mut o = order(&adj);
//! o.sort();
//! assert_eq!(o, vec![0, 1, 2, 3, 4]);
//! ```

use std::collections::VecDeque;

/// Parts of at most this many vertices are ordered by minimum degree.
pub const LEAF: usize = 64;

/// The elimination order of the graph `adj` (`adj[v]`: the neighbours of vertex `v`,
/// symmetric, no self-loops needed): `order[k]` is the vertex eliminated `k`-th.
pub fn order(adj: &[Vec<usize>]) -> Vec<usize> {
    let n = adj.len();
    let mut st = State {
        adj,
        stamp: vec![0; n],
        level: vec![usize::MAX; n],
        next_stamp: 0,
        order: Vec::with_capacity(n),
    };
    let all: Vec<usize> = (0..n).collect();
    for component in st.components(&all) {
        st.dissect(component);
    }
    debug_assert_eq!(st.order.len(), n);
    st.order
}

/// As [`order`], for a graph whose `interior` vertices come in small pieces hung between the
/// others (the frames of a curve between two nodes, hung between the frames at the nodes):
/// each piece first (its own order), then the rest by nested dissection of the graph the
/// pieces leave behind (each piece's neighbours made a clique, as its elimination makes
/// them). The separators are then cut across the nodes' graph alone, a few vertices at each
/// node rather than wherever a wavefront crosses a curve; on the regression's networks of
/// crossing curves it fills a fifth less than [`order`] and is found 3–4× faster
/// (BENCHMARKS.md, "Sessions of hundreds of curves").
///
/// ```
/// use sfs_geometry::nested_dissection::order_interiors_first;
/// // A path 0 – 1 – 2 – 3 – 4 with 1, 2 and 3 interior: they go first.
/// let adj = vec![vec![1], vec![0, 2], vec![1, 3], vec![2, 4], vec![3]];
/// let interior = [false, true, true, true, false];
/// let o = order_interiors_first(&adj, &interior);
/// let mut first: Vec<usize> = o[..3].to_vec();
/// first.sort();
/// assert_eq!(first, vec![1, 2, 3]);
/// ```
pub fn order_interiors_first(adj: &[Vec<usize>], interior: &[bool]) -> Vec<usize> {
    let n = adj.len();
    let inside = |v: usize| interior.get(v).copied().unwrap_or(false);
    let mut piece = vec![usize::MAX; n];
    let mut local = vec![usize::MAX; n];
    let mut out = Vec::with_capacity(n);
    let mut cliques: Vec<Vec<usize>> = Vec::new();
    for s in 0..n {
        if !inside(s) || piece[s] != usize::MAX {
            continue;
        }
        let id = cliques.len();
        piece[s] = id;
        let (mut vs, mut boundary) = (vec![s], Vec::new());
        let mut i = 0;
        while i < vs.len() {
            let u = vs[i];
            i += 1;
            for &w in &adj[u] {
                if !inside(w) {
                    boundary.push(w);
                } else if piece[w] == usize::MAX {
                    piece[w] = id;
                    vs.push(w);
                }
            }
        }
        for (k, &v) in vs.iter().enumerate() {
            local[v] = k;
        }
        let sub: Vec<Vec<usize>> = vs
            .iter()
            .map(|&v| {
                adj[v]
                    .iter()
                    .filter(|&&w| inside(w))
                    .map(|&w| local[w])
                    .collect()
            })
            .collect();
        out.extend(order(&sub).into_iter().map(|k| vs[k]));
        boundary.sort_unstable();
        boundary.dedup();
        cliques.push(boundary);
    }
    let rest: Vec<usize> = (0..n).filter(|&v| !inside(v)).collect();
    for (k, &v) in rest.iter().enumerate() {
        local[v] = k;
    }
    let mut left: Vec<Vec<usize>> = rest
        .iter()
        .map(|&v| {
            adj[v]
                .iter()
                .filter(|&&w| !inside(w))
                .map(|&w| local[w])
                .collect()
        })
        .collect();
    for c in &cliques {
        for &a in c {
            left[local[a]].extend(c.iter().filter(|&&b| b != a).map(|&b| local[b]));
        }
    }
    for a in &mut left {
        a.sort_unstable();
        a.dedup();
    }
    out.extend(order(&left).into_iter().map(|k| rest[k]));
    out
}

struct State<'a> {
    adj: &'a [Vec<usize>],
    /// The part a vertex is in now (`next_stamp` numbers the parts as they are made).
    stamp: Vec<u32>,
    level: Vec<usize>,
    next_stamp: u32,
    order: Vec<usize>,
}

impl State<'_> {
    /// Marks `vs` as one part; its stamp.
    fn mark(&mut self, vs: &[usize]) -> u32 {
        self.next_stamp += 1;
        let s = self.next_stamp;
        for &v in vs {
            self.stamp[v] = s;
        }
        s
    }

    /// The connected components of the subgraph on `vs`.
    fn components(&mut self, vs: &[usize]) -> Vec<Vec<usize>> {
        let s = self.mark(vs);
        let seen = s + 1;
        self.next_stamp += 1;
        let mut out = Vec::new();
        for &v in vs {
            if self.stamp[v] != s {
                continue;
            }
            let mut comp = vec![v];
            self.stamp[v] = seen;
            let mut i = 0;
            while i < comp.len() {
                let u = comp[i];
                i += 1;
                for &w in &self.adj[u] {
                    if self.stamp[w] == s {
                        self.stamp[w] = seen;
                        comp.push(w);
                    }
                }
            }
            out.push(comp);
        }
        out
    }

    /// Breadth-first levels from `root` within the part stamped `s`: the levels' vertices
    /// (`self.level` set for each).
    fn bfs(&mut self, root: usize, s: u32, vs: &[usize]) -> Vec<Vec<usize>> {
        for &v in vs {
            self.level[v] = usize::MAX;
        }
        self.level[root] = 0;
        let mut levels = vec![vec![root]];
        let mut queue = VecDeque::from([root]);
        while let Some(u) = queue.pop_front() {
            let l = self.level[u];
            for &w in &self.adj[u] {
                if self.stamp[w] == s && self.level[w] == usize::MAX {
                    self.level[w] = l + 1;
                    if levels.len() <= l + 1 {
                        levels.push(Vec::new());
                    }
                    levels[l + 1].push(w);
                    queue.push_back(w);
                }
            }
        }
        levels
    }

    /// Orders the connected part `vs`: its sides, then its separator.
    fn dissect(&mut self, vs: Vec<usize>) {
        if vs.len() <= LEAF {
            self.minimum_degree(&vs);
            return;
        }
        let s = self.mark(&vs);
        // A pseudo-peripheral root: the far end of a search from the far end of a search.
        let mut root = vs[0];
        let mut levels = self.bfs(root, s, &vs);
        for _ in 0..2 {
            let far = *levels.last().expect("a level").first().expect("a vertex");
            let next = self.bfs(far, s, &vs);
            if next.len() <= levels.len() {
                levels = self.bfs(root, s, &vs);
                break;
            }
            root = far;
            levels = next;
        }
        if levels.len() < 3 {
            // No level separates it (a clique, a star): minimum degree on the whole part.
            self.minimum_degree(&vs);
            return;
        }
        // The level where half the part lies behind, moved to the smallest level nearby.
        let half = vs.len() / 2;
        let (mut count, mut mid) = (0, 1);
        for (k, l) in levels.iter().enumerate() {
            count += l.len();
            if count >= half {
                mid = k.clamp(1, levels.len() - 2);
                break;
            }
        }
        let span = (levels.len() / 8).max(1);
        let lo = mid.saturating_sub(span).max(1);
        let hi = (mid + span).min(levels.len() - 2);
        let mid = (lo..=hi)
            .min_by_key(|&k| (levels[k].len(), k.abs_diff(mid)))
            .unwrap_or(mid);
        // The separator: the level's vertices that touch the far side.
        let mut sep = Vec::new();
        let mut near: Vec<usize> = levels[..mid].iter().flatten().copied().collect();
        for &v in &levels[mid] {
            if self.adj[v]
                .iter()
                .any(|&w| self.stamp[w] == s && self.level[w] == mid + 1)
            {
                sep.push(v);
            } else {
                near.push(v);
            }
        }
        let far: Vec<usize> = levels[mid + 1..].iter().flatten().copied().collect();
        for side in [near, far] {
            for c in self.components(&side) {
                self.dissect(c);
            }
        }
        self.minimum_degree(&sep);
    }

    /// Appends `vs` in minimum-degree order of the subgraph on them (the fill of each
    /// elimination counted).
    fn minimum_degree(&mut self, vs: &[usize]) {
        let s = self.mark(vs);
        let local: std::collections::HashMap<usize, usize> =
            vs.iter().enumerate().map(|(i, &v)| (v, i)).collect();
        let mut nb: Vec<std::collections::BTreeSet<usize>> = vs
            .iter()
            .map(|&v| {
                self.adj[v]
                    .iter()
                    .filter(|&&w| w != v && self.stamp[w] == s)
                    .map(|w| local[w])
                    .collect()
            })
            .collect();
        let mut done = vec![false; vs.len()];
        for _ in 0..vs.len() {
            let Some(v) = (0..vs.len())
                .filter(|&i| !done[i])
                .min_by_key(|&i| (nb[i].len(), i))
            else {
                break;
            };
            done[v] = true;
            self.order.push(vs[v]);
            let ns: Vec<usize> = nb[v].iter().copied().collect();
            for &a in &ns {
                nb[a].remove(&v);
                for &b in &ns {
                    if a != b {
                        nb[a].insert(b);
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn is_permutation(o: &[usize], n: usize) -> bool {
        let mut s = o.to_vec();
        s.sort_unstable();
        s == (0..n).collect::<Vec<_>>()
    }

    /// A grid of `k` chains along x and `k` along y, each of `m` vertices between crossings.
    #[allow(clippy::needless_range_loop)] // rows and columns of the crossings alike
    fn chain_grid(k: usize, m: usize) -> Vec<Vec<usize>> {
        let mut adj: Vec<Vec<usize>> = Vec::new();
        let vertex = |adj: &mut Vec<Vec<usize>>| {
            adj.push(Vec::new());
            adj.len() - 1
        };
        let link = |adj: &mut Vec<Vec<usize>>, a: usize, b: usize| {
            adj[a].push(b);
            adj[b].push(a);
        };
        let crossings: Vec<Vec<usize>> = (0..k)
            .map(|_| (0..k).map(|_| vertex(&mut adj)).collect())
            .collect();
        for i in 0..k {
            for j in 0..k - 1 {
                for (a, b) in [
                    (crossings[i][j], crossings[i][j + 1]),
                    (crossings[j][i], crossings[j + 1][i]),
                ] {
                    let mut prev = a;
                    for _ in 0..m {
                        let v = vertex(&mut adj);
                        link(&mut adj, prev, v);
                        prev = v;
                    }
                    link(&mut adj, prev, b);
                }
            }
        }
        adj
    }

    /// The fill (entries of the Cholesky factor's strict lower triangle) of eliminating in
    /// `order`.
    fn fill(adj: &[Vec<usize>], order: &[usize]) -> usize {
        let mut pos = vec![0; adj.len()];
        for (k, &v) in order.iter().enumerate() {
            pos[v] = k;
        }
        let mut nb: Vec<std::collections::BTreeSet<usize>> =
            adj.iter().map(|a| a.iter().copied().collect()).collect();
        let mut total = 0;
        for &v in order {
            let later: Vec<usize> = nb[v].iter().copied().filter(|&w| pos[w] > pos[v]).collect();
            total += later.len();
            for &a in &later {
                for &b in &later {
                    if a != b {
                        nb[a].insert(b);
                    }
                }
            }
        }
        total
    }

    #[test]
    fn every_vertex_once_on_paths_grids_cliques_and_pieces() {
        let path: Vec<Vec<usize>> = (0..500)
            .map(|i| {
                let mut v = Vec::new();
                if i > 0 {
                    v.push(i - 1);
                }
                if i < 499 {
                    v.push(i + 1);
                }
                v
            })
            .collect();
        assert!(is_permutation(&order(&path), 500));
        // A path: at most two entries a vertex (each separator vertex joins its sides' ends).
        assert!(fill(&path, &order(&path)) <= 2 * 500);
        let clique: Vec<Vec<usize>> = (0..100)
            .map(|i| (0..100).filter(|&j| j != i).collect())
            .collect();
        assert!(is_permutation(&order(&clique), 100));
        let grid = chain_grid(12, 5);
        assert!(is_permutation(&order(&grid), grid.len()));
        let mut pieces = chain_grid(6, 3);
        let offset = pieces.len();
        pieces.extend(
            chain_grid(5, 2)
                .into_iter()
                .map(|a| a.into_iter().map(|v| v + offset).collect()),
        );
        pieces.push(Vec::new());
        assert!(is_permutation(&order(&pieces), pieces.len()));
    }

    #[test]
    fn interiors_first_orders_every_vertex_once_and_fills_no_more_on_a_grid_of_chains() {
        // The crossings are the first k² vertices, the chains' vertices the interior.
        let (k, m) = (16, 6);
        let grid = chain_grid(k, m);
        let interior: Vec<bool> = (0..grid.len()).map(|v| v >= k * k).collect();
        let o = order_interiors_first(&grid, &interior);
        assert!(is_permutation(&o, grid.len()));
        // The pieces first: no crossing before the last interior vertex.
        let first_crossing = o.iter().position(|&v| v < k * k).expect("crossings");
        assert!(o[first_crossing..].iter().all(|&v| v < k * k));
        let (ours, plain) = (fill(&grid, &o), fill(&grid, &order(&grid)));
        assert!(ours <= plain, "interiors first {ours}, plain {plain}");
        // Nothing interior, everything interior, an empty graph: the plain order's cases.
        for mask in [vec![false; grid.len()], vec![true; grid.len()]] {
            assert!(is_permutation(
                &order_interiors_first(&grid, &mask),
                grid.len()
            ));
        }
        assert!(order_interiors_first(&[], &[]).is_empty());
    }

    #[test]
    fn a_grid_of_chains_fills_less_than_its_natural_order() {
        let grid = chain_grid(16, 6);
        let nd = fill(&grid, &order(&grid));
        let natural: Vec<usize> = (0..grid.len()).collect();
        let plain = fill(&grid, &natural);
        assert!(nd * 3 < plain, "nested dissection {nd}, natural {plain}");
        // Near-linear: a few entries a vertex.
        assert!(nd < 12 * grid.len(), "{nd} for {} vertices", grid.len());
    }
}
