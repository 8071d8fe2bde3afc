//! The worker pool every long call runs on.
//!
//! The library's parallel passes use rayon. A process has one global pool
//! whose size is fixed at first use, so the bindings keep their own pool,
//! replaced by `set_threads`, and run each call inside it: a Python program
//! can compare thread counts in one process (the results do not change).

use std::sync::{Arc, Mutex};

use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

/// The pool chosen by `set_threads` (None: rayon's global pool, one thread
/// per core).
static POOL: Mutex<Option<Arc<rayon::ThreadPool>>> = Mutex::new(None);

/// Stack of the worker threads: deep scenes are parsed on them (as in the CLI).
const WORKER_STACK_BYTES: usize = 64 << 20;

/// Most threads allowed per core: beyond that they only slow a run down.
const MAX_THREADS_PER_CORE: usize = 8;

fn cores() -> usize {
    std::thread::available_parallelism().map_or(1, usize::from)
}

/// set_threads(n=None)
/// --
///
/// Sets the number of worker threads of every later call (`None`: one per
/// core). Results do not depend on it.
#[pyfunction]
#[pyo3(signature = (n=None))]
pub fn set_threads(n: Option<usize>) -> PyResult<()> {
    let pool = match n {
        None => None,
        Some(0) => {
            return Err(PyValueError::new_err(
                "set_threads(0): give at least 1 thread (or None for one per core)",
            ));
        }
        Some(n) if n > MAX_THREADS_PER_CORE * cores() => {
            return Err(PyValueError::new_err(format!(
                "set_threads({n}): this machine has {} cores; more than {} threads only slow the run down",
                cores(),
                MAX_THREADS_PER_CORE * cores()
            )));
        }
        Some(n) => Some(Arc::new(
            rayon::ThreadPoolBuilder::new()
                .num_threads(n)
                .stack_size(WORKER_STACK_BYTES)
                .build()
                .map_err(|e| {
                    PyValueError::new_err(format!("cannot start {n} worker threads: {e}"))
                })?,
        )),
    };
    *POOL.lock().unwrap_or_else(|e| e.into_inner()) = pool;
    Ok(())
}

/// get_threads()
/// --
///
/// The number of worker threads calls run on.
#[pyfunction]
pub fn get_threads() -> usize {
    match current() {
        Some(p) => p.current_num_threads(),
        None => rayon::current_num_threads(),
    }
}

fn current() -> Option<Arc<rayon::ThreadPool>> {
    POOL.lock().unwrap_or_else(|e| e.into_inner()).clone()
}

/// Runs `f` without the GIL, on the chosen pool.
pub fn detached<T: Send>(py: Python<'_>, f: impl FnOnce() -> T + Send) -> T {
    py.detach(|| match current() {
        Some(pool) => pool.install(f),
        None => f(),
    })
}
