//! `sfs eval`: the error metric of the shape-from-sensors paper. The reconstructed network is
//! registered rigidly on the truth (Kabsch on the matching nodes, then ICP on all curve points;
//! no scaling; a glb without node positions is started from each of the 24 orientations that
//! map its principal axes onto the truth's, a short ICP from each, the best kept, since from
//! one start ICP lands in a wrong minimum on symmetric shapes), then every reconstructed curve
//! point is measured to the truth network, and
//! every surface vertex to the truth surface; mean and max, in metres and in % of the truth
//! network's bounding-box diagonal.

use crate::gltf_out::ReadNetwork;
use crate::simulate::surface::{point_triangle_distance, Surface};
use crate::simulate::truth::Truth;
use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};
use serde::Serialize;
use sfs_geometry::curve::CurveKind;
use std::collections::HashMap;

/// Distances of one set of points.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct Distances {
    pub count: usize,
    pub mean_m: f64,
    pub max_m: f64,
    pub rms_m: f64,
    /// Mean and max in % of the truth bounding-box diagonal (the paper's unit).
    pub mean_pct: f64,
    pub max_pct: f64,
}

/// The distances of one curve's points to the truth network.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct CurveDistances {
    pub curve: usize,
    pub kind: CurveKind,
    pub distances: Distances,
}

/// The rigid registration found.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct Registration {
    /// Nodes present in both and used for the initial alignment.
    pub nodes_matched: usize,
    /// Nodes of the reconstruction (typed, not anonymous) that the truth does not have: a
    /// network of another scene.
    pub nodes_unknown: Vec<u32>,
    /// How the alignment was started: `"nodes"` (Kabsch on the matched nodes), or
    /// `"principal axes k/24"` (the best of the 24 starts without nodes).
    pub initialisation: String,
    pub rotation_deg: f64,
    pub translation_m: [f64; 3],
    pub icp_iterations: usize,
    /// The root mean square distance of the registered curve points to the truth network,
    /// % of the truth's diagonal.
    pub residual_rms_pct: f64,
    /// Whether the registration fits: the residual is under [`MAX_RESIDUAL_PCT`] and every
    /// node of the reconstruction is one of the truth's. When not, the reconstruction is most
    /// likely of another shape than the truth's (`sfs eval` exits 5), and the distances below
    /// mean nothing.
    pub fits: bool,
}

/// The largest registration residual (RMS, % of the diagonal) of a reconstruction of the
/// truth's own shape. Measured (BENCHMARKS.md "The operator's experience"): on 345 of 346
/// captures of the validation set and our simulator, planted faults included, it is at most
/// 0.96 %; the one over it (5.3 %) is a capture reconstructed 3.6 % off. A network of another
/// scene can stay under it (the cone's against the sphere-octa's truth: 4.85 %): its nodes
/// the truth does not have refuse it ([`Registration::nodes_unknown`]).
pub const MAX_RESIDUAL_PCT: f64 = 5.0;

/// The JSON object `sfs eval` prints.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct Evaluation {
    pub scene: String,
    pub bbox_diagonal_m: f64,
    pub registration: Registration,
    pub curves: Distances,
    /// The same per curve (by scan index), for the curves of a kind other than boundary or
    /// interior (creases, guides: a guide's own error, against which the surface's distance
    /// from it in `report.json` is read).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub curves_by_kind: Vec<CurveDistances>,
    pub surface: Option<Distances>,
    /// Per crease curve, the angle between the surface's two faces across it against the
    /// truth's (truth surfaces of flat faces only).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub creases: Vec<CreaseAngles>,
    /// Node position errors after registration, m, by node index.
    /// (Sorted by node number; JSON object keys are strings.)
    pub node_errors_m: std::collections::BTreeMap<u32, f64>,
}

/// The dihedral angle along one crease curve: at its points (every centimetre, away from its
/// nodes by a twentieth of the diagonal, where other faces meet), the angle between the
/// area-weighted normals of the surface's triangles on either side of the curve within three
/// mean edge lengths, against the angle between the truth's two faces there.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct CreaseAngles {
    pub curve: usize,
    pub points: usize,
    /// Mean truth dihedral angle (between the faces' normals), degrees.
    pub truth_deg: f64,
    /// Mean dihedral angle of the surface, degrees.
    pub surface_deg: f64,
    /// Mean and largest |surface − truth|, degrees.
    pub error_mean_deg: f64,
    pub error_max_deg: f64,
}

