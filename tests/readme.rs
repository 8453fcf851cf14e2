//! Issue 50 point 10: the README is a user's guide whose claims hold. It opens with the two
//! set-up commands; every `sfs COMMAND … --flag` it and the reference in `docs/` write is
//! one `sfs COMMAND --help` lists; the reference's Commands table names every command; every
//! relative link leads to a file; no issue number is left in the user's text.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::process::Command;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The user's text: the README and the documents beside it.
fn documents() -> Vec<(PathBuf, String)> {
    let mut docs = vec![root().join("README.md")];
    for e in std::fs::read_dir(root().join("docs")).unwrap() {
        let p = e.unwrap().path();
        if p.extension().is_some_and(|x| x == "md") {
            docs.push(p);
        }
    }
    docs.into_iter()
        .map(|p| {
            let text = std::fs::read_to_string(&p).unwrap();
            (p, text)
        })
        .collect()
}

const COMMANDS: [&str; 7] = [
    "replay",
    "run",
    "calibrate",
    "simulate",
    "eval",
    "config",
    "ports",
];

fn help(command: &str) -> String {
    let mut c = Command::new(env!("CARGO_BIN_EXE_sfs"));
    match command {
        "config" => c.args(["config", "check", "--help"]),
        _ => c.args([command, "--help"]),
    };
    let out = c.output().unwrap();
    assert!(out.status.success(), "sfs {command} --help");
    String::from_utf8(out.stdout).unwrap()
}

#[test]
fn issue_50_the_readme_opens_with_the_two_commands() {
    let readme = std::fs::read_to_string(root().join("README.md")).unwrap();
    let first: Vec<&str> = readme.lines().take(6).collect();
    assert_eq!(
        first,
        [
            "# sfs — shape from sensors",
            "",
            "```sh",
            "cargo run --release -- run --config config/demo.toml --session out/demo",
            "cargo test --workspace --release",
            "```",
        ]
    );
    // A user's guide: short, a guide per device.
    for guide in [
        "## Scan with a Morphorider",
        "## Scan with a phone",
        "## Monitor a structure",
    ] {
        assert!(readme.contains(guide), "no {guide:?}");
    }
    assert!(
        readme.lines().count() < 250,
        "{} lines",
        readme.lines().count()
    );
}

#[test]
fn issue_50_every_flag_the_documents_give_is_one_the_binary_takes() {
    let helps: Vec<(&str, String)> = COMMANDS.iter().map(|c| (*c, help(c))).collect();
    let flag = |s: &str| -> Option<String> {
        let f: String = s
            .strip_prefix("--")?
            .chars()
            .take_while(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || *c == '-')
            .collect();
        (!f.is_empty()).then(|| format!("--{}", f.trim_end_matches('-')))
    };
    let mut checked = 0;
    for (path, text) in documents() {
        for line in text.lines() {
            // Each `sfs COMMAND …` up to the end of its code span (or line).
            let mut rest = line;
            while let Some(i) = rest.find("sfs ") {
                let after = &rest[i + 4..];
                rest = after;
                let Some((command, help)) = helps.iter().find(|(c, _)| {
                    after.starts_with(c) && after[c.len()..].starts_with([' ', '`'])
                }) else {
                    continue;
                };
                let span = after.split('`').next().unwrap_or(after);
                let span = span.split(" sfs ").next().unwrap_or(span);
                for word in span.split([' ', '[', ']', '|', '(', ')']) {
                    let Some(f) = flag(word) else { continue };
                    assert!(
                        help.contains(&f),
                        "{}: `sfs {command} … {f}` but `sfs {command} --help` has no {f}:\n{line}",
                        path.display()
                    );
                    checked += 1;
                }
            }
        }
    }
    assert!(checked > 40, "only {checked} flags found in the documents");
}

