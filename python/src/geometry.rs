//! Surfaces, the voxelizer and lattices: `Mesh`, `Lattice`, `Skin`,
//! `Embedding`, `load_mesh`, `voxelize`.

use std::sync::{Arc, OnceLock};

use mss_scene::hexmesh::Placement;
use mss_scene::hexmesh::load::Loaders;
use mss_scene::hexmesh::{Embedding, Lattice, TriMesh};
use mss_scene::limits::Limits;
use mss_scene::scene::{MeshSection, VoxelizeSection};
use mss_scene::stages::{self, StageError};
use numpy::PyArray2;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::convert::{
    from_py, index_array, indices_in, kwargs_dict, points_array, points_in, read_only,
};
use crate::errors::{Kind, from_error, raise};
use crate::threads::detached;

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyMesh>()?;
    m.add_class::<PyLattice>()?;
    m.add_class::<PySkin>()?;
    m.add_class::<PyEmbedding>()?;
    m.add_function(wrap_pyfunction!(load_mesh, m)?)?;
    m.add_function(wrap_pyfunction!(voxelize, m)?)?;
    Ok(())
}

/// A closed triangle surface (m): what is voxelized.
///
/// Mesh(vertices, triangles, name="arrays")
///
/// A mesh from an (n, 3) array of vertex positions (m) and an (m, 3)
/// array of vertex indices, cleaned as files are (degenerate and
/// repeated triangles dropped, unused vertices removed).
#[pyclass(name = "Mesh", module = "hexmss", frozen)]
pub struct PyMesh {
    pub mesh: Arc<TriMesh>,
    pub name: String,
    vertices: OnceLock<Py<PyArray2<f64>>>,
    triangles: OnceLock<Py<PyArray2<u32>>>,
}

impl PyMesh {
    pub fn wrap(mesh: TriMesh, name: String) -> Self {
        Self {
            mesh: Arc::new(mesh),
            name,
            vertices: OnceLock::new(),
            triangles: OnceLock::new(),
        }
    }
}

/// A cached, read-only array built on first access.
fn cached<'py, T: numpy::Element>(
    py: Python<'py>,
    cell: &OnceLock<Py<PyArray2<T>>>,
    make: impl FnOnce(Python<'py>) -> Bound<'py, PyArray2<T>>,
) -> PyResult<Bound<'py, PyArray2<T>>> {
    if let Some(a) = cell.get() {
        return Ok(a.bind(py).clone());
    }
    let a = read_only(make(py))?;
    let _ = cell.set(a.clone().unbind());
    Ok(cell.get().map_or(a, |c| c.bind(py).clone()))
}

#[pymethods]
impl PyMesh {
    #[new]
    #[pyo3(signature = (vertices, triangles, name = "arrays".to_owned()))]
    fn new(
        vertices: &Bound<'_, PyAny>,
        triangles: &Bound<'_, PyAny>,
        name: String,
    ) -> PyResult<Self> {
        let v = points_in("vertices", vertices)?;
        let t = indices_in::<3>("triangles", triangles, Some(v.len()))?;
        let raw = TriMesh {
            vertices: v,
            triangles: t,
        };
        let loaded = mss_scene::hexmesh::load::clean_mesh(raw, 0.0, &name)
            .map_err(|e| from_error(Kind::Mesh, &e))?;
        Ok(Self::wrap(loaded.mesh, name))
    }

