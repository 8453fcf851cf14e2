//! Orientation errors of a simulated scan, split into tilt and heading, per curve: which part
//! of the frames the reconstruction error comes from.
//!
//! `cargo run --release --example orientation_study -- SCENE [phone|morphorider] [default|field] [SEED]`
//!
//! Environment: `SFS_SHOW_FALSE_STAND` / `SFS_SHOW_MISSED_STAND` list samples flagged standing
//! while moving / moving while standing; `SFS_SHOW_WORST` includes standing samples in the
//! orientation errors; `SFS_SHOW_MID` prints each segment's distance error at its middle;
//! `SFS_TRACE=CURVE` prints that curve's errors every 200 samples.

use device_protocol::DeviceKind;
use nalgebra::{Quaternion, UnitQuaternion, Vector3};
use sfs::acquisition::{Acquisition, AcquisitionConfig};
use sfs::simulate::{self, scene, Profile};

fn main() {
    let a: Vec<String> = std::env::args().skip(1).collect();
    let name = a.first().map_or("bowl", |s| s.as_str());
    let device = match a.get(1).map(|s| s.as_str()) {
        Some("phone") => DeviceKind::Phone,
        _ => DeviceKind::Morphorider,
    };
    let profile = match a.get(2).map(|s| s.as_str()) {
        Some("field") => Profile::Field,
        _ => Profile::Default,
    };
    let seed = a.get(3).and_then(|s| s.parse().ok()).unwrap_or(1);
    let s = scene::builtin(name).expect("scene");
    let sim = simulate::run(&s, device, profile, seed);
    let mut cfg = AcquisitionConfig::default();
    // Parameter studies: SFS_TAU_MAG, SFS_TAU_BIAS override the phone filter's defaults.
    let env = |k: &str| std::env::var(k).ok().and_then(|v| v.parse::<f64>().ok());
    if let Some(v) = env("SFS_TAU_MAG") {
        cfg.ahrs.tau_mag = v;
    }
    if let Some(v) = env("SFS_TAU_HB") {
        cfg.ahrs.tau_heading_bias = v;
    }
    if let Some(v) = env("SFS_TAU_TB") {
        cfg.ahrs.tau_tilt_bias = v;
    }
    if let Some(v) = env("SFS_TAU_BIAS") {
        cfg.ahrs.tau_bias = v;
    }
    let scan = Acquisition::scan_bytes(&sim.bytes, cfg);
    let truth = &sim.samples;
    println!("curve  samples  total(median/p90)  tilt(median)  heading(median, mean signed)");
    for c in &scan.curves {
        let (mut tot, mut tilt, mut head) = (vec![], vec![], vec![]);
        for (i, q) in c.samples.q.iter().enumerate() {
            let t = c.samples.t[i];
            let k = truth.session_t.partition_point(|&x| x < t - 2e-6);
            if k >= truth.t.len()
                || (truth.session_t[k] - t).abs() > 2e-6
                || (truth.standing[k] && std::env::var("SFS_SHOW_WORST").is_err())
            {
                continue;
            }
            let est = UnitQuaternion::new_normalize(Quaternion::new(q[0], q[1], q[2], q[3]));
            let tq = truth.q[k];
            tot.push(est.angle_to(&tq).to_degrees());
            if std::env::var("SFS_SHOW_WORST").is_ok() && est.angle_to(&tq).to_degrees() > 20.0 {
                println!(
                    "  curve {} t {:.2} s {:.3} err {:.1}°",
                    c.index,
                    c.samples.t[i],
                    truth.s[k],
                    est.angle_to(&tq).to_degrees()
                );
            }
            let up_e = est.inverse() * Vector3::z();
            let up_t = tq.inverse() * Vector3::z();
            tilt.push(up_e.angle(&up_t).to_degrees());
            // Heading: the rotation about world z left after aligning the tilts.
            let d = est * tq.inverse();
            let x = d * Vector3::x();
            head.push(x.y.atan2(x.x).to_degrees());
            if std::env::var("SFS_TRACE")
                .ok()
                .and_then(|v| v.parse::<usize>().ok())
                == Some(c.index)
                && i % 200 == 0
            {
                println!(
                    "  t {:.1} s {:.3} heading {:+.1}° tilt {:.2}° flags {:#x}",
                    c.samples.t[i],
                    truth.s[k],
                    head.last().copied().unwrap_or(0.0),
                    tilt.last().copied().unwrap_or(0.0),
                    c.samples.flags[i]
                );
            }
        }
        if tot.is_empty() {
            continue;
        }
        // Distance: the estimate against the truth (from the first tag), RMS and worst, mm;
        // and the share of truly standing samples flagged standing, and of moving ones.
        let near = |t: f64| {
            let k = truth.session_t.partition_point(|&x| x < t - 2e-6);
            (k < truth.t.len() && (truth.session_t[k] - t).abs() < 2e-6).then_some(k)
        };
        if let Some(k0) = c.tags.first().and_then(|g| near(g.t)) {
            let (mut se, mut worst, mut m) = (0.0, 0.0f64, 0);
            let (mut st, mut st_flag, mut mv, mut mv_flag) = (0, 0, 0, 0);
            for i in 0..c.samples.len() {
                if let Some(k) = near(c.samples.t[i]) {
                    let e = c.samples.d[i] - (truth.s[k] - truth.s[k0]);
                    se += e * e;
                    worst = worst.max(e.abs());
                    m += 1;
                    let flagged = c.samples.flags[i] & sfs::orientation::flags::STATIONARY != 0;
                    if flagged
                        && !truth.standing[k]
                        && std::env::var("SFS_SHOW_FALSE_STAND").is_ok()
                        && i % 50 == 0
                    {
                        println!(
                            "  curve {} t {:.2} s {:.3} flagged standing while moving",
                            c.index, c.samples.t[i], truth.s[k]
                        );
                    }
                    if !flagged
                        && truth.standing[k]
                        && std::env::var("SFS_SHOW_MISSED_STAND").is_ok()
                        && i % 20 == 0
                    {
                        println!(
                            "  curve {} t {:.2} s {:.3} standing, not flagged",
                            c.index, c.samples.t[i], truth.s[k]
                        );
                    }
                    if truth.standing[k] {
                        st += 1;
                        st_flag += flagged as usize;
                    } else {
                        mv += 1;
                        mv_flag += flagged as usize;
                    }
                }
            }
            if std::env::var("SFS_SHOW_MID").is_ok() {
                for w in c.tags.windows(2) {
                    let mid = 0.5 * (w[0].d + w[1].d);
                    let i = c.samples.d.partition_point(|&d| d < mid);
                    if let Some(k) = c.samples.t.get(i).and_then(|&t| near(t)) {
                        let e = c.samples.d[i] - (truth.s[k] - truth.s[k0]);
                        print!("mid {:+.1} ", e * 1e3);
                    }
                }
                println!();
            }
            print!(
                "d rms {:5.1} max {:5.1} mm, standing flagged {:3.0} % moving flagged {:3.0} % | ",
                (se / m.max(1) as f64).sqrt() * 1e3,
                worst * 1e3,
                100.0 * st_flag as f64 / st.max(1) as f64,
                100.0 * mv_flag as f64 / mv.max(1) as f64
            );
        }
        let disturbed = c
            .samples
            .flags
            .iter()
            .filter(|&&f| f & sfs::orientation::flags::MAG_DISTURBED != 0)
            .count();
        print!("{disturbed:6} disturbed ");
        let med = |mut v: Vec<f64>, p: f64| {
            v.sort_by(f64::total_cmp);
            v[((v.len() - 1) as f64 * p) as usize]
        };
        let mean_h = head.iter().sum::<f64>() / head.len() as f64;
        let abs_h: Vec<f64> = head.iter().map(|h| h.abs()).collect();
        println!(
            "{:5}  {:7}  {:6.2}° / {:6.2}°   {:6.2}°      {:6.2}°, {:+6.2}°",
            c.index,
            tot.len(),
            med(tot.clone(), 0.5),
            med(tot, 0.9),
            med(tilt, 0.5),
            med(abs_h, 0.5),
            mean_h
        );
    }
}
