//! The progress callback shared by every long call, and Ctrl-C: a call that
//! runs without the GIL reports through [`Reporter`], which stops it cleanly
//! when Python raises.

use std::sync::Mutex;
use std::time::{Duration, Instant};

use mss_scene::{Cancel, Progress};
use pyo3::prelude::*;

/// How often, at most, a running call takes the GIL to report progress and
/// to look for Ctrl-C.
const REPORT_INTERVAL: Duration = Duration::from_millis(50);

/// Reports progress to an optional Python callback from a call that runs
/// without the GIL, and turns Ctrl-C (or an exception in the callback) into
/// a clean stop through [`Cancel`].
pub struct Reporter {
    callback: Option<Py<PyAny>>,
    /// The stage and time of the last event passed on.
    last: Mutex<Option<(String, Instant)>>,
    error: Mutex<Option<PyErr>>,
    pub cancel: Cancel,
}

impl Reporter {
    pub fn new(callback: Option<Py<PyAny>>) -> Self {
        Self {
            callback,
            last: Mutex::new(None),
            error: Mutex::new(None),
            cancel: Cancel::new(),
        }
    }

    /// Reports `done` of `total` in `stage` (rate-limited, except the end of
    /// a stage).
    pub fn report(&self, stage: &str, done: u64, total: u64) {
        let now = Instant::now();
        {
            let mut last = self.last.lock().unwrap_or_else(|e| e.into_inner());
            // The first event of a stage and its end are always reported.
            let new_stage = last.as_ref().is_none_or(|(s, _)| *s != stage);
            let due = new_stage
                || last
                    .as_ref()
                    .is_some_and(|(_, t)| now - *t >= REPORT_INTERVAL)
                || done == total;
            if !due {
                return;
            }
            *last = Some((stage.to_owned(), now));
        }
        if self.cancel.is_cancelled() {
            return;
        }
        let outcome = Python::attach(|py| -> PyResult<()> {
            py.check_signals()?;
            if let Some(cb) = &self.callback {
                cb.call1(py, (stage, done, total))?;
            }
            Ok(())
        });
        if let Err(e) = outcome {
            *self.error.lock().unwrap_or_else(|e| e.into_inner()) = Some(e);
            self.cancel.cancel();
        }
    }

    /// The library's progress event, reported.
    pub fn progress(&self, p: Progress) {
        match p {
            Progress::Voxelizing { done, total } => self.report("voxelizing", done, total),
            Progress::Solving => self.report("solving", 0, 0),
            Progress::Stepping { done, total } => self.report("stepping", done, total),
            Progress::StageDone => {}
        }
    }

    /// The exception that stopped the call (KeyboardInterrupt, or the
    /// callback's), if any.
    pub fn finish(&self) -> PyResult<()> {
        match self.error.lock().unwrap_or_else(|e| e.into_inner()).take() {
            Some(e) => Err(e),
            None => Ok(()),
        }
    }
}
