//! # mss-view
//!
//! A live window onto the hexahedral mass-spring system, in the browser:
//! `mss view [SCENE]` runs a scene in an interactive
//! [`Simulation`](mss_scene::mss_core::simulation::Simulation) on its own
//! thread and streams the deformed surface to a page served on
//! `127.0.0.1`, where it can be watched, dragged with the mouse and poked
//! with a sphere; `mss view OUT_DIR` replays the frames of a finished run.
//!
//! How it is put together:
//!
//! - a **source** thread (live: [`live`], replay: [`replay`]) owns the
//!   simulation or the run's files, paces itself to real time (times a
//!   scale) and publishes each frame into a `tokio::sync::watch` channel:
//!   the latest frame replaces the one before, so a slow page drops frames
//!   and never slows the simulation down;
//! - a **server** ([`server`], axum on a one-thread tokio runtime) serves
//!   the page (HTML, JavaScript and CSS compiled into the binary: no
//!   network at run time, no JavaScript toolchain) and one WebSocket per
//!   page, which sends the scene and topology once, then each frame's
//!   positions as binary `f32` ([`protocol`]); the page's requests go to
//!   the source through a bounded queue (a flooding client loses messages,
//!   the source never waits);
//! - every request needs the **token** of the printed URL (403 without
//!   it); only the page's own assets have routes, so no request reaches the
//!   file system.
//!
//! ```no_run
//! use mss_view::{Source, Viewer, ViewOptions};
//!
//! let viewer = Viewer::start(Source::Bundled, ViewOptions::default()).unwrap();
//! println!("open {}", viewer.url());
//! viewer.wait();
//! ```
//!
//! The status of the running source can be read in-process (the page gets
//! the same figures):
//!
//! ```
//! use mss_view::{Source, Viewer, ViewOptions};
//!
//! let scene = mss_scene::SceneInput::from_toml(
//!     r#"
//!     [mesh]
//!     path = "builtin:critter"
//!     [voxelize]
//!     cells = 6
//!     [material]
//!     young = 1.0e5
//!     poisson = 0.3
//!     density = 1000.0
//!     [loads]
//!     gravity = [0.0, 0.0, -9.81]
//!     [[fixed]]
//!     kind = "lowest_layer"
//!     "#,
//!     "doc.toml",
//! )
//! .unwrap();
//! let options = ViewOptions { port: 0, ..ViewOptions::default() };
//! let viewer = Viewer::start(Source::Input(Box::new(scene)), options).unwrap();
//! assert!(viewer.url().starts_with("http://127.0.0.1:"));
//! let status = viewer.wait_for_frame(std::time::Duration::from_secs(60)).unwrap();
//! assert!(status.error.is_none());
//! viewer.stop();
//! ```

use std::net::{IpAddr, Ipv4Addr, SocketAddr};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

pub use mss_scene;

pub mod live;
mod plane_live;
pub mod protocol;
pub mod replay;
pub mod server;

use protocol::{ClientMessage, SceneInfo, Status};

/// What the viewer shows.
#[derive(Debug)]
pub enum Source {
    /// The bundled default scene (what `mss run` runs without arguments).
    Bundled,
    /// A scene file, read again at every reset (so edits are picked up).
    SceneFile(PathBuf),
    /// A scene given by a program (reset rebuilds it as given).
    Input(Box<mss_scene::SceneInput>),
    /// A folder written by `mss run`: its frames are replayed.
    Replay(PathBuf),
}

impl Source {
    /// The source `mss view PATH` means: nothing, the bundled scene; a
    /// folder, a replay of the run in it; a file, a scene.
    pub fn for_path(path: Option<&Path>) -> Result<Self, ViewError> {
        match path {
            None => Ok(Source::Bundled),
            Some(p) if p.is_dir() => Ok(Source::Replay(p.to_path_buf())),
            Some(p) if p.is_file() => Ok(Source::SceneFile(p.to_path_buf())),
            Some(p) => Err(ViewError::NoSuchPath(p.to_path_buf())),
        }
    }
}

/// How the viewer serves.
#[derive(Debug, Clone, PartialEq)]
pub struct ViewOptions {
    /// Address to bind (default 127.0.0.1: only this machine can connect).
    pub host: IpAddr,
    /// Port (0: any free port).
    pub port: u16,
    /// Start paused.
    pub paused: bool,
    /// Frames per second of wall time the source aims for.
    pub frame_rate: f64,
    /// Resource limits for building the scene.
    pub limits: mss_scene::limits::Limits,
}

impl Default for ViewOptions {
    fn default() -> Self {
        Self {
            host: IpAddr::V4(Ipv4Addr::LOCALHOST),
            port: 0,
            paused: false,
            frame_rate: 60.0,
            limits: mss_scene::limits::Limits::default(),
        }
    }
}

