//! The viewer end to end in headless Chromium: the page loads and draws
//! the body, a drag with the mouse moves the body's nodes on the server
//! toward the cursor, pause stops time, and a replay shows a run's last
//! frame. Skipped with a message on a machine without a browser, unless
//! `MSS_VIEW_REQUIRE_BROWSER=1` (as CI sets it).
//!
//! `MSS_VIEW_SCREENSHOT=path.png` also writes the live page's screenshot
//! there (the README's picture is made this way).

use crate::cdp;
use crate::common;

use std::time::Duration;

use cdp::{Browser, COLOURED_FRACTION, browser_required};
use mss_view::{Source, ViewOptions, Viewer};

const WAIT: Duration = Duration::from_secs(90);

async fn browser() -> Option<Browser> {
    match Browser::launch(1000, 700).await {
        Some(b) => Some(b),
        None if browser_required() => {
            panic!("MSS_VIEW_REQUIRE_BROWSER=1 but no chromium was found (MSS_CHROMIUM names one)")
        }
        None => {
            eprintln!("skipped: no chromium on this machine (apt-get install chromium)");
            None
        }
    }
}

fn distance(a: [f64; 3], b: [f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

#[tokio::test(flavor = "current_thread")]
async fn the_page_draws_the_body_and_the_mouse_drags_it() {
    let Some(mut page) = browser().await else {
        return;
    };
    let v = tokio::task::spawn_blocking(|| {
        Viewer::start(Source::Bundled, ViewOptions::default()).unwrap()
    })
    .await
    .unwrap();
    page.navigate(v.url()).await;
    page.wait_for(
        "!!(window.mssView && mssView.ready && mssView.framesDrawn > 3)",
        WAIT,
    )
    .await;
    assert_eq!(page.eval("mssView.error").await, serde_json::Value::Null);
    let coloured = page.eval(COLOURED_FRACTION).await.as_f64().unwrap();
    assert!(
        coloured > 0.03,
        "the body covers only {coloured} of the canvas"
    );
    let png = page.screenshot().await;
    assert!(png.starts_with(b"\x89PNG"));
    if let Some(path) = std::env::var_os("MSS_VIEW_SCREENSHOT") {
        std::fs::write(path, &png).unwrap();
    }

    // Press on the body, drag the cursor up by 120 px.
    let hit = page.eval("mssView.findBodyPixel()").await;
    let (x, y) = (hit["x"].as_f64().unwrap(), hit["y"].as_f64().unwrap());
    page.mouse("mouseMoved", x, y, false).await;
    page.mouse("mousePressed", x, y, true).await;
    let end = std::time::Instant::now() + WAIT;
    let start = loop {
        if let Some(s) = v.status()
            && let (Some(c), Some(t)) = (s.grab_centroid, s.grab_target)
        {
            break (c, t);
        }
        assert!(
            std::time::Instant::now() < end,
            "the press did not grab the body"
        );
        tokio::time::sleep(Duration::from_millis(20)).await;
    };
    for k in 1..=12 {
        page.mouse("mouseMoved", x, y - 10.0 * f64::from(k), true)
            .await;
        tokio::time::sleep(Duration::from_millis(30)).await;
    }
    tokio::time::sleep(Duration::from_millis(1500)).await;
    let s = v.status().unwrap();
    let (centroid, target) = (s.grab_centroid.unwrap(), s.grab_target.unwrap());
    assert!(
        target[2] > start.1[2],
        "the target did not follow the cursor up: {start:?} -> {target:?}"
    );
    assert!(
        distance(centroid, target) < distance(start.0, target),
        "the grabbed nodes did not move toward the cursor: {start:?} -> {centroid:?}, target {target:?}"
    );
    assert!(centroid[2] > start.0[2], "the grab did not lift the body");
    page.mouse("mouseReleased", x, y - 120.0, false).await;
    let end = std::time::Instant::now() + WAIT;
    while v.status().unwrap().grab_target.is_some() {
        assert!(
            std::time::Instant::now() < end,
            "the release did not let go"
        );
        tokio::time::sleep(Duration::from_millis(20)).await;
    }

    // Pause with the page's button: time stops on the server.
    page.eval("document.getElementById('play').click()").await;
    let end = std::time::Instant::now() + WAIT;
    while v.status().unwrap().playing {
        assert!(
            std::time::Instant::now() < end,
            "the pause button did not pause"
        );
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    let t = v.status().unwrap().time;
    tokio::time::sleep(Duration::from_millis(500)).await;
    assert_eq!(v.status().unwrap().time, t, "time advanced while paused");
    page.wait_for("mssView.status.playing === false", WAIT)
        .await;
    tokio::task::spawn_blocking(move || v.stop()).await.unwrap();
}

#[tokio::test(flavor = "current_thread")]
async fn a_replay_shows_the_last_frame_of_a_run() {
    let Some(mut page) = browser().await else {
        return;
    };
    let run = common::finished_run(common::SMALL_SCENE);
    let dir = run.path().to_path_buf();
    let v = tokio::task::spawn_blocking(move || {
        let options = ViewOptions {
            paused: true,
            ..ViewOptions::default()
        };
        Viewer::start(Source::for_path(Some(&dir)).unwrap(), options).unwrap()
    })
    .await
    .unwrap();
    page.navigate(v.url()).await;
    page.wait_for(
        "!!(window.mssView && mssView.ready && mssView.framesDrawn > 1)",
        WAIT,
    )
    .await;
    let frames = v.scene().unwrap().frame_times.len();
    assert!(frames > 2);
    assert_eq!(
        page.eval("document.getElementById('replay').hidden").await,
        false
    );
    page.eval(
        "(() => { const f = document.getElementById('frame'); f.value = f.max; \
         f.dispatchEvent(new Event('input')); return f.max; })()",
    )
    .await;
    let last = (frames - 1) as u32;
    page.wait_for(&format!("mssView.status.frame === {last}"), WAIT)
        .await;
    assert_eq!(v.status().unwrap().frame, last);
    page.wait_for(
        &format!("mssView.framesReceived > 1 && mssView.status.frame === {last}"),
        WAIT,
    )
    .await;
    let coloured = page.eval(COLOURED_FRACTION).await.as_f64().unwrap();
    assert!(
        coloured > 0.02,
        "the replayed body covers only {coloured} of the canvas"
    );
    tokio::task::spawn_blocking(move || v.stop()).await.unwrap();
}
