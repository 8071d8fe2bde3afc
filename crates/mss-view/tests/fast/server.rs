//! The viewer's server against a stand-in page: the token, the routes, the
//! protocol's round trips, bad messages, several pages, the drag, the
//! poking sphere, errors of the scene and replay.

use crate::common;

use std::time::Duration;

use common::{Page, finished_run, raw_http, small_input};
use futures_util::SinkExt;
use mss_view::mss_scene::mss_io::vtk::read::read_lattice_vtu;
use mss_view::{Source, ViewError, ViewOptions, Viewer};

const WAIT: Duration = Duration::from_secs(60);

/// A page's pick of `triangle` of surface 0 at `point`.
fn pick_message(triangle: usize, point: [f64; 3]) -> String {
    format!(
        r#"{{"type":"pick","surface":0,"triangle":{triangle},"point":[{},{},{}]}}"#,
        point[0], point[1], point[2]
    )
}

/// A page's message of `kind` whose `key` is the point `p`.
fn point_message(kind: &str, key: &str, p: [f64; 3]) -> String {
    format!(
        r#"{{"type":"{kind}","{key}":[{},{},{}]}}"#,
        p[0], p[1], p[2]
    )
}

fn live(paused: bool) -> Viewer {
    let options = ViewOptions {
        paused,
        ..ViewOptions::default()
    };
    let v = Viewer::start(Source::Input(Box::new(small_input())), options).unwrap();
    assert!(v.wait_for_frame(WAIT).is_some(), "no first frame");
    v
}

#[test]
fn binds_loopback_and_needs_the_token_everywhere() {
    let v = live(true);
    let addr = v.addr();
    assert!(addr.ip().is_loopback());
    assert!(v.url().ends_with(&format!("/?token={}", v.token())));
    assert_eq!(v.token().len(), 32);
    let t = v.token().to_owned();
    for path in [
        "/",
        "/viewer.js",
        "/viewer.css",
        "/ws",
        "/nope",
        "/../Cargo.toml",
    ] {
        for query in [
            String::new(),
            "?token=".into(),
            "?token=0123".into(),
            format!("?token={}x", t),
        ] {
            let (code, body) = raw_http(addr, &format!("GET {path}{query} HTTP/1.1"));
            assert_eq!(code, 403, "{path}{query}: {body}");
        }
    }
    let (code, body) = raw_http(addr, &format!("GET /?token={t} HTTP/1.1"));
    assert_eq!(code, 200);
    assert!(body.contains(&format!("viewer.js?token={t}")), "{body}");
    for asset in ["viewer.js", "viewer.css"] {
        let (code, body) = raw_http(addr, &format!("GET /{asset}?token={t} HTTP/1.1"));
        assert_eq!(code, 200, "{asset}");
        assert!(body.len() > 500, "{asset}");
    }
    // A second viewer gets another token.
    let w = live(true);
    assert_ne!(w.token(), v.token());
    let (code, _) = raw_http(w.addr(), &format!("GET /?token={t} HTTP/1.1"));
    assert_eq!(code, 403);
}

#[test]
fn no_path_reaches_the_file_system() {
    let v = live(true);
    let t = v.token().to_owned();
    for path in [
        "/../../../../etc/passwd",
        "/%2e%2e/%2e%2e/%2e%2e/etc/passwd",
        "/viewer.js/../../Cargo.toml",
        "/..%2f..%2fCargo.toml",
        "//etc/passwd",
        "/assets/viewer.js",
        "/src/lib.rs",
        "/Cargo.toml",
    ] {
        let (code, body) = raw_http(v.addr(), &format!("GET {path}?token={t} HTTP/1.1"));
        assert!(code == 404 || code == 400, "{path}: {code}");
        assert!(
            !body.contains("root:") && !body.contains("[package]"),
            "{path}: {body}"
        );
    }
    // Only GET is served.
    let (code, _) = raw_http(v.addr(), &format!("POST /?token={t} HTTP/1.1"));
    assert_eq!(code, 405);
}

