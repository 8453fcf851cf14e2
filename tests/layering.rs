//! Issue 14: the layering the workspace promises. The geometry crate does no I/O (its
//! manifest names only the numerical crates, error and logging facades, and serde behind a
//! feature), and no crate of the workspace has an import cycle between its modules (read
//! here from their `crate::…` paths, no tool beside the repository needed).

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

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

/// The modules of a crate (`src/a/b.rs` and `src/a/b/mod.rs` are `a::b`; `lib.rs`, `main.rs`
/// the root) and the files that hold them.
fn modules(src: &Path) -> BTreeMap<Vec<String>, PathBuf> {
    fn walk(dir: &Path, src: &Path, out: &mut BTreeMap<Vec<String>, PathBuf>) {
        for e in std::fs::read_dir(dir).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                walk(&p, src, out);
            } else if p.extension().is_some_and(|x| x == "rs") {
                let rel = p.strip_prefix(src).unwrap().with_extension("");
                let mut parts: Vec<String> = rel
                    .components()
                    .map(|c| c.as_os_str().to_string_lossy().into_owned())
                    .collect();
                if matches!(
                    parts.last().map(String::as_str),
                    Some("mod" | "lib" | "main")
                ) {
                    parts.pop();
                }
                out.insert(parts, p);
            }
        }
    }
    let mut out = BTreeMap::new();
    walk(src, src, &mut out);
    out
}

/// Every `crate::…` path in `text` (use declarations, groups `crate::{a, b::{c, d}}` included,
/// and qualified names), as its segments; the unit tests at the end of a file and comments
/// (a doc link names a module, it does not import it) do not count.
fn crate_paths(text: &str) -> Vec<Vec<String>> {
    paths_after(text, "crate::")
}

/// Every path in `text` that follows `start` (`crate::`, `super::`, `self::`, `use `), as its
/// segments (see [`crate_paths`]).
fn paths_after(text: &str, start: &str) -> Vec<Vec<String>> {
    let text = &text[..text.find("#[cfg(test)]").unwrap_or(text.len())];
    let code: String = text
        .lines()
        .filter(|l| !l.trim_start().starts_with("//"))
        .flat_map(|l| [l, "\n"])
        .collect();
    let text = code.as_str();
    let b = text.as_bytes();
    let ident = |i: usize| {
        let n = b[i..]
            .iter()
            .take_while(|c| c.is_ascii_alphanumeric() || **c == b'_')
            .count();
        (text[i..i + n].to_owned(), i + n)
    };
    // The paths that start at `i` (just after a `::`), prefixed by `prefix`.
    fn paths_at(
        text: &str,
        mut i: usize,
        prefix: Vec<String>,
        ident: &dyn Fn(usize) -> (String, usize),
        out: &mut Vec<Vec<String>>,
    ) {
        let b = text.as_bytes();
        let mut path = prefix;
        loop {
            while i < b.len() && b[i].is_ascii_whitespace() {
                i += 1;
            }
            if i < b.len() && b[i] == b'{' {
                // A group: each top-level item continues the path.
                let mut depth = 0;
                let mut start = i + 1;
                for (k, c) in text[i..].char_indices() {
                    match c {
                        '{' => depth += 1,
                        '}' | ',' if depth == 1 => {
                            paths_at(text, start, path.clone(), ident, out);
                            start = i + k + 1;
                            if c == '}' {
                                return;
                            }
                        }
                        '}' => depth -= 1,
                        _ => {}
                    }
                }
                return;
            }
            let (name, end) = ident(i);
            if name.is_empty() {
                break;
            }
            path.push(name);
            i = end;
            if text[i..].starts_with("::") {
                i += 2;
            } else {
                break;
            }
        }
        if !path.is_empty() {
            out.push(path);
        }
    }
    let mut out = Vec::new();
    let mut from = 0;
    while let Some(k) = text[from..].find(start) {
        let at = from + k;
        let word_before = at > 0 && (b[at - 1].is_ascii_alphanumeric() || b[at - 1] == b'_');
        if !word_before {
            paths_at(text, at + start.len(), Vec::new(), &ident, &mut out);
        }
        from = at + start.len();
    }
    out
}

