//! Label images: `load_image` (the voxels' labels and their transform) and
//! `voxelize_image` (the chosen labels as a lattice of cubes, with each
//! cell's label and the labels' surface).

use std::collections::BTreeMap;

use mss_scene::hexmesh::image::{ImageLimits, LabelImage, Space, load_image as read_image};
use mss_scene::limits::Limits;
use mss_scene::scene::{ImageSection, VoxelizeSection};
use mss_scene::stages;
use numpy::ndarray::{Array1, Array2};
use numpy::{IntoPyArray, PyArray1, PyArray2};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::convert::{from_py, kwargs_dict};
use crate::errors::{Kind, from_error, raise};
use crate::geometry::{PyLattice, PyMesh, stage_error};
use crate::threads::detached;

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyImage>()?;
    m.add_class::<PyImageLattice>()?;
    m.add_function(wrap_pyfunction!(load_image, m)?)?;
    m.add_function(wrap_pyfunction!(voxelize_image, m)?)?;
    Ok(())
}

/// A label volume: one integer label per voxel, and where the voxels are.
#[pyclass(name = "Image", module = "hexmss", frozen)]
pub struct PyImage {
    image: LabelImage,
    name: String,
}

fn space_name(space: &Space) -> String {
    match space {
        Space::Ras => "RAS".into(),
        Space::Lps => "LPS".into(),
        Space::Other(s) => s.clone(),
    }
}

#[pymethods]
impl PyImage {
    /// The labels, int32, indexed ``labels[i, j, k]`` (shape ``(ni, nj,
    /// nk)``, as nibabel and pynrrd give them), read-only.
    #[getter]
    fn labels<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let [ni, nj, nk] = self.image.dims;
        let flat = Array1::from_vec(self.image.labels.clone()).into_pyarray(py);
        // Stored with i fastest: a C-ordered (k, j, i) array, transposed.
        let a = flat
            .call_method1("reshape", ((nk, nj, ni),))?
            .getattr("T")?;
        crate::convert::read_only(a)
    }

    /// The 4 x 4 voxel-to-world matrix (the file's units): voxel ``(i, j,
    /// k)`` is centred at ``affine @ (i, j, k, 1)``.
    #[getter]
    fn affine<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        let mut m = Array2::<f64>::zeros((4, 4));
        for r in 0..3 {
            for c in 0..4 {
                m[[r, c]] = self.image.affine[r][c];
            }
        }
        m[[3, 3]] = 1.0;
        m.into_pyarray(py)
    }

    /// Voxels along i, j, k.
    #[getter]
    fn shape(&self) -> (usize, usize, usize) {
        let [a, b, c] = self.image.dims;
        (a, b, c)
    }

    /// Voxel spacing along i, j, k (the file's units).
    #[getter]
    fn spacing(&self) -> [f64; 3] {
        self.image.spacing()
    }

    /// Metres per unit of the world coordinates, as the file says, or
    /// None when it does not (read as millimetres then).
    #[getter]
    fn unit_metres(&self) -> Option<f64> {
        self.image.unit_metres
    }

    /// The frame of the world coordinates: "RAS", "LPS", or the name the
    /// file gives another.
    #[getter]
    fn space(&self) -> String {
        space_name(&self.image.space)
    }

    /// The file it was read from.
    #[getter]
    fn name(&self) -> &str {
        &self.name
    }

    /// The number of voxels of each label, as a dict.
    fn label_counts(&self) -> BTreeMap<i32, usize> {
        self.image.label_counts()
    }

    fn __repr__(&self) -> String {
        let [a, b, c] = self.image.dims;
        format!(
            "Image({:?}, {a} x {b} x {c} voxels, spacing {:?}, space {})",
            self.name,
            self.image.spacing(),
            space_name(&self.image.space)
        )
    }
}

/// load_image(path)
/// --
///
/// Reads a label image: NIfTI-1 or NIfTI-2 (``.nii``, ``.nii.gz``, a
/// ``.hdr`` beside its ``.img``) or NRRD (``.nrrd``, ``.nhdr`` with its data
/// file), any integer voxel type (or whole-numbered floats), either byte
/// order. The voxels' memory is estimated from the header and refused past
/// three quarters of the machine's memory (ResourceError) before they are
/// read; a damaged file raises MeshError naming the file and the field.
#[pyfunction]
fn load_image(py: Python<'_>, path: std::path::PathBuf) -> PyResult<PyImage> {
    let limits = ImageLimits {
        max_bytes: Limits::default().memory_bytes,
    };
    let image = detached(py, || read_image(&path, &limits));
    let image = image.map_err(|e| {
        let kind = match e {
            mss_scene::hexmesh::image::ImageError::TooLarge { .. } => Kind::Resource,
            _ => Kind::Mesh,
        };
        from_error(kind, &e)
    })?;
    Ok(PyImage {
        image,
        name: path.display().to_string(),
    })
}

