//! What single precision costs in accuracy and gives in time on a scene:
//! the scene's body is stepped to its `[solver] duration` twice from rest,
//! with the force pass in `f64` and in `f32` (everything else equal: an
//! interactive [`Simulation`] at the stable step, frames of 1/60 s), and
//! the final positions are compared node by node.
//!
//!     cargo run --release -p mss-scene --example precision_cost -- SCENE.toml [SCENE.toml ...]
//!
//! The scenes of docs/solvers.md's table are in `examples/precision/`
//! (a clamped cantilever, the bunny held at its base).
//!
//! Prints per scene: nodes, the largest displacement, the largest
//! difference between the two runs (absolute and relative to that
//! displacement) and the CPU time of each run (one thread:
//! `RAYON_NUM_THREADS=1`).

use std::path::Path;

use mss_scene::mss_core::simulation::Simulation;
use mss_scene::mss_core::{Precision, Vec3};
use mss_scene::{Job, Registry, SceneInput, no_progress};

/// CPU time of the process so far (s).
fn cpu_seconds() -> f64 {
    let t = rustix::time::clock_gettime(rustix::time::ClockId::ProcessCPUTime);
    t.tv_sec as f64 + 1e-9 * t.tv_nsec as f64
}

/// The final positions of `job`'s body after its duration, stepped in
/// frames of 1/60 s with the force pass in `precision`, and the CPU time.
fn run(job: &Job, precision: Precision) -> Result<(Vec<Vec3>, f64), Box<dyn std::error::Error>> {
    let mut sim = Simulation::new(job.rebuild_problem()?)?;
    sim.set_precision(precision);
    let duration = job.input.scene.solver.duration;
    let frame = 1.0 / 60.0;
    let frames = (duration / frame).ceil() as usize;
    let cpu = cpu_seconds();
    for k in 0..frames {
        let dt = frame.min(duration - k as f64 * frame);
        if dt > 0.0 {
            sim.step(dt)?;
        }
    }
    Ok((sim.positions().to_vec(), cpu_seconds() - cpu))
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let scenes: Vec<String> = std::env::args().skip(1).collect();
    if scenes.is_empty() {
        return Err("give one or more scene files".into());
    }
    println!(
        "{:<28} {:>8} {:>12} {:>12} {:>10} {:>9} {:>9}",
        "scene", "nodes", "max disp m", "f32-f64 m", "relative", "f64 s", "f32 s"
    );
    for path in scenes {
        let input = SceneInput::load(Some(Path::new(&path)))?;
        let job = Job::prepare(input, Registry::default(), &no_progress)?;
        let (x64, t64) = run(&job, Precision::F64)?;
        let (x32, t32) = run(&job, Precision::F32)?;
        let rest = job.problem.model().rest_positions();
        let max_disp = x64
            .iter()
            .zip(rest)
            .map(|(x, r)| (x - r).norm())
            .fold(0.0, f64::max);
        let max_diff = x64
            .iter()
            .zip(&x32)
            .map(|(a, b)| (a - b).norm())
            .fold(0.0, f64::max);
        println!(
            "{:<28} {:>8} {:>12.4e} {:>12.3e} {:>10.2e} {:>9.2} {:>9.2}",
            Path::new(&path)
                .file_name()
                .map_or(path.clone(), |n| n.to_string_lossy().into_owned()),
            x64.len(),
            max_disp,
            max_diff,
            max_diff / max_disp,
            t64,
            t32
        );
    }
    Ok(())
}
