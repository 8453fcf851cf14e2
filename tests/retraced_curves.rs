//! Issue 31, point 6: a session whose curves retrace each other (the demo capture appended to
//! itself: every curve scanned twice) keeps its network and its surface. The sliver faces
//! between retraced curves made a triangle that was degenerate once written in f32, and
//! network.glb was not written at all; a live session left the first curve's glb on disk
//! while report.json described fourteen.

mod common;
use common::{replay_to, run_stdin, tmpdir};
use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The demo capture twice over (the second copy is a device reboot and the same curves again).
fn twice() -> Vec<u8> {
    let one = std::fs::read(root().join("replay-logs/cone-morphorider.bin")).unwrap();
    [one.clone(), one].concat()
}

/// network.glb and report.json of `dir`, checked against each other: the same curves, the
/// surface's triangles, none of them degenerate in the file's own coordinates.
fn consistent(dir: &Path) -> (Vec<u8>, serde_json::Value) {
    let glb = std::fs::read(dir.join("network.glb")).expect("network.glb written");
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("report.json")).unwrap()).unwrap();
    let net = sfs::gltf_out::read_glb(&glb).unwrap();
    assert_eq!(
        net.curves.len() as u64,
        report["network"]["curves_used"].as_u64().unwrap(),
        "network.glb and report.json describe different updates"
    );
    let surface = net.surface.as_ref().expect("a surface");
    assert_eq!(
        surface.triangles.len() as u64,
        report["surface"]["triangles"].as_u64().unwrap()
    );
    assert!(surface.triangles.len() > 1000);
    for t in &surface.triangles {
        let [a, b, c] = t.map(|i| surface.positions[i as usize]);
        assert!(
            (b - a).cross(&(c - a)).norm() > 0.0,
            "a degenerate triangle"
        );
    }
    let warnings: Vec<&str> = report["warnings"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(|w| w.as_str())
        .collect();
    assert!(
        !warnings.iter().any(|w| w.contains("not written")),
        "{warnings:?}"
    );
    (glb, report)
}

#[test]
fn issue_31_curves_scanned_twice_keep_their_network_and_surface() {
    let dir = tmpdir("retraced");
    let capture = dir.join("twice.bin");
    std::fs::write(&capture, twice()).unwrap();
    replay_to(&capture, &dir.join("replayed"));
    let (replayed, report) = consistent(&dir.join("replayed"));
    assert_eq!(report["curves"].as_array().unwrap().len(), 14);

    // Live, after every curve: the final network.glb is the replay's, and report.json its.
    let mut child = run_stdin(&["--session"], &dir.join("live"));
    let mut stdin = child.stdin.take().unwrap();
    std::io::Write::write_all(&mut stdin, &twice()).unwrap();
    drop(stdin);
    let status = child.wait().unwrap();
    assert!(status.success(), "sfs run --stdin: {status}");
    let (live, _) = consistent(&dir.join("live"));
    assert!(
        live == replayed,
        "the live session's network.glb differs from the replay's"
    );
}
