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

mod cache;
pub mod constraints;

/// Vectors as plain coordinate triples, without copying (for writers and
/// bindings that take `[f64; 3]`).
pub fn as_arrays(v: &[Vec3]) -> &[[f64; 3]] {
    // SAFETY: Vector3<f64> is a repr(C) wrapper of [[f64; 3]; 1], so the
    // slice has the layout of a slice of [f64; 3] of the same length.
    unsafe { std::slice::from_raw_parts(v.as_ptr().cast::<[f64; 3]>(), v.len()) }
}

/// [`as_arrays`] of a mutable slice.
pub(crate) fn as_arrays_mut(v: &mut [Vec3]) -> &mut [[f64; 3]] {
    // SAFETY: as `as_arrays`; the borrow is handed on.
    unsafe { std::slice::from_raw_parts_mut(v.as_mut_ptr().cast::<[f64; 3]>(), v.len()) }
}

/// A deterministic pseudo-random number in [-1, 1) (a linear congruential
/// step of `seed`), for the unit tests' random inputs.
#[cfg(test)]
pub(crate) fn noise(seed: &mut u64) -> f64 {
    *seed = seed
        .wrapping_mul(6_364_136_223_846_793_005)
        .wrapping_add(1_442_695_040_888_963_407);
    (*seed >> 11) as f64 / (1u64 << 52) as f64 - 1.0
}

/// Runs `f` on a pool of `threads` threads (the unit tests' check that
/// results do not depend on the thread count).
#[cfg(test)]
pub(crate) fn on_threads<R: Send>(threads: usize, f: impl FnOnce() -> R + Send) -> R {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .expect("a thread pool")
        .install(f)
}

/// Runs `f` on a thread of the current rayon pool (the global one outside
/// any pool), waiting for it. A step makes a dozen parallel passes; called
/// from a thread outside the pool, each of them would hand its work to the
/// pool and sleep until it is done, which costs more than the pass itself on
/// small models. On a worker they run without those hand-offs; inside a
/// pool already, `f` just runs.
pub fn on_worker<R: Send>(f: impl FnOnce() -> R + Send) -> R {
    if rayon::current_thread_index().is_some() {
        f()
    } else {
        rayon::scope(|_| f())
    }
}
pub mod contact;
mod krylov;
pub mod loads;
pub mod material;
pub mod model;
pub mod modes;
pub mod plane;
pub mod simulation;
pub mod solver;
pub mod sparse;
pub mod springs;

pub use constraints::{ConstraintSpec, Constraints, NodeSelector};
pub use loads::{Damping, Load, LoadSpec};
pub use material::{Material, MaterialError};
pub use model::{
    BodySpan, CellChecks, CellCoefficients, CellDiagnostics, CellMeasure, ForceOperations,
    ForceWorkspace, HourglassControl, HourglassError, Model, ModelError, PaperModel,
    Parameterization, ParameterizationError, Parameterizations, Precision, SpringsOnly,
    UnknownParameterization, Volumetric, VolumetricBarrier,
};
pub use solver::{
    Integrator, Integrators, Problem, SolverError, State, StaticOptions, solve_static,
};
pub use sparse::{BlockCsr, Factorization, LinearSolveError};
pub use springs::{SpringError, SpringSet};

/// The 64-bit FNV-1a hash of `bytes`: a fingerprint that stays the same
/// across builds and platforms (checkpoints store it; the standard
/// library's hasher may change between releases).
///
/// ```
/// assert_eq!(mss_core::fnv1a(*b""), 0xcbf2_9ce4_8422_2325);
/// assert_ne!(mss_core::fnv1a(*b"a"), mss_core::fnv1a(*b"b"));
/// ```
pub fn fnv1a(bytes: impl IntoIterator<Item = u8>) -> u64 {
    bytes.into_iter().fold(0xcbf2_9ce4_8422_2325, |h, b| {
        (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3)
    })
}

/// 3-vectors of the simulation (`f64`).
pub type Vec3 = nalgebra::Vector3<f64>;
/// 3x3 matrices of the simulation (`f64`).
pub type Mat3 = nalgebra::Matrix3<f64>;
