//! The stages from a mesh to a lattice, shared by every front end: the
//! scene's [`Job`](crate::Job), `mss voxelize` and the Python package call
//! these and nothing else, so that the guards (memory estimated before
//! anything is allocated, the lattice's cell limit) and the messages are
//! the same wherever a body is built.
//!
//! - [`load_placed`]: a mesh from a file or the bundled ones, cleaned, then
//!   moved, scaled and turned by a [`Placement`].
//! - [`lattice_within`]: the mesh voxelized under a memory limit: the
//!   bounding grid is estimated before it is allocated, the lattice is
//!   built only up to the cells the memory allows, and the run that would
//!   follow (with or without matrices) is estimated before it is returned.
//! - [`problem`]: a model under constraints, loads, damping and obstacles
//!   given in the scene's syntax ([`ProblemSpecs`]).
//!
//! ```
//! use mss_scene::hexmesh::{Placement, Resolution, VoxelizeOptions};
//! use mss_scene::limits::Limits;
//! use mss_scene::scene::MeshSource;
//! use mss_scene::stages::{RunNeeds, lattice_within, load_placed};
//!
//! let source = MeshSource::Builtin("critter".into());
//! let placed = load_placed(&source, &Placement::default(), &Default::default()).unwrap();
//! let options = VoxelizeOptions {
//!     resolution: Resolution::CellsAlongLongestAxis(12),
//!     ..Default::default()
//! };
//! let vox = lattice_within(&placed.mesh, &placed.name, &options, &Limits::default(), RunNeeds::EXPLICIT, &|_, _| {}).unwrap();
//! assert!(vox.lattice.num_cells() > 100);
//!
//! // A memory limit too small for the bounding grid is refused before
//! // anything is allocated.
//! let tiny = Limits { memory_bytes: 1000, ..Limits::default() };
//! let err = lattice_within(&placed.mesh, &placed.name, &options, &tiny, RunNeeds::EXPLICIT, &|_, _| {}).unwrap_err();
//! assert!(err.to_string().contains("bounding grid"), "{err}");
//! ```

use hexmesh::Embedding;
use hexmesh::image::ImageLattice;
use hexmesh::image::resample::IMAGE_GRID_BYTES_PER_CELL;
use hexmesh::load::{LoadReport, Loaders};
use hexmesh::voxelize::{GRID_BYTES_PER_CELL, LATTICE_BYTES_PER_CELL, plan_grid};
use hexmesh::{Placement, PlacementError, TriMesh, VoxelizeError, VoxelizeOptions, Voxelized};
use mss_core::constraints::ConstraintSpec;
use mss_core::contact::{ContactSettings, Obstacle, ObstacleError};
use mss_core::loads::Damping;
use mss_core::solver::{Problem, ProblemError};
use mss_core::{LoadSpec, Model};
use thiserror::Error;

use crate::build::{MeshSourceError, load_mesh};
use crate::error::human;
use crate::kind_table::KindTable;
use crate::limits::{Limits, cell_budget, mesh_memory_estimate, run_memory_estimate};
use crate::obstacles::{ObstacleSpec, Shapes, build_contact_with};
use crate::scene::LoadKinds;
use crate::scene::MeshSource;

/// A mesh loaded, cleaned and placed.
#[derive(Debug, Clone)]
pub struct PlacedMesh {
    /// Its name in messages (the file, or `builtin:NAME`).
    pub name: String,
    /// The cleaned mesh, placed (m).
    pub mesh: TriMesh,
    /// What cleaning did.
    pub report: LoadReport,
}

/// Why a stage failed. The messages name the mesh; a front end adds the
/// scene, the command or the call.
#[derive(Debug, Error)]
pub enum StageError {
    /// The mesh could not be had (unknown built-in, missing file, a loader's
    /// error).
    #[error(transparent)]
    Source(#[from] MeshSourceError),
    /// The placement does not apply to the mesh (it would overflow or
    /// flatten it).
    #[error("{mesh}: {source}")]
    Placement {
        /// The mesh.
        mesh: String,
        /// Why.
        source: PlacementError,
    },
    /// A stage would need more memory than the limit.
    #[error(
        "{what} would need about {} of memory, more than the limit of {} ({limit_origin}); use a coarser resolution{hint}",
        human(*needed), human(*limit)
    )]
    Memory {
        /// What would need it.
        what: String,
        /// Estimated bytes.
        needed: u64,
        /// The limit (bytes).
        limit: u64,
        /// Where the limit comes from.
        limit_origin: &'static str,
        /// What else can be done, starting with ", " (or empty).
        hint: &'static str,
    },
    /// The label image could not be read.
    #[error(transparent)]
    Image(#[from] hexmesh::image::ImageError),
    /// No voxel of the image carries the labels chosen.
    #[error("{image}: no voxel carries {wanted}; the image's labels are {present:?}")]
    NoLabelledVoxels {
        /// The image.
        image: String,
        /// The labels asked for, in words.
        wanted: String,
        /// The labels the image holds.
        present: Vec<i32>,
    },
    /// The voxelizer refused the mesh or the options.
    #[error("cannot voxelize {mesh}: {source}")]
    Voxelize {
        /// The mesh.
        mesh: String,
        /// Why.
        source: VoxelizeError,
    },
}

