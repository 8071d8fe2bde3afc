//! The interactive benchmark of the contact issue: a body of about 10,000
//! cells on the ground, dragged by a picked node at 60 frames per second;
//! prints the frame time (with its explicit sub-steps) on the threads rayon
//! is given (`RAYON_NUM_THREADS=1` for one). With `FRAMES` set, frames over
//! two frame periods are listed with their sub-steps.
//!
//!     cargo run --release -p mss-core --example interactive [CELLS_PER_SIDE] [YOUNG] [f64|f32]

mod common;
use common::frames;

fn main() {
    let (n, young, precision, _) = frames::args(22, 2.0e4);
    let s = frames::interactive(n, young, precision, 120);
    println!(
        "{} cells, E = {young} Pa, {} threads, {}: frame of 1/60 s in {} sub-steps; \
         frame time mean {:.1} ms, median {:.1} ms, max {:.1} ms (the first frame, which sets \
         up the integrator: {:.1} ms); CPU {:.1} ms per frame, {:.1} ms per frame after the \
         first (target 8 ms on one thread)",
        s.cells,
        rayon::current_num_threads(),
        precision.name(),
        s.substeps,
        s.mean,
        s.median,
        s.worst,
        s.first,
        s.cpu_per_frame,
        s.cpu_per_later_frame
    );
}
