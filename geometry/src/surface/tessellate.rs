//! Tessellation of one cycle (Stanko et al. 2016, §3.3): the closed boundary polyline is
//! projected onto the plane of its average position and average normal and triangulated there
//! by a constrained Delaunay triangulation (spade) of the boundary and a triangular lattice of
//! the target edge length inside it, refined where the lattice meets the boundary. The
//! boundary vertices are kept exactly (the constraint edges are never split), so patches that
//! share a segment share its vertices and the mesh is watertight along the curves.
//!
//! The projection is not always injective (a patch that wraps around more than a half-space
//! overlaps itself in the plane). That is detected — the projected boundary must be a simple
//! polygon turning counter-clockwise around the normal — and so is a projection that shrinks
//! part of the boundary to less than half its length, or sees the surface at a boundary point
//! more than 60° from face-on (its triangles would lift to slivers):
//! the fallback develops the boundary into the plane from its lengths and its turning in the
//! tangent planes of its normals, and the last resort maps it by arc length onto a circle (a
//! convex, always simple polygon). Never a folded triangulation. See [`Embedding`].
//!
//! ```
//! use nalgebra::Vector3;
//! use sfs_geometry::surface::tessellate::{tessellate, Embedding};
//! // A unit square at z = 1 seen from +z, boundary sampled every 0.25.
//! let mut b = Vec::new();
//! for k in 0..16 {
//!     let t = (k % 4) as f64 * 0.25;
//!     b.push(match k / 4 {
//!         0 => Vector3::new(t, 0.0, 1.0),
//!         1 => Vector3::new(1.0, t, 1.0),
//!         2 => Vector3::new(1.0 - t, 1.0, 1.0),
//!         _ => Vector3::new(0.0, 1.0 - t, 1.0),
//!     });
//! }
//! let m = tessellate(&b, &vec![Vector3::z(); 16], 0.25).unwrap();
//! assert_eq!(m.boundary, 16);
//! assert_eq!(m.embedding, Embedding::Projection);
//! let area: f64 = m.triangles.iter().map(|t| m.area(t)).sum();
//! assert!((area - 1.0).abs() < 1e-9);
//! ```

use nalgebra::Vector3;
use spade::{ConstrainedDelaunayTriangulation, Point2, RefinementParameters, Triangulation};

/// The triangulation of one cycle in its plane.
#[derive(Debug, Clone, PartialEq)]
pub struct PatchMesh {
    /// Planar positions: the first `boundary` are the cycle's points in order, then the
    /// points the refinement added.
    pub uv: Vec<[f64; 2]>,
    pub boundary: usize,
    /// Counter-clockwise in the plane (seen from the normal's side).
    pub triangles: Vec<[usize; 3]>,
    /// How the boundary was laid out in the plane.
    pub embedding: Embedding,
    /// The refinement stopped at its vertex budget (the triangles are valid but coarser).
    pub incomplete: bool,
}

impl PatchMesh {
    /// Signed area of a triangle in the plane (positive: counter-clockwise).
    pub fn area(&self, t: &[usize; 3]) -> f64 {
        let [a, b, c] = [self.uv[t[0]], self.uv[t[1]], self.uv[t[2]]];
        0.5 * ((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]))
    }
}

/// Why a cycle cannot be tessellated.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TessellateError {
    #[error("the cycle has {0} points; a patch needs at least 3")]
    TooFewPoints(usize),
    #[error("the cycle has a non-finite point or normal")]
    NonFinite,
    #[error("points {0} and {1} of the cycle coincide")]
    Coincident(usize, usize),
    #[error("the triangulation failed: {0}")]
    Spade(String),
    #[error("the triangulation has a degenerate triangle ({0:?})")]
    Degenerate([usize; 3]),
}

