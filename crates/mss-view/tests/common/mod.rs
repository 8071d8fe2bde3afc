//! Helpers shared by the viewer's tests: small scenes, a raw HTTP client
//! (so that paths reach the server exactly as written, unnormalized) and a
//! WebSocket page stand-in.

#![allow(dead_code)]

use std::io::{Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::time::{Duration, Instant};

use futures_util::{SinkExt, StreamExt};
use mss_view::protocol::{DecodedFrame, SceneInfo, Status, decode_frame, decode_topology};
use tokio_tungstenite::tungstenite::Message;

/// A small live scene: the critter at 8 cells, feet held, gravity.
pub const SMALL_SCENE: &str = r#"
[mesh]
path = "builtin:critter"
[voxelize]
cells = 8
[material]
young = 1.0e5
poisson = 0.3
density = 1000.0
[[fixed]]
kind = "lowest_layer"
[loads]
gravity = [0.0, 0.0, -9.81]
[solver]
damping = 20.0
duration = 0.1
[output]
every_time = 0.025
"#;

pub fn small_input() -> mss_view::mss_scene::SceneInput {
    mss_view::mss_scene::SceneInput::from_toml(SMALL_SCENE, "small.toml").unwrap()
}

/// Sends `request` as written and returns the status code and body.
pub fn raw_http(addr: SocketAddr, request_line: &str) -> (u16, String) {
    let mut s = TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    write!(
        s,
        "{request_line}\r\nHost: {addr}\r\nConnection: close\r\n\r\n"
    )
    .unwrap();
    let mut reply = Vec::new();
    s.read_to_end(&mut reply).unwrap();
    let text = String::from_utf8_lossy(&reply).into_owned();
    let code = text
        .split_whitespace()
        .nth(1)
        .and_then(|c| c.parse().ok())
        .unwrap_or(0);
    let body = text.split("\r\n\r\n").nth(1).unwrap_or("").to_owned();
    (code, body)
}

/// A page stand-in on the viewer's WebSocket.
pub struct Page {
    pub socket: tokio_tungstenite::WebSocketStream<
        tokio_tungstenite::MaybeTlsStream<tokio::net::TcpStream>,
    >,
    pub scene: Option<SceneInfo>,
    pub topology: Option<Vec<Vec<[u32; 3]>>>,
    pub status: Option<Status>,
    pub frame: Option<DecodedFrame>,
}

impl Page {
    pub async fn connect(addr: SocketAddr, token: &str) -> Page {
        let url = format!("ws://{addr}/ws?token={token}");
        let (socket, _) = tokio_tungstenite::connect_async(url).await.unwrap();
        Page {
            socket,
            scene: None,
            topology: None,
            status: None,
            frame: None,
        }
    }

    pub async fn send(&mut self, json: &str) {
        self.socket.send(Message::text(json)).await.unwrap();
    }

    /// Reads messages until a frame arrives (true) or `timeout` passes.
    pub async fn next_frame(&mut self, timeout: Duration) -> bool {
        let end = Instant::now() + timeout;
        while Instant::now() < end {
            let left = end - Instant::now();
            let Ok(Some(Ok(m))) = tokio::time::timeout(left, self.socket.next()).await else {
                return false;
            };
            match m {
                Message::Text(t) => {
                    let v: serde_json::Value = serde_json::from_str(t.as_str()).unwrap();
                    match v["type"].as_str() {
                        Some("scene") => self.scene = Some(serde_json::from_value(v).unwrap()),
                        Some("status") => self.status = Some(serde_json::from_value(v).unwrap()),
                        other => panic!("unexpected message {other:?}"),
                    }
                }
                Message::Binary(b) => {
                    if let Some(t) = decode_topology(&b) {
                        self.topology = Some(t);
                    } else if let Some(f) = decode_frame(&b) {
                        self.frame = Some(f);
                        return true;
                    } else {
                        panic!("undecodable binary message of {} bytes", b.len());
                    }
                }
                _ => {}
            }
        }
        false
    }

    /// Reads frames until `done(status)` holds; panics after `timeout`.
    pub async fn until(&mut self, timeout: Duration, what: &str, done: impl Fn(&Status) -> bool) {
        let end = Instant::now() + timeout;
        loop {
            if let Some(s) = &self.status
                && done(s)
            {
                return;
            }
            assert!(
                Instant::now() < end,
                "timed out waiting for {what}; last status {:?}",
                self.status
            );
            self.next_frame(end - Instant::now()).await;
        }
    }
}

/// Runs a short job of `toml` into a fresh folder and returns it.
pub fn finished_run(toml: &str) -> tempfile::TempDir {
    use mss_view::mss_scene::{Cancel, Job, Registry, SceneInput, no_progress};
    let dir = tempfile::tempdir().unwrap();
    let input = SceneInput::from_toml(toml, "run.toml").unwrap();
    let job = Job::prepare(input, Registry::default(), &no_progress).unwrap();
    job.run(dir.path(), &no_progress, &Cancel::new()).unwrap();
    dir
}
