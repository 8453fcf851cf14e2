//! Triangle meshes for scenes: OBJ loading, vertex normals, boundary loops and plane sections.
//!
//! A plane section of a mesh is a set of polylines whose points lie on mesh edges; the normal
//! at such a point interpolates the edge's vertex normals linearly, so between two consecutive
//! points (on two edges of one triangle) the linear interpolation is exactly the barycentric
//! interpolation of the triangle's vertex normals.

use nalgebra::Vector3;
use std::collections::HashMap;
use std::path::Path;

/// An indexed triangle mesh with per-vertex unit normals.
#[derive(Debug, Clone, Default)]
pub struct TriMesh {
    /// #V positions.
    pub v: Vec<Vector3<f64>>,
    /// #F triangles, counter-clockwise seen from the side the normals point to.
    pub f: Vec<[u32; 3]>,
    /// #V unit normals (angle-weighted face normals, or exact for analytic surfaces).
    pub n: Vec<Vector3<f64>>,
}

/// Why a mesh could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum MeshError {
    #[error("cannot read {}: {source}", path.display())]
    Read {
        path: std::path::PathBuf,
        source: std::io::Error,
    },
    #[error("{}:{line}: {reason}", path.display())]
    Parse {
        path: std::path::PathBuf,
        line: usize,
        reason: String,
    },
    #[error("{}: no triangles", path.display())]
    Empty { path: std::path::PathBuf },
    #[error("no generated mesh is called {name:?}")]
    Unknown { name: String },
}

impl TriMesh {
    /// Loads the `v` and `f` lines of an OBJ file (polygons are fanned into triangles; texture
    /// and normal indices are ignored), then computes vertex normals.
    pub fn load_obj(path: &Path) -> Result<TriMesh, MeshError> {
        let text = read_bounded(path).map_err(|source| MeshError::Read {
            path: path.to_owned(),
            source,
        })?;
        Self::parse_obj(&text, path)
    }

    /// Parses the text of an OBJ file (`path` names it in errors).
    pub fn parse_obj(text: &str, path: &Path) -> Result<TriMesh, MeshError> {
        let perr = |line: usize, reason: String| MeshError::Parse {
            path: path.to_owned(),
            line,
            reason,
        };
        let mut m = TriMesh::default();
        for (i, line) in text.lines().enumerate() {
            let mut it = line.split_whitespace();
            match it.next() {
                Some("v") => {
                    let c: Vec<f64> = it
                        .take(3)
                        .map(|s| {
                            s.parse::<f64>()
                                .map_err(|e| perr(i + 1, format!("vertex: {e}")))
                        })
                        .collect::<Result<_, _>>()?;
                    if c.len() != 3 || c.iter().any(|x| !x.is_finite()) {
                        return Err(perr(
                            i + 1,
                            "a vertex needs three finite coordinates".into(),
                        ));
                    }
                    m.v.push(Vector3::new(c[0], c[1], c[2]));
                }
                Some("f") => {
                    let idx: Vec<u32> = it
                        .map(|s| {
                            let k: i64 = s
                                .split('/')
                                .next()
                                .unwrap_or("")
                                .parse()
                                .map_err(|e| perr(i + 1, format!("face index: {e}")))?;
                            let n = m.v.len() as i64;
                            let k = if k < 0 { n + k } else { k - 1 };
                            if k < 0 || k >= n {
                                return Err(perr(i + 1, format!("face index {s} out of range")));
                            }
                            Ok(k as u32)
                        })
                        .collect::<Result<_, _>>()?;
                    if idx.len() < 3 {
                        return Err(perr(i + 1, "a face needs three vertices".into()));
                    }
                    for k in 1..idx.len() - 1 {
                        m.f.push([idx[0], idx[k], idx[k + 1]]);
                    }
                }
                _ => {}
            }
        }
        if m.f.is_empty() {
            return Err(MeshError::Empty {
                path: path.to_owned(),
            });
        }
        m.compute_normals();
        Ok(m)
    }

    /// The mesh as OBJ text (`v` and `f` lines), every coordinate written with the shortest
    /// decimal that reads back to the same `f64`: [`TriMesh::parse_obj`] gives this mesh
    /// again, bit for bit.
    pub fn to_obj(&self) -> String {
        use std::fmt::Write;
        let mut s = String::with_capacity(self.v.len() * 60 + self.f.len() * 24);
        for p in &self.v {
            let _ = writeln!(s, "v {} {} {}", p.x, p.y, p.z);
        }
        for f in &self.f {
            let _ = writeln!(s, "f {} {} {}", f[0] + 1, f[1] + 1, f[2] + 1);
        }
        s
    }

