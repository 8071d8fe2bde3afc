//! Materials, models, problems, states and the solvers: `Material`, `Model`,
//! `Problem`, `State`, `solve_static`, `Integrator`, `Simulation`.

use std::sync::{Arc, Mutex};

use mss_scene::hexmesh::load::Loaders;
use mss_scene::mss_core::constraints::{ConstraintSpec, NodeSelector};
use mss_scene::mss_core::contact::ContactPoints;
use mss_scene::mss_core::loads::Damping;
use mss_scene::mss_core::simulation::Simulation;
use mss_scene::mss_core::solver::{
    Integrator, IntegratorSettings, Integrators, LinearSolverKind, Problem, SettleOptions,
    Stability, State, StaticOptions, solve_static,
};
use mss_scene::mss_core::{LoadSpec, Material, Model, Parameterizations, Precision, Vec3};
use mss_scene::obstacles::ObstacleSpec;
use mss_scene::scene::{LoadsSection, MotionSpec};
use mss_scene::stages;
use numpy::{PyArray2, PyArrayMethods, PyReadwriteArray2};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::convert::{from_py, node_list, vec3_array, vec3_in};
use crate::errors::{Kind, from_error, raise, solver};
use crate::geometry::{PyEmbedding, PyLattice};
use crate::threads::detached;

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyMaterial>()?;
    m.add_class::<PyModel>()?;
    m.add_class::<PyProblem>()?;
    m.add_class::<PyState>()?;
    m.add_class::<PyIntegrator>()?;
    m.add_class::<PySimulation>()?;
    m.add_function(wrap_pyfunction!(py_solve_static, m)?)?;
    m.add_function(wrap_pyfunction!(parameterizations, m)?)?;
    m.add_function(wrap_pyfunction!(integrators, m)?)?;
    Ok(())
}

/// An isotropic linear elastic material.
///
/// Material(young, poisson, density)
///
/// Young's modulus E (Pa), Poisson's ratio nu (-1 < nu < 0.5) and
/// density (kg/m^3).
#[pyclass(name = "Material", module = "hexmss", frozen)]
#[derive(Clone, Copy)]
pub struct PyMaterial {
    pub material: Material,
}

#[pymethods]
impl PyMaterial {
    #[new]
    fn new(young: f64, poisson: f64, density: f64) -> PyResult<Self> {
        Material::new(young, poisson, density)
            .map(|material| Self { material })
            .map_err(|e| from_error(Kind::Model, &e))
    }
    /// Young's modulus E (Pa).
    #[getter]
    fn young(&self) -> f64 {
        self.material.young
    }
    /// Poisson's ratio nu.
    #[getter]
    fn poisson(&self) -> f64 {
        self.material.poisson
    }
    /// Density (kg/m^3).
    #[getter]
    fn density(&self) -> f64 {
        self.material.density
    }
    /// Shear modulus mu = E / (2 (1 + nu)) (Pa).
    #[getter]
    fn shear_modulus(&self) -> f64 {
        self.material.shear_modulus()
    }
    /// Lame's first parameter lambda (Pa).
    #[getter]
    fn lame_lambda(&self) -> f64 {
        self.material.lambda()
    }
    /// Bulk modulus K (Pa).
    #[getter]
    fn bulk_modulus(&self) -> f64 {
        self.material.bulk_modulus()
    }
    fn __repr__(&self) -> String {
        format!(
            "Material(young={}, poisson={}, density={})",
            self.material.young, self.material.poisson, self.material.density
        )
    }
}

/// parameterizations()
/// --
///
/// The parameterization names a `Model` accepts (each also with `+hg`).
#[pyfunction]
fn parameterizations() -> Vec<String> {
    Parameterizations::default().names()
}

/// integrators()
/// --
///
/// The integrator names an `Integrator` accepts.
#[pyfunction]
fn integrators() -> Vec<String> {
    Integrators::default().names()
}

/// A lattice turned into a mass-spring model (masses, springs, the chosen
/// parameterization's coefficients).
///
/// Model(lattice, material, parameterization=None, hourglass=None)
///
/// `parameterization` is one of `parameterizations()`, optionally with
/// `+hg`, read as a scene's `[model]` table: `hourglass` sets the
/// factor of hourglass control (and adds it to any name); a `+hg` name
/// without it gets the library's default factor (0.05). Without a
/// parameterization: the bundled default scene's model,
/// `"volumetric-barrier+hg"` with hourglass 1.0 (unless given).
#[pyclass(name = "Model", module = "hexmss", frozen)]
pub struct PyModel {
    pub model: Arc<Model>,
}

impl PyModel {
    /// A per-cell figure of the model at node positions `x`, computed
    /// without the GIL, as a numpy array.
    fn per_cell<'py>(
        &self,
        py: Python<'py>,
        x: &Bound<'py, PyAny>,
        figure: fn(&Model, &[Vec3]) -> Vec<f64>,
    ) -> PyResult<Bound<'py, numpy::PyArray1<f64>>> {
        let x = vec3_in("x", x, self.model.num_nodes())?;
        let m = Arc::clone(&self.model);
        let values = detached(py, || figure(&m, &x));
        Ok(numpy::PyArray1::from_vec(py, values))
    }
}

