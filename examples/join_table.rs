//! The joins' table of BENCHMARKS.md (issue 34): each scene simulated with every crossing
//! tagged, with a fraction of them left untagged on one of their curves (`sfs simulate
//! --untagged`), reconstructed without joins and with them; scored with the paper's metric
//! (mean distance of the curve points to the truth network, % of the diagonal).
//!
//! `cargo run --release --example join_table -- [--seeds 1,2,3] [--devices morphorider,phone]
//! [--profiles default,field] [--scenes a,b] [--fraction 0.333] [--untagged]`
//!
//! Per cell: `full / untagged / joined` error, then the crossings left out, those joined
//! right, false joins (a node joined to a curve it is not on), joins refused, proposals, the
//! passes and the time the joins added (ms). `--untagged`: `[network] join_untagged = true`.
//! Diagnostics: `SFS_TRUE_D=1` / `SFS_TRUE_Q=1` put the simulator's true distances /
//! orientations into every capture (as `kinds_table` does).

use device_protocol::DeviceKind;
use sfs::acquisition::{Acquisition, AcquisitionConfig};
use sfs::simulate::{self, scene, Mistakes, Profile};
use sfs_geometry::network::join::{JoinParams, JoinSettings};
use sfs_geometry::network::{NetworkParams, Reconstructor};

#[path = "shared/mod.rs"]
mod shared;
use shared::{list, parallel};

const SCENES: &[&str] = &[
    "ellipsoid-dense",
    "lilium",
    "box",
    "sphere-octa",
    "cone",
    "relief",
    "bowl",
    "torus",
];

struct Cell {
    full: f64,
    untagged: f64,
    joined: f64,
    oracle: f64,
    left_out: usize,
    /// Left out on a curve that then hangs free (none of its nodes on another curve): only
    /// its normals could place it.
    free: usize,
    right: usize,
    wrong: usize,
    refused: usize,
    proposed: usize,
    passes: usize,
    join_ms: f64,
}