    /// Angle-weighted vertex normals from the faces' orientation.
    pub fn compute_normals(&mut self) {
        let mut n = vec![Vector3::zeros(); self.v.len()];
        for f in &self.f {
            let p = f.map(|i| self.v[i as usize]);
            let fnorm = (p[1] - p[0]).cross(&(p[2] - p[0]));
            let len = fnorm.norm();
            if len <= 0.0 {
                continue; // degenerate triangle: no direction to contribute
            }
            let fnorm = fnorm / len;
            for k in 0..3 {
                let a = (p[(k + 1) % 3] - p[k]).normalize();
                let b = (p[(k + 2) % 3] - p[k]).normalize();
                let ang = a.dot(&b).clamp(-1.0, 1.0).acos();
                n[f[k] as usize] += fnorm * ang;
            }
        }
        self.n = n
            .into_iter()
            .map(|x| {
                let l = x.norm();
                if l > 0.0 {
                    x / l
                } else {
                    Vector3::z()
                }
            })
            .collect();
    }

    /// Applies `x ↦ s·x + t` (normals unchanged).
    pub fn transform(&mut self, s: f64, t: Vector3<f64>) {
        for p in &mut self.v {
            *p = *p * s + t;
        }
    }

    /// Flips the orientation (faces and normals).
    pub fn flip(&mut self) {
        for f in &mut self.f {
            f.swap(1, 2);
        }
        for n in &mut self.n {
            *n = -*n;
        }
    }

    /// Axis-aligned bounds `(min, max)`.
    pub fn bounds(&self) -> (Vector3<f64>, Vector3<f64>) {
        let mut lo = Vector3::repeat(f64::MAX);
        let mut hi = Vector3::repeat(f64::MIN);
        for p in &self.v {
            lo = lo.inf(p);
            hi = hi.sup(p);
        }
        (lo, hi)
    }

    /// The boundary loops (edges used by one face), as vertex index cycles.
    pub fn boundary_loops(&self) -> Vec<Vec<u32>> {
        let mut count: HashMap<(u32, u32), u32> = HashMap::new();
        for f in &self.f {
            for k in 0..3 {
                let (a, b) = (f[k], f[(k + 1) % 3]);
                *count.entry((a.min(b), a.max(b))).or_default() += 1;
            }
        }
        // Directed boundary edges, following the faces' orientation.
        let mut next: HashMap<u32, u32> = HashMap::new();
        for f in &self.f {
            for k in 0..3 {
                let (a, b) = (f[k], f[(k + 1) % 3]);
                if count[&(a.min(b), a.max(b))] == 1 {
                    next.insert(a, b);
                }
            }
        }
        let mut loops = Vec::new();
        let mut starts: Vec<u32> = next.keys().copied().collect();
        starts.sort_unstable();
        let mut seen = std::collections::HashSet::new();
        for s in starts {
            if seen.contains(&s) {
                continue;
            }
            let mut lp = vec![s];
            seen.insert(s);
            let mut c = s;
            while let Some(&n) = next.get(&c) {
                if n == s || !seen.insert(n) {
                    break;
                }
                lp.push(n);
                c = n;
            }
            loops.push(lp);
        }
        loops
    }

