//! How close `mss check`'s memory, time and output estimates come to what
//! runs measure: for the bundled scenes and voxelized cubes, the estimates of
//! `mss_scene::check::CheckReport` (computed here on a pool of the run's
//! thread count) beside the peak memory, stepping time and bytes written
//! that `mss run` (the binary, one process per run) writes to its summary.
//!
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

fn main() {
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
    let mut scenes: Vec<(String, std::path::PathBuf)> = ["default", "template", "drop", "press"]
        .iter()
        .map(|n| (n.to_string(), data.join(format!("{n}.toml"))))
        .collect();
    for cells in [32, 48, 64, 96, 128].into_iter().filter(|&c| c <= largest) {
        let path = dir.path().join(format!("cube{cells}.toml"));
        std::fs::write(&path, cube_scene(cells)).expect("scene");
        scenes.push((format!("cube {cells}^3"), path));
    }
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .expect("a thread pool");
    println!(
        "{threads} thread(s)\n| scene | cells | memory estimate | peak memory | ratio | time estimate | stepping time | ratio | output estimate | written | ratio |\n|---|---|---|---|---|---|---|---|---|---|---|"
    );
    for (name, path) in scenes {
        let (report, cells) = pool.install(|| {
            let input = SceneInput::load(Some(&path)).expect("the scene");
            let job = Job::prepare(input, Registry::default(), &no_progress).expect("prepared");
            (CheckReport::new(&job), job.problem.model().num_cells())
        });
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
        let output = (report.frame_bytes * report.frames) as f64;
        let mib = |b: f64| b / f64::from(1 << 20);
        let (time, time_ratio) =
            report
                .time_estimate
                .as_ref()
                .map_or(("-".to_string(), "-".to_string()), |t| {
                    (
                        format!("{:.2} s", t.seconds),
                        format!("{:.2}", t.seconds / seconds),
                    )
                });
        println!(
            "| {name} | {cells} | {:.1} MiB | {:.1} MiB | {:.2} | {time} | {seconds:.2} s | {time_ratio} | {:.1} MiB | {:.1} MiB | {:.2} |",
            mib(report.memory_bytes as f64),
            mib(peak),
            report.memory_bytes as f64 / peak,
            mib(output),
            mib(written),
            output / written,
        );
    }
}
