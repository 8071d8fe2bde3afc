//! The paper's 2D element from Python: `RectLattice` (rectangles of any
//! aspect ratio), `PlaneModel` (plane stress, a thickness) and
//! `PlaneProblem` (held nodes, in-plane loads, the static, explicit and
//! implicit solves). Positions are `(n, 3)` arrays with z = 0, as the 3D
//! classes take them; the methods have the 3D classes' names.

use std::sync::Arc;

use mss_scene::hexmesh::plane::{Outline, RectLattice, rasterize};
use mss_scene::mss_core::Vec3;
use mss_scene::mss_core::constraints::NodeSelector;
use mss_scene::mss_core::plane::{PlaneModel, PlaneProblem, PlaneSolveError};
use mss_scene::scene::{LoadsSection, ModelSection, plane_drag, plane_force, plane_traction};
use numpy::IntoPyArray;
use numpy::PyArray2;
use numpy::ndarray::Array2;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::convert::{from_py, index_array, vec3_array, vec3_in};
use crate::errors::{Kind, raise};
use crate::physics::PyMaterial;
use crate::threads::detached;

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyRectLattice>()?;
    m.add_class::<PyPlaneModel>()?;
    m.add_class::<PyPlaneProblem>()?;
    Ok(())
}

/// Rectangles `lx x ly` of any aspect ratio on a grid of the x-y plane,
/// for the paper's 2D element.
///
/// RectLattice.block(n, cell, origin=(0.0, 0.0)): a block of n = (nx, ny)
/// cells of cell = (lx, ly) m from origin.
/// RectLattice.rasterize(polygons, cell): the cells whose centres lie
/// inside closed polygons (lists of (x, y) points; a polygon inside
/// another is a hole).
#[pyclass(name = "RectLattice", module = "hexmss", frozen)]
pub struct PyRectLattice {
    pub lattice: Arc<RectLattice>,
}

fn plane_error(e: impl std::fmt::Display) -> PyErr {
    raise(Kind::Voxelize, e.to_string())
}

#[pymethods]
impl PyRectLattice {
    /// block(n, cell, origin=(0.0, 0.0))
    ///
    /// A block of n = (nx, ny) cells of cell = (lx, ly) m from origin (m).
    #[staticmethod]
    #[pyo3(signature = (n, cell, origin = (0.0, 0.0)))]
    fn block(n: [u32; 2], cell: [f64; 2], origin: (f64, f64)) -> PyResult<Self> {
        let lattice = RectLattice::block(n, cell, [origin.0, origin.1]).map_err(plane_error)?;
        Ok(Self {
            lattice: Arc::new(lattice),
        })
    }

    /// rasterize(polygons, cell)
    ///
    /// The cells of cell = (lx, ly) m whose centres lie inside the closed
    /// polygons (each a list of (x, y) points, m; even-odd rule: a polygon
    /// inside another is a hole).
    #[staticmethod]
    fn rasterize(py: Python<'_>, polygons: Vec<Vec<[f64; 2]>>, cell: [f64; 2]) -> PyResult<Self> {
        let outline = Outline::new(polygons).map_err(plane_error)?;
        let lattice = detached(py, || rasterize(&outline, cell)).map_err(plane_error)?;
        Ok(Self {
            lattice: Arc::new(lattice),
        })
    }

    /// Node positions, (N, 2) float64 (m).
    #[getter]
    fn nodes<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        let nodes = self.lattice.nodes();
        Array2::from_shape_vec((nodes.len(), 2), nodes.to_vec().into_flattened())
            .expect("n x 2 values")
            .into_pyarray(py)
    }
    /// Cells as 4 node indices counter-clockwise from the lower left, (C, 4)
    /// uint32 (VTK_QUAD order).
    #[getter]
    fn cells<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<u32>> {
        index_array(py, self.lattice.cells().to_vec())
    }
    /// The cells' sides (lx, ly) (m).
    #[getter]
    fn cell_size(&self) -> (f64, f64) {
        let [lx, ly] = self.lattice.cell_size();
        (lx, ly)
    }
    /// Number of nodes.
    #[getter]
    fn num_nodes(&self) -> usize {
        self.lattice.num_nodes()
    }
    /// Number of cells.
    #[getter]
    fn num_cells(&self) -> usize {
        self.lattice.num_cells()
    }
    /// Area covered (m^2).
    #[getter]
    fn area(&self) -> f64 {
        self.lattice.area()
    }
    fn __repr__(&self) -> String {
        let [lx, ly] = self.lattice.cell_size();
        format!(
            "RectLattice({} cells of {lx} x {ly} m, {} nodes)",
            self.lattice.num_cells(),
            self.lattice.num_nodes()
        )
    }
}

