//! Issue 49, point 1: every node and every curve point has an uncertainty, and it is
//! calibrated: on simulated captures of seeds the calibration never saw (it was fitted on
//! seeds 1–4; BENCHMARKS.md "Trust" has the whole table), the nodes' true errors (the paper's
//! registration, `sfs eval`) against their σ.

mod common;

use device_protocol::DeviceKind;
use sfs::acquisition::{Acquisition, AcquisitionConfig};
use sfs::simulate::{self, scene, Profile};
use sfs_geometry::network::{NetworkParams, Reconstructor};

/// Each node's (true error, σ), m, of a simulated capture reconstructed with the device's
/// noise; and the curves' points' σ at their tags against their nodes'.
fn errors_and_sigmas(
    name: &str,
    device: DeviceKind,
    profile: Profile,
    seed: u64,
) -> Vec<(f64, f64)> {
    let s = scene::builtin(name).expect("shipped scene");
    let sim = simulate::run(&s, device, profile, seed);
    let scan = Acquisition::scan_bytes(&sim.bytes, AcquisitionConfig::default());
    let params = sfs::pipeline::for_device(&NetworkParams::default(), Some(device));
    let net = Reconstructor::new()
        .run(&scan.curves, &params)
        .expect("the capture reconstructs");
    let u = &net.uncertainty;
    // The points at the tags carry their node's σ; every point has one, finite.
    for c in &net.positions.curves {
        assert_eq!(c.sigma_m.len(), c.points.len(), "curve {}", c.index);
        assert!(
            c.sigma_m.iter().all(|s| s.is_finite() && *s > 0.0),
            "curve {}",
            c.index
        );
        for &(i, node) in &c.nodes {
            let (a, b) = (c.sigma_m[i], u.nodes[&node]);
            assert!(
                (a - b).abs() <= 1e-9 * b.max(1e-3),
                "curve {}, node {node}: {a} {b}",
                c.index
            );
        }
    }
    let e = sfs::eval::evaluate(&sim.truth, &sfs::gltf_out::as_read_network(&net.positions))
        .expect("evaluates");
    e.node_errors_m
        .iter()
        .map(|(k, err)| (*err, u.nodes[k]))
        .collect()
}

#[test]
fn issue_49_node_uncertainty_is_calibrated_on_unseen_seeds() {
    for device in [DeviceKind::Morphorider, DeviceKind::Phone] {
        let mut pairs = Vec::new();
        for name in ["bowl", "cone", "relief"] {
            for profile in [Profile::Default, Profile::Field] {
                pairs.extend(errors_and_sigmas(name, device, profile, 5));
            }
        }
        let rms = |v: &mut dyn Iterator<Item = f64>| {
            let (s, n) = v.fold((0.0, 0usize), |(s, n), x| (s + x * x, n + 1));
            (s / n as f64).sqrt()
        };
        let ratio = rms(&mut pairs.iter().map(|p| p.0)) / rms(&mut pairs.iter().map(|p| p.1));
        let within =
            |k: f64| pairs.iter().filter(|(e, s)| *e <= k * s).count() as f64 / pairs.len() as f64;
        eprintln!(
            "{device:?}: {} nodes, RMS error / RMS σ {ratio:.2}, within σ {:.2}, within 2σ {:.2}",
            pairs.len(),
            within(1.0),
            within(2.0)
        );
        // The issue's targets are [0.7, 1.4] and 90 % over many captures (BENCHMARKS.md); six
        // captures draw few loops' worth of noise, so the margin here is wider.
        assert!((0.55..1.8).contains(&ratio), "{device:?}: ratio {ratio:.2}");
        assert!(
            within(2.0) >= 0.85,
            "{device:?}: {:.2} within 2σ",
            within(2.0)
        );
        assert!(
            within(1.0) >= 0.4,
            "{device:?}: {:.2} within σ",
            within(1.0)
        );
    }
}

/// `sfs replay` of a simulated capture: its `report.json` and its summary (standard output).
fn replayed(tag: &str, sim: &simulate::Simulation) -> (serde_json::Value, String) {
    let dir = common::tmpdir(&format!("verdict-{tag}"));
    let capture = dir.join("capture.bin");
    std::fs::write(&capture, &sim.bytes).unwrap();
    let out = common::sfs()
        .arg("replay")
        .arg(&capture)
        .arg("--out")
        .arg(dir.join("out"))
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let report = common::read_report(&dir.join("out"));
    let _ = std::fs::remove_dir_all(&dir);
    (report, String::from_utf8_lossy(&out.stdout).into_owned())
}

