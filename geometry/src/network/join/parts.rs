//! A network in parts put together (issue 34): where the parts' lonely nodes lie on each
//! other's curves ([`place_parts`]).

use super::grid::{cell_of, cells_around, Grid};
use super::{
    curves_at_nodes, face_angle, faces, line_angle, normals_fit, JoinParams, ALONGSIDE_DEG,
};
use crate::curve::{CurveKind, ANONYMOUS_NODE_BASE};
use crate::network::poisson::{CurvePositions, Positions};
use nalgebra::Vector3;
use std::collections::HashMap;

/// A node tagged by one curve only: its position and faces.
struct Lonely {
    node: u32,
    curve: usize,
    kind: CurveKind,
    x: Vector3<f64>,
    faces: Vec<Vector3<f64>>,
    /// Its curve's tangent there, where known.
    tangent: Option<Vector3<f64>>,
}

/// The lonely nodes of `net` (see the module docs), with the curve (position) that tags each.
fn lonely_nodes(net: &Positions) -> Vec<Lonely> {
    curves_at_nodes(net)
        .into_iter()
        .filter(|(node, curves)| *node < ANONYMOUS_NODE_BASE && curves.len() == 1)
        .filter_map(|(node, curves)| {
            let c = &net.curves[curves[0]];
            let i = c.nodes.iter().find(|x| x.1 == node)?.0;
            let x = *net.nodes.get(&node)?;
            (i < c.normals.len()).then(|| Lonely {
                node,
                curve: curves[0],
                kind: c.kind,
                x,
                faces: faces(c, i, 0.0),
                tangent: c.tangents.get(i).copied(),
            })
        })
        .collect()
}

/// The connected part of every curve of `net` (curves sharing a node are in one part).
fn parts(net: &Positions) -> Vec<usize> {
    let mut sets = crate::union_find::UnionFind::new(net.curves.len());
    let mut first: std::collections::HashMap<u32, usize> = Default::default();
    for (ci, c) in net.curves.iter().enumerate() {
        for &(_, node) in &c.nodes {
            let f = *first.entry(node).or_insert(ci);
            sets.union(f, ci);
        }
    }
    (0..net.curves.len()).map(|ci| sets.find(ci)).collect()
}

/// Whether a curve of `grid` passes within its reach of `l` moved by `t`, its normals fitting
/// ([`normals_fit`]).
fn meets(grid: &Grid, net: &Positions, l: &Lonely, t: &Vector3<f64>, normal_deg: f64) -> bool {
    let x = l.x + t;
    let mut near: std::collections::BTreeMap<usize, Vec<usize>> = Default::default();
    for (ci, j) in grid.around(&x) {
        if (net.curves[ci].points[j] - x).norm() <= grid.reach {
            near.entry(ci).or_default().push(j);
        }
    }
    near.into_iter().any(|(ci, js)| {
        let c = &net.curves[ci];
        let js = js.into_iter().filter(|&j| l.crosses(c, j));
        normals_fit(&l.faces, l.kind, c, js, normal_deg).is_some()
    })
}

impl Lonely {
    /// Whether curve `c` at its sample `j` would cross the node's curve, not run alongside it
    /// (their tangents more than [`ALONGSIDE_DEG`] apart as lines): the joins' own test, so
    /// that a part is placed only by incidences that can be joins. Parallel sections, which
    /// a translation lays one over another, meet nowhere.
    fn crosses(&self, c: &CurvePositions, j: usize) -> bool {
        match (&self.tangent, c.tangents.get(j)) {
            (Some(a), Some(b)) => line_angle(a, b) >= ALONGSIDE_DEG,
            _ => true,
        }
    }

    /// A crease node with two faces: its normals are judged against a crease curve's near
    /// samples together ([`normals_fit`]), not one sample at a time.
    fn two_faced_crease(&self) -> bool {
        self.kind == CurveKind::Crease && self.faces.len() >= 2
    }
}

/// A cell's incidences (indices into [`Votes::candidates`]) sorted by lonely node, and the
/// runs `(start, end)` of each node among them.
type Incidences = (Vec<u32>, Vec<(u32, u32)>);

