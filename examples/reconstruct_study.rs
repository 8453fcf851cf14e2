//! Parameter study of the reconstruction: replays a capture's scan through the network stages
//! with the given settings and scores it against the truth.
//! `cargo run --release --example reconstruct_study -- CAPTURE TRUTH [h sigma bend stretch xi]`
//! (`bend` < 0: pre-filter only).
use sfs::acquisition::{Acquisition, AcquisitionConfig};
use sfs_geometry::network::{NetworkParams, Reconstructor};
fn main() {
    sfs_geometry::sparse_llt::single_threaded();
    let a: Vec<String> = std::env::args().collect();
    let bytes = std::fs::read(&a[1]).expect("capture");
    let truth = sfs::simulate::truth::Truth::load(std::path::Path::new(&a[2])).expect("truth");
    let num = |i: usize, d: f64| a.get(i).and_then(|s| s.parse().ok()).unwrap_or(d);
    // SFS_MOUNT="ax,ay,az,deg": a known mounting rotation for the calibration.
    let mut cfg = AcquisitionConfig::default();
    if let Ok(m) = std::env::var("SFS_MOUNT") {
        let v: Vec<f64> = m.split(',').filter_map(|x| x.parse().ok()).collect();
        let axis = nalgebra::Unit::new_normalize(nalgebra::Vector3::new(v[0], v[1], v[2]));
        cfg.calibration.mounting = nalgebra::Rotation3::from_axis_angle(&axis, v[3].to_radians());
    }
    let scan = Acquisition::scan_bytes(&bytes, cfg);
    let mut p = NetworkParams::default();
    p.prefilter.h = num(3, p.prefilter.h);
    p.prefilter.sigma = num(4, p.prefilter.sigma);
    // bend: < 0 pre-filter only; 0 the default (a fraction of the size); > 0 metres.
    let bend = num(5, 0.0);
    p.no_regression = bend < 0.0;
    p.regression.bend_length = (bend > 0.0).then_some(bend);
    p.regression.stretch_length = num(6, 0.0);
    p.regression.xi = num(7, p.regression.xi);
    let net = Reconstructor::new().run(&scan.curves, &p).expect("network");
    let rec = sfs::gltf_out::as_read_network(&net.positions);
    let e = sfs::eval::evaluate(&truth, &rec).expect("eval");
    print!("{} samples: ", net.report.samples);
    println!("mean {:.4}% max {:.4}% node-normals {:.2}° iters {} E {:.3e}→{:.3e} t(pre {:.1} reg {:.1} poi {:.1} ms)",
        e.curves.mean_pct, e.curves.max_pct, net.report.max_node_normal_angle_deg, net.report.regression.iterations,
        net.report.regression.energy_initial, net.report.regression.energy_final,
        net.report.timings_ms.prefilter, net.report.timings_ms.regression, net.report.timings_ms.poisson);
}