/// How a cycle was laid out in the plane.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Embedding {
    /// Orthogonal projection on the plane of the average position and normal (the paper's).
    Projection,
    /// The boundary developed into the plane: its edge lengths and its turning angles in the
    /// tangent planes of its normals (the holonomy spread evenly, the closure gap by arc
    /// length). Used when the projection shrinks part of the boundary below
    /// [`MAX_SHRINK`] of its length or sees a boundary normal more than 60° from the plane's
    /// normal (a strongly curved patch, e.g. half a torus' tube, whose projected triangles
    /// would lift to slivers), or is not injective.
    Development,
    /// The boundary by arc length on a circle: the last resort, always injective.
    Circle,
}

/// Projected edges shorter than this fraction of their length, or boundary normals tilted from
/// the plane's normal by more than its arc-cosine (60°), reject the projection.
pub const MAX_SHRINK: f64 = 0.5;

/// Triangulates the closed polyline `boundary` (last point not repeated) with unit surface
/// `normals` at its points, with edges of about `target_edge` inside.
pub fn tessellate(
    boundary: &[Vector3<f64>],
    normals: &[Vector3<f64>],
    target_edge: f64,
) -> Result<PatchMesh, TessellateError> {
    let n = boundary.len();
    if n < 3 {
        return Err(TessellateError::TooFewPoints(n));
    }
    let finite = boundary
        .iter()
        .chain(normals)
        .all(|p| p.iter().all(|x| x.is_finite()));
    if !finite || normals.len() != n || !target_edge.is_finite() || target_edge <= 0.0 {
        return Err(TessellateError::NonFinite);
    }
    let c = boundary.iter().sum::<Vector3<f64>>() / n as f64;
    let lens: Vec<f64> = (0..n)
        .map(|i| (boundary[(i + 1) % n] - boundary[i]).norm())
        .collect();
    let length: f64 = lens.iter().sum();
    if let Some(i) = lens.iter().position(|&l| l <= 1e-12 * length) {
        return Err(TessellateError::Coincident(i, (i + 1) % n));
    }
    // The plane: the average normal (the paper's), else the polygon's vector area.
    let area = super::cycles::vector_area(boundary);
    let nrm = normals
        .iter()
        .sum::<Vector3<f64>>()
        .try_normalize(1e-12)
        .or_else(|| area.try_normalize(1e-300))
        .ok_or(TessellateError::NonFinite)?;
    let e1 = if nrm.x.abs() < 0.9 {
        Vector3::x()
    } else {
        Vector3::y()
    };
    let e1 = (e1 - nrm * nrm.dot(&e1)).normalize();
    let e2 = nrm.cross(&e1);
    let projected: Vec<[f64; 2]> = boundary
        .iter()
        .map(|p| [(p - c).dot(&e1), (p - c).dot(&e2)])
        .collect();
    let shrink = (0..n)
        .map(|i| {
            let (a, b) = (projected[i], projected[(i + 1) % n]);
            ((b[0] - a[0]).powi(2) + (b[1] - a[1]).powi(2)).sqrt() / lens[i]
        })
        .fold(f64::MAX, f64::min);
    // The surface at a boundary point shrinks by the cosine of its normal's tilt from the
    // plane's normal: a patch seen edge-on somewhere (half a torus' tube seen from outside)
    // projects its triangles there to slivers, even when its boundary's edges do not shrink.
    let steepest = normals.iter().map(|m| m.dot(&nrm)).fold(f64::MAX, f64::min);
    if shrink >= MAX_SHRINK && steepest >= MAX_SHRINK && is_simple_ccw(&projected) {
        if let Ok(m) = triangulate(&projected, target_edge, Embedding::Projection) {
            return Ok(m);
        }
    }
    let developed = develop(boundary, normals, &lens);
    if is_simple_ccw(&developed) {
        if let Ok(m) = triangulate(&developed, target_edge, Embedding::Development) {
            return Ok(m);
        }
    }
    if is_simple_ccw(&projected) {
        if let Ok(m) = triangulate(&projected, target_edge, Embedding::Projection) {
            return Ok(m);
        }
    }
    // Last resort: the boundary by arc length onto a circle of the same length.
    let r = length / std::f64::consts::TAU;
    let mut s = 0.0;
    let mut circle = Vec::with_capacity(n);
    for l in &lens {
        let a = s / r;
        circle.push([r * a.cos(), r * a.sin()]);
        s += l;
    }
    triangulate(&circle, target_edge, Embedding::Circle)
}

