//! Who the view answers: requests whose `Host` names this server (against DNS rebinding: a
//! web page the operator visits cannot read the scan through a name that it rebinds to this
//! machine), and, with `[view] token`, only those that carry the token.
//!
//! - `Host` must be `localhost`, an IP address literal (rebinding needs a name, so an address
//!   is safe: `127.0.0.1`, `[::1]`, the machine's LAN address when bound to every interface),
//!   or a name in `[view] allowed_hosts`, each with the port the view listens on (no port:
//!   80). Anything else, an empty, missing or overlong `Host` included, gets 421.
//! - With a token, every route wants it: `?token=…`, `Authorization: Bearer …`, or the
//!   cookie the page sets when it is opened with `?token=…` (so that the page's own scripts,
//!   images and event stream carry it without knowing it). Without it: 403.
//!
//! ```
//! use sfs::view::access::{Access, Verdict};
//! let a = Access::new(vec![8040], vec!["scanner.lan".into()], None);
//! assert_eq!(a.host(Some("127.0.0.1:8040")), Verdict::Allowed);
//! assert_eq!(a.host(Some("scanner.lan:8040")), Verdict::Allowed);
//! assert_eq!(a.host(Some("evil.example.com:8040")), Verdict::WrongHost);
//! ```

use axum::extract::{Request, State};
use axum::http::{header, HeaderValue, StatusCode};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use std::sync::Arc;

/// The cookie that carries the token for the page's own requests.
const COOKIE: &str = "sfs_view_token";

/// The view's access policy (see the module documentation).
#[derive(Debug, Clone, Default)]
pub struct Access {
    /// The ports the view listens on.
    ports: Vec<u16>,
    /// Names besides `localhost` and address literals, lower case, without port.
    names: Vec<String>,
    token: Option<String>,
}

/// What [`Access`] says of a request.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Verdict {
    Allowed,
    /// 421: the `Host` does not name this server.
    WrongHost,
    /// 403: the token is required and absent or wrong.
    NoToken,
}

impl Access {
    /// The policy of a view listening on `ports`, answering the names `allowed_hosts` (with or
    /// without a port) besides `localhost` and addresses, wanting `token` if given.
    pub fn new(ports: Vec<u16>, allowed_hosts: Vec<String>, token: Option<String>) -> Access {
        let names = allowed_hosts
            .into_iter()
            .map(|h| crate::host::split_port(&h).0.to_ascii_lowercase())
            .collect();
        Access {
            ports,
            names,
            token,
        }
    }

    /// Whether a request with this `Host` header is for this server ([`crate::host`]).
    pub fn host(&self, host: Option<&str>) -> Verdict {
        if crate::host::names_this_server(host, &self.ports, &self.names) {
            Verdict::Allowed
        } else {
            Verdict::WrongHost
        }
    }

    /// Whether the request carries the token (always, without one).
    fn token_ok(&self, req: &Request) -> bool {
        let Some(want) = &self.token else {
            return true;
        };
        let eq = |got: &str| constant_time_eq(got.as_bytes(), want.as_bytes());
        let query = req
            .uri()
            .query()
            .and_then(query_token)
            .is_some_and(|t| eq(&t));
        let bearer = req
            .headers()
            .get(header::AUTHORIZATION)
            .and_then(|v| v.to_str().ok())
            .and_then(|v| v.strip_prefix("Bearer "))
            .is_some_and(|t| eq(t.trim()));
        let cookie = req
            .headers()
            .get_all(header::COOKIE)
            .iter()
            .filter_map(|v| v.to_str().ok())
            .flat_map(|v| v.split(';'))
            .filter_map(|c| c.trim().strip_prefix(COOKIE)?.strip_prefix('='))
            .any(eq);
        query || bearer || cookie
    }
}

/// The `token` parameter of a query string, percent-decoded.
fn query_token(query: &str) -> Option<String> {
    query.split('&').find_map(|kv| {
        let v = kv.strip_prefix("token=")?;
        let mut out = Vec::with_capacity(v.len());
        let b = v.as_bytes();
        let mut i = 0;
        while i < b.len() {
            match b[i] {
                b'%' if i + 2 < b.len() => {
                    let hex = std::str::from_utf8(&b[i + 1..i + 3]).ok()?;
                    out.push(u8::from_str_radix(hex, 16).ok()?);
                    i += 3;
                }
                b'+' => {
                    out.push(b' ');
                    i += 1;
                }
                c => {
                    out.push(c);
                    i += 1;
                }
            }
        }
        String::from_utf8(out).ok()
    })
}

