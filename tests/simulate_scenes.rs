//! The simulator against its own contract: every shipped scene builds with the expected
//! network; the bytes decode with exactly the faults the device model put in; acquisition
//! recovers every curve of a field-profile session (its mistakes, reboot, clock wrap and
//! partial start included); the same seed gives the same bytes.

use device_protocol::{Decoder, DeviceKind};
use sfs::acquisition::{Acquisition, AcquisitionConfig};
use sfs::link::LinkStats;
use sfs::scan::Scan;
use sfs::simulate::{self, scene, Profile};
use std::path::{Path, PathBuf};

fn decode(bytes: &[u8]) -> (LinkStats, Scan) {
    let mut dec = Decoder::new();
    let mut stats = LinkStats::default();
    let mut acq = Acquisition::new(AcquisitionConfig::default());
    for chunk in bytes.chunks(4096) {
        stats.bytes += chunk.len() as u64;
        for e in dec.feed(chunk) {
            stats.observe(&e);
            acq.event(&e);
        }
    }
    (stats, acq.finish())
}

#[test]
fn shipped_scenes_build_the_expected_networks() {
    // (scene, nodes, curves, closed curves, boundary curves)
    check_scenes(&[
        ("sphere-cube", 8, 12, 0, 0),
        ("sphere-octa", 6, 3, 3, 0),
        ("torus", 8, 6, 6, 0),
        ("cone", 12, 7, 3, 2),
        ("bowl", 9, 4, 2, 1),
        ("relief", 32, 9, 1, 1),
        ("bumpy", 6, 3, 3, 0),
        ("torus-loops", 1, 2, 2, 0),
        ("ellipsoid-dense", 20, 5, 5, 0),
        ("parallel", 14, 5, 2, 1),
    ]);
}

/// Issue 51, point 4: the 100-curve grid is built in (`sfs simulate --scene ellipsoid-grid`),
/// and its exact scan reconstructs as one network whose nodes lie where the scene's do
/// (the distances between nodes one segment apart).
#[test]
fn issue_51_the_100_curve_grid_is_built_in_and_reconstructs() {
    check_scenes(&[("ellipsoid-grid", 4432, 100, 100, 0)]);
    let s = scene::builtin("ellipsoid-grid").unwrap();
    let scan = s.exact_scan();
    let net = sfs_geometry::network::Reconstructor::new()
        .run(&scan.curves, &Default::default())
        .unwrap();
    assert_eq!(net.report.curves_used, 100);
    assert_eq!(net.positions.components, 1);
    let (mut sum, mut count, mut worst) = (0.0, 0, 0.0_f64);
    for c in &s.curves {
        for w in c.tags.windows(2) {
            let (a, b) = (w[0].1, w[1].1);
            let truth = (s.nodes[a as usize] - s.nodes[b as usize]).norm();
            let got = (net.positions.nodes[&a] - net.positions.nodes[&b]).norm();
            let e = (got - truth).abs();
            sum += e * e;
            count += 1;
            worst = worst.max(e);
        }
    }
    let rms = (sum / count as f64).sqrt();
    assert!(count >= 8_000, "{count} segments");
    assert!(rms < 1e-3 && worst < 5e-3, "rms {rms} m, worst {worst} m");
}

#[test]
#[cfg_attr(
    not(sfs_paper_data),
    ignore = "needs the paper's meshes (lilium.obj, bumpy-cube.obj): set SFS_PAPER_DATA to their directory"
)]
fn the_paper_scenes_build_the_expected_networks() {
    check_scenes(&[("lilium", 32, 9, 1, 1), ("bumpy-cube", 6, 3, 3, 0)]);
}