#[test]
fn issue_50_the_reference_names_every_command() {
    let reference = std::fs::read_to_string(root().join("docs/reference.md")).unwrap();
    let table: Vec<&str> = reference
        .lines()
        .skip_while(|l| *l != "## Commands")
        .take_while(|l| !l.starts_with("Global flags"))
        .collect();
    let out = Command::new(env!("CARGO_BIN_EXE_sfs"))
        .arg("--help")
        .output()
        .unwrap();
    let top = String::from_utf8(out.stdout).unwrap();
    let listed: BTreeSet<&str> = top
        .lines()
        .skip_while(|l| !l.starts_with("Commands:"))
        .skip(1)
        .take_while(|l| !l.is_empty())
        .filter_map(|l| l.split_whitespace().next())
        .filter(|c| *c != "help" && l_is_command(c))
        .collect();
    assert_eq!(listed, COMMANDS.iter().copied().collect());
    for c in &listed {
        assert!(
            table
                .iter()
                .any(|row| row.starts_with(&format!("| `sfs {c}"))),
            "the Commands table has no row for sfs {c}"
        );
    }
    // Each way to run a session.
    for source in [
        "--serial",
        "--stdin",
        "--phone",
        "--config",
        "--resume",
        "--continue",
    ] {
        assert!(
            table
                .iter()
                .any(|row| row.starts_with("| `sfs run") && row.contains(source)),
            "no sfs run row with {source}"
        );
    }
}

fn l_is_command(c: &str) -> bool {
    c.chars().all(|c| c.is_ascii_lowercase())
}

#[test]
fn issue_50_links_lead_somewhere_and_no_issue_numbers_are_left() {
    for (path, text) in documents() {
        let dir = path.parent().unwrap();
        for (i, _) in text.match_indices("](") {
            let target: String = text[i + 2..].chars().take_while(|c| *c != ')').collect();
            if target.starts_with("http") || target.starts_with('#') {
                continue;
            }
            let file = target.split('#').next().unwrap();
            assert!(
                Path::new(dir).join(file).exists(),
                "{}: a link to {target} that leads nowhere",
                path.display()
            );
        }
        let lower = text.to_lowercase();
        for (i, _) in lower.match_indices("issue ") {
            let next = lower[i + 6..].chars().next();
            assert!(
                !next.is_some_and(|c| c.is_ascii_digit()),
                "{}: an issue number in the user's text: {}",
                path.display(),
                &text[i..(i + 20).min(text.len())]
            );
        }
    }
}

/// Issue 50 point 11: BENCHMARKS.md opens with its summary, and every section the summary
/// links to is there (GitHub's anchors of the headings).
#[test]
fn issue_50_the_benchmarks_summary_links_to_its_sections() {
    let text = std::fs::read_to_string(root().join("BENCHMARKS.md")).unwrap();
    let anchors: BTreeSet<String> = text
        .lines()
        .filter(|l| l.starts_with('#'))
        .map(|l| {
            l.trim_start_matches('#')
                .trim()
                .to_lowercase()
                .chars()
                .filter(|c| c.is_alphanumeric() || *c == '-' || *c == ' ' || *c == '_')
                .map(|c| if c == ' ' { '-' } else { c })
                .collect()
        })
        .collect();
    let summary: Vec<&str> = text
        .lines()
        .skip_while(|l| *l != "## Summary")
        .skip(1)
        .take_while(|l| !l.starts_with("## "))
        .collect();
    let head: Vec<&str> = text.lines().take(8).collect();
    assert!(
        head.contains(&"## Summary"),
        "the summary is not at the top"
    );
    let rows = summary
        .iter()
        .filter(|l| l.starts_with("| ") && !l.starts_with("| what"))
        .count();
    assert!(rows >= 10, "{rows} rows");
    let mut links = 0;
    for line in &summary {
        for (i, _) in line.match_indices("](#") {
            let anchor: String = line[i + 3..].chars().take_while(|c| *c != ')').collect();
            assert!(anchors.contains(&anchor), "no section #{anchor}");
            links += 1;
        }
    }
    assert!(links >= rows - 1, "{links} links for {rows} rows");
}