/// The lattice of a label image: its cells, the label of each, and the
/// labels' surface.
#[pyclass(name = "ImageLattice", module = "hexmss", frozen)]
pub struct PyImageLattice {
    lattice: Py<PyLattice>,
    surface: Py<PyMesh>,
    cell_labels: Vec<i32>,
    voxels_per_label: Vec<(i32, usize)>,
}

#[pymethods]
impl PyImageLattice {
    /// The cubic lattice (a Lattice, as ``voxelize`` gives).
    #[getter]
    fn lattice(&self, py: Python<'_>) -> Py<PyLattice> {
        self.lattice.clone_ref(py)
    }

    /// The label covering most of each cell, (C,) int32.
    #[getter]
    fn cell_labels<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<i32>> {
        Array1::from_vec(self.cell_labels.clone()).into_pyarray(py)
    }

    /// The chosen labels' boundary (m), a Mesh that embeds in the lattice
    /// like a surface file's.
    #[getter]
    fn surface(&self, py: Python<'_>) -> Py<PyMesh> {
        self.surface.clone_ref(py)
    }

    /// Voxels of each chosen label, as a dict.
    #[getter]
    fn voxels_per_label(&self) -> BTreeMap<i32, usize> {
        self.voxels_per_label.iter().copied().collect()
    }

    fn __repr__(&self) -> String {
        format!(
            "ImageLattice({:?}, {} cells, voxels per label {:?})",
            self.surface.get().name,
            self.lattice.get().lattice.num_cells(),
            self.voxels_per_label(),
        )
    }
}

/// Keys of a scene's `[image]` table (besides `path`).
const IMAGE_KEYS: [&str; 6] = [
    "labels",
    "threshold",
    "units",
    "space",
    "rotate",
    "translate",
];

/// voxelize_image(path, *, labels=None, threshold=0.5, units=None, space="file", rotate=(0, 0, 0), translate=(0, 0, 0), cells=24, cell_size=None, components="largest", max_cells=10000000)
/// --
///
/// The voxels of a label image whose labels are in ``labels`` (default:
/// every non-zero label), resampled onto cubic cells: ``cells`` along the
/// longest axis of the labelled region, or ``cell_size`` (m). A cell is kept
/// when the labels cover at least ``threshold`` of it, and takes the label
/// covering most of it. ``units`` ("m", "cm", "mm") overrides the file's
/// unit; ``space`` ("file", "RAS", "LPS") the frame; ``rotate`` (degrees)
/// and ``translate`` (m) place it after its own transform. The keys are
/// those of a scene's ``[image]`` and ``[voxelize]`` tables.
#[pyfunction]
#[pyo3(signature = (path, **options))]
fn voxelize_image(
    py: Python<'_>,
    path: std::path::PathBuf,
    options: Option<&Bound<'_, PyDict>>,
) -> PyResult<PyImageLattice> {
    let all = kwargs_dict(py, options);
    let image_keys = PyDict::new(py);
    let voxelize_keys = PyDict::new(py);
    for (k, v) in all.iter() {
        let key: String = k.extract()?;
        if key == "rule" || key == "fraction" {
            return Err(raise(
                Kind::Voxelize,
                format!(
                    "{key}: an image's cells are kept by the fraction its labels cover: give threshold="
                ),
            ));
        }
        if IMAGE_KEYS.contains(&key.as_str()) {
            image_keys.set_item(k, v)?;
        } else {
            voxelize_keys.set_item(k, v)?;
        }
    }
    image_keys.set_item("path", path.display().to_string())?;
    let section: ImageSection = from_py("voxelize_image", image_keys.as_any())?;
    let voxelize: VoxelizeSection = from_py("voxelize_image", voxelize_keys.as_any())?;
    let check =
        |e: mss_scene::scene::KeyError| raise(Kind::Voxelize, format!("{} {}", e.key, e.message));
    section.check().map_err(check)?;
    let options = voxelize
        .check()
        .and_then(|()| voxelize.options(&mss_scene::Registry::default().occupancy))
        .map_err(check)?;
    let choice = stages::ImageChoice {
        labels: section.labels.as_deref(),
        threshold: section.threshold,
        unit_metres: section.units.map(|u| u.factor()),
        space: section.space.target(),
        placement: section.placement(),
    };
    let limits = Limits::default();
    let placed = detached(py, || {
        stages::image_lattice_within(
            &path,
            &choice,
            &options,
            &limits,
            stages::RunNeeds::EXPLICIT,
        )
    });
    let placed = placed.map_err(|e| stage_error(&e))?;
    let out = placed.lattice;
    Ok(PyImageLattice {
        lattice: Py::new(py, PyLattice::wrap(out.lattice))?,
        surface: Py::new(py, PyMesh::wrap(out.surface, placed.name))?,
        cell_labels: out.cell_labels,
        voxels_per_label: out.voxels_per_label,
    })
}