/// The paper's 2D element on a RectLattice (plane stress).
///
/// PlaneModel(lattice, material, thickness, parameterization=None, hourglass=None)
///
/// `thickness` (m) scales masses and forces. `parameterization` is
/// "paper", "springs" or "areal", each optionally with "+hg" (hourglass
/// control, factor `hourglass`, default 1); None means "paper+hg", as a
/// 2D scene's [model] table. The methods are those of the 3D Model, with
/// positions as (N, 3) arrays whose z is 0.
#[pyclass(name = "PlaneModel", module = "hexmss", frozen)]
pub struct PyPlaneModel {
    pub model: Arc<PlaneModel>,
    name: String,
}

#[pymethods]
impl PyPlaneModel {
    #[new]
    #[pyo3(signature = (lattice, material, thickness, parameterization = None, hourglass = None))]
    fn new(
        lattice: &PyRectLattice,
        material: &PyMaterial,
        thickness: f64,
        parameterization: Option<String>,
        hourglass: Option<f64>,
    ) -> PyResult<Self> {
        let section = ModelSection::new(parameterization, hourglass);
        let (variant, hg) = section
            .plane_variant()
            .map_err(|e| raise(Kind::Model, format!("parameterization {}", e.message)))?;
        let model = PlaneModel::new(&lattice.lattice, material.material, thickness, variant, hg)
            .map_err(|e| raise(Kind::Model, e.to_string()))?;
        let name = match hg {
            Some(_) => format!("{}+hg", variant.name()),
            None => variant.name().to_owned(),
        };
        Ok(Self {
            model: Arc::new(model),
            name,
        })
    }

    /// Always 2 (a 3D Model's is 3).
    #[getter]
    fn dimension(&self) -> u32 {
        2
    }
    /// Node masses, (N,) float64 (kg).
    #[getter]
    fn masses<'py>(&self, py: Python<'py>) -> Bound<'py, numpy::PyArray1<f64>> {
        numpy::PyArray1::from_slice(py, self.model.masses())
    }
    /// Rest positions of the nodes, (N, 3) with z = 0 (m).
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
    /// Total mass (kg).
    #[getter]
    fn total_mass(&self) -> f64 {
        self.model.total_mass()
    }
    /// The cells' sides (lx, ly) (m).
    #[getter]
    fn cell_size(&self) -> (f64, f64) {
        let [lx, ly] = self.model.cell_size();
        (lx, ly)
    }
    /// Thickness (m).
    #[getter]
    fn thickness(&self) -> f64 {
        self.model.thickness()
    }
    /// The 2D variant's name ("paper", "springs", "areal", with "+hg").
    #[getter]
    fn parameterization(&self) -> String {
        self.name.clone()
    }
    /// Stable explicit time step of the undamped model at rest (s).
    #[getter]
    fn stable_time_step(&self) -> f64 {
        self.model.stable_time_step(1.0)
    }

    /// internal_forces(x)
    ///
    /// Internal forces at node positions x (N, 3) (N; z stays 0).
    fn internal_forces<'py>(
        &self,
        py: Python<'py>,
        x: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let n = self.model.num_nodes();
        let x = plane_positions("x", x, n)?;
        let m = Arc::clone(&self.model);
        let f = detached(py, || {
            let mut f = vec![Vec3::zeros(); n];
            m.internal_forces(&x, &mut f);
            f
        });
        Ok(vec3_array(py, &f))
    }

    /// energy(x)
    ///
    /// Elastic energy at node positions x (J); the paper's correction
    /// forces are not conservative and have none.
    fn energy(&self, py: Python<'_>, x: &Bound<'_, PyAny>) -> PyResult<f64> {
        let x = plane_positions("x", x, self.model.num_nodes())?;
        let m = Arc::clone(&self.model);
        Ok(detached(py, || m.energy(&x)))
    }

    fn __repr__(&self) -> String {
        format!(
            "PlaneModel({:?}, {} cells, {} nodes, {:.4} kg)",
            self.name,
            self.model.num_cells(),
            self.model.num_nodes(),
            self.model.total_mass()
        )
    }
}

