//! Writes the truth network of a truth file as a `network.glb` (the perfect reconstruction):
//! `cargo run --example truth_glb -- T.truth.json OUT.glb`. Used to check the output contract
//! and `sfs eval` against a known answer.
use nalgebra::Vector3;
use sfs::gltf_out::{network_glb, NetworkCurve};
fn main() {
    let a: Vec<String> = std::env::args().collect();
    let t = sfs::simulate::truth::Truth::load(std::path::Path::new(&a[1])).expect("truth");
    let curves: Vec<NetworkCurve> = t
        .curves
        .iter()
        .map(|c| NetworkCurve {
            index: c.index,
            kind: c.kind(),
            nodes: c.nodes.clone(),
            points: c.points.iter().map(|p| Vector3::from(*p)).collect(),
            normals: c.normals.iter().map(|p| Vector3::from(*p)).collect(),
            sigma_m: Vec::new(),
        })
        .collect();
    let nodes = t
        .nodes
        .iter()
        .map(|(k, p)| (k.parse().unwrap(), Vector3::from(*p)))
        .collect();
    std::fs::write(&a[2], network_glb(&curves, &nodes, None).expect("glb")).expect("write");
}
