//! Conversions between Python values and the library's: numpy arrays of
//! points and indices, and Python dicts as the serde values the scene
//! schema deserializes (so keyword options take exactly the scene's keys).

use mss_scene::mss_core::Vec3;
use numpy::ndarray::Array2;
use numpy::{AllowTypeChange, IntoPyArray, PyArray2, PyArrayLike2};
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{IntoPyDict, PyBool, PyDict, PyFloat, PyInt, PyList, PyString, PyTuple};
use serde::de::DeserializeOwned;

use crate::errors::{Kind, raise};

/// An `(n, 3)` float64 array that owns `points` (moved, not copied).
pub fn points_array(py: Python<'_>, points: Vec<[f64; 3]>) -> Bound<'_, PyArray2<f64>> {
    let n = points.len();
    Array2::from_shape_vec((n, 3), points.into_flattened())
        .expect("n x 3 values")
        .into_pyarray(py)
}

/// An `(n, 3)` float64 array of vectors (one copy out of nalgebra's type).
pub fn vec3_array<'py>(py: Python<'py>, v: &[Vec3]) -> Bound<'py, PyArray2<f64>> {
    points_array(py, v.iter().map(|p| [p.x, p.y, p.z]).collect())
}

/// An `(n, K)` uint32 array that owns `rows`.
pub fn index_array<const K: usize>(
    py: Python<'_>,
    rows: Vec<[u32; K]>,
) -> Bound<'_, PyArray2<u32>> {
    let n = rows.len();
    Array2::from_shape_vec((n, K), rows.into_flattened())
        .expect("n x K values")
        .into_pyarray(py)
}

/// Marks an array read-only (for arrays a value owns and hands out cached).
pub fn read_only<'py, T>(a: Bound<'py, T>) -> PyResult<Bound<'py, T>> {
    let kwargs = [("write", false)].into_py_dict(a.py())?;
    a.as_any().call_method("setflags", (), Some(&kwargs))?;
    Ok(a)
}

/// Rows of an `(n, 3)` array-like of numbers, as points.
pub fn points_in(what: &str, a: &Bound<'_, PyAny>) -> PyResult<Vec<[f64; 3]>> {
    let arr: PyArrayLike2<'_, f64, AllowTypeChange> = a.extract().map_err(|_| {
        PyTypeError::new_err(format!(
            "{what}: give an (n, 3) array of numbers (numpy array or nested lists)"
        ))
    })?;
    let view = arr.as_array();
    if view.ncols() != 3 {
        return Err(PyValueError::new_err(format!(
            "{what}: expected shape (n, 3), got {:?}",
            view.shape()
        )));
    }
    let mut out = Vec::with_capacity(view.nrows());
    for (i, row) in view.rows().into_iter().enumerate() {
        let p = [row[0], row[1], row[2]];
        if !p.iter().all(|c| c.is_finite()) {
            return Err(PyValueError::new_err(format!(
                "{what}: row {i} is {p:?}: every coordinate must be finite"
            )));
        }
        out.push(p);
    }
    Ok(out)
}

/// Rows of an `(n, 3)` array-like as vectors, checked against `expected` rows.
pub fn vec3_in(what: &str, a: &Bound<'_, PyAny>, expected: usize) -> PyResult<Vec<Vec3>> {
    let p = points_in(what, a)?;
    if p.len() != expected {
        return Err(PyValueError::new_err(format!(
            "{what}: expected {expected} rows (one per node), got {}",
            p.len()
        )));
    }
    Ok(p.into_iter().map(Vec3::from).collect())
}

/// Rows of an `(n, K)` array-like of non-negative integers below `bound`.
pub fn indices_in<const K: usize>(
    what: &str,
    a: &Bound<'_, PyAny>,
    bound: Option<usize>,
) -> PyResult<Vec<[u32; K]>> {
    let arr: PyArrayLike2<'_, i64, AllowTypeChange> = a.extract().map_err(|_| {
        PyTypeError::new_err(format!(
            "{what}: give an (n, {K}) array of integers (numpy array or nested lists)"
        ))
    })?;
    let view = arr.as_array();
    if view.ncols() != K {
        return Err(PyValueError::new_err(format!(
            "{what}: expected shape (n, {K}), got {:?}",
            view.shape()
        )));
    }
    let mut out = Vec::with_capacity(view.nrows());
    for (i, row) in view.rows().into_iter().enumerate() {
        let mut r = [0u32; K];
        for (k, &v) in row.iter().enumerate() {
            let ok = v >= 0 && v <= u32::MAX as i64 && bound.is_none_or(|b| (v as u64) < b as u64);
            if !ok {
                return Err(PyValueError::new_err(match bound {
                    Some(b) => format!("{what}: row {i} has index {v}: indices must be in 0..{b}"),
                    None => format!("{what}: row {i} has index {v}: indices must be non-negative"),
                }));
            }
            r[k] = v as u32;
        }
        out.push(r);
    }
    Ok(out)
}

