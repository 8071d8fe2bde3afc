//! Scenes and jobs: `Scene`, `Job`, `prepare`, `run`.

use std::path::PathBuf;
use std::sync::Arc;

use mss_scene::limits::Limits;
use mss_scene::{Job, Registry, SceneInput};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::convert::{cached_object, to_json};
use crate::errors::{Kind, job as job_error, raise};
use crate::geometry::{PyLattice, PyMesh};
use crate::physics::{PyModel, PyProblem, PySimulation};
use crate::progress::Reporter;
use crate::threads::detached;

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyScene>()?;
    m.add_class::<PyJob>()?;
    m.add_function(wrap_pyfunction!(prepare, m)?)?;
    m.add_function(wrap_pyfunction!(run, m)?)?;
    Ok(())
}

/// A scene: the mesh, material, model, constraints, loads, solver and
/// output of a job (the TOML schema of `mss run`, see docs/scenes.md).
#[pyclass(name = "Scene", module = "hexmss", frozen)]
#[derive(Clone)]
pub struct PyScene {
    pub input: SceneInput,
}

#[pymethods]
impl PyScene {
    /// Scene.from_file(path)
    ///
    /// Reads and checks a scene file; relative paths in it are relative to
    /// its folder.
    #[staticmethod]
    fn from_file(path: PathBuf) -> PyResult<Self> {
        SceneInput::load(Some(&path))
            .map(|input| Self { input })
            .map_err(job_error)
    }

    /// Scene.from_toml(text, name="<toml>")
    ///
    /// A scene from TOML text; relative paths are relative to the working
    /// directory.
    #[staticmethod]
    #[pyo3(signature = (text, name = "<toml>"))]
    fn from_toml(text: &str, name: &str) -> PyResult<Self> {
        SceneInput::from_toml(text, name)
            .map(|input| Self { input })
            .map_err(job_error)
    }

    /// Scene.from_dict(d, name="<dict>")
    ///
    /// A scene from a dict with the tables of a scene file (`{"mesh":
    /// {"path": ...}, "material": {...}, "fixed": [{...}], ...}`); `None`
    /// values are left out.
    #[staticmethod]
    #[pyo3(signature = (d, name = "<dict>"))]
    fn from_dict(d: &Bound<'_, PyDict>, name: &str) -> PyResult<Self> {
        let json = to_json("scene", d.as_any())?;
        let value: toml::Value =
            serde_json::from_value(json).map_err(|e| raise(Kind::Scene, format!("{name}: {e}")))?;
        let text =
            toml::to_string(&value).map_err(|e| raise(Kind::Scene, format!("{name}: {e}")))?;
        Self::from_toml(&text, name)
    }

    /// Scene.default()
    ///
    /// The bundled default scene (the critter sagging under gravity), what
    /// `mss run` runs without arguments.
    #[staticmethod]
    fn default() -> Self {
        Self {
            input: SceneInput::bundled_default(),
        }
    }

    /// The scene's name in messages (its file, or the name given).
    #[getter]
    fn name(&self) -> String {
        self.input.name()
    }

    /// The simulated duration (s).
    #[getter]
    fn duration(&self) -> f64 {
        self.input.scene.solver.duration
    }

    /// with_duration(seconds)
    ///
    /// A copy simulating `seconds` instead (as `mss run --duration`).
    fn with_duration(&self, seconds: f64) -> PyResult<Self> {
        if !(seconds.is_finite() && seconds > 0.0) {
            return Err(raise(
                Kind::Scene,
                format!("duration {seconds}: give a positive number of seconds"),
            ));
        }
        let mut input = self.input.clone();
        input.scene.solver.duration = seconds;
        Ok(Self { input })
    }

    /// The output folder of the scene (`[output] folder`).
    #[getter]
    fn output_folder(&self) -> PathBuf {
        self.input.scene.output.folder.clone()
    }

    fn __repr__(&self) -> String {
        format!("Scene({:?})", self.input.name())
    }
}

/// A scene, or the path of a scene file.
fn scene_of(scene: &Bound<'_, PyAny>) -> PyResult<SceneInput> {
    if let Ok(s) = scene.cast::<PyScene>() {
        return Ok(s.get().input.clone());
    }
    if let Ok(d) = scene.cast::<PyDict>() {
        return PyScene::from_dict(d, "<dict>").map(|s| s.input);
    }
    if let Ok(p) = scene.extract::<PathBuf>() {
        return PyScene::from_file(p).map(|s| s.input);
    }
    Err(pyo3::exceptions::PyTypeError::new_err(
        "scene: give a Scene, a dict, or the path of a scene file",
    ))
}