    /// Vertex positions, (n, 3) float64, read-only (m).
    #[getter]
    fn vertices<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        cached(py, &self.vertices, |py| {
            points_array(py, self.mesh.vertices.clone())
        })
    }

    /// Triangles as vertex indices, (m, 3) uint32, read-only.
    #[getter]
    fn triangles<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<u32>>> {
        cached(py, &self.triangles, |py| {
            index_array(py, self.mesh.triangles.clone())
        })
    }

    /// Where the mesh came from (a path, `builtin:NAME`, or `arrays`).
    #[getter]
    fn name(&self) -> &str {
        &self.name
    }

    /// The bounding box as (min, max) corners (m).
    #[getter]
    fn bounds(&self) -> ([f64; 3], [f64; 3]) {
        self.mesh
            .bounding_box()
            .map_or(([0.0; 3], [0.0; 3]), |b| (b.min, b.max))
    }

    /// Enclosed volume (m^3, positive for outward winding).
    #[getter]
    fn volume(&self) -> f64 {
        self.mesh.signed_volume()
    }

    /// place(*, units="m", scale=1.0, up="z", rotate=(0, 0, 0), translate=(0, 0, 0))
    ///
    /// A placed copy, with the keys of a scene's `[mesh]` table: `units` of
    /// the coordinates, `scale` (one number or three), the file's `up` axis
    /// turned to +z, `rotate` in degrees about fixed x, y, z, then `translate` (m).
    #[pyo3(signature = (**placement))]
    fn place(&self, placement: Option<&Bound<'_, PyDict>>) -> PyResult<Self> {
        let mut mesh = (*self.mesh).clone();
        place(&mut mesh, &self.name, placement)?;
        Ok(Self::wrap(mesh, self.name.clone()))
    }

    fn __len__(&self) -> usize {
        self.mesh.triangles.len()
    }

    fn __repr__(&self) -> String {
        format!(
            "Mesh({:?}, {} vertices, {} triangles)",
            self.name,
            self.mesh.vertices.len(),
            self.mesh.triangles.len()
        )
    }
}

/// The placement that `[mesh]`-style keys describe (identity without keys).
fn placement_of(name: &str, placement: Option<&Bound<'_, PyDict>>) -> PyResult<Placement> {
    let Some(kw) = placement else {
        return Ok(Placement::default());
    };
    if kw.is_empty() {
        return Ok(Placement::default());
    }
    let d = kw.copy()?;
    d.set_item("path", name)?;
    let section: MeshSection = from_py("placement", d.as_any())?;
    Ok(section.placement())
}

/// Applies `[mesh]`-style placement keys to `mesh`.
fn place(mesh: &mut TriMesh, name: &str, placement: Option<&Bound<'_, PyDict>>) -> PyResult<()> {
    placement_of(name, placement)?
        .apply(mesh)
        .map_err(|e| raise(Kind::Scene, format!("{name}: {e}")))
}

/// The exception of a stage's error.
pub(crate) fn stage_error(e: &StageError) -> PyErr {
    let kind = match e {
        StageError::Source(_) | StageError::Image(_) => Kind::Mesh,
        StageError::Placement { .. } => Kind::Scene,
        StageError::Memory { .. } => Kind::Resource,
        StageError::Voxelize { .. } | StageError::NoLabelledVoxels { .. } => Kind::Voxelize,
    };
    from_error(kind, e)
}

/// load_mesh(path, **placement)
/// --
///
/// Loads a surface mesh (OBJ, STL, PLY, VTK legacy/.vtu/.vtp, the format
/// told from the content) or a bundled one (`"builtin:critter"`), cleaned,
/// then placed with the keys of a scene's `[mesh]` table (`units`, `scale`,
/// `up`, `rotate`, `translate`).
#[pyfunction]
#[pyo3(signature = (path, **placement))]
fn load_mesh(
    py: Python<'_>,
    path: std::path::PathBuf,
    placement: Option<&Bound<'_, PyDict>>,
) -> PyResult<PyMesh> {
    let text = path.to_string_lossy().into_owned();
    let source = mss_scene::Scene::source_of(
        &text,
        &mss_scene::scene::SceneOrigin::Text("load_mesh".into()),
    );
    let placement = placement_of(&text, placement)?;
    let placed = detached(py, || {
        stages::load_placed(&source, &placement, &Loaders::default())
    });
    let placed = placed.map_err(|e| match &e {
        // Not a scene's path: relative to the working directory.
        StageError::Source(mss_scene::build::MeshSourceError::Missing { path }) => raise(
            Kind::Mesh,
            format!(
                "mesh file {} does not exist (a relative path is relative to the working \
                 directory, {})",
                path.display(),
                std::env::current_dir()
                    .map_or_else(|_| "unknown".into(), |d| d.display().to_string())
            ),
        ),
        _ => stage_error(&e),
    })?;
    Ok(PyMesh::wrap(placed.mesh, placed.name))
}

