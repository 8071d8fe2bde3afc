//! How close `mss check`'s memory, time and output estimates come to what
//! runs measure: for the bundled scenes and voxelized cubes, the estimates of
//! `mss_scene::check::CheckReport` (computed in a process of its own on a
//! pool of the run's thread count) beside the peak memory, stepping time and bytes written
//! that `mss run` (the binary, one process per run) writes to its summary.
//!
//! The scenes: the bundled 3D ones, the Stanford bunny sagging and folding
//! (the time estimate's pilot run), and voxelized cubes.
//! `cargo bench -p mss-cli --bench estimates [-- THREADS [LARGEST_CUBE]]`
//! (defaults: 1 thread, cubes up to 64^3 cells). Not run by CI.

use std::path::Path;
use std::process::Command;

use mss_scene::check::CheckReport;
use mss_scene::{Job, Registry, SceneInput, no_progress};

fn cube_scene(cells: u32) -> String {
    format!(
        "[mesh]\npath = \"cube.obj\"\n[voxelize]\ncells = {cells}\n\
         [material]\nyoung = 2.0e4\npoisson = 0.3\ndensity = 1000.0\n\
         [model]\nparameterization = \"paper\"\n[[fixed]]\nkind = \"lowest_layer\"\n\
         [loads]\ngravity = [0.0, 0.0, -9.81]\n[solver]\nkind = \"explicit\"\nduration = 0.05\n"
    )
}

/// Prints the check report of the scene at `path` as JSON, on a pool of
/// `threads`: run in a process of its own, so that its peak memory (which
/// the memory estimate takes from the load check's solve) is the scene's.
fn child_check(path: &Path, threads: usize) {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .expect("a thread pool");
    let report = pool.install(|| {
        let input = SceneInput::load(Some(path)).expect("the scene");
        let job = Job::prepare(input, Registry::default(), &no_progress).expect("prepared");
        let mut value = serde_json::to_value(CheckReport::new(&job)).expect("json");
        value["cells"] = job.problem.model().num_cells().into();
        value
    });
    println!("{report}");
}

fn main() {
    let all: Vec<String> = std::env::args().collect();
    if let Some(i) = all.iter().position(|a| a == "--child-check") {
        child_check(Path::new(&all[i + 1]), all[i + 2].parse().expect("threads"));
        return;
    }
    let args: Vec<String> = std::env::args()
        .skip(1)
        .filter(|a| !a.starts_with("--"))
        .collect();
    let threads: usize = args.first().and_then(|s| s.parse().ok()).unwrap_or(1);
    let largest: u32 = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(64);
    let dir = tempfile::tempdir().expect("a temporary folder");
    let cube = mss_scene::hexmesh::generate::box_mesh([0.0; 3], [1.0; 3]);
    mss_scene::mss_io::skin::write_obj(
        &dir.path().join("cube.obj"),
        &cube.vertices,
        &cube.triangles,
    )
    .expect("cube.obj");
    let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data/scenes");
    let mut scenes: Vec<(String, std::path::PathBuf)> = [
        "default", "template", "drop", "press", "organ", "stack", "squeeze",
    ]
    .iter()
    .map(|n| (n.to_string(), data.join(format!("{n}.toml"))))
    .collect();
    // The Stanford bunny, 0.15 m tall on its feet, at 32 cells: sagging at
    // 100 kPa, and at 10 kPa and nu = 0.45 folding onto its few held nodes
    // (its explicit sub-step shrinks tenfold: the estimate's pilot run).
    let default = std::fs::read_to_string(data.join("default.toml")).expect("default.toml");
    let bunny_mesh = data.join("../meshes/bunny.obj");
    let bunny = default
        .replace(
            "path = \"../meshes/critter.obj\"",
            &format!(
                "path = {bunny_mesh:?}\nup = \"y\"\nscale = {}",
                0.15 / 9.657897
            ),
        )
        .replace("cells = 24 ", "cells = 32 ");
    let soft_bunny = bunny
        .replace("young = 1.0e5", "young = 1.0e4")
        .replace("poisson = 0.3", "poisson = 0.45")
        .replace("duration = 1.0 ", "duration = 0.5 ");
    for (name, toml) in [("bunny", bunny), ("soft bunny", soft_bunny)] {
        assert!(toml.contains("bunny.obj"), "the default scene changed");
        let path = dir.path().join(format!("{}.toml", name.replace(' ', "_")));
        std::fs::write(&path, toml).expect("scene");
        scenes.push((name.to_owned(), path));
    }
    for cells in [32, 48, 64, 96, 128].into_iter().filter(|&c| c <= largest) {
        let path = dir.path().join(format!("cube{cells}.toml"));
        std::fs::write(&path, cube_scene(cells)).expect("scene");
        scenes.push((format!("cube {cells}^3"), path));
    }
    println!(
        "{threads} thread(s)\n| scene | cells | memory estimate | peak memory | ratio | time estimate | run's time | ratio | output estimate | written | ratio |\n|---|---|---|---|---|---|---|---|---|---|---|"
    );
    let me = std::env::current_exe().expect("this bench");
    for (name, path) in scenes {
        let child = Command::new(&me)
            .arg("--child-check")
            .arg(&path)
            .arg(threads.to_string())
            .output()
            .expect("the check runs");
        assert!(child.status.success(), "{name}: the check failed");
        let report: serde_json::Value =
            serde_json::from_slice(&child.stdout).expect("the check's json");
        let cells = report["cells"].as_u64().unwrap_or(0);
        let out = dir.path().join("out");
        let status = Command::new(env!("CARGO_BIN_EXE_mss"))
            .args(["-q", "--threads", &threads.to_string(), "run"])
            .arg(&path)
            .arg("--out")
            .arg(&out)
            .status()
            .expect("mss runs");
        assert!(status.success(), "{name}: mss run failed");
        let summary: serde_json::Value = serde_json::from_str(
            &std::fs::read_to_string(out.join("summary.json")).expect("summary.json"),
        )
        .expect("json");
        let peak = summary["peak_memory_bytes"].as_f64().unwrap_or(f64::NAN);
        let seconds = summary["simulate_seconds"].as_f64().unwrap_or(f64::NAN);
        let written = summary["bytes_written"].as_f64().unwrap_or(f64::NAN);
        let number = |v: &serde_json::Value| v.as_f64().unwrap_or(f64::NAN);
        let output = number(&report["frame_bytes"]) * number(&report["frames"]);
        let memory = number(&report["memory_bytes"]);
        let mib = |b: f64| b / f64::from(1 << 20);
        let estimate = &report["time_estimate"];
        let (time, time_ratio) = if estimate.is_null() {
            ("-".to_string(), "-".to_string())
        } else {
            let t = number(&estimate["seconds"]);
            (format!("{t:.2} s"), format!("{:.2}", t / seconds))
        };
        println!(
            "| {name} | {cells} | {:.1} MiB | {:.1} MiB | {:.2} | {time} | {seconds:.2} s | {time_ratio} | {:.1} MiB | {:.1} MiB | {:.2} |",
            mib(memory),
            mib(peak),
            memory / peak,
            mib(output),
            mib(written),
            output / written,
        );
    }
}
