//! `mss view`: the live browser viewer of a scene, or the replay of a run.

use std::net::IpAddr;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use anyhow::Context;
use clap::Args;
use mss_view::{Source, ViewOptions, Viewer};

use crate::GlobalArgs;

/// Arguments of `mss view`.
#[derive(Debug, Clone, Args)]
pub struct ViewArgs {
    /// Scene file (TOML) to run live, or a folder written by `mss run` to
    /// replay. Without it, the bundled default scene runs live.
    #[arg(value_name = "SCENE_OR_RUN")]
    pub path: Option<PathBuf>,
    /// Port to listen on (0: any free port).
    #[arg(long, default_value_t = 0)]
    pub port: u16,
    /// Address to listen on. The default lets only this machine connect;
    /// another address exposes the viewer (still behind its token) to the
    /// network.
    #[arg(long, default_value = "127.0.0.1")]
    pub host: IpAddr,
    /// Do not try to open a browser.
    #[arg(long)]
    pub no_open: bool,
    /// Start paused.
    #[arg(long)]
    pub paused: bool,
}

impl ViewArgs {
    /// The library's options: the one place where the arguments become them.
    pub fn options(&self, global: &GlobalArgs) -> ViewOptions {
        ViewOptions {
            host: self.host,
            port: self.port,
            paused: self.paused,
            limits: global.limits(),
            ..ViewOptions::default()
        }
    }
}

/// Tries the desktop's opener; a machine without one just prints the URL.
fn open_browser(url: &str) {
    for opener in ["xdg-open", "open"] {
        let spawned = std::process::Command::new(opener)
            .arg(url)
            .stdin(std::process::Stdio::null())
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::null())
            .spawn();
        if spawned.is_ok() {
            return;
        }
    }
    log::info!("no browser opener found; open the URL by hand");
}

/// Runs `mss view` until Ctrl-C (SIGINT) or SIGTERM.
pub fn run(args: &ViewArgs, global: &GlobalArgs) -> anyhow::Result<()> {
    let source = Source::for_path(args.path.as_deref())?;
    let options = args.options(global);
    if !args.host.is_loopback() {
        log::warn!(
            "mss view listens on {}: other machines can reach it (each request still needs the token)",
            args.host
        );
    }
    let stop = Arc::new(AtomicBool::new(false));
    for signal in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        signal_hook::flag::register(signal, Arc::clone(&stop))
            .context("cannot install the Ctrl-C handler")?;
    }
    let viewer = Viewer::start(source, options)?;
    crate::outln!("mss view: {}", viewer.url());
    if !args.no_open {
        open_browser(viewer.url());
    }
    while !stop.load(Ordering::Relaxed) {
        std::thread::sleep(Duration::from_millis(50));
    }
    viewer.stop();
    Ok(())
}
