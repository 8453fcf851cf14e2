//! The validation table of BENCHMARKS.md (issue 33): the captures of the independent simulator
//! (`../shared/validation/`, beside the repository; never read by the tests), each acquired and
//! reconstructed with the default configuration as `sfs replay` does and scored as `sfs eval`
//! does (curve mean error, % of the truth network's bounding-box diagonal), beside its target
//! and its figure before the field-accuracy work (from that directory's README).
//!
//! `cargo run --release --example validation_table -- [--dir DIR] [--captures a,b]
//! [--config FILE] [--no-bridge] [--no-smooth] [--no-skids] [--study]`
//!
//! `--no-bridge`, `--no-smooth`, `--no-skids`: the Morphorider's heading bridge across
//! disturbed stretches, the phone's smoother, the filling of the Morphorider's wheel skids,
//! off (to find which mechanism a capture's error comes from).
//!
//! `--study [--per-curve]`: where each capture's error comes from. The per-sample truth
//! (`NAME.samples.csv.gz`, read through `gzip -dc`) is put into the acquired curves, matched by
//! sample time within 0.1 ms: the true orientations (estimated distances), the true distances
//! (estimated orientations), both. Rough captures shift their clock at each power-up: the
//! shift is found per curve ([`clock_shift`]), and the share of samples matched is printed.
//! On phone captures also the true standing mask (phases standing and turning in place) with the
//! distances made from it as the phone's were before issue 33 (a constant speed between the
//! stands): what the best standing mask alone could give. `--per-curve` also prints each
//! curve's segment lengths against the truth and its frames' error, and its timeline in 25
//! stretches of equal sample count: the frames' mean tilt and heading error (°), what the
//! operator did (`S` standing, `T` turning, `m` moving, `t` transit), whether the stretch's
//! samples are flagged magnetically disturbed (`*` most, `'` some) and the distance's error
//! at its end (mm), to see where a curve's error comes from.
//!
//! Columns: the error now; the target (Morphorider rough 0.30, phone clean 0.40, phone rough
//! 0.80); the figure before the field-accuracy work (baa97be) and at 1b493a8, both from the
//! README; whether the target is met, and whether the capture is within 5 % of its figure
//! before. Runs two captures at a time (about 20 s for the 14).

use sfs::acquisition::{Acquisition, AcquisitionConfig};
use sfs::simulate::truth::Truth;
use sfs_geometry::curve::Curve;
use sfs_geometry::network::{NetworkParams, Reconstructor};
use std::path::{Path, PathBuf};

#[path = "shared/mod.rs"]
mod shared;
use shared::{list, parallel};

/// `(before, at 1b493a8, target)` of each capture, from the README's table.
fn readme_figures(dir: &Path) -> std::collections::HashMap<String, (f64, f64, f64)> {
    let text = std::fs::read_to_string(dir.join("README.md")).unwrap_or_default();
    text.lines()
        .filter_map(|l| {
            let cells: Vec<&str> = l.split('|').map(|c| c.trim()).collect();
            if cells.len() < 6 {
                return None;
            }
            let num = |s: &str| s.trim_matches('*').parse::<f64>().ok();
            Some((
                cells[1].to_owned(),
                (num(cells[2])?, num(cells[3])?, num(cells[4])?),
            ))
        })
        .collect()
}

/// One row of `NAME.samples.csv.gz`: time, phase (0 transit, 1 standing at a node, 2 turning
/// in place, 3 moving), arc length from the curve's start node, the true frame `[w, x, y, z]`.
struct TruthSample {
    t: f64,
    /// Scan order of the truth curve being scanned (−1 in transit, −2 cancelled).
    curve: i32,
    phase: u8,
    arc: f64,
    q: [f64; 4],
}