/// The incidences of a part's lonely nodes (`ours`, on the placed curves) and of the placed
/// parts' (`theirs`, on the part's curves): every sample whose normals fit the node's, in a
/// grid by the translation that puts the node on it, so that a translation's score is a
/// look-up around it, not every lonely node against every curve.
struct Votes {
    /// `(lonely node: ours then theirs, sample, curve)` in the order the candidates are
    /// considered.
    candidates: Vec<(usize, usize, usize)>,
    /// The same by translation (`x − node` for ours, `node − x` for theirs), in cells a
    /// little wider than the reach, each cell's runs by node ([`Incidences`]: a node met
    /// once is skipped whole); crease nodes with two faces left out (they are judged by
    /// [`meets`], see [`Lonely::two_faced_crease`]).
    cells: HashMap<[i64; 3], Incidences>,
    cell: f64,
    reach: f64,
    /// Per lonely node, the last count that met it.
    stamp: std::cell::RefCell<(Vec<u32>, u32)>,
}

/// The samples of each curve whose normals fit each lonely node's ([`normals_fit`] one
/// sample at a time) and that cross its curve ([`Lonely::crosses`]), found once for every
/// part placed: translating parts turns no normal and no tangent.
struct Fits {
    normal_deg: f64,
    by: HashMap<(u32, usize), Vec<u32>>,
}

impl Fits {
    fn of(&mut self, net: &Positions, l: &Lonely, ci: usize) -> &[u32] {
        let normal_deg = self.normal_deg;
        self.by.entry((l.node, ci)).or_insert_with(|| {
            let c = &net.curves[ci];
            (0..c.points.len())
                // As `normals_fit` reads it: an angle that is not a number fits not.
                .filter(|&j| face_angle(&l.faces, &faces(c, j, 0.0)) <= normal_deg)
                .filter(|&j| l.crosses(c, j))
                .map(|j| j as u32)
                .collect()
        })
    }
}

impl Votes {
    #[allow(clippy::too_many_arguments)]
    fn of(
        net: &Positions,
        ours: &[&Lonely],
        theirs: &[&Lonely],
        in_placed: &impl Fn(usize) -> bool,
        in_part: &impl Fn(usize) -> bool,
        fits: &mut Fits,
        reach: f64,
    ) -> Votes {
        let mut v = Votes {
            candidates: Vec::new(),
            cells: HashMap::default(),
            // Wider by a hair: a translation within the reach of another by the exact test
            // below is always in the 27 cells around it, whatever the rounding.
            cell: reach * (1.0 + 1e-9),
            reach,
            stamp: std::cell::RefCell::new((vec![0; ours.len() + theirs.len()], 0)),
        };
        let sides = [(ours, true), (theirs, false)];
        let mut k0 = 0;
        for (side, is_ours) in sides {
            for (k, l) in side.iter().enumerate() {
                for (ci, c) in net.curves.iter().enumerate() {
                    let on = if is_ours { in_placed(ci) } else { in_part(ci) };
                    if !on {
                        continue;
                    }
                    for &j in fits.of(net, l, ci) {
                        let (j, x) = (j as usize, &c.points[j as usize]);
                        v.candidates.push((k0 + k, j, ci));
                        if l.two_faced_crease() {
                            continue;
                        }
                        let t = if is_ours { x - l.x } else { l.x - x };
                        if let Some(key) = v.key(&t) {
                            v.cells
                                .entry(key)
                                .or_default()
                                .0
                                .push((v.candidates.len() - 1) as u32);
                        }
                    }
                }
            }
            k0 += side.len();
        }
        for (list, runs) in v.cells.values_mut() {
            list.sort_by_key(|&c| v.candidates[c as usize].0);
            let mut start = 0;
            for i in 1..=list.len() {
                let node = |i: usize| v.candidates[list[i] as usize].0;
                if i == list.len() || node(i) != node(start) {
                    runs.push((start as u32, i as u32));
                    start = i;
                }
            }
        }
        v
    }

    fn key(&self, t: &Vector3<f64>) -> Option<[i64; 3]> {
        cell_of(t, self.cell)
    }

