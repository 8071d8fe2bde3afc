//! Streaming benchmark: the bundled default scene (or the scene file
//! given) live in headless Chromium, counting the frames the page receives
//! and draws over a few seconds of wall time.
//!
//! ```text
//! cargo run --release -p mss-view --example stream_rate [-- SCENE [SECONDS]]
//! ```
//!
//! Prints the displayed frames per second (the issue's target: at least 30
//! on the bundled scene), the real-time factor reached and the server's CPU
//! time per frame. Needs `chromium` (or `MSS_CHROMIUM`).

#[path = "../tests/common/cdp.rs"]
mod cdp;

use std::time::{Duration, Instant};

use mss_view::{Source, ViewOptions, Viewer};

#[tokio::main(flavor = "current_thread")]
async fn main() {
    let mut args = std::env::args().skip(1);
    let source = Source::for_path(args.next().as_deref().map(std::path::Path::new))
        .expect("a scene file, a run folder, or nothing");
    let seconds: f64 = args.next().map_or(5.0, |s| s.parse().expect("seconds"));
    let mut page = cdp::Browser::launch(1280, 800)
        .await
        .expect("no chromium found (install it, or set MSS_CHROMIUM)");
    let raf_js = "new Promise(r => { let n = 0; const t0 = performance.now(); const f = () => { n++; if (performance.now() - t0 < 2000) requestAnimationFrame(f); else r(n / 2); }; requestAnimationFrame(f); })";
    let idle = page.eval(raf_js).await;
    let viewer = tokio::task::spawn_blocking(move || {
        Viewer::start(source, ViewOptions::default()).expect("viewer")
    })
    .await
    .unwrap();
    page.navigate(viewer.url()).await;
    page.wait_for(
        "!!(window.mssView && mssView.ready && mssView.framesDrawn > 3)",
        Duration::from_secs(120),
    )
    .await;
    // Let the first frames (building, shader compilation) pass.
    tokio::time::sleep(Duration::from_secs(1)).await;
    let counts = "[mssView.framesReceived, mssView.framesShown]";
    let before = page.eval(counts).await;
    let t0 = Instant::now();
    let status0 = viewer.status().unwrap();
    tokio::time::sleep(Duration::from_secs_f64(seconds)).await;
    let after = page.eval(counts).await;
    let wall = t0.elapsed().as_secs_f64();
    let status1 = viewer.status().unwrap();
    let n = |v: &serde_json::Value, k: usize| v[k].as_f64().unwrap();
    let scene = viewer.scene().unwrap();
    println!(
        "scene {} ({} cells, {} nodes), {:.1} s of wall time",
        scene.name, scene.cells, scene.nodes, wall
    );
    println!(
        "frames received by the page  {:6.1} per second",
        (n(&after, 0) - n(&before, 0)) / wall
    );
    println!(
        "frames displayed by the page {:6.1} per second (new frames drawn)",
        (n(&after, 1) - n(&before, 1)) / wall
    );
    println!(
        "frames published             {:6.1} per second",
        (status1.seq - status0.seq) as f64 / wall
    );
    println!(
        "real-time factor             {:6.2} (simulated {:.3} s)",
        (status1.time - status0.time) / wall,
        status1.time - status0.time
    );
    println!(
        "server CPU per frame         {:6.2} ms, {} sub-steps",
        status1.frame_ms, status1.substeps
    );
    let raf = page.eval(raf_js).await;
    println!(
        "page animation frames        {:6.1} per second ({:.1} on a blank page before the viewer)",
        raf.as_f64().unwrap_or(0.0),
        idle.as_f64().unwrap_or(0.0)
    );
    tokio::task::spawn_blocking(move || viewer.stop())
        .await
        .unwrap();
}