/// The boundary developed into the plane (see [`Embedding::Development`]).
fn develop(b: &[Vector3<f64>], normals: &[Vector3<f64>], lens: &[f64]) -> Vec<[f64; 2]> {
    let n = b.len();
    let mut turn: Vec<f64> = (0..n)
        .map(|i| {
            let nn = normals[i];
            let a = b[i] - b[(i + n - 1) % n];
            let c = b[(i + 1) % n] - b[i];
            let (a, c) = (a - nn * nn.dot(&a), c - nn * nn.dot(&c));
            nn.dot(&a.cross(&c)).atan2(a.dot(&c))
        })
        .collect();
    let total: f64 = turn.iter().sum();
    // A disk's boundary turns once around: spread what the surface's curvature took (or
    // added) evenly over the corners.
    let fix = (std::f64::consts::TAU - total) / n as f64;
    for t in &mut turn {
        *t += fix;
    }
    let length: f64 = lens.iter().sum();
    let mut out = Vec::with_capacity(n + 1);
    let (mut x, mut y, mut phi) = (0.0, 0.0, 0.0);
    out.push([x, y]);
    for i in 0..n {
        if i > 0 {
            phi += turn[i];
        }
        x += lens[i] * phi.cos();
        y += lens[i] * phi.sin();
        out.push([x, y]);
    }
    let gap = out[n];
    let mut s = 0.0;
    for (i, p) in out.iter_mut().enumerate().take(n) {
        let f = s / length;
        p[0] -= gap[0] * f;
        p[1] -= gap[1] * f;
        s += lens[i];
    }
    out.truncate(n);
    out
}

fn triangulate(
    poly: &[[f64; 2]],
    target_edge: f64,
    embedding: Embedding,
) -> Result<PatchMesh, TessellateError> {
    let n = poly.len();
    let mut cdt: ConstrainedDelaunayTriangulation<Point2<f64>> =
        ConstrainedDelaunayTriangulation::new();
    let mut handles = Vec::with_capacity(n);
    for (i, p) in poly.iter().enumerate() {
        let h = cdt
            .insert(Point2::new(p[0], p[1]))
            .map_err(|e| TessellateError::Spade(format!("{e:?}")))?;
        if h.index() != i {
            return Err(TessellateError::Coincident(h.index(), i));
        }
        handles.push(h);
    }
    for i in 0..n {
        let (a, b) = (handles[i], handles[(i + 1) % n]);
        if !cdt.can_add_constraint(a, b) {
            return Err(TessellateError::Spade(format!(
                "boundary edge {i} crosses another"
            )));
        }
        cdt.add_constraint(a, b);
    }
    // Seed the interior with a triangular lattice of the target edge (bulk insertion is far
    // cheaper than refining from the boundary alone), then let the refinement fix whatever
    // the lattice left too big or too thin near the boundary.
    for p in interior_lattice(poly, target_edge) {
        cdt.insert(Point2::new(p[0], p[1]))
            .map_err(|e| TessellateError::Spade(format!("{e:?}")))?;
    }
    // Equilateral triangles of the target edge; a budget of four times the expected count.
    let area: f64 = 0.5
        * (0..n)
            .map(|i| {
                let (p, q) = (poly[i], poly[(i + 1) % n]);
                p[0] * q[1] - p[1] * q[0]
            })
            .sum::<f64>();
    let tri = 3f64.sqrt() / 4.0 * target_edge * target_edge;
    let budget = (4.0 * area.abs() / tri) as usize + 4 * n + 100;
    let result = cdt.refine(
        RefinementParameters::<f64>::new()
            .with_max_allowed_area(tri * 1.5)
            .keep_constraint_edges()
            .exclude_outer_faces(true)
            .with_max_additional_vertices(budget),
    );
    let excluded: std::collections::HashSet<_> = result.excluded_faces.iter().copied().collect();
    let uv: Vec<[f64; 2]> = cdt
        .vertices()
        .map(|v| {
            let p = v.position();
            [p.x, p.y]
        })
        .collect();
    let mut triangles = Vec::new();
    for f in cdt.inner_faces() {
        if excluded.contains(&f.fix()) {
            continue;
        }
        let [a, b, c] = f.vertices().map(|v| v.fix().index());
        triangles.push([a, b, c]);
    }
    let mut m = PatchMesh {
        uv,
        boundary: n,
        triangles,
        embedding,
        incomplete: !result.refinement_complete,
    };
    // Drop vertices no triangle uses (cannot happen inside a closed constraint loop, but keep
    // the mesh honest), keeping the boundary first.
    let mut used = vec![false; m.uv.len()];
    for t in &m.triangles {
        for &i in t {
            used[i] = true;
        }
    }
    if used[..n].iter().any(|u| !u) {
        return Err(TessellateError::Spade(
            "a boundary point is in no triangle".into(),
        ));
    }
    let mut map = vec![usize::MAX; m.uv.len()];
    let mut uv = Vec::with_capacity(m.uv.len());
    for i in 0..m.uv.len() {
        if used[i] {
            map[i] = uv.len();
            uv.push(m.uv[i]);
        }
    }
    m.uv = uv;
    for t in &mut m.triangles {
        *t = t.map(|i| map[i]);
    }
    let scale = target_edge * target_edge;
    if let Some(t) = m.triangles.iter().find(|t| m.area(t) <= 1e-12 * scale) {
        return Err(TessellateError::Degenerate(*t));
    }
    Ok(m)
}