/// voxelize(mesh, *, cells=None, cell_size=None, rule="centre", fraction=0.5, components="largest", max_cells=10_000_000, progress=None)
/// --
///
/// The cubic lattice of a mesh, with the keys of a scene's `[voxelize]`
/// table: `cells` along the longest axis (default 24) or `cell_size` (m),
/// the occupancy `rule` (`"centre"`, `"any"`, `"fraction"`), the kept
/// `components` (`"largest"`, `"all"`) and the largest lattice accepted.
/// Refused with ResourceError when the bounding grid or an explicit run of
/// the lattice would need more than three quarters of the machine's memory.
/// `progress(stage, done, total)` is called as grid rows are classified.
#[pyfunction]
#[pyo3(signature = (mesh, *, progress=None, **options))]
fn voxelize(
    py: Python<'_>,
    mesh: &PyMesh,
    progress: Option<Py<PyAny>>,
    options: Option<&Bound<'_, PyDict>>,
) -> PyResult<PyLattice> {
    let section: VoxelizeSection = from_py("voxelize", kwargs_dict(py, options).as_any())?;
    let opts = section
        .check()
        .and_then(|()| section.options(&mss_scene::Registry::default().occupancy))
        .map_err(|e| {
            let key = if e.key.is_empty() { "voxelize" } else { &e.key };
            raise(Kind::Voxelize, format!("{key} {}", e.message))
        })?;
    let m = Arc::clone(&mesh.mesh);
    let reporter = crate::progress::Reporter::new(progress);
    let hook = |done: u64, total: u64| reporter.report("voxelizing", done, total);
    let limits = Limits::default();
    let vox = detached(py, || {
        stages::lattice_within(
            &m,
            &mesh.name,
            &opts,
            &limits,
            stages::RunNeeds::EXPLICIT,
            &hook,
        )
    });
    reporter.finish()?;
    let vox = vox.map_err(|e| stage_error(&e))?;
    Ok(PyLattice::wrap(vox.lattice))
}

/// A cubic lattice of cells (hexahedra) and their corner nodes.
#[pyclass(name = "Lattice", module = "hexmss", frozen)]
pub struct PyLattice {
    pub lattice: Arc<Lattice>,
    nodes: OnceLock<Py<PyArray2<f64>>>,
    cells: OnceLock<Py<PyArray2<u32>>>,
}

impl PyLattice {
    pub fn wrap(lattice: Lattice) -> Self {
        Self::shared(Arc::new(lattice))
    }
    pub fn shared(lattice: Arc<Lattice>) -> Self {
        Self {
            lattice,
            nodes: OnceLock::new(),
            cells: OnceLock::new(),
        }
    }
}

#[pymethods]
impl PyLattice {
    /// Lattice.block(n, h, origin=(0, 0, 0))
    ///
    /// A box of n = (nx, ny, nz) cells of edge h (m) from `origin`.
    #[staticmethod]
    #[pyo3(signature = (n, h, origin = [0.0; 3]))]
    fn block(n: [u32; 3], h: f64, origin: [f64; 3]) -> PyResult<Self> {
        Lattice::block(n, h, origin)
            .map(Self::wrap)
            .map_err(|e| from_error(Kind::Voxelize, &e))
    }

