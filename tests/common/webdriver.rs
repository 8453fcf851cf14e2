//! Debian's chromium, headless (WebGL through SwiftShader), driven through Debian's
//! chromedriver over the W3C WebDriver protocol (plain HTTP and JSON): what the live view's
//! browser tests and its latency benchmark need, no more.

use base64::Engine;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

const CHROMIUM: &str = "/usr/bin/chromium";
const CHROMEDRIVER: &str = "/usr/bin/chromedriver";

/// Whether chromium and chromedriver are installed. A test that needs them is ignored where
/// the build script did not find them (`cfg(sfs_chromium)`); where it runs, they must be
/// there (`.ci/run` installs both and sets `SFS_REQUIRE_BROWSER`): else this panics.
pub fn available() -> bool {
    let there = installed();
    assert!(
        there,
        "chromium or chromedriver is not installed (Debian: apt-get install chromium chromium-driver)"
    );
    there
}

/// Whether both are installed (for the benchmark, which says so and measures nothing).
#[allow(dead_code)]
pub fn installed() -> bool {
    Path::new(CHROMIUM).exists() && Path::new(CHROMEDRIVER).exists()
}

/// One headless browser (a chromedriver and its session); both end when dropped.
pub struct Browser {
    driver: Child,
    http: reqwest::Client,
    session: String,
    base: String,
}

impl Browser {
    /// Starts chromedriver and a headless chromium with its profile in `profile`.
    pub async fn start(profile: &Path) -> Browser {
        Browser::start_with(profile, false).await
    }