/// Node positions of a 2D body: `(n, 3)` rows whose z is 0.
fn plane_positions(what: &str, a: &Bound<'_, PyAny>, n: usize) -> PyResult<Vec<Vec3>> {
    let x = vec3_in(what, a, n)?;
    if let Some(i) = x.iter().position(|p| p.z != 0.0) {
        return Err(raise(
            Kind::Model,
            format!(
                "{what}: row {i} has z = {}; a 2D body lies in z = 0",
                x[i].z
            ),
        ));
    }
    Ok(x)
}

/// A 2D model with held nodes, in-plane loads and damping.
///
/// PlaneProblem(model, *, fixed=None, gravity=None, forces=None, tractions=None, drags=None, damping=0.0)
///
/// The keywords take a 2D scene's tables, as Problem's do: `fixed` a list
/// of node selectors (dicts as [[fixed]]), `gravity` [gx, gy, 0] (m/s^2),
/// `forces`, `tractions` and `drags` lists of the tables of
/// [[loads.forces]], [[loads.tractions]] and [[loads.drags]] (vectors in
/// the plane), `damping` mass-proportional (1/s).
#[pyclass(name = "PlaneProblem", module = "hexmss", frozen)]
pub struct PyPlaneProblem {
    problem: Arc<PlaneProblem>,
    model: Py<PyPlaneModel>,
}

fn solve_error(e: PlaneSolveError) -> PyErr {
    match e {
        PlaneSolveError::Diverged(_) => raise(Kind::Diverged, e.to_string()),
        PlaneSolveError::Newton(_) => raise(Kind::Solver, e.to_string()),
    }
}