/// Node indices (a sequence or 1-d array of integers).
pub fn node_list(what: &str, a: &Bound<'_, PyAny>, nodes: usize) -> PyResult<Vec<u32>> {
    let v: Vec<i64> = match a.extract::<numpy::PyReadonlyArray1<'_, i64>>() {
        Ok(arr) => arr.as_array().to_vec(),
        Err(_) => a.extract().map_err(|_| {
            PyTypeError::new_err(format!("{what}: give a sequence of node indices"))
        })?,
    };
    v.into_iter()
        .map(|i| {
            if i >= 0 && (i as u64) < nodes as u64 {
                Ok(i as u32)
            } else {
                Err(PyValueError::new_err(format!(
                    "{what}: node {i} does not exist (the model has {nodes} nodes)"
                )))
            }
        })
        .collect()
}

/// A Python value (dicts, lists, tuples, numbers, strings, numpy arrays and
/// scalars) as a JSON value; `None` in a dict drops the key.
pub fn to_json(what: &str, v: &Bound<'_, PyAny>) -> PyResult<serde_json::Value> {
    use serde_json::Value;
    if v.is_none() {
        return Ok(Value::Null);
    }
    if v.is_instance_of::<PyBool>() {
        return Ok(Value::Bool(v.extract()?));
    }
    if v.is_instance_of::<PyInt>() {
        return Ok(match v.extract::<i64>() {
            Ok(i) => Value::from(i),
            Err(_) => Value::from(v.extract::<u64>()?),
        });
    }
    if v.is_instance_of::<PyFloat>() {
        let f: f64 = v.extract()?;
        return serde_json::Number::from_f64(f)
            .map(Value::Number)
            .ok_or_else(|| raise(Kind::Scene, format!("{what}: {f} is not a finite number")));
    }
    if v.is_instance_of::<PyString>() {
        return Ok(Value::String(v.extract()?));
    }
    if let Ok(d) = v.cast::<PyDict>() {
        let mut map = serde_json::Map::new();
        for (k, val) in d.iter() {
            let key: String = k.extract().map_err(|_| {
                PyTypeError::new_err(format!("{what}: keys must be strings, got {k}"))
            })?;
            if val.is_none() {
                continue;
            }
            let inner = to_json(&format!("{what}.{key}"), &val)?;
            map.insert(key, inner);
        }
        return Ok(Value::Object(map));
    }
    if v.is_instance_of::<PyList>() || v.is_instance_of::<PyTuple>() {
        let mut out = Vec::new();
        for (i, item) in v.try_iter()?.enumerate() {
            out.push(to_json(&format!("{what}[{i}]"), &item?)?);
        }
        return Ok(Value::Array(out));
    }
    // numpy arrays and scalars.
    if v.hasattr("tolist")? {
        return to_json(what, &v.call_method0("tolist")?);
    }
    Err(PyTypeError::new_err(format!(
        "{what}: cannot use a value of type {} here (give dicts, lists, numbers, strings or booleans)",
        v.get_type().name()?
    )))
}

/// A Python value deserialized as the scene schema's `T`; errors name `what`.
pub fn from_py<T: DeserializeOwned>(what: &str, v: &Bound<'_, PyAny>) -> PyResult<T> {
    let json = to_json(what, v)?;
    serde_path_to_error::deserialize(json).map_err(|e| {
        let path = e.path().to_string();
        let inner = e.into_inner();
        if path == "." || path.is_empty() {
            raise(Kind::Scene, format!("{what}: {inner}"))
        } else {
            raise(Kind::Scene, format!("{what}: {path}: {inner}"))
        }
    })
}

/// Keyword arguments as a dict (empty if none).
pub fn kwargs_dict<'py>(py: Python<'py>, kw: Option<&Bound<'py, PyDict>>) -> Bound<'py, PyDict> {
    kw.cloned().unwrap_or_else(|| PyDict::new(py))
}

/// The Python object in `cell`, made by `make` at the first call: a getter
/// that hands out a large value (a model, a lattice) builds it once.
pub fn cached_object<T>(
    py: Python<'_>,
    cell: &std::sync::OnceLock<Py<T>>,
    make: impl FnOnce() -> T,
) -> PyResult<Py<T>>
where
    T: pyo3::PyClass + Into<pyo3::PyClassInitializer<T>>,
{
    if let Some(o) = cell.get() {
        return Ok(o.clone_ref(py));
    }
    let o = Py::new(py, make())?;
    Ok(cell.get_or_init(|| o).clone_ref(py))
}