    /// The lonely nodes (crease nodes with two faces aside) that `t` puts within the reach
    /// of a sample they fit: ours moved by `t`, theirs by `−t` ([`meets`]'s test).
    fn count(
        &self,
        net: &Positions,
        ours: &[&Lonely],
        theirs: &[&Lonely],
        t: &Vector3<f64>,
    ) -> usize {
        let Some(key) = self.key(t) else { return 0 };
        let mut stamp = self.stamp.borrow_mut();
        let (seen, query) = &mut *stamp;
        *query += 1;
        let mut met = 0;
        for c in cells_around(key) {
            let Some((list, runs)) = self.cells.get(&c) else {
                continue;
            };
            for &(start, end) in runs {
                let k = self.candidates[list[start as usize] as usize].0;
                if seen[k] == *query {
                    continue;
                }
                let x = if k < ours.len() {
                    ours[k].x + t
                } else {
                    theirs[k - ours.len()].x + (-t)
                };
                let hit = list[start as usize..end as usize].iter().any(|&c| {
                    let (_, j, ci) = self.candidates[c as usize];
                    (net.curves[ci].points[j] - x).norm() <= self.reach
                });
                if hit {
                    seen[k] = *query;
                    met += 1;
                }
            }
        }
        met
    }
}

/// How much better the placement of a part scores than any placement away from it: at least
/// this many times the incidences ([`place_parts`]).
pub const DISTINCT_RATIO: usize = 2;

/// A network in parts (a crossing left untagged can cut it) has no relative placement of its
/// parts: the Poisson solve gives each its own gauge. The orientations are absolute, so each
/// part's shape is right and only its translation is unknown. This moves each part, greedily
/// from the largest, by the translation that puts the most of its lonely nodes on the placed
/// parts' curves and the placed parts' lonely nodes on its curves (at least two such
/// incidences, and no translation farther than twice the join distance with more than half
/// as many, [`DISTINCT_RATIO`]: one incidence leaves the part free to slide along a curve,
/// and a part that fits nearly as well elsewhere is not placed by chance). An incidence is
/// what a join could be: normals that fit, and a curve that crosses the node's, not one
/// alongside it. Candidates come from each incidence along every sample of the curve; each
/// is scored by the incidences around it in a grid of them by translation. Returns the parts
/// moved; the joins ([`find_joins`](super::find_joins)) are then found in the moved network.
pub fn place_parts(net: &mut Positions, p: &JoinParams) -> usize {
    placement(net, p).len()
}

/// The parts of `net` (each the scan indices of its curves, sorted; the parts in order):
/// what a [`placement`] was found for.
pub(crate) fn partition(net: &Positions) -> Vec<Vec<usize>> {
    let part = parts(net);
    let mut by: std::collections::BTreeMap<usize, Vec<usize>> = Default::default();
    for (ci, c) in net.curves.iter().enumerate() {
        by.entry(part[ci]).or_default().push(c.index);
    }
    let mut out: Vec<Vec<usize>> = by
        .into_values()
        .map(|mut v| {
            v.sort_unstable();
            v
        })
        .collect();
    out.sort();
    out
}

/// A part moved: the scan indices of its curves and the translation, m.
pub(crate) type Move = (Vec<usize>, Vector3<f64>);

