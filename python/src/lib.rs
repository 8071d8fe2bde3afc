//! # hexmss (Python bindings)
//!
//! The extension module `hexmss._hexmss` behind the Python package
//! `hexmss`: the geometry of `hexmesh`, the model and solvers of
//! `mss-core`, the writers of `mss-io` and the scene pipeline of `mss-scene`,
//! with numpy arrays in and out. The Python-facing documentation is in the
//! docstrings and in `python/hexmss/_hexmss.pyi`; this crate is built by
//! maturin (`pip install ./python`) and tested from Python (`python/tests`).
//!
//! Conventions the bindings keep:
//! - arrays out are float64 `(n, 3)` positions and uint32 index arrays,
//!   C-contiguous, built once from the Rust data (no second copy); the ones
//!   a value owns (a lattice's nodes) are cached and read-only;
//! - arrays in may be anything numpy converts (lists, other dtypes);
//! - every long call releases the GIL, runs on the pool that
//!   `set_threads` chose, and reports to an optional `progress(stage, done,
//!   total)` callback; Ctrl-C stops a run cleanly (its frames stay written);
//! - errors are the exceptions of `hexmss.errors`, with the one-line
//!   message the `mss` CLI prints.

use pyo3::prelude::*;

mod convert;
mod errors;
mod geometry;
mod image;
mod io;
mod physics;
mod plane;
mod progress;
mod scene;
mod threads;
mod view;

/// The extension module.
#[pymodule]
fn _hexmss(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add_function(wrap_pyfunction!(threads::set_threads, m)?)?;
    m.add_function(wrap_pyfunction!(threads::get_threads, m)?)?;
    geometry::register(m)?;
    image::register(m)?;
    physics::register(m)?;
    plane::register(m)?;
    scene::register(m)?;
    io::register(m)?;
    view::register(m)?;
    Ok(())
}
