//! # mss-core
//!
//! The hexahedral mass-spring model (MSS) of Baudet et al. (WSCG 2009) as
//! defined in the project's MODEL.md: per-cell edge and body-diagonal springs
//! whose stiffnesses follow from Young's modulus and Poisson's ratio, lumped
//! masses, and the correction forces that make the lattice reproduce both E and
//! nu. Also boundary conditions, loads, explicit / implicit / static solvers,
//! virtual material tests and a small hexahedral FEM used as the reference.
//!
//! Knows nothing of file formats: it takes a [`hexmesh::Lattice`].

pub mod constraints;
pub mod experiments;
pub mod fem;
pub mod loads;
pub mod material;
pub mod material_test;
pub mod model;
pub mod modes;
pub mod solver;
pub mod sparse;
pub mod springs;

pub use constraints::{ConstraintSpec, Constraints, NodeSelector};
pub use loads::{Damping, Load, LoadSpec};
pub use material::{Material, MaterialError};
pub use material_test::{MeasuredMaterial, measure_material};
pub use model::{
    CellCoefficients, CellDiagnostics, ForceWorkspace, HourglassControl, HourglassError, Model,
    ModelError, PARAMETERIZATION_NAMES, PaperModel, Parameterization, SpringsOnly, Volumetric,
    parameterization_by_name,
};
pub use solver::{
    Integrator, Problem, SolverError, State, StaticOptions, integrator_by_name, solve_static,
};
pub use sparse::{BlockCsr, Factorization, LinearSolveError};
pub use springs::{SpringError, SpringSet};

/// 3-vectors of the simulation (`f64`).
pub type Vec3 = nalgebra::Vector3<f64>;
/// 3x3 matrices of the simulation (`f64`).
pub type Mat3 = nalgebra::Matrix3<f64>;