fn truth_samples(path: &Path) -> Result<Vec<TruthSample>, String> {
    let out = std::process::Command::new("gzip")
        .arg("-dc")
        .arg(path)
        .output()
        .map_err(|e| format!("gzip: {e}"))?;
    let text = String::from_utf8(out.stdout).map_err(|e| e.to_string())?;
    Ok(text
        .lines()
        .skip(1)
        .filter_map(|l| {
            let f: Vec<f64> = l
                .split(',')
                .map(|x| x.parse().unwrap_or(f64::NAN))
                .collect();
            (f.len() == 9).then(|| TruthSample {
                t: f[0],
                curve: f[2] as i32,
                phase: f[3] as u8,
                arc: f[4],
                q: [f[5], f[6], f[7], f[8]],
            })
        })
        .collect())
}

/// The truth row of the sample at time `t`: the nearest, if within 0.1 ms (`truth` in time
/// order).
fn truth_at(truth: &[TruthSample], t: f64) -> Option<&TruthSample> {
    let i = truth.partition_point(|s| s.t < t);
    [i.wrapping_sub(1), i]
        .into_iter()
        .filter_map(|j| truth.get(j))
        .min_by(|a, b| (a.t - t).abs().total_cmp(&(b.t - t).abs()))
        .filter(|s| (s.t - t).abs() < 1e-4)
}

/// The shift from a curve's sample clock to the truth's (`truth time = sample time + shift`):
/// zero on clean captures; on rough ones constant per power-up, so found per curve: zero when
/// it puts 90 % of the curve's samples on the truth's curve of the same scan order; else the
/// candidates put the curve's first sample on a truth row within ±5 s of where the truth's
/// curve of the same scan order starts; the one whose arc length follows the curve's distances
/// best (mean |Δd − Δarc| between neighbouring samples of the curve, so that a skid
/// costs only where it happens) wins. None when no candidate matches most samples.
fn clock_shift(c: &Curve, k: usize, truth: &[TruthSample]) -> Option<f64> {
    let n = c.samples.len();
    let t0 = *c.samples.t.first()?;
    // No shift where the sample clock is the truth's (every clean capture, and a rough one
    // before its first power-up again).
    let on_truth = c
        .samples
        .t
        .iter()
        .filter(|&&t| truth_at(truth, t).is_some_and(|s| s.curve == k as i32))
        .count();
    if 10 * on_truth >= 9 * n {
        return Some(0.0);
    }
    let start = truth.iter().find(|s| s.curve == k as i32)?.t;
    let lo = truth.partition_point(|s| s.t < start - 5.0);
    let hi = truth.partition_point(|s| s.t < start + 5.0);
    let step = (n / 200).max(1);
    let mut best: Option<(f64, f64)> = None;
    for row in &truth[lo..hi] {
        let shift = row.t - t0;
        let (mut cost, mut matched, mut tried) = (0.0, 0usize, 0usize);
        let mut last: Option<(f64, f64)> = None;
        for i in (0..n).step_by(step) {
            tried += 1;
            let Some(s) = truth_at(truth, c.samples.t[i] + shift) else {
                last = None;
                continue;
            };
            if s.curve != k as i32 {
                last = None;
                continue;
            }
            matched += 1;
            if let Some((d0, a0)) = last {
                cost += ((c.samples.d[i] - d0) - (s.arc - a0)).abs();
            }
            last = Some((c.samples.d[i], s.arc));
        }
        if 2 * matched < tried {
            continue;
        }
        let cost = cost / matched as f64;
        if best.is_none_or(|(_, b)| cost < b) {
            best = Some((shift, cost));
        }
    }
    best.map(|(s, _)| s)
}