/// Loads the mesh `source` names with `loaders` and applies `placement`.
pub fn load_placed(
    source: &MeshSource,
    placement: &Placement,
    loaders: &Loaders,
) -> Result<PlacedMesh, StageError> {
    let (name, mut loaded) = load_mesh(source, loaders)?;
    placement
        .apply(&mut loaded.mesh)
        .map_err(|source| StageError::Placement {
            mesh: name.clone(),
            source,
        })?;
    if !placement.is_identity() {
        log::info!("{name}: placed with {placement}");
    }
    Ok(PlacedMesh {
        name,
        mesh: loaded.mesh,
        report: loaded.report,
    })
}

/// Largest extent (m) of a soft body this tool is made for: an organ, a
/// tool, a toy or a piece of furniture; larger meshes are most likely in
/// millimetres or centimetres, read as metres.
pub const PLAUSIBLE_EXTENT_MAX: f64 = 5.0;
/// Smallest plausible extent (m): smaller meshes are most likely in metres
/// scaled down twice, or in another unit.
pub const PLAUSIBLE_EXTENT_MIN: f64 = 0.005;

/// What is odd about the size of a placed mesh for a soft body (its
/// largest extent), if anything: the front end adds how to change its
/// units or scale in its own terms.
///
/// ```
/// use mss_scene::hexmesh::generate::box_mesh;
/// use mss_scene::stages::implausible_size;
/// assert!(implausible_size(&box_mesh([0.0; 3], [9.7, 1.0, 1.0])).unwrap().contains("9.700 m across"));
/// assert!(implausible_size(&box_mesh([0.0; 3], [0.2; 3])).is_none());
/// assert!(implausible_size(&box_mesh([0.0; 3], [0.0002; 3])).is_some());
/// ```
pub fn implausible_size(mesh: &TriMesh) -> Option<String> {
    let extent = mesh
        .bounding_box()?
        .extent()
        .into_iter()
        .fold(0.0, f64::max);
    if extent > PLAUSIBLE_EXTENT_MAX {
        Some(format!(
            "the mesh is {extent:.3} m across, large for a soft body: if its coordinates are \
             millimetres or centimetres, say so"
        ))
    } else if extent < PLAUSIBLE_EXTENT_MIN {
        Some(format!(
            "the mesh is {extent:.3e} m across, small for a soft body: check its unit and scale"
        ))
    } else {
        None
    }
}

/// The run a lattice is built for: its memory depends on whether the
/// solver assembles matrices.
#[derive(Debug, Clone, Copy)]
pub struct RunNeeds<'a> {
    /// The solver's name, in messages (`"explicit"`, `"static"`, ...).
    pub solver: &'a str,
    /// Whether it assembles matrices (an implicit or static solve).
    pub needs_matrix: bool,
}

impl RunNeeds<'_> {
    /// An explicit run (no matrices): what `mss voxelize` and a lattice
    /// made for inspection are measured against.
    pub const EXPLICIT: RunNeeds<'static> = RunNeeds {
        solver: "explicit",
        needs_matrix: false,
    };
}

/// Voxelizes `mesh` (named `mesh_name` in errors) with `options` within `limits.memory_bytes`: the cells
/// are capped at what that memory can run for `run`, the bounding grid is
/// estimated before it is allocated, and the run's estimate is checked on
/// the lattice built. `progress(done, total)` follows the grid's rows.
pub fn lattice_within(
    mesh: &TriMesh,
    mesh_name: &str,
    options: &VoxelizeOptions,
    limits: &Limits,
    run: RunNeeds<'_>,
    progress: &(dyn Fn(u64, u64) + Sync),
) -> Result<Voxelized, StageError> {
    let needs_matrix = run.needs_matrix;
    let matrix_hint = matrix_hint(needs_matrix);
    let memory =
        |what: String, needed: u64, hint: &'static str| memory_error(limits, what, needed, hint);
    let mut opts = options.clone();
    let budget = cell_budget(limits.memory_bytes, needs_matrix);
    let memory_binds = budget < opts.max_cells;
    opts.max_cells = opts.max_cells.min(budget);
    // The grid is allocated whole while classifying: estimate it first.
    if let Ok(grid) = plan_grid(mesh, &opts) {
        let needed = grid.len() as u64 * GRID_BYTES_PER_CELL;
        if needed > limits.memory_bytes {
            return Err(memory(
                format!("voxelizing (a bounding grid of {:?} cells)", grid.dims),
                needed,
                "",
            ));
        }
    }
    let vox =
        hexmesh::voxelize_with_progress(mesh, &opts, progress).map_err(|source| match source {
            VoxelizeError::TooManyCells { cells, .. } if memory_binds => memory(
                format!("a lattice of {cells} cells"),
                run_memory_estimate(cells as usize, cells as usize, needs_matrix)
                    + cells * LATTICE_BYTES_PER_CELL,
                matrix_hint,
            ),
            source => StageError::Voxelize {
                mesh: mesh_name.to_owned(),
                source,
            },
        })?;
    check_run_memory(&vox.lattice, mesh.vertices.len(), limits, run)?;
    Ok(vox)
}

