//! The quick tests of this crate, in one binary (a module per file): `cargo
//! test --release --test fast` runs them, and `cargo fast` runs every crate's
//! (see README).

mod blender;
mod bodies;
mod image;
mod job;
mod placement;
mod plane;
mod plug_points;
mod regions;
mod shapes;
mod stages;
