//! The haptic benchmark of the speed issue: a 1,000-cell soft block held at
//! its base, pressed by a sphere that a hand moves every frame, one frame
//! per millisecond of simulated time (a haptic device's 1 kHz loop). Prints
//! the frame time over 10,000 frames: mean, median, 99th percentile and the
//! worst, and the process's CPU time per frame, on the threads rayon is
//! given (`RAYON_NUM_THREADS=1` for one). With `FRAMES` set, frames over
//! 2 ms are listed with their sub-steps.
//!
//!     cargo run --release -p mss-core --example haptic [CELLS_PER_SIDE] [YOUNG] [f64|f32] [FRAMES]

mod common;
use common::frames;

fn main() {
    let (n, young, precision, rest) = frames::args(10, 1.0e4);
    let count: usize = rest.first().and_then(|a| a.parse().ok()).unwrap_or(10_000);
    let s = frames::haptic(n, young, precision, count);
    println!(
        "{} cells, E = {young} Pa, {} thread(s), {}: {count} frames of 1 ms (at most {} \
         sub-steps); frame time mean {:.3} ms, median {:.3} ms, 99th percentile {:.3} ms, \
         worst {:.3} ms (the first frame, which sets up the integrator: {:.3} ms); \
         CPU {:.3} ms per frame (target 1 ms)",
        s.cells,
        rayon::current_num_threads(),
        precision.name(),
        s.substeps,
        s.mean,
        s.median,
        s.p99,
        s.worst,
        s.first,
        s.cpu_per_frame
    );
}