fn memory_error(limits: &Limits, what: String, needed: u64, hint: &'static str) -> StageError {
    StageError::Memory {
        what,
        needed,
        limit: limits.memory_bytes,
        limit_origin: limits.memory_origin(),
        hint,
    }
}

/// What else frees memory when a run needs matrices.
fn matrix_hint(needs_matrix: bool) -> &'static str {
    if needs_matrix {
        ", or the explicit solver (no matrices)"
    } else {
        ""
    }
}

/// Refuses a run on `lattice` (with an input surface of `surface_vertices`)
/// whose estimate exceeds the limit.
fn check_run_memory(
    lattice: &hexmesh::Lattice,
    surface_vertices: usize,
    limits: &Limits,
    run: RunNeeds<'_>,
) -> Result<(), StageError> {
    let needed = run_memory_estimate(lattice.num_cells(), lattice.num_nodes(), run.needs_matrix)
        + mesh_memory_estimate(surface_vertices);
    if needed > limits.memory_bytes {
        return Err(memory_error(
            limits,
            format!("the {} run of {} cells", run.solver, lattice.num_cells()),
            needed,
            matrix_hint(run.needs_matrix),
        ));
    }
    Ok(())
}

/// A label image read and resampled by [`image_lattice_within`].
#[derive(Debug, Clone)]
pub struct PlacedImage {
    /// Its name in messages (the file).
    pub name: String,
    /// Voxels along i, j, k.
    pub dims: [usize; 3],
    /// Voxel spacing along i, j, k (m).
    pub spacing: [f64; 3],
    /// The lattice, the label of each cell and the labels' surface (m).
    pub lattice: ImageLattice,
}

/// What [`image_lattice_within`] makes of a label image.
#[derive(Debug, Clone)]
pub struct ImageChoice<'a> {
    /// Which labels form the body (`None`: every non-zero label).
    pub labels: Option<&'a [i32]>,
    /// Fraction of a cell the labels must cover (0 < t <= 1).
    pub threshold: f64,
    /// Metres per unit of the file's coordinates (`None`: the file's unit,
    /// else millimetres).
    pub unit_metres: Option<f64>,
    /// The frame to express the file's coordinates in (`None`: the file's).
    pub space: Option<hexmesh::image::Space>,
    /// Placement after the file's transform and unit.
    pub placement: Placement,
}

/// Reads the label image at `path` and resamples the labels `choice` names
/// onto cubes at `options`' resolution, within `limits.memory_bytes`: the
/// voxels' memory is estimated from the header before they are read, the
/// resampling grid before it is allocated (refused past the limit), and the
/// cells are capped at what the memory can run for `run`.
pub fn image_lattice_within(
    path: &std::path::Path,
    choice: &ImageChoice<'_>,
    options: &VoxelizeOptions,
    limits: &Limits,
    run: RunNeeds<'_>,
) -> Result<PlacedImage, StageError> {
    let name = path.display().to_string();
    let image_limits = hexmesh::image::ImageLimits {
        max_bytes: limits.memory_bytes,
    };
    let mut image = hexmesh::image::load_image(path, &image_limits)?;
    if let Some(target) = &choice.space {
        image = image.in_space(target);
    }
    choice
        .placement
        .validate()
        .map_err(|source| StageError::Placement {
            mesh: name.clone(),
            source,
        })?;
    let unit = choice
        .unit_metres
        .unwrap_or_else(|| image.unit_metres_or_default());
    let to_metres = image.to_metres(unit, &choice.placement);
    let budget = cell_budget(limits.memory_bytes, run.needs_matrix);
    let memory_binds = budget < options.max_cells;
    let resample_options = hexmesh::image::ImageVoxelizeOptions {
        labels: choice.labels.map(<[i32]>::to_vec),
        resolution: options.resolution,
        threshold: choice.threshold,
        padding_cells: options.padding_cells,
        max_cells: options.max_cells.min(budget),
        max_grid_cells: limits.memory_bytes / IMAGE_GRID_BYTES_PER_CELL,
        components: options.components,
    };
    let memory =
        |what: String, needed: u64, hint: &'static str| memory_error(limits, what, needed, hint);
    let lattice =
        hexmesh::image::resample(&image, &to_metres, &resample_options).map_err(|source| {
            match source {
                VoxelizeError::GridTooLarge { dims, cells, .. } => memory(
                    format!("resampling the image (a grid of {dims:?} cells)"),
                    cells.saturating_mul(IMAGE_GRID_BYTES_PER_CELL),
                    "",
                ),
                VoxelizeError::TooManyCells { cells, .. } if memory_binds => memory(
                    format!("a lattice of {cells} cells"),
                    run_memory_estimate(cells as usize, cells as usize, run.needs_matrix)
                        + cells * LATTICE_BYTES_PER_CELL,
                    matrix_hint(run.needs_matrix),
                ),
                VoxelizeError::EmptyMesh => StageError::NoLabelledVoxels {
                    image: name.clone(),
                    wanted: match choice.labels {
                        Some(l) => format!("the labels {l:?}"),
                        None => "a non-zero label".into(),
                    },
                    present: image.label_counts().keys().copied().collect(),
                },
                source => StageError::Voxelize {
                    mesh: name.clone(),
                    source,
                },
            }
        })?;
    let spacing = {
        let s = image.spacing();
        std::array::from_fn(|k| s[k] * unit)
    };
    check_run_memory(
        &lattice.lattice,
        lattice.surface.vertices.len(),
        limits,
        run,
    )?;
    Ok(PlacedImage {
        name,
        dims: image.dims,
        spacing,
        lattice,
    })
}

