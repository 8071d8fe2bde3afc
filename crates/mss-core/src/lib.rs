//! # mss-core
//!
//! The hexahedral mass-spring model (MSS) of Baudet et al. (WSCG 2009) as
//! defined in the project's `docs/model.md`: per-cell edge and body-diagonal springs
//! whose stiffnesses follow from Young's modulus and Poisson's ratio, lumped
//! masses, and the correction forces that make the lattice reproduce both E and
//! nu. Also boundary conditions, loads, and explicit / implicit / static
//! solvers. The FEM reference and the experiments are in `mss-validate`.
//!
//! Knows nothing of file formats: it takes a [`hexmesh::Lattice`].

pub mod constraints;
pub mod contact;
pub mod loads;
pub mod material;
pub mod model;
pub mod modes;
pub mod simulation;
pub mod solver;
pub mod sparse;
pub mod springs;

pub use constraints::{ConstraintSpec, Constraints, NodeSelector};
pub use loads::{Damping, Load, LoadSpec};
pub use material::{Material, MaterialError};
pub use model::{
    CellCoefficients, CellDiagnostics, ForceWorkspace, HourglassControl, HourglassError, Model,
    ModelError, PaperModel, Parameterization, ParameterizationError, Parameterizations,
    SpringsOnly, UnknownParameterization, Volumetric, VolumetricBarrier,
};
pub use solver::{
    Integrator, Integrators, Problem, SolverError, State, StaticOptions, solve_static,
};
pub use sparse::{BlockCsr, Factorization, LinearSolveError};
pub use springs::{SpringError, SpringSet};

/// 3-vectors of the simulation (`f64`).
pub type Vec3 = nalgebra::Vector3<f64>;
/// 3x3 matrices of the simulation (`f64`).
pub type Mat3 = nalgebra::Matrix3<f64>;
