//! The surfacer on analytic networks and on simulated scans: watertight, consistently oriented,
//! finite, no degenerate triangle, valid glb; accuracy on the unit sphere against the paper's
//! Table 1 target; bad input (an open network, a dangling curve) surfaces what it can.

use sfs_geometry::surface::analytic::{
    sphere_circles, sphere_cube, sphere_distance, torus, torus_distance, torus_with_parallels,
};
use sfs_geometry::surface::cycles::NetworkSegments;
use sfs_geometry::surface::fit::{surface, Method, SurfaceParams, Surfaced};
use std::collections::BTreeMap;

/// Every directed edge once and its twin once (closed, consistently oriented, watertight),
/// except along `open` boundary edges; finite; no degenerate triangle; a valid glb.
fn check_mesh(s: &Surfaced, closed: bool) {
    let mut directed: BTreeMap<(u32, u32), usize> = BTreeMap::new();
    for t in &s.triangles {
        for k in 0..3 {
            *directed.entry((t[k], t[(k + 1) % 3])).or_default() += 1;
        }
        let [a, b, c] = t.map(|i| s.positions[i as usize]);
        assert!((b - a).cross(&(c - a)).norm() > 0.0, "degenerate {t:?}");
    }
    assert!(
        directed.values().all(|&n| n == 1),
        "an edge used twice in one direction"
    );
    let open = directed
        .keys()
        .filter(|(a, b)| !directed.contains_key(&(*b, *a)))
        .count();
    if closed {
        assert_eq!(open, 0, "the mesh has {open} open edges");
    }
    assert!(s.positions.iter().all(|p| p.iter().all(|x| x.is_finite())));
    assert!(s.normals.iter().all(|n| (n.norm() - 1.0).abs() < 1e-9));
    let glb = sfs::gltf_out::network_glb(&[], &BTreeMap::new(), Some(&s.mesh())).unwrap();
    let back = sfs::gltf_out::read_glb(&glb).unwrap();
    assert_eq!(back.surface.unwrap().triangles.len(), s.triangles.len());
}

fn mean_distance(s: &Surfaced) -> f64 {
    let free = &s.positions[s.constrained..];
    free.iter().map(sphere_distance).sum::<f64>() / free.len() as f64
}

#[test]
fn sphere_networks_meet_the_paper_target_and_beat_biharmonic() {
    for (name, net) in [
        ("cube network", sphere_cube(0.04)),
        ("three circles", sphere_circles(0.04)),
    ] {
        let p = SurfaceParams {
            edge: Some(0.054),
            ..Default::default()
        };
        let ours = surface(&net, &p).unwrap();
        check_mesh(&ours, true);
        assert!(ours.problems.is_empty(), "{name}: {:?}", ours.problems);
        let bih = surface(
            &net,
            &SurfaceParams {
                method: Method::Biharmonic,
                reweight: 0,
                ..p
            },
        )
        .unwrap();
        let (m, b) = (mean_distance(&ours), mean_distance(&bih));
        eprintln!("{name}: ours {m:.5}, biharmonic {b:.5}");
        // Paper, Table 1: ours 0.0319, biharmonic 0.1465; issue target ≤ 0.008.
        assert!(m <= 0.008, "{name}: mean distance {m}");
        assert!(m < b / 4.0, "{name}: {m} vs biharmonic {b}");
        // The free vertices lie outside the constrained ones' convex hull pull: the surface
        // bulges like the sphere (not a flat membrane).
        let far = ours.positions[ours.constrained..]
            .iter()
            .map(|p| p.norm())
            .fold(f64::MAX, f64::min);
        assert!(far > 0.97, "{name}: a free vertex at radius {far}");
    }
}

/// Table 1's torus (R = 4, r = 2, four meridians and two parallels), the parallels on the top
/// and bottom circles and on the equators. On the first, the patches outside the tube span
/// its whole outer half: seen along their average normal they are edge-on at the parallels,
/// and their projected triangulation lifted to slivers (mean 0.68 before the projection
/// was refused there, see `tessellate::MAX_SHRINK`).
#[test]
fn torus_networks_meet_the_paper_target_and_beat_biharmonic() {
    for (name, net) in [
        ("top and bottom parallels", torus(0.2)),
        ("equator parallels", torus_with_parallels(0.2, 0.0)),
    ] {
        let p = SurfaceParams {
            edge: Some(0.27),
            ..Default::default()
        };
        let ours = surface(&net, &p).unwrap();
        check_mesh(&ours, true);
        let bih = surface(
            &net,
            &SurfaceParams {
                method: Method::Biharmonic,
                reweight: 0,
                ..p
            },
        )
        .unwrap();
        let mean = |s: &Surfaced| {
            let free = &s.positions[s.constrained..];
            free.iter().map(torus_distance).sum::<f64>() / free.len() as f64
        };
        let (m, b) = (mean(&ours), mean(&bih));
        eprintln!("{name}: ours {m:.5}, biharmonic {b:.5}");
        // Paper, Table 1: ours 0.1260, biharmonic 0.4122; issue target ≤ 0.04.
        assert!(m <= 0.04, "{name}: mean distance {m}");
        assert!(m < b / 4.0, "{name}: {m} vs biharmonic {b}");
    }
}

