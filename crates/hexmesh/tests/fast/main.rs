//! The quick tests of this crate, in one binary (a module per file): `cargo
//! test --release --test fast` runs them, and `cargo fast` runs every crate's
//! (see README).

#[path = "../common/mod.rs"]
mod common;

mod convergence;
mod critter;
mod formats;
mod fuzz_replay;
mod image;
mod load_errors;
mod plane;
mod skin_embed;
mod voxelize;
