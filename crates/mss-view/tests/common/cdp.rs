//! A headless Chromium driven through the DevTools protocol (CDP) over a
//! WebSocket: just what the viewer's browser tests and the streaming
//! benchmark need (navigate, evaluate, mouse events, screenshots).
//!
//! WebGL2 works headless through SwiftShader (ANGLE's software backend),
//! so the page renders for real, without a GPU.

#![allow(dead_code)]

use std::io::{Read, Write};
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use futures_util::{SinkExt, StreamExt};
use serde_json::{Value, json};
use tokio_tungstenite::tungstenite::Message;

type Socket =
    tokio_tungstenite::WebSocketStream<tokio_tungstenite::MaybeTlsStream<tokio::net::TcpStream>>;

/// A headless browser has no display: its vsync is a timer that slows
/// down under load (36 animation frames per second on a blank page on 2
/// busy cores). These flags let it draw as fast as it can, as a browser
/// on a desktop at 60 Hz does; `MSS_VIEW_BROWSER_VSYNC=1` keeps the timer.
fn uncapped_frames() -> &'static [&'static str] {
    if std::env::var_os("MSS_VIEW_BROWSER_VSYNC").is_some_and(|v| v == "1") {
        &[]
    } else {
        &["--disable-gpu-vsync", "--disable-frame-rate-limit"]
    }
}

/// Kills the browser when dropped, also when a launch fails half-way.
struct Process(Child);

impl Drop for Process {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// A running headless browser with one page.
pub struct Browser {
    _child: Process,
    _profile: tempfile::TempDir,
    socket: Socket,
    next_id: u64,
}

/// The browser to use: `MSS_CHROMIUM`, else the first of the usual names
/// on the PATH.
pub fn find_browser() -> Option<PathBuf> {
    if let Some(p) = std::env::var_os("MSS_CHROMIUM") {
        return Some(PathBuf::from(p));
    }
    let path = std::env::var_os("PATH")?;
    for dir in std::env::split_paths(&path) {
        for name in [
            "chromium",
            "chromium-browser",
            "google-chrome",
            "google-chrome-stable",
        ] {
            let p = dir.join(name);
            if p.is_file() {
                return Some(p);
            }
        }
    }
    None
}

/// Whether the tests must find a browser (CI sets it); otherwise a machine
/// without one skips the browser tests with a message.
pub fn browser_required() -> bool {
    std::env::var_os("MSS_VIEW_REQUIRE_BROWSER").is_some_and(|v| v == "1")
}

fn http_get(port: u16, path: &str) -> Option<String> {
    let mut s = std::net::TcpStream::connect(("127.0.0.1", port)).ok()?;
    s.set_read_timeout(Some(Duration::from_secs(5))).ok()?;
    write!(
        s,
        "GET {path} HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nConnection: close\r\n\r\n"
    )
    .ok()?;
    // The DevTools server keeps the connection open: read what
    // Content-Length says, not to the end.
    let mut reply = Vec::new();
    let mut buf = [0u8; 4096];
    loop {
        let n = s.read(&mut buf).ok()?;
        if n == 0 {
            break;
        }
        reply.extend_from_slice(&buf[..n]);
        let text = String::from_utf8_lossy(&reply);
        if let Some(at) = text.find("\r\n\r\n") {
            let length = text[..at].lines().find_map(|l| {
                let (k, v) = l.split_once(':')?;
                k.eq_ignore_ascii_case("content-length")
                    .then(|| v.trim().parse::<usize>().ok())?
            });
            if let Some(len) = length
                && reply.len() >= at + 4 + len
            {
                return Some(String::from_utf8_lossy(&reply[at + 4..at + 4 + len]).into_owned());
            }
        }
    }
    let text = String::from_utf8_lossy(&reply).into_owned();
    text.split("\r\n\r\n").nth(1).map(str::to_owned)
}

impl Browser {
    /// Starts the browser with a `width` x `height` window on `about:blank`
    /// and attaches to its page; `None` when no browser is installed.
    pub async fn launch(width: u32, height: u32) -> Option<Browser> {
        let exe = find_browser()?;
        let profile = tempfile::tempdir().unwrap();
        let child = Process(
            Command::new(&exe)
                .args([
                    "--headless=new",
                    "--no-sandbox",
                    "--use-gl=angle",
                    "--use-angle=swiftshader",
                    "--enable-unsafe-swiftshader",
                    "--disable-background-networking",
                    "--disable-component-update",
                    "--disable-sync",
                    "--disable-dev-shm-usage",
                    "--no-first-run",
                    "--no-default-browser-check",
                    "--remote-debugging-port=0",
                    "--remote-allow-origins=*",
                    &format!("--window-size={width},{height}"),
                    &format!("--user-data-dir={}", profile.path().display()),
                    "about:blank",
                ])
                .args(uncapped_frames())
                .stdin(Stdio::null())
                .stdout(Stdio::null())
                .stderr(Stdio::null())
                .spawn()
                .unwrap_or_else(|e| panic!("cannot start {}: {e}", exe.display())),
        );
        // The browser writes its debugging port into the profile.
        let port_file = profile.path().join("DevToolsActivePort");
        let end = Instant::now() + Duration::from_secs(60);
        let port: u16 = loop {
            if let Ok(text) = std::fs::read_to_string(&port_file)
                && let Some(p) = text.lines().next().and_then(|l| l.trim().parse().ok())
            {
                break p;
            }
            assert!(
                Instant::now() < end,
                "the browser did not start its DevTools server"
            );
            tokio::time::sleep(Duration::from_millis(100)).await;
        };
        let page_url = loop {
            let list: Option<Value> =
                http_get(port, "/json/list").and_then(|b| serde_json::from_str(&b).ok());
            let url = list.as_ref().and_then(|l| l.as_array()).and_then(|pages| {
                pages
                    .iter()
                    .find(|p| p["type"] == "page")
                    .and_then(|p| p["webSocketDebuggerUrl"].as_str().map(str::to_owned))
            });
            if let Some(u) = url {
                break u;
            }
            assert!(Instant::now() < end, "the browser has no page to attach to");
            tokio::time::sleep(Duration::from_millis(100)).await;
        };
        let (socket, _) = tokio_tungstenite::connect_async(page_url).await.unwrap();
        Some(Browser {
            _child: child,
            _profile: profile,
            socket,
            next_id: 1,
        })
    }

