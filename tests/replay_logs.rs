//! The curated replay logs: each is exactly what `replay-logs/regenerate.sh` produces (so a
//! simulator change cannot silently leave stale logs behind), and each replays through the
//! binary into the truth's curves.

use device_protocol::DeviceKind;
use sfs::simulate::{self, scene, Profile};
use std::path::Path;
use std::process::Command;

const LOGS: &[(&str, &str, DeviceKind, Profile, u64)] = &[
    (
        "cone-morphorider",
        "cone",
        DeviceKind::Morphorider,
        Profile::Default,
        1,
    ),
    (
        "sphere-octa-morphorider-field",
        "sphere-octa",
        DeviceKind::Morphorider,
        Profile::Field,
        2,
    ),
    ("bowl-phone", "bowl", DeviceKind::Phone, Profile::Default, 3),
];

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

#[test]
fn committed_logs_are_what_the_simulator_makes() {
    for &(name, sc, device, profile, seed) in LOGS {
        let s = scene::load(&scene::find(sc, &root().join("config/scenes"))).unwrap();
        let sim = simulate::run(&s, device, profile, seed);
        let bin = std::fs::read(root().join(format!("replay-logs/{name}.bin"))).unwrap();
        assert!(
            bin == sim.bytes,
            "{name}.bin is stale: run replay-logs/regenerate.sh"
        );
        let committed =
            std::fs::read(root().join(format!("replay-logs/{name}.truth.json"))).unwrap();
        assert!(
            committed == serde_json::to_vec(&sim.truth).unwrap(),
            "{name}.truth.json is stale: run replay-logs/regenerate.sh"
        );
    }
}

#[test]
fn logs_replay_into_the_truth_curves() {
    for &(name, ..) in LOGS {
        let out_dir = std::path::PathBuf::from(env!("CARGO_TARGET_TMPDIR"))
            .join(format!("logs-{}-{name}", std::process::id()));
        let out = Command::new(env!("CARGO_BIN_EXE_sfs"))
            .args(["--log", "off", "replay"])
            .arg(root().join(format!("replay-logs/{name}.bin")))
            .arg("--out")
            .arg(&out_dir)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{name}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        let report: serde_json::Value =
            serde_json::from_slice(&std::fs::read(out_dir.join("report.json")).unwrap()).unwrap();
        let truth: serde_json::Value = serde_json::from_slice(
            &std::fs::read(root().join(format!("replay-logs/{name}.truth.json"))).unwrap(),
        )
        .unwrap();
        let got: Vec<&serde_json::Value> = report["curves"]
            .as_array()
            .unwrap()
            .iter()
            .map(|c| &c["nodes"])
            .collect();
        let want: Vec<&serde_json::Value> = truth["curves"]
            .as_array()
            .unwrap()
            .iter()
            .map(|c| &c["nodes"])
            .collect();
        assert_eq!(got, want, "{name}: {}", report["warnings"]);
        let link = &report["link"];
        assert!(
            link["packets"]
                .as_object()
                .unwrap()
                .values()
                .map(|v| v.as_u64().unwrap())
                .sum::<u64>()
                > 10_000
        );
    }
}

/// The reconstruction of the clean Morphorider log scores within the reconstruction target
/// (mean ≤ 0.10 % of the diagonal) with `sfs eval`, its glb holds every curve and node, and
/// its surface has the cone's patches and lies within 0.10 % of the diagonal of the truth.
#[test]
fn cone_log_reconstructs_within_target() {
    let out_dir = std::path::PathBuf::from(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("logs-rec-{}", std::process::id()));
    let st = Command::new(env!("CARGO_BIN_EXE_sfs"))
        .args(["--log", "off", "replay"])
        .arg(root().join("replay-logs/cone-morphorider.bin"))
        .arg("--out")
        .arg(&out_dir)
        .status()
        .unwrap();
    assert!(st.success());
    let out = Command::new(env!("CARGO_BIN_EXE_sfs"))
        .args(["eval", "--truth"])
        .arg(root().join("replay-logs/cone-morphorider.truth.json"))
        .arg("--glb")
        .arg(out_dir.join("network.glb"))
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let e: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(e["registration"]["nodes_matched"], 12);
    let mean = e["curves"]["mean_pct"].as_f64().unwrap();
    assert!(mean <= 0.10, "mean {mean} % of the diagonal");
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out_dir.join("report.json")).unwrap()).unwrap();
    assert_eq!(report["nodes"].as_object().unwrap().len(), 12);
    assert_eq!(report["network"]["curves_used"], 7);
    // The surface: the cone's eight patches between its two rims, close to the truth surface.
    assert_eq!(report["surface"]["patches"], 8, "{}", report["surface"]);
    assert_eq!(report["surface"]["holes"], 2);
    assert_eq!(report["surface"]["euler"], 2);
    let s = e["surface"]["mean_pct"].as_f64().expect("a surface scored");
    assert!(s <= 0.10, "surface mean {s} % of the diagonal");
}
