//! Helpers of the table examples (`accuracy_table`, `kinds_table`, `validation_table`).

use sfs::acquisition::AcquisitionConfig;
use sfs_geometry::network::NetworkParams;

/// The comma-separated values after `flag` in `args`, or `default`'s.
pub fn list(args: &[String], flag: &str, default: &str) -> Vec<String> {
    args.iter()
        .position(|a| a == flag)
        .and_then(|i| args.get(i + 1))
        .map_or(default, |s| s.as_str())
        .split(',')
        .map(str::to_owned)
        .collect()
}

#[allow(dead_code)]
/// The acquisition and network settings: `--config FILE`'s, or the defaults; `--no-skids`
/// leaves the Morphorider's wheel skids unfilled ([`sfs::acquisition::skid`]).
pub fn config(args: &[String]) -> (AcquisitionConfig, NetworkParams) {
    let mut settings = match args.iter().position(|a| a == "--config") {
        Some(i) => {
            let path = args.get(i + 1).expect("--config FILE");
            let s = sfs::config::load(std::path::Path::new(path))
                .unwrap_or_else(|e| panic!("--config {path}: {e}"));
            (s.acquisition, s.network)
        }
        None => (AcquisitionConfig::default(), NetworkParams::default()),
    };
    // Issue 33: the Morphorider's wheel skids left unfilled (for comparisons).
    if args.iter().any(|a| a == "--no-skids") {
        settings.0.fill_skids = false;
    }
    settings
}

#[allow(dead_code)]
/// Runs `f` over `jobs` on two threads.
pub fn parallel<J: Sync, R: Send>(jobs: &[J], f: impl Fn(&J) -> R + Sync) -> Vec<R> {
    let next = std::sync::atomic::AtomicUsize::new(0);
    let results = std::sync::Mutex::new((0..jobs.len()).map(|_| None).collect::<Vec<_>>());
    std::thread::scope(|sc| {
        for _ in 0..2 {
            sc.spawn(|| loop {
                let i = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                let Some(j) = jobs.get(i) else {
                    return;
                };
                let r = f(j);
                results.lock().unwrap()[i] = Some(r);
            });
        }
    });
    results
        .into_inner()
        .unwrap()
        .into_iter()
        .map(|r| r.expect("every job ran"))
        .collect()
}

#[allow(dead_code)]
/// `--devices` (default both).
pub fn devices(args: &[String]) -> Vec<device_protocol::DeviceKind> {
    list(args, "--devices", "morphorider,phone")
        .iter()
        .map(|d| match d.as_str() {
            "phone" => device_protocol::DeviceKind::Phone,
            "morphorider" => device_protocol::DeviceKind::Morphorider,
            other => panic!("--devices: {other} is not morphorider or phone"),
        })
        .collect()
}

#[allow(dead_code)]
/// `--profiles` (default both).
pub fn profiles(args: &[String]) -> Vec<sfs::simulate::Profile> {
    list(args, "--profiles", "default,field")
        .iter()
        .map(|p| match p.as_str() {
            "default" => sfs::simulate::Profile::Default,
            "field" => sfs::simulate::Profile::Field,
            other => panic!("--profiles: {other} is not default or field"),
        })
        .collect()
}

#[allow(dead_code)]
/// `--seeds`, numbers separated by commas (else `default`'s).
pub fn seeds(args: &[String], default: &str) -> Vec<u64> {
    list(args, "--seeds", default)
        .iter()
        .map(|s| s.parse().expect("--seeds: numbers separated by commas"))
        .collect()
}