/// Issue 49, point 3: the verdict on the whole scan, in `report.json` and the summary line.
/// The cone scanned cleanly is `good`; with a wrong node typed `suspect`, the tag named and
/// put on the node meant; a phone capture with a digit lost at a node of two curves `good`,
/// the digit put back; a network whose nodes are expected over 1.5 % of its size off
/// `inconsistent`; the cone with a late Enter `suspect`, the curve named with the keys that
/// rescan it.
#[test]
fn issue_49_the_verdict_on_the_whole_scan() {
    use sfs::simulate::planted::Planted;
    let s = scene::builtin("cone").unwrap();
    let m = DeviceKind::Morphorider;
    let (twin, out) = replayed("twin", &simulate::run(&s, m, Profile::Default, 2));
    let q = &twin["quality"];
    assert_eq!(q["verdict"], "good", "{q}");
    assert!(out.contains("scan: good ("), "{out}");
    let pct = q["expected_error_pct"].as_f64().unwrap();
    assert!(pct > 0.0 && pct < sfs::report::INCONSISTENT_PCT, "{q}");
    let rms = twin["nodes_sigma_m"]
        .as_object()
        .unwrap()
        .values()
        .map(|v| v.as_f64().unwrap().powi(2))
        .sum::<f64>()
        / twin["nodes_sigma_m"].as_object().unwrap().len() as f64;
    assert!((q["expected_error_m"].as_f64().unwrap() - rms.sqrt()).abs() < 1e-12);

    // A wrong node the loops refuse, a third of the cone's size off: put on the node its
    // curve lands on (repaired), and named.
    let wrong = simulate::run_planted(&s, m, Profile::Default, 2, Planted::WrongNode).unwrap();
    let fault = &wrong.truth.faults[0];
    let (report, out) = replayed("wrong", &wrong);
    let q = &report["quality"];
    assert_eq!(q["verdict"], "suspect", "{q}");
    assert!(out.contains("scan: suspect ("), "{out}");
    assert!(
        q["suspects"].as_array().unwrap().iter().any(|x| {
            x["curve"].as_u64() == Some(fault.curve as u64)
                && x["tag"].as_u64() == fault.tag.map(|t| t as u64)
                && x["repair"] == "retagged"
        }),
        "{q} for {fault:?}"
    );
    // Issue 52, no capture far off: the phone on the dense ellipsoid, field profile, seed 4
    // lost curve 0's index at node 7 and a digit of curve 4's 17 (received as 7), so node 7
    // was held by two curves that the loops blamed alike: kept, it was reconstructed 3.6 %
    // off, `inconsistent`. The tag typed while packets were lost, whose curve lands on 17, is
    // now put back there; the scan is `good`, the digit named.
    let ell = scene::builtin("ellipsoid-dense").unwrap();
    let lost = simulate::run(&ell, DeviceKind::Phone, Profile::Field, 4);
    let (report, out) = replayed("digit-lost", &lost);
    let q = &report["quality"];
    assert_eq!(q["verdict"], "good", "{q}");
    assert!(out.contains("a digit lost on the link put back"), "{out}");
    let put_back = q["suspects"]
        .as_array()
        .unwrap()
        .iter()
        .find(|x| x["curve"] == 4 && x["node"] == 7)
        .unwrap_or_else(|| panic!("{q}"));
    assert_eq!(put_back["repair"], "retagged", "{q}");
    assert_eq!(put_back["evidence"]["kept_as"], 17, "{q}");
    assert_eq!(put_back["evidence"]["digits_lost"], true, "{q}");
    // A network whose nodes are expected more than INCONSISTENT_PCT of its size off (its
    // loops do not close as the device's noise would) is `inconsistent`, suspects or not.
    let cone = scene::builtin("cone").unwrap().exact_scan();
    let mut net = Reconstructor::new()
        .run(&cone.curves, &NetworkParams::default())
        .unwrap();
    let diagonal = sfs_geometry::bbox_diagonal(net.positions.curves.iter().flat_map(|c| &c.points));
    net.uncertainty.noise.sigma_rms_m = 0.02 * diagonal;
    let mut quality = sfs::report::Quality::default();
    quality.judge(Some(&net));
    assert_eq!(quality.verdict, sfs::report::Verdict::Inconsistent);
    assert!(quality.expected_error_pct.unwrap() > sfs::report::INCONSISTENT_PCT);
    net.uncertainty.noise.sigma_rms_m = 0.005 * diagonal;
    quality.judge(Some(&net));
    assert_eq!(quality.verdict, sfs::report::Verdict::Good);

    let late = simulate::run_planted(&s, m, Profile::Default, 1, Planted::LateEnter).unwrap();
    let fault = &late.truth.faults[0];
    let (report, out) = replayed("late", &late);
    let q = &report["quality"];
    assert_eq!(q["verdict"], "suspect", "{q}");
    let kind_key = match report["curves"][fault.curve]["kind"].as_str().unwrap() {
        "boundary" => "B",
        "interior" => "I",
        "crease" => "K",
        _ => "G",
    };
    let named = &q["suspects"][0];
    assert_eq!(named["curve"].as_u64(), Some(fault.curve as u64), "{q}");
    assert_eq!(
        named["rescan"],
        format!("{} {kind_key} … E", fault.curve),
        "{q}"
    );
    assert!(
        out.contains(&format!("rescan with {} {kind_key} … E", fault.curve)),
        "{out}"
    );
}
