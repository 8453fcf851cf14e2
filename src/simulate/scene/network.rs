//! A scene's nodes: every crossing of two curves and every end of an open curve, found (not
//! declared), inserted exactly into the polylines, and every curve tagged with them.

use super::super::surface::Surface;
use super::curve_spec::{arclen, closest, Piece};
use super::SceneCurve;
use nalgebra::Vector3;

/// The scene's curves and its nodes (by index).
pub(super) type Network = (Vec<SceneCurve>, Vec<Vector3<f64>>);

/// Finds the nodes (crossings and open ends), inserts them exactly into the polylines, and
/// tags every curve.
pub(super) fn network(s: &Surface, pieces: Vec<Piece>, h: f64) -> Result<Network, (usize, String)> {
    let tol = h;
    let mut cand: Vec<Vector3<f64>> = Vec::new();
    for (i, a) in pieces.iter().enumerate() {
        if !a.closed {
            cand.push(a.points[0]);
            cand.push(*a.points.last().expect("non-empty"));
        }
        cand.extend(&a.nodes);
        for b in pieces.iter().skip(i + 1) {
            cand.extend(crossings(s, a, b, tol));
        }
    }
    // Merge candidates closer than 2 h; keep the first.
    let mut nodes: Vec<Vector3<f64>> = Vec::new();
    for c in cand {
        if nodes.iter().all(|n| (n - c).norm() > 2.0 * tol) {
            nodes.push(c);
        }
    }
    // Tag each curve; order nodes by first appearance along the curves in scene order.
    let mut order: Vec<Option<u32>> = vec![None; nodes.len()];
    let mut next = 0u32;
    let mut curves = Vec::new();
    for (ci, pc) in pieces.into_iter().enumerate() {
        let mut pts = pc.points;
        let mut nrm = pc.normals;
        let c = arclen(&pts);
        let mut on: Vec<(f64, usize)> = Vec::new();
        for (k, nd) in nodes.iter().enumerate() {
            let (i, u, d) = closest(&pts, nd);
            if d <= tol {
                on.push((c[i] + (c[i + 1] - c[i]) * u, k));
            }
        }
        on.sort_by(|a, b| a.0.total_cmp(&b.0));
        if on.len() < if pc.closed { 1 } else { 2 } {
            return Err((
                ci,
                format!(
                    "crosses {} node(s); a curve needs two ends (or a node on its loop)",
                    on.len()
                ),
            ));
        }
        // Insert the node positions exactly (from the end, so earlier indices stay valid).
        let mut tag_pos: Vec<(f64, usize)> = Vec::new();
        for &(sv, k) in on.iter().rev() {
            let cc = arclen(&pts);
            let i = cc.partition_point(|&x| x <= sv).clamp(1, pts.len() - 1);
            let (a, b) = (cc[i - 1], cc[i]);
            let u = if b > a { (sv - a) / (b - a) } else { 0.0 };
            let nn = (nrm[i - 1] + (nrm[i] - nrm[i - 1]) * u).normalize();
            let near_prev = (nodes[k] - pts[i - 1]).norm() < h * 0.25;
            let near_next = (nodes[k] - pts[i]).norm() < h * 0.25;
            if near_prev {
                pts[i - 1] = nodes[k];
            } else if near_next {
                pts[i] = nodes[k];
            } else {
                pts.insert(i, nodes[k]);
                nrm.insert(i, nn);
            }
            tag_pos.push((sv, k));
        }
        tag_pos.reverse();
        // Point index of each tag.
        let mut tags: Vec<(usize, u32)> = Vec::new();
        for &(_, k) in &tag_pos {
            let idx = pts
                .iter()
                .enumerate()
                .min_by(|a, b| (a.1 - nodes[k]).norm().total_cmp(&(b.1 - nodes[k]).norm()))
                .map(|x| x.0)
                .expect("non-empty");
            let id = *order[k].get_or_insert_with(|| {
                next += 1;
                next - 1
            });
            tags.push((idx, id));
        }
        if pc.closed {
            // Start the loop at its first node; end there again.
            let first = tags[0].0;
            let m = pts.len() - 1; // last == first
            let mut p2: Vec<Vector3<f64>> = (0..m).map(|j| pts[(first + j) % m]).collect();
            let mut n2: Vec<Vector3<f64>> = (0..m).map(|j| nrm[(first + j) % m]).collect();
            p2.push(p2[0]);
            n2.push(n2[0]);
            let mut t2: Vec<(usize, u32)> = tags
                .iter()
                .map(|&(i, id)| ((i + m - first) % m, id))
                .collect();
            t2.sort_by_key(|t| t.0);
            t2.push((m, t2[0].1));
            pts = p2;
            nrm = n2;
            tags = t2;
        } else {
            // Trim to the first and last node.
            let (a, b) = (tags[0].0, tags.last().expect("two").0);
            pts = pts[a..=b].to_vec();
            nrm = nrm[a..=b].to_vec();
            for t in &mut tags {
                t.0 -= a;
            }
        }
        curves.push(SceneCurve {
            points: pts,
            normals: nrm,
            kind: pc.kind,
            closed: pc.closed,
            tags,
        });
    }
    // Node positions by their index.
    let mut by_index = vec![Vector3::zeros(); next as usize];
    for (k, o) in order.iter().enumerate() {
        if let Some(id) = o {
            by_index[*id as usize] = nodes[k];
        }
    }
    Ok((curves, by_index))
}

/// Where curve `b`'s plane cuts curve `a` at a point of `b`.
pub(super) fn crossings(s: &Surface, a: &Piece, b: &Piece, tol: f64) -> Vec<Vector3<f64>> {
    let mut out = Vec::new();
    let Some((nb, db)) = b.plane else {
        // A non-planar curve (mesh boundary): crossings are ends of other curves, found as ends.
        return out;
    };
    for w in a.points.windows(2) {
        let (s0, s1) = (nb.dot(&w[0]) - db, nb.dot(&w[1]) - db);
        if (s0 < 0.0) == (s1 < 0.0) || s0 == s1 {
            continue;
        }
        let t = s0 / (s0 - s1);
        let mut p = w[0] + (w[1] - w[0]) * t;
        // On an analytic surface, snap onto the line where both planes meet.
        if let (Some((na, _)), Some(_)) = (a.plane, s.implicit(&p)) {
            let u = na.cross(&nb);
            if u.norm() > 1e-9 {
                let u = u.normalize();
                for _ in 0..30 {
                    let Some((f, g)) = s.implicit(&p) else { break };
                    let gu = g.dot(&u);
                    if gu.abs() < 1e-12 {
                        break;
                    }
                    p -= u * (f / gu);
                    if f.abs() < 1e-13 {
                        break;
                    }
                }
            }
        }
        if closest(&b.points, &p).2 <= tol {
            out.push(p);
        }
    }
    out
}