/// Why the viewer could not start.
#[derive(Debug, thiserror::Error)]
pub enum ViewError {
    /// The path is neither a scene file nor a run folder.
    #[error("{}: no such scene file or run folder", .0.display())]
    NoSuchPath(PathBuf),
    /// The folder holds no run.
    #[error("{}: not a run folder ({reason})", path.display())]
    NotARun {
        /// The folder.
        path: PathBuf,
        /// What is missing.
        reason: String,
    },
    /// The address could not be bound.
    #[error("cannot listen on {addr}: {source}")]
    Bind {
        /// The address.
        addr: SocketAddr,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// A thread or the runtime could not be started.
    #[error("cannot start the viewer: {0}")]
    Start(std::io::Error),
    /// No random token could be made.
    #[error("cannot make an access token: {0}")]
    Token(String),
    /// The frame frequency is not a positive number.
    #[error("frame rate {0} must be a positive number of frames per second, at most 1000")]
    FrameRate(f64),
}

/// A scene message ready to send: the info, as JSON, and the topology.
#[derive(Debug)]
pub(crate) struct ScenePacket {
    pub info: SceneInfo,
    pub json: String,
    pub topology: Vec<u8>,
}

/// A frame ready to send: the status, as JSON, and the positions.
#[derive(Debug)]
pub(crate) struct FramePacket {
    pub status: Status,
    pub json: String,
    pub binary: Vec<u8>,
}

/// What the source has published last.
#[derive(Debug, Default, Clone)]
pub(crate) struct Published {
    pub scene: Option<Arc<ScenePacket>>,
    pub frame: Option<Arc<FramePacket>>,
}

/// How a source thread talks to the rest.
pub(crate) struct SourceContext {
    pub publish: tokio::sync::watch::Sender<Published>,
    pub commands: std::sync::mpsc::Receiver<ClientMessage>,
    pub stop: Arc<AtomicBool>,
    pub options: ViewOptions,
}

impl SourceContext {
    pub(crate) fn publish_scene(&self, info: SceneInfo, topology: Vec<u8>) {
        let json = serde_json::to_string(&info).unwrap_or_default();
        let packet = Arc::new(ScenePacket {
            info,
            json,
            topology,
        });
        self.publish.send_modify(|p| {
            p.scene = Some(packet);
            p.frame = None;
        });
    }

    pub(crate) fn publish_frame(&self, status: Status, binary: Vec<u8>) {
        let json = serde_json::to_string(&status).unwrap_or_default();
        let packet = Arc::new(FramePacket {
            status,
            json,
            binary,
        });
        self.publish.send_modify(|p| p.frame = Some(packet));
    }

    pub(crate) fn stopped(&self) -> bool {
        self.stop.load(Ordering::Relaxed)
    }

    /// Waits up to `timeout` for a command (or returns at once with one
    /// queued).
    pub(crate) fn next_command(&self, timeout: Duration) -> Option<ClientMessage> {
        if timeout.is_zero() {
            self.commands.try_recv().ok()
        } else {
            self.commands.recv_timeout(timeout).ok()
        }
    }
}

/// The bounding box (min, max) of `points`; zeros for none.
pub(crate) fn bounds_of(points: impl Iterator<Item = [f64; 3]>) -> [[f64; 3]; 2] {
    let mut b = [[f64::INFINITY; 3], [f64::NEG_INFINITY; 3]];
    for p in points {
        for k in 0..3 {
            b[0][k] = b[0][k].min(p[k]);
            b[1][k] = b[1][k].max(p[k]);
        }
    }
    if !b[0][0].is_finite() {
        return [[0.0; 3]; 2];
    }
    b
}

/// Simulated seconds per wall second over the last second or so.
#[derive(Debug, Default)]
pub(crate) struct RateMeter {
    samples: std::collections::VecDeque<(Instant, f64)>,
}

impl RateMeter {
    pub(crate) fn record(&mut self, sim_time: f64) -> f64 {
        let now = Instant::now();
        self.samples.push_back((now, sim_time));
        while self.samples.len() > 2
            && now.duration_since(self.samples[0].0) > Duration::from_secs(1)
        {
            self.samples.pop_front();
        }
        let (t0, s0) = self.samples[0];
        let wall = now.duration_since(t0).as_secs_f64();
        if wall > 0.0 {
            (sim_time - s0) / wall
        } else {
            0.0
        }
    }

    pub(crate) fn reset(&mut self) {
        self.samples.clear();
    }
}

/// A running viewer: the server and its source. Dropping it stops both.
pub struct Viewer {
    url: String,
    token: String,
    addr: SocketAddr,
    stop: Arc<AtomicBool>,
    published: tokio::sync::watch::Receiver<Published>,
    shutdown: Option<tokio::sync::oneshot::Sender<()>>,
    threads: Vec<std::thread::JoinHandle<()>>,
}

impl std::fmt::Debug for Viewer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Viewer").field("addr", &self.addr).finish()
    }
}

/// A fresh 128-bit token, hex-encoded.
fn new_token() -> Result<String, ViewError> {
    let mut bytes = [0u8; 16];
    getrandom::fill(&mut bytes).map_err(|e| ViewError::Token(e.to_string()))?;
    Ok(bytes.iter().map(|b| format!("{b:02x}")).collect())
}

