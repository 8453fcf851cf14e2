/// The x86-64 micro-architecture level faer's kernels dispatch on (and so the rounding of the
/// outputs): shared by `build.rs` and `tests/outputs_unchanged.rs` through `include!`.
fn simd_level() -> &'static str {
    #[cfg(target_arch = "x86_64")]
    {
        if std::arch::is_x86_feature_detected!("avx512f") {
            return "x86-64-v4";
        }
        if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
        {
            return "x86-64-v3";
        }
        "x86-64"
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        std::env::consts::ARCH
    }
}

/// Whether a digests file (its text, `digests`) was made (or checked, the same digests) on
/// this machine's SIMD level: its first line ends `made on LEVEL[, LEVEL…]`.
fn made_on_this_level(digests: &str) -> bool {
    digests
        .lines()
        .next()
        .and_then(|l| l.split_once("made on "))
        .is_some_and(|(_, levels)| levels.split(", ").any(|l| l.trim() == simd_level()))
}
