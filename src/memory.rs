//! The process's memory: resident size as the operating system sees it, and returning what
//! the allocator holds but no longer uses (a long-running daemon's figures in `report.json`).

/// Returns memory the allocator holds but no longer uses to the operating system (glibc keeps
/// freed blocks in per-thread arenas; after a reconstruction of an hour-long scan that is
/// ~40 MB that a long-running daemon would otherwise keep). A no-op elsewhere.
pub fn release_free_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    {
        extern "C" {
            fn malloc_trim(pad: usize) -> i32;
        }
        // SAFETY: glibc's malloc_trim only releases free pages of its own arenas; it takes no
        // pointers and is safe to call at any time from any thread.
        unsafe {
            malloc_trim(0);
        }
    }
}

/// Resident and peak resident memory of this process, MB (`None` off Linux).
pub fn rss_mb() -> (Option<f64>, Option<f64>) {
    let Ok(status) = std::fs::read_to_string("/proc/self/status") else {
        return (None, None);
    };
    let field = |name: &str| {
        status
            .lines()
            .find(|l| l.starts_with(name))
            .and_then(|l| l.split_whitespace().nth(1))
            .and_then(|kb| kb.parse::<f64>().ok())
            .map(|kb| kb / 1024.0)
    };
    (field("VmRSS:"), field("VmHWM:"))
}