/// Puts the truth into `curves` (orientations with `q`, distances from each curve's first
/// tag with `d`), sample by sample where a truth row lies within 0.1 ms; returns the samples
/// matched and all.
fn put_truth(
    curves: &mut [sfs_geometry::curve::Curve],
    truth: &[TruthSample],
    shifts: &[f64],
    q: bool,
    d: bool,
) -> (usize, usize) {
    // The arc length at a key press (between two samples), interpolated.
    let arc_at = |t: f64| -> Option<f64> {
        let i = truth.partition_point(|s| s.t < t);
        let (a, b) = (truth.get(i.checked_sub(1)?)?, truth.get(i)?);
        (b.t - a.t < 0.05).then(|| a.arc + (b.arc - a.arc) * (t - a.t) / (b.t - a.t).max(1e-9))
    };
    let (mut matched, mut all) = (0, 0);
    for (c, shift) in curves.iter_mut().zip(shifts) {
        let s0 = c.tags.first().and_then(|tag| arc_at(tag.t + shift));
        for i in 0..c.samples.len() {
            all += 1;
            let Some(row) = truth_at(truth, c.samples.t[i] + shift) else {
                continue;
            };
            matched += 1;
            if q {
                c.samples.q[i] = row.q;
            }
            if let (true, Some(s0)) = (d, s0) {
                c.samples.d[i] = row.arc - s0;
            }
        }
        if let (true, Some(s0)) = (d, s0) {
            for tag in &mut c.tags {
                if let Some(a) = arc_at(tag.t + shift) {
                    tag.d = a - s0;
                }
            }
        }
    }
    (matched, all)
}

/// Puts the truth's standing (phases standing and turning in place) into `curves` as their
/// stationary flags where a truth row lies within 0.1 ms, and makes the phone's distances
/// from them again.
fn put_stands(curves: &mut [Curve], truth: &[TruthSample], shifts: &[f64], nominal_speed: f64) {
    use sfs::orientation::flags::STATIONARY;
    for (c, shift) in curves.iter_mut().zip(shifts) {
        for i in 0..c.samples.len() {
            if let Some(s) = truth_at(truth, c.samples.t[i] + shift) {
                let f = &mut c.samples.flags[i];
                *f = if matches!(s.phase, 1 | 2) {
                    *f | STATIONARY
                } else {
                    *f & !STATIONARY
                };
            }
        }
        sfs::acquisition::phone_distances(c, nominal_speed);
    }
}

/// The curves acquired from a capture as `sfs replay` acquires them.
fn acquire(
    bin: &Path,
    settings: &(AcquisitionConfig, NetworkParams),
) -> Result<Vec<Curve>, String> {
    let bytes = std::fs::read(bin).map_err(|e| format!("{}: {e}", bin.display()))?;
    Ok(Acquisition::scan_bytes(&bytes, settings.0.clone()).curves)
}

fn load_truth(path: &Path) -> Result<Truth, String> {
    Truth::load(path).map_err(|e| e.to_string())
}

/// The curve mean error of `curves` reconstructed (with the daemon's default joins, issue 34),
/// % of the diagonal, or why there is none.
fn score_curves(curves: &[Curve], truth: &Truth, network: &NetworkParams) -> Result<f64, String> {
    let net = sfs_geometry::network::join::run_joined(
        &mut Reconstructor::new(),
        curves,
        network,
        &Default::default(),
    )
    .map_err(|e| format!("{:?}", e.warnings))?;
    let e = sfs::eval::evaluate(truth, &sfs::gltf_out::as_read_network(&net.positions))
        .map_err(|e| e.to_string())?;
    Ok(e.curves.mean_pct)
}

/// The curve mean error of one capture, % of the diagonal, or why there is none.
fn score(
    bin: &Path,
    truth: &Path,
    settings: &(AcquisitionConfig, NetworkParams),
) -> Result<f64, String> {
    score_curves(&acquire(bin, settings)?, &load_truth(truth)?, &settings.1)
}

/// Seconds of the acquired curves' samples by (truth phase, flagged stationary): how the
/// standing mask that the phone's distances rest on compares with what the operator did.
fn standing_mask(curves: &[Curve], truth: &[TruthSample], shifts: &[f64]) -> [[f64; 2]; 4] {
    let mut secs = [[0.0; 2]; 4];
    for (c, shift) in curves.iter().zip(shifts) {
        for i in 1..c.samples.len() {
            let t = c.samples.t[i];
            let Some(s) = truth_at(truth, t + shift) else {
                continue;
            };
            let still = c.samples.flags[i] & sfs::orientation::flags::STATIONARY != 0;
            secs[usize::from(s.phase.min(3))][usize::from(still)] += t - c.samples.t[i - 1];
        }
    }
    secs
}

