//! Issue 49, point 2: `sfs simulate --fault` plants one fault, placed and sized on a random
//! stream of its own, so that the rest of the capture is its unfaulted twin's (same seed); the
//! truth's `faults` says where. Checked on the decoded bytes and on what acquisition makes of
//! them, against the twin.

mod common;
use common::{eval, read_report, replay_to, tmpdir};
use device_protocol::{Decoder, DeviceKind, Event, Packet};
use sfs::acquisition::{Acquisition, AcquisitionConfig};
use sfs::scan::Scan;
use sfs::simulate::planted::Planted;
use sfs::simulate::{self, scene, Profile, Simulation};

fn packets(bytes: &[u8]) -> Vec<Packet> {
    let mut dec = Decoder::new();
    dec.feed(bytes)
        .filter_map(|e| match e {
            Event::Packet { packet, .. } => Some(packet),
            _ => None,
        })
        .collect()
}

fn acquire(bytes: &[u8]) -> Scan {
    Acquisition::scan_bytes(bytes, AcquisitionConfig::default())
}

fn twin_and(device: DeviceKind, seed: u64, kind: Planted) -> (Simulation, Simulation) {
    let s = scene::builtin("cone").unwrap();
    let twin = simulate::run(&s, device, Profile::Default, seed);
    let faulted = simulate::run_planted(&s, device, Profile::Default, seed, kind).unwrap();
    (twin, faulted)
}

/// A segment's length as acquired: the distance between two tags of a curve.
fn segment(scan: &Scan, curve: usize, k: usize) -> f64 {
    let t = &scan.curves[curve].tags;
    t[k + 1].d - t[k].d
}

#[test]
fn issue_49_a_wrong_node_changes_only_the_keys_typed() {
    for seed in [1, 2, 3] {
        let (twin, faulted) = twin_and(DeviceKind::Morphorider, seed, Planted::WrongNode);
        let f = &faulted.truth.faults[0];
        assert_eq!(f.kind, "wrong-node");
        let (tag, node) = (f.tag.unwrap(), f.node.unwrap());
        let typed = f.details["typed_node"].as_u64().unwrap() as u32;
        assert_ne!(typed, node);
        assert_eq!(typed.to_string().len(), node.to_string().len());
        // The truth is the twin's: the device stood at the true node.
        assert_eq!(twin.truth.curves, faulted.truth.curves);
        assert_eq!(faulted.truth.curves[f.curve].nodes[tag], node);
        // Packet for packet the same, but the digits of one index.
        let (a, b) = (packets(&twin.bytes), packets(&faulted.bytes));
        assert_eq!(a.len(), b.len());
        let differ: Vec<_> = a.iter().zip(&b).filter(|(x, y)| x != y).collect();
        assert!(!differ.is_empty() && differ.len() <= node.to_string().len());
        assert!(differ
            .iter()
            .all(|(x, y)| matches!((x, y), (Packet::Key(_), Packet::Key(_)))));
        // Acquisition reads the typed node there.
        let scan = acquire(&faulted.bytes);
        assert_eq!(scan.curves[f.curve].tags[tag].node, typed, "seed {seed}");
    }
}

#[test]
fn issue_49_a_slip_shortens_one_segment_by_its_fraction() {
    for device in [DeviceKind::Morphorider, DeviceKind::Phone] {
        let (twin, faulted) = twin_and(device, 2, Planted::Slip);
        let f = &faulted.truth.faults[0];
        assert_eq!((f.kind.as_str(), f.tag, f.node), ("slip", None, None));
        let k = f.details["segment"].as_u64().unwrap() as usize;
        let short = f.details["short_fraction"].as_f64().unwrap();
        assert!((0.08..=0.15).contains(&short));
        let (a, b) = (acquire(&twin.bytes), acquire(&faulted.bytes));
        let ratio = segment(&b, f.curve, k) / segment(&a, f.curve, k);
        assert!(
            (ratio - (1.0 - short)).abs() < 0.01,
            "{device:?}: the segment reads {ratio} of the twin's, planted {}",
            1.0 - short
        );
        // The other segments of the curve read as the twin's.
        for j in 0..a.curves[f.curve].tags.len() - 1 {
            if j != k {
                let (x, y) = (segment(&a, f.curve, j), segment(&b, f.curve, j));
                assert!((x - y).abs() < 1e-3, "{device:?}: segment {j}: {x} {y}");
            }
        }
    }
}

