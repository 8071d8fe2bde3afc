//! Writing frames and skins: `write_vtu`, `write_obj`, `write_stl`. Every
//! file is written atomically (a temporary file, then a rename).

use std::path::PathBuf;

use mss_scene::mss_io::skin::Normals;
use mss_scene::mss_io::vtk::{Field, LatticeFrame, VtuEncoding};
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::convert::{indices_in, points_in};
use crate::errors::{Kind, from_error, raise};
use crate::geometry::PyLattice;
use crate::threads::detached;

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(write_vtu, m)?)?;
    m.add_function(wrap_pyfunction!(write_obj, m)?)?;
    m.add_function(wrap_pyfunction!(write_stl, m)?)?;
    Ok(())
}

/// A data array given by the user: one scalar or one 3-vector per entity.
enum Values {
    Scalars(Vec<f64>),
    Vectors(Vec<[f64; 3]>),
}

fn fields_in(
    what: &str,
    d: Option<&Bound<'_, PyDict>>,
    count: usize,
) -> PyResult<Vec<(String, Values)>> {
    let mut out = Vec::new();
    let Some(d) = d else { return Ok(out) };
    for (k, v) in d.iter() {
        let name: String = k
            .extract()
            .map_err(|_| PyTypeError::new_err(format!("{what}: names must be strings")))?;
        let label = format!("{what}[{name:?}]");
        let values = match v.extract::<numpy::PyArrayLike1<'_, f64, numpy::AllowTypeChange>>() {
            Ok(a) => Values::Scalars(a.as_array().to_vec()),
            Err(_) => Values::Vectors(points_in(&label, &v)?),
        };
        let len = match &values {
            Values::Scalars(s) => s.len(),
            Values::Vectors(s) => s.len(),
        };
        if len != count {
            return Err(PyValueError::new_err(format!(
                "{label}: {len} values, expected {count}"
            )));
        }
        out.push((name, values));
    }
    Ok(out)
}

/// write_vtu(path, lattice, positions=None, *, point_data=None, cell_data=None, encoding="zlib")
/// --
///
/// Writes the lattice (its cells as VTK_HEXAHEDRON) at node `positions`
/// (default: rest) as a `.vtu` file for ParaView, with optional point and
/// cell arrays (name -> (N,) scalars or (N, 3) vectors). `encoding` is
/// `"zlib"` (compressed, default), `"base64"` or `"ascii"`.
#[pyfunction]
#[pyo3(signature = (path, lattice, positions = None, *, point_data = None, cell_data = None, encoding = "zlib"))]
fn write_vtu(
    py: Python<'_>,
    path: PathBuf,
    lattice: &PyLattice,
    positions: Option<&Bound<'_, PyAny>>,
    point_data: Option<&Bound<'_, PyDict>>,
    cell_data: Option<&Bound<'_, PyDict>>,
    encoding: &str,
) -> PyResult<()> {
    let l = &lattice.lattice;
    let points = match positions {
        Some(p) => {
            let p = points_in("positions", p)?;
            if p.len() != l.num_nodes() {
                return Err(PyValueError::new_err(format!(
                    "positions: {} rows, the lattice has {} nodes",
                    p.len(),
                    l.num_nodes()
                )));
            }
            p
        }
        None => l.nodes().to_vec(),
    };
    let encoding = match encoding {
        "zlib" => VtuEncoding::Base64Zlib,
        "base64" => VtuEncoding::Base64,
        "ascii" => VtuEncoding::Ascii,
        other => {
            return Err(raise(
                Kind::Scene,
                format!("encoding = {other:?}: use \"zlib\", \"base64\" or \"ascii\""),
            ));
        }
    };
    let pf = fields_in("point_data", point_data, l.num_nodes())?;
    let cf = fields_in("cell_data", cell_data, l.num_cells())?;
    let l = std::sync::Arc::clone(l);
    detached(py, || {
        let mut frame = LatticeFrame::new(&points, l.cells());
        for (name, v) in &pf {
            frame = frame.with_point_field(field(name, v));
        }
        for (name, v) in &cf {
            frame = frame.with_cell_field(field(name, v));
        }
        mss_scene::mss_io::vtk::write_vtu(&path, &frame, encoding)
    })
    .map_err(|e| from_error(Kind::Output, &e))
}

fn field<'a>(name: &'a str, v: &'a Values) -> Field<'a> {
    match v {
        Values::Scalars(s) => Field::scalars(name, s),
        Values::Vectors(s) => Field::vectors(name, s),
    }
}

/// write_obj(path, vertices, triangles, *, normals="smooth")
/// --
///
/// Writes a triangle surface as Wavefront OBJ (for Blender and the like);
/// `normals` is `"smooth"` (per vertex) or `"flat"` (per triangle, right
/// for the voxel skin).
#[pyfunction]
#[pyo3(signature = (path, vertices, triangles, *, normals = "smooth"))]
fn write_obj(
    py: Python<'_>,
    path: PathBuf,
    vertices: &Bound<'_, PyAny>,
    triangles: &Bound<'_, PyAny>,
    normals: &str,
) -> PyResult<()> {
    let v = points_in("vertices", vertices)?;
    let t = indices_in::<3>("triangles", triangles, Some(v.len()))?;
    let normals = match normals {
        "smooth" => Normals::Smooth,
        "flat" => Normals::Flat,
        other => {
            return Err(raise(
                Kind::Scene,
                format!("normals = {other:?}: use \"smooth\" or \"flat\""),
            ));
        }
    };
    detached(py, || {
        mss_scene::mss_io::skin::write_obj_with(&path, &v, &t, normals)
    })
    .map_err(|e| from_error(Kind::Output, &e))
}

/// write_stl(path, vertices, triangles)
/// --
///
/// Writes a triangle surface as binary STL.
#[pyfunction]
fn write_stl(
    py: Python<'_>,
    path: PathBuf,
    vertices: &Bound<'_, PyAny>,
    triangles: &Bound<'_, PyAny>,
) -> PyResult<()> {
    let v = points_in("vertices", vertices)?;
    let t = indices_in::<3>("triangles", triangles, Some(v.len()))?;
    detached(py, || mss_scene::mss_io::skin::write_stl(&path, &v, &t))
        .map_err(|e| from_error(Kind::Output, &e))
}
