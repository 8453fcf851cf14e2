//! Logging on standard error: human lines or JSON objects (`--log-format`), filtered by
//! `--log` / `RUST_LOG`.
//!
//! - JSON: every line carries the session it belongs to (`"session"`: the session or output
//!   directory, once known: [`set_session`]), so that the lines of several instances in one
//!   journal or log store can be told apart.
//! - Under systemd (`JOURNAL_STREAM` names standard error's device and inode, as systemd sets
//!   it for a service whose output goes to the journal), human lines have no timestamp of their
//!   own and no colours: journald stamps every line itself.
//! - A closed log pipe never stops or panics the daemon: write errors are ignored.

use std::sync::OnceLock;

static SESSION: OnceLock<String> = OnceLock::new();

/// Names the session the following log lines belong to (the first call wins: one process
/// runs one session).
pub fn set_session(name: &str) {
    let _ = SESSION.set(name.to_owned());
}

/// Whether the log is JSON lines (`--log-format json`): then nothing but JSON may go to
/// standard error (the phone page's banner is logged as an event instead).
static JSON: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

/// Whether [`init`] made the log JSON lines.
pub fn json() -> bool {
    JSON.load(std::sync::atomic::Ordering::Relaxed)
}

/// Installs the global subscriber: JSON lines when `json` (`--log-format json`), else
/// human-readable ones.
pub fn init(json: bool, filter: Option<&str>) {
    JSON.store(json, std::sync::atomic::Ordering::Relaxed);
    use tracing_subscriber::EnvFilter;
    let filter = match filter {
        Some(f) => EnvFilter::new(f),
        None => EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new("info")),
    };
    use std::io::IsTerminal;
    let journal = under_journald();
    let builder = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_ansi(std::io::stderr().is_terminal() && !journal);
    match json {
        false if journal => builder
            .without_time()
            .with_writer(|| Stderr { json: false })
            .init(),
        false => builder.with_writer(|| Stderr { json: false }).init(),
        true => builder.json().with_writer(|| Stderr { json: true }).init(),
    }
}

/// Whether standard error is the journal's stream: `JOURNAL_STREAM` (`DEVICE:INODE`, set by
/// systemd) names it. A value inherited by a child whose standard error went elsewhere does
/// not match.
pub fn under_journald() -> bool {
    let Some(expected) = std::env::var("JOURNAL_STREAM")
        .ok()
        .and_then(|v| parse_journal_stream(&v))
    else {
        return false;
    };
    stderr_identity().is_some_and(|id| id == expected)
}

/// `DEVICE:INODE` as systemd writes `JOURNAL_STREAM`.
fn parse_journal_stream(v: &str) -> Option<(u64, u64)> {
    let (dev, ino) = v.trim().split_once(':')?;
    Some((dev.parse().ok()?, ino.parse().ok()?))
}

/// Device and inode of standard error.
fn stderr_identity() -> Option<(u64, u64)> {
    use std::os::fd::AsFd;
    use std::os::unix::fs::MetadataExt;
    let fd = std::io::stderr().as_fd().try_clone_to_owned().ok()?;
    let meta = std::fs::File::from(fd).metadata().ok()?;
    Some((meta.dev(), meta.ino()))
}

/// A JSON log line with `"session"` first, when a session is named (other lines as they are).
fn with_session<'a>(line: &'a [u8], session: Option<&str>) -> std::borrow::Cow<'a, [u8]> {
    match (session, line.split_first()) {
        (Some(s), Some((b'{', rest))) => {
            let name = serde_json::to_string(s).unwrap_or_else(|_| "\"\"".into());
            let mut out = Vec::with_capacity(line.len() + name.len() + 12);
            out.extend_from_slice(b"{\"session\":");
            out.extend_from_slice(name.as_bytes());
            if rest.first() != Some(&b'}') {
                out.push(b',');
            }
            out.extend_from_slice(rest);
            out.into()
        }
        _ => line.into(),
    }
}

/// Standard error for the logs, ignoring write errors. The formatter writes each event whole
/// in one call, so a JSON line can be given its session here.
struct Stderr {
    json: bool,
}

impl std::io::Write for Stderr {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        let session = SESSION.get().map(String::as_str).filter(|_| self.json);
        let _ = std::io::stderr().write_all(&with_session(buf, session));
        Ok(buf.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_json_line_gets_its_session_first_and_stays_json() {
        let line = br#"{"timestamp":"t","level":"INFO","fields":{"message":"hi"}}
"#;
        let out = with_session(line, Some("/var/lib/sfs/panel \"a\""));
        let v: serde_json::Value = serde_json::from_slice(&out).unwrap();
        assert_eq!(v["session"], "/var/lib/sfs/panel \"a\"");
        assert_eq!(v["fields"]["message"], "hi");
        assert!(out.ends_with(b"\n"));
        let empty: serde_json::Value =
            serde_json::from_slice(&with_session(b"{}", Some("s"))).unwrap();
        assert_eq!(empty["session"], "s");
        // No session yet, or not a JSON object: unchanged.
        assert_eq!(&*with_session(line, None), &line[..]);
        assert_eq!(&*with_session(b"INFO x", Some("s")), b"INFO x");
    }

    #[test]
    fn journal_stream_is_device_colon_inode() {
        assert_eq!(parse_journal_stream("8:12345"), Some((8, 12345)));
        assert_eq!(parse_journal_stream("8:12345\n"), Some((8, 12345)));
        assert_eq!(parse_journal_stream("8"), None);
        assert_eq!(parse_journal_stream("a:1"), None);
    }
}