#[pymethods]
impl PyModel {
    #[new]
    #[pyo3(signature = (lattice, material, parameterization = None, hourglass = None))]
    fn new(
        py: Python<'_>,
        lattice: &PyLattice,
        material: &PyMaterial,
        parameterization: Option<String>,
        hourglass: Option<f64>,
    ) -> PyResult<Self> {
        // A scene's [model] table means the same, defaults included.
        let section = mss_scene::scene::ModelSection::new(parameterization, hourglass);
        let param = Parameterizations::default()
            .build(&section.parameterization, section.hourglass)
            .map_err(|e| from_error(Kind::Model, &e))?;
        param
            .validate(&material.material)
            .map_err(|e| raise(Kind::Model, e.to_string()))?;
        let l = Arc::clone(&lattice.lattice);
        let mat = material.material;
        let model = detached(py, || Model::new(&l, mat, &*param))
            .map_err(|e| from_error(Kind::Model, &e))?;
        Ok(Self {
            model: Arc::new(model),
        })
    }

    /// Always 3 (a PlaneModel's is 2).
    #[getter]
    fn dimension(&self) -> u32 {
        3
    }
    /// Node masses, (N,) float64 (kg).
    #[getter]
    fn masses<'py>(&self, py: Python<'py>) -> Bound<'py, numpy::PyArray1<f64>> {
        numpy::PyArray1::from_slice(py, self.model.masses())
    }
    /// Rest positions of the nodes, (N, 3) (m).
    #[getter]
    fn rest_positions<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        vec3_array(py, self.model.rest_positions())
    }
    /// Number of nodes.
    #[getter]
    fn num_nodes(&self) -> usize {
        self.model.num_nodes()
    }
    /// Number of cells.
    #[getter]
    fn num_cells(&self) -> usize {
        self.model.num_cells()
    }
    /// Number of springs.
    #[getter]
    fn num_springs(&self) -> usize {
        self.model.num_springs()
    }
    /// Total mass (kg).
    #[getter]
    fn total_mass(&self) -> f64 {
        self.model.total_mass()
    }
    /// Cell edge (m).
    #[getter]
    fn h(&self) -> f64 {
        self.model.h()
    }
    /// The parameterization's name.
    #[getter]
    fn parameterization(&self) -> String {
        self.model.parameterization_name().to_owned()
    }
    /// Stable explicit time step of the undamped model at rest (s).
    #[getter]
    fn stable_time_step(&self) -> f64 {
        self.model.stable_time_step()
    }

    /// internal_forces(x, out=None)
    ///
    /// Internal forces at node positions x (N, 3) (N). With `out` (an
    /// (N, 3) float64 C-contiguous array) they are written there and `out`
    /// is returned: no allocation per call.
    #[pyo3(signature = (x, out = None))]
    fn internal_forces<'py>(
        &self,
        py: Python<'py>,
        x: &Bound<'py, PyAny>,
        out: Option<Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let n = self.model.num_nodes();
        let x = vec3_in("x", x, n)?;
        let m = Arc::clone(&self.model);
        let f = detached(py, || {
            let mut f = vec![Vec3::zeros(); n];
            m.internal_forces(&x, &mut f);
            f
        });
        match out {
            Some(out) => {
                let out = out_array(out)?;
                write_rows(&mut out.readwrite(), &f, "out")?;
                Ok(out)
            }
            None => Ok(vec3_array(py, &f)),
        }
    }

    /// energy(x)
    ///
    /// Elastic energy of the springs and the volumetric term at node
    /// positions x (J); the paper's correction forces are not conservative
    /// and have none.
    fn energy(&self, py: Python<'_>, x: &Bound<'_, PyAny>) -> PyResult<f64> {
        let x = vec3_in("x", x, self.model.num_nodes())?;
        let m = Arc::clone(&self.model);
        Ok(detached(py, || m.energy(&x)))
    }

    /// inverted_cells(x)
    ///
    /// Indices of the cells turned inside out at node positions x.
    fn inverted_cells(&self, py: Python<'_>, x: &Bound<'_, PyAny>) -> PyResult<Vec<u32>> {
        let x = vec3_in("x", x, self.model.num_nodes())?;
        let m = Arc::clone(&self.model);
        Ok(detached(py, || m.inverted_cells(&x)))
    }

    /// folded_cells(x)
    ///
    /// Indices of the cells folded at a corner at node positions x: a
    /// corner Jacobian <= 0 (the trilinear map turned inside out near that
    /// corner) while the centre may look healthy.
    fn folded_cells(&self, py: Python<'_>, x: &Bound<'_, PyAny>) -> PyResult<Vec<u32>> {
        let x = vec3_in("x", x, self.model.num_nodes())?;
        let m = Arc::clone(&self.model);
        Ok(detached(py, || m.folded_cells(&x)))
    }

    /// corner_jacobians(x)
    ///
    /// Per cell, the smallest of its 8 corner Jacobians at node positions x
    /// (1 at rest, <= 0 where the cell is folded at that corner).
    fn corner_jacobians<'py>(
        &self,
        py: Python<'py>,
        x: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, numpy::PyArray1<f64>>> {
        self.per_cell(py, x, Model::corner_jacobians)
    }

    /// affine_deviation(x)
    ///
    /// Per cell, how far its 8 nodes are from the best affine map of the
    /// rest cell, as a fraction of h (the hourglass zigzag measure).
    fn affine_deviation<'py>(
        &self,
        py: Python<'py>,
        x: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, numpy::PyArray1<f64>>> {
        self.per_cell(py, x, Model::affine_deviation)
    }

    fn __repr__(&self) -> String {
        format!(
            "Model({:?}, {} cells, {} nodes, {:.4} kg)",
            self.model.parameterization_name(),
            self.model.num_cells(),
            self.model.num_nodes(),
            self.model.total_mass()
        )
    }
}

