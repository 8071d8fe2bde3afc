//! Voxelization: a surface mesh to a [`Lattice`] of cubic cells.
//!
//! The grid: cell edge `h` from [`Resolution`]; along each axis the grid holds
//! `ceil(extent / h)` cells (at least 1) plus `padding_cells` on both sides, and
//! is centred on the mesh's bounding box (so along the longest axis with
//! [`Resolution::CellsAlongLongestAxis`] the cells span the box exactly).
//!
//! Inside/outside is decided by the generalized winding number with threshold
//! 0.5 (exact signed crossings for closed meshes, a fast hierarchical
//! evaluation for open ones; see [`crate::winding`]). Cells are then kept by an
//! [`OccupancyRule`], and face-connected components are filtered by a
//! [`ComponentPolicy`].
//!
//! Progress: [`voxelize_with_progress`] reports the classification, the
//! dominant cost, as work units done out of a total (see [`ProgressFn`]).

use std::fmt;
use std::str::FromStr;
use std::sync::{Arc, Mutex, PoisonError};
use std::time::Instant;

use rayon::prelude::*;
use thiserror::Error;

use crate::winding::{InsideTest, WindingInside};
use crate::{Lattice, LatticeError, TriMesh};

/// How fine the grid is.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Resolution {
    /// This many cells along the longest axis of the bounding box.
    CellsAlongLongestAxis(u32),
    /// This cell edge length (m).
    CellSize(f64),
}

/// Which grid cells become lattice cells.
#[derive(Clone)]
pub enum OccupancyRule {
    /// The cell's centre is inside (default).
    Centre,
    /// The cell overlaps the solid: centre inside, or the cell box intersects
    /// a triangle (conservative).
    AnyOverlap,
    /// At least `threshold` of `samples_per_axis^3` regularly spaced samples
    /// in the cell are inside.
    Fraction {
        /// Fraction in (0, 1].
        threshold: f64,
        /// Samples per axis (>= 1).
        samples_per_axis: u32,
    },
    /// A user rule.
    Custom(Arc<dyn Occupancy>),
}

impl fmt::Debug for OccupancyRule {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Centre => write!(f, "Centre"),
            Self::AnyOverlap => write!(f, "AnyOverlap"),
            Self::Fraction {
                threshold,
                samples_per_axis,
            } => write!(
                f,
                "Fraction {{ threshold: {threshold}, samples_per_axis: {samples_per_axis} }}"
            ),
            Self::Custom(_) => write!(f, "Custom(..)"),
        }
    }
}

impl FromStr for OccupancyRule {
    type Err = String;

    /// "centre" | "center", "any", "fraction" (threshold 0.5, 4 samples per
    /// axis) or "fraction:T" / "fraction:T:S".
    fn from_str(s: &str) -> Result<Self, String> {
        let lower = s.trim().to_ascii_lowercase();
        let mut parts = lower.split(':');
        match parts.next().unwrap_or("") {
            "centre" | "center" => Ok(Self::Centre),
            "any" => Ok(Self::AnyOverlap),
            "fraction" => {
                let threshold = match parts.next() {
                    Some(t) => t
                        .parse::<f64>()
                        .map_err(|e| format!("bad fraction threshold {t:?}: {e}"))?,
                    None => 0.5,
                };
                let samples_per_axis = match parts.next() {
                    Some(t) => t
                        .parse::<u32>()
                        .map_err(|e| format!("bad samples per axis {t:?}: {e}"))?,
                    None => 4,
                };
                Ok(Self::Fraction {
                    threshold,
                    samples_per_axis,
                })
            }
            other => Err(format!(
                "unknown occupancy rule {other:?}: use centre, any, fraction or fraction:THRESHOLD:SAMPLES"
            )),
        }
    }
}

/// Which face-connected components of cells are kept.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "serde", derive(serde::Deserialize))]
pub enum ComponentPolicy {
    /// Only the component with the most cells (ties: the one whose first cell
    /// in grid order comes first; `"largest"` in a scene).
    #[default]
    #[cfg_attr(feature = "serde", serde(rename = "largest"))]
    LargestOnly,
    /// Every component (`"all"`).
    #[cfg_attr(feature = "serde", serde(rename = "all"))]
    All,
}

/// Voxelization settings.
#[derive(Debug, Clone)]
pub struct VoxelizeOptions {
    /// Grid resolution.
    pub resolution: Resolution,
    /// Which cells are occupied.
    pub rule: OccupancyRule,
    /// Empty cells added around the bounding box on every side.
    pub padding_cells: u32,
    /// Refuse lattices with more occupied cells than this (checked after
    /// classification, before the lattice is built).
    pub max_cells: u64,
    /// Refuse bounding grids with more cells than this (checked before
    /// anything is allocated; the grid costs about [`GRID_BYTES_PER_CELL`]
    /// bytes per grid cell while classifying).
    pub max_grid_cells: u64,
    /// Which components are kept.
    pub components: ComponentPolicy,
}