fn cell(
    name: &str,
    device: DeviceKind,
    profile: Profile,
    seed: u64,
    fraction: f64,
    untagged: bool,
) -> Result<Cell, String> {
    let s = scene::builtin(name).map_err(|e| e.to_string())?;
    let off = JoinSettings {
        params: JoinParams {
            distance_m: 0.0,
            ..Default::default()
        },
        ..Default::default()
    };
    let on = JoinSettings {
        untagged,
        ..Default::default()
    };
    let specs = s.specs();
    let run = |m: &Mistakes, js: &JoinSettings, oracle: bool| {
        let sim = simulate::run_with(&s, device, profile, seed, m);
        let mut scan = Acquisition::scan_bytes(&sim.bytes, AcquisitionConfig::default());
        // Diagnostics: the simulator's true distances and/or orientations put in.
        let (true_q, true_d) = (
            std::env::var("SFS_TRUE_Q").is_ok(),
            std::env::var("SFS_TRUE_D").is_ok(),
        );
        if true_q || true_d {
            sim.samples.put_into(&mut scan.curves, true_q, true_d);
        }
        if oracle {
            // Each untagged crossing tagged where the device truly passed it.
            let mut joins = Vec::new();
            for &(ci, k) in &m.untagged {
                let sp = &specs[ci];
                let at: f64 = sp.points[..=sp.tags[k].0]
                    .windows(2)
                    .map(|w| (w[1] - w[0]).norm())
                    .sum();
                let Some(c) = scan.curves.iter().find(|c| c.index == ci) else {
                    continue;
                };
                let ts = &sim.samples.session_t;
                let truth_s = |t: f64| {
                    let j = ts.partition_point(|&x| x < t).min(ts.len() - 1);
                    sim.samples.s[j]
                };
                let s0 = truth_s(c.tags[0].t);
                let Some(i) = (1..c.samples.len()).find(|&i| truth_s(c.samples.t[i]) - s0 >= at)
                else {
                    continue;
                };
                joins.push(sfs_geometry::network::join::Join {
                    node: sp.tags[k].1,
                    curve: ci,
                    home: ci,
                    d: c.samples.d[i],
                    arc_length_m: 0.0,
                    distance_m: 0.0,
                    normal_deg: 0.0,
                });
            }
            sfs_geometry::network::join::apply_joins(&mut scan.curves, &joins);
        }
        let net = sfs_geometry::network::join::run_joined(
            &mut Reconstructor::new(),
            &scan.curves,
            &NetworkParams::default(),
            js,
        )
        .map_err(|e| e.to_string())?;
        let e = sfs::eval::evaluate(&sim.truth, &sfs::gltf_out::as_read_network(&net.positions))
            .map_err(|e| e.to_string())?;
        Ok::<_, String>((e.curves.mean_pct, net))
    };
    let (full, full_net) = run(&Mistakes::default(), &off, false)?;
    let m = Mistakes {
        untagged: simulate::untagged_crossings(&s, fraction, seed),
        ..Default::default()
    };
    let (untagged_err, un_net) = run(&m, &off, false)?;
    if std::env::var_os("SFS_JOIN_DEBUG").is_some() {
        let loose = JoinParams {
            distance_m: 0.2,
            normal_deg: 180.0,
            noise_factor: 0.0,
        };
        for c in &un_net.positions.curves {
            eprintln!(
                "  curve {} {:?} nodes {:?} d {:.3}..{:.3} max step {:.4}",
                c.index,
                c.kind,
                c.nodes.iter().map(|x| x.1).collect::<Vec<_>>(),
                c.d[0],
                c.d[c.d.len() - 1],
                c.d.windows(2).map(|w| w[1] - w[0]).fold(0.0, f64::max)
            );
        }
        for j in sfs_geometry::network::join::find_joins(&un_net.positions, &loose) {
            eprintln!(
                "  candidate node {} on curve {} (home {}): gap {:.1} mm, normals {:.0}°",
                j.node,
                j.curve,
                j.home,
                j.distance_m * 1e3,
                j.normal_deg
            );
        }
    }
    let (joined, net) = run(&m, &on, false)?;
    let cs = &un_net.positions.curves;
    let hangs_free = |node: u32| {
        cs.iter().any(|c| {
            c.nodes.iter().any(|x| x.1 == node)
                && c.nodes.iter().all(|x| {
                    !cs.iter()
                        .any(|o| o.index != c.index && o.nodes.iter().any(|y| y.1 == x.1))
                })
        })
    };
    let free = m
        .untagged
        .iter()
        .filter(|&&(c, k)| hangs_free(specs[c].tags[k].1))
        .count();
    let (oracle, _) = run(&m, &off, true)?;
    let truth = |node: u32, curve: usize| {
        m.untagged
            .iter()
            .any(|&(c, k)| c == curve && specs[c].tags[k].1 == node)
    };
    let r = &net.report;
    if std::env::var_os("SFS_JOIN_DEBUG").is_some() {
        eprintln!(
            "{name} {} {} s{seed}: left out {:?}, components {}, refused {:?}",
            device.name(),
            profile.name(),
            m.untagged
                .iter()
                .map(|&(c, k)| (specs[c].tags[k].1, c))
                .collect::<Vec<_>>(),
            r.components,
            r.joins_refused
        );
        for j in &r.joined {
            // The node's arc length on the same curve fully tagged, from its first node.
            let c = full_net
                .positions
                .curves
                .iter()
                .find(|c| c.index == j.curve);
            let tagged = c.and_then(|c| {
                let i = c.nodes.iter().find(|x| x.1 == j.node)?.0;
                Some(c.d[i] - c.d[0])
            });
            eprintln!(
                "{name} {} {} s{seed}: node {} on curve {}: joined at {:.1} mm, tagged at {:?} mm; gap {:.1} mm; misfit {:?} / {:?}",
                device.name(),
                profile.name(),
                j.node,
                j.curve,
                j.arc_length_m * 1e3,
                tagged.map(|t| (t * 1e3 * 10.0).round() / 10.0),
                j.distance_m * 1e3,
                j.misfit_before_m.map(|x| (x * 1e4).round() / 10.0),
                j.misfit_after_m.map(|x| (x * 1e4).round() / 10.0),
            );
        }
    }
    let right = r
        .joined
        .iter()
        .filter(|j| !j.untagged && truth(j.node, j.curve))
        .count();
    Ok(Cell {
        full,
        untagged: untagged_err,
        joined,
        oracle,
        left_out: m.untagged.len(),
        free,
        right,
        wrong: r
            .joined
            .iter()
            .filter(|j| !j.untagged && !truth(j.node, j.curve))
            .count(),
        refused: r.joins_refused.len(),
        proposed: r.proposed.len() + r.joined.iter().filter(|j| j.untagged).count() / 2,
        passes: r.join_passes,
        join_ms: r.timings_ms.join,
    })
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let seeds = shared::seeds(&args, "1,2,3");
    let devices = shared::devices(&args);
    let profiles = shared::profiles(&args);
    let scenes = list(&args, "--scenes", &SCENES.join(","));
    let fraction: f64 = list(&args, "--fraction", "0.3333333333333333")[0]
        .parse()
        .expect("--fraction: a number");
    let untagged = args.iter().any(|a| a == "--untagged");
    let mut jobs = Vec::new();
    for sc in &scenes {
        for &d in &devices {
            for &p in &profiles {
                for &seed in &seeds {
                    jobs.push((sc.clone(), d, p, seed));
                }
            }
        }
    }
    let results = parallel(&jobs, |(sc, d, p, seed)| {
        cell(sc, *d, *p, *seed, fraction, untagged)
    });
    println!("| scene | device | profile | seed | full % | untagged % | joined % | at the true place % | joined / left out (free) | false | refused | proposed | passes | join ms |");
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    for ((sc, d, p, seed), r) in jobs.iter().zip(&results) {
        match r {
            Ok(c) => println!(
                "| {sc} | {} | {} | {seed} | {:.3} | {:.3} | {:.3} | {:.3} | {} / {} ({}) | {} | {} | {} | {} | {:.0} |",
                d.name(),
                p.name(),
                c.full,
                c.untagged,
                c.joined,
                c.oracle,
                c.right,
                c.left_out,
                c.free,
                c.wrong,
                c.refused,
                c.proposed,
                c.passes,
                c.join_ms
            ),
            Err(e) => println!("| {sc} | {} | {} | {seed} | failed: {e} |", d.name(), p.name()),
        }
    }
    // Per scene, device and profile: the means over the seeds and the ratio to fully tagged.
    println!();
    println!("| scene | device | profile | full % | untagged % | joined % | at the true place % | joined / full | joined / left out (free) | false | join ms (max) |");
    println!("|---|---|---|---|---|---|---|---|---|---|");
    for sc in &scenes {
        for &d in &devices {
            for &p in &profiles {
                let cells: Vec<&Cell> = jobs
                    .iter()
                    .zip(&results)
                    .filter(|(j, _)| &j.0 == sc && j.1 == d && j.2 == p)
                    .filter_map(|(_, r)| r.as_ref().ok())
                    .collect();
                if cells.is_empty() {
                    continue;
                }
                let n = cells.len() as f64;
                let mean = |f: &dyn Fn(&Cell) -> f64| cells.iter().map(|c| f(c)).sum::<f64>() / n;
                let (full, un, jo) = (
                    mean(&|c| c.full),
                    mean(&|c| c.untagged),
                    mean(&|c| c.joined),
                );
                let or = mean(&|c| c.oracle);
                println!(
                    "| {sc} | {} | {} | {full:.3} | {un:.3} | {jo:.3} | {or:.3} | {:.2} | {} / {} ({}) | {} | {:.0} |",
                    d.name(),
                    p.name(),
                    jo / full,
                    cells.iter().map(|c| c.right).sum::<usize>(),
                    cells.iter().map(|c| c.left_out).sum::<usize>(),
                    cells.iter().map(|c| c.free).sum::<usize>(),
                    cells.iter().map(|c| c.wrong).sum::<usize>(),
                    cells.iter().map(|c| c.join_ms).fold(0.0, f64::max)
                );
            }
        }
    }
}
