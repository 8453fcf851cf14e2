//! A scene's curves: each `[[curve]]` table, a plane section of the surface (the piece near a
//! point, an arc between two, or the whole loop), a polyline on a box's or a gable's faces, or
//! a mesh's boundary loop, resampled at the scene's spacing with exact normals.

use super::super::mesh::{Section, TriMesh};
use super::super::operator::CurveKind;
use super::super::surface::Surface;

use nalgebra::Vector3;
use serde::Deserialize;

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct CurveToml {
    #[serde(default = "section_kind")]
    pub(super) kind: String,
    pub(super) normal: Option<[f64; 3]>,
    pub(super) offset: Option<f64>,
    pub(super) through: Option<[[f64; 3]; 3]>,
    pub(super) near: Option<[f64; 3]>,
    pub(super) from: Option<[f64; 3]>,
    pub(super) to: Option<[f64; 3]>,
    pub(super) via: Option<[f64; 3]>,
    pub(super) points: Option<Vec<[f64; 3]>>,
    pub(super) rest: Option<[f64; 3]>,
    #[serde(default)]
    pub(super) closed: bool,
    #[serde(default)]
    pub(super) boundary: bool,
    #[serde(default)]
    pub(super) crease: bool,
    #[serde(default)]
    pub(super) guide: bool,
    /// A polyline's points are nodes too (the operator tags each corner where it stands to
    /// turn), besides its crossings.
    #[serde(default)]
    pub(super) tag_points: bool,
}

pub(super) fn section_kind() -> String {
    "section".into()
}

/// A polyline with normals (and the plane it lies in, for exact snapping).
#[derive(Debug, Clone)]
pub(super) struct Piece {
    pub(super) points: Vec<Vector3<f64>>,
    pub(super) normals: Vec<Vector3<f64>>,
    pub(super) closed: bool,
    pub(super) plane: Option<(Vector3<f64>, f64)>,
    pub(super) kind: CurveKind,
    /// Points declared nodes (a polyline's `tag_points`), besides the crossings.
    pub(super) nodes: Vec<Vector3<f64>>,
}

pub(super) fn v3(a: [f64; 3]) -> Vector3<f64> {
    Vector3::from(a)
}

/// Cumulative arc lengths.
pub(super) fn arclen(p: &[Vector3<f64>]) -> Vec<f64> {
    let mut c = vec![0.0; p.len()];
    for i in 1..p.len() {
        c[i] = c[i - 1] + (p[i] - p[i - 1]).norm();
    }
    c
}

/// The closest point of a polyline to `x`: (segment index, parameter in it, distance).
pub(super) fn closest(p: &[Vector3<f64>], x: &Vector3<f64>) -> (usize, f64, f64) {
    sfs_geometry::curve::closest_on_polyline(p, x)
}

