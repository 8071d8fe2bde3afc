//! The quick tests of this crate, in one binary (a module per file): `cargo
//! test --release --test fast` runs them, and `cargo fast` runs every crate's
//! (see README).

mod barrier;
mod bodies;
mod contact;
mod determinism;
mod hourglass;
mod model_facts;
mod plane;
mod rigid_cell_modes;
mod solvers;
mod step_control;

/// Runs `f` in a rayon pool of `threads` threads: the determinism tests
/// compare runs on several thread counts.
pub fn on_threads<R: Send>(threads: usize, f: impl FnOnce() -> R + Send) -> R {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap()
        .install(f)
}