/// Bytes the voxelizer holds per cell of the bounding grid at its peak (the
/// occupancy, the kept component, and the rows in flight).
pub const GRID_BYTES_PER_CELL: u64 = 3;

/// Bytes a built [`Lattice`] holds per occupied cell, about (cell
/// coordinates and corners, nodes, their coordinates and the lookup).
pub const LATTICE_BYTES_PER_CELL: u64 = 120;

impl Default for VoxelizeOptions {
    fn default() -> Self {
        Self {
            resolution: Resolution::CellsAlongLongestAxis(24),
            rule: OccupancyRule::Centre,
            padding_cells: 1,
            max_cells: 10_000_000,
            max_grid_cells: 2_000_000_000,
            components: ComponentPolicy::LargestOnly,
        }
    }
}

/// Why voxelization failed.
#[derive(Debug, Error)]
pub enum VoxelizeError {
    /// The mesh has no triangles or no vertices.
    #[error("the mesh has no triangles")]
    EmptyMesh,
    /// A vertex coordinate is NaN or infinite.
    #[error("vertex {0} has a non-finite coordinate")]
    NonFinite(usize),
    /// A triangle index is out of range.
    #[error("triangle {0} refers to a vertex that does not exist")]
    BadIndex(usize),
    /// The requested resolution is unusable.
    #[error(
        "bad resolution {0}: give a positive finite cell size or at least 1 cell along the longest axis"
    )]
    BadResolution(String),
    /// The mesh's bounding box has zero extent along every axis.
    #[error("the mesh's bounding box has zero extent")]
    ZeroExtent,
    /// The cell size is larger than the mesh itself: the lattice would be a
    /// single coarse cell that does not represent the shape.
    #[error(
        "the mesh ({longest} m along its longest axis) is smaller than one cell of {h} m: \
         use a smaller cell size or more cells along the longest axis"
    )]
    MeshSmallerThanCell {
        /// Longest extent of the mesh's bounding box (m).
        longest: f64,
        /// Requested cell edge (m).
        h: f64,
    },
    /// An occupancy rule parameter is out of range.
    #[error("bad occupancy rule: {0}")]
    BadRule(String),
    /// The bounding grid would be too large to classify.
    #[error(
        "the bounding grid of {dims:?} = {cells} cells exceeds the limit of {max_grid_cells} \
         (about {} bytes per grid cell while voxelizing): use a coarser resolution",
        GRID_BYTES_PER_CELL
    )]
    GridTooLarge {
        /// Grid dimensions that would be needed.
        dims: [u64; 3],
        /// Their product.
        cells: u64,
        /// The limit.
        max_grid_cells: u64,
    },
    /// The lattice would have more occupied cells than allowed.
    #[error(
        "the lattice would have {cells} occupied cells, more than the limit of {max_cells}: use \
         a coarser resolution or raise max_cells"
    )]
    TooManyCells {
        /// Occupied cells.
        cells: u64,
        /// The limit.
        max_cells: u64,
    },
    /// No cell is occupied.
    #[error(
        "no cell is occupied at cell size {h}: the mesh is thinner than a cell or encloses nothing; use a finer resolution"
    )]
    NoCells {
        /// Cell edge (m).
        h: f64,
    },
    /// The lattice could not be built.
    #[error(transparent)]
    Lattice(#[from] LatticeError),
}

/// Counts and timings of a voxelization.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct VoxelStats {
    /// Grid dimensions (cells, padding included).
    pub grid_dims: [u32; 3],
    /// Cell edge (m).
    pub h: f64,
    /// Cells kept.
    pub cells: usize,
    /// Nodes of the kept cells.
    pub nodes: usize,
    /// Distinct cell edges of the kept cells.
    pub unique_edges: usize,
    /// Face-connected components found.
    pub components_found: usize,
    /// Components kept.
    pub components_kept: usize,
    /// Components dropped.
    pub components_dropped: usize,
    /// Cells in the dropped components.
    pub cells_dropped: usize,
    /// Volume of the kept cells (m^3).
    pub lattice_volume: f64,
    /// Absolute signed volume of the mesh after orientation repair (m^3).
    pub mesh_volume: f64,
    /// Whether the mesh was closed (exact crossings) rather than open (winding number).
    pub mesh_closed: bool,
    /// Triangles flipped by orientation repair.
    pub triangles_flipped: usize,
    /// Milliseconds spent preparing the inside test.
    pub ms_prepare: f64,
    /// Milliseconds spent classifying cells.
    pub ms_classify: f64,
    /// Milliseconds spent on connected components.
    pub ms_components: f64,
    /// Milliseconds spent building the lattice.
    pub ms_lattice: f64,
}

/// Another name for [`VoxelStats`].
pub type VoxelizeStats = VoxelStats;