#[tokio::test(flavor = "current_thread")]
async fn the_websocket_refuses_a_missing_token() {
    let v = tokio::task::spawn_blocking(|| live(true)).await.unwrap();
    for url in [
        format!("ws://{}/ws", v.addr()),
        format!("ws://{}/ws?token=bad", v.addr()),
    ] {
        match tokio_tungstenite::connect_async(url).await {
            Err(tokio_tungstenite::tungstenite::Error::Http(r)) => assert_eq!(r.status(), 403),
            other => panic!("expected 403, got {:?}", other.map(|_| ())),
        }
    }
    tokio::task::spawn_blocking(move || v.stop()).await.unwrap();
}

#[tokio::test(flavor = "current_thread")]
async fn a_page_gets_the_scene_then_frames_and_controls_the_run() {
    let v = tokio::task::spawn_blocking(|| live(false)).await.unwrap();
    let mut page = Page::connect(v.addr(), v.token()).await;
    assert!(page.next_frame(WAIT).await);
    let scene = page.scene.clone().unwrap();
    assert_eq!(scene.mode, "live");
    assert!(scene.cells > 0 && scene.nodes > scene.cells);
    let topo = page.topology.clone().unwrap();
    assert_eq!(topo.len(), scene.surfaces.len());
    let frame = page.frame.clone().unwrap();
    for ((info, tris), s) in scene.surfaces.iter().zip(&topo).zip(&frame.surfaces) {
        assert_eq!(tris.len() as u32, info.triangles);
        assert_eq!(s.positions.len() as u32, info.vertices);
        assert_eq!(s.displacement.len(), s.positions.len());
        assert!(tris.iter().flatten().all(|&i| i < info.vertices));
        assert!(s.positions.iter().flatten().all(|c| c.is_finite()));
        assert!(s.jacobian.iter().all(|j| *j > 0.5 && *j < 1.5));
    }
    // Running: time advances and the body sags.
    page.until(WAIT, "time to pass", |s| s.time > 0.05).await;
    let status = page.status.clone().unwrap();
    assert!(status.playing && status.substeps >= 1 && status.max_displacement > 0.0);

    // Pause: time stops.
    page.send(r#"{"type":"pause"}"#).await;
    page.until(WAIT, "the pause", |s| !s.playing).await;
    let t = page.status.as_ref().unwrap().time;
    tokio::time::sleep(Duration::from_millis(300)).await;
    let s = v.status().unwrap();
    assert_eq!(s.time, t, "time advanced while paused");
    // One step: exactly one frame of 1/60 s.
    page.send(r#"{"type":"step"}"#).await;
    page.until(WAIT, "the step", |s| s.time > t).await;
    let dt = page.status.as_ref().unwrap().time - t;
    assert!((dt - 1.0 / 60.0).abs() < 1e-9, "{dt}");

    // Bad messages are ignored; the connection stays and still controls.
    for bad in [
        "not json",
        r#"{"type":"warp"}"#,
        r#"{"type":"drag","target":[1e300,0,0]}"#,
        r#"{"type":"time_scale","value":-1}"#,
        r#"{"type":"pick","surface":9,"triangle":0,"point":[0,0,0]}"#,
        r#"{"type":"pick","surface":0,"triangle":4000000000,"point":[0,0,0]}"#,
        r#"{"type":"seek","frame":3}"#,
    ] {
        page.send(bad).await;
    }
    page.send(r#"{"type":"time_scale","value":0.5}"#).await;
    page.send(r#"{"type":"play"}"#).await;
    page.until(WAIT, "play after bad messages", |s| {
        s.playing && s.time_scale == 0.5
    })
    .await;

    // A second page connects and gets the same scene and frames.
    let mut second = Page::connect(v.addr(), v.token()).await;
    assert!(second.next_frame(WAIT).await);
    assert_eq!(second.scene.as_ref().unwrap().generation, scene.generation);

    // A message over the limit ends that page's connection only.
    let huge = format!(r#"{{"type":"play","x":"{}"}}"#, "a".repeat(100_000));
    let _ = page
        .socket
        .send(tokio_tungstenite::tungstenite::Message::text(huge))
        .await;
    let t2 = second.status.as_ref().unwrap().time;
    second
        .until(WAIT, "frames after the flood", |s| s.time > t2 + 0.02)
        .await;

    // Reset: a new generation from rest.
    second.send(r#"{"type":"reset"}"#).await;
    let g = scene.generation;
    second
        .until(WAIT, "the reset", |s| s.generation > g && s.time < 0.05)
        .await;
    assert!(second.scene.as_ref().unwrap().generation > g);
    tokio::task::spawn_blocking(move || v.stop()).await.unwrap();
}

#[tokio::test(flavor = "current_thread")]
async fn a_drag_moves_the_grabbed_nodes_toward_the_cursor_and_a_poke_pushes() {
    let v = tokio::task::spawn_blocking(|| live(false)).await.unwrap();
    let mut page = Page::connect(v.addr(), v.token()).await;
    assert!(page.next_frame(WAIT).await);
    let scene = page.scene.clone().unwrap();
    // Grab the embedded surface at its highest vertex.
    let frame = page.frame.clone().unwrap();
    let surface = &frame.surfaces[0];
    let top = (0..surface.positions.len())
        .max_by(|&a, &b| surface.positions[a][2].total_cmp(&surface.positions[b][2]))
        .unwrap() as u32;
    let tri = page.topology.as_ref().unwrap()[0]
        .iter()
        .position(|t| t.contains(&top))
        .unwrap();
    let p = surface.positions[top as usize].map(f64::from);
    page.send(&pick_message(tri, p)).await;
    page.until(WAIT, "the grab", |s| s.grab_target.is_some())
        .await;
    let start = page.status.as_ref().unwrap().grab_centroid.unwrap();
    let lift = 0.25 * (scene.bounds[1][2] - scene.bounds[0][2]);
    page.send(&point_message("drag", "target", [p[0], p[1], p[2] + lift]))
        .await;
    page.until(WAIT, "the drag to lift the grab", |s| {
        s.grab_centroid
            .is_some_and(|c| c[2] > start[2] + 0.5 * lift)
    })
    .await;
    let s = page.status.clone().unwrap();
    let (c, t) = (s.grab_centroid.unwrap(), s.grab_target.unwrap());
    let gap = |a: [f64; 3], b: [f64; 3]| {
        ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
    };
    assert!(
        gap(c, t) < gap(start, t),
        "the grab did not approach its target"
    );
    page.send(r#"{"type":"release"}"#).await;
    page.until(WAIT, "the release", |s| s.grab_target.is_none())
        .await;

    // Poke, from rest: the sphere goes where asked and pushes the skin's
    // top node (the lattice's boundary is what touches) down.
    page.send(r#"{"type":"reset"}"#).await;
    let g = scene.generation;
    page.until(WAIT, "the reset", |s| s.generation > g).await;
    let skin = page.frame.clone().unwrap().surfaces[1].clone();
    let top = (0..skin.positions.len())
        .max_by(|&a, &b| skin.positions[a][2].total_cmp(&skin.positions[b][2]))
        .unwrap();
    let p = skin.positions[top].map(f64::from);
    let r = page.scene.as_ref().unwrap().poke_radius;
    assert!(r > 0.0);
    let above = [p[0], p[1], p[2] + r * 1.05];
    page.send(&point_message(
        "poke",
        "centre",
        [above[0], above[1], above[2]],
    ))
    .await;
    page.until(WAIT, "the sphere", |s| s.poke_centre.is_some())
        .await;
    let depth = 0.4 * r;
    let pushed = [p[0], p[1], p[2] + r - depth];
    page.send(&point_message(
        "poke",
        "centre",
        [pushed[0], pushed[1], pushed[2]],
    ))
    .await;
    page.until(WAIT, "the sphere to move", |s| {
        s.poke_centre
            .is_some_and(|c| (c[2] - pushed[2]).abs() < 1e-9)
    })
    .await;
    let t0 = page.status.as_ref().unwrap().time;
    page.until(WAIT, "the push", |s| s.time > t0 + 0.3).await;
    let after = f64::from(page.frame.clone().unwrap().surfaces[1].positions[top][2]);
    assert!(
        after < p[2] - 0.5 * depth,
        "the sphere did not push the top down: {} -> {after} (pushed by {depth})",
        p[2],
    );
    assert!(page.status.as_ref().unwrap().error.is_none());
    page.send(r#"{"type":"unpoke"}"#).await;
    page.until(WAIT, "the sphere to go", |s| s.poke_centre.is_none())
        .await;
    tokio::task::spawn_blocking(move || v.stop()).await.unwrap();
}

#[tokio::test(flavor = "current_thread")]
async fn a_bad_scene_is_shown_to_the_page_and_reset_reads_the_fixed_file() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("bad.toml");
    std::fs::write(
        &file,
        common::SMALL_SCENE.replace("poisson = 0.3", "poisson = 0.7"),
    )
    .unwrap();
    let f = file.clone();
    let v = tokio::task::spawn_blocking(move || {
        Viewer::start(Source::SceneFile(f), ViewOptions::default()).unwrap()
    })
    .await
    .unwrap();
    let mut page = Page::connect(v.addr(), v.token()).await;
    let end = std::time::Instant::now() + WAIT;
    while page.scene.is_none() && std::time::Instant::now() < end {
        page.next_frame(Duration::from_millis(200)).await;
    }
    let scene = page.scene.clone().expect("a scene message");
    let error = scene.error.expect("the scene's error");
    assert!(
        error.contains("bad.toml") && error.contains("0.7"),
        "{error}"
    );
    std::fs::write(&file, common::SMALL_SCENE).unwrap();
    page.send(r#"{"type":"reset"}"#).await;
    assert!(
        page.next_frame(WAIT).await,
        "no frame after fixing the scene"
    );
    assert!(page.scene.as_ref().unwrap().error.is_none());
    tokio::task::spawn_blocking(move || v.stop()).await.unwrap();
}

#[test]
fn paths_that_are_neither_scene_nor_run_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("missing.toml");
    assert!(matches!(
        Source::for_path(Some(&missing)),
        Err(ViewError::NoSuchPath(_))
    ));
    let source = Source::for_path(Some(dir.path())).unwrap();
    let err = Viewer::start(source, ViewOptions::default()).unwrap_err();
    assert!(matches!(err, ViewError::NotARun { .. }), "{err}");
    assert!(err.to_string().contains("lattice.pvd"), "{err}");
    // A .pvd naming a file outside its folder.
    std::fs::write(
        dir.path().join("lattice.pvd"),
        r#"<VTKFile type="Collection"><Collection><DataSet timestep="0" file="../x.vtu"/></Collection></VTKFile>"#,
    )
    .unwrap();
    let err = Viewer::start(Source::Replay(dir.path().into()), ViewOptions::default()).unwrap_err();
    assert!(err.to_string().contains("plain file name"), "{err}");
    let busy = Viewer::start(
        Source::Input(Box::new(small_input())),
        ViewOptions::default(),
    )
    .unwrap();
    let taken = ViewOptions {
        port: busy.addr().port(),
        ..ViewOptions::default()
    };
    let err = Viewer::start(Source::Input(Box::new(small_input())), taken).unwrap_err();
    assert!(matches!(err, ViewError::Bind { .. }), "{err}");
}

/// A paused replay of the run folder `dir`, and a page connected to it.
async fn paused_replay(dir: &std::path::Path) -> (Viewer, Page) {
    let d = dir.to_path_buf();
    let v = tokio::task::spawn_blocking(move || {
        Viewer::start(
            Source::for_path(Some(&d)).unwrap(),
            ViewOptions {
                paused: true,
                ..ViewOptions::default()
            },
        )
        .unwrap()
    })
    .await
    .unwrap();
    let page = Page::connect(v.addr(), v.token()).await;
    (v, page)
}

#[tokio::test(flavor = "current_thread")]
async fn replay_plays_the_frames_of_a_run_and_seeks() {
    let run = finished_run(common::SMALL_SCENE);
    let dir = run.path().to_path_buf();
    let (v, mut page) = paused_replay(&dir).await;
    assert!(page.next_frame(WAIT).await);
    let scene = page.scene.clone().unwrap();
    assert_eq!(scene.mode, "replay");
    let pvd = mss_view::mss_scene::mss_io::vtk::read::read_pvd(&dir.join("lattice.pvd")).unwrap();
    assert_eq!(scene.frame_times.len(), pvd.len());
    assert_eq!(scene.surfaces.last().unwrap().name, "skin");
    assert_eq!(scene.surfaces[0].name, "surface");
    let last = pvd.len() - 1;
    page.send(&format!(r#"{{"type":"seek","frame":{last}}}"#))
        .await;
    page.until(WAIT, "the seek", |s| s.frame as usize == last)
        .await;
    let frame = page.frame.clone().unwrap();
    assert_eq!(frame.time, pvd[last].time);
    // The skin shows the last frame's lattice positions.
    let data = read_lattice_vtu(&dir.join(&pvd[last].file), 1 << 30).unwrap();
    let skin = frame.surfaces.last().unwrap();
    let mut matched = 0;
    for p in &skin.positions {
        let near = data
            .points
            .iter()
            .any(|q| (0..3).all(|k| (f64::from(p[k]) - q[k]).abs() < 1e-6));
        matched += usize::from(near);
    }
    assert_eq!(matched, skin.positions.len());
    assert!(skin.displacement.iter().any(|&d| d > 0.0));
    // Play from the first frame runs to the end and stops there.
    page.send(r#"{"type":"reset"}"#).await;
    page.until(WAIT, "the first frame", |s| s.frame == 0).await;
    page.send(r#"{"type":"time_scale","value":2.0}"#).await;
    page.send(r#"{"type":"play"}"#).await;
    page.until(WAIT, "the end of the replay", |s| {
        s.frame as usize == last && !s.playing
    })
    .await;
    tokio::task::spawn_blocking(move || v.stop()).await.unwrap();
}

#[tokio::test(flavor = "current_thread")]
async fn replay_shows_every_body_of_a_run_of_several() {
    let two = r#"
[loads]
gravity = [0.0, 0.0, -9.81]
[[obstacles]]
shape = { kind = "ground" }
[solver]
damping = 20.0
duration = 0.05
[output]
every_time = 0.025
[[bodies]]
name = "lower"
[bodies.mesh]
path = "builtin:cube"
scale = 0.1
translate = [0.0, 0.0, 0.05]
[bodies.voxelize]
cells = 3
[bodies.material]
young = 1.0e5
poisson = 0.3
density = 1000.0
[[bodies]]
name = "upper"
[bodies.mesh]
path = "builtin:cube"
scale = 0.05
translate = [0.0, 0.0, 0.13]
[bodies.voxelize]
cells = 4
[bodies.material]
young = 1.0e5
poisson = 0.3
density = 1000.0
"#;
    let run = finished_run(two);
    let dir = run.path().to_path_buf();
    let (v, mut page) = paused_replay(&dir).await;
    assert!(page.next_frame(WAIT).await);
    let scene = page.scene.clone().unwrap();
    // Three frames, each of two parts; the skin is both cubes' boundaries
    // (3^3 and 4^3 cells: 6 * 9 + 2 and 6 * 16 + 2 boundary nodes).
    assert_eq!(scene.frame_times, vec![0.0, 0.025, 0.05]);
    assert_eq!(scene.nodes, 64 + 125);
    assert_eq!(scene.cells, 27 + 64);
    let skin = scene.surfaces.last().unwrap();
    assert_eq!(skin.vertices, (6 * 9 + 2) + (6 * 16 + 2));
    assert_eq!(scene.surfaces[0].name, "surface");
    tokio::task::spawn_blocking(move || v.stop()).await.unwrap();
}

/// A 10 x 3 cm strip of 1 cm squares (a 2D scene) held at x = 0, its
/// SVG written in `dir`, with `tail` (more tables) at the end.
fn strip_input(dir: &std::path::Path, tail: &str) -> mss_view::mss_scene::SceneInput {
    let svg = dir.join("strip.svg");
    std::fs::write(
        &svg,
        r#"<svg><rect x="0" y="0" width="0.1" height="0.03"/></svg>"#,
    )
    .unwrap();
    let text = format!(
        "[mesh]\npath = {:?}\n[voxelize]\ncell_size = [0.01, 0.01]\n[model]\ndimension = 2\n\
         thickness = 0.01\nparameterization = \"paper+hg\"\n[material]\nyoung = 1.0e5\n\
         poisson = 0.3\ndensity = 1000.0\n[[fixed]]\nkind = \"face\"\nface = \"x-\"\n{tail}",
        svg.display().to_string()
    );
    mss_view::mss_scene::SceneInput::from_toml(&text, "strip.toml").unwrap()
}

/// A 2D scene in the live viewer: the strip stands upright (the plane's y
/// is the page's z), one surface of two triangles per rectangle; a drag
/// lifts the picked rectangle toward the cursor; the poking disc pushes the
/// top down; the scene's obstacles are drawn.
#[tokio::test(flavor = "current_thread")]
async fn a_2d_body_is_shown_upright_dragged_and_poked() {
    let dir = tempfile::tempdir().unwrap();
    let input = strip_input(
        dir.path(),
        "[[obstacles]]\nshape = { kind = \"sphere\", centre = [0.2, 0.0, 0.0], radius = 0.01 }\n\
         [solver]\nkind = \"explicit\"\ndamping = 10.0\nduration = 1.0\n",
    );
    let v = tokio::task::spawn_blocking(move || {
        let v = Viewer::start(Source::Input(Box::new(input)), ViewOptions::default()).unwrap();
        assert!(v.wait_for_frame(WAIT).is_some(), "no first frame");
        v
    })
    .await
    .unwrap();
    let mut page = Page::connect(v.addr(), v.token()).await;
    assert!(page.next_frame(WAIT).await);
    let scene = page.scene.clone().unwrap();
    assert!(scene.error.is_none(), "{:?}", scene.error);
    assert_eq!(scene.cells, 30);
    assert_eq!(scene.surfaces.len(), 1);
    assert_eq!(scene.surfaces[0].triangles, 60);
    assert_eq!(scene.obstacles.len(), 1);
    // Upright: the strip's height (3 cm) is the page's z, its depth 0.
    assert!((scene.bounds[1][2] - scene.bounds[0][2] - 0.03).abs() < 1e-9);
    assert!((scene.bounds[1][1] - scene.bounds[0][1]).abs() < 1e-12);
    // Grab the free end's top corner and lift it by 2 cm.
    let frame = page.frame.clone().unwrap();
    let surface = &frame.surfaces[0];
    let corner = (0..surface.positions.len())
        .max_by(|&a, &b| {
            let s = |i: usize| surface.positions[i][0] + surface.positions[i][2];
            s(a).total_cmp(&s(b))
        })
        .unwrap() as u32;
    let tri = page.topology.as_ref().unwrap()[0]
        .iter()
        .position(|t| t.contains(&corner))
        .unwrap();
    let p = surface.positions[corner as usize].map(f64::from);
    page.send(&pick_message(tri, p)).await;
    page.until(WAIT, "the grab", |s| s.grab_target.is_some())
        .await;
    let start = page.status.as_ref().unwrap().grab_centroid.unwrap();
    let lift = 0.02;
    page.send(&point_message("drag", "target", [p[0], p[1], p[2] + lift]))
        .await;
    page.until(WAIT, "the drag to lift the end", |s| {
        s.grab_centroid
            .is_some_and(|c| c[2] > start[2] + 0.3 * lift)
    })
    .await;
    page.send(r#"{"type":"release"}"#).await;
    page.until(WAIT, "the release", |s| s.grab_target.is_none())
        .await;
    // Poke the free end's top from above, from rest.
    page.send(r#"{"type":"reset"}"#).await;
    let g = scene.generation;
    page.until(WAIT, "the reset", |s| s.generation > g).await;
    let r = page.scene.as_ref().unwrap().poke_radius;
    let above = [p[0] - 0.005, 0.0, p[2] + r * 1.05];
    page.send(&point_message(
        "poke",
        "centre",
        [above[0], above[1], above[2]],
    ))
    .await;
    page.until(WAIT, "the disc", |s| s.poke_centre.is_some())
        .await;
    let depth = 0.4 * r;
    page.send(&point_message(
        "poke",
        "centre",
        [above[0], above[1], p[2] + r - depth],
    ))
    .await;
    let t0 = page.status.as_ref().unwrap().time;
    page.until(WAIT, "the push", |s| s.time > t0 + 0.3).await;
    let after = f64::from(page.frame.clone().unwrap().surfaces[0].positions[corner as usize][2]);
    assert!(
        after < p[2] - 0.3 * depth,
        "the disc did not push the end down: {} -> {after}",
        p[2]
    );
    assert!(page.status.as_ref().unwrap().error.is_none());
    tokio::task::spawn_blocking(move || v.stop()).await.unwrap();
}

/// A 2D run's folder replays: its quads stand upright as a thin slab (the
/// plane's y is the page's z), its frames come with their displacement.
#[tokio::test(flavor = "current_thread")]
async fn a_2d_run_replays_upright() {
    let dir = tempfile::tempdir().unwrap();
    let input = strip_input(
        dir.path(),
        "[loads]\ngravity = [0.0, -9.81, 0.0]\n[solver]\nkind = \"explicit\"\ndamping = 10.0\n\
         duration = 0.2\n[output]\nevery_time = 0.05\n",
    );
    let job = mss_view::mss_scene::plane_job::PlaneJob::prepare(input).unwrap();
    let out = dir.path().join("out");
    let summary = job.run(&out, &mss_view::mss_scene::Cancel::new()).unwrap();
    assert!(summary.frames >= 4);
    let v = tokio::task::spawn_blocking(move || {
        let options = ViewOptions {
            paused: true,
            ..ViewOptions::default()
        };
        let v = Viewer::start(Source::Replay(out), options).unwrap();
        assert!(v.wait_for_frame(WAIT).is_some(), "no first frame");
        v
    })
    .await
    .unwrap();
    let mut page = Page::connect(v.addr(), v.token()).await;
    assert!(page.next_frame(WAIT).await);
    let scene = page.scene.clone().unwrap();
    assert!(scene.error.is_none(), "{:?}", scene.error);
    assert_eq!(scene.mode, "replay");
    assert_eq!(scene.cells, 30);
    assert!((scene.bounds[1][2] - scene.bounds[0][2] - 0.03).abs() < 1e-9);
    assert!(scene.bounds[1][1] - scene.bounds[0][1] < 0.01);
    // The last frame sags: its displacement is the summary's.
    let last = scene.frame_times.len() - 1;
    page.send(&format!(r#"{{"type":"seek","frame":{last}}}"#))
        .await;
    page.until(WAIT, "the last frame", |s| s.frame as usize == last)
        .await;
    let shown = page.status.as_ref().unwrap().max_displacement;
    assert!(
        (shown - summary.max_displacement).abs() < 1e-9 * summary.max_displacement.max(1e-12),
        "{shown} vs {}",
        summary.max_displacement
    );
    tokio::task::spawn_blocking(move || v.stop()).await.unwrap();
}
