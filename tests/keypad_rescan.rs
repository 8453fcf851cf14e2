//! Issue 49, point 4: a curve rescanned from the keypad (`N B … E`) gives the same outputs
//! live, resumed after a kill in the middle of the rescan, and replayed: the keys are in the
//! capture.

mod common;
use common::*;
use sfs::simulate::{self, planted::Planted, scene, Mistakes, Profile};

#[test]
fn issue_49_a_rescan_resumed_after_a_kill_gives_the_replays_network() {
    let dir = tmpdir("rescan-resume");
    let s = scene::builtin("cone").unwrap();
    let kind = device_protocol::DeviceKind::Morphorider;
    let plan = simulate::planted::plan(Planted::WrongNode, &s, 2, &Mistakes::default()).unwrap();
    let more = Mistakes {
        rescan: Some(plan.curve()),
        ..Default::default()
    };
    let sim = simulate::run_planted_with(&s, kind, Profile::Default, 2, &more, Planted::WrongNode)
        .unwrap();
    let bytes = sim.bytes;
    // The rescan is the last eighth of the capture or so: killed in its middle.
    let (first, rest) = bytes.split_at(bytes.len() * 15 / 16);
    let session = dir.join("session");
    killed_then_resumed(&session, first, rest);
    assert_eq!(std::fs::read(session.join("capture.bin")).unwrap(), bytes);
    replay_to(&session.join("capture.bin"), &dir.join("replayed"));
    assert_same_files(&session, &dir.join("replayed"), &["network.glb"], "resumed");
    let scan: serde_json::Value =
        serde_json::from_slice(&std::fs::read(session.join("scan.json")).unwrap()).unwrap();
    assert_eq!(scan["dropped"][0]["curve"], plan.curve());
    assert_eq!(read_report(&session)["network"]["curves_used"], 7);
}
