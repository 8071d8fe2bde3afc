//! The error type of building and running a job.

use std::path::PathBuf;

use thiserror::Error;

use crate::scene::SceneError;

/// Why a job could not be built or did not finish. Every message is one line
/// that names the scene (file or bundled default) and the key or stage
/// concerned, and says what to change.
#[derive(Debug, Error)]
pub enum JobError {
    /// The scene file could not be read or parsed, or a value is out of range.
    #[error(transparent)]
    Scene(#[from] SceneError),
    /// A value is refused once it meets the mesh, the library or the
    /// registry (an unknown name, a material outside the model's range, a
    /// selection that selects nothing, ...).
    #[error("{scene}: {key}: {message}")]
    Setting {
        /// Scene name.
        scene: String,
        /// The key, as `[table] key` or `[[array]] #n`.
        key: String,
        /// What is wrong and what to do.
        message: String,
    },
    /// A dynamic run refused before it starts: the static solve of the
    /// scene's load says that the chosen model would fold or turn cells
    /// inside out under it (docs/robustness.md, causes 1 to 3).
    #[error("{scene}: not run: {reason}; {remedy}")]
    WouldFold {
        /// Scene name.
        scene: String,
        /// What the static solve of the load found, and what it means.
        reason: String,
        /// What to change, and the key that runs it anyway.
        remedy: String,
    },
    /// The mesh could not be loaded.
    #[error("{scene}: [mesh] path: {source}")]
    Mesh {
        /// Scene name.
        scene: String,
        /// What the loader said.
        source: hexmesh::LoadError,
    },
    /// The mesh could not be voxelized.
    #[error("{scene}: cannot voxelize {mesh}: {source}")]
    Voxelize {
        /// Scene name.
        scene: String,
        /// Mesh name.
        mesh: String,
        /// What the voxelizer said.
        source: hexmesh::VoxelizeError,
    },
    /// The model could not be built from the lattice and material.
    #[error("{scene}: cannot build the model: {source}")]
    Model {
        /// Scene name.
        scene: String,
        /// What the model said.
        source: mss_core::ModelError,
    },
    /// A solver failed (the simulation diverged, Newton did not converge, a
    /// static problem is singular, ...). What was simulated up to the last
    /// good state has been written.
    #[error("{scene}: {stage}: {source}")]
    Solver {
        /// Scene name.
        scene: String,
        /// `"static solve failed"` or `"the simulation failed"`.
        stage: &'static str,
        /// What the solver said.
        source: Box<mss_core::SolverError>,
    },
    /// The output folder cannot be created or written.
    #[error("the output folder {} {problem}: {source}", path.display())]
    OutputFolder {
        /// The folder.
        path: PathBuf,
        /// `"cannot be created"` or `"is not writable"`.
        problem: &'static str,
        /// The operating system's error.
        source: std::io::Error,
    },
    /// Writing an output file failed.
    #[error(transparent)]
    Output(#[from] mss_io::IoError),
    /// A run cannot be resumed from the checkpoint in its folder.
    #[error("{scene}: cannot resume the run in {}: {message}", folder.display())]
    Resume {
        /// Scene name.
        scene: String,
        /// The output folder.
        folder: PathBuf,
        /// Why.
        message: String,
    },
    /// The job would need more memory than the limit.
    #[error(
        "{scene}: {what} would need about {} of memory, more than the limit of {} ({}); use a coarser resolution{}",
        human(*needed), human(*limit), limit_origin, hint
    )]
    Memory {
        /// Scene name.
        scene: String,
        /// What would need it.
        what: String,
        /// Estimated bytes.
        needed: u64,
        /// The limit (bytes).
        limit: u64,
        /// Where the limit comes from.
        limit_origin: &'static str,
        /// What else can be done, starting with ", ".
        hint: &'static str,
    },
    /// The output would not fit on the disk.
    #[error(
        "{scene}: the run would write about {} into {} ({frames} frames of about {} each), but only {} are free there; write fewer frames (`[output] every_time`, `last_only`), fewer file kinds, or into another folder",
        human(*needed), folder.display(), human(*frame_bytes), human(*free)
    )]
    DiskSpace {
        /// Scene name.
        scene: String,
        /// Output folder.
        folder: PathBuf,
        /// Frames the run writes.
        frames: u64,
        /// Estimated bytes per frame.
        frame_bytes: u64,
        /// Estimated bytes in all.
        needed: u64,
        /// Free bytes.
        free: u64,
    },
}

/// The messages of an error and its causes, each on one line (whitespace
/// runs folded), a cause left out when the message before already says it
/// (as wrappers that quote their source do): what every front end prints.
pub fn causes(e: &(dyn std::error::Error + 'static)) -> Vec<String> {
    let flat = |s: String| s.split_whitespace().collect::<Vec<_>>().join(" ");
    let mut parts: Vec<String> = Vec::new();
    let mut cause = Some(e);
    while let Some(c) = cause {
        let text = flat(c.to_string());
        if !parts.last().is_some_and(|prev| prev.contains(&text)) {
            parts.push(text);
        }
        cause = c.source();
    }
    parts
}

/// [`causes`] joined by ": ": the one-line message of an error.
pub fn one_line(e: &(dyn std::error::Error + 'static)) -> String {
    causes(e).join(": ")
}

/// Bytes with a binary unit, for messages.
pub fn human(bytes: u64) -> String {
    const UNITS: [&str; 5] = ["B", "KiB", "MiB", "GiB", "TiB"];
    let mut v = bytes as f64;
    let mut u = 0;
    while v >= 1024.0 && u + 1 < UNITS.len() {
        v /= 1024.0;
        u += 1;
    }
    if u == 0 {
        format!("{bytes} B")
    } else {
        format!("{v:.1} {}", UNITS[u])
    }
}