/// A voxelization result.
#[derive(Debug, Clone)]
pub struct Voxelized {
    /// The kept cells.
    pub lattice: Lattice,
    /// Counts and timings.
    pub stats: VoxelStats,
}

/// The regular grid of candidate cells.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Grid {
    /// Position of grid node (0, 0, 0).
    pub origin: [f64; 3],
    /// Cell edge.
    pub h: f64,
    /// Cells along each axis.
    pub dims: [u32; 3],
}

impl Grid {
    /// Linear index of cell `(x, y, z)`: x fastest.
    pub fn index(&self, x: usize, y: usize, z: usize) -> usize {
        x + self.dims[0] as usize * (y + self.dims[1] as usize * z)
    }

    /// Number of cells.
    pub fn len(&self) -> usize {
        self.dims.iter().map(|&d| d as usize).product()
    }

    /// Whether the grid has no cells.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// What an occupancy rule gets to decide with.
pub struct OccupancyContext<'a> {
    /// The grid.
    pub grid: Grid,
    /// The (orientation-repaired) mesh.
    pub mesh: &'a TriMesh,
    /// The inside test.
    pub inside: &'a dyn InsideTest,
}

/// A user occupancy rule, the plug point for how grid cells become lattice
/// cells ([`OccupancyRule::Custom`]).
///
/// Contract: return one flag per grid cell in linear order ([`Grid::index`],
/// x fastest), `ctx.grid.len()` in all; be deterministic (the same answer for
/// any thread count); never panic. Components are filtered afterwards as the
/// options say, like for the built-in rules.
///
/// ```
/// use std::sync::Arc;
/// use hexmesh::voxelize::{Occupancy, OccupancyContext, OccupancyRule, Resolution, VoxelizeOptions};
///
/// /// Keeps the cells whose centre is inside and below the mesh's mid-height.
/// struct LowerHalf;
/// impl Occupancy for LowerHalf {
///     fn occupied(&self, ctx: &OccupancyContext<'_>) -> Vec<bool> {
///         let g = ctx.grid;
///         let [nx, ny, nz] = g.dims.map(|d| d as usize);
///         let mut out = vec![false; g.len()];
///         let mut row = vec![false; nx];
///         for z in 0..nz {
///             let cz = g.origin[2] + (z as f64 + 0.5) * g.h;
///             for y in 0..ny {
///                 let cy = g.origin[1] + (y as f64 + 0.5) * g.h;
///                 ctx.inside.classify_row(cy, cz, g.origin[0] + 0.5 * g.h, g.h, &mut row);
///                 for x in 0..nx {
///                     out[g.index(x, y, z)] = row[x] && cz < 0.5;
///                 }
///             }
///         }
///         out
///     }
/// }
///
/// let cube = hexmesh::generate::box_mesh([0.0; 3], [1.0; 3]);
/// let opts = VoxelizeOptions {
///     resolution: Resolution::CellsAlongLongestAxis(4),
///     rule: OccupancyRule::Custom(Arc::new(LowerHalf)),
///     ..VoxelizeOptions::default()
/// };
/// let vox = hexmesh::voxelize(&cube, &opts).unwrap();
/// assert_eq!(vox.lattice.num_cells(), 4 * 4 * 2);
/// ```
pub trait Occupancy: Send + Sync {
    /// Classifies every cell of `ctx.grid`.
    fn occupied(&self, ctx: &OccupancyContext<'_>) -> Vec<bool>;
}

/// Chooses the grid for `mesh`; checks the cell budget before anything is allocated.
pub fn plan_grid(mesh: &TriMesh, opts: &VoxelizeOptions) -> Result<Grid, VoxelizeError> {
    let crate::Aabb { min: lo, max: hi } = mesh.bounding_box().ok_or(VoxelizeError::EmptyMesh)?;
    if let Some(i) = mesh
        .vertices
        .iter()
        .position(|v| v.iter().any(|c| !c.is_finite()))
    {
        return Err(VoxelizeError::NonFinite(i));
    }
    grid_around(
        lo,
        hi,
        opts.resolution,
        opts.padding_cells,
        opts.max_grid_cells,
    )
}

/// The grid of cubes covering the box `lo`..`hi` (m) at `resolution`, with
/// `padding` empty cells on every side, centred on the box; refused past
/// `max_grid_cells` before anything is allocated.
pub(crate) fn grid_around(
    lo: [f64; 3],
    hi: [f64; 3],
    resolution: Resolution,
    padding: u32,
    max_grid_cells: u64,
) -> Result<Grid, VoxelizeError> {
    let ext: [f64; 3] = std::array::from_fn(|k| hi[k] - lo[k]);
    let longest = ext[0].max(ext[1]).max(ext[2]);
    if longest <= 0.0 {
        return Err(VoxelizeError::ZeroExtent);
    }
    let h = match resolution {
        Resolution::CellsAlongLongestAxis(n) if n >= 1 => longest / n as f64,
        Resolution::CellSize(h) if h.is_finite() && h > 0.0 => h,
        r => return Err(VoxelizeError::BadResolution(format!("{r:?}"))),
    };
    if h > longest {
        return Err(VoxelizeError::MeshSmallerThanCell { longest, h });
    }
    let pad = padding as u64;
    let mut dims64 = [0u64; 3];
    for k in 0..3 {
        // Tolerance so that an extent of exactly n cells gives n, not n + 1.
        let n = (ext[k] / h * (1.0 - 1e-12)).ceil().max(1.0);
        if !n.is_finite() || n > 1e12 {
            return Err(VoxelizeError::GridTooLarge {
                dims: [u64::MAX; 3],
                cells: u64::MAX,
                max_grid_cells,
            });
        }
        dims64[k] = n as u64 + 2 * pad;
    }
    let cells = dims64
        .iter()
        .try_fold(1u64, |a, &d| a.checked_mul(d))
        .unwrap_or(u64::MAX);
    if cells > max_grid_cells || dims64.iter().any(|&d| d > u32::MAX as u64 / 2) {
        return Err(VoxelizeError::GridTooLarge {
            dims: dims64,
            cells,
            max_grid_cells,
        });
    }
    let dims = dims64.map(|d| d as u32);
    let origin = std::array::from_fn(|k| 0.5 * (lo[k] + hi[k]) - 0.5 * h * dims[k] as f64);
    Ok(Grid { origin, h, dims })
}

/// A progress hook: called as `progress(done, total)` with the work units
/// (grid rows classified, plus triangles for [`OccupancyRule::AnyOverlap`];
/// one unit for a custom rule) done so far out of `total`.
///
/// It is called once with `done = 0` before classification starts, then from
/// the worker threads as rows finish, one call at a time and with `done`
/// strictly increasing, and last with `done == total`. The hook only
/// observes: the result never depends on it or on the thread count. It
/// should be cheap (a progress bar's `set_position`), since calls are
/// serialized.
pub type ProgressFn<'a> = &'a (dyn Fn(u64, u64) + Sync);

/// Voxelizes `mesh` with the built-in inside test ([`WindingInside`]).
pub fn voxelize(mesh: &TriMesh, opts: &VoxelizeOptions) -> Result<Voxelized, VoxelizeError> {
    voxelize_impl(mesh, opts, None)
}

/// Like [`voxelize`], reporting the progress of cell classification to
/// `progress` (see [`ProgressFn`]). The result is the same as [`voxelize`]'s.
pub fn voxelize_with_progress(
    mesh: &TriMesh,
    opts: &VoxelizeOptions,
    progress: ProgressFn<'_>,
) -> Result<Voxelized, VoxelizeError> {
    voxelize_impl(mesh, opts, Some(progress))
}

fn voxelize_impl(
    mesh: &TriMesh,
    opts: &VoxelizeOptions,
    progress: Option<ProgressFn<'_>>,
) -> Result<Voxelized, VoxelizeError> {
    let grid = plan_grid(mesh, opts)?;
    check_mesh(mesh)?;
    let t0 = Instant::now();
    let inside = WindingInside::new(mesh, grid.h);
    let ms_prepare = ms(t0);
    let mut v = classify_and_build(inside.oriented_mesh(), &inside, grid, opts, progress)?;
    v.stats.ms_prepare = ms_prepare;
    v.stats.mesh_closed = inside.orient_report().closed;
    v.stats.triangles_flipped = inside.orient_report().flipped;
    v.stats.mesh_volume = inside.oriented_mesh().signed_volume().abs();
    Ok(v)
}

/// Counts work units done and forwards them to a [`ProgressFn`].
///
/// The count and the call sit under one lock so that calls arrive one at a
/// time with increasing counts, whatever the order the threads finish in.
struct Reporter<'a> {
    hook: Option<ProgressFn<'a>>,
    done: Mutex<u64>,
    total: u64,
}

