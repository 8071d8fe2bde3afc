//! The model: per-cell springs, lumped masses, correction forces (MODEL.md).
//!
//! SKELETON: the bodies marked `todo!` are being written; signatures are the
//! contract other modules build against. Extend, do not break, without telling
//! the integrator.

use std::fmt::Debug;

use hexmesh::Lattice;
use thiserror::Error;

use crate::{BlockCsr, Material, MaterialError, Vec3};

/// Why a model could not be built.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum ModelError {
    /// A material parameter is invalid for the chosen parameterization.
    #[error(transparent)]
    Material(#[from] MaterialError),
    /// The per-cell material table does not match the lattice.
    #[error("cell {cell} refers to material {index}, but only {count} materials were given")]
    MaterialIndex {
        /// Cell index.
        cell: usize,
        /// Material index given for it.
        index: u32,
        /// Number of materials.
        count: usize,
    },
    /// `cell_material` has the wrong length.
    #[error("{given} per-cell material indices given for {cells} cells")]
    MaterialCount {
        /// Entries given.
        given: usize,
        /// Cells in the lattice.
        cells: usize,
    },
}

/// The per-cell constants a parameterization derives from a material and the
/// cell edge `h`. The force kernel is shared by all parameterizations; they
/// differ only in these numbers.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CellCoefficients {
    /// Stiffness of each of the cell's 12 edge springs (N/m), rest length h.
    pub k_edge: f64,
    /// Stiffness of each of the 4 body-diagonal springs (N/m), rest length sqrt(3) h.
    pub k_diag: f64,
    /// Correction coefficient `c = (4 nu - 1) / 2` of MODEL.md step 4, or
    /// `None` for no correction forces.
    pub correction: Option<f64>,
    /// Lame lambda (Pa) of the one-point volumetric energy
    /// `lambda h^3 (J - 1)^2 / 2` (0 for none).
    pub volumetric_lambda: f64,
}

/// Maps a material to per-cell spring constants: the plugin point for spring
/// parameterizations. Implement it to try your own.
pub trait Parameterization: Send + Sync + Debug {
    /// Short name used by scene files and the CLI (e.g. `"paper"`).
    fn name(&self) -> &'static str;
    /// Checks the material against the range this parameterization supports.
    fn validate(&self, material: &Material) -> Result<(), MaterialError>;
    /// The per-cell constants for cells of edge `h` (m).
    fn coefficients(&self, material: &Material, h: f64) -> CellCoefficients;
}

/// The paper's model (M2 lattice with correction forces), exact E and nu in
/// uniaxial tension for -0.25 < nu < 0.5.
#[derive(Debug, Clone, Copy, Default)]
pub struct PaperModel;

/// Springs only: the paper's stiffnesses without correction forces (the
/// "classic MSS"); it measures nu' = 1 / (4 nu + 3) in tension.
#[derive(Debug, Clone, Copy, Default)]
pub struct SpringsOnly;

fn paper_springs(m: &Material, h: f64) -> (f64, f64) {
    let nu = m.poisson;
    let k_edge = m.young * h * (4.0 * nu + 1.0) / (8.0 * (1.0 + nu));
    let k_diag = 3.0 * m.young * h / (8.0 * (1.0 + nu));
    (k_edge, k_diag)
}

impl Parameterization for PaperModel {
    fn name(&self) -> &'static str {
        "paper"
    }
    fn validate(&self, material: &Material) -> Result<(), MaterialError> {
        Material::new(material.young, material.poisson, material.density).map(|_| ())
    }
    fn coefficients(&self, material: &Material, h: f64) -> CellCoefficients {
        let (k_edge, k_diag) = paper_springs(material, h);
        CellCoefficients {
            k_edge,
            k_diag,
            correction: Some((4.0 * material.poisson - 1.0) / 2.0),
            volumetric_lambda: 0.0,
        }
    }
}

impl Parameterization for SpringsOnly {
    fn name(&self) -> &'static str {
        "springs"
    }
    fn validate(&self, material: &Material) -> Result<(), MaterialError> {
        Material::new(material.young, material.poisson, material.density).map(|_| ())
    }
    fn coefficients(&self, material: &Material, h: f64) -> CellCoefficients {
        let (k_edge, k_diag) = paper_springs(material, h);
        CellCoefficients {
            k_edge,
            k_diag,
            correction: None,
            volumetric_lambda: 0.0,
        }
    }
}

/// The built-in parameterizations by name: `"paper"` (default), `"springs"`.
pub fn parameterization_by_name(name: &str) -> Option<Box<dyn Parameterization>> {
    match name {
        "paper" => Some(Box::new(PaperModel)),
        "springs" => Some(Box::new(SpringsOnly)),
        _ => None,
    }
}

/// Names accepted by [`parameterization_by_name`].
pub const PARAMETERIZATION_NAMES: &[&str] = &["paper", "springs"];

/// A lattice turned into a mass-spring model. Positions are absolute (m).
#[derive(Debug, Clone)]
pub struct Model {
    // Fields are private: see the module docs of the implementation.
    rest: Vec<Vec3>,
    cells: Vec<[u32; 8]>,
    h: f64,
    masses: Vec<f64>,
}

impl Model {
    /// Builds the model of `lattice` for one material everywhere.
    pub fn new(
        lattice: &Lattice,
        material: Material,
        param: &dyn Parameterization,
    ) -> Result<Self, ModelError> {
        let _ = (lattice, material, param);
        todo!()
    }

    /// Rest positions of the nodes (m).
    pub fn rest_positions(&self) -> &[Vec3] {
        &self.rest
    }
    /// Cells (VTK_HEXAHEDRON order).
    pub fn cells(&self) -> &[[u32; 8]] {
        &self.cells
    }
    /// Cell edge (m).
    pub fn h(&self) -> f64 {
        self.h
    }
    /// Lumped node masses (kg).
    pub fn masses(&self) -> &[f64] {
        &self.masses
    }
    /// Number of nodes.
    pub fn num_nodes(&self) -> usize {
        self.rest.len()
    }
    /// Internal forces at positions `x` (N), written to `out`.
    pub fn internal_forces(&self, x: &[Vec3], out: &mut [Vec3]) {
        let _ = (x, out);
        todo!()
    }
    /// Jacobian d(internal force)/dx at `x` (N/m), pattern of
    /// [`BlockCsr::lattice_pattern`].
    pub fn tangent(&self, x: &[Vec3]) -> BlockCsr {
        let _ = x;
        todo!()
    }
    /// Stable explicit time step estimate (s), with safety margin.
    pub fn stable_time_step(&self) -> f64 {
        todo!()
    }
}
