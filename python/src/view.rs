//! `view`: the live browser viewer (`mss view`) from Python, serving from
//! the interpreter's process until `stop_views()` or the process ends.

use std::path::PathBuf;
use std::sync::Mutex;

use mss_view::{Source, ViewError, ViewOptions, Viewer};
use pyo3::prelude::*;

use crate::errors::{Kind, raise};
use crate::scene::PyScene;

/// The viewers started from Python: they serve until stopped.
static VIEWERS: Mutex<Vec<Viewer>> = Mutex::new(Vec::new());

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(view, m)?)?;
    m.add_function(wrap_pyfunction!(stop_views, m)?)?;
    Ok(())
}

fn view_error(e: ViewError) -> PyErr {
    let kind = match e {
        ViewError::NoSuchPath(_) | ViewError::NotARun { .. } | ViewError::FrameRate(_) => {
            Kind::Scene
        }
        _ => Kind::Output,
    };
    raise(kind, e.to_string())
}

/// view(scene_or_path=None, port=0, open_browser=True, host="127.0.0.1", paused=False)
///
/// Starts the live viewer of ``mss view`` and returns its address
/// (``http://127.0.0.1:PORT/?token=...``): a ``Scene`` (or None, the
/// bundled default scene, or the path of a scene file) runs live in the
/// browser, where it can be dragged and poked; the path of a folder written
/// by ``run`` replays its frames. ``port=0`` takes any free port;
/// ``open_browser`` opens the address with Python's ``webbrowser``. The
/// viewer serves from a background thread until ``stop_views()`` or the
/// end of the process; it binds to 127.0.0.1 unless ``host`` says otherwise,
/// and every request needs the token of the address.
#[pyfunction]
#[pyo3(signature = (scene_or_path = None, port = 0, open_browser = true, host = "127.0.0.1", paused = false))]
fn view(
    py: Python<'_>,
    scene_or_path: Option<&Bound<'_, PyAny>>,
    port: u16,
    open_browser: bool,
    host: &str,
    paused: bool,
) -> PyResult<String> {
    let source = match scene_or_path {
        None => Source::Bundled,
        Some(obj) => {
            if let Ok(scene) = obj.extract::<PyRef<'_, PyScene>>() {
                Source::Input(Box::new(scene.input.clone()))
            } else if let Ok(path) = obj.extract::<PathBuf>() {
                Source::for_path(Some(&path)).map_err(view_error)?
            } else {
                return Err(raise(
                    Kind::Scene,
                    "view(scene_or_path): give a Scene, the path of a scene file or of a run's folder, or None",
                ));
            }
        }
    };
    let host = host.parse().map_err(|_| {
        raise(
            Kind::Scene,
            format!("view(host={host:?}): give an IP address such as \"127.0.0.1\""),
        )
    })?;
    let options = ViewOptions {
        host,
        port,
        paused,
        ..ViewOptions::default()
    };
    let viewer = py
        .detach(|| Viewer::start(source, options))
        .map_err(view_error)?;
    let url = viewer.url().to_owned();
    VIEWERS
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .push(viewer);
    if open_browser {
        py.import("webbrowser")?.call_method1("open", (&url,))?;
    }
    Ok(url)
}

/// stop_views()
///
/// Stops every viewer started by ``view`` and returns how many there were.
#[pyfunction]
fn stop_views(py: Python<'_>) -> usize {
    let viewers: Vec<Viewer> =
        std::mem::take(&mut *VIEWERS.lock().unwrap_or_else(|e| e.into_inner()));
    let n = viewers.len();
    py.detach(move || viewers.into_iter().for_each(Viewer::stop));
    n
}
