//! Whether a request's `Host` names this server: the live view's and the phone page's defence
//! against DNS rebinding (a web page the operator visits cannot reach them through a name that
//! it rebinds to this machine). `localhost`, an IP address literal (rebinding needs a name) or
//! one of the configured names, each with a port the server listens on (no port: 80); anything
//! else, an empty, missing or overlong `Host` included, is not.
//!
//! ```
//! use sfs::host::names_this_server;
//! let names = vec!["scanner.lan".to_owned()];
//! assert!(names_this_server(Some("127.0.0.1:8040"), &[8040], &names));
//! assert!(names_this_server(Some("Scanner.LAN:8040"), &[8040], &names));
//! assert!(!names_this_server(Some("evil.example.com:8040"), &[8040], &names));
//! assert!(!names_this_server(Some("localhost:9999"), &[8040], &names));
//! ```

/// The longest `Host` considered (a DNS name has at most 253 characters, plus a port).
const MAX_HOST: usize = 260;

/// Whether `host` (a `Host` header) names this server, listening on `ports`, known also by
/// `names` (lower case, without port).
pub fn names_this_server(host: Option<&str>, ports: &[u16], names: &[String]) -> bool {
    let Some(h) = host.filter(|h| !h.is_empty() && h.len() <= MAX_HOST) else {
        return false;
    };
    let (name, port) = split_port(h);
    let port = match port {
        None => 80,
        Some(p) => match p.parse::<u16>() {
            Ok(p) => p,
            Err(_) => return false,
        },
    };
    if !ports.contains(&port) {
        return false;
    }
    let name = name.to_ascii_lowercase();
    let literal = name
        .strip_prefix('[')
        .and_then(|n| n.strip_suffix(']'))
        .map_or_else(
            || name.parse::<std::net::Ipv4Addr>().is_ok(),
            |v6| v6.parse::<std::net::Ipv6Addr>().is_ok(),
        );
    literal || name == "localhost" || names.contains(&name)
}

/// `name:port` → (`name`, `port`); an IPv6 literal keeps its brackets.
pub fn split_port(h: &str) -> (&str, Option<&str>) {
    if let Some(rest) = h.strip_prefix('[') {
        return match rest.find(']') {
            Some(end) => {
                let (name, after) = h.split_at(end + 2);
                (name, after.strip_prefix(':'))
            }
            None => (h, None),
        };
    }
    match h.rsplit_once(':') {
        Some((name, port)) => (name, Some(port)),
        None => (h, None),
    }
}