/// The crate-rooted paths that the module `m` names: `crate::…`, and the relative ones
/// (`super::…`, `self::…`, and a `use` of one of its child modules, `children`), resolved.
fn module_paths(text: &str, m: &[String], children: &BTreeSet<String>) -> Vec<Vec<String>> {
    let mut out = crate_paths(text);
    for mut p in paths_after(text, "super::") {
        let mut base = m[..m.len().saturating_sub(1)].to_vec();
        while p.first().is_some_and(|s| s == "super") {
            p.remove(0);
            base.pop();
        }
        base.extend(p);
        out.push(base);
    }
    for p in paths_after(text, "self::").into_iter().chain(
        paths_after(text, "use ")
            .into_iter()
            .filter(|p| p.first().is_some_and(|s| children.contains(s))),
    ) {
        out.push(m.iter().cloned().chain(p).collect());
    }
    out
}

/// The import graph between the modules of the crate at `src`: module → modules it names.
fn import_graph(src: &Path) -> BTreeMap<Vec<String>, BTreeSet<Vec<String>>> {
    let mods = modules(src);
    let mut edges: BTreeMap<Vec<String>, BTreeSet<Vec<String>>> = BTreeMap::new();
    for (m, file) in &mods {
        let text = std::fs::read_to_string(file).unwrap();
        let children: BTreeSet<String> = mods
            .keys()
            .filter(|c| c.len() == m.len() + 1 && c.starts_with(m))
            .map(|c| c[m.len()].clone())
            .collect();
        for p in module_paths(&text, m, &children) {
            // The longest prefix of the path that is a module.
            if let Some(t) = (1..=p.len())
                .rev()
                .map(|k| &p[..k])
                .find(|t| mods.contains_key(*t))
            {
                // A child naming its own ancestor (`super::`, `crate::parent::`) is how a
                // folder module shares its items: not an edge; the ancestor's use of the
                // child is.
                if t != m.as_slice() && !m.starts_with(t) {
                    edges.entry(m.clone()).or_default().insert(t.to_vec());
                }
            }
        }
    }
    edges
}

/// The strongly connected components of more than one module (Tarjan), each sorted.
fn cycles(edges: &BTreeMap<Vec<String>, BTreeSet<Vec<String>>>) -> Vec<Vec<String>> {
    struct T<'a> {
        edges: &'a BTreeMap<Vec<String>, BTreeSet<Vec<String>>>,
        index: BTreeMap<&'a [String], usize>,
        low: BTreeMap<&'a [String], usize>,
        stack: Vec<&'a [String]>,
        out: Vec<Vec<String>>,
    }
    fn visit<'a>(t: &mut T<'a>, v: &'a [String]) {
        let n = t.index.len();
        t.index.insert(v, n);
        t.low.insert(v, n);
        t.stack.push(v);
        for w in t.edges.get(v).into_iter().flatten() {
            if !t.index.contains_key(w.as_slice()) {
                visit(t, w);
                let lw = t.low[w.as_slice()];
                let lv = t.low.get_mut(v).unwrap();
                *lv = (*lv).min(lw);
            } else if t.stack.contains(&w.as_slice()) {
                let iw = t.index[w.as_slice()];
                let lv = t.low.get_mut(v).unwrap();
                *lv = (*lv).min(iw);
            }
        }
        if t.low[v] == t.index[v] {
            let mut comp = Vec::new();
            loop {
                let w = t.stack.pop().unwrap();
                comp.push(w.join("::"));
                if w == v {
                    break;
                }
            }
            if comp.len() > 1 {
                comp.sort();
                t.out.push(comp);
            }
        }
    }
    let mut t = T {
        edges,
        index: BTreeMap::new(),
        low: BTreeMap::new(),
        stack: Vec::new(),
        out: Vec::new(),
    };
    let nodes: BTreeSet<&[String]> = edges
        .iter()
        .flat_map(|(k, v)| std::iter::once(k.as_slice()).chain(v.iter().map(Vec::as_slice)))
        .collect();
    for v in nodes {
        if !t.index.contains_key(v) {
            visit(&mut t, v);
        }
    }
    t.out
}

