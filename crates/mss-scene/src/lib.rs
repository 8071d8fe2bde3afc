//! # mss-scene
//!
//! Scene files and running them: what every front end of the hexahedral
//! mass-spring system (the `mss` CLI, a Python package, a viewer, a user's
//! own program) shares.
//!
//! - [`scene`]: the TOML schema. Tables deserialize into the libraries' own
//!   parameter types where they have one; unknown keys are refused; every
//!   error is one line naming the file, line and column or the key.
//! - [`build`]: scene values to library parameters (mesh, voxelizer options,
//!   material and parameterization, problem, integrator, time plan).
//! - [`Registry`]: the plug points a scene names (mesh loaders,
//!   parameterizations, integrators, exporters), as one value a program
//!   extends and passes in.
//! - [`Job`]: prepare (load, voxelize, build) and run (time loop, outputs),
//!   with progress through a callback and cancellation through [`Cancel`].
//! - [`check`]: size, memory and output estimates and the mechanism warning
//!   of a prepared job; [`limits`]: the memory and disk guards that refuse a
//!   job before it allocates or writes too much.
//! - [`checkpoint`]: the state of a run in one file, so that an interrupted
//!   run resumes ([`Job::resume`]) bitwise as if it had not stopped.
//! - [`obstacles`]: the rigid obstacles of `[[obstacles]]` (contact with
//!   friction).
//! - [`regions`]: materials per region (`[[regions]]`: box, sphere or a
//!   second mesh).
//! - [`output`]: the frames of a run (lattice, skins, embedded surface,
//!   springs, point caches).
//!
//! ```
//! use mss_scene::{Cancel, Job, Registry, SceneInput, no_progress};
//!
//! let scene = SceneInput::from_toml(
//!     r#"
//!     [mesh]
//!     path = "builtin:critter"
//!     [voxelize]
//!     cells = 8
//!     [material]
//!     young = 1.0e5
//!     poisson = 0.3
//!     density = 1000.0
//!     [[fixed]]
//!     kind = "lowest_layer"
//!     [loads]
//!     gravity = [0.0, 0.0, -9.81]
//!     [solver]
//!     duration = 0.01
//!     [output]
//!     last_only = true
//!     "#,
//!     "example.toml",
//! )
//! .unwrap();
//! let job = Job::prepare(scene, Registry::default(), &no_progress).unwrap();
//! let out = tempfile::tempdir().unwrap();
//! let summary = job.run(out.path(), &no_progress, &Cancel::new()).unwrap();
//! assert_eq!(summary.frames, 1);
//! assert!(summary.max_displacement > 0.0);
//! assert!(out.path().join("lattice.pvd").exists());
//! ```

pub mod build;
pub mod check;
pub mod checkpoint;
pub mod error;
pub mod job;
pub mod kind_table;
pub mod limits;
pub mod load_check;
pub mod obstacles;
pub mod output;
pub mod plane_job;
pub mod regions;
pub mod registry;
pub mod scene;
pub mod stages;

pub use build::{SceneInput, TimePlan};
pub use error::JobError;
/// The libraries a front end needs beside the scene layer, re-exported so
/// that a front end depends on `mss-scene` alone.
pub use hexmesh;
pub use job::{
    Cancel, Job, LoadCheckBudget, Progress, ProgressFn, RunSummary, no_progress, write_summary,
};
pub use mss_core;
pub use mss_io;
pub use registry::Registry;
pub use scene::{Scene, SceneError};