fn limits_of(max_memory: Option<&Bound<'_, PyAny>>) -> PyResult<Limits> {
    let mut limits = Limits::default();
    if let Some(m) = max_memory {
        limits.memory_bytes = match m.extract::<u64>() {
            Ok(b) => b,
            Err(_) => {
                let text: String = m.extract().map_err(|_| {
                    pyo3::exceptions::PyTypeError::new_err(
                        "max_memory: give bytes (an int) or a size like \"8GiB\"",
                    )
                })?;
                mss_scene::limits::parse_size(&text)
                    .map_err(|e| raise(Kind::Scene, format!("max_memory: {e}")))?
            }
        };
    }
    Ok(limits)
}

/// A prepared scene: its mesh voxelized, model and problem built.
#[pyclass(name = "Job", module = "hexmss", frozen)]
pub struct PyJob {
    job: Arc<Job>,
    /// What the getters hand out, made once (each is a copy of the job's).
    mesh: std::sync::OnceLock<Py<PyMesh>>,
    lattice: std::sync::OnceLock<Py<PyLattice>>,
    model: std::sync::OnceLock<Py<PyModel>>,
}

/// prepare(scene, *, max_memory=None, progress=None)
/// --
///
/// Loads the mesh, voxelizes it and builds the model, problem and time plan
/// of a scene (a `Scene`, a dict or a path), refusing jobs estimated above
/// `max_memory` (bytes or "8GiB"; default 3/4 of the machine's memory).
#[pyfunction]
#[pyo3(signature = (scene, *, max_memory = None, progress = None))]
fn prepare(
    py: Python<'_>,
    scene: &Bound<'_, PyAny>,
    max_memory: Option<&Bound<'_, PyAny>>,
    progress: Option<Py<PyAny>>,
) -> PyResult<PyJob> {
    let input = scene_of(scene)?;
    let limits = limits_of(max_memory)?;
    let reporter = Reporter::new(progress);
    let job = detached(py, || {
        Job::prepare_with_limits(input, Registry::default(), limits, &|p| {
            reporter.progress(p)
        })
    });
    reporter.finish()?;
    Ok(PyJob {
        job: Arc::new(job.map_err(job_error)?),
        mesh: std::sync::OnceLock::new(),
        lattice: std::sync::OnceLock::new(),
        model: std::sync::OnceLock::new(),
    })
}

/// The summary of a run as a dict (the fields of `summary.json`).
fn summary_dict<'py>(
    py: Python<'py>,
    summary: &mss_scene::RunSummary,
) -> PyResult<Bound<'py, PyAny>> {
    let text =
        serde_json::to_string(summary).map_err(|e| raise(Kind::Output, format!("summary: {e}")))?;
    py.import("json")?.call_method1("loads", (text,))
}

fn run_job<'py>(
    py: Python<'py>,
    job: &Arc<Job>,
    out: Option<PathBuf>,
    progress: Option<Py<PyAny>>,
    resume: bool,
) -> PyResult<Bound<'py, PyAny>> {
    let out_dir = mss_scene::build::output_folder(&job.input.scene, out.as_deref());
    let reporter = Reporter::new(progress);
    let j = Arc::clone(job);
    let result = detached(py, || {
        let report = |p| reporter.progress(p);
        let summary = if resume {
            j.resume(&out_dir, &report, &reporter.cancel)?
        } else {
            j.run(&out_dir, &report, &reporter.cancel)?
        };
        mss_scene::write_summary(&out_dir, &summary)?;
        Ok::<_, mss_scene::JobError>(summary)
    });
    let summary = result.map_err(job_error)?;
    // Ctrl-C or a failing callback: the frames so far and summary.json
    // ("interrupted": true) are written; the exception goes on.
    reporter.finish()?;
    summary_dict(py, &summary)
}

#[pymethods]
impl PyJob {
    /// The mesh (placed as the scene says; the first body's in a scene of
    /// `[[bodies]]`).
    #[getter]
    fn mesh(&self, py: Python<'_>) -> PyResult<Py<PyMesh>> {
        cached_object(py, &self.mesh, || {
            PyMesh::wrap(self.job.mesh().clone(), self.job.mesh_name().to_owned())
        })
    }

    /// The lattice (the first body's in a scene of `[[bodies]]`).
    #[getter]
    fn lattice(&self, py: Python<'_>) -> PyResult<Py<PyLattice>> {
        cached_object(py, &self.lattice, || {
            PyLattice::wrap(self.job.lattice().clone())
        })
    }

    /// The names of the bodies, in the order of the model's nodes.
    #[getter]
    fn body_names(&self) -> Vec<String> {
        self.job.bodies.iter().map(|b| b.name.clone()).collect()
    }

    /// The first and one-past-last node index of each body, in the order
    /// of `body_names`: `positions[start:end]` are that body's.
    #[getter]
    fn body_nodes(&self) -> Vec<(usize, usize)> {
        self.job
            .problem
            .model()
            .bodies()
            .iter()
            .map(|b| (b.nodes.start, b.nodes.end))
            .collect()
    }