/// One capture of the study: its error as is, with true q, true d and both; the share of its
/// samples the truth matched; its standing mask against the truth.
struct Study {
    errors: [f64; 4],
    /// The error with the true standing mask (phases standing and turning) and the
    /// distances made from it as the phone's are; NaN for a Morphorider.
    true_stands: f64,
    matched: f64,
    mask: [[f64; 2]; 4],
}

/// `--study --per-curve`: per acquired curve (on standard error), each segment's length as
/// acquired and as the truth has it (mm), and the median and 90th percentile of the angle
/// between the acquired and the true frames (degrees).
fn per_curve(name: &str, curves: &[Curve], truth: &[TruthSample], shifts: &[f64]) {
    let arc_before = |t: f64| {
        truth[..truth.partition_point(|s| s.t <= t)]
            .last()
            .map_or(f64::NAN, |s| s.arc)
    };
    for (c, shift) in curves.iter().zip(shifts) {
        let segments: Vec<String> = c
            .tags
            .windows(2)
            .map(|w| {
                let truth_mm = 1e3 * (arc_before(w[1].t + shift) - arc_before(w[0].t + shift));
                format!("{:.0}/{truth_mm:.0}", 1e3 * (w[1].d - w[0].d))
            })
            .collect();
        let mut angles: Vec<f64> = (0..c.samples.len())
            .filter_map(|i| {
                let s = truth_at(truth, c.samples.t[i] + shift)?;
                let a = c.samples.q[i];
                let dot = (0..4).map(|k| a[k] * s.q[k]).sum::<f64>().abs().min(1.0);
                Some(2.0 * dot.acos().to_degrees())
            })
            .collect();
        eprintln!("  timeline: {}", timeline(c, truth, *shift));
        eprintln!("  {}", body_offset(c, truth, *shift, 3));
        eprintln!("  {}", body_offset(c, truth, *shift, 1));
        angles.sort_by(f64::total_cmp);
        let at = |p: usize| {
            angles
                .get(angles.len() * p / 100)
                .copied()
                .unwrap_or(f64::NAN)
        };
        eprintln!(
            "{name} curve {} (shift {shift:.2} s): segments acquired/true mm {}; frame error median {:.1}°, p90 {:.1}°",
            c.index,
            segments.join(" "),
            at(50),
            at(90)
        );
    }
}

/// The timeline of `--per-curve` (see the module's documentation): per stretch of a 25th of
/// the curve's samples, `tilt/heading` error (°), the operator's phase, the disturbance mark
/// and the distance's error at its end (mm).
fn timeline(c: &Curve, truth: &[TruthSample], shift: f64) -> String {
    use nalgebra::{Quaternion, UnitQuaternion, Vector3};
    let quat =
        |a: [f64; 4]| UnitQuaternion::from_quaternion(Quaternion::new(a[0], a[1], a[2], a[3]));
    let n = c.samples.len();
    let bins = 25;
    let mut out = Vec::new();
    for b in 0..bins {
        let (lo, hi) = (n * b / bins, n * (b + 1) / bins);
        let (mut tilt, mut heading, mut k, mut phases, mut flagged) = (0.0, 0.0, 0, [0usize; 4], 0);
        let mut dd = f64::NAN;
        for i in lo..hi {
            if c.samples.flags[i] & sfs::orientation::flags::MAG_DISTURBED != 0 {
                flagged += 1;
            }
            let Some(s) = truth_at(truth, c.samples.t[i] + shift) else {
                continue;
            };
            let (qa, qt) = (quat(c.samples.q[i]), quat(s.q));
            // Tilt: the angle between the vertical as each frame sees it.
            let up = Vector3::z();
            tilt += (qa.inverse() * up).angle(&(qt.inverse() * up)).to_degrees();
            // Heading: the error rotation's twist about the vertical.
            let e = qa * qt.inverse();
            heading += 2.0
                * e.k
                    .atan2(e.w)
                    .abs()
                    .min(std::f64::consts::PI - e.k.atan2(e.w).abs())
                    .to_degrees();
            phases[usize::from(s.phase.min(3))] += 1;
            dd = c.samples.d[i] - s.arc;
            k += 1;
        }
        if k == 0 {
            continue;
        }
        let phase = (0..4).max_by_key(|&p| phases[p]).unwrap_or(0);
        let mark = if 2 * flagged > hi - lo {
            "*"
        } else if flagged > 0 {
            "'"
        } else {
            ""
        };
        out.push(format!(
            "{:.0}/{:.0}{}{mark}{:+.0}",
            tilt / k as f64,
            heading / k as f64,
            ["t", "S", "T", "m"][phase],
            dd * 1e3
        ));
    }
    out.join(" ")
}