/// An output argument as a float64 2-d array.
fn out_array(out: Bound<'_, PyAny>) -> PyResult<Bound<'_, PyArray2<f64>>> {
    out.cast_into::<PyArray2<f64>>().map_err(|e| {
        let given = e.into_inner();
        // A numpy array of another dtype or dimension is named by those,
        // anything else by its type.
        let what = match (given.getattr("dtype"), given.getattr("shape")) {
            (Ok(dtype), Ok(shape)) => format!("an array of dtype {dtype} and shape {shape}"),
            _ => format!("a {}", given.get_type()),
        };
        pyo3::exceptions::PyTypeError::new_err(format!(
            "out: give a float64 numpy array of shape (n, 3), not {what}"
        ))
    })
}

/// Writes vectors into a C-contiguous (n, 3) float64 array.
fn write_rows(out: &mut PyReadwriteArray2<'_, f64>, v: &[Vec3], what: &str) -> PyResult<()> {
    let shape = out.as_array().shape().to_vec();
    if shape != [v.len(), 3] {
        return Err(PyValueError::new_err(format!(
            "{what}: expected shape ({}, 3), got {shape:?}",
            v.len()
        )));
    }
    let slice = out
        .as_slice_mut()
        .map_err(|_| PyValueError::new_err(format!("{what}: give a C-contiguous float64 array")))?;
    for (row, p) in slice.chunks_exact_mut(3).zip(v) {
        row.copy_from_slice(&[p.x, p.y, p.z]);
    }
    Ok(())
}

/// How a problem is (re)built: a `Simulation` owns its problem, so it gets
/// a fresh one built the same way.
pub enum Recipe {
    /// From keyword descriptions (scene syntax).
    Specs {
        model: Arc<Model>,
        constraints: Vec<ConstraintSpec>,
        loads: Vec<LoadSpec>,
        custom_loads: Vec<mss_scene::kind_table::KindTable>,
        damping: Damping,
        obstacles: Vec<ObstacleSpec>,
        points: ContactPoints,
        surface: Option<Arc<mss_scene::hexmesh::Embedding>>,
    },
    /// The problem of a prepared scene.
    Job(Arc<mss_scene::Job>),
}

impl Recipe {
    pub fn build(&self) -> PyResult<Problem> {
        match self {
            Recipe::Specs {
                model,
                constraints,
                loads,
                custom_loads,
                damping,
                obstacles,
                points,
                surface,
            } => {
                let loaders = Loaders::default();
                let origin = mss_scene::scene::SceneOrigin::Text("Problem".into());
                let mesh_of = |path: &str| {
                    let source = mss_scene::Scene::source_of(path, &origin);
                    stages::load_placed(&source, &Default::default(), &loaders)
                        .map(|placed| placed.mesh)
                        .map_err(|e| e.to_string())
                };
                let registry = mss_scene::Registry::default();
                let specs = stages::ProblemSpecs {
                    constraints,
                    loads,
                    custom_loads,
                    load_kinds: &registry.loads,
                    damping: *damping,
                    obstacles,
                    points: *points,
                    shapes: &registry.shapes,
                };
                stages::problem(
                    (**model).clone(),
                    &specs,
                    &mesh_of,
                    surface.as_deref(),
                    Vec::new(),
                )
                .map_err(|e| match e {
                    stages::ProblemStageError::Obstacle { index, source } => {
                        raise(Kind::Scene, format!("obstacles[{index}]: {source}"))
                    }
                    stages::ProblemStageError::CustomLoad { index, source } => {
                        raise(Kind::Scene, format!("custom_loads[{index}]: {source}"))
                    }
                    stages::ProblemStageError::Problem(p) => from_error(Kind::Model, &p),
                })
            }
            Recipe::Job(job) => job.rebuild_problem().map_err(crate::errors::job),
        }
    }
}

/// A model with boundary conditions, loads, damping and obstacles.
///
/// Problem(model, *, fixed=(), gravity=None, forces=(), tractions=(), drags=(), custom_loads=(), motions=(), motion_duration=1.0, damping=0.0, stiffness_damping=0.0, obstacles=(), contact_points="nodes", surface=None)
///
/// The keys follow a scene's tables: `fixed` is a list of `[[fixed]]`
/// tables (`{"kind": "lowest_layer"}`, `{"kind": "face", "face": "x-"}`,
/// ...), `gravity` (m/s^2), `forces`, `tractions`, `drags` and
/// `custom_loads` (loads by `kind`) are the lists of `[loads]`, `motions` the `[[motions]]` tables (their default
/// end is `motion_duration`, s), `damping` the mass damping alpha (1/s)
/// and `stiffness_damping` beta (s), `obstacles` the `[[obstacles]]`
/// tables touched by `contact_points` (`"nodes"`, or `"surface"` /
/// `"both"` with the embedded `surface`).
#[pyclass(name = "Problem", module = "hexmss", frozen)]
pub struct PyProblem {
    pub recipe: Recipe,
    pub problem: Arc<ProblemRef>,
    /// The model handed to Python, made once.
    model: std::sync::OnceLock<Py<PyModel>>,
}

/// The problem itself, owned or inside a prepared job.
pub enum ProblemRef {
    Owned(Box<Problem>),
    Job(Arc<mss_scene::Job>),
}

impl ProblemRef {
    pub fn get(&self) -> &Problem {
        match self {
            ProblemRef::Owned(p) => p,
            ProblemRef::Job(j) => &j.problem,
        }
    }
}

impl PyProblem {
    pub fn of_job(job: Arc<mss_scene::Job>) -> Self {
        Self {
            recipe: Recipe::Job(Arc::clone(&job)),
            problem: Arc::new(ProblemRef::Job(job)),
            model: std::sync::OnceLock::new(),
        }
    }
}

#[pymethods]
impl PyProblem {
    #[new]
    #[pyo3(signature = (model, *, fixed = None, gravity = None, forces = None, tractions = None, drags = None, custom_loads = None, motions = None, motion_duration = 1.0, damping = 0.0, stiffness_damping = 0.0, obstacles = None, contact_points = None, surface = None))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        model: &PyModel,
        fixed: Option<&Bound<'_, PyAny>>,
        gravity: Option<&Bound<'_, PyAny>>,
        forces: Option<&Bound<'_, PyAny>>,
        tractions: Option<&Bound<'_, PyAny>>,
        drags: Option<&Bound<'_, PyAny>>,
        custom_loads: Option<&Bound<'_, PyAny>>,
        motions: Option<&Bound<'_, PyAny>>,
        motion_duration: f64,
        damping: f64,
        stiffness_damping: f64,
        obstacles: Option<&Bound<'_, PyAny>>,
        contact_points: Option<&Bound<'_, PyAny>>,
        surface: Option<&PyEmbedding>,
    ) -> PyResult<Self> {
        let selectors: Vec<NodeSelector> = match fixed {
            Some(f) => from_py("fixed", f)?,
            None => Vec::new(),
        };
        let motions: Vec<MotionSpec> = match motions {
            Some(m) => from_py("motions", m)?,
            None => Vec::new(),
        };
        if !(motion_duration.is_finite() && motion_duration > 0.0) {
            return Err(raise(
                Kind::Scene,
                format!("motion_duration = {motion_duration}: give a positive number of seconds"),
            ));
        }
        let loads_dict = PyDict::new(py);
        for (key, v) in [
            ("gravity", gravity),
            ("forces", forces),
            ("tractions", tractions),
            ("drags", drags),
            ("custom", custom_loads),
        ] {
            if let Some(v) = v {
                loads_dict.set_item(key, v)?;
            }
        }
        let loads: LoadsSection = from_py("loads", loads_dict.as_any())?;
        let obstacles: Vec<ObstacleSpec> = match obstacles {
            Some(o) => from_py("obstacles", o)?,
            None => Vec::new(),
        };
        let points: ContactPoints = match contact_points {
            Some(p) => from_py("contact_points", p)?,
            None => ContactPoints::Nodes,
        };
        if points != ContactPoints::Nodes && surface.is_none() {
            return Err(raise(
                Kind::Scene,
                "contact_points: \"surface\" and \"both\" need the embedded surface (surface=lattice.embed(mesh))",
            ));
        }
        let constraints = selectors
            .into_iter()
            .map(ConstraintSpec::fixed)
            .chain(motions.iter().map(|m| m.constraint(motion_duration)))
            .collect();
        let recipe = Recipe::Specs {
            model: Arc::clone(&model.model),
            constraints,
            loads: loads.specs(),
            custom_loads: loads.custom.clone(),
            damping: Damping {
                alpha: damping,
                beta: stiffness_damping,
            },
            obstacles,
            points,
            surface: surface.map(|s| Arc::clone(&s.embedding)),
        };
        let problem = detached(py, || recipe.build())?;
        Ok(Self {
            recipe,
            problem: Arc::new(ProblemRef::Owned(Box::new(problem))),
            model: std::sync::OnceLock::new(),
        })
    }

    /// The model.
    #[getter]
    fn model(&self, py: Python<'_>) -> PyResult<Py<PyModel>> {
        crate::convert::cached_object(py, &self.model, || PyModel {
            model: match &self.recipe {
                // The model the problem was built from, shared.
                Recipe::Specs { model, .. } => Arc::clone(model),
                Recipe::Job(job) => Arc::new(job.problem.model().clone()),
            },
        })
    }

    /// Number of nodes.
    #[getter]
    fn num_nodes(&self) -> usize {
        self.problem.get().model().num_nodes()
    }

    /// Number of held displacement components (fixed and prescribed).
    #[getter]
    fn num_held_dofs(&self) -> usize {
        self.problem.get().constraints().num_held_dofs()
    }

    /// Indices of the fully held nodes.
    #[getter]
    fn held_nodes(&self) -> Vec<u32> {
        self.problem.get().constraints().fully_fixed_nodes()
    }

    /// Stable explicit time step with damping and contact (safety 1) (s).
    #[getter]
    fn stable_time_step(&self) -> f64 {
        mss_scene::mss_core::solver::explicit_time_step_limit(self.problem.get(), 1.0)
    }

    /// external_forces(x, t=0.0)
    ///
    /// Loads at node positions x and time t (N), without contact.
    #[pyo3(signature = (x, t = 0.0))]
    fn external_forces<'py>(
        &self,
        py: Python<'py>,
        x: &Bound<'py, PyAny>,
        t: f64,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let p = self.problem.get();
        let x = vec3_in("x", x, p.model().num_nodes())?;
        let mut f = vec![Vec3::zeros(); x.len()];
        p.external_forces(t, &x, 1.0, &mut f);
        Ok(vec3_array(py, &f))
    }

    /// contact_forces(state)
    ///
    /// The obstacles' forces on the nodes in `state` (N); zero without obstacles.
    fn contact_forces<'py>(&self, py: Python<'py>, state: &PyState) -> Bound<'py, PyArray2<f64>> {
        let s = state.lock();
        vec3_array(py, &self.problem.get().contact_forces(&s))
    }

    fn __repr__(&self) -> String {
        let p = self.problem.get();
        format!(
            "Problem({} nodes, {} held dofs, {} loads{})",
            p.model().num_nodes(),
            p.constraints().num_held_dofs(),
            p.loads().len(),
            if p.contact().is_some() {
                ", with obstacles"
            } else {
                ""
            }
        )
    }
}

