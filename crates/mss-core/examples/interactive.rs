//! The interactive benchmark of the contact issue: a body of about 10,000
//! cells on the ground, dragged by a picked node at 60 frames per second;
//! prints the frame time (with its explicit sub-steps) on the threads rayon
//! is given (`RAYON_NUM_THREADS=1` for one). With `FRAMES` set, frames over
//! two frame periods are listed with their sub-steps.
//!
//!     cargo run --release -p mss-core --example interactive [CELLS_PER_SIDE] [YOUNG] [f64|f32]

mod common;
use common::frames;

use mss_core::Precision;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let n: u32 = args.get(1).and_then(|a| a.parse().ok()).unwrap_or(22);
    let young: f64 = args.get(2).and_then(|a| a.parse().ok()).unwrap_or(2.0e4);
    let precision = args
        .get(3)
        .map(|a| Precision::from_name(a).expect("precision: f64 or f32"))
        .unwrap_or_default();
    let s = frames::interactive(n, young, precision, 120);
    println!(
        "{} cells, E = {young} Pa, {} threads, {}: frame of 1/60 s in {} sub-steps; \
         frame time mean {:.1} ms, median {:.1} ms, max {:.1} ms (the first frame, which sets \
         up the integrator: {:.1} ms); CPU {:.1} ms per frame (target 8 ms on one thread)",
        s.cells,
        rayon::current_num_threads(),
        precision.name(),
        s.substeps,
        s.mean,
        s.median,
        s.worst,
        s.first,
        s.cpu_per_frame
    );
}