/// A uniform grid of segments for nearest-segment queries.
struct SegmentGrid {
    cell: f64,
    segs: Vec<(Vector3<f64>, Vector3<f64>)>,
    map: HashMap<[i64; 3], Vec<u32>>,
}

impl SegmentGrid {
    fn new(segs: Vec<(Vector3<f64>, Vector3<f64>)>, cell: f64) -> Self {
        let mut map: HashMap<[i64; 3], Vec<u32>> = HashMap::new();
        for (i, (a, b)) in segs.iter().enumerate() {
            let lo = a.inf(b);
            let hi = a.sup(b);
            let (l, h) = (key(&lo, cell), key(&hi, cell));
            for x in l[0]..=h[0] {
                for y in l[1]..=h[1] {
                    for z in l[2]..=h[2] {
                        map.entry([x, y, z]).or_default().push(i as u32);
                    }
                }
            }
        }
        SegmentGrid { cell, segs, map }
    }

    /// Nearest point on any segment, and its distance.
    fn nearest(&self, p: &Vector3<f64>) -> (Vector3<f64>, f64) {
        let c = key(p, self.cell);
        let mut best = (*p, f64::INFINITY);
        for r in 0i64.. {
            // Cells at Chebyshev ring r; once the ring is farther than the best, stop.
            if best.1 < (r as f64 - 1.0) * self.cell {
                break;
            }
            if r > 100_000 {
                break;
            }
            // Only the shell of the ring: all z where x or y is on it, else its two z faces.
            for x in -r..=r {
                for y in -r..=r {
                    let side = x.abs() == r || y.abs() == r;
                    let step = if side || r == 0 { 1 } else { (2 * r) as usize };
                    for z in (-r..=r).step_by(step) {
                        if let Some(ids) = self.map.get(&[c[0] + x, c[1] + y, c[2] + z]) {
                            for &i in ids {
                                let (a, b) = self.segs[i as usize];
                                let q = closest_on_segment(p, &a, &b);
                                let d = (q - p).norm();
                                if d < best.1 {
                                    best = (q, d);
                                }
                            }
                        }
                    }
                }
            }
            if r > 4 && best.1.is_infinite() && self.map.is_empty() {
                break;
            }
        }
        best
    }
}

fn key(p: &Vector3<f64>, cell: f64) -> [i64; 3] {
    [
        (p.x / cell).floor() as i64,
        (p.y / cell).floor() as i64,
        (p.z / cell).floor() as i64,
    ]
}

fn closest_on_segment(p: &Vector3<f64>, a: &Vector3<f64>, b: &Vector3<f64>) -> Vector3<f64> {
    let ab = b - a;
    let l2 = ab.norm_squared();
    if l2 <= 0.0 {
        return *a;
    }
    a + ab * ((p - a).dot(&ab) / l2).clamp(0.0, 1.0)
}

/// Best rigid motion `(R, t)` with `R·a + t ≈ b` (Kabsch), `None` for fewer than 3 pairs or
/// collinear points.
pub fn kabsch(a: &[Vector3<f64>], b: &[Vector3<f64>]) -> Option<(Rotation3<f64>, Vector3<f64>)> {
    if a.len() < 3 || a.len() != b.len() {
        return None;
    }
    let ca = a.iter().sum::<Vector3<f64>>() / a.len() as f64;
    let cb = b.iter().sum::<Vector3<f64>>() / b.len() as f64;
    let mut h = Matrix3::zeros();
    for (p, q) in a.iter().zip(b) {
        h += (p - ca) * (q - cb).transpose();
    }
    let svd = h.svd(true, true);
    let (u, vt) = (svd.u?, svd.v_t?);
    // `SVD::new` sorts the singular values in descending order.
    let s = svd.singular_values;
    if s[1] < 1e-12 * s[0].max(1e-300) {
        return None; // collinear: the rotation about the line is undetermined
    }
    let mut d = Matrix3::identity();
    if (vt.transpose() * u.transpose()).determinant() < 0.0 {
        d[(2, 2)] = -1.0;
    }
    let r = Rotation3::from_matrix_unchecked(vt.transpose() * d * u.transpose());
    Some((r, cb - r * ca))
}