    /// The section by the plane `normal · x = offset`: polylines of `(point, unit normal)`;
    /// `closed` tells whether each is a loop.
    pub fn slice(&self, normal: &Vector3<f64>, offset: f64) -> Vec<Section> {
        // Vertices exactly on the plane count as above it (symbolic perturbation), so every
        // crossing lies strictly inside an edge.
        let s: Vec<f64> = self.v.iter().map(|p| normal.dot(p) - offset).collect();
        let above = |i: u32| s[i as usize] >= 0.0;
        let key = |a: u32, b: u32| (a.min(b), a.max(b));
        let mut adj: HashMap<(u32, u32), Vec<(u32, u32)>> = HashMap::new();
        for f in &self.f {
            let mut cut = Vec::with_capacity(2);
            for k in 0..3 {
                let (a, b) = (f[k], f[(k + 1) % 3]);
                if above(a) != above(b) {
                    cut.push(key(a, b));
                }
            }
            if cut.len() == 2 {
                adj.entry(cut[0]).or_default().push(cut[1]);
                adj.entry(cut[1]).or_default().push(cut[0]);
            }
        }
        let point = |(a, b): (u32, u32)| {
            let (sa, sb) = (s[a as usize], s[b as usize]);
            let t = sa / (sa - sb);
            let p = self.v[a as usize] + (self.v[b as usize] - self.v[a as usize]) * t;
            let n = self.n[a as usize] + (self.n[b as usize] - self.n[a as usize]) * t;
            (p, n.normalize())
        };
        let mut keys: Vec<(u32, u32)> = adj.keys().copied().collect();
        keys.sort_unstable();
        let mut used = std::collections::HashSet::new();
        let mut out = Vec::new();
        // Open chains first (start at an end: one neighbour), then loops.
        for pass in 0..2 {
            for &k in &keys {
                if used.contains(&k) || (pass == 0 && adj[&k].len() != 1) {
                    continue;
                }
                let mut chain = vec![k];
                used.insert(k);
                let mut cur = k;
                loop {
                    let next = adj[&cur].iter().find(|e| !used.contains(*e)).copied();
                    match next {
                        Some(n) => {
                            used.insert(n);
                            chain.push(n);
                            cur = n;
                        }
                        None => break,
                    }
                }
                let closed = pass == 1 && adj[&cur].contains(&k) && chain.len() > 2;
                let (points, normals) = chain.into_iter().map(point).unzip();
                out.push(Section {
                    points,
                    normals,
                    closed,
                });
            }
        }
        out
    }
}

/// Largest mesh file read (a scene's OBJ): 256 MB.
pub const MAX_MESH_BYTES: u64 = 256 << 20;

/// Reads a mesh file: a regular file of at most [`MAX_MESH_BYTES`].
fn read_bounded(path: &Path) -> std::io::Result<String> {
    crate::named_file::read_text(path, MAX_MESH_BYTES, "a mesh")
}

/// One connected piece of a plane section.
#[derive(Debug, Clone)]
pub struct Section {
    pub points: Vec<Vector3<f64>>,
    pub normals: Vec<Vector3<f64>>,
    pub closed: bool,
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A unit square in the xy plane split into two triangles, normals up.
    fn square() -> TriMesh {
        let mut m = TriMesh {
            v: vec![
                Vector3::new(0.0, 0.0, 0.0),
                Vector3::new(1.0, 0.0, 0.0),
                Vector3::new(1.0, 1.0, 0.0),
                Vector3::new(0.0, 1.0, 0.0),
            ],
            f: vec![[0, 1, 2], [0, 2, 3]],
            n: vec![],
        };
        m.compute_normals();
        m
    }

    #[test]
    fn normals_boundary_and_slice_of_a_square() {
        let m = square();
        assert!(m.n.iter().all(|n| (n - Vector3::z()).norm() < 1e-12));
        let loops = m.boundary_loops();
        assert_eq!(loops.len(), 1);
        assert_eq!(loops[0].len(), 4);
        let s = m.slice(&Vector3::x(), 0.25);
        assert_eq!(s.len(), 1);
        assert!(!s[0].closed);
        for p in &s[0].points {
            assert!((p.x - 0.25).abs() < 1e-12);
        }
        let ys: Vec<f64> = s[0].points.iter().map(|p| p.y).collect();
        assert!(ys.iter().any(|&y| y.abs() < 1e-12) && ys.iter().any(|&y| (y - 1.0).abs() < 1e-12));
    }

    #[test]
    fn obj_errors_name_the_line() {
        let dir = std::env::temp_dir().join(format!("sfs-obj-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("bad.obj");
        std::fs::write(&p, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n").unwrap();
        let e = TriMesh::load_obj(&p).unwrap_err().to_string();
        assert!(e.contains(":4:") && e.contains("out of range"), "{e}");
        std::fs::write(&p, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
        assert_eq!(TriMesh::load_obj(&p).unwrap().f.len(), 1);
        assert!(TriMesh::load_obj(&dir)
            .unwrap_err()
            .to_string()
            .contains("not a regular file"));
    }

    #[test]
    fn obj_text_reads_back_bit_for_bit() {
        let mut m = square();
        m.transform(0.1, Vector3::new(1.0 / 3.0, -2.0e-7, 1e300));
        let back = TriMesh::parse_obj(&m.to_obj(), Path::new("x.obj")).unwrap();
        assert_eq!(back.v, m.v);
        assert_eq!(back.f, m.f);
    }
}
