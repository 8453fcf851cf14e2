//! Cycles from normals on the exact networks of every shipped scene: the expected number of
//! patches and holes, a consistent Euler characteristic (2 for sphere-like networks, 0 for the
//! torus), every segment in exactly two faces, and no problem reported.

use sfs::simulate::scene;
use sfs_geometry::surface::cycles::{cycles, HalfEdge, NetworkSegments};
use std::collections::BTreeMap;

fn network(name: &str) -> NetworkSegments {
    let s = scene::builtin(name).unwrap_or_else(|e| panic!("{e}"));
    let mut net = NetworkSegments::default();
    let mut sums: BTreeMap<u32, nalgebra::Vector3<f64>> = BTreeMap::new();
    for (ci, c) in s.curves.iter().enumerate() {
        for w in c.tags.windows(2) {
            let ((i, a), (j, b)) = (w[0], w[1]);
            net.push(
                ci,
                c.kind,
                (a, b),
                c.points[i..=j].to_vec(),
                c.normals[i..=j].to_vec(),
            );
        }
        for &(i, n) in &c.tags {
            *sums.entry(n).or_insert_with(nalgebra::Vector3::zeros) += c.normals[i];
        }
    }
    for (n, v) in sums {
        net.set_normal(n, v.normalize());
    }
    net
}

#[test]
fn every_scene_traces_a_consistent_cell_complex() {
    // (scene, patches, holes, Euler characteristic)
    check(&[
        ("sphere-cube", 6, 0, 2),
        ("sphere-octa", 8, 0, 2),
        ("torus", 8, 0, 0),
        ("cone", 8, 2, 2),
        ("bowl", 8, 1, 2),
        ("relief", 25, 1, 2),
        ("bumpy", 8, 0, 2),
        ("ellipsoid-dense", 22, 0, 2),
        ("parallel", 12, 1, 2),
    ]);
}

#[test]
#[cfg_attr(
    not(sfs_paper_data),
    ignore = "needs the paper's meshes (lilium.obj, bumpy-cube.obj): set SFS_PAPER_DATA to their directory"
)]
fn the_paper_scenes_trace_a_consistent_cell_complex() {
    check(&[("lilium", 25, 1, 2), ("bumpy-cube", 8, 0, 2)]);
}

fn check(expected: &[(&str, usize, usize, i64)]) {
    for &(name, patches, holes, euler) in expected {
        let net = network(name);
        let c = cycles(&net);
        eprintln!(
            "{name}: {} patches, {} holes, χ = {}, problems {:?}",
            c.patches.len(),
            c.outer.len(),
            c.euler,
            c.problems
        );
        assert!(c.problems.is_empty(), "{name}: {:?}", c.problems);
        let mut count: BTreeMap<HalfEdge, usize> = BTreeMap::new();
        for f in c.patches.iter().chain(&c.outer) {
            for h in &f.edges {
                *count.entry(*h).or_default() += 1;
            }
        }
        assert_eq!(count.len(), 2 * net.segments.len(), "{name}");
        assert!(count.values().all(|&n| n == 1), "{name}");
        assert_eq!(
            (c.patches.len(), c.outer.len(), c.euler),
            (patches, holes, euler),
            "{name}"
        );
    }
}