/// Resamples a polyline at about `h` (both ends kept), interpolating normals, and snaps the
/// points onto an analytic surface.
pub(super) fn resample(
    points: &[Vector3<f64>],
    normals: &[Vector3<f64>],
    h: f64,
    s: &Surface,
    plane: Option<&Vector3<f64>>,
) -> (Vec<Vector3<f64>>, Vec<Vector3<f64>>) {
    let c = arclen(points);
    let total = *c.last().unwrap_or(&0.0);
    let n = ((total / h).ceil() as usize).max(1);
    let mut out_p = Vec::with_capacity(n + 1);
    let mut out_n = Vec::with_capacity(n + 1);
    let mut seg = 0;
    for k in 0..=n {
        let target = total * k as f64 / n as f64;
        while seg + 2 < c.len() && c[seg + 1] < target {
            seg += 1;
        }
        let len = c[seg + 1] - c[seg];
        let t = if len > 0.0 {
            ((target - c[seg]) / len).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let p = points[seg] + (points[seg + 1] - points[seg]) * t;
        let nn = (normals[seg] + (normals[seg + 1] - normals[seg]) * t).normalize();
        let (p, nn) = match plane {
            Some(pl) => s.snap_in_plane(p, nn, pl),
            None => (p, nn),
        };
        out_p.push(p);
        out_n.push(nn);
    }
    // On flat faces a point on an edge has two normals: take, at every point, the face of the
    // chord towards its neighbour (the one the curve runs on).
    if let (Surface::Faces(_), Some(_)) = (s, plane) {
        let m = out_p.len();
        for i in 0..m {
            let j = if i + 1 < m {
                i + 1
            } else {
                i.saturating_sub(1)
            };
            if let Some((_, g)) = s.implicit(&((out_p[i] + out_p[j]) / 2.0)) {
                out_n[i] = g;
            }
        }
    }
    (out_p, out_n)
}

/// Why a scene curve cannot be built (its key is named by [`SceneError`](super::SceneError)).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum CurveError {
    #[error("kind = \"mesh-boundary\" needs a mesh surface")]
    NotAMesh,
    #[error("the mesh has no boundary")]
    NoBoundary,
    #[error("unknown curve kind {0:?}: section, polyline or mesh-boundary")]
    UnknownKind(String),
    #[error("kind = \"polyline\" needs a surface of flat faces (box or gable)")]
    NotFaces,
    #[error("a polyline needs `points`, at least two")]
    NoPoints,
    #[error("tag_points needs kind = \"polyline\"")]
    TagPointsNotPolyline,
    #[error("polyline segment {0} does not lie on a face")]
    OffFaces(usize),
    #[error(
        "polyline segment {0} runs along an edge: say which face the device rests on with `rest`"
    )]
    AlongEdge(usize),
    #[error("normal must be a non-zero vector")]
    ZeroNormal,
    #[error("the three `through` points are collinear")]
    Collinear,
    #[error("give either normal (+ offset) or through")]
    NoPlane,
    #[error("the plane does not cut the surface")]
    NoCut,
    #[error("closed = true, but this section is not a loop")]
    NotALoop,
    #[error("give both from and to, or neither")]
    HalfArc,
    #[error("from and to are the same point of the section")]
    EmptyArc,
    #[error("boundary, crease and guide: at most one of them")]
    TwoKinds,
}

impl CurveToml {
    /// What the curve means, from its `boundary` / `crease` / `guide` flags.
    fn kind(&self) -> Result<CurveKind, CurveError> {
        match (self.boundary, self.crease, self.guide) {
            (false, false, false) => Ok(CurveKind::Interior),
            (true, false, false) => Ok(CurveKind::Boundary),
            (false, true, false) => Ok(CurveKind::Crease),
            (false, false, true) => Ok(CurveKind::Guide),
            _ => Err(CurveError::TwoKinds),
        }
    }
}

