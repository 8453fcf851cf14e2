//! Issue 14: the layering the workspace promises. The geometry crate does no I/O (its
//! manifest names only the numerical crates, error and logging facades, and serde behind a
//! feature), and no crate of the workspace has an import cycle between its modules.

use std::path::Path;

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

#[test]
fn issue_14_the_geometry_crate_depends_on_nothing_that_does_io() {
    let manifest: toml::Table = std::fs::read_to_string(root().join("geometry/Cargo.toml"))
        .unwrap()
        .parse()
        .unwrap();
    let deps: Vec<&String> = manifest["dependencies"]
        .as_table()
        .unwrap()
        .keys()
        .collect();
    let allowed = ["nalgebra", "faer", "spade", "thiserror", "tracing", "serde"];
    for d in &deps {
        assert!(
            allowed.contains(&d.as_str()),
            "sfs-geometry depends on {d}: the geometry does no I/O ({allowed:?} only)"
        );
    }
    assert!(
        manifest["dependencies"]["serde"]["optional"]
            .as_bool()
            .unwrap_or(false),
        "serde is an optional feature of the geometry"
    );
}

#[test]
fn issue_14_no_module_import_cycles() {
    let tool = root().join("../shared/tools/rust_imports.py");
    if !tool.exists() {
        eprintln!("skipped: ../shared/tools is not beside the repository");
        return;
    }
    // Every crate of the workspace, named.
    let out = std::process::Command::new("python3")
        .arg(&tool)
        .args(["src", "geometry/src", "device-protocol/src"])
        .current_dir(root())
        .output()
        .expect("python3 runs");
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        text.to_lowercase().contains("no import cycles") && !text.contains("import cycle:"),
        "{text}"
    );
}