/// The segments of the truth's curves, through every `stride`-th point of each (and its last).
fn segments(truth: &Truth, stride: usize) -> Vec<(Vector3<f64>, Vector3<f64>)> {
    let mut segs = Vec::new();
    for c in &truth.curves {
        let n = c.points.len();
        let kept = c
            .points
            .iter()
            .enumerate()
            .filter(|(i, _)| i % stride == 0 || i + 1 == n)
            .map(|(_, p)| Vector3::from(*p));
        let mut last: Option<Vector3<f64>> = None;
        for p in kept {
            if let Some(l) = last {
                segs.push((l, p));
            }
            last = Some(p);
        }
    }
    segs
}

/// ICP of `sample` onto the truth polylines in `grid` from `(r, t)`, at most `max_iter`
/// iterations (stopping when the RMS distance changes less than 1e-9 of `diag`): the rotation,
/// translation, the last RMS distance and the iterations done.
fn icp(
    sample: &[Vector3<f64>],
    grid: &SegmentGrid,
    mut r: Rotation3<f64>,
    mut t: Vector3<f64>,
    max_iter: usize,
    diag: f64,
) -> (Rotation3<f64>, Vector3<f64>, f64, usize) {
    let mut iterations = 0;
    let mut last_rms = f64::INFINITY;
    for it in 0..max_iter {
        iterations = it + 1;
        let moved: Vec<Vector3<f64>> = sample.iter().map(|p| r * p + t).collect();
        let near: Vec<(Vector3<f64>, f64)> = moved.iter().map(|p| grid.nearest(p)).collect();
        let rms = (near.iter().map(|n| n.1 * n.1).sum::<f64>() / near.len() as f64).sqrt();
        let converged = (last_rms - rms).abs() <= 1e-9 * diag;
        last_rms = rms;
        // Twice the residual any registration of the same shape leaves, after 20 iterations:
        // no fit will come (another scene's truth); each further iteration would search far
        // from every curve, where the grid is slow.
        if it >= 20 && rms > 2.0 * MAX_RESIDUAL_PCT / 100.0 * diag {
            break;
        }
        let targets: Vec<Vector3<f64>> = near.iter().map(|n| n.0).collect();
        let Some((dr, dt)) = kabsch(&moved, &targets) else {
            break;
        };
        r = dr * r;
        t = dr * t + dt;
        if converged {
            break;
        }
    }
    (r, t, last_rms, iterations)
}

/// The 24 rigid motions that take the centroid of `a` to that of `b` and the principal axes
/// of `a` onto those of `b` (each of the 24 rotations of a cube between the two frames: the
/// axes' order and signs are ambiguous when their spreads are alike, as on symmetric shapes).
fn principal_axes_starts(
    a: &[Vector3<f64>],
    b: &[Vector3<f64>],
) -> Vec<(Rotation3<f64>, Vector3<f64>)> {
    let frame = |p: &[Vector3<f64>]| {
        let c = p.iter().sum::<Vector3<f64>>() / p.len().max(1) as f64;
        let mut cov = Matrix3::zeros();
        for x in p {
            cov += (x - c) * (x - c).transpose();
        }
        let mut e = cov.symmetric_eigen().eigenvectors;
        if e.determinant() < 0.0 {
            e.set_column(2, &(-e.column(2)));
        }
        (c, e)
    };
    let ((ca, fa), (cb, fb)) = (frame(a), frame(b));
    let mut starts = Vec::with_capacity(24);
    for perm in [
        [0, 1, 2],
        [1, 2, 0],
        [2, 0, 1],
        [1, 0, 2],
        [0, 2, 1],
        [2, 1, 0],
    ] {
        for signs in [[1.0, 1.0], [1.0, -1.0], [-1.0, 1.0], [-1.0, -1.0]] {
            let mut s = Matrix3::zeros();
            s[(perm[0], 0)] = signs[0];
            s[(perm[1], 1)] = signs[1];
            s[(perm[2], 2)] = 1.0;
            if s.determinant() < 0.0 {
                s[(perm[2], 2)] = -1.0;
            }
            let r = Rotation3::from_matrix_unchecked(fb * s * fa.transpose());
            starts.push((r, cb - r * ca));
        }
    }
    starts
}