#[test]
fn issue_14_no_module_import_cycles() {
    for src in ["src", "geometry/src", "device-protocol/src"] {
        let edges = import_graph(&root().join(src));
        assert!(
            !edges.is_empty(),
            "{src}: no imports found: the reader is broken"
        );
        let found = cycles(&edges);
        assert!(found.is_empty(), "{src}: import cycles: {found:?}");
    }
}

/// The checker itself: a cycle through a group import and a qualified name is found, a
/// chain is not, and names that merely end in `crate` are not paths.
#[test]
fn issue_30_the_import_cycle_check_finds_a_planted_cycle() {
    let dir =
        PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(format!("layering-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(dir.join("src/b")).unwrap();
    std::fs::write(
        dir.join("src/lib.rs"),
        "pub mod a;\npub mod b;\npub mod c;\n",
    )
    .unwrap();
    std::fs::write(dir.join("src/a.rs"), "use crate::{c, b::{d::D, e}};\n").unwrap();
    std::fs::write(dir.join("src/b/mod.rs"), "pub mod d;\n").unwrap();
    std::fs::write(
        dir.join("src/b/d.rs"),
        "pub struct D;\nfn f() { let _ = my_crate::a::x; }\n",
    )
    .unwrap();
    std::fs::write(
        dir.join("src/c.rs"),
        "fn g() { crate::b::d::D; }\n#[cfg(test)]\nmod t { use crate::a; }\n",
    )
    .unwrap();
    let edges = import_graph(&dir.join("src"));
    assert!(cycles(&edges).is_empty(), "{edges:?}");
    std::fs::write(
        dir.join("src/b/d.rs"),
        "pub struct D;\nfn f() { crate::a::x(); }\n",
    )
    .unwrap();
    let edges = import_graph(&dir.join("src"));
    let cycle = ["a", "b::d", "c"].map(String::from).to_vec();
    assert_eq!(cycles(&edges), vec![cycle], "{edges:?}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// Issue 50 point 12: cycles through relative paths are found too: two siblings naming each
/// other through `super::`, and a parent that re-exports its child (`pub use q::Q`) whose
/// child names a module that names the parent (the `report` ↔ `source::phone` circle).
#[test]
fn issue_50_the_import_cycle_check_reads_relative_paths() {
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("layering-rel-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(dir.join("src/x")).unwrap();
    std::fs::create_dir_all(dir.join("src/p")).unwrap();
    let write = |f: &str, text: &str| std::fs::write(dir.join(f), text).unwrap();
    write("src/lib.rs", "pub mod x;\npub mod p;\npub mod r;\n");
    write("src/x/mod.rs", "pub mod y;\npub mod z;\n");
    write("src/x/y.rs", "use super::z::Z;\n");
    write("src/x/z.rs", "pub struct Z;\n");
    write("src/p/mod.rs", "mod q;\npub use q::Q;\n");
    write("src/p/q.rs", "pub struct Q;\n");
    write(
        "src/r.rs",
        "pub struct R;\nfn f() { let _ = crate::p::Q; }\n",
    );
    assert!(cycles(&import_graph(&dir.join("src"))).is_empty());
    write(
        "src/x/z.rs",
        "pub struct Z;\nfn f() { self::g(); super::y::h(); }\n",
    );
    write("src/p/q.rs", "pub struct Q;\nuse crate::r::R;\n");
    let found = cycles(&import_graph(&dir.join("src")));
    let want = vec![
        ["p", "p::q", "r"].map(String::from).to_vec(),
        ["x::y", "x::z"].map(String::from).to_vec(),
    ];
    let mut found = found;
    found.sort();
    assert_eq!(found, want);
    let _ = std::fs::remove_dir_all(&dir);
}