pub(super) fn piece(
    s: &Surface,
    tess: &TriMesh,
    c: &CurveToml,
    h: f64,
) -> Result<Piece, CurveError> {
    if c.kind == "mesh-boundary" {
        let Surface::Mesh(m) = s else {
            return Err(CurveError::NotAMesh);
        };
        let loops = m.boundary_loops();
        let lp = loops
            .iter()
            .max_by_key(|l| l.len())
            .ok_or(CurveError::NoBoundary)?;
        let mut points: Vec<Vector3<f64>> = lp.iter().map(|&i| m.v[i as usize]).collect();
        let mut normals: Vec<Vector3<f64>> = lp.iter().map(|&i| m.n[i as usize]).collect();
        points.push(points[0]);
        normals.push(normals[0]);
        let (points, normals) = resample(&points, &normals, h, s, None);
        return Ok(Piece {
            points,
            normals,
            closed: true,
            plane: None,
            kind: c.kind()?,
            nodes: Vec::new(),
        });
    }
    if c.kind == "polyline" {
        return polyline(s, c, h);
    }
    if c.tag_points {
        return Err(CurveError::TagPointsNotPolyline);
    }
    if c.kind != "section" {
        return Err(CurveError::UnknownKind(c.kind.clone()));
    }
    let (normal, offset) = match (c.normal, c.through) {
        (Some(n), None) => {
            let n = v3(n);
            let l = n.norm();
            if !(l > 0.0 && l.is_finite()) {
                return Err(CurveError::ZeroNormal);
            }
            (n / l, c.offset.unwrap_or(0.0) / l)
        }
        (None, Some([a, b, q])) => {
            let (a, b, q) = (v3(a), v3(b), v3(q));
            let n = (b - a).cross(&(q - a));
            let l = n.norm();
            if l.is_nan() || l < 1e-12 {
                return Err(CurveError::Collinear);
            }
            (n / l, (n / l).dot(&a))
        }
        _ => return Err(CurveError::NoPlane),
    };
    let pieces: Vec<Section> = tess.slice(&normal, offset);
    if pieces.is_empty() {
        return Err(CurveError::NoCut);
    }
    let hint = c.near.or(c.from).map(v3).unwrap_or_else(Vector3::zeros);
    let sec = pieces
        .into_iter()
        .min_by(|a, b| {
            closest(&a.points, &hint)
                .2
                .total_cmp(&closest(&b.points, &hint).2)
        })
        .expect("non-empty");
    let mut pts = sec.points;
    let mut nrm = sec.normals;
    if sec.closed {
        pts.push(pts[0]);
        nrm.push(nrm[0]);
    }
    let (pts, nrm) = match (c.from, c.to) {
        (Some(f), Some(t)) => arc(
            &pts,
            &nrm,
            sec.closed,
            &v3(f),
            &v3(t),
            c.via.map(v3).as_ref(),
        )?,
        (None, None) => {
            if c.closed && !sec.closed {
                return Err(CurveError::NotALoop);
            }
            (pts, nrm)
        }
        _ => return Err(CurveError::HalfArc),
    };
    let closed = c.closed && c.from.is_none();
    let (points, normals) = resample(&pts, &nrm, h, s, Some(&normal));
    Ok(Piece {
        points,
        normals,
        closed,
        plane: Some((normal, offset)),
        kind: c.kind()?,
        nodes: Vec::new(),
    })
}

/// A polyline on flat faces through `points` (closed: back to the first), sampled about every
/// `h` with its corners kept; each segment's normal is its face's (along an edge, the face
/// whose normal is nearest `rest`: the one the device rests on), a corner's the mean of its
/// two segments'.
pub(super) fn polyline(s: &Surface, c: &CurveToml, h: f64) -> Result<Piece, CurveError> {
    let Surface::Faces(faces) = s else {
        return Err(CurveError::NotFaces);
    };
    let mut corners: Vec<Vector3<f64>> = c
        .points
        .as_ref()
        .ok_or(CurveError::NoPoints)?
        .iter()
        .map(|p| v3(*p))
        .collect();
    if corners.len() < 2 {
        return Err(CurveError::NoPoints);
    }
    if c.closed {
        corners.push(corners[0]);
    }
    let scale = corners.iter().map(|p| p.norm()).fold(1.0, f64::max);
    let mut normals = Vec::new();
    for (k, w) in corners.windows(2).enumerate() {
        let on: Vec<usize> = faces
            .faces_at(&w[0], 1e-9 * scale)
            .into_iter()
            .filter(|f| faces.faces_at(&w[1], 1e-9 * scale).contains(f))
            .collect();
        let n = match on.len() {
            0 => return Err(CurveError::OffFaces(k)),
            1 => faces.planes[on[0]].0,
            _ => {
                let rest = v3(c.rest.ok_or(CurveError::AlongEdge(k))?);
                on.iter()
                    .map(|&f| faces.planes[f].0)
                    .max_by(|a, b| a.dot(&rest).total_cmp(&b.dot(&rest)))
                    .expect("two faces")
            }
        };
        normals.push(n);
    }
    let (mut points, mut nrm) = (Vec::new(), Vec::new());
    for (k, w) in corners.windows(2).enumerate() {
        let m = (((w[1] - w[0]).norm() / h).ceil() as usize).max(1);
        for j in 0..m {
            points.push(w[0] + (w[1] - w[0]) * (j as f64 / m as f64));
            let n = if j == 0 && k > 0 {
                (normals[k - 1] + normals[k]).normalize()
            } else {
                normals[k]
            };
            nrm.push(n);
        }
    }
    let last = normals.len() - 1;
    points.push(*corners.last().expect("two"));
    nrm.push(if c.closed {
        (normals[last] + normals[0]).normalize()
    } else {
        normals[last]
    });
    if c.closed {
        nrm[0] = nrm[nrm.len() - 1];
    }
    Ok(Piece {
        points,
        normals: nrm,
        closed: c.closed,
        plane: None,
        kind: c.kind()?,
        nodes: match c.tag_points {
            true => corners[..corners.len() - usize::from(c.closed)].to_vec(),
            false => Vec::new(),
        },
    })
}