/// Positions, velocities and time of a problem's nodes.
///
/// State(problem)
///
/// The problem's rest state at t = 0 (held nodes on their motion).
#[pyclass(name = "State", module = "hexmss", frozen)]
pub struct PyState {
    pub state: Mutex<State>,
}

impl PyState {
    pub fn wrap(state: State) -> Self {
        Self {
            state: Mutex::new(state),
        }
    }
    pub fn lock(&self) -> std::sync::MutexGuard<'_, State> {
        self.state.lock().unwrap_or_else(|e| e.into_inner())
    }
}

#[pymethods]
impl PyState {
    #[new]
    fn new(problem: &PyProblem) -> Self {
        let p = problem.problem.get();
        let mut s = State::at_rest(p.model());
        p.apply_constraints(&mut s);
        Self::wrap(s)
    }

    /// Node positions, (N, 3) (m): a copy; assign an (N, 3) array to set them.
    #[getter]
    fn x<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        vec3_array(py, &self.lock().x)
    }
    #[setter]
    fn set_x(&self, x: &Bound<'_, PyAny>) -> PyResult<()> {
        let mut s = self.lock();
        let n = s.x.len();
        s.x = vec3_in("x", x, n)?;
        Ok(())
    }
    /// Node velocities, (N, 3) (m/s): a copy; assign to set them.
    #[getter]
    fn v<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        vec3_array(py, &self.lock().v)
    }
    #[setter]
    fn set_v(&self, v: &Bound<'_, PyAny>) -> PyResult<()> {
        let mut s = self.lock();
        let n = s.v.len();
        s.v = vec3_in("v", v, n)?;
        Ok(())
    }
    /// Time (s).
    #[getter]
    fn time(&self) -> f64 {
        self.lock().time
    }
    #[setter]
    fn set_time(&self, t: f64) -> PyResult<()> {
        if !t.is_finite() {
            return Err(PyValueError::new_err(format!("time {t} must be finite")));
        }
        self.lock().time = t;
        Ok(())
    }

    /// positions_into(out)
    ///
    /// Copies the positions into `out`, an (N, 3) float64 C-contiguous
    /// array, without allocating; returns `out`.
    fn positions_into<'py>(&self, out: Bound<'py, PyAny>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let out = out_array(out)?;
        write_rows(&mut out.readwrite(), &self.lock().x, "out")?;
        Ok(out)
    }

    /// displacements(model)
    ///
    /// Positions minus the model's rest positions, (N, 3) (m).
    fn displacements<'py>(
        &self,
        py: Python<'py>,
        model: &PyModel,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let s = self.lock();
        if s.x.len() != model.model.num_nodes() {
            return Err(PyValueError::new_err(format!(
                "the state has {} nodes, the model {}",
                s.x.len(),
                model.model.num_nodes()
            )));
        }
        Ok(vec3_array(py, &s.displacements(&model.model)))
    }

    /// kinetic_energy(model)
    ///
    /// Kinetic energy with the model's masses (J).
    fn kinetic_energy(&self, model: &PyModel) -> PyResult<f64> {
        let s = self.lock();
        if s.v.len() != model.model.num_nodes() {
            return Err(PyValueError::new_err(format!(
                "the state has {} nodes, the model {}",
                s.v.len(),
                model.model.num_nodes()
            )));
        }
        Ok(s.kinetic_energy(model.model.masses()))
    }

    /// A copy of this state.
    fn copy(&self) -> Self {
        Self::wrap(self.lock().clone())
    }

    fn __repr__(&self) -> String {
        let s = self.lock();
        format!("State({} nodes, t = {} s)", s.x.len(), s.time)
    }
}