/// What a problem is made of besides its model, as a scene's tables (or a
/// front end's arguments in the same syntax) give it.
#[derive(Debug, Clone, Copy)]
pub struct ProblemSpecs<'a> {
    /// Held nodes and prescribed motions, in order (`[[fixed]]`, then
    /// `[[motions]]`).
    pub constraints: &'a [ConstraintSpec],
    /// Gravity, forces, tractions, drags.
    pub loads: &'a [LoadSpec],
    /// Loads by kind (`[[loads.custom]]`), after `loads`.
    pub custom_loads: &'a [KindTable],
    /// The load kinds `custom_loads` may name.
    pub load_kinds: &'a LoadKinds,
    /// Mass and stiffness damping.
    pub damping: Damping,
    /// The `[[obstacles]]` tables.
    pub obstacles: &'a [ObstacleSpec],
    /// Which points of the body touch the obstacles.
    pub points: mss_core::contact::ContactPoints,
    /// The shapes the obstacles may name.
    pub shapes: &'a Shapes,
}

/// Why [`problem`] failed.
#[derive(Debug, Error)]
pub enum ProblemStageError {
    /// An obstacle could not be built (index into [`ProblemSpecs::obstacles`]).
    #[error("obstacle #{}: {source}", index + 1)]
    Obstacle {
        /// Its index.
        index: usize,
        /// Why.
        source: ObstacleError,
    },
    /// A constraint or load does not apply to the model.
    #[error(transparent)]
    Problem(#[from] ProblemError),
    /// A load by kind could not be built (index into
    /// [`ProblemSpecs::custom_loads`]).
    #[error("custom load #{}: {source}", index + 1)]
    CustomLoad {
        /// Its index.
        index: usize,
        /// Why.
        source: mss_core::loads::LoadError,
    },
}

/// The problem of `model` under `specs`: obstacle meshes come from
/// `mesh_of`, the embedded `surface` touches obstacles when
/// [`ProblemSpecs::points`] asks, and `extra` obstacles (an interactive
/// front end's tools) come after the scene's.
pub fn problem(
    model: Model,
    specs: &ProblemSpecs<'_>,
    mesh_of: &dyn Fn(&str) -> Result<TriMesh, String>,
    surface: Option<&Embedding>,
    extra: Vec<(Box<dyn Obstacle>, ContactSettings)>,
) -> Result<Problem, ProblemStageError> {
    let contact = build_contact_with(
        &model,
        specs.obstacles,
        specs.shapes,
        extra,
        mesh_of,
        specs.points,
        surface,
    )
    .map_err(|(index, source)| ProblemStageError::Obstacle { index, source })?;
    let custom: Vec<_> = specs
        .custom_loads
        .iter()
        .enumerate()
        .map(|(index, table)| {
            specs
                .load_kinds
                .build(table, &model)
                .map_err(|source| ProblemStageError::CustomLoad { index, source })
        })
        .collect::<Result<_, _>>()?;
    let problem = custom.into_iter().fold(
        Problem::from_specs(model, specs.constraints, specs.loads, specs.damping)?,
        Problem::with_load,
    );
    Ok(match contact {
        Some(c) => problem.with_contact(c),
        None => problem,
    })
}
