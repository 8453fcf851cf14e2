//! Issue 14 (one restructuring step, no behaviour change): the outputs of `sfs replay` on every
//! replay log and on every simulated scene (both scanning devices, seed 1) are compared byte for
//! byte with the outputs of the code before the step, recorded as digests in
//! `tests/golden/outputs.txt`.
//!
//! Compared: `network.glb`, `scan.json` and `report.json` without what varies from run to run
//! (wall time, timings, memory, the source's path); for the monitored riser, `latest.glb`,
//! `metrics.csv`, `events.log` and `reference.json` too.
//!
//! An intended change of the outputs is recorded again with
//! `SFS_BLESS=1 cargo test --test outputs_unchanged`, in the commit that makes it, saying why.
//!
//! The digests depend on the floating point the machine runs: faer picks its SIMD kernels
//! (and so whether it fuses multiply-adds) at run time. The file records the instruction set
//! levels it was made on (`made on x86-64-v4, x86-64-v3`: the same digests on both, recorded
//! on one and checked on the other); on a machine of another level the build script
//! (`build.rs`) tells cargo, and the comparison is reported as ignored. A record made where the
//! digests are those of the file already adds this machine's level to it; different digests
//! replace it, made on this level alone. The paper's scenes (LILIUM, BUMPY CUBE)
//! have their own file, `tests/golden/outputs-paper.txt`, compared when `SFS_PAPER_DATA`
//! names their meshes.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// The digests of the cases that run from the repository alone.
fn golden_path() -> PathBuf {
    root().join("tests/golden/outputs.txt")
}

/// The digests of the paper's scenes (their meshes are not shipped: `SFS_PAPER_DATA`).
fn paper_golden_path() -> PathBuf {
    root().join("tests/golden/outputs-paper.txt")
}

include!("golden/simd_level.rs");