/// The linear solver called `name`, read as the scene's `[solver]
/// linear_solver` key is (the library type names its choices).
fn precision_named(name: &str) -> PyResult<Precision> {
    Precision::from_name(name).ok_or_else(|| {
        raise(
            Kind::Scene,
            format!("precision = {name:?}: use \"f64\" or \"f32\""),
        )
    })
}

fn linear_kind(name: &str) -> PyResult<LinearSolverKind> {
    use serde::Deserialize;
    let value = serde::de::value::StrDeserializer::<serde::de::value::Error>::new(name);
    LinearSolverKind::deserialize(value).map_err(|_| {
        raise(
            Kind::Scene,
            format!("linear_solver = {name:?}: use \"auto\", \"direct\" or \"iterative\""),
        )
    })
}

/// solve_static(problem, state=None, *, rtol=1e-8, max_newton=40, linear=False, accept_unstable=False, linear_solver="auto")
/// --
///
/// Static equilibrium of `problem` (at `state.time`, from `state.x`; from
/// rest by default). Returns `(state, info)`: the equilibrium and a dict
/// with `newton_iterations`, `load_steps`, `relative_residual`,
/// `krylov_iterations` and `stable` (True, False, or None when the
/// stability test was skipped). Raises `MechanismError` for zero-energy
/// motions and for an unstable equilibrium unless `accept_unstable`.
/// `obstacles_from`: the time at which `state` was in equilibrium with the
/// obstacles (0.0 for a body at rest): they are then moved along their
/// paths from there, as a slow press would (default: where they are at
/// `state.time`; one that starts deep in the body is inserted there from
/// outside along its shortest way out).
#[pyfunction(name = "solve_static")]
#[pyo3(signature = (problem, state = None, *, rtol = None, max_newton = None, linear = false, accept_unstable = false, linear_solver = "auto", obstacles_from = None))]
#[allow(clippy::too_many_arguments)]
fn py_solve_static<'py>(
    py: Python<'py>,
    problem: &PyProblem,
    state: Option<&PyState>,
    rtol: Option<f64>,
    max_newton: Option<u32>,
    linear: bool,
    accept_unstable: bool,
    linear_solver: &str,
    obstacles_from: Option<f64>,
) -> PyResult<(PyState, Bound<'py, PyDict>)> {
    if let Some(t) = obstacles_from
        && !t.is_finite()
    {
        return Err(pyo3::exceptions::PyValueError::new_err(format!(
            "obstacles_from = {t}: give a finite time (s)"
        )));
    }
    let defaults = StaticOptions::default();
    let opts = StaticOptions {
        rtol: rtol.unwrap_or(defaults.rtol),
        max_newton: max_newton.unwrap_or(defaults.max_newton),
        small_strain: linear,
        accept_unstable,
        linear_solver: linear_kind(linear_solver)?,
        obstacles_from,
        ..defaults
    };
    let p = Arc::clone(&problem.problem);
    let mut s = match state {
        Some(s) => s.lock().clone(),
        None => {
            let mut s = State::at_rest(p.get().model());
            p.get().apply_constraints(&mut s);
            s
        }
    };
    let info = detached(py, || solve_static(p.get(), &mut s, &opts)).map_err(solver)?;
    let d = PyDict::new(py);
    d.set_item("newton_iterations", info.newton_iterations)?;
    d.set_item("load_steps", info.load_steps)?;
    d.set_item("rejected_iterations", info.rejected_iterations)?;
    d.set_item("relative_residual", info.relative_residual)?;
    d.set_item("krylov_iterations", info.linear.krylov_iterations)?;
    d.set_item(
        "stable",
        match info.stability {
            Stability::Stable => Some(true),
            Stability::Unstable => Some(false),
            Stability::NotTested => None,
        },
    )?;
    Ok((PyState::wrap(s), d))
}