    /// Rest positions of the nodes, (N, 3) float64, read-only (m).
    #[getter]
    fn nodes<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        cached(py, &self.nodes, |py| {
            points_array(py, self.lattice.nodes().to_vec())
        })
    }

    /// The 8 corner nodes of each cell, (C, 8) uint32, read-only, in the
    /// order of VTK_HEXAHEDRON.
    #[getter]
    fn cells<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<u32>>> {
        cached(py, &self.cells, |py| {
            index_array(py, self.lattice.cells().to_vec())
        })
    }

    /// Integer grid coordinates of each cell, (C, 3) uint32.
    #[getter]
    fn cell_coords<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<u32>> {
        index_array(py, self.lattice.cell_coords().to_vec())
    }

    /// Integer grid coordinates of each node, (N, 3) uint32.
    #[getter]
    fn node_coords<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<u32>> {
        index_array(py, self.lattice.node_coords().to_vec())
    }

    /// Cell edge (m).
    #[getter]
    fn h(&self) -> f64 {
        self.lattice.h()
    }

    /// Position of grid node (0, 0, 0) (m).
    #[getter]
    fn origin(&self) -> [f64; 3] {
        self.lattice.origin()
    }

    /// Grid dimensions in cells.
    #[getter]
    fn dims(&self) -> [u32; 3] {
        self.lattice.dims()
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

    /// Volume of the cells (m^3).
    #[getter]
    fn volume(&self) -> f64 {
        self.lattice.volume()
    }

    /// The boundary faces as a triangle skin bound to the nodes.
    fn skin(&self) -> PySkin {
        PySkin {
            skin: mss_scene::hexmesh::boundary_skin(&self.lattice),
        }
    }

    /// embed(mesh)
    ///
    /// Binds each vertex of `mesh` to the cell holding it (trilinear
    /// weights), so that the surface follows the lattice.
    fn embed(&self, py: Python<'_>, mesh: &PyMesh) -> PyEmbedding {
        let l = Arc::clone(&self.lattice);
        let m = Arc::clone(&mesh.mesh);
        PyEmbedding {
            embedding: Arc::new(detached(py, || Embedding::new(&l, &m))),
        }
    }

    fn __repr__(&self) -> String {
        format!(
            "Lattice({} cells, {} nodes, h = {} m, dims {:?})",
            self.lattice.num_cells(),
            self.lattice.num_nodes(),
            self.lattice.h(),
            self.lattice.dims()
        )
    }
}

/// The lattice's boundary as triangles whose vertices follow nodes.
#[pyclass(name = "Skin", module = "hexmss", frozen)]
pub struct PySkin {
    pub skin: mss_scene::hexmesh::Skin,
}

#[pymethods]
impl PySkin {
    /// The node each skin vertex follows, (V,) uint32.
    #[getter]
    fn vertex_nodes<'py>(&self, py: Python<'py>) -> Bound<'py, numpy::PyArray1<u32>> {
        numpy::PyArray1::from_slice(py, &self.skin.vertex_nodes)
    }

    /// Triangles as skin vertex indices, (T, 3) uint32, outward.
    #[getter]
    fn triangles<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<u32>> {
        index_array(py, self.skin.triangles.clone())
    }

    /// positions(node_positions)
    ///
    /// Skin vertex positions, (V, 3), for node positions (N, 3) (m).
    fn positions<'py>(
        &self,
        py: Python<'py>,
        node_positions: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let x = points_in("node_positions", node_positions)?;
        if let Some(&bad) = self
            .skin
            .vertex_nodes
            .iter()
            .find(|&&n| n as usize >= x.len())
        {
            return Err(pyo3::exceptions::PyValueError::new_err(format!(
                "node_positions: {} rows, but the skin follows node {bad}",
                x.len()
            )));
        }
        Ok(points_array(py, self.skin.positions(&x)))
    }
}

/// A surface embedded in a lattice: its vertices move trilinearly with the
/// cell holding them.
#[pyclass(name = "Embedding", module = "hexmss", frozen)]
pub struct PyEmbedding {
    pub embedding: Arc<Embedding>,
}

#[pymethods]
impl PyEmbedding {
    /// Triangles of the embedded surface, (T, 3) uint32.
    #[getter]
    fn triangles<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<u32>> {
        index_array(py, self.embedding.triangles().to_vec())
    }

    /// deform(node_positions)
    ///
    /// Vertex positions of the surface, (V, 3), for node positions (N, 3) (m).
    fn deform<'py>(
        &self,
        py: Python<'py>,
        node_positions: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let x = points_in("node_positions", node_positions)?;
        let needed = self
            .embedding
            .vertex_cells()
            .iter()
            .flatten()
            .map(|&n| n as usize + 1)
            .max()
            .unwrap_or(0);
        if x.len() < needed {
            return Err(pyo3::exceptions::PyValueError::new_err(format!(
                "node_positions: {} rows, but the surface follows {needed} nodes",
                x.len()
            )));
        }
        let e = Arc::clone(&self.embedding);
        let out = detached(py, || e.deform(&x));
        Ok(points_array(py, out))
    }
}