/// Most messages a page may have queued for the source; beyond, they are
/// dropped (a flooding client cannot grow the server's memory).
const COMMAND_QUEUE: usize = 256;

impl Viewer {
    /// Binds the address, starts the source and the server, and returns at
    /// once (the scene is built on the source's thread; the page shows it
    /// when it is ready, or its error).
    pub fn start(source: Source, options: ViewOptions) -> Result<Viewer, ViewError> {
        if !(options.frame_rate.is_finite()
            && options.frame_rate > 0.0
            && options.frame_rate <= 1000.0)
        {
            return Err(ViewError::FrameRate(options.frame_rate));
        }
        let replay = match &source {
            Source::Replay(dir) => Some(replay::RunFolder::open(dir)?),
            _ => None,
        };
        let addr = SocketAddr::new(options.host, options.port);
        let listener =
            std::net::TcpListener::bind(addr).map_err(|source| ViewError::Bind { addr, source })?;
        listener
            .set_nonblocking(true)
            .map_err(|source| ViewError::Bind { addr, source })?;
        let addr = listener
            .local_addr()
            .map_err(|source| ViewError::Bind { addr, source })?;
        let token = new_token()?;
        let host = match addr.ip() {
            IpAddr::V6(ip) => format!("[{ip}]"),
            IpAddr::V4(ip) => ip.to_string(),
        };
        let url = format!("http://{host}:{}/?token={token}", addr.port());

        let (publish, published) = tokio::sync::watch::channel(Published::default());
        let (command_tx, command_rx) = std::sync::mpsc::sync_channel(COMMAND_QUEUE);
        let stop = Arc::new(AtomicBool::new(false));
        let ctx = SourceContext {
            publish,
            commands: command_rx,
            stop: Arc::clone(&stop),
            options: options.clone(),
        };
        let source_thread = std::thread::Builder::new()
            .name("mss-view-source".into())
            .stack_size(64 << 20)
            .spawn(move || match replay {
                Some(run) => replay::run(run, ctx),
                None => live::run(source, ctx),
            })
            .map_err(ViewError::Start)?;

        let (shutdown_tx, shutdown_rx) = tokio::sync::oneshot::channel();
        let state = server::ServerState::new(token.clone(), published.clone(), command_tx);
        let runtime = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .map_err(ViewError::Start)?;
        let server_thread = std::thread::Builder::new()
            .name("mss-view-server".into())
            .spawn(move || {
                runtime.block_on(async move {
                    match tokio::net::TcpListener::from_std(listener) {
                        Ok(l) => server::serve(l, state, shutdown_rx).await,
                        Err(e) => log::error!("viewer: cannot serve: {e}"),
                    }
                });
            })
            .map_err(ViewError::Start)?;
        Ok(Viewer {
            url,
            token,
            addr,
            stop,
            published,
            shutdown: Some(shutdown_tx),
            threads: vec![source_thread, server_thread],
        })
    }

    /// The page's address with its token, `http://127.0.0.1:PORT/?token=...`.
    pub fn url(&self) -> &str {
        &self.url
    }

    /// The access token every request must carry.
    pub fn token(&self) -> &str {
        &self.token
    }

    /// The address the server listens on.
    pub fn addr(&self) -> SocketAddr {
        self.addr
    }

    /// The scene being shown, once the source has built it.
    pub fn scene(&self) -> Option<SceneInfo> {
        self.published
            .borrow()
            .scene
            .as_ref()
            .map(|s| s.info.clone())
    }

    /// The status of the last frame published, if any.
    pub fn status(&self) -> Option<Status> {
        self.published
            .borrow()
            .frame
            .as_ref()
            .map(|f| f.status.clone())
    }

    /// Waits until the source has published a frame (or a scene that
    /// failed to build) and returns its status; `None` after `timeout`.
    pub fn wait_for_frame(&self, timeout: Duration) -> Option<Status> {
        let end = Instant::now() + timeout;
        while Instant::now() < end {
            if let Some(s) = self.status() {
                return Some(s);
            }
            if let Some(scene) = self.scene()
                && let Some(e) = scene.error
            {
                return Some(Status {
                    kind: "status".into(),
                    generation: scene.generation,
                    error: Some(e),
                    ..Status::default()
                });
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        None
    }

    /// Blocks until the viewer stops (it does not stop by itself: another
    /// thread calls [`Viewer::stop`], or the process ends).
    pub fn wait(mut self) {
        for t in self.threads.drain(..) {
            let _ = t.join();
        }
    }

    /// Stops the server and the source and waits for them.
    pub fn stop(mut self) {
        self.shutdown_now();
    }

    fn shutdown_now(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(tx) = self.shutdown.take() {
            let _ = tx.send(());
        }
        for t in self.threads.drain(..) {
            let _ = t.join();
        }
    }
}

impl Drop for Viewer {
    fn drop(&mut self) {
        self.shutdown_now();
    }
}