/// The arc from the point nearest `f` to the point nearest `t` (through `via`, else the
/// shorter way round a loop).
pub(super) type Polyline = (Vec<Vector3<f64>>, Vec<Vector3<f64>>);
pub(super) fn arc(
    p: &[Vector3<f64>],
    n: &[Vector3<f64>],
    closed: bool,
    f: &Vector3<f64>,
    t: &Vector3<f64>,
    via: Option<&Vector3<f64>>,
) -> Result<Polyline, CurveError> {
    // Insert the exact closest points, then walk between them.
    let split = |p: &[Vector3<f64>],
                 n: &[Vector3<f64>],
                 x: &Vector3<f64>|
     -> (Vec<Vector3<f64>>, Vec<Vector3<f64>>, usize) {
        let (i, u, _) = closest(p, x);
        let q = p[i] + (p[i + 1] - p[i]) * u;
        let m = (n[i] + (n[i + 1] - n[i]) * u).normalize();
        let mut pp = p.to_vec();
        let mut nn = n.to_vec();
        pp.insert(i + 1, q);
        nn.insert(i + 1, m);
        (pp, nn, i + 1)
    };
    let (p1, n1, _) = split(p, n, f);
    let (p2, n2, _) = split(&p1, &n1, t);
    let fi = p2
        .iter()
        .position(|q| (q - closest_point(&p2, f)).norm() < 1e-12)
        .unwrap_or(0);
    let ti = p2
        .iter()
        .position(|q| (q - closest_point(&p2, t)).norm() < 1e-12)
        .unwrap_or(p2.len() - 1);
    if fi == ti {
        return Err(CurveError::EmptyArc);
    }
    let forward = |a: usize, b: usize| -> Polyline {
        let m = p2.len() - 1; // closed: last == first
        let mut pp = Vec::new();
        let mut nn = Vec::new();
        let mut i = a;
        loop {
            pp.push(p2[i]);
            nn.push(n2[i]);
            if i == b {
                break;
            }
            i = if closed { (i + 1) % m } else { i + 1 };
        }
        (pp, nn)
    };
    if !closed {
        let (a, b) = (fi.min(ti), fi.max(ti));
        let (mut pp, mut nn) = forward(a, b);
        if fi > ti {
            pp.reverse();
            nn.reverse();
        }
        return Ok((pp, nn));
    }
    let m = p2.len() - 1;
    let (fi, ti) = (fi % m, ti % m);
    let one = forward(fi, ti);
    let (mut other_p, mut other_n) = forward(ti, fi);
    other_p.reverse();
    other_n.reverse();
    let len = |x: &[Vector3<f64>]| *arclen(x).last().unwrap_or(&0.0);
    let pick_one = match via {
        Some(v) => closest(&one.0, v).2 <= closest(&other_p, v).2,
        None => len(&one.0) <= len(&other_p),
    };
    Ok(if pick_one { one } else { (other_p, other_n) })
}

pub(super) fn closest_point(p: &[Vector3<f64>], x: &Vector3<f64>) -> Vector3<f64> {
    let (i, u, _) = closest(p, x);
    p[i] + (p[i + 1] - p[i]) * u
}