impl<'a> Reporter<'a> {
    fn new(hook: Option<ProgressFn<'a>>, total: u64) -> Self {
        if let Some(f) = hook {
            f(0, total);
        }
        Self {
            hook,
            done: Mutex::new(0),
            total,
        }
    }

    fn add(&self, n: u64) {
        if let Some(f) = self.hook {
            // A panicking hook poisons the lock; the count is still valid.
            let mut done = self.done.lock().unwrap_or_else(PoisonError::into_inner);
            *done = (*done + n).min(self.total);
            f(*done, self.total);
        }
    }
}

fn ms(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}

fn check_mesh(mesh: &TriMesh) -> Result<(), VoxelizeError> {
    if mesh.triangles.is_empty() {
        return Err(VoxelizeError::EmptyMesh);
    }
    let n = mesh.vertices.len();
    if let Some(t) = mesh
        .triangles
        .iter()
        .position(|t| t.iter().any(|&i| i as usize >= n))
    {
        return Err(VoxelizeError::BadIndex(t));
    }
    Ok(())
}

/// Voxelizes `mesh` on `grid` (from [`plan_grid`]) with a given inside test.
pub fn voxelize_with(
    mesh: &TriMesh,
    inside: &dyn InsideTest,
    grid: Grid,
    opts: &VoxelizeOptions,
) -> Result<Voxelized, VoxelizeError> {
    classify_and_build(mesh, inside, grid, opts, None)
}

