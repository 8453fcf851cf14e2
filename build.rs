//! What this machine can run of the optional tests, told to cargo as `cfg`s so that a test that
//! cannot run here is reported as ignored with its reason (`#[cfg_attr(not(…), ignore = "…")]`),
//! never skipped while it passes. Nothing here changes the library or the binary.
//!
//! | cfg | set when |
//! |---|---|
//! | `sfs_chromium` | `/usr/bin/chromium` and `/usr/bin/chromedriver` exist (Debian's `chromium`, `chromium-driver`), or `SFS_REQUIRE_BROWSER` is set |
//! | `sfs_systemd_analyze` | `systemd-analyze` is on `PATH` (Debian's `systemd`), or `SFS_REQUIRE_SYSTEMD` is set |
//! | `sfs_promtool` | `promtool` is on `PATH` (Debian's `prometheus`), or `SFS_REQUIRE_PROMTOOL` is set |
//! | `sfs_paper_data` | `SFS_PAPER_DATA` names a directory with the paper's meshes (`lilium.obj`, `bumpy-cube.obj`) |
//! | `sfs_dev_full` | `/dev/full` exists |
//! | `sfs_golden_simd` | this machine's SIMD level is one `tests/golden/outputs.txt` was made on |
//!
//! A `SFS_REQUIRE_*` variable (`.ci/run` sets them) makes the tests run, and fail, where the
//! tool is missing. The directories on `PATH` are watched, so installing a package builds the
//! tests again with its tests enabled.

use std::path::Path;

fn main() {
    let flags = [
        "sfs_chromium",
        "sfs_systemd_analyze",
        "sfs_promtool",
        "sfs_paper_data",
        "sfs_dev_full",
        "sfs_golden_simd",
    ];
    for f in flags {
        println!("cargo::rustc-check-cfg=cfg({f})");
    }
    println!("cargo::rerun-if-changed=build.rs");
    println!("cargo::rerun-if-changed=tests/golden/outputs.txt");
    println!("cargo::rerun-if-changed=tests/golden/simd_level.rs");
    for v in [
        "PATH",
        "SFS_PAPER_DATA",
        "SFS_REQUIRE_BROWSER",
        "SFS_REQUIRE_SYSTEMD",
        "SFS_REQUIRE_PROMTOOL",
    ] {
        println!("cargo::rerun-if-env-changed={v}");
    }
    let path_dirs: Vec<std::path::PathBuf> = std::env::var_os("PATH")
        .map(|p| std::env::split_paths(&p).collect())
        .unwrap_or_default();
    // A package installed later adds a file to one of these: its mtime changes.
    for d in path_dirs.iter().filter(|d| d.is_absolute() && d.is_dir()) {
        println!("cargo::rerun-if-changed={}", d.display());
    }
    let on_path = |exe: &str| path_dirs.iter().any(|d| d.join(exe).is_file());
    let required = |v: &str| std::env::var_os(v).is_some_and(|s| !s.is_empty());

    let set = |f: &str, on: bool| {
        if on {
            println!("cargo::rustc-cfg={f}");
        }
    };
    set(
        "sfs_chromium",
        (Path::new("/usr/bin/chromium").exists() && Path::new("/usr/bin/chromedriver").exists())
            || required("SFS_REQUIRE_BROWSER"),
    );
    set(
        "sfs_systemd_analyze",
        on_path("systemd-analyze") || required("SFS_REQUIRE_SYSTEMD"),
    );
    set(
        "sfs_promtool",
        on_path("promtool") || required("SFS_REQUIRE_PROMTOOL"),
    );
    set(
        "sfs_paper_data",
        std::env::var_os("SFS_PAPER_DATA").is_some_and(|d| {
            let d = Path::new(&d);
            d.join("lilium.obj").is_file() && d.join("bumpy-cube.obj").is_file()
        }),
    );
    set("sfs_dev_full", Path::new("/dev/full").exists());
    let golden = std::fs::read_to_string("tests/golden/outputs.txt").unwrap_or_default();
    set("sfs_golden_simd", made_on_this_level(&golden));
}

include!("tests/golden/simd_level.rs");