/// A time integrator bound to a problem.
///
/// Integrator(problem, kind="explicit", *, dt=None, safety=0.9, substep=False, rtol=None, max_newton=None, linear_solver="auto", precision="f64")
///
/// `kind` is one of `integrators()`. Explicit schemes step at the stable
/// limit times `safety` unless `dt` is given (refused above the limit
/// unless `substep`); `"implicit"` needs no stability limit (default
/// dt 0.01 s). `precision="f32"` runs the explicit force pass in single
/// precision (faster; Newton solvers refuse it).
#[pyclass(name = "Integrator", module = "hexmss", frozen)]
pub struct PyIntegrator {
    problem: Arc<ProblemRef>,
    integrator: Mutex<Box<dyn Integrator>>,
}

#[pymethods]
impl PyIntegrator {
    #[new]
    #[pyo3(signature = (problem, kind = "explicit", *, dt = None, safety = None, substep = false, rtol = None, max_newton = None, linear_solver = "auto", precision = "f64"))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        problem: &PyProblem,
        kind: &str,
        dt: Option<f64>,
        safety: Option<f64>,
        substep: bool,
        rtol: Option<f64>,
        max_newton: Option<u32>,
        linear_solver: &str,
        precision: &str,
    ) -> PyResult<Self> {
        let d = IntegratorSettings::default();
        let settings = IntegratorSettings {
            dt,
            safety: safety.unwrap_or(d.safety),
            substep,
            rtol: rtol.unwrap_or(d.rtol),
            max_newton: max_newton.unwrap_or(d.max_newton),
            linear_solver: linear_kind(linear_solver)?,
            precision: precision_named(precision)?,
        };
        let p = Arc::clone(&problem.problem);
        let kind = kind.to_owned();
        let integrator = detached(py, || {
            Integrators::default().build(&kind, p.get(), &settings)
        })
        .map_err(solver)?;
        Ok(Self {
            problem: Arc::clone(&problem.problem),
            integrator: Mutex::new(integrator),
        })
    }

    /// The time step (s).
    #[getter]
    fn dt(&self) -> f64 {
        self.lock().dt()
    }

    /// The scheme's name.
    #[getter]
    fn name(&self) -> &'static str {
        self.lock().name()
    }

    /// step(state, n=1)
    ///
    /// Advances `state` in place by n steps. Returns a dict with `time`,
    /// `steps`, `substeps` and `newton_iterations`. On failure (a
    /// `DivergedError`) the state is the last good one.
    #[pyo3(signature = (state, n = 1))]
    fn step<'py>(&self, py: Python<'py>, state: &PyState, n: u64) -> PyResult<Bound<'py, PyDict>> {
        let p = Arc::clone(&self.problem);
        let (substeps, newton, done, result) = detached(py, || {
            let mut integ = self.lock();
            let mut s = state.lock();
            let (mut substeps, mut newton, mut done) = (0u64, 0u64, 0u64);
            for _ in 0..n {
                match integ.step(p.get(), &mut s) {
                    Ok(info) => {
                        substeps += u64::from(info.substeps);
                        newton += u64::from(info.newton_iterations);
                        done += 1;
                    }
                    Err(e) => return (substeps, newton, done, Err(e)),
                }
            }
            (substeps, newton, done, Ok(()))
        });
        result.map_err(solver)?;
        let d = PyDict::new(py);
        d.set_item("time", state.lock().time)?;
        d.set_item("steps", done)?;
        d.set_item("substeps", substeps)?;
        d.set_item("newton_iterations", newton)?;
        Ok(d)
    }
}

