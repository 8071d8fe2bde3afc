//! Rust errors as the exceptions of `hexmss.errors`.
//!
//! The exception classes are defined in Python (so that they can also
//! derive from `ValueError`, `OSError`, ...) and looked up when raised. The
//! message is the line the `mss` CLI prints after `error: `
//! ([`mss_scene::error::one_line`]).

use mss_scene::JobError;
use mss_scene::mss_core::SolverError;
use pyo3::prelude::*;

/// The exception classes of `hexmss.errors`.
#[derive(Debug, Clone, Copy)]
pub enum Kind {
    /// A scene file, scene dict or keyword value is refused.
    Scene,
    /// A mesh cannot be read or is malformed.
    Mesh,
    /// A mesh cannot be voxelized.
    Voxelize,
    /// A material, model or problem cannot be built.
    Model,
    /// A solver failed (other than the two below).
    Solver,
    /// A run diverged (inverted cells, non-finite values, Newton failed).
    Diverged,
    /// Zero-energy motions the loads excite (no unique static solution).
    Mechanism,
    /// Writing failed, or the output folder is unusable.
    Output,
    /// A memory or disk limit refuses the job.
    Resource,
}

impl Kind {
    fn class_name(self) -> &'static str {
        match self {
            Kind::Scene => "SceneError",
            Kind::Mesh => "MeshError",
            Kind::Voxelize => "VoxelizeError",
            Kind::Model => "ModelError",
            Kind::Solver => "SolverError",
            Kind::Diverged => "DivergedError",
            Kind::Mechanism => "MechanismError",
            Kind::Output => "OutputError",
            Kind::Resource => "ResourceError",
        }
    }
}

/// An exception of class `kind` with `message`.
pub fn raise(kind: Kind, message: impl Into<String>) -> PyErr {
    let message = message.into();
    Python::attach(|py| {
        let class = py
            .import("hexmss.errors")
            .and_then(|m| m.getattr(kind.class_name()));
        match class {
            Ok(class) => match class.call1((message.clone(),)) {
                Ok(instance) => PyErr::from_value(instance),
                Err(e) => e,
            },
            // Only if the package's Python half is missing.
            Err(_) => pyo3::exceptions::PyRuntimeError::new_err(message),
        }
    })
}

/// A typed error of the library as its exception.
pub fn from_error(kind: Kind, e: &(dyn std::error::Error + 'static)) -> PyErr {
    raise(kind, mss_scene::error::one_line(e))
}

/// The class of a solver error.
pub fn solver_kind(e: &SolverError) -> Kind {
    match e {
        SolverError::Diverged { .. } | SolverError::LoadLimit { .. } => Kind::Diverged,
        SolverError::Mechanism { .. } | SolverError::UnstableEquilibrium { .. } => Kind::Mechanism,
        SolverError::BadOption(_)
        | SolverError::BadTimeStep(_)
        | SolverError::UnknownIntegrator { .. }
        | SolverError::StateSize { .. } => Kind::Scene,
        _ => Kind::Solver,
    }
}

/// A solver error as its exception.
pub fn solver(e: SolverError) -> PyErr {
    match e {
        SolverError::UnstableEquilibrium { .. } => raise(
            Kind::Mechanism,
            format!(
                "{}; pass accept_unstable=True to keep it",
                mss_scene::error::one_line(&e)
            ),
        ),
        e => from_error(solver_kind(&e), &e),
    }
}

/// A job error as its exception.
pub fn job(e: JobError) -> PyErr {
    let kind = match &e {
        JobError::Scene(_) | JobError::Setting { .. } | JobError::Resume { .. } => Kind::Scene,
        JobError::Mesh { .. } => Kind::Mesh,
        JobError::Voxelize { .. } => Kind::Voxelize,
        JobError::Model { .. } | JobError::WouldFold { .. } => Kind::Model,
        JobError::Solver { source, .. } => solver_kind(source),
        JobError::OutputFolder { .. } | JobError::Output(_) => Kind::Output,
        JobError::Memory { .. } | JobError::DiskSpace { .. } => Kind::Resource,
    };
    from_error(kind, &e)
}