fn distances(d: &[f64], diag: f64) -> Distances {
    let n = d.len().max(1) as f64;
    let mean = d.iter().sum::<f64>() / n;
    let max = d.iter().cloned().fold(0.0, f64::max);
    let rms = (d.iter().map(|x| x * x).sum::<f64>() / n).sqrt();
    Distances {
        count: d.len(),
        mean_m: mean,
        max_m: max,
        rms_m: rms,
        mean_pct: 100.0 * mean / diag,
        max_pct: 100.0 * max / diag,
    }
}

/// Why an evaluation is impossible.
#[derive(Debug, thiserror::Error)]
pub enum EvalError {
    #[error("the glb holds no curve point")]
    NoPoints,
    #[error("the truth holds no curve")]
    NoTruth,
    #[error("the truth surface cannot be rebuilt: {0}")]
    Surface(#[from] crate::simulate::mesh::MeshError),
}

/// Evaluates a reconstruction against the truth.
pub fn evaluate(truth: &Truth, rec: &ReadNetwork) -> Result<Evaluation, EvalError> {
    let pts: Vec<Vector3<f64>> = rec
        .curves
        .iter()
        .flat_map(|c| c.points.iter().copied())
        .collect();
    if pts.is_empty() {
        return Err(EvalError::NoPoints);
    }
    let segs = segments(truth, 1);
    if segs.is_empty() {
        return Err(EvalError::NoTruth);
    }
    let diag = truth.bbox_diagonal.max(1e-12);
    let grid = SegmentGrid::new(segs, (diag / 100.0).max(1e-6));

    // Initial alignment: matching nodes, else the best of the principal-axes starts.
    let mut a = Vec::new();
    let mut b = Vec::new();
    for (k, p) in &rec.nodes {
        if let Some(q) = truth.nodes.get(&k.to_string()) {
            a.push(*p);
            b.push(Vector3::from(*q));
        }
    }
    let nodes_matched = a.len();
    let nodes_unknown: Vec<u32> = rec
        .nodes
        .keys()
        .copied()
        .filter(|&k| {
            !sfs_geometry::curve::is_anonymous(k) && !truth.nodes.contains_key(&k.to_string())
        })
        .collect();
    // ICP (point to closest point on the truth polylines), subsampled for speed.
    let step = (pts.len() / 20_000).max(1);
    let sample: Vec<Vector3<f64>> = pts.iter().step_by(step).copied().collect();
    let (start, initialisation) = match kabsch(&a, &b) {
        Some(rt) => (rt, "nodes".to_string()),
        None => {
            let truth_pts: Vec<Vector3<f64>> = truth
                .curves
                .iter()
                .flat_map(|c| c.points.iter().map(|p| Vector3::from(*p)))
                .collect();
            // The starts are compared by a short ICP of ~500 points onto the truth polylines
            // thinned to ~2000 segments, in a coarse grid (a wrong start leaves points far
            // from every curve, where a fine grid's search would be slow).
            let thin = segments(truth, (truth_pts.len() / 2000).max(1));
            let coarse_grid = SegmentGrid::new(thin, diag / 20.0);
            let coarse: Vec<Vector3<f64>> = pts
                .iter()
                .step_by((pts.len() / 500).max(1))
                .copied()
                .collect();
            let (k, rt) = principal_axes_starts(&pts, &truth_pts)
                .into_iter()
                .enumerate()
                .map(|(k, (r, t))| {
                    let (r, t, rms, _) = icp(&coarse, &coarse_grid, r, t, 15, diag);
                    (k, (r, t), rms)
                })
                .min_by(|x, y| x.2.total_cmp(&y.2))
                .map(|(k, rt, _)| (k, rt))
                .expect("24 starts");
            (rt, format!("principal axes {}/24", k + 1))
        }
    };
    let (r, t, _, iterations) = icp(&sample, &grid, start.0, start.1, 100, diag);
    let d: Vec<f64> = pts.iter().map(|p| grid.nearest(&(r * p + t)).1).collect();
    let mut curves_by_kind = Vec::new();
    let mut start = 0;
    for c in &rec.curves {
        let range = start..start + c.points.len();
        start = range.end;
        if matches!(c.kind, CurveKind::Crease | CurveKind::Guide) {
            curves_by_kind.push(CurveDistances {
                curve: c.index,
                kind: c.kind,
                distances: distances(&d[range], diag),
            });
        }
    }
    let surface = match &rec.surface {
        Some(s) if !s.positions.is_empty() => {
            let surf = truth.surface.build().map_err(EvalError::Surface)?;
            let ds = surface_distances(
                &surf,
                &s.positions.iter().map(|p| r * p + t).collect::<Vec<_>>(),
                diag,
            );
            Some(distances(&ds, diag))
        }
        _ => None,
    };
    let creases = match (&rec.surface, truth.surface.build()) {
        (Some(mesh), Ok(Surface::Faces(faces))) => {
            // The truth's creases (also when the reconstruction made them smooth curves).
            let creases: Vec<usize> = truth
                .curves
                .iter()
                .filter(|c| c.kind() == CurveKind::Crease)
                .map(|c| c.index)
                .collect();
            crease_angles(rec, &creases, mesh, &faces, (&r, &t), diag)
        }
        _ => Vec::new(),
    };
    let node_errors_m = rec
        .nodes
        .iter()
        .filter_map(|(k, p)| {
            let q = truth.nodes.get(&k.to_string())?;
            Some((*k, (r * p + t - Vector3::from(*q)).norm()))
        })
        .collect();
    let curves = distances(&d, diag);
    let residual_rms_pct = curves.rms_m / diag * 100.0;
    Ok(Evaluation {
        scene: truth.scene.clone(),
        bbox_diagonal_m: diag,
        registration: Registration {
            nodes_matched,
            fits: residual_rms_pct <= MAX_RESIDUAL_PCT && nodes_unknown.is_empty(),
            nodes_unknown,
            initialisation,
            rotation_deg: UnitQuaternion::from_rotation_matrix(&r)
                .angle()
                .to_degrees(),
            translation_m: [t.x, t.y, t.z],
            icp_iterations: iterations,
            residual_rms_pct,
        },
        curves,
        curves_by_kind,
        surface,
        creases,
        node_errors_m,
    })
}

/// The dihedral angles along the crease curves of `rec` and its curves `creases` (the
/// truth's) ([`CreaseAngles`]), registered by `(r, t)` onto the truth of flat `faces`.
fn crease_angles(
    rec: &ReadNetwork,
    creases: &[usize],
    mesh: &crate::gltf_out::SurfaceMesh,
    faces: &crate::simulate::surface::Faces,
    (r, t): (&Rotation3<f64>, &Vector3<f64>),
    diag: f64,
) -> Vec<CreaseAngles> {
    let pos: Vec<Vector3<f64>> = mesh.positions.iter().map(|p| r * p + t).collect();
    let tris: Vec<(Vector3<f64>, Vector3<f64>)> = mesh
        .triangles
        .iter()
        .map(|f| {
            let [a, b, c] = f.map(|i| pos[i as usize]);
            ((a + b + c) / 3.0, (b - a).cross(&(c - a)) / 2.0)
        })
        .collect();
    let edge = {
        let (mut sum, mut n) = (0.0, 0usize);
        for f in &mesh.triangles {
            for k in 0..3 {
                sum += (pos[f[k] as usize] - pos[f[(k + 1) % 3] as usize]).norm();
                n += 1;
            }
        }
        sum / n.max(1) as f64
    };
    let radius = 3.0 * edge;
    let nodes: Vec<Vector3<f64>> = rec.nodes.values().map(|p| r * p + t).collect();
    let mut out = Vec::new();
    for c in rec
        .curves
        .iter()
        .filter(|c| c.kind == CurveKind::Crease || creases.contains(&c.index))
    {
        let pts: Vec<Vector3<f64>> = c.points.iter().map(|p| r * p + t).collect();
        let (mut truth_sum, mut surf_sum, mut err_sum, mut err_max, mut count) =
            (0.0, 0.0, 0.0, 0.0f64, 0usize);
        let mut last: Option<Vector3<f64>> = None;
        for j in 1..pts.len().saturating_sub(1) {
            let p = pts[j];
            if last.is_some_and(|q| (p - q).norm() < 0.01)
                || nodes.iter().any(|n| (n - p).norm() < diag / 20.0)
            {
                continue;
            }
            let Some(tan) = (pts[j + 1] - pts[j - 1]).try_normalize(1e-12) else {
                continue;
            };
            // The truth: the two face planes nearest the point.
            let mut by: Vec<(f64, Vector3<f64>)> = faces
                .planes
                .iter()
                .map(|(n, d)| ((n.dot(&p) - d).abs(), *n))
                .collect();
            by.sort_by(|a, b| a.0.total_cmp(&b.0));
            if by.len() < 2 {
                continue;
            }
            let truth_deg = by[0].1.angle(&by[1].1).to_degrees();
            // The surface: triangles near the point, split by the side of the curve.
            let near: Vec<&(Vector3<f64>, Vector3<f64>)> = tris
                .iter()
                .filter(|(cen, _)| (cen - p).norm() < radius)
                .collect();
            let mean: Vector3<f64> = near.iter().map(|(_, a)| *a).sum();
            let Some(side) = mean.cross(&tan).try_normalize(1e-300) else {
                continue;
            };
            let (mut left, mut right) = (Vector3::zeros(), Vector3::zeros());
            for (cen, a) in near {
                if (cen - p).dot(&side) > 0.0 {
                    left += a;
                } else {
                    right += a;
                }
            }
            if left.norm() == 0.0 || right.norm() == 0.0 {
                continue;
            }
            let surf_deg = left.angle(&right).to_degrees();
            truth_sum += truth_deg;
            surf_sum += surf_deg;
            err_sum += (surf_deg - truth_deg).abs();
            err_max = err_max.max((surf_deg - truth_deg).abs());
            count += 1;
            last = Some(p);
        }
        if count > 0 {
            let n = count as f64;
            out.push(CreaseAngles {
                curve: c.index,
                points: count,
                truth_deg: truth_sum / n,
                surface_deg: surf_sum / n,
                error_mean_deg: err_sum / n,
                error_max_deg: err_max,
            });
        }
    }
    out
}

/// Distances of points to a surface; meshes through a triangle grid.
fn surface_distances(s: &Surface, pts: &[Vector3<f64>], diag: f64) -> Vec<f64> {
    let Surface::Mesh(m) = s else {
        return pts.iter().map(|p| s.distance(p)).collect();
    };
    let cell = (diag / 60.0).max(1e-6);
    let mut map: HashMap<[i64; 3], Vec<u32>> = HashMap::new();
    for (i, f) in m.f.iter().enumerate() {
        let v = f.map(|k| m.v[k as usize]);
        let (l, h) = (
            key(&v[0].inf(&v[1]).inf(&v[2]), cell),
            key(&v[0].sup(&v[1]).sup(&v[2]), cell),
        );
        for x in l[0]..=h[0] {
            for y in l[1]..=h[1] {
                for z in l[2]..=h[2] {
                    map.entry([x, y, z]).or_default().push(i as u32);
                }
            }
        }
    }
    pts.iter()
        .map(|p| {
            let c = key(p, cell);
            let mut best = f64::INFINITY;
            for r in 0i64..10_000 {
                if best < (r as f64 - 1.0) * cell {
                    break;
                }
                for x in -r..=r {
                    for y in -r..=r {
                        for z in -r..=r {
                            if x.abs().max(y.abs()).max(z.abs()) != r {
                                continue;
                            }
                            for &i in map
                                .get(&[c[0] + x, c[1] + y, c[2] + z])
                                .into_iter()
                                .flatten()
                            {
                                let f = m.f[i as usize];
                                let d = point_triangle_distance(
                                    p,
                                    &m.v[f[0] as usize],
                                    &m.v[f[1] as usize],
                                    &m.v[f[2] as usize],
                                );
                                best = best.min(d);
                            }
                        }
                    }
                }
            }
            best
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kabsch_recovers_a_rigid_motion() {
        let a: Vec<Vector3<f64>> = (0..10)
            .map(|i| Vector3::new(i as f64, (i * i) as f64 * 0.1, (i as f64).sin()))
            .collect();
        let r = Rotation3::from_euler_angles(0.3, -0.2, 1.1);
        let t = Vector3::new(1.0, -2.0, 0.5);
        let b: Vec<Vector3<f64>> = a.iter().map(|p| r * p + t).collect();
        let (rr, tt) = kabsch(&a, &b).unwrap();
        assert!((rr.matrix() - r.matrix()).norm() < 1e-9 && (tt - t).norm() < 1e-9);
        assert!(kabsch(&a[..2], &b[..2]).is_none());
    }
}