impl PyIntegrator {
    fn lock(&self) -> std::sync::MutexGuard<'_, Box<dyn Integrator>> {
        self.integrator.lock().unwrap_or_else(|e| e.into_inner())
    }
}

/// An interactive simulation: a problem and its state stepped frame by
/// frame, with a drag on picked nodes.
///
/// Simulation(problem, surface=None)
///
/// A simulation of (a fresh copy of) `problem` from rest; `surface`, an
/// `Embedding`, is what `surface_positions()` deforms.
#[pyclass(name = "Simulation", module = "hexmss", frozen)]
pub struct PySimulation {
    sim: Mutex<Simulation>,
    surface: Option<Arc<mss_scene::hexmesh::Embedding>>,
}

impl PySimulation {
    pub fn build(
        problem: Problem,
        surface: Option<Arc<mss_scene::hexmesh::Embedding>>,
    ) -> PyResult<Self> {
        Ok(Self {
            sim: Mutex::new(Simulation::new(problem).map_err(solver)?),
            surface,
        })
    }
    fn lock(&self) -> std::sync::MutexGuard<'_, Simulation> {
        self.sim.lock().unwrap_or_else(|e| e.into_inner())
    }
    /// [`Simulation::settle`].
    pub fn settle_with(
        &self,
        opts: &SettleOptions,
    ) -> Result<mss_scene::mss_core::solver::SettleInfo, mss_scene::mss_core::solver::SolverError>
    {
        self.lock().settle(opts)
    }
}

#[pymethods]
impl PySimulation {
    #[new]
    #[pyo3(signature = (problem, surface = None))]
    fn new(py: Python<'_>, problem: &PyProblem, surface: Option<&PyEmbedding>) -> PyResult<Self> {
        let p = detached(py, || problem.recipe.build())?;
        Self::build(p, surface.map(|s| Arc::clone(&s.embedding)))
    }