/// Points of a triangular lattice of spacing `edge` strictly inside the closed polygon and at
/// least [`LATTICE_CLEARANCE`]` · edge` from its boundary, row by row (scanlines: each row's
/// crossings with the boundary, paired by the even-odd rule; the clearance from a grid of the
/// boundary's edges), so the cost is linear in the points and the boundary.
fn interior_lattice(poly: &[[f64; 2]], edge: f64) -> Vec<[f64; 2]> {
    let n = poly.len();
    let (mut lo, mut hi) = ([f64::MAX; 2], [f64::MIN; 2]);
    for p in poly {
        for k in 0..2 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    let dy = edge * 3f64.sqrt() / 2.0;
    let rows = ((hi[1] - lo[1]) / dy).floor() as usize + 1;
    if rows >= 1 << 24 {
        return Vec::new();
    }
    let row_y =
        |j: usize| lo[1] + (j as f64 + 0.5) * dy - 0.5 * (rows as f64 * dy - (hi[1] - lo[1]));
    let mut crossings: Vec<Vec<f64>> = vec![Vec::new(); rows];
    for i in 0..n {
        let (a, b) = (poly[i], poly[(i + 1) % n]);
        let (p, q) = if a[1] <= b[1] { (a, b) } else { (b, a) };
        // Rows with p.y <= y < q.y (half-open: a vertex on a row counts once).
        let first = (((p[1] - row_y(0)) / dy).ceil().max(0.0)) as usize;
        let mut j = first;
        while j < rows && row_y(j) < q[1] {
            let y = row_y(j);
            if y >= p[1] {
                crossings[j].push(p[0] + (y - p[1]) / (q[1] - p[1]) * (q[0] - p[0]));
            }
            j += 1;
        }
    }
    let clearance = LATTICE_CLEARANCE * edge;
    let cell = clearance;
    let key = |x: f64| (x / cell).floor() as i64;
    let mut grid: std::collections::HashMap<(i64, i64), Vec<usize>> = Default::default();
    for i in 0..n {
        let (a, b) = (poly[i], poly[(i + 1) % n]);
        for x in key(a[0].min(b[0])) - 1..=key(a[0].max(b[0])) + 1 {
            for y in key(a[1].min(b[1])) - 1..=key(a[1].max(b[1])) + 1 {
                grid.entry((x, y)).or_default().push(i);
            }
        }
    }
    let near_boundary = |p: [f64; 2]| {
        grid.get(&(key(p[0]), key(p[1]))).is_some_and(|list| {
            list.iter().any(|&i| {
                let (a, b) = (poly[i], poly[(i + 1) % n]);
                let (ab, ap) = ([b[0] - a[0], b[1] - a[1]], [p[0] - a[0], p[1] - a[1]]);
                let l2 = ab[0] * ab[0] + ab[1] * ab[1];
                let t = if l2 > 0.0 {
                    ((ap[0] * ab[0] + ap[1] * ab[1]) / l2).clamp(0.0, 1.0)
                } else {
                    0.0
                };
                let d = [ap[0] - t * ab[0], ap[1] - t * ab[1]];
                d[0] * d[0] + d[1] * d[1] < clearance * clearance
            })
        })
    };
    let mut out = Vec::new();
    for (j, xs) in crossings.iter_mut().enumerate() {
        xs.sort_unstable_by(f64::total_cmp);
        let y = row_y(j);
        let offset = if j % 2 == 0 { 0.0 } else { 0.5 * edge };
        for pair in xs.chunks_exact(2) {
            let k0 = ((pair[0] - lo[0] - offset) / edge).ceil() as i64;
            let k1 = ((pair[1] - lo[0] - offset) / edge).floor() as i64;
            for k in k0..=k1 {
                let p = [lo[0] + offset + k as f64 * edge, y];
                if p[0] > pair[0] && p[0] < pair[1] && !near_boundary(p) {
                    out.push(p);
                }
            }
        }
    }
    out
}

/// Lattice points closer than this many target edges to the boundary are left out.
pub const LATTICE_CLEARANCE: f64 = 0.6;

/// Whether the closed polygon is simple (no two non-adjacent edges meet) and turns
/// counter-clockwise. Edges are bucketed in a uniform grid, so the cost is linear in the
/// number of edges for evenly sampled boundaries.
pub fn is_simple_ccw(p: &[[f64; 2]]) -> bool {
    let n = p.len();
    if n < 3 {
        return false;
    }
    let signed: f64 = (0..n)
        .map(|i| {
            let (a, b) = (p[i], p[(i + 1) % n]);
            a[0] * b[1] - a[1] * b[0]
        })
        .sum();
    if signed <= 0.0 {
        return false;
    }
    let mean_len: f64 = (0..n)
        .map(|i| {
            let (a, b) = (p[i], p[(i + 1) % n]);
            ((b[0] - a[0]).powi(2) + (b[1] - a[1]).powi(2)).sqrt()
        })
        .sum::<f64>()
        / n as f64;
    let cell = mean_len.max(f64::MIN_POSITIVE);
    let key = |x: f64| (x / cell).floor() as i64;
    let mut grid: std::collections::HashMap<(i64, i64), Vec<usize>> = Default::default();
    for i in 0..n {
        let (a, b) = (p[i], p[(i + 1) % n]);
        let (x0, x1) = (key(a[0].min(b[0])), key(a[0].max(b[0])));
        let (y0, y1) = (key(a[1].min(b[1])), key(a[1].max(b[1])));
        if (x1 - x0 + 1) * (y1 - y0 + 1) > 4 * n as i64 + 16 {
            return false; // an edge far longer than the others: not an even sampling
        }
        for x in x0..=x1 {
            for y in y0..=y1 {
                grid.entry((x, y)).or_default().push(i);
            }
        }
    }
    for list in grid.values() {
        for (k, &i) in list.iter().enumerate() {
            for &j in &list[k + 1..] {
                let adjacent = (i + 1) % n == j || (j + 1) % n == i;
                if !adjacent && segments_meet(p[i], p[(i + 1) % n], p[j], p[(j + 1) % n]) {
                    return false;
                }
            }
        }
    }
    true
}

fn orient(a: [f64; 2], b: [f64; 2], c: [f64; 2]) -> f64 {
    (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
}

/// Closed segments `ab` and `cd` intersect (touching counts).
fn segments_meet(a: [f64; 2], b: [f64; 2], c: [f64; 2], d: [f64; 2]) -> bool {
    let (d1, d2) = (orient(c, d, a), orient(c, d, b));
    let (d3, d4) = (orient(a, b, c), orient(a, b, d));
    if ((d1 > 0.0) != (d2 > 0.0))
        && ((d3 > 0.0) != (d4 > 0.0))
        && d1 != 0.0
        && d2 != 0.0
        && d3 != 0.0
        && d4 != 0.0
    {
        return true;
    }
    let on = |p: [f64; 2], q: [f64; 2], r: [f64; 2]| {
        orient(p, q, r) == 0.0
            && r[0] >= p[0].min(q[0])
            && r[0] <= p[0].max(q[0])
            && r[1] >= p[1].min(q[1])
            && r[1] <= p[1].max(q[1])
    };
    on(c, d, a) || on(c, d, b) || on(a, b, c) || on(a, b, d)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn check(m: &PatchMesh) {
        assert!(m.triangles.iter().all(|t| m.area(t) > 0.0));
        // Every boundary edge is in exactly one triangle, in the boundary's direction.
        let n = m.boundary;
        for i in 0..n {
            let (a, b) = (i, (i + 1) % n);
            let count = m
                .triangles
                .iter()
                .filter(|t| (0..3).any(|k| t[k] == a && t[(k + 1) % 3] == b))
                .count();
            assert_eq!(count, 1, "boundary edge {a}-{b}");
        }
    }

    #[test]
    fn a_disk_keeps_its_boundary_and_reaches_the_target_edge() {
        let n = 64;
        let b: Vec<Vector3<f64>> = (0..n)
            .map(|i| {
                let a = i as f64 / n as f64 * std::f64::consts::TAU;
                Vector3::new(a.cos(), a.sin(), 0.1 * (3.0 * a).sin())
            })
            .collect();
        let h = std::f64::consts::TAU / n as f64;
        let m = tessellate(&b, &vec![Vector3::z(); n], h).unwrap();
        check(&m);
        assert!(m.embedding == Embedding::Projection && !m.incomplete);
        assert_eq!(m.boundary, n);
        for (i, p) in b.iter().enumerate() {
            let d = ((m.uv[i][0] - p.x).powi(2) + (m.uv[i][1] - p.y).powi(2)).sqrt();
            assert!(d < 0.2, "boundary point {i} kept in order");
        }
        // About the number of equilateral triangles of side h in the disk.
        let expect = std::f64::consts::PI / (3f64.sqrt() / 4.0 * h * h);
        let got = m.triangles.len() as f64;
        assert!(
            got > 0.4 * expect && got < 2.5 * expect,
            "{got} vs {expect}"
        );
    }

    #[test]
    fn a_boundary_that_overlaps_itself_in_the_plane_falls_back_to_a_circle() {
        // Three quarters of a cylinder's cross-section extruded: seen along the average
        // normal the boundary folds over itself.
        let mut b = Vec::new();
        let k = 24;
        for i in 0..=k {
            let a = -0.75 * std::f64::consts::PI + 1.5 * std::f64::consts::PI * i as f64 / k as f64;
            b.push(Vector3::new(a.sin(), 0.0, a.cos()));
        }
        for i in (0..=k).rev() {
            let a = -0.75 * std::f64::consts::PI + 1.5 * std::f64::consts::PI * i as f64 / k as f64;
            b.push(Vector3::new(a.sin(), 0.5, a.cos()));
        }
        // Outward normals: (sin, 0, cos); their sum points to +z.
        let normals: Vec<Vector3<f64>> = b.iter().map(|p| Vector3::new(p.x, 0.0, p.z)).collect();
        let m = tessellate(&b, &normals, 0.1).unwrap();
        assert_eq!(m.embedding, Embedding::Development);
        check(&m);
        // Developed, the boundary keeps its lengths: a 0.5 × 1.5π rectangle.
        let area: f64 = m.triangles.iter().map(|t| m.area(t)).sum();
        assert!((area - 0.75 * std::f64::consts::PI).abs() < 0.05, "{area}");
    }

    #[test]
    fn the_lattice_is_inside_clear_of_the_boundary_and_as_dense_as_the_target() {
        // An L-shaped polygon (concave), sampled every 0.1, with edge 0.05.
        let corners = [
            [0.0, 0.0],
            [2.0, 0.0],
            [2.0, 1.0],
            [1.0, 1.0],
            [1.0, 2.0],
            [0.0, 2.0],
        ];
        let mut poly = Vec::new();
        for k in 0..corners.len() {
            let (a, b): ([f64; 2], [f64; 2]) = (corners[k], corners[(k + 1) % corners.len()]);
            let m = (((b[0] - a[0]).abs() + (b[1] - a[1]).abs()) / 0.1).round() as usize;
            for i in 0..m {
                let t = i as f64 / m as f64;
                poly.push([a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])]);
            }
        }
        let edge = 0.05;
        let pts = interior_lattice(&poly, edge);
        let clear = LATTICE_CLEARANCE * edge;
        for p in &pts {
            let inside_l =
                p[0] > 0.0 && p[1] > 0.0 && p[0] < 2.0 && p[1] < 2.0 && (p[0] < 1.0 || p[1] < 1.0);
            assert!(inside_l, "{p:?} outside");
            let d = (0..corners.len())
                .map(|k| {
                    let (a, b) = (corners[k], corners[(k + 1) % corners.len()]);
                    let (ab, ap) = ([b[0] - a[0], b[1] - a[1]], [p[0] - a[0], p[1] - a[1]]);
                    let t = ((ap[0] * ab[0] + ap[1] * ab[1]) / (ab[0] * ab[0] + ab[1] * ab[1]))
                        .clamp(0.0, 1.0);
                    ((ap[0] - t * ab[0]).powi(2) + (ap[1] - t * ab[1]).powi(2)).sqrt()
                })
                .fold(f64::MAX, f64::min);
            assert!(d >= clear - 1e-12, "{p:?} is {d} from the boundary");
        }
        // Area 3 less a clearance band of length 8: about (3 − 8·0.6·0.05) / (√3/2 · 0.05²).
        let expected = (3.0 - 8.0 * clear) / (3f64.sqrt() / 2.0 * edge * edge);
        let ratio = pts.len() as f64 / expected;
        assert!(
            (0.95..1.05).contains(&ratio),
            "{} points, expected {expected:.0}",
            pts.len()
        );
        // Neighbours at the lattice spacing: no two points closer than the edge.
        let mut sorted = pts.clone();
        sorted.sort_by(|a, b| a[0].total_cmp(&b[0]));
        for (i, a) in sorted.iter().enumerate() {
            for b in sorted[i + 1..].iter().take_while(|b| b[0] - a[0] < edge) {
                let d = ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)).sqrt();
                assert!(d > edge * (1.0 - 1e-9), "{a:?} and {b:?} are {d} apart");
            }
        }
    }

    #[test]
    fn simple_polygon_test() {
        let square = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]];
        assert!(is_simple_ccw(&square));
        let mut cw = square;
        cw.reverse();
        assert!(!is_simple_ccw(&cw));
        let bowtie = [[0.0, 0.0], [1.0, 1.0], [1.0, 0.0], [0.0, 1.0]];
        assert!(!is_simple_ccw(&bowtie));
    }

    #[test]
    fn bad_input_is_an_error_not_a_panic() {
        let p = Vector3::new(0.0, 0.0, 0.0);
        assert!(matches!(
            tessellate(&[p, p], &[Vector3::z(); 2], 0.1),
            Err(TessellateError::TooFewPoints(2))
        ));
        let q = Vector3::new(1.0, 0.0, 0.0);
        assert!(matches!(
            tessellate(&[p, q, q, Vector3::y()], &[Vector3::z(); 4], 0.1),
            Err(TessellateError::Coincident(1, 2))
        ));
        let nan = Vector3::new(f64::NAN, 0.0, 0.0);
        assert!(matches!(
            tessellate(&[p, q, nan], &[Vector3::z(); 3], 0.1),
            Err(TessellateError::NonFinite)
        ));
    }
}