/// The mean error rotation in the device's own frame, `q_true⁻¹ q_acquired` over the samples
/// where it moves (a rotation vector about T, B, N, degrees), and the spread about it: a
/// mounting offset (the sensor turned in the device) is the same on every curve.
fn body_offset(c: &Curve, truth: &[TruthSample], shift: f64, phase: u8) -> String {
    use nalgebra::{Quaternion, UnitQuaternion, Vector3};
    let quat =
        |a: [f64; 4]| UnitQuaternion::from_quaternion(Quaternion::new(a[0], a[1], a[2], a[3]));
    let errs: Vec<Vector3<f64>> = (0..c.samples.len())
        .filter_map(|i| {
            let s = truth_at(truth, c.samples.t[i] + shift)?;
            (s.phase == phase).then(|| (quat(s.q).inverse() * quat(c.samples.q[i])).scaled_axis())
        })
        .collect();
    let n = errs.len().max(1) as f64;
    let mean = errs.iter().sum::<Vector3<f64>>() / n;
    let sd = (errs.iter().map(|e| (e - mean).norm_squared()).sum::<f64>() / n).sqrt();
    format!(
        "body-frame error, phase {phase} (about T, B, N): {:+.2}° {:+.2}° {:+.2}°, spread {:.2}°",
        mean.x.to_degrees(),
        mean.y.to_degrees(),
        mean.z.to_degrees(),
        sd.to_degrees()
    )
}