/// A late Enter in the simulator: the index typed at the node, Enter pressed 3–5 cm on. Both
/// devices find it from the sensors (the Morphorider's wheel turning while the index was typed,
/// the phone's accelerometer setting off before its Enter) and put the tag back where the
/// device stood; the phone's segment lengths, measured from Enter to Enter, give the segment
/// before the tag what the device went meanwhile.
#[test]
fn issue_49_a_late_enter_leaves_the_tag_where_the_device_stood_on_both_devices() {
    for device in [DeviceKind::Morphorider, DeviceKind::Phone] {
        let (twin, faulted) = twin_and(device, 3, Planted::LateEnter);
        let f = &faulted.truth.faults[0];
        assert_eq!(f.kind, "late-enter");
        let (tag, node) = (f.tag.unwrap(), f.node.unwrap());
        let late = f.details["late_m"].as_f64().unwrap();
        assert!((0.03..=0.05).contains(&late), "{late}");
        let (a, b) = (acquire(&twin.bytes), acquire(&faulted.bytes));
        let (ta, tb) = (&a.curves[f.curve].tags, &b.curves[f.curve].tags);
        assert_eq!(tb[tag].node, node);
        // Measured from the curve's first tag (or to the next tag, when it is the first).
        let shift = if tag == 0 {
            (ta[1].d - ta[0].d) - (tb[1].d - tb[0].d)
        } else {
            (tb[tag].d - tb[0].d) - (ta[tag].d - ta[0].d)
        };
        assert!(
            shift.abs() < 0.012,
            "{device:?}: the tag moved {shift} m on, planted {late} m"
        );
    }
}

#[test]
fn issue_49_a_magnet_changes_the_magnetometer_near_one_curve_only() {
    let (twin, faulted) = twin_and(DeviceKind::Morphorider, 1, Planted::Magnet);
    let f = &faulted.truth.faults[0];
    assert_eq!(f.kind, "magnet");
    let (a, b) = (packets(&twin.bytes), packets(&faulted.bytes));
    assert_eq!(a.len(), b.len());
    let mut changed = 0;
    for (x, y) in a.iter().zip(&b) {
        match (x, y) {
            (Packet::RiderSample(p), Packet::RiderSample(q)) => {
                assert_eq!((p.t_us, p.acc, p.wheel), (q.t_us, q.acc, q.wheel));
                changed += usize::from(p.mag != q.mag);
            }
            _ => assert_eq!(x, y),
        }
    }
    // Some, not most: one stretch of one curve.
    assert!(
        changed > 20 && changed < a.len() / 4,
        "{changed} of {}",
        a.len()
    );
}

#[test]
fn issue_49_a_planted_fault_is_the_same_for_the_same_seed() {
    let s = scene::builtin("bowl").unwrap();
    for kind in [
        Planted::WrongNode,
        Planted::Slip,
        Planted::LateEnter,
        Planted::Magnet,
    ] {
        let run = || simulate::run_planted(&s, DeviceKind::Phone, Profile::Field, 7, kind);
        let (x, y) = (run().unwrap(), run().unwrap());
        assert_eq!(x.bytes, y.bytes, "{kind:?}");
        assert_eq!(x.truth, y.truth, "{kind:?}");
        assert_eq!(x.truth.faults.len(), 1);
    }
}

/// The command line: `--fault KIND` writes the truth's `faults` and says where it planted it;
/// a structure's sensor array has no place for one (usage, exit 2).
#[test]
fn issue_49_sfs_simulate_fault_plants_one_and_says_where() {
    let dir = std::env::temp_dir().join(format!("sfs-fault-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_sfs"))
        .args([
            "simulate",
            "--scene",
            "bowl",
            "--fault",
            "late-enter",
            "--out",
        ])
        .arg(dir.join("bowl"))
        .output()
        .expect("runs sfs");
    assert_eq!(out.status.code(), Some(0), "{out:?}");
    let said = String::from_utf8_lossy(&out.stdout);
    let truth: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("bowl.truth.json")).unwrap()).unwrap();
    let f = &truth["faults"][0];
    assert_eq!(f["kind"], "late-enter");
    let line = format!(
        "planted: late-enter on curve {}, tag {} (node {})",
        f["curve"], f["tag"], f["node"]
    );
    assert!(said.contains(&line), "{said}");
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_sfs"))
        .args([
            "simulate",
            "--structure",
            "riser",
            "--fault",
            "slip",
            "--out",
        ])
        .arg(dir.join("pipe"))
        .output()
        .expect("runs sfs");
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("--fault"));
    let _ = std::fs::remove_dir_all(&dir);
}