/// Issue 30: the project's own meshes written as OBJ files and read back through a scene file
/// give the built-in scene bit for bit (the OBJ reader, and `path` relative to the file).
#[test]
fn issue_30_the_made_meshes_read_back_from_obj_files_as_the_built_in_scenes() {
    let dir =
        PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(format!("made-{}", std::process::id()));
    std::fs::create_dir_all(dir.join("meshes")).unwrap();
    for name in ["relief", "bumpy"] {
        let mesh = sfs::simulate::procedural::generate(name).unwrap();
        std::fs::write(dir.join(format!("meshes/{name}.obj")), mesh.to_obj()).unwrap();
        let text = scene::BUILTIN.iter().find(|(n, _)| *n == name).unwrap().1;
        let text = text.replace(
            &format!("generate = \"{name}\""),
            &format!("path = \"meshes/{name}.obj\""),
        );
        let file = dir.join(format!("{name}.toml"));
        std::fs::write(&file, text).unwrap();
        let from_file = scene::load(&file).unwrap_or_else(|e| panic!("{e}"));
        let built_in = scene::builtin(name).unwrap();
        assert_eq!(from_file.curves.len(), built_in.curves.len());
        assert_eq!(from_file.nodes, built_in.nodes, "{name}: nodes");
        for (a, b) in from_file.curves.iter().zip(&built_in.curves) {
            assert_eq!(a.points, b.points, "{name}: points");
            assert_eq!(a.normals, b.normals, "{name}: normals");
            assert_eq!(a.tags, b.tags, "{name}: tags");
        }
        // The truth of a file scene names the file; of the built-in one, the generator.
        assert!(matches!(
            from_file.surface_ref,
            scene::SurfaceRef::Mesh { .. }
        ));
        assert!(matches!(
            built_in.surface_ref,
            scene::SurfaceRef::Generated { .. }
        ));
        assert_eq!(
            from_file.surface_ref.build().unwrap().tessellate().v,
            built_in.surface_ref.build().unwrap().tessellate().v
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// Issue 30: no shipped scene names a file outside the repository, and each built-in scene
/// is the file of its name in `config/scenes`.
#[test]
fn issue_30_every_shipped_scene_is_built_in_and_stays_inside_the_repository() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/scenes");
    let mut files: Vec<String> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    files.sort();
    let mut names: Vec<String> = scene::names().map(|n| format!("{n}.toml")).collect();
    names.sort();
    assert_eq!(files, names, "config/scenes and the built-in scenes");
    for (name, text) in scene::BUILTIN {
        assert_eq!(
            std::fs::read_to_string(dir.join(format!("{name}.toml"))).unwrap(),
            *text
        );
        let t: toml::Table = text.parse().unwrap();
        assert_eq!(t["name"].as_str(), Some(*name));
        if let Some(p) = t["surface"].get("path") {
            panic!("{name}: a shipped scene names a file ({p}); generate or paper instead");
        }
    }
}

fn check_scenes(expected: &[(&str, usize, usize, usize, usize)]) {
    for &(name, nodes, curves, closed, boundary) in expected {
        let s = scene::builtin(name).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(s.nodes.len(), nodes, "{name}: nodes");
        assert_eq!(s.curves.len(), curves, "{name}: curves");
        assert_eq!(
            s.curves.iter().filter(|c| c.closed).count(),
            closed,
            "{name}: closed"
        );
        assert_eq!(
            s.curves.iter().filter(|c| c.boundary()).count(),
            boundary,
            "{name}: boundary"
        );
        // Every node is used by at least two curve ends or crossings, tags sit on their nodes,
        // points lie on the surface and normals are unit and agree with the surface.
        let mut uses = vec![0; nodes];
        for c in &s.curves {
            assert!(c.tags.len() >= 2);
            assert_eq!(c.tags[0].0, 0, "{name}: a curve starts at a node");
            assert_eq!(
                c.tags.last().unwrap().0,
                c.points.len() - 1,
                "{name}: a curve ends at a node"
            );
            for &(i, n) in &c.tags {
                assert!(
                    (c.points[i] - s.nodes[n as usize]).norm() < 1e-6,
                    "{name}: tag off its node"
                );
                uses[n as usize] += 1;
            }
            // Analytic surfaces: points are snapped exactly; meshes: chords between section
            // points and crossings on them stay within a tenth of a millimetre.
            let tol = if matches!(s.surface, sfs::simulate::surface::Surface::Mesh(_)) {
                1e-4
            } else {
                1e-9
            };
            for (p, n) in c.points.iter().zip(&c.normals).step_by(17) {
                assert!((n.norm() - 1.0).abs() < 1e-9);
                let d = s.surface.distance(p);
                assert!(
                    d < tol * s.bbox_diagonal().max(1.0),
                    "{name}: point {d} off the surface"
                );
            }
        }
        assert!(
            uses.iter().all(|&u| u >= 2),
            "{name}: a node used once: {uses:?}"
        );
    }
}

#[test]
fn simulated_bytes_decode_with_the_faults_put_in() {
    let s = scene::builtin("cone").unwrap();
    for profile in [Profile::Default, Profile::Field] {
        let sim = simulate::run(&s, DeviceKind::Morphorider, profile, 5);
        let (stats, _) = decode(&sim.bytes);
        let t = &sim.samples;
        let delivered = t.packets_sent - t.packets_lost - t.packets_corrupted;
        let field = profile == Profile::Field;
        // The field capture starts mid-packet: its first packet is not delivered.
        assert_eq!(
            stats.packets.total(),
            delivered - field as u64,
            "{profile:?}: packets"
        );
        assert_eq!(
            stats.lost_packets,
            t.packets_lost + t.packets_corrupted,
            "{profile:?}: lost"
        );
        assert!(
            stats.rejected.total() >= t.packets_corrupted
                && stats.rejected.total() <= 2 * t.packets_corrupted
        );
        assert_eq!(stats.reboots, field as u64, "{profile:?}: reboots");
        assert_eq!(stats.clock_wraps, field as u64, "{profile:?}: clock wraps");
        assert_eq!(
            stats.partial_start_bytes > 0,
            field,
            "{profile:?}: partial start"
        );
        assert!(
            t.packets_corrupted > 0 && t.packets_lost > 0,
            "the profile puts link faults in"
        );
        // Issue 17: one 0.3 s stall in the middle of a move (30 samples at 100 Hz).
        let dropped = t.samples_dropped as i64;
        assert!(
            if field {
                (29..=31).contains(&dropped)
            } else {
                dropped == 0
            },
            "{profile:?}: {dropped} samples dropped"
        );
        let gap =
            t.t.windows(2)
                .zip(&t.curve)
                .filter(|(_, c)| c.is_some())
                .map(|(w, _)| w[1] - w[0])
                .fold(0.0, f64::max);
        assert_eq!(
            gap > 0.29,
            field,
            "{profile:?}: longest gap on a curve {gap} s"
        );
        // Issue 17: the hand tilts the standing device by 3-5° while an index is typed (its
        // normal turns), and the device is put down turned about its normal at each curve's
        // start and turned in place before moving (the normal stays).
        let (mut tilt, mut turn): (f64, f64) = (0.0, 0.0);
        let mut since = None;
        for (i, (&standing, c)) in t.standing.iter().zip(&t.curve).enumerate() {
            if standing && c.is_some() {
                let first = *since.get_or_insert(i);
                let normal = |k: usize| t.q[k] * nalgebra::Vector3::z();
                tilt = tilt.max(normal(first).angle(&normal(i)).to_degrees());
                turn = turn.max(t.q[first].angle_to(&t.q[i]).to_degrees());
            } else {
                since = None;
            }
        }
        assert!(
            if field { turn > 22.0 } else { turn < 1.0 },
            "{profile:?}: the standing device turned by up to {turn:.2}°"
        );
        assert!(
            if field {
                (2.2..6.3).contains(&tilt)
            } else {
                tilt < 1.0
            },
            "{profile:?}: the resting device tilted by up to {tilt:.2}°"
        );
    }
}

#[test]
fn field_session_is_recovered_curve_by_curve() {
    let s = scene::builtin("sphere-octa").unwrap();
    for device in [DeviceKind::Morphorider, DeviceKind::Phone] {
        let sim = simulate::run(&s, device, Profile::Field, 7);
        let (_, scan) = decode(&sim.bytes);
        let got: Vec<Vec<u32>> = scan.curves.iter().map(|c| c.nodes()).collect();
        let want: Vec<Vec<u32>> = sim.truth.curves.iter().map(|c| c.nodes.clone()).collect();
        assert_eq!(got, want, "{device:?}: {:?}", scan.warnings);
        assert_eq!(
            scan.counts.curves_discarded, 1,
            "{device:?}: the cancelled false start; {:?}",
            scan.counts
        );
        assert!(scan.counts.mag_disturbed > 0, "the magnet is noticed");
        assert!(sim.truth.events.len() >= 5, "{:?}", sim.truth.events);
    }
}

#[test]
fn same_seed_same_bytes() {
    let s = scene::builtin("bowl").unwrap();
    let a = simulate::run(&s, DeviceKind::Phone, Profile::Field, 9);
    let b = simulate::run(&s, DeviceKind::Phone, Profile::Field, 9);
    let c = simulate::run(&s, DeviceKind::Phone, Profile::Field, 10);
    assert!(a.bytes == b.bytes && a.truth == b.truth);
    assert_ne!(a.bytes, c.bytes);
}

#[test]
fn scene_errors_name_the_key() {
    let dir =
        PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(format!("scenes-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let cases = [
        ("[surface]\nkind = \"sphere\"\n[[curve]]\nnormal = [0.0, 0.0, 1.0]\nclosed = true\n", "surface.radius"),
        ("[surface]\nkind = \"blob\"\n[[curve]]\nnormal = [0.0, 0.0, 1.0]\n", "surface.kind"),
        ("[surface]\nkind = \"sphere\"\nradius = 1.0\n[[curve]]\nnormal = [0.0, 0.0, 1.0]\noffset = 3.0\n", "curve[0]"),
        ("[surface]\nkind = \"sphere\"\nradius = 1.0\n[[curve]]\nthrough = [[0.0, 0.0, 0.0], [1.0, 1.0, 1.0], [2.0, 2.0, 2.0]]\n", "curve[0]"),
        ("[surface]\nkind = \"sphere\"\nradius = 1.0\n[[curve]]\nnormal = [0.0, 0.0, 1.0]\nclosed = true\ntag_points = true\n", "curve[0]"),
    ];
    for (i, (body, key)) in cases.iter().enumerate() {
        let p = dir.join(format!("s{i}.toml"));
        std::fs::write(&p, format!("name = \"x\"\n{body}")).unwrap();
        let e = scene::load(&p).unwrap_err();
        assert_eq!(e.key.as_deref(), Some(*key), "{e}");
    }
}

#[test]
fn deforming_riser_streams_orientations_that_acquisition_recovers() {
    use sfs::simulate::structure::{run, StructureKind};
    let (bytes, truth) = run(StructureKind::Riser, 4, 20.0, 10.0);
    let (stats, scan) = decode(&bytes);
    assert_eq!(stats.rejected.total() + stats.lost_packets, 0);
    assert_eq!(
        scan.array.len(),
        41 * 19,
        "one epoch per sensor and second but the last"
    );
    // Each averaged orientation matches the truth at the middle of its window (the structure
    // moves during the window: tip up to 0.9°/s).
    let mut worst: f64 = 0.0;
    for e in &scan.array {
        let mid = e.t - 0.5;
        let k = ((mid - 0.5).round().max(0.0) as usize).min(truth.epochs.len() - 1);
        let q = truth.epochs[k].q[e.sensor as usize];
        let tq = nalgebra::UnitQuaternion::new_normalize(nalgebra::Quaternion::new(
            q[0], q[1], q[2], q[3],
        ));
        let eq = nalgebra::UnitQuaternion::new_normalize(nalgebra::Quaternion::new(
            e.q[0], e.q[1], e.q[2], e.q[3],
        ));
        worst = worst.max(eq.angle_to(&tq).to_degrees());
    }
    assert!(worst < 1.5, "worst sensor orientation error {worst:.2}°");
    // The tip swings ±2 m (2/3 θ_tip L); 20 s cover a third of the period.
    let max_tip = truth
        .epochs
        .iter()
        .filter_map(|e| e.tip_displacement)
        .fold(0.0, f64::max);
    assert!(max_tip > 1.5, "{max_tip}");
}

/// Issue 17: the field phone's gyroscope is an uncalibrated consumer one: at rest before the
/// first curve it reads about 1.7°/s per axis (and the default profile's well under 1°/s).
#[test]
fn issue_17_the_field_phone_has_an_uncalibrated_gyroscope() {
    let s = scene::builtin("cone").unwrap();
    for (profile, range) in [(Profile::Default, 0.0..1.0), (Profile::Field, 1.2..2.3)] {
        let sim = simulate::run(&s, DeviceKind::Phone, profile, 4);
        let mut dec = Decoder::new();
        // (The field capture starts mid-packet: its first HELLO may be lost.)
        let lsb = simulate::device::DeviceParams::phone().gyro_lsb;
        let mut rest = Vec::new();
        for e in dec.feed(&sim.bytes) {
            if let device_protocol::Event::Packet {
                packet: device_protocol::Packet::PhoneSample(p),
                ..
            } = e
            {
                if rest.len() < 150 {
                    rest.push(p.gyro.map(|g| g as f64 * lsb));
                }
            }
        }
        // The first 0.75 s: the device lies still before the first curve starts.
        for axis in 0..3 {
            let mean = rest.iter().map(|g| g[axis]).sum::<f64>() / rest.len() as f64;
            let deg = mean.abs().to_degrees();
            assert!(
                range.contains(&deg),
                "{profile:?}, axis {axis}: {deg:.2}°/s"
            );
        }
    }
}

/// Issue 34, point 4: `--untagged FRACTION` leaves that fraction of the crossings untagged on
/// one of their curves (the operator rolls through), chosen with the seed; every curve keeps
/// its first and last tag, every node stays tagged on another curve, and the truth still names
/// every crossing.
#[test]
fn issue_34_a_fraction_of_the_crossings_is_left_untagged_on_one_curve() {
    let s = scene::builtin("sphere-octa").expect("shipped scene");
    assert!(simulate::untagged_crossings(&s, 0.0, 1).is_empty());
    // Six crossings of two closed great circles each; one is where two of them start and
    // end (a curve's first and last tags stay), so five can be left out.
    assert_eq!(simulate::untagged_crossings(&s, 1.0, 1).len(), 5);
    let chosen = simulate::untagged_crossings(&s, 1.0 / 3.0, 1);
    assert_eq!(chosen.len(), 2, "{chosen:?}");
    assert_eq!(chosen, simulate::untagged_crossings(&s, 1.0 / 3.0, 1));
    let specs = s.specs();
    let mistakes = simulate::operator::Mistakes {
        untagged: chosen.clone(),
        ..Default::default()
    };
    let sim = simulate::run_with(&s, DeviceKind::Morphorider, Profile::Default, 1, &mistakes);
    let (_, scan) = decode(&sim.bytes);
    assert_eq!(scan.curves.len(), specs.len(), "{:?}", scan.warnings);
    for (ci, spec) in specs.iter().enumerate() {
        let tagged: Vec<u32> = spec
            .tags
            .iter()
            .enumerate()
            .filter(|&(k, _)| !chosen.contains(&(ci, k)))
            .map(|(_, t)| t.1)
            .collect();
        assert_eq!(scan.curves[ci].nodes(), tagged, "curve {ci}");
        // The truth names every node the curve passes.
        let all: Vec<u32> = spec.tags.iter().map(|t| t.1).collect();
        assert_eq!(sim.truth.curves[ci].nodes, all, "truth of curve {ci}");
    }
    for &(ci, k) in &chosen {
        let node = specs[ci].tags[k].1;
        assert!(
            scan.curves
                .iter()
                .enumerate()
                .any(|(cj, c)| cj != ci && c.nodes().contains(&node)),
            "node {node} is tagged on no other curve"
        );
        assert!(
            sim.truth
                .events
                .iter()
                .any(|e| e.contains(&format!("curve {ci}: node {node} rolled through untagged"))),
            "{:?}",
            sim.truth.events
        );
    }
    // The command line refuses what is not a fraction.
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_sfs"))
        .args([
            "simulate",
            "--scene",
            "sphere-octa",
            "--untagged",
            "1.5",
            "--out",
        ])
        .arg(std::env::temp_dir().join("sfs-untagged-refused"))
        .output()
        .expect("runs sfs");
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("--untagged 1.5"));
}