    /// The model.
    #[getter]
    fn model(&self, py: Python<'_>) -> PyResult<Py<PyModel>> {
        cached_object(py, &self.model, || PyModel {
            model: Arc::new(self.job.problem.model().clone()),
        })
    }

    /// The problem (constraints, loads, damping, obstacles).
    #[getter]
    fn problem(&self) -> PyProblem {
        PyProblem::of_job(Arc::clone(&self.job))
    }

    /// The time step of the run (s).
    #[getter]
    fn dt(&self) -> f64 {
        self.job.plan.dt
    }

    /// The number of steps of the run (1 for a static solve).
    #[getter]
    fn steps(&self) -> u64 {
        self.job.plan.steps
    }

    /// Whether the scene asks for a static solve.
    #[getter]
    fn is_static(&self) -> bool {
        self.job.plan.is_static
    }

    /// The stable explicit step with the scene's safety factor (s).
    #[getter]
    fn stable_time_step(&self) -> f64 {
        self.job.plan.stable_dt
    }

    /// run(out=None, *, progress=None, resume=False)
    ///
    /// Runs the job, writing its frames and summary.json into `out` (default
    /// the scene's `[output] folder`); returns the summary as a dict. With
    /// `resume`, continues the interrupted run in `out` from its checkpoint.
    #[pyo3(signature = (out = None, *, progress = None, resume = false))]
    fn run<'py>(
        &self,
        py: Python<'py>,
        out: Option<PathBuf>,
        progress: Option<Py<PyAny>>,
        resume: bool,
    ) -> PyResult<Bound<'py, PyAny>> {
        run_job(py, &self.job, out, progress, resume)
    }

    /// simulation()
    ///
    /// An interactive `Simulation` of the job's problem (a fresh copy), whose
    /// `surface_positions()` is the scene's mesh; settled first when the
    /// scene says `[solver] start = "settled"`.
    fn simulation(&self, py: Python<'_>) -> PyResult<PySimulation> {
        let job = Arc::clone(&self.job);
        let (problem, surface) = detached(py, || {
            let surface = job.embedding();
            (job.rebuild_problem(), surface)
        });
        let sim = PySimulation::build(problem.map_err(job_error)?, Some(Arc::new(surface)))?;
        let solver_section = &self.job.input.scene.solver;
        if solver_section.start == mss_scene::scene::Start::Settled {
            let opts = solver_section.settle_options();
            detached(py, || sim.settle_with(&opts)).map_err(crate::errors::solver)?;
        }
        Ok(sim)
    }

    fn __repr__(&self) -> String {
        format!("Job({:?})", self.job)
    }
}

/// run(scene, out=None, *, progress=None, max_memory=None, resume=False)
/// --
///
/// Prepares and runs a scene (a `Scene`, a dict or a path) as `mss run`
/// does, writing its frames and summary.json into `out` (default the
/// scene's `[output] folder`); returns the summary as a dict.
/// `progress(stage, done, total)` is called during voxelizing and stepping.
/// Ctrl-C stops the run after the step under way, with the state reached
/// and a checkpoint written, and raises KeyboardInterrupt; `resume=True`
/// then continues it in the same `out`, ending bitwise as an uninterrupted
/// run (as `mss run --resume`).
#[pyfunction]
#[pyo3(signature = (scene, out = None, *, progress = None, max_memory = None, resume = false))]
fn run<'py>(
    py: Python<'py>,
    scene: &Bound<'py, PyAny>,
    out: Option<PathBuf>,
    progress: Option<Py<PyAny>>,
    max_memory: Option<&Bound<'py, PyAny>>,
    resume: bool,
) -> PyResult<Bound<'py, PyAny>> {
    let input = scene_of(scene)?;
    if input.scene.is_plane() {
        if resume {
            return Err(raise(
                Kind::Scene,
                "resume=True: a 2D run has no checkpoints; run it again",
            ));
        }
        return run_plane(py, input, out);
    }
    let cb = progress.as_ref().map(|p| p.clone_ref(py));
    let job = prepare(py, scene, max_memory, cb)?;
    run_job(py, &job.job, out, progress, resume)
}

/// `run` of a 2D scene (`[model] dimension = 2`).
fn run_plane<'py>(
    py: Python<'py>,
    input: mss_scene::SceneInput,
    out: Option<PathBuf>,
) -> PyResult<Bound<'py, PyAny>> {
    let out_dir = mss_scene::build::output_folder(&input.scene, out.as_deref());
    let job = mss_scene::plane_job::PlaneJob::prepare(input).map_err(job_error)?;
    let cancel = mss_scene::Cancel::new();
    let summary = detached(py, || job.run(&out_dir, &cancel)).map_err(job_error)?;
    let text = serde_json::to_string(&summary)
        .map_err(|e| raise(Kind::Output, format!("summary: {e}")))?;
    py.import("json")?.call_method1("loads", (text,))
}