    /// As [`start`](Self::start); with `insecure_certs`, a self-signed certificate is
    /// accepted (the phone page's, as the operator accepts it on the phone).
    pub async fn start_with(profile: &Path, insecure_certs: bool) -> Browser {
        let port = super::view::free_port();
        let driver = Command::new(CHROMEDRIVER)
            .arg(format!("--port={port}"))
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("chromedriver");
        let http = reqwest::Client::new();
        let base = format!("http://127.0.0.1:{port}");
        let t0 = Instant::now();
        loop {
            let ready = match http.get(format!("{base}/status")).send().await {
                Ok(r) => r.json::<serde_json::Value>().await.ok(),
                Err(_) => None,
            };
            if ready.is_some_and(|v| v["value"]["ready"] == true) {
                break;
            }
            assert!(
                t0.elapsed() < Duration::from_secs(20),
                "chromedriver not ready"
            );
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
        let args = [
            "--headless=new",
            "--no-sandbox",
            "--disable-gpu",
            "--use-gl=swiftshader",
            "--enable-unsafe-swiftshader",
            "--disable-quic",
            "--no-first-run",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--window-size=1280,800",
        ]
        .iter()
        .map(|a| a.to_string())
        .chain([format!("--user-data-dir={}", profile.display())])
        .collect::<Vec<_>>();
        let caps = serde_json::json!({ "capabilities": { "alwaysMatch": {
            "browserName": "chrome",
            "acceptInsecureCerts": insecure_certs,
            "goog:chromeOptions": { "binary": CHROMIUM, "args": args },
        }}});
        let mut b = Browser {
            driver,
            http,
            session: String::new(),
            base,
        };
        let v = b.call(reqwest::Method::POST, "/session", Some(caps)).await;
        b.session = v["sessionId"].as_str().expect("a session id").to_owned();
        b
    }

    async fn call(
        &self,
        method: reqwest::Method,
        path: &str,
        body: Option<serde_json::Value>,
    ) -> serde_json::Value {
        let mut r = self.http.request(method, format!("{}{}", self.base, path));
        if let Some(b) = body {
            r = r.json(&b);
        }
        let v: serde_json::Value = r.send().await.unwrap().json().await.unwrap();
        assert!(
            v["value"]["error"].is_null(),
            "WebDriver {path}: {}",
            v["value"]
        );
        v["value"].clone()
    }

    fn at(&self, what: &str) -> String {
        format!("/session/{}/{what}", self.session)
    }

    /// Loads `url` (returns once the page has loaded).
    pub async fn goto(&self, url: &str) {
        let body = serde_json::json!({ "url": url });
        self.call(reqwest::Method::POST, &self.at("url"), Some(body))
            .await;
    }

    /// A DevTools protocol command, through chromedriver (`goog/cdp/execute`).
    #[allow(dead_code)]
    pub async fn cdp(&self, cmd: &str, params: serde_json::Value) -> serde_json::Value {
        let body = serde_json::json!({ "cmd": cmd, "params": params });
        self.call(
            reqwest::Method::POST,
            &self.at("goog/cdp/execute"),
            Some(body),
        )
        .await
    }

    /// Runs `script` (a function body: `arguments` are `args`, its `return` the result).
    #[allow(dead_code)]
    pub async fn execute(&self, script: &str, args: serde_json::Value) -> serde_json::Value {
        let body = serde_json::json!({ "script": script, "args": args });
        self.call(reqwest::Method::POST, &self.at("execute/sync"), Some(body))
            .await
    }

    /// Runs `script` asynchronously: its last argument is the callback that returns.
    #[allow(dead_code)]
    pub async fn execute_async(&self, script: &str, args: serde_json::Value) -> serde_json::Value {
        let body = serde_json::json!({ "script": script, "args": args });
        self.call(reqwest::Method::POST, &self.at("execute/async"), Some(body))
            .await
    }

    /// The element `css` selects (its WebDriver reference).
    #[allow(dead_code)]
    pub async fn find(&self, css: &str) -> String {
        let body = serde_json::json!({ "using": "css selector", "value": css });
        let v = self
            .call(reqwest::Method::POST, &self.at("element"), Some(body))
            .await;
        v.as_object()
            .and_then(|o| o.values().next())
            .and_then(|id| id.as_str())
            .unwrap_or_else(|| panic!("no element {css}: {v}"))
            .to_owned()
    }

    /// Clicks the element (as a pointer would: WebDriver's element click).
    #[allow(dead_code)]
    pub async fn click(&self, element: &str) {
        self.call(
            reqwest::Method::POST,
            &self.at(&format!("element/{element}/click")),
            Some(serde_json::json!({})),
        )
        .await;
    }

    /// `JSON.stringify(window.sfsView)`, parsed (null before the page's script has run).
    pub async fn view_state(&self) -> serde_json::Value {
        let body = serde_json::json!({
            "script": "return JSON.stringify(window.sfsView ? { ...window.sfsView, status: undefined } : null)",
            "args": [],
        });
        let v = self
            .call(reqwest::Method::POST, &self.at("execute/sync"), Some(body))
            .await;
        serde_json::from_str(v.as_str().unwrap_or("null")).unwrap()
    }

    /// Polls [`view_state`](Self::view_state) every 50 ms until `done` says so (panics after
    /// `limit`); returns every state seen.
    pub async fn watch(
        &self,
        limit: Duration,
        mut done: impl FnMut(&serde_json::Value) -> bool,
    ) -> Vec<serde_json::Value> {
        let t0 = Instant::now();
        let mut seen = Vec::new();
        loop {
            let s = self.view_state().await;
            let stop = done(&s);
            seen.push(s);
            if stop {
                return seen;
            }
            assert!(t0.elapsed() < limit, "the page: {}", seen.last().unwrap());
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
    }

    /// A PNG of the window, written to `path`.
    pub async fn screenshot(&self, path: &PathBuf) {
        let v = self
            .call(reqwest::Method::GET, &self.at("screenshot"), None)
            .await;
        let png = base64::engine::general_purpose::STANDARD
            .decode(v.as_str().unwrap())
            .unwrap();
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        std::fs::write(path, png).unwrap();
    }
}

impl Browser {
    /// Ends the browser's session (chromium exits), then chromedriver.
    pub async fn close(self) {
        let _ = self
            .http
            .delete(format!("{}/session/{}", self.base, self.session))
            .send()
            .await;
    }
}

impl Drop for Browser {
    fn drop(&mut self) {
        // chromedriver ends its browser when it ends.
        let _ = self.driver.kill();
        let _ = self.driver.wait();
    }
}