#[test]
fn an_open_network_and_a_dangling_curve_surface_what_they_can() {
    let mut net = sphere_cube(0.05);
    // Remove the four edges of the top face (z > 0 corners 4..7) but one: the top is open,
    // and the last top edge dangles.
    let top = |s: &sfs_geometry::surface::cycles::Segment| s.a >= 4 && s.b >= 4;
    let mut kept = NetworkSegments {
        segments: Vec::new(),
        normals: net.normals.clone(),
    };
    let mut dropped = 0;
    for s in net.segments.drain(..) {
        if top(&s) && dropped < 3 {
            dropped += 1;
            continue;
        }
        kept.segments.push(s);
    }
    let out = surface(&kept, &SurfaceParams::default()).unwrap();
    check_mesh(&out, false);
    // The open side merges into one face that runs along the dangling top edge both ways:
    // rejected with the curve named; the bottom and the side under the kept edge surface.
    assert!(
        out.problems.iter().any(|p| matches!(
            p,
            sfs_geometry::surface::SurfaceProblem::BothDirections { .. }
        )),
        "{:?}",
        out.problems
    );
    assert_eq!(out.cycles.rejected.len(), 1);
    assert_eq!(out.cycles.patches.len(), 2, "{:?}", out.problems);
    // Nothing at all to surface: an error, not a panic.
    let lone = NetworkSegments {
        segments: kept.segments[..1].to_vec(),
        normals: kept.normals.clone(),
    };
    assert!(surface(&lone, &SurfaceParams::default()).is_err());
}

#[test]
fn the_same_network_gives_the_same_surface() {
    let net = sphere_circles(0.08);
    let a = surface(&net, &SurfaceParams::default()).unwrap();
    let b = surface(&net, &SurfaceParams::default()).unwrap();
    assert_eq!(a.positions, b.positions);
    assert_eq!(a.triangles, b.triangles);
}

/// The paper's Figure 7: positions and normals along the network perturbed by noise; soft
/// constraints give a surface closer to the truth than hard ones.
#[test]
fn soft_constraints_beat_hard_ones_on_noisy_input() {
    let mut net = sphere_cube(0.04);
    let mut s = 0x9E3779B97F4A7C15u64;
    let mut r = || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    };
    for seg in &mut net.segments {
        let m = seg.points.len();
        for k in 1..m - 1 {
            let d = nalgebra::Vector3::new(r(), r(), r()) * 0.02;
            seg.points[k] += d;
            seg.normals[k] =
                (seg.normals[k] + nalgebra::Vector3::new(r(), r(), r()) * 0.05).normalize();
        }
    }
    let p = SurfaceParams {
        edge: Some(0.054),
        ..Default::default()
    };
    let hard = surface(&net, &p).unwrap();
    let mut line = format!("hard {:.5}", mean_distance(&hard));
    let sessions = sfs::pipeline::SCAN_SOFTNESS.expect("sessions use soft constraints");
    let mut at_default = f64::MAX;
    for w in [0.01, 0.1, sessions, 1.0] {
        let soft = surface(&net, &SurfaceParams { soft: Some(w), ..p }).unwrap();
        check_mesh(&soft, true);
        let d = mean_distance(&soft);
        line += &format!(", soft {w}: {d:.5}");
        assert!(d < mean_distance(&hard), "{line}");
        if w == sessions {
            at_default = d;
        }
    }
    eprintln!("{line}");
    // The sessions' weight removes a good part of the noise.
    assert!(at_default < 0.6 * mean_distance(&hard), "{line}");
}

/// A network sampled ten times finer than the surface's edge: the patch rims keep samples
/// about half an edge apart (`NetworkSegments::decimated`), so the vertex count follows the
/// edge, not the sampling (without it: a band of graded triangles along every curve), and the
/// mesh stays closed and accurate.
#[test]
fn a_finely_sampled_network_keeps_a_light_rim() {
    let fine = sphere_cube(0.004);
    let a = surface(&fine, &SurfaceParams::default()).unwrap();
    check_mesh(&a, true);
    assert!(a.problems.is_empty(), "{:?}", a.problems);
    let m = mean_distance(&a);
    assert!(m <= 0.008, "mean distance {m}");
    // The default edge here is at least 1/120 of the diagonal (0.029): the fine network gives
    // about the vertices of a lattice of that edge, not of its 4 mm sampling.
    let budget = 4.0 * std::f64::consts::PI / (3f64.sqrt() / 2.0 * 0.029f64.powi(2));
    assert!(
        (a.positions.len() as f64) < 1.5 * budget,
        "{} vertices, lattice {budget:.0}",
        a.positions.len()
    );
    assert!(a.constrained < fine.segments.iter().map(|s| s.points.len()).sum::<usize>() / 3);
}