fn classify_and_build(
    mesh: &TriMesh,
    inside: &dyn InsideTest,
    grid: Grid,
    opts: &VoxelizeOptions,
    progress: Option<ProgressFn<'_>>,
) -> Result<Voxelized, VoxelizeError> {
    check_mesh(mesh)?;
    let t0 = Instant::now();
    let ctx = OccupancyContext { grid, mesh, inside };
    let rows = grid.dims[1] as u64 * grid.dims[2] as u64;
    let occupied = match &opts.rule {
        OccupancyRule::Centre => centre_rule(&ctx, &Reporter::new(progress, rows)),
        OccupancyRule::AnyOverlap => {
            let report = Reporter::new(progress, rows + mesh.triangles.len() as u64);
            let mut occ = centre_rule(&ctx, &report);
            mark_triangle_cells(&ctx, &mut occ, &report);
            occ
        }
        &OccupancyRule::Fraction {
            threshold,
            samples_per_axis,
        } => {
            if !(threshold > 0.0 && threshold <= 1.0)
                || samples_per_axis == 0
                || samples_per_axis > 16
            {
                return Err(VoxelizeError::BadRule(format!(
                    "fraction threshold {threshold} must be in (0, 1] and samples per axis \
                     {samples_per_axis} in 1..=16"
                )));
            }
            fraction_rule(
                &ctx,
                threshold,
                samples_per_axis,
                &Reporter::new(progress, rows),
            )
        }
        OccupancyRule::Custom(rule) => {
            // A user rule classifies the whole grid in one call: one unit.
            let report = Reporter::new(progress, 1);
            let occ = rule.occupied(&ctx);
            report.add(1);
            if occ.len() != grid.len() {
                return Err(VoxelizeError::BadRule(format!(
                    "custom rule returned {} cells for a grid of {}",
                    occ.len(),
                    grid.len()
                )));
            }
            occ
        }
    };
    let ms_classify = ms(t0);
    let t1 = Instant::now();
    let (kept, found, kept_n, dropped_cells) = filter_components(&grid, occupied, opts.components);
    let ms_components = ms(t1);
    if found == 0 {
        return Err(VoxelizeError::NoCells { h: grid.h });
    }
    let occupied_cells = kept.iter().filter(|&&o| o).count() as u64;
    if occupied_cells > opts.max_cells {
        return Err(VoxelizeError::TooManyCells {
            cells: occupied_cells,
            max_cells: opts.max_cells,
        });
    }
    let t2 = Instant::now();
    let unique_edges = count_edges(&grid, &kept);
    let lattice = Lattice::from_occupancy(grid.origin, grid.h, grid.dims, &kept)?;
    let ms_lattice = ms(t2);
    let stats = VoxelStats {
        grid_dims: grid.dims,
        h: grid.h,
        cells: lattice.num_cells(),
        nodes: lattice.num_nodes(),
        unique_edges,
        components_found: found,
        components_kept: kept_n,
        components_dropped: found - kept_n,
        cells_dropped: dropped_cells,
        lattice_volume: lattice.volume(),
        mesh_volume: mesh.signed_volume().abs(),
        mesh_closed: false,
        triangles_flipped: 0,
        ms_prepare: 0.0,
        ms_classify,
        ms_components,
        ms_lattice,
    };
    log::debug!("voxelized: {stats:?}");
    Ok(Voxelized { lattice, stats })
}

fn centre_rule(ctx: &OccupancyContext<'_>, report: &Reporter<'_>) -> Vec<bool> {
    let g = ctx.grid;
    let [nx, ny, _] = g.dims.map(|d| d as usize);
    let mut occ = vec![false; g.len()];
    occ.par_chunks_mut(nx).enumerate().for_each(|(row, out)| {
        let (j, k) = (row % ny, row / ny);
        let y = g.origin[1] + (j as f64 + 0.5) * g.h;
        let z = g.origin[2] + (k as f64 + 0.5) * g.h;
        ctx.inside
            .classify_row(y, z, g.origin[0] + 0.5 * g.h, g.h, out);
        report.add(1);
    });
    occ
}

