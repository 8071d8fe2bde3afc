//! The slow tests of this crate (large lattices, convergence studies, process
//! and browser runs), in one binary apart from the quick ones: `cargo test
//! --release --workspace` runs them too; `cargo fast` leaves them out.

mod equilibrium;
mod model_slow;
mod multigrid;
mod sliding;