    /// Calls a CDP method and returns its result (events are skipped).
    pub async fn call(&mut self, method: &str, params: Value) -> Value {
        let id = self.next_id;
        self.next_id += 1;
        let m = json!({"id": id, "method": method, "params": params});
        self.socket
            .send(Message::text(m.to_string()))
            .await
            .unwrap();
        loop {
            let next = tokio::time::timeout(Duration::from_secs(60), self.socket.next())
                .await
                .unwrap_or_else(|_| panic!("{method}: no answer from the browser"));
            let Some(Ok(Message::Text(t))) = next else {
                continue;
            };
            let v: Value = serde_json::from_str(t.as_str()).unwrap();
            if v["id"] == id {
                if let Some(e) = v.get("error") {
                    panic!("{method}: {e}");
                }
                return v["result"].clone();
            }
        }
    }

    /// Evaluates `expression` in the page and returns its value.
    pub async fn eval(&mut self, expression: &str) -> Value {
        let r = self
            .call(
                "Runtime.evaluate",
                json!({"expression": expression, "returnByValue": true, "awaitPromise": true}),
            )
            .await;
        if let Some(e) = r.get("exceptionDetails") {
            panic!("{expression}: {e}");
        }
        r["result"]["value"].clone()
    }

    /// Loads `url`.
    pub async fn navigate(&mut self, url: &str) {
        self.call("Page.enable", json!({})).await;
        self.call("Page.navigate", json!({"url": url})).await;
    }

    /// Polls `expression` until it is `true`; panics after `timeout`.
    pub async fn wait_for(&mut self, expression: &str, timeout: Duration) {
        let end = Instant::now() + timeout;
        loop {
            if self.eval(expression).await == Value::Bool(true) {
                return;
            }
            assert!(Instant::now() < end, "timed out waiting for {expression}");
            tokio::time::sleep(Duration::from_millis(100)).await;
        }
    }

    /// A mouse event at CSS pixel (x, y): `kind` is mousePressed,
    /// mouseMoved or mouseReleased; the left button is down for pressed and
    /// moved when `held`.
    pub async fn mouse(&mut self, kind: &str, x: f64, y: f64, held: bool) {
        self.call(
            "Input.dispatchMouseEvent",
            json!({
                "type": kind, "x": x, "y": y,
                "button": if held || kind == "mouseReleased" { "left" } else { "none" },
                "buttons": if held { 1 } else { 0 },
                "clickCount": if kind == "mouseMoved" { 0 } else { 1 },
            }),
        )
        .await;
    }

    /// A PNG screenshot of the page.
    pub async fn screenshot(&mut self) -> Vec<u8> {
        use base64::Engine;
        let r = self
            .call("Page.captureScreenshot", json!({"format": "png"}))
            .await;
        base64::engine::general_purpose::STANDARD
            .decode(r["data"].as_str().unwrap())
            .unwrap()
    }
}

/// JavaScript: the fraction of the viewer's canvas covered by saturated
/// colour (the body's colour map; the background, grid and text are grey),
/// read by the page right after a draw.
pub const COLOURED_FRACTION: &str = "mssView.colouredFraction()";