/// Compares without stopping at the first difference (the token is a secret).
fn constant_time_eq(a: &[u8], b: &[u8]) -> bool {
    a.len() == b.len() && a.iter().zip(b).fold(0u8, |acc, (x, y)| acc | (x ^ y)) == 0
}

/// The middleware: 421 for a foreign `Host`, 403 without the token; a page opened with a
/// valid `?token=` gets the cookie.
pub async fn check(State(access): State<Arc<Access>>, req: Request, next: Next) -> Response {
    let host = req
        .headers()
        .get(header::HOST)
        .and_then(|h| h.to_str().ok())
        .map(str::to_owned)
        .or_else(|| req.uri().authority().map(|a| a.as_str().to_owned()));
    match access.host(host.as_deref()) {
        Verdict::Allowed => {}
        _ => {
            return (
                StatusCode::MISDIRECTED_REQUEST,
                "this Host is not the view's: open it by its address or localhost, or add the name to [view] allowed_hosts\n",
            )
                .into_response()
        }
    }
    if !access.token_ok(&req) {
        return (
            StatusCode::FORBIDDEN,
            "the view wants its token: ?token=… or Authorization: Bearer …\n",
        )
            .into_response();
    }
    let set_cookie = access
        .token
        .as_ref()
        .filter(|_| req.uri().query().and_then(query_token).is_some());
    let cookie = set_cookie.and_then(|t| {
        HeaderValue::from_str(&format!("{COOKIE}={t}; Path=/; HttpOnly; SameSite=Strict")).ok()
    });
    let mut resp = next.run(req).await;
    if let Some(c) = cookie {
        resp.headers_mut().insert(header::SET_COOKIE, c);
    }
    resp
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hosts_that_name_this_server_and_those_that_do_not() {
        let a = Access::new(vec![8040, 80], vec!["Scanner.LAN:8040".into()], None);
        for ok in [
            "127.0.0.1:8040",
            "localhost:8040",
            "LOCALHOST:8040",
            "[::1]:8040",
            "192.168.1.20:8040",
            "scanner.lan:8040",
            "localhost",
        ] {
            assert_eq!(a.host(Some(ok)), Verdict::Allowed, "{ok}");
        }
        let long = "a".repeat(5000);
        for bad in [
            "evil.example.com:8040",
            "evil.example.com",
            "",
            long.as_str(),
            "localhost:9999",
            "127.0.0.1:x",
            "[::1",
            "localhost.evil.com:8040",
        ] {
            assert_eq!(a.host(Some(bad)), Verdict::WrongHost, "{bad}");
        }
        assert_eq!(a.host(None), Verdict::WrongHost);
    }

    #[test]
    fn the_token_from_the_query_the_header_or_the_cookie() {
        let a = Access::new(vec![80], vec![], Some("s3cr t".into()));
        let req = |uri: &str, h: &[(&str, &str)]| {
            let mut b = Request::builder().uri(uri);
            for (k, v) in h {
                b = b.header(*k, *v);
            }
            b.body(axum::body::Body::empty()).unwrap()
        };
        assert!(a.token_ok(&req("/?token=s3cr%20t", &[])));
        assert!(a.token_ok(&req("/?x=1&token=s3cr+t", &[])));
        assert!(a.token_ok(&req("/status", &[("authorization", "Bearer s3cr t")])));
        assert!(a.token_ok(&req("/events", &[("cookie", "a=b; sfs_view_token=s3cr t")])));
        assert!(!a.token_ok(&req("/", &[])));
        assert!(!a.token_ok(&req("/?token=s3cr", &[])));
        assert!(!a.token_ok(&req("/", &[("authorization", "Bearer nope")])));
        assert!(!a.token_ok(&req("/?token=%zz", &[])));
        assert!(Access::new(vec![80], vec![], None).token_ok(&req("/", &[])));
    }
}
