//! The quick tests of this crate, in one binary (a module per file): `cargo
//! test --release --test fast` runs them, and `cargo fast` runs every crate's
//! (see README).

mod barrier;
mod bodies;
mod contact;
mod determinism;
mod hourglass;
mod model_facts;
mod rigid_cell_modes;
mod solvers;
mod step_control;