/// Issue 49 point 4: `N C` after the last curve drops curve N: the scan is the same but for
/// it, and a replay's network leaves it out (`curves_used` one less, `scan.json` says which).
#[test]
fn issue_49_a_curve_dropped_from_the_keypad_leaves_the_network() {
    let s = scene::builtin("cone").unwrap();
    let kind = DeviceKind::Morphorider;
    let twin = simulate::run(&s, kind, Profile::Default, 1);
    let more = simulate::Mistakes {
        drop_after: Some(2),
        ..Default::default()
    };
    let dropped = simulate::run_with(&s, kind, Profile::Default, 1, &more);
    let (a, b) = (acquire(&twin.bytes), acquire(&dropped.bytes));
    let kept: Vec<_> = a.curves.iter().filter(|c| c.index != 2).cloned().collect();
    assert!(b.curves == kept, "the scan is the twin's without curve 2");
    assert_eq!(b.dropped.len(), 1);
    assert_eq!((b.dropped[0].curve, b.dropped[0].by), (2, None));
    assert_eq!(b.dropped[0].nodes, a.curves[2].nodes());
    // Through the daemon: the network is made of the six others.
    let r = replayed("drop", &dropped);
    assert_eq!(
        r.report["network"]["curves_used"], 6,
        "{}",
        r.report["network"]
    );
    assert_eq!(r.scan["dropped"][0]["curve"], 2);
}

/// What the daemon made of a simulated capture (`sfs replay`), and its score (`sfs eval`).
struct Replayed {
    report: serde_json::Value,
    scan: serde_json::Value,
    /// The curves' mean error against the capture's truth, % of the diagonal.
    error_pct: f64,
}

/// `sim` replayed through the daemon in a directory of its own (`name`, unique among the
/// tests running at once).
fn replayed(name: &str, sim: &Simulation) -> Replayed {
    let dir = tmpdir(&format!("faults-{name}"));
    let (capture, truth, out) = (dir.join("c.bin"), dir.join("c.truth.json"), dir.join("out"));
    std::fs::write(&capture, &sim.bytes).unwrap();
    std::fs::write(&truth, serde_json::to_vec(&sim.truth).unwrap()).unwrap();
    replay_to(&capture, &out);
    let e = eval(&truth, &out.join("network.glb"));
    let scan = serde_json::from_slice(&std::fs::read(out.join("scan.json")).unwrap()).unwrap();
    let r = Replayed {
        report: read_report(&out),
        scan,
        error_pct: e["curves"]["mean_pct"].as_f64().unwrap(),
    };
    let _ = std::fs::remove_dir_all(&dir);
    r
}

/// Issue 49 point 4: a capture with a wrong node planted, the faulted curve rescanned from the
/// keypad (`N B … E`): the error returns to within 1.1× its twin's (the same capture, rescan
/// and all, without the fault). Without the rescan the fault costs, unless the loops detached
/// the wrong tag themselves (point 2's repair).
#[test]
fn issue_49_a_wrong_node_rescanned_returns_to_the_twin() {
    let s = scene::builtin("cone").unwrap();
    let kind = DeviceKind::Morphorider;
    for seed in [1, 2, 3] {
        let none = simulate::Mistakes::default();
        let plan = simulate::planted::plan(Planted::WrongNode, &s, seed, &none).unwrap();
        let twin = simulate::run(&s, kind, Profile::Default, seed);
        let faulted =
            simulate::run_planted(&s, kind, Profile::Default, seed, Planted::WrongNode).unwrap();
        let more = simulate::Mistakes {
            rescan: Some(plan.curve()),
            ..Default::default()
        };
        let rescanned =
            simulate::run_planted_with(&s, kind, Profile::Default, seed, &more, Planted::WrongNode)
                .unwrap();
        let rescanned = replayed("rescan-rescanned", &rescanned);
        assert_eq!(rescanned.scan["dropped"].as_array().map(Vec::len), Some(1));
        let faulted = replayed("rescan-faulted", &faulted);
        let (t, f, r) = (
            replayed("rescan-twin", &twin).error_pct,
            faulted.error_pct,
            rescanned.error_pct,
        );
        // The wrong tag detached by the loops (a curve pulled a third of the cone's size to
        // meet the node typed, issue 49's second sign), or put on the node its curve lands on,
        // repairs it without the rescan.
        let detached = faulted.report["quality"]["suspects"]
            .as_array()
            .unwrap()
            .iter()
            .any(|x| {
                x["curve"].as_u64() == Some(plan.curve() as u64)
                    && (x["repair"] == "detached" || x["repair"] == "retagged")
            });
        // The same rescan of the unfaulted capture: acting the rescan out draws the noise anew
        // (more samples), so this, not the capture without it, is the faulted one's twin.
        let twin_rescanned = simulate::run_with(&s, kind, Profile::Default, seed, &more);
        let twin_rescanned = replayed("rescan-twin-rescanned", &twin_rescanned);
        assert_eq!(
            twin_rescanned.scan["dropped"].as_array().map(Vec::len),
            Some(1)
        );
        let p = twin_rescanned.error_pct;
        eprintln!(
            "issue 49 point 4, seed {seed}: twin {t:.4} %, wrong node {f:.4} %, rescanned {r:.4} % (the twin rescanned {p:.4} %)"
        );
        assert!(
            f > 5.0 * t || (detached && f <= 1.2 * t + 0.02),
            "seed {seed}: the fault costs {f} against {t} (detached: {detached})"
        );
        assert!(r <= 1.1 * p, "seed {seed}: rescanned {r} against {p}");
    }
}