/// FNV-1a, 64 bits: enough to tell two outputs apart (nothing adversarial here).
fn digest(bytes: &[u8]) -> String {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for &b in bytes {
        h ^= b as u64;
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    format!("{h:016x}")
}

/// `report.json` without what varies between two runs of the same input: wall time, timings,
/// resident memory, the live worker's latencies, and the source (it names the path).
fn stable_report(bytes: &[u8]) -> Vec<u8> {
    fn strip(v: &mut serde_json::Value) {
        match v {
            serde_json::Value::Object(m) => {
                m.retain(|k, _| {
                    !(k == "wall_time_s"
                        || k == "source"
                        || k == "live"
                        || k == "latencies"
                        || k.ends_with("_ms")
                        || k.contains("rss"))
                });
                m.values_mut().for_each(strip);
            }
            serde_json::Value::Array(a) => a.iter_mut().for_each(strip),
            _ => {}
        }
    }
    let mut v: serde_json::Value = serde_json::from_slice(bytes).expect("report.json is JSON");
    strip(&mut v);
    serde_json::to_vec_pretty(&v).unwrap()
}

fn sfs(args: &[&str], paths: &[(&str, &Path)]) {
    let mut c = Command::new(env!("CARGO_BIN_EXE_sfs"));
    c.args(["--log", "off"]).args(args);
    for (flag, p) in paths {
        if !flag.is_empty() {
            c.arg(flag);
        }
        c.arg(p);
    }
    let out = c.output().unwrap();
    assert!(
        out.status.success(),
        "sfs {args:?} {paths:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// The outputs of one case: `file -> (length, digest)`.
type Digests = BTreeMap<String, (usize, String)>;

/// Digests of the outputs of one case.
fn outputs(dir: &Path, files: &[&str]) -> Digests {
    files
        .iter()
        .map(|f| {
            let raw = std::fs::read(dir.join(f))
                .unwrap_or_else(|e| panic!("{}: {e}", dir.join(f).display()));
            let bytes = if *f == "report.json" {
                stable_report(&raw)
            } else {
                raw
            };
            (f.to_string(), (bytes.len(), digest(&bytes)))
        })
        .collect()
}

const SCAN_OUTPUTS: &[&str] = &["network.glb", "report.json", "scan.json"];
const MONITOR_OUTPUTS: &[&str] = &[
    "report.json",
    "latest.glb",
    "metrics.csv",
    "events.log",
    "reference.json",
    "scan.json",
];

/// The replay logs, the README's main job and the shipped scenes that need no paper data:
/// each case's name and its outputs' digests.
fn all_cases() -> Vec<(String, Digests)> {
    let tmp = PathBuf::from(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("outputs-unchanged-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&tmp);
    std::fs::create_dir_all(&tmp).unwrap();
    let mut cases = Vec::new();
    // The replay logs, with the default configuration; the riser with its monitoring one.
    for name in [
        "cone-morphorider",
        "sphere-octa-morphorider-field",
        "bowl-phone",
    ] {
        let out = tmp.join(name);
        let log = root().join(format!("replay-logs/{name}.bin"));
        sfs(&["replay"], &[("", &log), ("--out", &out)]);
        cases.push((format!("log {name}"), outputs(&out, SCAN_OUTPUTS)));
    }
    let out = tmp.join("riser");
    sfs(
        &["replay"],
        &[
            ("", &root().join("replay-logs/riser-array.bin")),
            ("--config", &root().join("config/riser.toml")),
            ("--out", &out),
        ],
    );
    cases.push(("log riser-array".into(), outputs(&out, MONITOR_OUTPUTS)));
    // The README's main job: the demo capture through the daemon, with live updates.
    let session = tmp.join("demo");
    sfs(
        &["run"],
        &[
            ("--config", &root().join("config/demo.toml")),
            ("--session", &session),
        ],
    );
    cases.push(("run demo".into(), outputs(&session, SCAN_OUTPUTS)));
    // Every scene, both devices, seed 1, simulated and replayed by the binary.
    cases.extend(scene_cases(
        &tmp,
        &[
            "cone",
            "sphere-cube",
            "sphere-octa",
            "torus",
            "bowl",
            "relief",
            "bumpy",
        ],
    ));
    let _ = std::fs::remove_dir_all(&tmp);
    cases
}

/// The scenes, both devices, seed 1, simulated and replayed by the binary.
fn scene_cases(tmp: &Path, scenes: &[&str]) -> Vec<(String, Digests)> {
    let mut cases = Vec::new();
    for scene in scenes {
        for device in ["morphorider", "phone"] {
            let prefix = tmp.join(format!("{scene}-{device}"));
            sfs(
                &[
                    "simulate", "--scene", scene, "--device", device, "--seed", "1",
                ],
                &[("--out", &prefix)],
            );
            let out = tmp.join(format!("{scene}-{device}-out"));
            let bin = prefix.with_extension("bin");
            sfs(&["replay"], &[("", &bin), ("--out", &out)]);
            cases.push((
                format!("scene {scene} {device}"),
                outputs(&out, SCAN_OUTPUTS),
            ));
        }
    }
    cases
}

fn render(cases: &[(String, Digests)]) -> String {
    let mut s = format!(
        "# Digests of sfs replay's outputs (tests/outputs_unchanged.rs); made on {}\n",
        simd_level()
    );
    for (case, files) in cases {
        for (f, (len, d)) in files {
            s.push_str(&format!("{case} | {f} | {len} | {d}\n"));
        }
    }
    s
}

#[test]
#[cfg_attr(
    not(sfs_golden_simd),
    ignore = "tests/golden/outputs.txt was made on other SIMD levels than this machine's (faer's kernels may round differently): SFS_BLESS=1 with --include-ignored records or adds this machine's"
)]
fn issue_14_outputs_are_those_of_the_code_before_the_restructuring() {
    compare(&golden_path(), &all_cases());
}

#[test]
#[cfg_attr(
    not(all(sfs_golden_simd, sfs_paper_data)),
    ignore = "needs the paper's meshes (SFS_PAPER_DATA) and a machine of the SIMD level the digests were made on"
)]
fn issue_14_outputs_of_the_paper_scenes_are_unchanged() {
    let tmp = PathBuf::from(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("outputs-paper-{}", std::process::id()));
    std::fs::create_dir_all(&tmp).unwrap();
    let cases = scene_cases(&tmp, &sfs::simulate::scene::PAPER_SCENES);
    let _ = std::fs::remove_dir_all(&tmp);
    compare(&paper_golden_path(), &cases);
}

/// The digests of `cases` against the file `golden` (recorded instead with `SFS_BLESS=1`).
fn compare(golden: &Path, cases: &[(String, Digests)]) {
    let mut got = render(cases);
    if std::env::var_os("SFS_BLESS").is_some() {
        // The same digests as recorded: this level joins the levels they were made on.
        let old = std::fs::read_to_string(golden).unwrap_or_default();
        if let (Some((head, digests)), Some((_, new_digests))) =
            (old.split_once('\n'), got.split_once('\n'))
        {
            if digests == new_digests {
                got = if made_on_this_level(&old) {
                    old
                } else {
                    format!("{head}, {}\n{digests}", simd_level())
                };
            }
        }
        std::fs::create_dir_all(golden.parent().unwrap()).unwrap();
        std::fs::write(golden, &got).unwrap();
        eprintln!("recorded {}", golden.display());
        return;
    }
    let want =
        std::fs::read_to_string(golden).unwrap_or_else(|e| panic!("{}: {e}", golden.display()));
    assert!(
        made_on_this_level(&want),
        "{} was made on another SIMD level than this machine's ({})",
        golden.display(),
        simd_level()
    );
    let differ: Vec<String> = want
        .lines()
        .skip(1)
        .zip(got.lines().skip(1))
        .filter(|(w, g)| w != g)
        .map(|(w, g)| format!("  was {w}\n  now {g}"))
        .collect();
    assert!(
        differ.is_empty() && want.lines().count() == got.lines().count(),
        "outputs changed:\n{}\n(an intended change: SFS_BLESS=1 cargo test --test outputs_unchanged)",
        differ.join("\n")
    );
}
