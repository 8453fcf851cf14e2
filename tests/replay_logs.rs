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
        let s = scene::builtin(sc).unwrap();
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

/// The riser log (a sensor array, monitoring mode) is what the simulator makes, and replayed
/// with the shipped `config/riser.toml` it gives an epoch every 0.2 s, the top within 2 % of
/// the riser's length of the truth in `latest.glb`, and the alarm at 1.5 m raised as often
/// as the truth crosses it.
#[test]
fn riser_log_is_monitored_with_the_shipped_configuration() {
    use sfs::simulate::structure::{run, StructureKind};
    let (bytes, truth) = run(StructureKind::Riser, 1, 60.0, 10.0);
    let bin = std::fs::read(root().join("replay-logs/riser-array.bin")).unwrap();
    assert!(
        bin == bytes,
        "riser-array.bin is stale: run replay-logs/regenerate.sh"
    );
    let committed = std::fs::read(root().join("replay-logs/riser-array.truth.json")).unwrap();
    assert!(
        committed == serde_json::to_vec(&truth).unwrap(),
        "riser-array.truth.json is stale: run replay-logs/regenerate.sh"
    );
    let out_dir = std::path::PathBuf::from(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("logs-riser-{}", std::process::id()));
    let st = Command::new(env!("CARGO_BIN_EXE_sfs"))
        .args(["--log", "off", "replay"])
        .arg(root().join("replay-logs/riser-array.bin"))
        .arg("--config")
        .arg(root().join("config/riser.toml"))
        .arg("--out")
        .arg(&out_dir)
        .status()
        .unwrap();
    assert!(st.success());
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out_dir.join("report.json")).unwrap()).unwrap();
    let m = &report["monitor"];
    assert_eq!(m["epochs"], 300, "{m}");
    assert_eq!(m["failed"], 0);
    // The truth's top (the last sensor), every second; the reference is the mean of the
    // first 10 s, the alarm at 1.5 m with 0.2 m of hysteresis (config/riser.toml).
    let top =
        |e: &sfs::simulate::structure::Epoch| nalgebra::Vector3::from(*e.positions.last().unwrap());
    let reference = truth
        .epochs
        .iter()
        .filter(|e| e.t < 10.0)
        .map(top)
        .sum::<nalgebra::Vector3<f64>>()
        / truth.epochs.iter().filter(|e| e.t < 10.0).count() as f64;
    let (mut episodes, mut below) = (0, true);
    for e in &truth.epochs {
        let d = (top(e) - reference).norm();
        if below && d > 1.5 {
            episodes += 1;
            below = false;
        } else if d < 1.3 {
            below = true;
        }
    }
    assert!(episodes >= 1);
    assert_eq!(m["alarms_raised"], episodes);
    let net = sfs::gltf_out::read_glb(&std::fs::read(out_dir.join("latest.glb")).unwrap()).unwrap();
    let t_last = report["monitor"]["epochs"].as_f64().unwrap() / 5.0;
    let end = truth
        .epochs
        .iter()
        .min_by(|a, b| (a.t - t_last).abs().total_cmp(&(b.t - t_last).abs()))
        .unwrap();
    let got = net.nodes[&1] - net.nodes[&0];
    assert!(
        (got - top(end)).norm() < 0.02 * truth.size,
        "top {got:?}, truth {:?} at {} s",
        top(end),
        end.t
    );
}