/// Issue 49 point 2: a late Enter is named from the sensors (a Morphorider's wheel turned while
/// the index was typed; a phone's accelerometer set off before the Enter), on its curve and
/// node, and the tag placed where the device stood: the error returns to near the twin's. No
/// curve of the twin is named.
///
/// The late Enter shifts the timeline, so the faulted capture's noise is drawn anew: one
/// seed's twin is another draw of the noise (on 16 more seeds of the cone and relief, repaired
/// minus twin spread over ±0.06 pp, mean −0.01). The errors are compared over the three seeds
/// of each device (unrepaired, one seed alone costs 0.25 % against 0.07 %).
#[test]
fn issue_49_a_late_enter_is_named_and_placed_where_the_device_stood() {
    let s = scene::builtin("cone").unwrap();
    let cases = [
        (DeviceKind::Morphorider, 1),
        (DeviceKind::Morphorider, 2),
        (DeviceKind::Morphorider, 3),
        (DeviceKind::Phone, 1),
        (DeviceKind::Phone, 2),
        (DeviceKind::Phone, 3),
    ];
    let mut errors: std::collections::BTreeMap<String, Vec<(f64, f64)>> = Default::default();
    for (kind, seed) in cases {
        let twin = simulate::run(&s, kind, Profile::Default, seed);
        let late =
            simulate::run_planted(&s, kind, Profile::Default, seed, Planted::LateEnter).unwrap();
        let f = &late.truth.faults[0];
        let named = |scan: &Scan| -> Vec<(usize, u32)> {
            scan.warnings
                .iter()
                .filter_map(|w| match w {
                    sfs::warning::Warning::Acquisition(
                        sfs::warning::AcquisitionWarning::LateEnter { curve, node, .. },
                    ) => Some((*curve, *node)),
                    _ => None,
                })
                .collect()
        };
        assert_eq!(
            named(&acquire(&twin.bytes)),
            [],
            "{kind:?} seed {seed}: the twin"
        );
        assert_eq!(
            named(&acquire(&late.bytes)),
            [(f.curve, f.node.unwrap())],
            "{kind:?} seed {seed}"
        );
        let (t, l) = (
            replayed("late-twin", &twin).error_pct,
            replayed("late-late", &late).error_pct,
        );
        eprintln!(
            "issue 49 point 2, {kind:?} seed {seed}: twin {t:.4} %, late Enter repaired {l:.4} %"
        );
        errors.entry(format!("{kind:?}")).or_default().push((t, l));
    }
    for (kind, e) in errors {
        let n = e.len() as f64;
        let t = e.iter().map(|x| x.0).sum::<f64>() / n;
        let l = e.iter().map(|x| x.1).sum::<f64>() / n;
        assert!(
            l <= 1.2 * t + 0.02,
            "{kind}: late Enters repaired {l} against twins {t}"
        );
    }
}