fn fraction_rule(
    ctx: &OccupancyContext<'_>,
    threshold: f64,
    s: u32,
    report: &Reporter<'_>,
) -> Vec<bool> {
    let g = ctx.grid;
    let [nx, ny, _] = g.dims.map(|d| d as usize);
    let s = s as usize;
    let need = (threshold * (s * s * s) as f64 - 1e-9).ceil().max(1.0) as usize;
    let mut occ = vec![false; g.len()];
    occ.par_chunks_mut(nx).enumerate().for_each(|(row, out)| {
        let (j, k) = (row % ny, row / ny);
        let mut count = vec![0usize; nx];
        let mut samples = vec![false; nx * s];
        let sub = g.h / s as f64;
        for b in 0..s {
            for a in 0..s {
                let y = g.origin[1] + j as f64 * g.h + (a as f64 + 0.5) * sub;
                let z = g.origin[2] + k as f64 * g.h + (b as f64 + 0.5) * sub;
                ctx.inside
                    .classify_row(y, z, g.origin[0] + 0.5 * sub, sub, &mut samples);
                for (i, c) in count.iter_mut().enumerate() {
                    *c += samples[i * s..(i + 1) * s].iter().filter(|&&v| v).count();
                }
            }
        }
        for (o, &c) in out.iter_mut().zip(&count) {
            *o = c >= need;
        }
        report.add(1);
    });
    occ
}

/// Marks every cell whose box intersects a triangle (separating axis test).
fn mark_triangle_cells(ctx: &OccupancyContext<'_>, occ: &mut [bool], report: &Reporter<'_>) {
    // Triangles per progress report: this loop is sequential and a triangle
    // takes well under a microsecond, so one call each would cost more than the work.
    const BATCH: u64 = 1024;
    let g = ctx.grid;
    let mesh = ctx.mesh;
    let mut unreported = 0u64;
    for t in &mesh.triangles {
        if unreported == BATCH {
            report.add(unreported);
            unreported = 0;
        }
        unreported += 1;
        let p = t.map(|i| mesh.vertices[i as usize]);
        let mut lo = [0usize; 3];
        let mut hi = [0usize; 3];
        for k in 0..3 {
            let a = p[0][k].min(p[1][k]).min(p[2][k]);
            let b = p[0][k].max(p[1][k]).max(p[2][k]);
            let to_cell = |v: f64| ((v - g.origin[k]) / g.h).floor();
            lo[k] = to_cell(a).max(0.0) as usize;
            hi[k] = (to_cell(b).max(0.0) as usize).min(g.dims[k] as usize - 1);
        }
        for z in lo[2]..=hi[2] {
            for y in lo[1]..=hi[1] {
                for x in lo[0]..=hi[0] {
                    let idx = g.index(x, y, z);
                    if occ[idx] {
                        continue;
                    }
                    let c = [
                        g.origin[0] + (x as f64 + 0.5) * g.h,
                        g.origin[1] + (y as f64 + 0.5) * g.h,
                        g.origin[2] + (z as f64 + 0.5) * g.h,
                    ];
                    if tri_box_overlap(c, 0.5 * g.h, p) {
                        occ[idx] = true;
                    }
                }
            }
        }
    }
    report.add(unreported);
}

/// Triangle / axis-aligned cube overlap by the separating axis theorem
/// (Akenine-Möller): the 3 box axes, the triangle normal, and the 9 cross
/// products of box axes with triangle edges. Only the open box counts:
/// a triangle that merely touches the box's boundary does not overlap it.
pub fn tri_box_overlap(centre: [f64; 3], half: f64, tri: [[f64; 3]; 3]) -> bool {
    let v: [[f64; 3]; 3] = tri.map(|p| std::array::from_fn(|k| p[k] - centre[k]));
    let e: [[f64; 3]; 3] = std::array::from_fn(|i| {
        let (a, b) = (v[i], v[(i + 1) % 3]);
        [b[0] - a[0], b[1] - a[1], b[2] - a[2]]
    });
    let separated = |axis: [f64; 3]| {
        if axis == [0.0; 3] {
            return false;
        }
        let p = v.map(|x| x[0] * axis[0] + x[1] * axis[1] + x[2] * axis[2]);
        let r = half * (axis[0].abs() + axis[1].abs() + axis[2].abs());
        let (mn, mx) = (p[0].min(p[1]).min(p[2]), p[0].max(p[1]).max(p[2]));
        mn >= r || mx <= -r
    };
    for k in 0..3 {
        let mut a = [0.0; 3];
        a[k] = 1.0;
        if separated(a) {
            return false;
        }
    }
    let n = [
        e[0][1] * e[1][2] - e[0][2] * e[1][1],
        e[0][2] * e[1][0] - e[0][0] * e[1][2],
        e[0][0] * e[1][1] - e[0][1] * e[1][0],
    ];
    if separated(n) {
        return false;
    }
    for ed in &e {
        for k in 0..3 {
            let mut u = [0.0; 3];
            u[k] = 1.0;
            let a = [
                u[1] * ed[2] - u[2] * ed[1],
                u[2] * ed[0] - u[0] * ed[2],
                u[0] * ed[1] - u[1] * ed[0],
            ];
            if separated(a) {
                return false;
            }
        }
    }
    true
}

