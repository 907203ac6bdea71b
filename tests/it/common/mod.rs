//! The service as users run it: the real binary on 127.0.0.1:0 with a
//! fresh database in a temporary directory (removed when the server is
//! dropped), driven over HTTP.
#![allow(dead_code)]

use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

pub struct Server {
    pub child: Child,
    pub base: String,
    pub _dir: std::path::PathBuf,
}

impl Drop for Server {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
        // Tests that restart on the same directory `forget` the first server.
        let _ = std::fs::remove_dir_all(&self._dir);
    }
}

pub fn start() -> Server {
    let dir =
        std::env::temp_dir().join(format!("zwidth-svc-{}-{}", std::process::id(), uuid_like()));
    std::fs::create_dir_all(&dir).unwrap();
    start_in(dir)
}

pub fn start_in(dir: std::path::PathBuf) -> Server {
    start_with(dir, &[])
}

/// The binary under test: this build's, or `ZWIDTH_TEST_BIN` (to check
/// that a test fails on another build, e.g. the version before a fix).
pub fn bin() -> std::ffi::OsString {
    std::env::var_os("ZWIDTH_TEST_BIN").unwrap_or_else(|| env!("CARGO_BIN_EXE_zwidth").into())
}

pub fn start_with(dir: std::path::PathBuf, extra: &[&str]) -> Server {
    start_on(dir, "127.0.0.1:0", extra)
}

/// A server bound to `bind` (a restart on the port its agents know).
pub fn start_on(dir: std::path::PathBuf, bind: &str, extra: &[&str]) -> Server {
    let mut child = Command::new(bin())
        .args(["serve", "--bind", bind])
        .args(extra)
        .arg("--db")
        .arg(dir.join("test.db"))
        .env("RUST_LOG", "warn")
        .env_remove("ZWIDTH_TOKENS")
        .stdout(Stdio::piped())
        .stderr(std::fs::File::create(dir.join("serve.err")).unwrap())
        .spawn()
        .unwrap();
    let mut line = String::new();
    BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    // Bound to every interface: reached here on loopback.
    let base = line
        .trim()
        .rsplit(' ')
        .next()
        .unwrap()
        .replace("//0.0.0.0:", "//127.0.0.1:");
    assert!(
        base.starts_with("http://127.0.0.1:") || base.starts_with("https://127.0.0.1:"),
        "{line}"
    );
    // The token the server made on first start (none when given one).
    if let Ok(t) = std::fs::read_to_string(dir.join("test.db.token")) {
        TOKENS
            .lock()
            .unwrap()
            .push((base.clone(), t.trim().to_string()));
    }
    Server {
        child,
        base,
        _dir: dir,
    }
}

/// Each server's own token (`<db>.token`), by base URL.
static TOKENS: std::sync::Mutex<Vec<(String, String)>> = std::sync::Mutex::new(Vec::new());

/// The token of the server `url` is on, if it made one.
pub fn token_for(url: &str) -> Option<String> {
    TOKENS
        .lock()
        .unwrap()
        .iter()
        .rev()
        .find(|(base, _)| url.starts_with(base.as_str()))
        .map(|(_, t)| t.clone())
}

/// Writes as a user does: with the server's token.
pub mod authed {
    fn with(r: ureq::Request, url: &str) -> ureq::Request {
        match super::token_for(url) {
            Some(t) => r.set("authorization", &format!("Bearer {t}")),
            None => r,
        }
    }
    pub fn post(url: &str) -> ureq::Request {
        with(ureq::post(url), url)
    }
    pub fn put(url: &str) -> ureq::Request {
        with(ureq::put(url), url)
    }
    pub fn delete(url: &str) -> ureq::Request {
        with(ureq::delete(url), url)
    }
}

pub fn uuid_like() -> u128 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_nanos()
}

pub fn post(url: &str, body: &str) -> (u16, serde_json::Value, String) {
    match authed::post(url)
        .set("content-type", "application/json")
        .send_string(body)
    {
        Ok(r) => {
            let ct = r.content_type().to_string();
            (r.status(), r.into_json().unwrap(), ct)
        }
        Err(ureq::Error::Status(code, r)) => {
            let ct = r.content_type().to_string();
            (code, r.into_json().unwrap(), ct)
        }
        Err(e) => panic!("{e}"),
    }
}

pub fn get(url: &str) -> serde_json::Value {
    ureq::get(url).call().unwrap().into_json().unwrap()
}

/// Status, content type and body text of any request.
pub fn fetch(r: Result<ureq::Response, ureq::Error>) -> (u16, String, String) {
    match r {
        Ok(r) | Err(ureq::Error::Status(_, r)) => {
            let (code, ct) = (r.status(), r.content_type().to_string());
            (code, ct, r.into_string().unwrap())
        }
        Err(e) => panic!("{e}"),
    }
}

/// Poll `cond` every 20 ms until it holds; panics naming `what` after `secs`.
pub fn wait_for(what: &str, secs: u64, mut cond: impl FnMut() -> bool) {
    let deadline = Instant::now() + Duration::from_secs(secs);
    while !cond() {
        assert!(Instant::now() < deadline, "waited {secs} s for {what}");
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Poll an experiment until it ends; panics after `secs`.
pub fn wait_end(base: &str, id: &str, secs: u64) -> serde_json::Value {
    let deadline = Instant::now() + Duration::from_secs(secs);
    loop {
        let v = get(&format!("{base}/v1/experiments/{id}"));
        if ["succeeded", "failed", "cancelled"].contains(&v["state"].as_str().unwrap()) {
            return v;
        }
        assert!(Instant::now() < deadline, "still {v}");
        std::thread::sleep(Duration::from_millis(50));
    }
}
pub mod pg;
pub mod tools;

/// Use `token` for writes to the server at `base` (one given, not made).
pub fn register_token(base: &str, token: &str) {
    TOKENS
        .lock()
        .unwrap()
        .push((base.to_string(), token.to_string()));
}

/// Start `zwidth ARGS` with stderr in `dir/<log>`, and wait for the first
/// line it prints on stdout (its "serving on …" or "zwidth worker …").
pub fn spawn_ready(args: &[&str], dir: &std::path::Path, log: &str) -> (Child, String) {
    let mut child = Command::new(bin())
        .args(args)
        .env("RUST_LOG", "info")
        .env_remove("ZWIDTH_TOKENS")
        .env_remove("ZWIDTH_DB")
        .stdout(Stdio::piped())
        .stderr(std::fs::File::create(dir.join(log)).unwrap())
        .spawn()
        .unwrap();
    let mut line = String::new();
    BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    assert!(
        !line.is_empty(),
        "zwidth {args:?} printed nothing: {}",
        std::fs::read_to_string(dir.join(log)).unwrap_or_default()
    );
    (child, line.trim().to_string())
}
