//! Curve samples in cells the size of the join distance: what lies near a point is in the 27
//! cells around it, so the joins' searches are linear in the samples.

use crate::network::poisson::Positions;
use nalgebra::Vector3;

/// The samples `(curve position, sample)` of some curves of a network, by cell.
pub(super) struct Grid {
    /// The cells' size, m.
    pub(super) reach: f64,
    cells: std::collections::HashMap<[i64; 3], Vec<(usize, usize)>>,
}

/// The cell of size `size` that holds `x` (none for a point not finite, or too far).
pub(super) fn cell_of(x: &Vector3<f64>, size: f64) -> Option<[i64; 3]> {
    let k = x / size;
    k.iter()
        .all(|v| v.is_finite() && v.abs() < 1e12)
        .then(|| [k.x.floor() as i64, k.y.floor() as i64, k.z.floor() as i64])
}

/// The 27 cells around cell `k`, itself included: all that lies within one cell's size of a
/// point in `k` is in them.
pub(super) fn cells_around(k: [i64; 3]) -> impl Iterator<Item = [i64; 3]> {
    (-1..=1).flat_map(move |dx| {
        (-1..=1).flat_map(move |dy| (-1..=1).map(move |dz| [k[0] + dx, k[1] + dy, k[2] + dz]))
    })
}

impl Grid {
    fn key(&self, x: &Vector3<f64>) -> Option<[i64; 3]> {
        cell_of(x, self.reach)
    }

    /// The samples of the curves `take` of `net`, in cells of size `reach`.
    pub(super) fn of(net: &Positions, reach: f64, take: impl Fn(usize) -> bool) -> Grid {
        let mut g = Grid {
            reach,
            cells: Default::default(),
        };
        for (ci, c) in net.curves.iter().enumerate().filter(|(ci, _)| take(*ci)) {
            for (j, x) in c.points.iter().enumerate() {
                if let Some(k) = g.key(x) {
                    g.cells.entry(k).or_default().push((ci, j));
                }
            }
        }
        g
    }

    /// The samples in the 27 cells around `x` (none for a point not finite).
    pub(super) fn around(&self, x: &Vector3<f64>) -> impl Iterator<Item = (usize, usize)> + '_ {
        self.key(x)
            .into_iter()
            .flat_map(cells_around)
            .filter_map(|c| self.cells.get(&c))
            .flatten()
            .copied()
    }
}