/// Issue 49 point 2: `report.json` `quality.suspects[]` names a planted late Enter where the
/// truth put it, and a planted wrong node's tag the loops refuse; the twin has none.
#[test]
fn issue_49_report_quality_suspects_name_the_planted_faults() {
    let s = scene::builtin("cone").unwrap();
    let kind = DeviceKind::Morphorider;
    let twin = simulate::run(&s, kind, Profile::Default, 1);
    let suspects = |r: &serde_json::Value| r["quality"]["suspects"].as_array().unwrap().clone();
    assert!(suspects(&replayed("quality-twin", &twin).report).is_empty());
    let late = simulate::run_planted(&s, kind, Profile::Default, 1, Planted::LateEnter).unwrap();
    let f = &late.truth.faults[0];
    let got = suspects(&replayed("quality-late", &late).report);
    assert_eq!(got.len(), 1, "{got:?}");
    assert_eq!(
        (
            &got[0]["kind"],
            &got[0]["curve"],
            &got[0]["tag"],
            &got[0]["node"]
        ),
        (
            &"late-enter".into(),
            &f.curve.into(),
            &f.tag.unwrap().into(),
            &f.node.unwrap().into()
        )
    );
    assert_eq!(got[0]["repair"], "placed");
    let wrong = simulate::run_planted(&s, kind, Profile::Default, 1, Planted::WrongNode).unwrap();
    let got = suspects(&replayed("quality-wrong", &wrong).report);
    assert!(got.iter().any(|x| x["kind"] == "wrong-node"), "{got:?}");
}

/// Issue 49: a late Enter named on a curve that the operator then rescanned from the keypad
/// (`N B … E`) is not a suspect any more: the curve it named has left the network (its
/// warning stays in the report), and the verdict is the rescanned scan's.
#[test]
fn issue_49_a_suspect_leaves_with_its_rescanned_curve() {
    let s = scene::builtin("cone").unwrap();
    let kind = DeviceKind::Morphorider;
    let none = simulate::Mistakes::default();
    let plan = simulate::planted::plan(Planted::LateEnter, &s, 1, &none).unwrap();
    let more = simulate::Mistakes {
        rescan: Some(plan.curve()),
        ..Default::default()
    };
    let rescanned =
        simulate::run_planted_with(&s, kind, Profile::Default, 1, &more, Planted::LateEnter)
            .unwrap();
    let r = replayed("suspect-rescanned", &rescanned);
    assert_eq!(r.scan["dropped"].as_array().map(Vec::len), Some(1));
    let warned = r.report["warnings"].as_array().unwrap().iter().any(|w| {
        w.as_str()
            .is_some_and(|w| w.contains("while the node's index was typed"))
    });
    assert!(warned, "the late Enter is still in the warnings");
    assert_eq!(r.report["quality"]["suspects"], serde_json::json!([]));
    assert_eq!(r.report["quality"]["verdict"], "good");
}

/// Issue 49 point 2: a wrong node on the sphere-cube, whose curves are one segment from a node
/// of three curves to another. The loops cannot tell which end of the curve is wrong (freeing
/// either frees the segment), but let go at the wrong end the curve lands on the node the
/// device stood at: the tag is named, put on that node, and the error returns to the twin's.
#[test]
fn issue_49_a_wrong_node_at_a_node_of_three_curves_is_put_where_its_curve_lands() {
    let s = scene::builtin("sphere-cube").unwrap();
    let kind = DeviceKind::Morphorider;
    for seed in [1, 2] {
        let twin = simulate::run(&s, kind, Profile::Default, seed);
        let wrong =
            simulate::run_planted(&s, kind, Profile::Default, seed, Planted::WrongNode).unwrap();
        let f = &wrong.truth.faults[0];
        let meant = f.details["true_node"].as_u64().unwrap();
        let r = replayed("land-wrong", &wrong);
        let suspects = r.report["quality"]["suspects"].as_array().unwrap().clone();
        assert_eq!(suspects.len(), 1, "seed {seed}: {suspects:?}");
        let x = &suspects[0];
        assert_eq!(
            (x["curve"].as_u64(), x["tag"].as_u64(), x["kind"].as_str()),
            (
                Some(f.curve as u64),
                Some(f.tag.unwrap() as u64),
                Some("wrong-node")
            ),
            "seed {seed}: {x}"
        );
        assert_eq!(x["repair"], "retagged", "seed {seed}: {x}");
        assert_eq!(
            x["evidence"]["kept_as"].as_u64(),
            Some(meant),
            "seed {seed}: {x}"
        );
        let (t, w) = (replayed("land-twin", &twin).error_pct, r.error_pct);
        eprintln!("issue 49 point 2, sphere-cube seed {seed}: twin {t:.4} %, wrong node retagged {w:.4} %");
        assert!(w <= 1.2 * t + 0.02, "seed {seed}: {w} against {t}");
    }
}