/// `--study`: as is, true q, true d, both, per capture.
fn study(dir: &Path, captures: &[String], settings: &(AcquisitionConfig, NetworkParams)) {
    println!("| capture | as is | true q | true d | both | true stands | samples matched |");
    println!("|---|---|---|---|---|---|---|");
    let rows = parallel(captures, |c| {
        let curves = acquire(&dir.join(format!("{c}.bin")), settings)?;
        let truth = load_truth(&dir.join(format!("{c}.truth.json")))?;
        let samples = truth_samples(&dir.join(format!("{c}.samples.csv.gz")))?;
        let mut errors = [score_curves(&curves, &truth, &settings.1)?; 4];
        let shifts: Vec<f64> = curves
            .iter()
            .enumerate()
            .map(|(k, c)| clock_shift(c, k, &samples).unwrap_or(0.0))
            .collect();
        if std::env::args().any(|a| a == "--per-curve") {
            per_curve(c, &curves, &samples, &shifts);
        }
        let mut matched = 0.0;
        for (k, (q, d)) in [(true, false), (false, true), (true, true)]
            .into_iter()
            .enumerate()
        {
            let mut put = curves.clone();
            let (m, all) = put_truth(&mut put, &samples, &shifts, q, d);
            matched = m as f64 / all.max(1) as f64;
            errors[k + 1] = score_curves(&put, &truth, &settings.1)?;
        }
        let true_stands = if c.contains("phone") {
            let mut put = curves.clone();
            put_stands(&mut put, &samples, &shifts, settings.0.nominal_speed);
            score_curves(&put, &truth, &settings.1)?
        } else {
            f64::NAN
        };
        Ok::<_, String>(Study {
            errors,
            true_stands,
            matched,
            mask: standing_mask(&curves, &samples, &shifts),
        })
    });
    for (c, r) in captures.iter().zip(&rows) {
        match r {
            Ok(r) => println!(
                "| {c} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} | {:.1} % |",
                r.errors[0],
                r.errors[1],
                r.errors[2],
                r.errors[3],
                r.true_stands,
                100.0 * r.matched
            ),
            Err(e) => println!("| {c} | failed: {e} |"),
        }
    }
    println!("\nSeconds of the acquired curves by what the operator did (truth phase) and whether the sample is flagged stationary (matched samples only):\n");
    println!(
        "| capture | standing: flagged / not | turning: flagged / not | moving: flagged / not |"
    );
    println!("|---|---|---|---|");
    for (c, r) in captures.iter().zip(&rows) {
        match r {
            Ok(Study { mask: m, .. }) => println!(
                "| {c} | {:.1} / {:.1} | {:.1} / {:.1} | {:.1} / {:.1} |",
                m[1][1], m[1][0], m[2][1], m[2][0], m[3][1], m[3][0]
            ),
            Err(e) => println!("| {c} | failed: {e} |"),
        }
    }
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let dir = args
        .iter()
        .position(|a| a == "--dir")
        .and_then(|i| args.get(i + 1))
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/validation"));
    let mut settings = shared::config(&args);
    // Mechanisms of the field-accuracy work that no configuration key turns off.
    if args.iter().any(|a| a == "--no-bridge") {
        settings.0.bridge_heading = false;
    }
    if args.iter().any(|a| a == "--no-smooth") {
        settings.0.smooth = false;
    }
    let figures = readme_figures(&dir);
    let mut captures: Vec<String> = match args.iter().any(|a| a == "--captures") {
        true => list(&args, "--captures", ""),
        false => std::fs::read_dir(&dir)
            .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
            .filter_map(|e| e.ok())
            .filter_map(|e| {
                let name = e.file_name().to_string_lossy().into_owned();
                name.strip_suffix(".bin").map(str::to_owned)
            })
            .collect(),
    };
    captures.sort_by_key(|c| (c.contains("phone"), c.contains("rough"), c.clone()));
    if args.iter().any(|a| a == "--study") {
        return study(&dir, &captures, &settings);
    }
    let results = parallel(&captures, |c| {
        score(
            &dir.join(format!("{c}.bin")),
            &dir.join(format!("{c}.truth.json")),
            &settings,
        )
    });
    println!("| capture | error | target | before (baa97be) | 1b493a8 | target met | within 5 % of before |");
    println!("|---|---|---|---|---|---|---|");
    let (mut met, mut kept) = (0, 0);
    for (c, r) in captures.iter().zip(&results) {
        let (before, then, target) =
            figures
                .get(c)
                .copied()
                .unwrap_or((f64::NAN, f64::NAN, f64::NAN));
        match r {
            Ok(e) => {
                let ok = *e <= target;
                let held = *e <= before * 1.05;
                met += usize::from(ok);
                kept += usize::from(held);
                println!(
                    "| {c} | {} | {target:.2} | {before:.3} | {then:.3} | {} | {} |",
                    if ok {
                        format!("{e:.3}")
                    } else {
                        format!("**{e:.3}**")
                    },
                    if ok { "yes" } else { "no" },
                    if held { "yes" } else { "no" },
                );
            }
            Err(e) => {
                println!("| {c} | failed: {e} | {target:.2} | {before:.3} | {then:.3} | no | no |")
            }
        }
    }
    println!(
        "\n{met} of {} captures meet their target; {kept} are within 5 % of their figure before the field-accuracy work.",
        captures.len()
    );
}