#[pymethods]
impl PyPlaneProblem {
    #[new]
    #[pyo3(signature = (model, *, fixed = None, gravity = None, forces = None, tractions = None, drags = None, damping = 0.0))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        model: Py<PyPlaneModel>,
        fixed: Option<&Bound<'_, PyAny>>,
        gravity: Option<&Bound<'_, PyAny>>,
        forces: Option<&Bound<'_, PyAny>>,
        tractions: Option<&Bound<'_, PyAny>>,
        drags: Option<&Bound<'_, PyAny>>,
        damping: f64,
    ) -> PyResult<Self> {
        let selectors: Vec<NodeSelector> = match fixed {
            Some(f) => from_py("fixed", f)?,
            None => Vec::new(),
        };
        let loads_dict = PyDict::new(py);
        for (key, v) in [
            ("gravity", gravity),
            ("forces", forces),
            ("tractions", tractions),
            ("drags", drags),
        ] {
            if let Some(v) = v {
                loads_dict.set_item(key, v)?;
            }
        }
        let loads: LoadsSection = from_py("loads", loads_dict.as_any())?;
        if !(damping.is_finite() && damping >= 0.0) {
            return Err(raise(
                Kind::Model,
                format!("damping = {damping}: give a number >= 0 (1/s)"),
            ));
        }
        let plane = Arc::clone(&model.borrow(py).model);
        let mut problem = PlaneProblem::new((*plane).clone());
        let model_error =
            |what: String, e: &dyn std::fmt::Display| raise(Kind::Model, format!("{what}: {e}"));
        for (i, s) in selectors.iter().enumerate() {
            let nodes = plane
                .select_nodes(s)
                .map_err(|e| model_error(format!("fixed #{}", i + 1), &e))?;
            for n in nodes {
                problem.held[n as usize] = [true, true];
            }
        }
        if let Some(g) = loads.gravity {
            if g[2] != 0.0 || !g.iter().all(|c| c.is_finite()) {
                return Err(raise(
                    Kind::Model,
                    format!(
                        "gravity = {g:?}: a 2D body takes finite gravity in the x-y plane (z = 0)"
                    ),
                ));
            }
            problem.gravity = [g[0], g[1]];
        }
        let mut dead = Vec::new();
        for (i, f) in loads.forces.iter().enumerate() {
            dead.extend(
                plane_force(f, &plane)
                    .map_err(|e| model_error(format!("forces #{}", i + 1), &e))?,
            );
        }
        for (i, t) in loads.tractions.iter().enumerate() {
            dead.extend(
                plane_traction(t, &plane)
                    .map_err(|e| model_error(format!("tractions #{}", i + 1), &e))?,
            );
        }
        for (n, f) in dead {
            problem.forces[n as usize][0] += f[0];
            problem.forces[n as usize][1] += f[1];
        }
        for (i, d) in loads.drags.iter().enumerate() {
            let drag =
                plane_drag(d, &plane).map_err(|e| model_error(format!("drags #{}", i + 1), &e))?;
            problem.loads.push(Arc::new(drag));
        }
        problem.damping = damping;
        Ok(Self {
            problem: Arc::new(problem),
            model,
        })
    }

    /// The model.
    #[getter]
    fn model(&self, py: Python<'_>) -> Py<PyPlaneModel> {
        self.model.clone_ref(py)
    }
    /// Indices of the held nodes.
    #[getter]
    fn held_nodes(&self) -> Vec<u32> {
        (0..self.problem.held.len() as u32)
            .filter(|&i| self.problem.held[i as usize] != [false, false])
            .collect()
    }
    /// stable_time_step(safety=0.9)
    ///
    /// A stable explicit step (s): 2 / omega_max times `safety`.
    #[pyo3(signature = (safety = 0.9))]
    fn stable_time_step(&self, safety: f64) -> f64 {
        self.problem.stable_time_step(safety)
    }

    /// solve_static(x=None, time=0.0)
    ///
    /// The static equilibrium from x (default: the rest positions), as an
    /// (N, 3) array.
    #[pyo3(signature = (x = None, time = 0.0))]
    fn solve_static<'py>(
        &self,
        py: Python<'py>,
        x: Option<&Bound<'py, PyAny>>,
        time: f64,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let n = self.problem.model.num_nodes();
        let mut x = match x {
            Some(x) => plane_positions("x", x, n)?,
            None => self.problem.model.rest_positions().to_vec(),
        };
        let p = Arc::clone(&self.problem);
        detached(py, || p.solve_static(time, &mut x)).map_err(solve_error)?;
        Ok(vec3_array(py, &x))
    }

    /// step(x, v, dt, n=1, t0=0.0, implicit=False)
    ///
    /// `n` steps of `dt` (s) from positions x and velocities v at time t0:
    /// explicit (semi-implicit Euler; dt must be stable) or implicit
    /// (backward Euler, any dt). Returns the new (x, v).
    #[pyo3(signature = (x, v, dt, n = 1, t0 = 0.0, implicit = false))]
    #[allow(clippy::too_many_arguments, clippy::type_complexity)]
    fn step<'py>(
        &self,
        py: Python<'py>,
        x: &Bound<'py, PyAny>,
        v: &Bound<'py, PyAny>,
        dt: f64,
        n: usize,
        t0: f64,
        implicit: bool,
    ) -> PyResult<(Bound<'py, PyArray2<f64>>, Bound<'py, PyArray2<f64>>)> {
        let nodes = self.problem.model.num_nodes();
        let mut x = plane_positions("x", x, nodes)?;
        let mut v = plane_positions("v", v, nodes)?;
        let stable = self.problem.stable_time_step(1.0);
        if !(dt.is_finite() && dt > 0.0) || (!implicit && dt > stable) {
            return Err(raise(
                Kind::Solver,
                format!(
                    "dt = {dt} s: give a positive step{}",
                    if implicit {
                        String::new()
                    } else {
                        format!(" at most the stable {stable:.3e} s (or implicit=True)")
                    }
                ),
            ));
        }
        let p = Arc::clone(&self.problem);
        detached(py, || {
            if implicit {
                p.step_implicit(t0, &mut x, &mut v, dt, n).map(|_| ())
            } else {
                p.step_explicit(t0, &mut x, &mut v, dt, n)
            }
        })
        .map_err(solve_error)?;
        Ok((vec3_array(py, &x), vec3_array(py, &v)))
    }

    fn __repr__(&self) -> String {
        format!(
            "PlaneProblem({} nodes, {} held)",
            self.problem.model.num_nodes(),
            self.held_nodes().len()
        )
    }
}