/// Issue 49 point 2: a wheel that slipped evenly over a whole segment (no sensor sees it: the
/// accelerometer reads no speed at a steady roll) is named by the loops on the Morphorider,
/// on its curve and segment, with the fraction missed; the segment is lengthened by as much,
/// the error returns to near the twin's, and the scan's verdict is `good` (the slip stays
/// listed, with the keys that rescan it). The default profile and the field one, whose noise
/// hid such slips from the strict test a phone keeps.
#[test]
fn issue_49_a_wheel_slip_is_named_lengthened_and_leaves_the_scan_good() {
    let kind = DeviceKind::Morphorider;
    for (name, profile, seed) in [
        ("cone", Profile::Default, 1),
        ("cone", Profile::Default, 2),
        ("bowl", Profile::Field, 2),
    ] {
        let s = scene::builtin(name).unwrap();
        let twin = replayed("slip-twin", &simulate::run(&s, kind, profile, seed));
        let slipped = simulate::run_planted(&s, kind, profile, seed, Planted::Slip).unwrap();
        let f = &slipped.truth.faults[0];
        let k = f.details["segment"].as_u64().unwrap();
        let short = f.details["short_fraction"].as_f64().unwrap();
        let r = replayed("slip", &slipped);
        let suspects = r.report["quality"]["suspects"].as_array().unwrap();
        let named = suspects
            .iter()
            .find(|x| {
                x["kind"] == "slip"
                    && x["curve"].as_u64() == Some(f.curve as u64)
                    && x["tag"].as_u64() == Some(k)
            })
            .unwrap_or_else(|| panic!("{name} seed {seed}: {suspects:?}"));
        assert_eq!(named["repair"], "lengthened");
        let said = named["evidence"]["short_fraction"].as_f64().unwrap();
        assert!(
            (said - short).abs() < 0.02,
            "{name} seed {seed}: {said} for {short}"
        );
        assert_eq!(
            r.report["quality"]["verdict"], "good",
            "{name} seed {seed}: {}",
            r.report["quality"]
        );
        let (e, t) = (r.error_pct, twin.error_pct);
        eprintln!("{name} {profile:?} seed {seed}: twin {t:.4} %, slipped and lengthened {e:.4} %");
        assert!(e <= 1.2 * t + 0.02, "{name} seed {seed}: {e} against {t}");
    }
}

/// A long session's lost Enters (issue 51's grid, 4-digit indices 15 mm apart): an Enter lost
/// on the link merges two indices into one over six digits, refused; the tag typed next is
/// counted from its own first digit, not from the refused index's, so no late Enter is named
/// there (it was, on each of the five: the device had rolled on over two nodes meanwhile).
#[test]
fn issue_51_an_index_refused_as_too_long_does_not_make_the_next_tag_late() {
    use sfs::warning::{AcquisitionWarning, Warning};
    let s = scene::builtin("ellipsoid-grid").unwrap();
    let sim = simulate::run(&s, DeviceKind::Morphorider, Profile::Default, 1);
    let scan = acquire(&sim.bytes);
    let refused: Vec<(usize, f64)> = scan
        .warnings
        .iter()
        .filter_map(|w| match w {
            Warning::Keypad(k) if k.issue.code() == "keypad_index_too_long" => {
                Some((k.curve?, k.t))
            }
            _ => None,
        })
        .collect();
    assert!(refused.len() >= 3, "{refused:?}");
    let late: Vec<(usize, f64)> = scan
        .warnings
        .iter()
        .filter_map(|w| match w {
            Warning::Acquisition(AcquisitionWarning::LateEnter { curve, t, .. }) => {
                Some((*curve, *t))
            }
            _ => None,
        })
        .collect();
    for (c, t0) in &refused {
        assert!(
            !late
                .iter()
                .any(|(l, t)| l == c && *t > *t0 && *t < t0 + 10.0),
            "curve {c}, index refused at {t0} s: {late:?}"
        );
    }
}