/// Labels face-connected components; returns the kept occupancy, components
/// found, kept, and cells dropped.
///
/// Works on runs of occupied cells along x: runs in neighbouring rows (y - 1
/// or z - 1) that overlap are joined by union-find, so the cost is in runs,
/// not cells.
pub(crate) fn filter_components(
    grid: &Grid,
    occ: Vec<bool>,
    policy: ComponentPolicy,
) -> (Vec<bool>, usize, usize, usize) {
    let [nx, ny, nz] = grid.dims.map(|d| d as usize);
    let rows = ny * nz;
    // Runs [start, end) per row, in grid order.
    let mut runs: Vec<(u32, u32)> = Vec::new();
    let mut row_start = Vec::with_capacity(rows + 1);
    for r in 0..rows {
        row_start.push(runs.len());
        let row = &occ[r * nx..(r + 1) * nx];
        let mut i = 0;
        while i < nx {
            if row[i] {
                let s = i;
                while i < nx && row[i] {
                    i += 1;
                }
                runs.push((s as u32, i as u32));
            } else {
                i += 1;
            }
        }
    }
    row_start.push(runs.len());
    let mut parent: Vec<u32> = (0..runs.len() as u32).collect();
    fn find(parent: &mut [u32], mut x: u32) -> u32 {
        while parent[x as usize] != x {
            let p = parent[x as usize];
            parent[x as usize] = parent[p as usize];
            x = p;
        }
        x
    }
    let join = |parent: &mut Vec<u32>, r: usize, q: usize| {
        let (mut a, mut b) = (row_start[r], row_start[q]);
        while a < row_start[r + 1] && b < row_start[q + 1] {
            let (ra, rb) = (runs[a], runs[b]);
            if ra.0 < rb.1 && rb.0 < ra.1 {
                let (x, y) = (find(parent, a as u32), find(parent, b as u32));
                // The smaller root wins: a component's root is its first run.
                if x != y {
                    let (lo, hi) = (x.min(y), x.max(y));
                    parent[hi as usize] = lo;
                }
            }
            if ra.1 < rb.1 {
                a += 1;
            } else {
                b += 1;
            }
        }
    };
    for k in 0..nz {
        for j in 0..ny {
            let r = j + ny * k;
            if j > 0 {
                join(&mut parent, r, r - 1);
            }
            if k > 0 {
                join(&mut parent, r, r - ny);
            }
        }
    }
    let mut size = vec![0usize; runs.len()];
    let mut roots = Vec::new();
    for (i, run) in runs.iter().enumerate() {
        let root = find(&mut parent, i as u32) as usize;
        if root == i {
            roots.push(i);
        }
        size[root] += (run.1 - run.0) as usize;
    }
    let found = roots.len();
    match policy {
        ComponentPolicy::All => (occ, found, found, 0),
        ComponentPolicy::LargestOnly => {
            // Largest; ties go to the component whose first cell comes first.
            let Some(&best) = roots
                .iter()
                .max_by(|&&a, &&b| size[a].cmp(&size[b]).then(b.cmp(&a)))
            else {
                return (occ, 0, 0, 0);
            };
            let total: usize = roots.iter().map(|&r| size[r]).sum();
            if found > 1 {
                log::info!(
                    "{found} components: keeping the largest ({} cells), dropping {} cells",
                    size[best],
                    total - size[best]
                );
            }
            let mut kept = vec![false; occ.len()];
            for r in 0..rows {
                for (i, &(s, e)) in runs
                    .iter()
                    .enumerate()
                    .take(row_start[r + 1])
                    .skip(row_start[r])
                {
                    if find(&mut parent, i as u32) as usize == best {
                        kept[r * nx + s as usize..r * nx + e as usize].fill(true);
                    }
                }
            }
            (kept, found, 1, total - size[best])
        }
    }
}