    fn __repr__(&self) -> String {
        let sim = self.lock();
        format!(
            "Simulation({} nodes, t = {} s, {} picked nodes{})",
            sim.positions().len(),
            sim.state().time,
            sim.grabbed_nodes().len(),
            if self.surface.is_some() {
                ", with a surface"
            } else {
                ""
            }
        )
    }

    /// The precision of the force pass, "f64" (default) or "f32" (faster,
    /// for interactive use).
    #[getter]
    fn get_precision(&self) -> &'static str {
        self.lock().precision().name()
    }

    #[setter]
    fn set_precision(&self, precision: &str) -> PyResult<()> {
        let p = precision_named(precision)?;
        self.lock().set_precision(p);
        Ok(())
    }

    /// step(dt)
    ///
    /// Advances by dt seconds (a frame) in as many explicit sub-steps as
    /// stability asks; returns the number of sub-steps.
    fn step(&self, py: Python<'_>, dt: f64) -> PyResult<u32> {
        let info = detached(py, || self.lock().step(dt)).map_err(solver)?;
        Ok(info.substeps)
    }

    /// settle(rtol=1e-4, max_time=10.0)
    ///
    /// Brings the bodies to rest under the loads at the current time,
    /// contact and friction included (a scene's `[solver] start =
    /// "settled"`), so that the frames that follow start from equilibrium.
    /// Returns a dict with `steps`, `settle_time` (s simulated),
    /// `relative_residual` and `omega`. A body that never comes to rest
    /// raises `SolverError` after `max_time` seconds of settling.
    #[pyo3(signature = (rtol = None, max_time = None))]
    fn settle<'py>(
        &self,
        py: Python<'py>,
        rtol: Option<f64>,
        max_time: Option<f64>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let defaults = SettleOptions::default();
        let opts = SettleOptions {
            rtol: rtol.unwrap_or(defaults.rtol),
            max_time: max_time.unwrap_or(defaults.max_time),
            ..defaults
        };
        let info = detached(py, || self.settle_with(&opts)).map_err(solver)?;
        let d = PyDict::new(py);
        d.set_item("steps", info.steps)?;
        d.set_item("settle_time", info.settle_time)?;
        d.set_item("relative_residual", info.relative_residual)?;
        d.set_item("omega", info.omega)?;
        Ok(d)
    }

    /// Time reached (s).
    #[getter]
    fn time(&self) -> f64 {
        self.lock().state().time
    }

    /// Node positions, (N, 3) (m): a copy (see `positions_into`).
    #[getter]
    fn positions<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        vec3_array(py, self.lock().positions())
    }

    /// positions_into(out)
    ///
    /// Copies the node positions into `out`, an (N, 3) float64 C-contiguous
    /// array, without allocating; returns `out`.
    fn positions_into<'py>(&self, out: Bound<'py, PyAny>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let out = out_array(out)?;
        write_rows(&mut out.readwrite(), self.lock().positions(), "out")?;
        Ok(out)
    }

    /// Node velocities, (N, 3) (m/s).
    #[getter]
    fn velocities<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        vec3_array(py, &self.lock().state().v)
    }

    /// The state reached (a copy).
    #[getter]
    fn state(&self) -> PyState {
        PyState::wrap(self.lock().state().clone())
    }

    /// nearest_node(point)
    ///
    /// The node nearest to a point (m) in the current positions.
    fn nearest_node(&self, point: [f64; 3]) -> u32 {
        self.lock().nearest_node(Vec3::from(point))
    }

    /// pick(nodes, stiffness)
    ///
    /// Holds `nodes` by zero-length springs of `stiffness` (N/m, per node)
    /// to targets that keep their offsets; `drag_to` moves them.
    fn pick(&self, nodes: &Bound<'_, PyAny>, stiffness: f64) -> PyResult<()> {
        let mut sim = self.lock();
        let n = sim.positions().len();
        let nodes = node_list("nodes", nodes, n)?;
        sim.pick(&nodes, stiffness)
            .map_err(|e| from_error(Kind::Scene, &e))
    }

    /// drag_to(point)
    ///
    /// Moves the picked nodes' target centroid to a point (m).
    fn drag_to(&self, point: [f64; 3]) -> PyResult<()> {
        if !point.iter().all(|c| c.is_finite()) {
            return Err(PyValueError::new_err(format!(
                "drag_to({point:?}): coordinates must be finite"
            )));
        }
        self.lock().drag_to(Vec3::from(point));
        Ok(())
    }

    /// Lets the picked nodes go.
    fn release(&self) {
        self.lock().release();
    }

    /// surface_positions()
    ///
    /// Vertex positions of the embedded surface (V, 3) (m); needs the
    /// `surface` given at construction (or a job's mesh).
    fn surface_positions<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let Some(e) = &self.surface else {
            return Err(raise(
                Kind::Scene,
                "this simulation has no embedded surface: give Simulation(problem, surface=lattice.embed(mesh))",
            ));
        };
        let v = self.lock().surface(e);
        Ok(crate::convert::points_array(py, v))
    }
}
