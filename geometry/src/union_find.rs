//! Connected components by union-find (path halving; the lowest index is each set's root,
//! so a component's root is its lowest unknown).
//!
//! ```
//! use sfs_geometry::union_find::UnionFind;
//! let mut u = UnionFind::new(4);
//! assert!(u.union(3, 1));
//! assert!(!u.union(1, 3));
//! assert_eq!(u.find(3), 1);
//! assert_eq!(u.roots().collect::<Vec<_>>(), [0, 1, 2]);
//! ```

/// Disjoint sets over `0..n`.
#[derive(Debug, Clone)]
pub struct UnionFind {
    parent: Vec<usize>,
}

impl UnionFind {
    pub fn new(n: usize) -> Self {
        UnionFind {
            parent: (0..n).collect(),
        }
    }

    /// The root of `x`'s set (the lowest index in it).
    pub fn find(&mut self, mut x: usize) -> usize {
        let p = &mut self.parent;
        while p[x] != x {
            p[x] = p[p[x]];
            x = p[x];
        }
        x
    }

    /// Joins the sets of `a` and `b`; whether they were apart.
    pub fn union(&mut self, a: usize, b: usize) -> bool {
        let (ra, rb) = (self.find(a), self.find(b));
        if ra != rb {
            self.parent[ra.max(rb)] = ra.min(rb);
        }
        ra != rb
    }

    /// The root of every set, in increasing order.
    pub fn roots(&mut self) -> impl Iterator<Item = usize> + '_ {
        (0..self.parent.len()).filter(move |&x| self.parent[x] == x)
    }
}