/// Distinct cell edges: a grid edge exists if any of the 4 cells around it
/// is occupied. Rows of cells are packed into bits so that "any of the cells
/// around" is an OR of shifted words.
pub(crate) fn count_edges(grid: &Grid, occ: &[bool]) -> usize {
    let [nx, ny, nz] = grid.dims.map(|d| d as usize);
    // Bit i + 1 of a packed row is cell i; bits 0 and nx + 1 stay empty.
    let words = (nx + 2).div_ceil(64);
    let pack = |r: usize| -> Vec<u64> {
        let mut w = vec![0u64; words];
        for (i, &o) in occ[r * nx..(r + 1) * nx].iter().enumerate() {
            if o {
                w[(i + 1) / 64] |= 1 << ((i + 1) % 64);
            }
        }
        w
    };
    let packed: Vec<Vec<u64>> = (0..ny * nz).into_par_iter().map(pack).collect();
    let empty = vec![0u64; words];
    let row = |j: isize, k: isize| -> &[u64] {
        if j < 0 || k < 0 || j >= ny as isize || k >= nz as isize {
            &empty
        } else {
            &packed[j as usize + ny * k as usize]
        }
    };
    // Bit m of (w | w << 1) is set if cell m - 1 or m - 2 is: node m - 1 has a cell on either side.
    let or_shift = |w: &[u64]| -> usize {
        let mut c = 0;
        let mut carry = 0u64;
        for &x in w {
            c += (x | (x << 1) | carry).count_ones() as usize;
            carry = x >> 63;
        }
        c + carry.count_ones() as usize
    };
    let mut count = 0;
    let mut tmp = vec![0u64; words];
    for k in 0..=nz as isize {
        for j in 0..=ny as isize {
            // x-edges along node row (j, k): cells (j-1..j, k-1..k) at the same x.
            let (a, b, c, d) = (row(j - 1, k - 1), row(j, k - 1), row(j - 1, k), row(j, k));
            count += (0..words)
                .map(|w| (a[w] | b[w] | c[w] | d[w]).count_ones() as usize)
                .sum::<usize>();
            // z-edges at node (x, j) of layer k (k < nz): cells (x-1..x, j-1..j, k).
            if k < nz as isize {
                for w in 0..words {
                    tmp[w] = c[w] | d[w];
                }
                count += or_shift(&tmp);
            }
            // y-edges at node (x, k) of row j (j < ny): cells (x-1..x, j, k-1..k).
            if j < ny as isize {
                for w in 0..words {
                    tmp[w] = b[w] | d[w];
                }
                count += or_shift(&tmp);
            }
        }
    }
    count
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::generate::{critter, sphere};

    /// Every rule, with and without a progress hook, on 1 and 3 threads:
    /// the same lattice, and a hook that sees 0, increasing counts and the total.
    #[test]
    fn progress_reaches_total_and_does_not_change_results() {
        struct EveryOther;
        impl Occupancy for EveryOther {
            fn occupied(&self, ctx: &OccupancyContext<'_>) -> Vec<bool> {
                (0..ctx.grid.len()).map(|i| i % 2 == 0).collect()
            }
        }
        let rules = [
            OccupancyRule::Centre,
            OccupancyRule::AnyOverlap,
            OccupancyRule::Fraction {
                threshold: 0.5,
                samples_per_axis: 2,
            },
            OccupancyRule::Custom(Arc::new(EveryOther)),
        ];
        // The critter is closed (exact crossings); the open sphere takes the
        // winding-number path.
        let mut open = sphere(1.0, 2);
        open.triangles.truncate(open.triangles.len() - 3);
        for mesh in [critter(), open] {
            for rule in &rules {
                let opts = VoxelizeOptions {
                    resolution: Resolution::CellsAlongLongestAxis(14),
                    rule: rule.clone(),
                    components: ComponentPolicy::All,
                    ..VoxelizeOptions::default()
                };
                let plain = voxelize(&mesh, &opts).unwrap();
                let grid = plan_grid(&mesh, &opts).unwrap();
                let rows = grid.dims[1] as u64 * grid.dims[2] as u64;
                let expect_total = match rule {
                    OccupancyRule::AnyOverlap => rows + mesh.triangles.len() as u64,
                    OccupancyRule::Custom(_) => 1,
                    _ => rows,
                };
                for threads in [1, 3] {
                    let pool = rayon::ThreadPoolBuilder::new()
                        .num_threads(threads)
                        .build()
                        .unwrap();
                    let calls = Mutex::new(Vec::new());
                    let hook = |done: u64, total: u64| calls.lock().unwrap().push((done, total));
                    let with = pool
                        .install(|| voxelize_with_progress(&mesh, &opts, &hook))
                        .unwrap();
                    assert_eq!(with.lattice, plain.lattice, "{rule:?}, {threads} threads");
                    assert_eq!(with.stats.cells, plain.stats.cells);
                    let calls = calls.into_inner().unwrap();
                    assert_eq!(calls.first(), Some(&(0, expect_total)), "{rule:?}");
                    assert_eq!(
                        calls.last(),
                        Some(&(expect_total, expect_total)),
                        "{rule:?}"
                    );
                    assert!(calls.windows(2).all(|w| w[0].0 < w[1].0), "{rule:?}");
                    assert!(calls.iter().all(|&(_, t)| t == expect_total));
                }
            }
        }
    }

    /// A hook is never called when voxelization is refused before classification.
    #[test]
    fn refused_grid_reports_nothing() {
        let opts = VoxelizeOptions {
            max_grid_cells: 10,
            ..VoxelizeOptions::default()
        };
        let called = Mutex::new(false);
        let hook = |_: u64, _: u64| *called.lock().unwrap() = true;
        let err = voxelize_with_progress(&critter(), &opts, &hook).unwrap_err();
        assert!(matches!(err, VoxelizeError::GridTooLarge { .. }), "{err}");
        assert!(!*called.lock().unwrap());
    }
}