/// Moves the parts of `net` as [`place_parts`] does, and returns the moves, in order, for
/// [`apply_moves`].
pub(crate) fn placement(net: &mut Positions, p: &JoinParams) -> Vec<Move> {
    let reach = p.distance_m;
    let mut moves = Vec::new();
    if net.components < 2 || reach <= 0.0 || !reach.is_finite() {
        return moves;
    }
    let part = parts(net);
    let mut roots: Vec<usize> = part.clone();
    roots.sort_unstable();
    roots.dedup();
    if roots.len() < 2 {
        return moves;
    }
    let size = |r: usize| -> usize {
        net.curves
            .iter()
            .enumerate()
            .filter(|(ci, _)| part[*ci] == r)
            .map(|(_, c)| c.points.len())
            .sum()
    };
    roots.sort_by_key(|&r| std::cmp::Reverse(size(r)));
    let mut placed = vec![roots[0]];
    let mut fits = Fits {
        normal_deg: p.normal_deg,
        by: HashMap::new(),
    };
    loop {
        let lonely = lonely_nodes(net);
        let mut best: Option<(usize, Vector3<f64>, usize)> = None;
        for &r in roots.iter().filter(|r| !placed.contains(r)) {
            let in_p = |ci: usize| part[ci] == r;
            let in_placed = |ci: usize| placed.contains(&part[ci]);
            // Incidences: a lonely node of the part on a placed curve (t = curve − node), and
            // a lonely node of a placed part on the part's curves (t = node − curve).
            let ours: Vec<&Lonely> = lonely.iter().filter(|l| in_p(l.curve)).collect();
            let theirs: Vec<&Lonely> = lonely.iter().filter(|l| in_placed(l.curve)).collect();
            if ours.len() + theirs.len() < 2 {
                continue;
            }
            // The samples by position, for the crease nodes with two faces (`meets`) only.
            let crease = |side: &[&Lonely]| side.iter().any(|l| l.two_faced_crease());
            let g_placed = crease(&ours).then(|| Grid::of(net, reach, in_placed));
            let g_part = crease(&theirs).then(|| Grid::of(net, reach, in_p));
            // Each lonely node's incidences (the samples its normals fit, on the curves it
            // may meet) by translation, for counting; a crease node with two faces is judged
            // by `meets`, on a crease curve's near samples at once.
            let votes = Votes::of(net, &ours, &theirs, &in_placed, &in_p, &mut fits, reach);
            let score = |t: &Vector3<f64>| -> usize {
                votes.count(net, &ours, &theirs, t)
                    + g_placed.as_ref().map_or(0, |g| {
                        ours.iter()
                            .filter(|l| l.two_faced_crease())
                            .filter(|l| meets(g, net, l, t, p.normal_deg))
                            .count()
                    })
                    + g_part.as_ref().map_or(0, |g| {
                        theirs
                            .iter()
                            .filter(|l| l.two_faced_crease())
                            .filter(|l| meets(g, net, l, &-t, p.normal_deg))
                            .count()
                    })
            };
            let mut top: Vec<(usize, Vector3<f64>)> = Vec::new();
            let mut consider = |t: Vector3<f64>| {
                let s = score(&t);
                if s >= 2 {
                    top.push((s, t));
                }
            };
            for &(k, j, ci) in &votes.candidates {
                let x = net.curves[ci].points[j];
                if k < ours.len() {
                    consider(x - ours[k].x);
                } else {
                    consider(theirs[k - ours.len()].x - x);
                }
            }
            let Some(&(s, t)) = top.iter().max_by_key(|x| x.0) else {
                continue;
            };
            // Distinct: no translation away from this one (beyond twice the reach) meets more
            // than half as many. Where many do, the part fits as well in other places: parallel
            // sections of a surface, whose lonely nodes lie on curves not yet scanned, meet
            // each other's curves by chance wherever they are laid.
            let runner = top
                .iter()
                .filter(|x| (x.1 - t).norm() > 2.0 * reach)
                .map(|x| x.0)
                .max()
                .unwrap_or(0);
            if DISTINCT_RATIO * runner > s {
                continue;
            }
            // The mean of the best translations near it (they spread along the curves within
            // the reach).
            let near: Vec<&Vector3<f64>> = top
                .iter()
                .filter(|x| x.0 == s && (x.1 - t).norm() <= 2.0 * reach)
                .map(|x| &x.1)
                .collect();
            let t = near.iter().copied().sum::<Vector3<f64>>() / near.len() as f64;
            if best.as_ref().is_none_or(|b| s > b.2) {
                best = Some((r, t, s));
            }
        }
        let Some((r, t, _)) = best else { break };
        let mut curves: Vec<usize> = net
            .curves
            .iter()
            .enumerate()
            .filter(|(ci, _)| part[*ci] == r)
            .map(|(_, c)| c.index)
            .collect();
        curves.sort_unstable();
        let m = (curves, t);
        apply_moves(net, std::slice::from_ref(&m));
        moves.push(m);
        placed.push(r);
    }
    moves
}

/// Each part of `moves` (by its curves' scan indices) moved by its translation: its curves'
/// points and their nodes.
pub(crate) fn apply_moves(net: &mut Positions, moves: &[Move]) {
    for (curves, t) in moves {
        let mut nodes_moved = std::collections::BTreeSet::new();
        for c in net.curves.iter_mut() {
            if curves.binary_search(&c.index).is_ok() {
                c.points.iter_mut().for_each(|x| *x += t);
                nodes_moved.extend(c.nodes.iter().map(|x| x.1));
            }
        }
        for n in nodes_moved {
            if let Some(x) = net.nodes.get_mut(&n) {
                *x += t;
            }
        }
    }
}
